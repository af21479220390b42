//! The error type of `iuq-campaign`.
//!
//! Failures of one model run are never errors: they are [`RunResult`](crate::RunResult)s
//! recorded in the store and handed to the caller as failures. An error is a problem with the
//! user's input ([`CampaignError::Study`], exit code 2 in the CLI) or with the campaign as a whole
//! (the store, the file system, the scheduler).

use std::path::PathBuf;

use iuq_study_file::StudyFileError;
use thiserror::Error;

/// Errors of campaigns: bad study files, and failures of the store, file system or scheduler.
#[derive(Debug, Error)]
pub enum CampaignError {
    /// A study file, or a file it names, that cannot be used: the message names the file, the key
    /// and the reason.
    #[error("{file}: key `{key}`: {reason}")]
    Study {
        /// The study file (or template) in question.
        file: String,
        /// The key, e.g. `model.output.file`.
        key: String,
        /// Why it cannot be used.
        reason: String,
    },
    /// Bad input that is not part of a study file (a command-line flag, a campaign directory).
    #[error("{0}")]
    BadInput(String),
    /// The campaign store could not be read or written. A file that is not an SQLite database,
    /// or a damaged one, is bad input ([`store_file_unusable`]); any other SQLite error (a full
    /// disk, a lock held too long) is a failure of the campaign.
    #[error("campaign store {path}: {}", store_reason(source))]
    Store {
        /// The database file.
        path: PathBuf,
        /// The SQLite error.
        #[source]
        source: rusqlite::Error,
    },
    /// A file or directory could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The scheduler (Slurm, HyperQueue) or the executor failed as a whole.
    #[error("{executor} executor: {reason}")]
    Executor {
        /// `local`, `slurm` or `hyperqueue`.
        executor: &'static str,
        /// What went wrong.
        reason: String,
    },
    /// The campaign was interrupted ([`crate::Interrupt`]): finished runs are stored, the
    /// rest stay pending and run when the campaign is resumed.
    #[error("interrupted: the runs finished so far are stored; run again to continue")]
    Interrupted,
    /// A file written by a worker or a scheduler that cannot be parsed.
    #[error("{path}: {reason}")]
    Format {
        /// The file (or command) whose output is malformed.
        path: String,
        /// What is wrong with it.
        reason: String,
    },
}

impl CampaignError {
    /// True when the error is caused by the user's input (a study file, a flag): exit code 2.
    pub fn is_bad_input(&self) -> bool {
        match self {
            Self::Study { .. } | Self::BadInput(_) => true,
            Self::Store { source, .. } => store_file_unusable(source),
            _ => false,
        }
    }

    /// A study-file error naming `file`, `key` and `reason`.
    pub fn study(
        file: impl Into<String>,
        key: impl Into<String>,
        reason: impl Into<String>,
    ) -> Self {
        Self::Study {
            file: file.into(),
            key: key.into(),
            reason: reason.into(),
        }
    }

    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }

    /// An executor failure.
    pub fn executor(executor: &'static str, reason: impl Into<String>) -> Self {
        Self::Executor {
            executor,
            reason: reason.into(),
        }
    }
}

/// True when SQLite says the file itself cannot be a campaign store: not a database at all
/// (`SQLITE_NOTADB`) or a damaged one (`SQLITE_CORRUPT`). Such a file is something the user
/// pointed the study at, not a failure of the work, so the CLI exits 2 for it.
pub fn store_file_unusable(error: &rusqlite::Error) -> bool {
    matches!(
        error.sqlite_error_code(),
        Some(rusqlite::ErrorCode::NotADatabase | rusqlite::ErrorCode::DatabaseCorrupt)
    )
}

/// The reason in a store error's message: what an unusable file is and what to do about it, else
/// SQLite's own text.
fn store_reason(error: &rusqlite::Error) -> String {
    match error.sqlite_error_code() {
        Some(rusqlite::ErrorCode::NotADatabase) => "not a campaign store: the file is not an \
            SQLite database (move it aside, or point `executor.directory` elsewhere)"
            .to_string(),
        Some(rusqlite::ErrorCode::DatabaseCorrupt) => "the campaign store is damaged (SQLite \
            reports it corrupt; restore it from a copy, or move it aside to start afresh)"
            .to_string(),
        _ => error.to_string(),
    }
}

/// A study-file error of the section reader is a [`CampaignError::Study`] with the same file,
/// key and reason (and so the same message).
impl From<StudyFileError> for CampaignError {
    fn from(error: StudyFileError) -> Self {
        match error {
            StudyFileError::Key { file, key, reason } => Self::Study { file, key, reason },
        }
    }
}

/// Result type of `iuq-campaign`.
pub type Result<T, E = CampaignError> = std::result::Result<T, E>;
