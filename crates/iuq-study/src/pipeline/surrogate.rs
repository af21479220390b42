//! The surrogate of a study's model: one GP per data point, trained on the successful training
//! runs that inform it, and — where runs have failed — one failure classifier per run group
//! (`iuq_gp::FailureClassifier`), trained on every run of the group.
//!
//! As a [`Model`] of θ ([`Surrogate`]), it returns the GPs' means with their predictive stds as
//! the computational std, and *fails* where a classifier says the model is more likely than not
//! to give no answer (p_fail > ½): the posterior then has no mass there, BASIS counts the
//! proposals as failures, and the adaptive engine places no run there.

use iuq_core::{EvaluationFailure, Model, Outcome, ParameterSpace};
use iuq_gp::{ClassifierOptions, FailureClassifier, FitOptions, GaussianProcess, GpBank};

use super::model_runs::ModelRuns;
use super::run_groups::GroupRuns;
use crate::error::{Context, Result, StudyError};

/// The probability of failure above which the surrogate gives no answer.
pub const FAILURE_THRESHOLD: f64 = 0.5;

/// GPs of every data point and failure classifiers of the run groups.
#[derive(Debug, Clone)]
pub struct Surrogate {
    /// One GP per data point.
    pub bank: GpBank,
    /// Per run group, its failure classifier (`None`: no run of the group failed).
    pub classifiers: Vec<Option<FailureClassifier>>,
}

/// Bounds of the classifier's unit cube: each prior's support where finite, else the runs'
/// extent.
fn classifier_bounds(space: &ParameterSpace, points: &[Vec<f64>]) -> Vec<(f64, f64)> {
    space
        .parameters()
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let (lo, hi) = p.prior.support();
            if lo.is_finite() && hi.is_finite() && lo < hi {
                return (lo, hi);
            }
            let (a, b) = points
                .iter()
                .fold((f64::MAX, f64::MIN), |(a, b), x| (a.min(x[k]), b.max(x[k])));
            if a < b { (a, b) } else { (a - 1.0, a + 1.0) }
        })
        .collect()
}

impl Surrogate {
    /// Fit the GPs (GP j with seed `seed + j`) and the classifiers of `groups`.
    ///
    /// # Errors
    /// A data point with fewer than 3 successful training runs, or a fit that fails.
    pub fn fit(
        groups: &[GroupRuns],
        runs: &ModelRuns,
        space: &ParameterSpace,
        seed: u64,
        describe: impl Fn(usize) -> String,
    ) -> Result<Self> {
        let mut gps = Vec::with_capacity(runs.output_names().len());
        let mut classifiers = Vec::with_capacity(groups.len());
        for (g, group) in groups.iter().enumerate() {
            for (k, j) in runs.group_outputs(g).enumerate() {
                let training = group.training(k);
                if training.y.len() < 3 {
                    return Err(StudyError::Failure(format!(
                        "{}: only {} training runs succeeded; a GP needs at least 3 (failures: {})",
                        describe(j),
                        training.y.len(),
                        group
                            .failure_reasons()
                            .first()
                            .map_or("none", String::as_str)
                    )));
                }
                let options = FitOptions {
                    seed: seed.wrapping_add(j as u64),
                    ..Default::default()
                };
                let gp = GaussianProcess::fit(&training.x, &training.y, &options.check()?)
                    .with_context(|| format!("GP fit {}", describe(j)))?;
                gps.push(gp);
            }
            let (points, failed) = group.failure_labels();
            let bounds = classifier_bounds(space, &points);
            let classifier = FailureClassifier::fit(
                &points,
                &failed,
                &bounds,
                &ClassifierOptions::default().check()?,
            )
            .with_context(|| format!("failure classifier of run group {}", g + 1))?;
            classifiers.push(classifier);
        }
        let bank = GpBank::new(
            runs.parameters().to_vec(),
            runs.output_names().to_vec(),
            gps,
        )?;
        Ok(Self { bank, classifiers })
    }

    /// The probability that a run of group `g` fails at each point.
    pub fn group_failure_probability(&self, g: usize, points: &[Vec<f64>]) -> Result<Vec<f64>> {
        match self.classifiers.get(g).and_then(Option::as_ref) {
            Some(c) => Ok(c.failure_probability(points)?),
            None => Ok(vec![0.0; points.len()]),
        }
    }
}

impl Model for Surrogate {
    fn input_names(&self) -> &[String] {
        self.bank.input_names()
    }

    fn output_names(&self) -> &[String] {
        self.bank.output_names()
    }

    fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
        let mut outcomes = self.bank.evaluate_batch(points)?;
        for (g, classifier) in self.classifiers.iter().enumerate() {
            let Some(c) = classifier else { continue };
            let valid: Vec<usize> = (0..points.len()).filter(|&i| outcomes[i].is_ok()).collect();
            let probe: Vec<Vec<f64>> = valid.iter().map(|&i| points[i].clone()).collect();
            let p = c
                .failure_probability(&probe)
                .map_err(|e| iuq_core::CoreError::ModelUnavailable(e.to_string()))?;
            for (&i, p_fail) in valid.iter().zip(p) {
                if p_fail > FAILURE_THRESHOLD {
                    outcomes[i] = Err(EvaluationFailure::new(format!(
                        "the failure classifier of run group {} predicts no answer here (p_fail = {p_fail:.2})",
                        g + 1
                    )));
                }
            }
        }
        Ok(outcomes)
    }
}
