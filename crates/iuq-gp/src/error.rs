//! The error type of `iuq-gp`.

use thiserror::Error;

/// Everything that can go wrong when fitting, evaluating, validating or loading a Gaussian
/// process. Bad input is always reported as an error, never as a panic.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum GpError {
    /// Fewer training points than a Gaussian process needs (at least 2).
    #[error("too few training points: {actual} given, at least {required} needed")]
    TooFewPoints {
        /// Points needed.
        required: usize,
        /// Points given.
        actual: usize,
    },
    /// A training or prediction point has no coordinates.
    #[error("points have no coordinates (input dimension 0)")]
    ZeroDimension,
    /// A point (or a row of a table) has the wrong number of values.
    #[error("{what} {index}: expected {expected} values, got {actual}")]
    DimensionMismatch {
        /// What was being checked, e.g. "training point", "prediction point".
        what: &'static str,
        /// Index of the offending point.
        index: usize,
        /// Expected length.
        expected: usize,
        /// Actual length.
        actual: usize,
    },
    /// Two collections that must have the same length do not.
    #[error("length mismatch: {what}: expected {expected}, got {actual}")]
    LengthMismatch {
        /// What was being compared, e.g. "outputs vs. training points".
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Actual length.
        actual: usize,
    },
    /// A value that must be finite is NaN or infinite.
    #[error("{what} {index} is not finite ({value})")]
    NonFinite {
        /// What was being checked, e.g. "training input", "output".
        what: &'static str,
        /// Flat index of the offending value.
        index: usize,
        /// The offending value.
        value: f64,
    },
    /// An invalid option or hyper-parameter (non-positive variance, empty bounds, …).
    #[error("invalid {what}: {reason}")]
    InvalidParameter {
        /// The option or hyper-parameter.
        what: &'static str,
        /// Why it is invalid.
        reason: String,
    },
    /// The covariance matrix is not numerically positive definite at these hyper-parameters.
    #[error(
        "covariance matrix not positive definite (pivot {pivot}); increase the noise or jitter"
    )]
    NotPositiveDefinite {
        /// The index of the first failing pivot of the Cholesky factorisation.
        pivot: usize,
    },
    /// No multi-start run produced a finite log marginal likelihood.
    #[error("hyper-parameter optimisation failed: {0}")]
    FitFailed(String),
    /// A saved Gaussian process could not be read.
    #[error("cannot load Gaussian process: {0}")]
    Persistence(String),
}

/// Result type of `iuq-gp`.
pub type Result<T, E = GpError> = std::result::Result<T, E>;
