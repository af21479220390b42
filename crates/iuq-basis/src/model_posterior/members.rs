//! The members the method weighs and what it computes over them: their log-likelihoods
//! ([`evaluate`]), log-ratios and weights' CV, the best point run, the corrected surrogate, and
//! where a correction's posterior leaves its batch.

use iuq_core::ParameterSpace;
use serde::{Deserialize, Serialize};

use super::settings::MIN_CORRECTED_WITHIN_BATCH;
use crate::error::{BasisError, Result};
use crate::likelihood::{LogLikelihood, PointLogLikelihood};
use crate::pareto_smoothing::normalised_weights;
use crate::spread_ratio::widest_spread_ratio;

/// Members with their surrogate and model log-likelihoods and log-priors (−∞, a failed run,
/// written as `null` in a checkpoint).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct Members {
    pub(crate) theta: Vec<Vec<f64>>,
    #[serde(with = "crate::json_numbers::negative_infinity_as_null")]
    pub(crate) surrogate: Vec<f64>,
    #[serde(with = "crate::json_numbers::negative_infinity_as_null")]
    pub(crate) model: Vec<f64>,
    #[serde(with = "crate::json_numbers::negative_infinity_as_null")]
    pub(crate) prior: Vec<f64>,
}

/// A correction of the surrogate's log-likelihood, chosen at run time among the candidates.
pub(crate) type BoxedCorrection = Box<dyn Fn(&[f64]) -> f64 + Send + Sync>;

/// ℓ_s + r̂: the surrogate corrected by a fit of the model–surrogate difference (a quadratic
/// fit of r, or the moment-matched log-ratio of a noisy model's weights).
pub(crate) struct CorrectedLikelihood<'a, F: Fn(&[f64]) -> f64 + Send + Sync> {
    pub(crate) base: &'a dyn LogLikelihood,
    pub(crate) correction: F,
}

impl<F: Fn(&[f64]) -> f64 + Send + Sync> LogLikelihood for CorrectedLikelihood<'_, F> {
    fn parameter_count(&self) -> usize {
        self.base.parameter_count()
    }

    fn log_likelihood_batch(&self, points: &[Vec<f64>]) -> Result<Vec<PointLogLikelihood>> {
        Ok(self
            .base
            .log_likelihood_batch(points)?
            .into_iter()
            .zip(points)
            .map(|(v, x)| v.map(|v| v + (self.correction)(x)))
            .collect())
    }
}

/// The likelihoods, with batch failures turned into errors naming what was evaluated.
pub(crate) fn evaluate(
    likelihood: &dyn LogLikelihood,
    points: &[Vec<f64>],
    what: &str,
) -> Result<Vec<f64>> {
    if points.is_empty() {
        return Ok(Vec::new());
    }
    let values = likelihood
        .log_likelihood_batch(points)
        .map_err(|e| match e {
            BasisError::ModelInput(_) => e,
            e => BasisError::ModelBatch(format!("{what}: {e}")),
        })?;
    if values.len() != points.len() {
        return Err(BasisError::ModelBatch(format!(
            "{what}: {} values for {} points",
            values.len(),
            points.len()
        )));
    }
    Ok(values
        .into_iter()
        .map(|v| match v {
            Ok(v) if v.is_finite() => v,
            _ => f64::NEG_INFINITY,
        })
        .collect())
}

/// A step's [`ModelPosteriorStage::spread_ratio`](super::ModelPosteriorStage::spread_ratio): the widest ratio of weighted std to the
/// proposal's over `points` (`batches` batches), 0 where it cannot be computed.
pub(crate) fn recorded_spread_ratio(
    points: &[Vec<f64>],
    log_weights: &[f64],
    batches: usize,
) -> f64 {
    widest_spread_ratio(points, log_weights, batches).map_or(0.0, |(_, ratio)| ratio)
}

/// Why a corrected posterior's `samples` are refused against the `batch` its correction was
/// fitted on ("keeps N % of its population inside the range of P …"), where less than
/// [`MIN_CORRECTED_WITHIN_BATCH`] of them lie inside the batch's range of some parameter P;
/// `None` when they do not.
pub(crate) fn outside_batch(
    space: &ParameterSpace,
    samples: &[Vec<f64>],
    batch: &[Vec<f64>],
) -> Option<String> {
    let (parameter, within) = least_share_within_ranges(samples, batch);
    (within < MIN_CORRECTED_WITHIN_BATCH).then(|| {
        format!(
            "keeps {:.0} % of its population inside the range of {} over the batch it was \
             fitted on (at least {:.0} % needed)",
            100.0 * within,
            space.names()[parameter],
            100.0 * MIN_CORRECTED_WITHIN_BATCH
        )
    })
}

/// The parameter whose range over `batch` (minimum to maximum) holds the smallest share of
/// `samples`, and that share (parameter 0 and share 0 for an empty batch).
fn least_share_within_ranges(samples: &[Vec<f64>], batch: &[Vec<f64>]) -> (usize, f64) {
    let Some(d) = batch.first().map(Vec::len) else {
        return (0, 0.0);
    };
    (0..d)
        .map(|k| {
            let (lo, hi) = batch
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| {
                    (lo.min(t[k]), hi.max(t[k]))
                });
            let inside = samples.iter().filter(|t| t[k] >= lo && t[k] <= hi).count();
            (k, inside as f64 / samples.len().max(1) as f64)
        })
        .fold((0, f64::INFINITY), |least, (k, share)| {
            if share < least.1 { (k, share) } else { least }
        })
}

/// The largest finite value (−∞ when there is none: every model run failed).
pub(crate) fn largest_finite(values: &[f64]) -> f64 {
    values
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(f64::NEG_INFINITY, f64::max)
}

/// r_i = ℓ_m,i − ℓ_s,i, −∞ where it is not finite (a failed model run).
pub(crate) fn log_ratios(model: &[f64], surrogate: &[f64]) -> Vec<f64> {
    model
        .iter()
        .zip(surrogate)
        .map(|(m, s)| {
            let r = m - s;
            if r.is_finite() { r } else { f64::NEG_INFINITY }
        })
        .collect()
}

/// CV (population std / mean) of the weights exp(lw − max lw), as BASIS's rule measures it;
/// failed members count as 0.
pub(crate) fn coefficient_of_variation(log_weights: &[f64]) -> f64 {
    crate::annealing::coefficient_of_variation(&normalised_weights(log_weights))
}

/// The best model-evaluated point so far (largest ℓ_m + ln π; the first one on ties).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub(crate) struct Best {
    pub(super) point: Option<(Vec<f64>, f64, f64)>,
}

impl Best {
    pub(crate) fn offer(&mut self, points: &[Vec<f64>], lm: &[f64], lp: &[f64]) {
        for ((p, &m), &q) in points.iter().zip(lm).zip(lp) {
            if !(m + q).is_finite() {
                continue;
            }
            let better = match &self.point {
                Some((_, bm, bq)) => m + q > bm + bq,
                None => true,
            };
            if better {
                self.point = Some((p.clone(), m, q));
            }
        }
    }
}
