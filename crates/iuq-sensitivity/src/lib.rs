//! Sobol' sensitivity indices (docs/methods.md §3): Saltelli/Jansen estimators on a Saltelli
//! design, bootstrap and replicate-scrambling confidence intervals, several outputs at once,
//! and explicit accounting of failed runs.
//!
//! - [`estimator`]: the point estimators on f_A, f_B, f_ABi;
//! - [`confidence`]: bootstrap and replicate intervals;
//! - [`analysis`]: a whole analysis of a [`iuq_core::Model`] over a parameter space.

#![warn(missing_docs)]

pub mod analysis;
pub mod confidence;
pub mod error;
pub mod estimator;

pub use analysis::{
    CheckedSensitivityOptions, IntervalMethod, OutputIndices, SensitivityOptions,
    SensitivityReport, analyse,
};
pub use error::{Result, SensitivityError};
pub use estimator::{SaltelliValues, SobolEstimate, estimate_indices};
