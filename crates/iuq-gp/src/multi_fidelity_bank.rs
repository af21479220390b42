//! A bank of two-fidelity GPs ([`MultiFidelityGp`]), one per output, sharing the inputs: the
//! surrogate of an expensive multi-output model helped by a cheap one, usable wherever a
//! [`Model`] is, as [`crate::GpBank`] is for one fidelity.
//!
//! ```
//! use iuq_core::Model;
//! use iuq_gp::{FitOptions, MultiFidelityBank, MultiFidelityGp};
//!
//! let low_x: Vec<Vec<f64>> = (0..20).map(|i| vec![i as f64 / 19.0]).collect();
//! let high_x: Vec<Vec<f64>> = (0..5).map(|i| vec![0.1 + i as f64 / 5.0]).collect();
//! let low = |x: &[f64]| (4.0 * x[0]).sin();
//! let high = |x: &[f64]| 1.5 * (4.0 * x[0]).sin() + 0.2;
//! let options = FitOptions::default().check()?;
//! let gp = MultiFidelityGp::fit(
//!     &low_x,
//!     &low_x.iter().map(|x| low(x)).collect::<Vec<_>>(),
//!     &high_x,
//!     &high_x.iter().map(|x| high(x)).collect::<Vec<_>>(),
//!     &options,
//! )?;
//! let bank = MultiFidelityBank::new(vec!["x".into()], vec!["y".into()], vec![gp])?;
//! let at = bank.evaluate_batch(&[vec![0.45]]).unwrap();
//! let value = at[0].as_ref().unwrap().outputs[0];
//! assert!((value - high(&[0.45])).abs() < 0.05, "{value}");
//! # Ok::<(), iuq_gp::GpError>(())
//! ```

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use iuq_core::model::{Evaluation, EvaluationFailure, Model, Outcome};

use crate::bank::PredictiveStd;
use crate::error::{GpError, Result};
use crate::multi_fidelity::MultiFidelityGp;
use crate::prediction::Prediction;

/// One two-fidelity GP per output, all on the same inputs. As a [`Model`], a batch of points
/// gives per point the high fidelity's posterior means and predictive stds (latent variance
/// plus a new high-fidelity run's noise) as the computational std.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MultiFidelityBank {
    input_names: Vec<String>,
    output_names: Vec<String>,
    gps: Vec<MultiFidelityGp>,
}

impl MultiFidelityBank {
    /// A bank from fitted two-fidelity GPs, one per output name.
    ///
    /// # Errors
    /// No outputs, or a count of GPs different from the outputs.
    pub fn new(
        input_names: Vec<String>,
        output_names: Vec<String>,
        gps: Vec<MultiFidelityGp>,
    ) -> Result<Self> {
        if output_names.is_empty() {
            return Err(GpError::InvalidParameter {
                what: "two-fidelity GP bank",
                reason: "needs at least one output".into(),
            });
        }
        if gps.len() != output_names.len() {
            return Err(GpError::LengthMismatch {
                what: "two-fidelity GPs vs. output names",
                expected: output_names.len(),
                actual: gps.len(),
            });
        }
        Ok(Self {
            input_names,
            output_names,
            gps,
        })
    }

    /// The GPs, in output order.
    pub fn gps(&self) -> &[MultiFidelityGp] {
        &self.gps
    }

    /// The outputs' names.
    pub fn output_names(&self) -> &[String] {
        &self.output_names
    }

    /// Which predictive std the bank reports: that of a new high-fidelity run, noise included.
    pub fn predictive_std(&self) -> PredictiveStd {
        PredictiveStd::WithNoise
    }

    /// Predictions of every output at `points` (outputs in parallel).
    ///
    /// # Errors
    /// A point of the wrong dimension or with a non-finite coordinate.
    pub fn predict(&self, points: &[Vec<f64>]) -> Result<Vec<Prediction>> {
        self.gps.par_iter().map(|gp| gp.predict(points)).collect()
    }
}

impl Model for MultiFidelityBank {
    fn input_names(&self) -> &[String] {
        &self.input_names
    }

    fn output_names(&self) -> &[String] {
        &self.output_names
    }

    /// Per point: every output's mean with √(latent variance + noise variance) as its
    /// computational std. A point of the wrong dimension or with a non-finite coordinate is a
    /// per-point failure.
    fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
        let d = self.input_names.len();
        let valid: Vec<bool> = points
            .iter()
            .map(|p| p.len() == d && p.iter().all(|v| v.is_finite()))
            .collect();
        let kept: Vec<Vec<f64>> = points
            .iter()
            .zip(&valid)
            .filter(|(_, ok)| **ok)
            .map(|(p, _)| p.clone())
            .collect();
        let predictions = self
            .predict(&kept)
            .map_err(|e| iuq_core::CoreError::ModelUnavailable(e.to_string()))?;
        let mut next = 0;
        Ok(valid
            .into_iter()
            .map(|ok| {
                if !ok {
                    return Err(EvaluationFailure::new(format!(
                        "expected {d} finite inputs"
                    )));
                }
                let i = next;
                next += 1;
                Ok(Evaluation::with_std(
                    predictions.iter().map(|p| p.mean[i]).collect(),
                    predictions
                        .iter()
                        .map(|p| (p.variance[i] + p.noise_variance).sqrt())
                        .collect(),
                ))
            })
            .collect())
    }
}
