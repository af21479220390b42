//! The error type of `iuq-basis`.

use thiserror::Error;

use iuq_core::CoreError;

/// Everything that can go wrong while building a likelihood, configuring or running the
/// sampler, or reading a checkpoint.
///
/// Failures of the model at single points are *not* errors: they are rejections, counted in the
/// per-stage diagnostics. An error here stops the run.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum BasisError {
    /// A sampler setting outside its valid range (checked once, before any work).
    #[error("invalid setting `{setting}`: {reason}")]
    InvalidSettings {
        /// The setting's name as in [`crate::BasisSettings`] (and the study file).
        setting: &'static str,
        /// Why the value is invalid.
        reason: String,
    },
    /// Data that cannot enter the prediction-error likelihood (empty, non-finite, negative
    /// measurement errors, a length that does not match the model's outputs).
    #[error("invalid data: {0}")]
    InvalidData(String),
    /// A likelihood that cannot be built or does not fit the parameter space.
    #[error("invalid likelihood: {0}")]
    InvalidLikelihood(String),
    /// A likelihood's model could not evaluate a whole batch (its infrastructure, not a single
    /// point), or returned the wrong number of outcomes. The sampler reports it as
    /// [`BasisError::Evaluation`] with the stage.
    #[error("model could not evaluate the batch: {0}")]
    ModelBatch(String),
    /// A likelihood's model cannot run as its study describes it
    /// ([`iuq_core::CoreError::ModelInput`]): bad input, passed on as it is.
    #[error("{0}")]
    ModelInput(String),
    /// A whole batch failed at a stage of the run (the model's infrastructure, not a single
    /// point), or returned the wrong number of outcomes.
    #[error("model evaluation failed at stage {stage}: {reason}")]
    Evaluation {
        /// The stage whose batch failed.
        stage: usize,
        /// The model's message.
        reason: String,
    },
    /// Every member of the population has a zero likelihood (failed or non-finite), so there is
    /// nothing to anneal from.
    #[error(
        "stage {stage}: no member of the population has a finite log-likelihood ({failures} failures)"
    )]
    NoFiniteLikelihood {
        /// The stage whose population is degenerate.
        stage: usize,
        /// How many members failed.
        failures: usize,
    },
    /// The run has already stopped; a finished state cannot be advanced.
    #[error("the run has already finished ({0})")]
    AlreadyFinished(String),
    /// A checkpoint that does not parse or is not a BASIS checkpoint of a supported version.
    #[error("invalid checkpoint: {0}")]
    Checkpoint(String),
    /// A checkpoint written by a run with other settings or parameters than the resuming one.
    #[error("checkpoint does not match this run: {0}")]
    CheckpointMismatch(String),
    /// An observer's own work failed (e.g. a checkpoint could not be written): it stopped the
    /// run, and its owner reports this error.
    #[error("observer: {0}")]
    Observer(String),
    /// The model posterior's observer answered [`iuq_core::Control::Stop`] where more work
    /// was to follow ([`crate::model_posterior()`]); the BASIS sampler instead ends a stopped
    /// run with [`crate::StopReason::Interrupted`].
    #[error("interrupted by its observer before the model posterior was done")]
    Interrupted,
    /// An error of the core types (priors, expressions, statistics, KDE).
    #[error(transparent)]
    Core(#[from] CoreError),
}

/// Result type of `iuq-basis`.
pub type Result<T, E = BasisError> = std::result::Result<T, E>;
