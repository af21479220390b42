//! The crate's one error type, [`StudyError`]: bad input versus failed work.
//!
//! Every error caused by what the user gave (a study file, a key in it, a data file, a flag) is
//! a [`StudyError::BadInput`] whose message names the file, the key and the reason; the command
//! line maps it to exit code 2. Any other error is a [`StudyError::Failure`] of the work (exit
//! code 1).
//!
//! The message of an error from another crate is its text followed by the texts of its sources,
//! each after `: `; [`Context::context`] puts `context: ` in front of a message and keeps its
//! kind. So a message reads like a chain of causes, outermost first.

use std::error::Error as StdError;
use std::fmt::Display;

use thiserror::Error;

use iuq_campaign::CampaignError;
use iuq_study_file::StudyFileError;

/// An error of a study: bad input or a failure of the work, with its whole message.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum StudyError {
    /// Caused by the user's input; the message names the file (or flag), the key and the reason.
    #[error("{0}")]
    BadInput(String),
    /// A failure of the work (a model, a file system, a numerical method).
    #[error("{0}")]
    Failure(String),
    /// The pipeline was interrupted (its observer asked it to stop): the model runs finished so
    /// far are stored, and a rerun continues from them.
    #[error("{INTERRUPTED}")]
    Interrupted,
}

/// The message of [`StudyError::Interrupted`].
pub const INTERRUPTED: &str =
    "interrupted: the model runs finished so far are stored; run again to continue";

/// Result type of `iuq-study`.
pub type Result<T, E = StudyError> = std::result::Result<T, E>;

impl StudyError {
    /// True when the error is caused by the user's input (exit code 2 in the command line).
    pub fn is_bad_input(&self) -> bool {
        matches!(self, Self::BadInput(_))
    }

    /// The whole message.
    pub fn message(&self) -> &str {
        match self {
            Self::BadInput(m) | Self::Failure(m) => m,
            Self::Interrupted => INTERRUPTED,
        }
    }

    /// The same kind of error with the message `context: message`.
    pub fn context(self, context: impl Display) -> Self {
        match self {
            Self::BadInput(m) => Self::BadInput(format!("{context}: {m}")),
            Self::Failure(m) => Self::Failure(format!("{context}: {m}")),
            Self::Interrupted => Self::Interrupted,
        }
    }

    /// Any error as a study error: a [`StudyError`] stays what it is, a [`StudyFileError`] is
    /// bad input, a [`CampaignError`] is bad input when it says so, as is a model that cannot run as its study describes it
    /// (`CoreError::ModelInput`, `BasisError::ModelInput`); anything else is a failure; the
    /// message is the error's text followed by its sources'.
    pub fn from_error<E: StdError + 'static>(error: E) -> Self {
        let any: &dyn std::any::Any = &error;
        if let Some(study) = any.downcast_ref::<StudyError>() {
            return study.clone();
        }
        if let Some(iuq_core::CoreError::ModelInput(reason)) =
            any.downcast_ref::<iuq_core::CoreError>()
        {
            return Self::BadInput(reason.clone());
        }
        if let Some(iuq_basis::BasisError::ModelInput(reason)) =
            any.downcast_ref::<iuq_basis::BasisError>()
        {
            return Self::BadInput(reason.clone());
        }
        if let Some(study_file) = any.downcast_ref::<StudyFileError>() {
            return Self::BadInput(study_file.to_string());
        }
        if let Some(campaign) = any.downcast_ref::<CampaignError>() {
            if matches!(campaign, CampaignError::Interrupted) {
                return Self::Interrupted;
            }
            if campaign.is_bad_input() {
                return Self::BadInput(campaign.to_string());
            }
        }
        Self::Failure(chain_text(&error))
    }
}

/// The text of `error` followed by the texts of its sources, each after `: `.
fn chain_text(error: &dyn StdError) -> String {
    let mut text = error.to_string();
    let mut source = error.source();
    while let Some(cause) = source {
        text.push_str(": ");
        text.push_str(&cause.to_string());
        source = cause.source();
    }
    text
}

/// Build a bad-input error from its message (which names the file, key and reason).
pub fn input_error(message: impl Into<String>) -> StudyError {
    StudyError::BadInput(message.into())
}

macro_rules! failures_from {
    ($($error:ty),* $(,)?) => {
        $(
            impl From<$error> for StudyError {
                fn from(error: $error) -> Self {
                    Self::from_error(error)
                }
            }
        )*
    };
}

failures_from!(
    StudyFileError,
    CampaignError,
    iuq_core::CoreError,
    iuq_doe::DoeError,
    iuq_gp::GpError,
    iuq_adaptive::AdaptiveError,
    iuq_basis::BasisError,
    iuq_sensitivity::SensitivityError,
    iuq_report::ReportError,
    iuq_rbc::RbcError,
    iuq_umbridge::UmBridgeError,
    std::io::Error,
    serde_json::Error,
    csv::Error,
    toml::ser::Error,
);

/// Extension to mark any error as bad input with a context message, e.g.
/// `parse(text).bad_input(|| format!("{path}: ..."))`.
pub trait BadInput<T> {
    /// Turn the error into [`StudyError::BadInput`] with the message `context: error`.
    fn bad_input<F: FnOnce() -> String>(self, context: F) -> Result<T>;
}

impl<T, E: Display> BadInput<T> for std::result::Result<T, E> {
    fn bad_input<F: FnOnce() -> String>(self, context: F) -> Result<T> {
        self.map_err(|e| input_error(format!("{}: {e}", context())))
    }
}

/// Extension to put a context message in front of an error, keeping its kind: the message
/// becomes `context: error` (a [`StudyError`] stays bad input or a failure; any other error is
/// converted with [`StudyError::from_error`]).
pub trait Context<T> {
    /// Put `context` in front of the error's message.
    fn context<C: Display>(self, context: C) -> Result<T>;

    /// Put the context `f` makes in front of the error's message (`f` runs only on an error).
    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T>;
}

impl<T, E: StdError + 'static> Context<T> for std::result::Result<T, E> {
    fn context<C: Display>(self, context: C) -> Result<T> {
        self.map_err(|e| StudyError::from_error(e).context(context))
    }

    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T> {
        self.map_err(|e| StudyError::from_error(e).context(f()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Error)]
    #[error("outer")]
    struct Outer(#[source] std::io::Error);

    #[test]
    fn context_keeps_the_kind_and_reads_like_a_chain() {
        let bad: Result<()> = Err(input_error("study.toml: key `x`: no"));
        let e = bad.context("loading").unwrap_err();
        assert!(e.is_bad_input());
        assert_eq!(e.to_string(), "loading: study.toml: key `x`: no");
        let failed: std::result::Result<(), Outer> = Err(Outer(std::io::Error::other("disk full")));
        let e = failed.with_context(|| "writing").unwrap_err();
        assert!(!e.is_bad_input());
        assert_eq!(e.to_string(), "writing: outer: disk full");
        let campaign = StudyError::from(CampaignError::study("c.toml", "model", "missing"));
        assert!(campaign.is_bad_input());
        let study_file = StudyError::from(StudyFileError::key("c.toml", "model", "missing"));
        assert_eq!(study_file, campaign);
        assert_eq!(
            "no".parse::<f64>().bad_input(|| "--n".into()).unwrap_err(),
            input_error("--n: invalid float literal")
        );
    }
}
