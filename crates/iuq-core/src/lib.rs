//! Core types of iuq: parameter spaces and priors, the batch [`Model`] trait with per-point
//! failures, analytic expression models, random streams keyed by `(seed, stage, index)`,
//! weighted statistics and Gaussian kernel density estimation.
//!
//! This crate does no I/O: every stage of the data flow builds on it.

pub mod error;
pub mod model;
pub mod random;

pub use error::{CoreError, Result};
pub use model::{Evaluation, EvaluationFailure, Model, Outcome};
