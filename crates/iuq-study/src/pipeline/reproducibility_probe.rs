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
//! than [`SPREAD_SHARE`] of the larger of the two runs' own computational stds, and by more than
//! [`RELATIVE_FLOOR`] of its value (a smooth model moves by about 1e-9 of its value). The pairs'
//! runs are campaign runs under [`PROBE_DESIGN`]: stored, reused by a rerun, and the members'
//! own runs are the ones the first batch requests anyway.

use serde_json::{Value, json};

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

/// What the probe found at one output (data point).
#[derive(Debug, Clone, PartialEq)]
pub struct ProbedOutput {
    /// The output's name.
    pub name: String,
    /// The largest |q(θ + δ) − q(θ)| over the pairs.
    pub largest_change: f64,
    /// The larger of the two runs' own stds at that pair (`None`: the model reports none).
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
}

impl ReproducibilityProbe {
    /// Some output is irregular: the model's likelihood is a noisy estimate.
    pub fn irregular(&self) -> bool {
        self.outputs.iter().any(|o| o.irregular)
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
                    if x + delta <= hi {
                        x + delta
                    } else {
                        x - delta
                    }
                })
                .collect()
        })
        .collect()
}

/// Run `members` and their nudged copies (one campaign batch under [`PROBE_DESIGN`]) and
/// compare their outputs.
pub fn probe_reproducibility(
    model_runs: &ModelRuns,
    members: &[Vec<f64>],
    ranges: &[(f64, f64)],
) -> Result<ReproducibilityProbe> {
    let moved = nudged(members, ranges);
    let points: Vec<Vec<f64>> = members.iter().chain(&moved).cloned().collect();
    let outcomes = model_runs
        .model_at_data()
        .evaluate_labelled(PROBE_DESIGN, &points)
        .map_err(|e| StudyError::Failure(format!("the reproducibility probe: {e}")))?;
    let (own, nudged_outcomes) = outcomes.split_at(members.len());
    let names = model_runs.output_names();
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
    for (a, b) in own.iter().zip(nudged_outcomes) {
        let (Ok(a), Ok(b)) = (a, b) else { continue };
        pairs += 1;
        for (j, out) in outputs.iter_mut().enumerate() {
            let (qa, qb) = (a.outputs[j], b.outputs[j]);
            let change = (qb - qa).abs();
            let std = match (&a.computational_std, &b.computational_std) {
                (Some(sa), Some(sb)) => Some(sa[j].max(sb[j])),
                (Some(s), None) | (None, Some(s)) => Some(s[j]),
                (None, None) => None,
            };
            let threshold = (SPREAD_SHARE * std.unwrap_or(0.0))
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
    Ok(ReproducibilityProbe {
        pairs,
        model_evaluations: moved.len(),
        outputs,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

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
    }
}
