//! Saving and loading a fitted GP as JSON (no file I/O here: the caller reads and writes).
//!
//! The JSON holds what defines the GP — kernel variant, hyper-parameters, jitter, scalers,
//! training data — and what the fit reported (LML, diagnostics). Loading validates everything,
//! rebuilds the Cholesky factor, α and the leave-one-out results from the stored data, and
//! checks that the recomputed LML matches the stored one. Floats are written in shortest
//! round-trip form and read back exactly, so a loaded GP predicts bit-identically.

use serde::{Deserialize, Serialize};

use crate::diagnostics::FitDiagnostics;
use crate::error::{GpError, Result};
use crate::gaussian_process::{Covariance, GaussianProcess, prepare_with};
use crate::kernel::{Hyperparameters, Kernel};
use crate::log_marginal_likelihood::validate_jitter;
use crate::scaling::{InputScaling, OutputScaling};

/// The value of the `format` field.
pub const FORMAT: &str = "iuq-gp";
/// The version of the layout written by this crate.
pub const FORMAT_VERSION: u32 = 1;

/// The stored form of a [`GaussianProcess`].
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct SavedGaussianProcess {
    format: String,
    version: u32,
    kernel: Kernel,
    hyperparameters: Hyperparameters,
    jitter: f64,
    input_scaling: InputScaling,
    output_scaling: OutputScaling,
    training_inputs: Vec<Vec<f64>>,
    training_outputs: Vec<f64>,
    log_marginal_likelihood: f64,
    diagnostics: FitDiagnostics,
}

impl From<GaussianProcess> for SavedGaussianProcess {
    fn from(gp: GaussianProcess) -> Self {
        Self {
            format: FORMAT.to_string(),
            version: FORMAT_VERSION,
            kernel: gp.kernel,
            hyperparameters: gp.hyperparameters,
            jitter: gp.jitter,
            input_scaling: gp.input_scaling,
            output_scaling: gp.output_scaling,
            training_inputs: gp.training_inputs,
            training_outputs: gp.training_outputs,
            log_marginal_likelihood: gp.log_marginal_likelihood,
            diagnostics: gp.diagnostics,
        }
    }
}

fn invalid(reason: impl Into<String>) -> GpError {
    GpError::Persistence(reason.into())
}

impl TryFrom<SavedGaussianProcess> for GaussianProcess {
    type Error = GpError;

    fn try_from(s: SavedGaussianProcess) -> Result<Self> {
        if s.format != FORMAT {
            return Err(invalid(format!(
                "format is `{}`, expected `{FORMAT}`",
                s.format
            )));
        }
        if s.version != FORMAT_VERSION {
            return Err(invalid(format!(
                "version {} is not supported (expected {FORMAT_VERSION})",
                s.version
            )));
        }
        let d = s.input_scaling.dimension();
        if s.input_scaling.range.len() != d
            || s.input_scaling
                .lower
                .iter()
                .chain(&s.input_scaling.range)
                .any(|v| !v.is_finite())
            || s.input_scaling.range.iter().any(|r| *r <= 0.0)
        {
            return Err(invalid(
                "input scaling must have finite offsets and positive ranges",
            ));
        }
        if !(s.output_scaling.mean.is_finite()
            && s.output_scaling.std.is_finite()
            && s.output_scaling.std > 0.0)
        {
            return Err(invalid(
                "output scaling must have a finite mean and a positive std",
            ));
        }
        s.kernel.validate()?;
        validate_jitter(s.jitter)?;
        // Validates the training data (shape, finiteness, n ≥ 2) like a fit does.
        crate::gaussian_process::prepare(&s.training_inputs, &s.training_outputs, false, false)?;
        if s.training_inputs[0].len() != d {
            return Err(invalid(format!(
                "training inputs have {} coordinates, the input scaling {d}",
                s.training_inputs[0].len()
            )));
        }
        s.hyperparameters.validate(&s.kernel, d)?;
        let prepared = prepare_with(
            &s.training_inputs,
            &s.training_outputs,
            s.input_scaling,
            s.output_scaling,
        )?;
        // The stored diagnostics are kept as saved (warnings included), not recomputed.
        let mut diagnostics = s.diagnostics;
        let saved_warnings = std::mem::take(&mut diagnostics.warnings);
        let mut gp = GaussianProcess::assemble(
            &s.training_inputs,
            &s.training_outputs,
            prepared,
            Covariance {
                kernel: s.kernel,
                hyperparameters: s.hyperparameters,
                jitter: s.jitter,
            },
            f64::NEG_INFINITY,
            diagnostics,
        )?;
        gp.diagnostics.warnings = saved_warnings;
        let tolerance = 1e-6 * s.log_marginal_likelihood.abs().max(1.0);
        let difference = (gp.log_marginal_likelihood - s.log_marginal_likelihood).abs();
        if difference.is_nan() || difference > tolerance {
            return Err(invalid(format!(
                "stored log marginal likelihood {} differs from the recomputed {}",
                s.log_marginal_likelihood, gp.log_marginal_likelihood
            )));
        }
        Ok(gp)
    }
}

impl Serialize for GaussianProcess {
    fn serialize<S: serde::Serializer>(
        &self,
        serializer: S,
    ) -> std::result::Result<S::Ok, S::Error> {
        SavedGaussianProcess::from(self.clone()).serialize(serializer)
    }
}

impl<'de> Deserialize<'de> for GaussianProcess {
    fn deserialize<D: serde::Deserializer<'de>>(
        deserializer: D,
    ) -> std::result::Result<Self, D::Error> {
        let saved = SavedGaussianProcess::deserialize(deserializer)?;
        GaussianProcess::try_from(saved).map_err(serde::de::Error::custom)
    }
}

impl GaussianProcess {
    /// The GP as a JSON document (see the module documentation).
    ///
    /// # Errors
    /// Only if serialisation fails (it does not for a valid GP).
    pub fn to_json_string(&self) -> Result<String> {
        serde_json::to_string(self).map_err(|e| invalid(e.to_string()))
    }

    /// A GP from a JSON document written by [`GaussianProcess::to_json_string`].
    ///
    /// # Errors
    /// Malformed JSON, a wrong format or version, invalid data or hyper-parameters, a K that is
    /// not positive definite, or a stored LML that the data do not reproduce.
    pub fn from_json_str(json: &str) -> Result<Self> {
        let saved: SavedGaussianProcess =
            serde_json::from_str(json).map_err(|e| invalid(e.to_string()))?;
        GaussianProcess::try_from(saved)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::FitOptions;
    use crate::test_data::spec_data;

    fn small_fit() -> GaussianProcess {
        let (x, y) = spec_data();
        let opts = FitOptions {
            n_restarts: 2,
            ..Default::default()
        };
        GaussianProcess::fit(&x[..30], &y[..30], &opts.check().unwrap()).unwrap()
    }

    #[test]
    fn roundtrip_gives_identical_predictions() {
        let gp = small_fit();
        let json = gp.to_json_string().unwrap();
        let back = GaussianProcess::from_json_str(&json).unwrap();
        let pts: Vec<Vec<f64>> = (0..50)
            .map(|i| {
                let t = i as f64 / 50.0;
                vec![t, (5.0 * t).fract(), (11.0 * t).fract()]
            })
            .collect();
        assert_eq!(gp.predict(&pts).unwrap(), back.predict(&pts).unwrap());
        assert_eq!(gp.log_marginal_likelihood(), back.log_marginal_likelihood());
        assert_eq!(gp.hyperparameters(), back.hyperparameters());
        assert_eq!(gp.diagnostics(), back.diagnostics());
        assert_eq!(gp.leave_one_out(), back.leave_one_out());
        assert_eq!(back.to_json_string().unwrap(), json);
    }

    #[test]
    fn corrupted_documents_are_errors() {
        let gp = small_fit();
        let json = gp.to_json_string().unwrap();
        assert!(GaussianProcess::from_json_str("{").is_err());
        assert!(GaussianProcess::from_json_str("{}").is_err());
        let mut v: serde_json::Value = serde_json::from_str(&json).unwrap();
        v["format"] = "other".into();
        assert!(GaussianProcess::from_json_str(&v.to_string()).is_err());
        let mut v: serde_json::Value = serde_json::from_str(&json).unwrap();
        v["hyperparameters"]["noise_variance"] = (-1.0).into();
        assert!(GaussianProcess::from_json_str(&v.to_string()).is_err());
        let mut v: serde_json::Value = serde_json::from_str(&json).unwrap();
        v["training_outputs"][3] = 100.0.into();
        let e = GaussianProcess::from_json_str(&v.to_string()).unwrap_err();
        assert!(e.to_string().contains("log marginal likelihood"), "{e}");
        let mut v: serde_json::Value = serde_json::from_str(&json).unwrap();
        v["training_inputs"][2] = serde_json::json!([0.1, 0.2]);
        assert!(GaussianProcess::from_json_str(&v.to_string()).is_err());
        let mut v: serde_json::Value = serde_json::from_str(&json).unwrap();
        v["input_scaling"]["range"][0] = 0.0.into();
        assert!(GaussianProcess::from_json_str(&v.to_string()).is_err());
    }
}
