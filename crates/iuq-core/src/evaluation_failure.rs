//! Why a model produced no result at one parameter vector: a failure is data (samplers reject
//! it, sensitivity estimators report it, surrogates skip it), carried with its reason.

/// Why a model produced no result at one parameter vector.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EvaluationFailure {
    /// A human-readable reason, e.g. "mesh broke: edge strain beyond the force singularity".
    pub reason: String,
}

impl EvaluationFailure {
    /// A failure with the given reason.
    pub fn new(reason: impl Into<String>) -> Self {
        Self {
            reason: reason.into(),
        }
    }
}

impl std::fmt::Display for EvaluationFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.reason)
    }
}
