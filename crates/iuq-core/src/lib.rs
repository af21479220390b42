//! Core types of iuq: parameter spaces and priors, the batch [`Model`] trait with per-point
//! failures, analytic expression models, random streams keyed by `(seed, stage, index)`,
//! weighted statistics and Gaussian kernel density estimation.
//!
//! This crate does no I/O: every stage of the data flow builds on it.

#![warn(missing_docs)]

pub mod error;
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
