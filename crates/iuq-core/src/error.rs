//! The error type of `iuq-core`.

use thiserror::Error;

/// Errors raised by the core types: invalid priors, parameter spaces, expressions and inputs to
/// the statistics.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum CoreError {
    /// A prior whose parameters make no distribution (e.g. `lower >= upper`, `std <= 0`).
    #[error("invalid prior for `{parameter}`: {reason}")]
    InvalidPrior {
        /// The parameter's name.
        parameter: String,
        /// What is wrong with its prior.
        reason: String,
    },
    /// A parameter space that cannot be used (no parameters, duplicate names).
    #[error("invalid parameter space: {0}")]
    InvalidParameterSpace(String),
    /// An analytic expression that does not parse or names an unknown variable.
    #[error("expression `{expression}`: {reason}")]
    InvalidExpression {
        /// The expression's text.
        expression: String,
        /// Why it cannot be evaluated.
        reason: String,
    },
    /// A point whose length does not match the dimension it is used with.
    #[error("dimension mismatch: expected {expected} values, got {actual}")]
    DimensionMismatch {
        /// The dimension the point is used with.
        expected: usize,
        /// The point's length.
        actual: usize,
    },
    /// Input to a statistic that does not define it (empty data, negative weights, singular covariance).
    #[error("invalid statistical input: {0}")]
    InvalidStatisticInput(String),
    /// A model could not evaluate a whole batch (infrastructure failure, not a per-point failure).
    #[error("model evaluation failed: {0}")]
    ModelUnavailable(String),
    /// A model cannot run as its study describes it (e.g. its command does not start): bad
    /// input to fix in the study, not a failure of the model or of its infrastructure.
    #[error("{0}")]
    ModelInput(String),
}

/// Result type of `iuq-core`.
pub type Result<T, E = CoreError> = std::result::Result<T, E>;
