//! Whether the model's outputs repeat under a negligible change of its parameters.
//!
//! A chaotic simulator (a red cell past its membrane's force singularity at high shear stress)
//! is deterministic, yet its measuring window's mean moves by many times the window's own spread
//! when a parameter moves by 1e-9 of its range: the trajectories part once the dynamics turn
//! irregular, and the window catches a different phase of a slow, irregular wandering. Its
//! likelihood is then, at any useful resolution, a random draw: the model's posterior is the one
//! averaged over that irregular part, and a run's likelihood is an unbiased draw of it
//! (pseudo-marginal; [`iuq_basis::ModelPosteriorSettings::pseudo_marginal`]).
//!
//! The probe reruns a few members of the model posterior's first batch with every parameter
//! moved by [`RELATIVE_NUDGE`] of its prior range (inwards at a bound) and compares each
//! output with the member's own run: an output is **irregular** where some pair differs by more
//! than [`SPREAD_SHARE`] of the larger of the two runs' own computational stds, by more than
//! [`LIKELIHOOD_SHARE`] of the datum's smallest error scale (its measurement std and the
//! modelling error's lower bound: a change below it moves the log-likelihood by less than about
//! 0.01 nats, whatever its cause, e.g. an adaptive solver's step selection), and by more than
//! [`RELATIVE_FLOOR`] of its value (a smooth model moves by about 1e-9 of its value). The pairs'
//! runs are campaign runs under [`PROBE_DESIGN`]: stored, reused by a rerun, and the members'
//! own runs are the ones the first batch requests anyway.

use serde_json::{Value, json};

use iuq_core::Outcome;

use super::model_runs::ModelRuns;
use crate::error::{Result, StudyError};

/// Label of the probe's runs in the campaign store.
pub const PROBE_DESIGN: &str = "model-posterior-probe";

/// The move of every parameter, as a share of its prior range.
pub const RELATIVE_NUDGE: f64 = 1e-9;

/// An output whose pair differs by more than this share of the runs' own std is irregular.
pub const SPREAD_SHARE: f64 = 0.1;

/// …and by more than this share of its value (a smooth model's output moves by about
/// [`RELATIVE_NUDGE`] times its sensitivity).
pub const RELATIVE_FLOOR: f64 = 1e-6;

/// …and by more than this share of the datum's smallest error scale.
pub const LIKELIHOOD_SHARE: f64 = 0.01;

/// What the probe found at one output (data point).
#[derive(Debug, Clone, PartialEq)]
pub struct ProbedOutput {
    /// The output's name.
    pub name: String,
    /// The largest |q(θ + δ) − q(θ)| over the pairs.
    pub largest_change: f64,
    /// The larger of the two runs' own stds at that pair (`None`: the model reports none, or 0).
    pub own_std: Option<f64>,
    /// The change exceeds [`SPREAD_SHARE`] of the own std and [`RELATIVE_FLOOR`] of the value.
    pub irregular: bool,
}

/// The probe's result.
#[derive(Debug, Clone, PartialEq)]
pub struct ReproducibilityProbe {
    /// Members probed (pairs with a failed run are left out).
    pub pairs: usize,
    /// Model evaluations the nudged points cost (the members' own are the first batch's).
    pub model_evaluations: usize,
    /// Per output.
    pub outputs: Vec<ProbedOutput>,
    nudged_points: Vec<Vec<f64>>,
}

impl ReproducibilityProbe {
    /// Some output is irregular: the model's likelihood is a noisy estimate.
    pub fn irregular(&self) -> bool {
        self.outputs.iter().any(|o| o.irregular)
    }

    /// The nudged points run (model parameters), in the order of the probed members.
    pub fn nudged_points(&self) -> &[Vec<f64>] {
        &self.nudged_points
    }

    /// The summary `model_posterior.probe` of `pipeline.json`.
    pub fn to_json(&self) -> Value {
        json!({
            "pairs": self.pairs,
            "relative_nudge": RELATIVE_NUDGE,
            "model_evaluations": self.model_evaluations,
            "irregular": self.irregular(),
            "outputs": self.outputs.iter().map(|o| json!({
                "name": o.name,
                "largest_change": o.largest_change,
                "own_std": o.own_std,
                "irregular": o.irregular,
            })).collect::<Vec<_>>(),
        })
    }
}

/// `members` (model parameters) moved by [`RELATIVE_NUDGE`] of each parameter's `ranges` width,
/// inwards where the move would leave the range.
pub fn nudged(members: &[Vec<f64>], ranges: &[(f64, f64)]) -> Vec<Vec<f64>> {
    nudged_by(members, ranges, 1.0)
}

/// `members` moved by `multiple` × [`RELATIVE_NUDGE`] of each parameter's range width (of its
/// magnitude, at least 1, where the range is unbounded), inwards where the move would leave the
/// range; `multiple` 0 leaves them as they are, bit for bit.
pub fn nudged_by(members: &[Vec<f64>], ranges: &[(f64, f64)], multiple: f64) -> Vec<Vec<f64>> {
    members
        .iter()
        .map(|m| {
            m.iter()
                .zip(ranges)
                .map(|(&x, &(lo, hi))| {
                    let width = hi - lo;
                    let delta = if width.is_finite() && width > 0.0 {
                        RELATIVE_NUDGE * width * multiple
                    } else {
                        RELATIVE_NUDGE * x.abs().max(1.0) * multiple
                    };
                    let moved = if x + delta <= hi {
                        x + delta
                    } else {
                        x - delta
                    };
                    // A nudge below the value's rounding step still moves it, by one step.
                    match (moved == x, multiple > 0.0) {
                        (true, true) if adjacent(x, true) <= hi => adjacent(x, true),
                        (true, true) => adjacent(x, false),
                        _ => moved,
                    }
                })
                .collect()
        })
        .collect()
}

/// The next representable value above (`up`) or below a finite `x` (`f64::next_up` and
/// `next_down`, stable only since Rust 1.86, above this crate's minimum).
fn adjacent(x: f64, up: bool) -> f64 {
    if x == 0.0 {
        let tiny = f64::from_bits(1);
        return if up { tiny } else { -tiny };
    }
    let bits = x.to_bits();
    // Away from zero for a positive step of a positive x or a negative step of a negative x.
    let away = (x > 0.0) == up;
    f64::from_bits(if away { bits + 1 } else { bits - 1 })
}

/// Run `members` and their nudged copies (one campaign batch under [`PROBE_DESIGN`]) and
/// compare their outputs; `error_scales[j]` is datum j's smallest error scale (0: none known).
pub fn probe_reproducibility(
    model_runs: &ModelRuns,
    members: &[Vec<f64>],
    ranges: &[(f64, f64)],
    error_scales: &[f64],
) -> Result<ReproducibilityProbe> {
    let moved = nudged(members, ranges);
    let points: Vec<Vec<f64>> = members.iter().chain(&moved).cloned().collect();
    let outcomes = model_runs
        .model_at_data()
        .evaluate_labelled(PROBE_DESIGN, &points)
        .map_err(|e| StudyError::from(e).context("the reproducibility probe"))?;
    let (own, nudged_outcomes) = outcomes.split_at(members.len());
    let (pairs, outputs) = compare_pairs(
        model_runs.output_names(),
        own,
        nudged_outcomes,
        error_scales,
    );
    Ok(ReproducibilityProbe {
        pairs,
        model_evaluations: moved.len(),
        outputs,
        nudged_points: moved,
    })
}

/// Per output, the largest change between each member's run (`own`) and its nudged copy's
/// (`nudged`), and whether it is irregular; pairs with a failed run are left out.
fn compare_pairs(
    names: &[String],
    own: &[Outcome],
    nudged: &[Outcome],
    error_scales: &[f64],
) -> (usize, Vec<ProbedOutput>) {
    let mut outputs: Vec<ProbedOutput> = names
        .iter()
        .map(|name| ProbedOutput {
            name: name.clone(),
            largest_change: 0.0,
            own_std: None,
            irregular: false,
        })
        .collect();
    let mut pairs = 0;
    for (a, b) in own.iter().zip(nudged) {
        let (Ok(a), Ok(b)) = (a, b) else { continue };
        pairs += 1;
        for (j, out) in outputs.iter_mut().enumerate() {
            let (qa, qb) = (a.outputs[j], b.outputs[j]);
            let change = (qb - qa).abs();
            let own = |s: &Option<Vec<f64>>| s.as_ref().and_then(|s| s.get(j).copied());
            let std = match (own(&a.computational_std), own(&b.computational_std)) {
                (Some(sa), Some(sb)) => Some(sa.max(sb)),
                (Some(s), None) | (None, Some(s)) => Some(s),
                (None, None) => None,
            }
            .filter(|s| *s > 0.0);
            let threshold = (SPREAD_SHARE * std.unwrap_or(0.0))
                .max(LIKELIHOOD_SHARE * error_scales.get(j).copied().unwrap_or(0.0))
                .max(RELATIVE_FLOOR * qa.abs().max(qb.abs()))
                .max(f64::MIN_POSITIVE);
            if change > threshold {
                out.irregular = true;
            }
            if change >= out.largest_change {
                out.largest_change = change;
                out.own_std = std;
            }
        }
    }
    (pairs, outputs)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(q: &[f64], s: Option<&[f64]>) -> Outcome {
        Ok(match s {
            Some(s) => iuq_core::Evaluation::with_std(q.to_vec(), s.to_vec()),
            None => iuq_core::Evaluation::new(q.to_vec()),
        })
    }

    #[test]
    fn an_output_is_irregular_only_beyond_its_spread_its_error_scale_and_a_millionth_of_itself() {
        let names: Vec<String> = ["a", "b", "c", "d"].map(String::from).to_vec();
        // a: moves by 5 times its own std (chaotic); b: by a 1e-7 of itself (smooth); c: an
        // output near 0 that moves by 1e-9, far below its datum's error scale 0.01; d: moves by
        // 2e-3, above a millionth of itself but below 0.1 × its std 0.05.
        let own = [run(
            &[0.6, 1.0, 1e-12, 0.5],
            Some(&[0.004, 0.01, 0.0, 0.05]),
        )];
        let moved = [run(
            &[0.62, 1.0 + 1e-7, 1e-9, 0.502],
            Some(&[0.004, 0.01, 0.0, 0.05]),
        )];
        let (pairs, outputs) = compare_pairs(&names, &own, &moved, &[0.002, 0.002, 0.01, 0.002]);
        assert_eq!(pairs, 1);
        let flags: Vec<bool> = outputs.iter().map(|o| o.irregular).collect();
        assert_eq!(flags, [true, false, false, false]);
        assert!((outputs[0].largest_change - 0.02).abs() < 1e-12);
        // A std of 0 is no std: `own_std` is none, and c is judged by its error scale alone.
        assert_eq!(outputs[2].own_std, None);
        // Without a known error scale, c's change is irregular (beyond a millionth of itself).
        let (_, outputs) = compare_pairs(&names, &own, &moved, &[]);
        assert!(outputs[2].irregular);
        // A pair with a failed run is left out; no pair at all flags nothing.
        let failed: [Outcome; 1] = [Err(iuq_core::EvaluationFailure::new("broke"))];
        let (pairs, outputs) = compare_pairs(&names, &own, &failed, &[]);
        assert_eq!(pairs, 0);
        assert!(
            outputs
                .iter()
                .all(|o| !o.irregular && o.largest_change == 0.0)
        );
    }

    #[test]
    fn a_nudge_moves_each_parameter_by_a_billionth_of_its_range_and_stays_inside() {
        let ranges = [(0.0, 10.0), (1.0, 2.0)];
        let moved = nudged(&[vec![5.0, 2.0]], &ranges);
        assert_eq!(moved[0][0], 5.0 + 1e-8);
        assert_eq!(moved[0][1], 2.0 - 1e-9);
        assert!(moved[0][1] >= 1.0);
        let still = nudged_by(&[vec![5.0, 2.0]], &ranges, 0.0);
        assert_eq!(still[0], vec![5.0, 2.0]);
        assert_eq!(nudged_by(&[vec![5.0, 2.0]], &ranges, 1.0), moved);
        assert_eq!(nudged_by(&[vec![5.0, 1.5]], &ranges, 3.0)[0][1], 1.5 + 3e-9);
        // A value too large for the nudge to change it moves by one rounding step.
        let wide = [(0.0, 1e12)];
        assert_eq!(
            nudged(&[vec![1e12 - 1.0]], &[(0.0, 1e-3)])[0][0],
            (1e12f64 - 1.0).next_down()
        );
        assert_eq!(nudged(&[vec![3e9]], &wide)[0][0], 3e9 + 1e3);
    }
}
