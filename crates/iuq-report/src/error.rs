//! The error type of `iuq-report`.

use std::path::PathBuf;

use thiserror::Error;

/// Errors of writing a report: invalid input, a figure that could not be drawn, or a file that
/// could not be written.
#[derive(Debug, Error)]
pub enum ReportError {
    /// The report's data are inconsistent (mismatched lengths, empty samples, non-finite values
    /// where a figure needs finite ones); `field` names the offending part of the report.
    #[error("invalid report input at `{field}`: {reason}")]
    InvalidInput {
        /// Path of the offending field, e.g. `posteriors[1].samples[3][0]`.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A figure could not be drawn (a plotting back-end error).
    #[error("figure `{figure}` could not be drawn: {reason}")]
    Drawing {
        /// The figure's file stem.
        figure: String,
        /// The back-end's message.
        reason: String,
    },
    /// The embedded font could not be loaded for PNG text.
    #[error("the embedded font could not be loaded")]
    Font,
    /// A file or directory could not be created, written or renamed.
    #[error("cannot write `{path}`: {source}")]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// The underlying I/O error.
        #[source]
        source: std::io::Error,
    },
    /// A table could not be encoded as CSV.
    #[error("cannot encode table `{table}` as CSV: {source}")]
    Csv {
        /// The table's file stem.
        table: String,
        /// The CSV writer's error.
        #[source]
        source: csv::Error,
    },
    /// A value could not be encoded as JSON.
    #[error("cannot encode `{what}` as JSON: {source}")]
    Json {
        /// What was being encoded.
        what: String,
        /// The JSON encoder's error.
        #[source]
        source: serde_json::Error,
    },
}

impl ReportError {
    /// An [`ReportError::InvalidInput`] for `field`.
    pub(crate) fn invalid(field: impl Into<String>, reason: impl Into<String>) -> Self {
        Self::InvalidInput {
            field: field.into(),
            reason: reason.into(),
        }
    }

    /// A [`ReportError::Drawing`] for `figure` from any back-end error.
    pub(crate) fn drawing(figure: &str, error: impl std::fmt::Display) -> Self {
        Self::Drawing {
            figure: figure.to_string(),
            reason: error.to_string(),
        }
    }
}

/// Result type of `iuq-report`.
pub type Result<T, E = ReportError> = std::result::Result<T, E>;
