//! The error type of `iuq-sensitivity`.

use thiserror::Error;

/// Errors of the sensitivity analysis.
#[derive(Debug, Error)]
pub enum SensitivityError {
    /// Inputs to an estimator with inconsistent lengths or too few values.
    #[error("invalid estimator input: {0}")]
    InvalidInput(String),
    /// The output has zero variance over the design, so no index is defined.
    #[error("output `{0}` has zero variance over the design: Sobol' indices are undefined")]
    ZeroVariance(String),
    /// Too many base points lost to failed runs for an estimate.
    #[error("output `{output}`: only {usable} of {total} base points have no failed run")]
    TooManyFailures {
        /// The output's name.
        output: String,
        /// Base points whose runs all succeeded.
        usable: usize,
        /// Base points of the design.
        total: usize,
    },
    /// Invalid analysis options (sample size, confidence level, replicate count).
    #[error("invalid option: {0}")]
    InvalidOption(String),
    /// The design could not be built.
    #[error(transparent)]
    Design(#[from] iuq_doe::DoeError),
    /// The model or parameter space failed.
    #[error(transparent)]
    Core(#[from] iuq_core::CoreError),
}

/// Result type of `iuq-sensitivity`.
pub type Result<T, E = SensitivityError> = std::result::Result<T, E>;
