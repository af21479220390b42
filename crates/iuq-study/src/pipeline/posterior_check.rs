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
    /// surrogate (the computational std included).
    pub fn within_two_std(&self) -> f64 {
        let ok: Vec<bool> = self
            .runs()
            .filter_map(|r| {
                r.model.map(|m| {
                    let s = (r.surrogate_std.powi(2) + r.model_std.unwrap_or(0.0).powi(2)).sqrt();
                    (m - r.surrogate).abs() <= 2.0 * s
                })
            })
            .collect();
        if ok.is_empty() {
            return f64::NAN;
        }
        ok.iter().filter(|b| **b).count() as f64 / ok.len() as f64
    }

    /// Runs that failed.
    pub fn failures(&self) -> usize {
        self.runs().filter(|r| r.model.is_none()).count()
    }

    /// The MAP's run, then the samples'.
    pub fn runs(&self) -> impl Iterator<Item = &CheckedRun> {
        std::iter::once(&self.map).chain(&self.samples)
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
}

impl PosteriorCheck {
    /// Per data point `{x, rmse, within_two_std, failed}` (a non-finite number as `null`), as
    /// `pipeline.json` and `iuq pipeline --json` give it.
    pub fn point_summaries(&self) -> serde_json::Value {
        let finite = |v: f64| v.is_finite().then_some(v);
        self.points
            .iter()
            .map(|p| {
                serde_json::json!({
                    "x": p.x,
                    "rmse": finite(p.rmse()),
                    "within_two_std": finite(p.within_two_std()),
                    "failed": p.failures(),
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

/// Run the model at the MAP of `posterior` and at `settings.samples` of its samples in every
/// run group, and predict the same points with `surrogate`.
pub fn check_posterior(
    posterior: &SampledPosterior,
    surrogate: &Surrogate,
    runs: &ModelRuns,
    settings: &PosteriorCheckSettings,
) -> Result<PosteriorCheck> {
    let d = runs.parameters().len();
    let map = posterior.summary.map[..d].to_vec();
    let samples = chosen_samples(posterior, d, settings.samples, settings.seed);
    let points: Vec<Vec<f64>> = std::iter::once(map.clone())
        .chain(samples.iter().cloned())
        .collect();
    let requests: Vec<(usize, Vec<f64>)> = (0..runs.groups())
        .flat_map(|g| points.iter().map(move |p| (g, p.clone())))
        .collect();
    let outcomes = runs.run_with_diagnostics(Some(POSTERIOR_CHECK_DESIGN), &requests)?;
    let predictions = surrogate.bank.predict(&points).map_err(|e| {
        StudyError::Failure(format!("predicting the posterior check's points: {e}"))
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
                .bank
                .predictive_std()
                .variance(prediction)
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
            });
        }
    }
    Ok(PosteriorCheck {
        map,
        samples,
        points: checks,
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
