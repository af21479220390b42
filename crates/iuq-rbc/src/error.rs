//! The error type of `iuq-rbc`.
//!
//! Two families: bad input ([`RbcError::InvalidParameter`], [`RbcError::InvalidData`]), which a
//! command line reports as exit code 2, and failures of a simulation
//! ([`RbcError::MeshBroken`], [`RbcError::NonFinite`], [`RbcError::NoEllipse`],
//! [`RbcError::CellLeftDomain`]), which a model reports as a per-point failure with this reason.

use thiserror::Error;

/// Errors of the RBC simulator.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum RbcError {
    /// A parameter or setting outside the range the simulator accepts.
    #[error("invalid value {value} for `{name}`: {reason}")]
    InvalidParameter {
        /// The parameter's name as the user wrote it (e.g. `kLink`, `--stress`).
        name: String,
        /// The offending value.
        value: f64,
        /// Why it is rejected.
        reason: String,
    },
    /// A data table (e.g. the ektacytometry CSV) that cannot be read.
    #[error("invalid data: {0}")]
    InvalidData(String),
    /// The membrane passed a singularity of its force laws (edge strain |ε| ≥ 3, triangle area
    /// change |α| ≥ 0.3, volume change |ν| ≥ 0.1 or bending deviation |δ| ≥ √0.055) under
    /// [`crate::PastSingularity::Fail`].
    #[error("mesh broke at step {step}: {reason}")]
    MeshBroken {
        /// The time step at which the breakage was detected.
        step: u64,
        /// Which force law and where.
        reason: String,
    },
    /// A vertex position, force or velocity became NaN or infinite.
    #[error("non-finite {what} at step {step}")]
    NonFinite {
        /// The time step.
        step: u64,
        /// What became non-finite.
        what: String,
    },
    /// The cell left the channel between the walls.
    #[error("the cell left the channel at step {step}: {reason}")]
    CellLeftDomain {
        /// The time step.
        step: u64,
        /// Which vertex and where.
        reason: String,
    },
    /// The contour of a recorded shape admits no ellipse (too few points, or the direct least
    /// squares conic is not an ellipse).
    #[error("no ellipse fits the cell contour: {0}")]
    NoEllipse(String),
}

impl RbcError {
    /// True for errors caused by the caller's input rather than by the simulation.
    pub fn is_input_error(&self) -> bool {
        matches!(self, Self::InvalidParameter { .. } | Self::InvalidData(_))
    }

    /// Shorthand for [`RbcError::InvalidParameter`].
    pub fn invalid(name: &str, value: f64, reason: impl Into<String>) -> Self {
        Self::InvalidParameter {
            name: name.to_string(),
            value,
            reason: reason.into(),
        }
    }
}

/// Result type of `iuq-rbc`.
pub type Result<T, E = RbcError> = std::result::Result<T, E>;
