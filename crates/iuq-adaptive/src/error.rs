//! The error type of `iuq-adaptive`.

use thiserror::Error;

/// Everything that can go wrong when choosing new runs or judging convergence.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum AdaptiveError {
    /// A surrogate could not be evaluated.
    #[error("surrogate: {0}")]
    Surrogate(#[from] iuq_gp::GpError),
    /// Inputs of inconsistent sizes.
    #[error("length mismatch: {what}: expected {expected}, got {actual}")]
    LengthMismatch {
        /// What was compared.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Actual length.
        actual: usize,
    },
    /// An invalid setting or value.
    #[error("invalid {what}: {reason}")]
    InvalidParameter {
        /// The setting or value.
        what: &'static str,
        /// Why it is invalid.
        reason: String,
    },
}

/// Result type of `iuq-adaptive`.
pub type Result<T, E = AdaptiveError> = std::result::Result<T, E>;
