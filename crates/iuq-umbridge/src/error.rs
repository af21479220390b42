//! The error type of `iuq-umbridge`.

use thiserror::Error;

/// Errors of the UM-Bridge client and server.
///
/// A failed model run at one point is not an error of this type: the client reports it as a
/// per-point [`iuq_core::EvaluationFailure`] and the server answers it with a 500 error object.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum UmBridgeError {
    /// A server URL this client cannot use (not `http://host[:port]`).
    #[error("UM-Bridge URL `{url}`: {reason}")]
    InvalidUrl {
        /// The URL as given.
        url: String,
        /// Why it cannot be used.
        reason: String,
    },
    /// Options that make no client or server (zero concurrency, zero parallel evaluations…).
    #[error("invalid UM-Bridge option: {0}")]
    InvalidOptions(String),
    /// The server could not be reached, or the connection kept failing, after every retry.
    #[error("UM-Bridge server {url} unreachable after {attempts} attempt(s): {reason}")]
    Unreachable {
        /// The server's URL.
        url: String,
        /// Attempts made (1 + retries).
        attempts: u32,
        /// The last transport error.
        reason: String,
    },
    /// The server speaks a protocol version other than 1.0.
    #[error(
        "UM-Bridge server {url} speaks protocol version {found}; this client supports protocol version 1.0 only"
    )]
    UnsupportedProtocolVersion {
        /// The server's URL.
        url: String,
        /// The `protocolVersion` the server answered (`none` when absent).
        found: String,
    },
    /// The server serves no model of that name.
    #[error("UM-Bridge server {url} has no model `{name}` (it serves: {available:?})")]
    ModelNotFound {
        /// The server's URL.
        url: String,
        /// The requested name.
        name: String,
        /// The names the server listed.
        available: Vec<String>,
    },
    /// The model does not support a feature the caller needs (`Evaluate`, `Gradient`…).
    #[error("UM-Bridge model `{name}` does not support {feature}")]
    UnsupportedFeature {
        /// The model's name.
        name: String,
        /// The feature.
        feature: String,
    },
    /// Sizes that do not fit together (the study's parameters vs. the model's input sizes,
    /// output names vs. output sizes, a vector of the wrong length).
    #[error("UM-Bridge model `{name}`: {reason}")]
    SizeMismatch {
        /// The model's name.
        name: String,
        /// What does not fit.
        reason: String,
    },
    /// The server answered a request with an error (status and error object).
    #[error("UM-Bridge server answered {endpoint} with HTTP {status}, {error_type}: {message}")]
    Server {
        /// The endpoint requested.
        endpoint: String,
        /// The HTTP status.
        status: u16,
        /// The error object's type (`HTTP` when the body was not an error object).
        error_type: String,
        /// The error object's message (or the start of the body).
        message: String,
    },
    /// The server answered with something that is not a valid protocol answer.
    #[error("UM-Bridge server answered {endpoint} with an invalid body: {reason}")]
    InvalidResponse {
        /// The endpoint requested.
        endpoint: String,
        /// What is wrong with the answer.
        reason: String,
    },
    /// The server could not listen or stopped accepting connections.
    #[error("UM-Bridge server on {address}: {reason}")]
    Listen {
        /// The address it tried to listen on.
        address: String,
        /// The I/O error.
        reason: String,
    },
}

impl UmBridgeError {
    /// True when the error comes from what the user asked for (a bad URL or option, a model
    /// name the server lacks, sizes that do not fit the study, a server of another protocol
    /// version) rather than from a failure of the work (an unreachable server, a broken answer).
    pub fn is_bad_input(&self) -> bool {
        matches!(
            self,
            Self::InvalidUrl { .. }
                | Self::InvalidOptions(_)
                | Self::UnsupportedProtocolVersion { .. }
                | Self::ModelNotFound { .. }
                | Self::UnsupportedFeature { .. }
                | Self::SizeMismatch { .. }
        )
    }
}

/// Result type of `iuq-umbridge`.
pub type Result<T, E = UmBridgeError> = std::result::Result<T, E>;
