//! The crate's error type, [`StudyFileError`].

use thiserror::Error;

/// A study file, or a key in it, that cannot be used: the message names the file, the whole key
/// and the reason.
///
/// Every such error is caused by the user's input; the crates that read study files turn it into
/// their own bad-input error (exit code 2 in the command line), keeping the message as it is.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum StudyFileError {
    /// A key of the study file (or the section as a whole) with a value that cannot be used.
    #[error("{file}: key `{key}`: {reason}")]
    Key {
        /// The study file.
        file: String,
        /// The whole key, e.g. `surrogate.adaptive.batch`.
        key: String,
        /// Why it cannot be used.
        reason: String,
    },
}

impl StudyFileError {
    /// An error about `key` of `file`, for `reason`.
    pub fn key(file: impl Into<String>, key: impl Into<String>, reason: impl Into<String>) -> Self {
        Self::Key {
            file: file.into(),
            key: key.into(),
            reason: reason.into(),
        }
    }
}

/// Result type of `iuq-study-file`.
pub type Result<T, E = StudyFileError> = std::result::Result<T, E>;
