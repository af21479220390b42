//! The surrogate checked where the calibration uses it: the model itself is run at the MAP of the
//! surrogate's posterior and at `samples` distinct posterior samples, in every run group, and its
//! outputs are set beside the surrogate's prediction at the same parameters (as the published
//! study's Fig. 8 shows model runs at the optimal parameters). The runs are a design of the
//! campaign store (`posterior-check`), so a rerun on the same posterior reuses them.

use iuq_core::Outcome;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_xoshiro::Xoshiro256PlusPlus;

use super::model_runs::ModelRuns;
use super::settings::PosteriorCheckSettings;
use super::surrogate::Surrogate;
use crate::error::{Result, StudyError};
use crate::posterior::SampledPosterior;

/// Label of the check's runs in the campaign store.
pub const POSTERIOR_CHECK_DESIGN: &str = "posterior-check";

/// Label under which the runs of a check made after round `round` are recorded once they become
/// training runs: a replay takes that check's points from the store, as it takes a round's, so
/// that what the later rounds were trained on does not hang on the last bits of a resampled
/// posterior.
pub fn retrained_check_label(round: usize) -> String {
    format!("posterior-check-after-round-{round}")
}

/// One model run of the check at one data point, beside the surrogate there.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CheckedRun {
    /// The model's output (`None` when the run failed).
    pub model: Option<f64>,
    /// Its computational std.
    pub model_std: Option<f64>,
    /// The model's further outputs (for the cell model: the elongation's drift over the window).
    pub diagnostics: Vec<f64>,
    /// The surrogate's mean there.
    pub surrogate: f64,
    /// The surrogate's predictive std there, as the likelihood uses it: by default that of a new
    /// run (latent function and the GP's noise, which at a stress where nearly equal cells end
    /// apart holds that run-to-run scatter).
    pub surrogate_std: f64,
}

/// The check at one data point.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PointCheck {
    /// The data point's abscissa.
    pub x: f64,
    /// The run at the MAP.
    pub map: CheckedRun,
    /// The runs at the posterior samples.
    pub samples: Vec<CheckedRun>,
    /// The smallest error that counts: `resolution` × the datum's likelihood std without the
    /// surrogate (measurement and modelling error, at the MAP), added in quadrature to each
    /// run's predictive std. A deterministic model's GP may be
    /// sure to a thousandth of the measurement std, and an error ten times its std but a
    /// hundredth of the measurement's moves no likelihood term.
    pub resolution: f64,
}

impl PointCheck {
    /// Root mean square of model − surrogate over the successful runs (MAP and samples).
    pub fn rmse(&self) -> f64 {
        let d: Vec<f64> = self
            .runs()
            .filter_map(|r| r.model.map(|m| m - r.surrogate))
            .collect();
        if d.is_empty() {
            return f64::NAN;
        }
        (d.iter().map(|v| v * v).sum::<f64>() / d.len() as f64).sqrt()
    }

    /// Share of the successful runs whose model output lies within two predictive stds of the
    /// surrogate (the computational std and the resolution included).
    pub fn within_two_std(&self) -> f64 {
        let z = self.standardised_residuals();
        if z.is_empty() {
            return f64::NAN;
        }
        z.iter().filter(|z| z.abs() <= 2.0).count() as f64 / z.len() as f64
    }

    /// z = (model − surrogate)/√(surrogate std² + the run's computational std² + resolution²)
    /// of each successful run: standard normal (or narrower) where the surrogate's predictive std
    /// is right.
    pub fn standardised_residuals(&self) -> Vec<f64> {
        self.runs()
            .filter_map(|r| {
                r.model.map(|m| {
                    let s = (r.surrogate_std.powi(2)
                        + r.model_std.unwrap_or(0.0).powi(2)
                        + self.resolution.powi(2))
                    .sqrt();
                    (m - r.surrogate) / s
                })
            })
            .collect()
    }

    /// Runs that failed.
    pub fn failures(&self) -> usize {
        self.runs().filter(|r| r.model.is_none()).count()
    }

    /// The MAP's run, then the samples'.
    pub fn runs(&self) -> impl Iterator<Item = &CheckedRun> {
        std::iter::once(&self.map).chain(&self.samples)
    }

    #[cfg(test)]
    fn runs_mut(&mut self) -> impl Iterator<Item = &mut CheckedRun> {
        std::iter::once(&mut self.map).chain(&mut self.samples)
    }
}

/// The check of every data point.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PosteriorCheck {
    /// The MAP's model parameters.
    pub map: Vec<f64>,
    /// The posterior samples' model parameters.
    pub samples: Vec<Vec<f64>>,
    /// One check per data point.
    pub points: Vec<PointCheck>,
    /// Its test ([`CheckVerdict`], at the study's `significance`).
    pub verdict: CheckVerdict,
}

/// Probability that a run falls more than two predictive stds from a surrogate whose predictive
/// distribution is right: 2(1 − Φ(2)).
pub const OUTSIDE_TWO_STD: f64 = 0.045_500_263_896_358_42;

/// The test of a posterior check: does the model scatter about the surrogate as the surrogate's
/// predictive stds say? Two tests, each at half the family-wise `significance` α:
///
/// - **the largest |z|** over all n successful runs: it fails when
///   |z| > z* = Φ⁻¹(1 − α/(4n)) (Bonferroni over the runs, both signs): one run far outside
///   finds a surrogate that is sure where it is wrong (a part of the posterior without runs);
/// - **the runs outside two stds per data point**: m of a point's n_j runs (failed runs count
///   as outside: the surrogate answered where the model does not), fails when
///   P(Binomial(n_j, 0.0455) ≥ m) < α/(2·points): many runs moderately outside find a
///   surrogate whose stds are too small everywhere.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CheckVerdict {
    /// Both tests passed.
    pub passed: bool,
    /// The family-wise significance α.
    pub significance: f64,
    /// The largest |z| over every successful run (0 when none).
    pub largest_z: f64,
    /// The bound z* it is held to.
    pub z_bound: f64,
    /// Per data point, the runs outside two predictive stds (failed runs included).
    pub outside: Vec<usize>,
    /// Per data point, P(Binomial(n_j, 0.0455) ≥ outside): how surprising that count is.
    pub tail_probability: Vec<f64>,
    /// The data points (indices) that failed either test.
    pub failed_points: Vec<usize>,
}

/// P(X ≥ m) for X ~ Binomial(n, p), summed exactly (n is a check's handful of runs).
fn binomial_upper_tail(n: usize, p: f64, m: usize) -> f64 {
    if m == 0 {
        return 1.0;
    }
    if m > n {
        return 0.0;
    }
    let ln_p = p.ln();
    let ln_q = (1.0 - p).ln();
    let mut ln_choose = 0.0; // ln C(n, k), built up from k = 0
    let mut total = 0.0;
    for k in 0..=n {
        if k > 0 {
            ln_choose += ((n - k + 1) as f64).ln() - (k as f64).ln();
        }
        if k >= m {
            total += (ln_choose + k as f64 * ln_p + (n - k) as f64 * ln_q).exp();
        }
    }
    total.min(1.0)
}

impl CheckVerdict {
    /// The test of the checks `points` at family-wise significance `significance`.
    pub fn of(points: &[PointCheck], significance: f64) -> Self {
        let residuals: Vec<Vec<f64>> = points
            .iter()
            .map(PointCheck::standardised_residuals)
            .collect();
        let runs: usize = residuals.iter().map(Vec::len).sum();
        let z_bound = iuq_core::normal::quantile(1.0 - significance / (4.0 * runs.max(1) as f64));
        let largest = |z: &[f64]| z.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let point_bound = significance / (2.0 * points.len().max(1) as f64);
        let mut outside = Vec::with_capacity(points.len());
        let mut tail_probability = Vec::with_capacity(points.len());
        let mut failed_points = Vec::new();
        for (j, (point, z)) in points.iter().zip(&residuals).enumerate() {
            let n = point.runs().count();
            let m = z.iter().filter(|z| z.abs() > 2.0).count() + point.failures();
            let tail = binomial_upper_tail(n, OUTSIDE_TWO_STD, m);
            if tail < point_bound || largest(z) > z_bound {
                failed_points.push(j);
            }
            outside.push(m);
            tail_probability.push(tail);
        }
        CheckVerdict {
            passed: failed_points.is_empty(),
            significance,
            largest_z: residuals.iter().map(|z| largest(z)).fold(0.0, f64::max),
            z_bound,
            outside,
            tail_probability,
            failed_points,
        }
    }
}

impl PosteriorCheck {
    /// Per data point `{x, rmse, within_two_std, failed, passed}` (a non-finite number as
    /// `null`; `passed`: the point passed the check's test), as `pipeline.json` and
    /// `iuq pipeline --json` give it.
    pub fn point_summaries(&self) -> serde_json::Value {
        let finite = |v: f64| v.is_finite().then_some(v);
        self.points
            .iter()
            .enumerate()
            .map(|(j, p)| {
                serde_json::json!({
                    "x": p.x,
                    "rmse": finite(p.rmse()),
                    "within_two_std": finite(p.within_two_std()),
                    "failed": p.failures(),
                    "passed": !self.verdict.failed_points.contains(&j),
                })
            })
            .collect()
    }
}

/// `count` distinct members of the posterior population, chosen with `seed` (the model's
/// parameters only: `sigma_m`, when sampled, is dropped), the MAP excluded.
fn chosen_samples(
    posterior: &SampledPosterior,
    d: usize,
    count: usize,
    seed: u64,
) -> Vec<Vec<f64>> {
    let map = &posterior.summary.map[..d.min(posterior.summary.map.len())];
    let mut distinct: Vec<Vec<f64>> = Vec::new();
    for s in &posterior.run.state.samples {
        let theta = s[..d].to_vec();
        if theta.as_slice() != map && !distinct.contains(&theta) {
            distinct.push(theta);
        }
    }
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    distinct.shuffle(&mut rng);
    distinct.truncate(count);
    distinct
}

/// Where a check's points come from.
pub enum CheckPoints<'a> {
    /// The MAP of the posterior and `samples` of its samples, the runs recorded as
    /// [`POSTERIOR_CHECK_DESIGN`].
    Posterior(&'a SampledPosterior),
    /// The points (MAP first) of a check recorded under `label`, replayed.
    Recorded {
        /// The points, the MAP's first.
        points: Vec<Vec<f64>>,
        /// Their design's label.
        label: String,
    },
}

/// Run the model at the check's points (the MAP of a posterior and `settings.samples` of its
/// samples, or a recorded check's) in every run group, and predict the same points with
/// `surrogate`; `likelihood_std` (per data point: the likelihood's std without the surrogate,
/// at the MAP) sets each point's resolution.
pub fn check_posterior(
    points: CheckPoints<'_>,
    surrogate: &Surrogate,
    runs: &ModelRuns,
    settings: &PosteriorCheckSettings,
    likelihood_std: &[f64],
) -> Result<PosteriorCheck> {
    let d = runs.parameters().len();
    let (map, samples, label) = match points {
        CheckPoints::Posterior(posterior) => (
            posterior.summary.map[..d].to_vec(),
            chosen_samples(posterior, d, settings.samples, settings.seed),
            POSTERIOR_CHECK_DESIGN.to_string(),
        ),
        CheckPoints::Recorded { mut points, label } => {
            if points.is_empty() {
                return Err(StudyError::failure(format!(
                    "the posterior check `{label}` recorded in the campaign store has no points"
                )));
            }
            let map = points.remove(0);
            (map, points, label)
        }
    };
    let points: Vec<Vec<f64>> = std::iter::once(map.clone())
        .chain(samples.iter().cloned())
        .collect();
    let requests: Vec<(usize, Vec<f64>)> = (0..runs.groups())
        .flat_map(|g| points.iter().map(move |p| (g, p.clone())))
        .collect();
    let outcomes = runs.run_with_diagnostics(Some(&label), &requests)?;
    let predictions = surrogate.emulator.predict(&points).map_err(|e| {
        StudyError::failure(format!("predicting the posterior check's points: {e}")).with_source(e)
    })?;
    let mut checks = Vec::new();
    for g in 0..runs.groups() {
        let group = &outcomes[g * points.len()..(g + 1) * points.len()];
        for (k, j) in runs.group_outputs(g).enumerate() {
            let width = runs.group_outputs(g).len();
            let prediction = &predictions[j];
            // The std the likelihood uses as the surrogate's computational std: with the
            // default bank, that of a new run (latent and noise), so the check asks whether the
            // runs scatter about the surrogate as the calibration assumed.
            let std: Vec<f64> = surrogate
                .emulator
                .reported_variance(j, prediction)
                .into_iter()
                .map(f64::sqrt)
                .collect();
            let checked: Vec<CheckedRun> = group
                .iter()
                .enumerate()
                .map(|(i, o)| checked_run(o, k, width, prediction.mean[i], std[i]))
                .collect();
            let mut checked = checked.into_iter();
            let Some(map_run) = checked.next() else {
                continue;
            };
            checks.push(PointCheck {
                x: runs.abscissa_of_output(j),
                map: map_run,
                samples: checked.collect(),
                resolution: settings.resolution * likelihood_std.get(j).copied().unwrap_or(0.0),
            });
        }
    }
    let verdict = CheckVerdict::of(&checks, settings.significance);
    Ok(PosteriorCheck {
        map,
        samples,
        points: checks,
        verdict,
    })
}

fn checked_run(
    outcome: &Outcome,
    k: usize,
    width: usize,
    surrogate: f64,
    surrogate_std: f64,
) -> CheckedRun {
    match outcome {
        Ok(e) if e.outputs.len() >= width => CheckedRun {
            model: Some(e.outputs[k]),
            model_std: e.computational_std.as_ref().and_then(|s| s.get(k).copied()),
            diagnostics: e.outputs[width..].to_vec(),
            surrogate,
            surrogate_std,
        },
        _ => CheckedRun {
            model: None,
            model_std: None,
            diagnostics: Vec::new(),
            surrogate,
            surrogate_std,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(model: Option<f64>, surrogate: f64, surrogate_std: f64) -> CheckedRun {
        CheckedRun {
            model,
            model_std: Some(0.0),
            diagnostics: Vec::new(),
            surrogate,
            surrogate_std,
        }
    }

    /// A point of 21 runs with standardised residuals `z` (surrogate 0, std 1).
    fn point(z: &[f64]) -> PointCheck {
        let mut runs = z.iter().map(|&z| run(Some(z), 0.0, 1.0));
        PointCheck {
            x: 1.0,
            map: runs.next().unwrap(),
            samples: runs.collect(),
            resolution: 0.0,
        }
    }

    /// 21 residuals spread as a standard normal's quantiles (none beyond ±2).
    fn calibrated() -> Vec<f64> {
        (0..21)
            .map(|i| iuq_core::normal::quantile((i as f64 + 0.5) / 21.0) * 0.9)
            .collect()
    }

    #[test]
    fn the_binomial_tail_matches_scipy() {
        // scipy.stats.binom.sf(m - 1, n, 2 * norm.sf(2)), scipy 1.x.
        for (n, m, reference) in [
            (21, 0, 1.0),
            (21, 1, 0.623_909_757_650_397_8),
            (21, 3, 0.067_954_985_081_704_37),
            (21, 6, 2.661_095_960_971_435e-4),
            (21, 21, 6.581_005_079_148_737e-29),
            (5, 2, 0.018_882_290_320_939_073),
        ] {
            let tail = binomial_upper_tail(n, OUTSIDE_TWO_STD, m);
            assert!(
                (tail - reference).abs() <= 1e-12 * reference.max(1e-300) + 1e-300,
                "n {n} m {m}: {tail} vs {reference}"
            );
        }
        assert_eq!(binomial_upper_tail(3, OUTSIDE_TWO_STD, 4), 0.0);
        // 2(1 − Φ(2)) = erfc(√2); scipy's 2 * norm.sf(2) gives 0.04550026389635839.
        assert!((OUTSIDE_TWO_STD - 0.045_500_263_896_358_39).abs() < 1e-16);
        assert!((OUTSIDE_TWO_STD - 2.0 * (1.0 - iuq_core::normal::cdf(2.0))).abs() < 1e-16);
    }

    #[test]
    fn a_surrogate_whose_stds_are_right_passes() {
        let points = vec![point(&calibrated()); 6];
        let v = CheckVerdict::of(&points, 0.01);
        assert!(v.passed, "{v:?}");
        assert_eq!(v.outside, vec![0; 6]);
        // Bonferroni bound over 126 runs, both signs, half of α: scipy norm.isf(0.01 / 504).
        assert!(
            (v.z_bound - 4.109_320_282_055_079).abs() < 1e-9,
            "{}",
            v.z_bound
        );
    }

    #[test]
    fn one_run_far_outside_fails_its_point_only() {
        let mut z = calibrated();
        z[7] = -4.8; // the TBHP study's 6.19 Pa run, surrogate 0.03 too high at std 0.006
        let points = vec![point(&calibrated()), point(&z), point(&calibrated())];
        let v = CheckVerdict::of(&points, 0.01);
        assert!(!v.passed);
        assert_eq!(v.failed_points, vec![1]);
        assert!((v.largest_z - 4.8).abs() < 1e-12);
        // One point alone (21 runs): its bound, and a run just inside it passes (one run
        // outside two stds is no surprise), just beyond it fails.
        let bound = iuq_core::normal::quantile(1.0 - 0.01 / 84.0);
        for (shift, passes) in [(-0.01, true), (0.01, false)] {
            let mut z = calibrated();
            z[7] = bound + shift;
            let v = CheckVerdict::of(&[point(&z)], 0.01);
            assert_eq!(v.passed, passes, "{v:?}");
            assert!((v.z_bound - bound).abs() < 1e-12);
        }
    }

    #[test]
    fn many_runs_moderately_outside_fail_by_their_count() {
        // 6 of 21 runs at |z| = 2.5: no single run beyond the bound, but P(≥ 6 outside) =
        // 2.7e-4 < 0.01 / 2.
        let mut z = calibrated();
        for (i, v) in z.iter_mut().enumerate().take(6) {
            *v = if i % 2 == 0 { 2.5 } else { -2.5 };
        }
        let v = CheckVerdict::of(&[point(&z)], 0.01);
        assert!(!v.passed);
        assert_eq!(v.outside, vec![6]);
        assert!(v.largest_z < v.z_bound);
        // Three outside (p = 0.068) pass.
        let mut z = calibrated();
        z[0] = 2.5;
        z[1] = -2.5;
        z[2] = 2.5;
        assert!(CheckVerdict::of(&[point(&z)], 0.01).passed);
    }

    #[test]
    fn failed_runs_count_as_outside() {
        let mut p = point(&calibrated());
        for r in p.samples.iter_mut().take(6) {
            r.model = None;
        }
        assert_eq!(p.failures(), 6);
        let v = CheckVerdict::of(&[p], 0.01);
        assert!(!v.passed);
        assert_eq!(v.outside, vec![6]);
    }

    #[test]
    fn the_resolution_keeps_errors_far_below_the_measurement_std_from_counting() {
        // A deterministic model's GP sure to 0.002 while off by 0.03, against a measurement
        // std of 0.8 (the bump test of the cooling study): z = 15 without the resolution.
        let mut p = point(&[0.0; 21]);
        for r in p.runs_mut() {
            r.model = Some(0.03);
            r.surrogate_std = 0.002;
        }
        assert!(!CheckVerdict::of(std::slice::from_ref(&p), 0.01).passed);
        p.resolution = 0.1 * 0.8;
        let z = p.standardised_residuals();
        assert!((z[0] - 0.03 / (0.002f64.powi(2) + 0.08f64.powi(2)).sqrt()).abs() < 1e-12);
        assert!(CheckVerdict::of(&[p], 0.01).passed);
    }
}
