//! Core types of iuq: parameter spaces and priors, the batch [`Model`] trait with per-point
//! failures, analytic expression models, random streams keyed by `(seed, stage, index)`,
//! weighted statistics and Gaussian kernel density estimation.
//!
//! This crate does no I/O: every stage of the data flow builds on it.
//!
//! ```
//! use iuq_core::{Parameter, ParameterSpace, Prior};
//!
//! let space = ParameterSpace::new(vec![
//!     Parameter { name: "k".into(), prior: Prior::Uniform(0.05, 0.8) },
//!     Parameter { name: "T0".into(), prior: Prior::Normal(80.0, 10.0) },
//! ])?;
//! assert_eq!(space.names(), ["k", "T0"]);
//! // ln π(θ) = ln(1/0.75) + ln N(90 | 80, 10²).
//! let expected = -(0.75f64).ln() - 0.5 * (2.0 * std::f64::consts::PI * 100.0).ln() - 0.5;
//! assert!((space.log_prior(&[0.3, 90.0])? - expected).abs() < 1e-12);
//! # Ok::<(), iuq_core::CoreError>(())
//! ```

#![warn(missing_docs)]
// No panic reachable from user input: a library reports every failure in its error type.
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

pub mod affine_screen;
pub mod error;
pub mod evaluation_failure;
pub mod model;
pub mod random;

pub use error::{CoreError, Result};
pub use model::{Evaluation, EvaluationFailure, Model, Outcome};
pub mod exponential;
pub mod expression;
pub mod kde;
pub mod normal;
pub mod observer;
pub mod parameter_space;
pub mod prior;
pub mod weighted_statistics;

pub use expression::{Expression, ExpressionModel};
pub use kde::GaussianKde;
pub use observer::{Control, Observer};
pub use parameter_space::{Parameter, ParameterSpace};
pub use prior::Prior;
