//! Sobol' sensitivity indices (docs/methods.md §3): Saltelli/Jansen estimators on a Saltelli
//! design, bootstrap and replicate-scrambling confidence intervals, several outputs at once,
//! and explicit accounting of failed runs.
//!
//! - [`estimator`]: the point estimators on f_A, f_B, f_ABi;
//! - [`confidence`]: bootstrap and replicate intervals;
//! - [`analysis`]: a whole analysis of a [`iuq_core::Model`] over a parameter space.
//!
//! ```
//! use iuq_core::{ExpressionModel, Parameter, ParameterSpace, Prior};
//! use iuq_sensitivity::{SensitivityOptions, analyse};
//!
//! // y = x1 + 2·x2 with both inputs U(0, 1): Var = 1/12 + 4/12, so S1 = ST = (0.2, 0.8).
//! let space = ParameterSpace::new(vec![
//!     Parameter { name: "x1".into(), prior: Prior::Uniform(0.0, 1.0) },
//!     Parameter { name: "x2".into(), prior: Prior::Uniform(0.0, 1.0) },
//! ])?;
//! let model = ExpressionModel::new(space.names(), &[("y".into(), "x1 + 2*x2".into())])?;
//! let options = SensitivityOptions { base_points: 4096, ..Default::default() }.check()?;
//! let report = analyse(&model, &space, &options)?;
//! let y = &report.outputs[0];
//! for (s1, exact) in y.first_order.iter().zip([0.2, 0.8]) {
//!     assert!((s1 - exact).abs() < 0.03, "{s1} against {exact}");
//! }
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]
// No panic reachable from user input: a library reports every failure in its error type.
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

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
