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
//!
//! Besides its message, a bad input or a failure keeps the typed error it came from (a
//! [`StudyFileError`], a [`CampaignError`], an `iuq_gp::GpError`, a `std::io::Error`, ...) as its
//! [`source`](StdError::source), shared in an [`Arc`] so that the error stays [`Clone`]: a caller
//! can downcast it, and a context put in front of the message keeps it. The message already
//! holds the text of that source (and usually of the source's own sources), so a printer that
//! walks the chain of sources stops at a `StudyError`, as [`chain_message`] (the command line's
//! message) does; two errors are equal when their kinds and messages are.

use std::error::Error as StdError;
use std::fmt::{self, Display};
use std::sync::Arc;

use iuq_campaign::CampaignError;
use iuq_study_file::StudyFileError;

/// The typed error a [`StudyError`] came from (shared, so that the error stays [`Clone`]).
pub type Source = Arc<dyn StdError + Send + Sync + 'static>;

/// An error of a study: bad input or a failure of the work, with its whole message and the
/// error it came from.
#[derive(Debug, Clone)]
pub enum StudyError {
    /// Caused by the user's input; the message names the file (or flag), the key and the reason.
    BadInput(Detail),
    /// A failure of the work (a model, a file system, a numerical method).
    Failure(Detail),
    /// The pipeline was interrupted (its observer asked it to stop): the model runs finished so
    /// far are stored, and a rerun continues from them.
    Interrupted,
}

/// The whole message of a bad input or a failure, and the typed error it came from (if any).
#[derive(Debug, Clone)]
pub struct Detail {
    message: String,
    source: Option<Source>,
}

impl Detail {
    /// A message with no source.
    pub fn new(message: impl Into<String>) -> Self {
        Self {
            message: message.into(),
            source: None,
        }
    }

    /// The whole message.
    pub fn message(&self) -> &str {
        &self.message
    }

    /// The typed error this one came from, if any.
    pub fn source(&self) -> Option<&Source> {
        self.source.as_ref()
    }
}

impl Display for Detail {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl From<String> for Detail {
    fn from(message: String) -> Self {
        Self::new(message)
    }
}

impl From<&str> for Detail {
    fn from(message: &str) -> Self {
        Self::new(message)
    }
}

/// The message of [`StudyError::Interrupted`].
pub const INTERRUPTED: &str =
    "interrupted: the model runs finished so far are stored; run again to continue";

/// Result type of `iuq-study`.
pub type Result<T, E = StudyError> = std::result::Result<T, E>;

impl Display for StudyError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.message())
    }
}

impl StdError for StudyError {
    fn source(&self) -> Option<&(dyn StdError + 'static)> {
        match self {
            Self::BadInput(d) | Self::Failure(d) => {
                d.source.as_deref().map(|e| e as &(dyn StdError + 'static))
            }
            Self::Interrupted => None,
        }
    }
}

/// Equal kinds and messages (the sources are not compared).
impl PartialEq for StudyError {
    fn eq(&self, other: &Self) -> bool {
        std::mem::discriminant(self) == std::mem::discriminant(other)
            && self.message() == other.message()
    }
}

impl Eq for StudyError {}

impl StudyError {
    /// A bad-input error with this message (which names the file, key and reason) and no source.
    pub fn bad_input(message: impl Into<String>) -> Self {
        Self::BadInput(Detail::new(message))
    }

    /// A failure with this message and no source.
    pub fn failure(message: impl Into<String>) -> Self {
        Self::Failure(Detail::new(message))
    }

    /// True when the error is caused by the user's input (exit code 2 in the command line).
    pub fn is_bad_input(&self) -> bool {
        matches!(self, Self::BadInput(_))
    }

    /// The whole message.
    pub fn message(&self) -> &str {
        match self {
            Self::BadInput(d) | Self::Failure(d) => &d.message,
            Self::Interrupted => INTERRUPTED,
        }
    }

    /// The same error with its message rewritten by `f` (its kind and source kept;
    /// [`StudyError::Interrupted`] stays as it is).
    pub fn map_message(self, f: impl FnOnce(&str) -> String) -> Self {
        match self {
            Self::BadInput(d) => Self::BadInput(Detail {
                message: f(&d.message),
                source: d.source,
            }),
            Self::Failure(d) => Self::Failure(Detail {
                message: f(&d.message),
                source: d.source,
            }),
            Self::Interrupted => Self::Interrupted,
        }
    }

    /// The same kind of error with the message `context: message` (its source kept).
    pub fn context(self, context: impl Display) -> Self {
        self.map_message(|m| format!("{context}: {m}"))
    }

    /// The same error (kind and message) with `source` as the error it came from; the message
    /// should already hold the source's text. A [`StudyError`] given as the source passes on its
    /// own source instead, so the source of a `StudyError` is never another one.
    pub fn with_source<E: StdError + Send + Sync + 'static>(self, source: E) -> Self {
        let source = into_source(source);
        match self {
            Self::BadInput(d) => Self::BadInput(Detail { source, ..d }),
            Self::Failure(d) => Self::Failure(Detail { source, ..d }),
            Self::Interrupted => Self::Interrupted,
        }
    }

    /// Any error as a study error: a [`StudyError`] stays what it is, a [`StudyFileError`] is
    /// bad input, a [`CampaignError`] is bad input when it says so, as is a model that cannot run as its study describes it
    /// (`CoreError::ModelInput`, `BasisError::ModelInput`); anything else is a failure; the
    /// message is the error's text followed by its sources'. The error itself is kept as the
    /// [`source`](StdError::source) (except for [`StudyError::Interrupted`]).
    pub fn from_error<E: StdError + Send + Sync + 'static>(error: E) -> Self {
        let any: &dyn std::any::Any = &error;
        if let Some(study) = any.downcast_ref::<StudyError>() {
            return study.clone();
        }
        if let Some(iuq_core::CoreError::ModelInput(reason)) =
            any.downcast_ref::<iuq_core::CoreError>()
        {
            return Self::bad_input(reason.clone()).with_source(error);
        }
        if let Some(iuq_basis::BasisError::ModelInput(reason)) =
            any.downcast_ref::<iuq_basis::BasisError>()
        {
            return Self::bad_input(reason.clone()).with_source(error);
        }
        if let Some(study_file) = any.downcast_ref::<StudyFileError>() {
            return Self::bad_input(study_file.to_string()).with_source(error);
        }
        if let Some(campaign) = any.downcast_ref::<CampaignError>() {
            if matches!(campaign, CampaignError::Interrupted) {
                return Self::Interrupted;
            }
            if campaign.is_bad_input() {
                return Self::bad_input(campaign.to_string()).with_source(error);
            }
        }
        Self::failure(chain_message(&error)).with_source(error)
    }
}

/// `error` as the source of a [`StudyError`]: a `StudyError` passes on its own source.
fn into_source<E: StdError + Send + Sync + 'static>(error: E) -> Option<Source> {
    let any: &dyn std::any::Any = &error;
    match any.downcast_ref::<StudyError>() {
        Some(StudyError::BadInput(d) | StudyError::Failure(d)) => d.source.clone(),
        Some(StudyError::Interrupted) => None,
        None => Some(Arc::new(error)),
    }
}

/// The text of `error` followed by the texts of its sources, each after `: ` (as `anyhow`'s
/// `{:#}` prints an error), up to the first [`StudyError`]: its message already holds the texts
/// of its own sources, which are not repeated.
pub fn chain_message(error: &(dyn StdError + 'static)) -> String {
    let mut text = error.to_string();
    let mut next = error;
    while let Some(cause) = next.source() {
        if next.is::<StudyError>() {
            break;
        }
        text.push_str(": ");
        text.push_str(&cause.to_string());
        next = cause;
    }
    text
}

/// Build a bad-input error from its message (which names the file, key and reason).
pub fn input_error(message: impl Into<String>) -> StudyError {
    StudyError::bad_input(message)
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
    /// Turn the error into [`StudyError::BadInput`] with the message `context: error`, the
    /// error as its source.
    fn bad_input<F: FnOnce() -> String>(self, context: F) -> Result<T>;
}

impl<T, E: StdError + Send + Sync + 'static> BadInput<T> for std::result::Result<T, E> {
    fn bad_input<F: FnOnce() -> String>(self, context: F) -> Result<T> {
        self.map_err(|e| input_error(format!("{}: {e}", context())).with_source(e))
    }
}

/// Extension to put a context message in front of an error, keeping its kind and source: the
/// message becomes `context: error` (a [`StudyError`] stays bad input or a failure; any other
/// error is converted with [`StudyError::from_error`]).
pub trait Context<T> {
    /// Put `context` in front of the error's message.
    fn context<C: Display>(self, context: C) -> Result<T>;

    /// Put the context `f` makes in front of the error's message (`f` runs only on an error).
    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T>;
}

impl<T, E: StdError + Send + Sync + 'static> Context<T> for std::result::Result<T, E> {
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
    use thiserror::Error;

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

    #[test]
    fn a_study_file_error_is_kept_as_the_source() {
        let key = StudyFileError::key("study.toml", "model.timeout", "not a duration");
        let e = StudyError::from(key.clone());
        assert!(e.is_bad_input());
        assert_eq!(
            e.message(),
            "study.toml: key `model.timeout`: not a duration"
        );
        assert_eq!(e.to_string(), e.message());
        let source = e.source().expect("a source");
        assert_eq!(source.downcast_ref::<StudyFileError>(), Some(&key));
        // A context in front of the message keeps the source, and the kind.
        let r: std::result::Result<(), _> = Err(key.clone());
        let e = r.context("loading").unwrap_err();
        assert!(e.is_bad_input());
        assert_eq!(
            e.message(),
            "loading: study.toml: key `model.timeout`: not a duration"
        );
        assert_eq!(
            e.source().unwrap().downcast_ref::<StudyFileError>(),
            Some(&key)
        );
        let e = e
            .context("again")
            .map_message(|m| m.replace("again", "twice"));
        assert!(e.to_string().starts_with("twice: loading: study.toml"));
        assert!(e.source().unwrap().is::<StudyFileError>());
        // A clone shares the source; equality compares kind and message only.
        assert_eq!(e.clone(), e);
        assert!(e.clone().source().unwrap().is::<StudyFileError>());
        assert_eq!(e, input_error(e.message()));
        assert_ne!(e, StudyError::failure(e.message()));
    }

    #[test]
    fn a_campaign_error_is_kept_as_the_source() {
        // Bad input: the campaign's message, the campaign's error as the source.
        let e = StudyError::from(CampaignError::study("c.toml", "model", "missing"));
        assert!(e.is_bad_input());
        assert_eq!(e.message(), "c.toml: key `model`: missing");
        let campaign = e.source().unwrap().downcast_ref::<CampaignError>();
        assert!(
            matches!(campaign, Some(CampaignError::Study { key, .. }) if key == "model"),
            "{campaign:?}"
        );
        // A failure: the message is the chain of texts, as before (`CampaignError::Io` names
        // its source's text, and the chain adds it again); the source is the campaign's error,
        // whose own source is the I/O error.
        let io = CampaignError::io("runs/000001", std::io::Error::other("disk full"));
        let e = StudyError::from(io).context("the model runs");
        assert!(!e.is_bad_input());
        assert_eq!(
            e.message(),
            "the model runs: runs/000001: disk full: disk full"
        );
        let source = e.source().unwrap();
        assert!(matches!(
            source.downcast_ref::<CampaignError>(),
            Some(CampaignError::Io { .. })
        ));
        assert_eq!(
            source
                .source()
                .unwrap()
                .downcast_ref::<std::io::Error>()
                .unwrap()
                .to_string(),
            "disk full"
        );
        // An interrupted campaign is an interrupted study, as before.
        let e = StudyError::from(CampaignError::Interrupted);
        assert_eq!(e, StudyError::Interrupted);
        assert!(e.source().is_none());
    }

    #[test]
    fn sources_are_never_study_errors_and_are_printed_once() {
        // `bad_input` keeps the error it marks; a study error given as a source passes on its own.
        let e = "no".parse::<f64>().bad_input(|| "--n".into()).unwrap_err();
        assert!(e.source().unwrap().is::<std::num::ParseFloatError>());
        let inner = StudyError::from(StudyFileError::key("s.toml", "x", "no"));
        let outer = StudyError::failure(format!("round 1: {inner}")).with_source(inner);
        assert_eq!(outer.message(), "round 1: s.toml: key `x`: no");
        assert!(outer.source().unwrap().is::<StudyFileError>());
        let outer = StudyError::from_error(outer.clone().context("again"));
        assert_eq!(outer.message(), "again: round 1: s.toml: key `x`: no");
        assert!(outer.source().unwrap().is::<StudyFileError>());
        // The command line's message stops at a study error: its message holds its sources'.
        assert_eq!(chain_message(&outer), outer.message());
        #[derive(Debug, Error)]
        #[error("wrapped")]
        struct Wrapped(#[source] StudyError);
        assert_eq!(
            chain_message(&Wrapped(outer)),
            "wrapped: again: round 1: s.toml: key `x`: no"
        );
        assert_eq!(
            chain_message(&Outer(std::io::Error::other("disk full"))),
            "outer: disk full"
        );
    }
}
