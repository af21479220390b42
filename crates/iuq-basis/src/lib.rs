//! BASIS — Bayesian annealed sequential importance sampling (Wu et al. 2017, "A Bayesian
//! annealed sequential importance sampling: an unbiased version of transitional Markov chain
//! Monte Carlo", ASCE-ASME J. Risk Uncertainty Eng. Syst. B 4(1); Ching & Chen 2007,
//! "Transitional Markov chain Monte Carlo method for Bayesian model updating, model class
//! selection, and model averaging", J. Eng. Mech. 133(7)) for iuq.
//!
//! - [`likelihood`]: the batch [`LogLikelihood`] trait, a direct log-density expression
//!   ([`LogDensityLikelihood`]) and closures ([`FnLikelihood`]);
//! - [`prediction_error`]: the prediction-error likelihood of a [`iuq_core::Model`] against data,
//!   with measurement, computational and modelling error ([`PredictionErrorLikelihood`]);
//! - [`curve_model`]: a formula of the parameters and the data's abscissa as a model;
//! - [`annealing`], [`proposal`], [`resampling`]: the steps of a stage;
//! - [`sampler`]: the sampler ([`Basis`]), its state, observers and stop reasons;
//! - [`checkpoint`]: the state as self-describing JSON, for bit-identical resumption;
//! - [`summary`]: MAP, mean, std, quantiles and KDE marginals;
//! - [`pareto_smoothing`]: Pareto-smoothed importance sampling (k̂, smoothed weights, ESS);
//! - [`model_posterior`](mod@model_posterior): from a surrogate's posterior to the model's, by importance stages
//!   and delayed-acceptance moves, certified by k̂ and [`spread_ratio`]; [`pseudo_marginal`] for a noisy model, with
//!   [`moment_matching`]'s correction and its test, and [`defensive_normal`]'s (or [`defensive_tempering`]'s) batch where
//!   that correction cannot be made; [`member_selection`]: the members a batch
//!   runs, nested in the batch's size; [`paired_estimate`]: its moments paired with the
//!   surrogate population's, where it is one step from a uniform subset of it.
//!
//! ```
//! use iuq_basis::{Basis, BasisSettings, FnLikelihood, Silent};
//! use iuq_core::{Parameter, ParameterSpace, Prior};
//!
//! let space = ParameterSpace::new(vec![Parameter {
//!     name: "x".into(),
//!     prior: Prior::Uniform(-15.0, 15.0),
//! }])
//! .unwrap();
//! // ln N(x; −2, 3²)
//! let likelihood = FnLikelihood::new(1, |x: &[f64]| {
//!     -0.5 * ((x[0] + 2.0) / 3.0).powi(2) - (3.0 * (2.0 * std::f64::consts::PI).sqrt()).ln()
//! });
//! let settings = BasisSettings { samples: 1000, seed: 1, ..Default::default() }.check().unwrap();
//! let run = Basis::new(&space, &likelihood, settings).unwrap().run(&mut Silent).unwrap();
//! // exact ln Z = −ln 30 = −3.4012
//! assert!((run.state.log_evidence + 3.401205).abs() < 1.0);
//! ```
//! This crate does no file I/O: checkpoints are strings, and the binary writes them.

#![warn(missing_docs)]
// No panic reachable from user input: a library reports every failure in its error type.
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

pub mod ancestral_variance;
pub mod annealing;
pub mod batch_mixture;
pub mod carried_population;
pub mod checkpoint;
pub mod curve_model;
pub mod defensive_normal;
pub mod defensive_tempering;
pub mod diagnostics;
pub mod error;
pub mod gaussian_screen;
pub mod heavy_tail_errors;
mod json_numbers;
pub mod likelihood;
pub mod member_selection;
pub mod model_posterior;
pub mod moment_matching;
mod moves;
pub mod paired_estimate;
pub mod pareto_smoothing;
pub mod prediction_error;
pub mod proposal;
pub mod pseudo_marginal;
pub mod quadratic_regression;
pub mod resampling;
pub mod sampler;
pub mod settings;
pub mod spread_ratio;
pub mod summary;

pub use ancestral_variance::{AncestralErrors, ancestral_errors};
pub use curve_model::CurveModel;
pub use diagnostics::StageDiagnostics;
pub use error::{BasisError, Result};
pub use likelihood::{FnLikelihood, LogDensityLikelihood, LogLikelihood, PointLogLikelihood};
pub use model_posterior::{
    ModelPosterior, ModelPosteriorEvent, ModelPosteriorSettings, ModelPosteriorStage,
    ModelPosteriorStop, SurrogatePopulation, Tempering, model_posterior, resume_model_posterior,
    selected_members,
};
pub use moment_matching::{GaussianLogRatio, ProposalMismatch, proposal_mismatch};
pub use pareto_smoothing::{
    ParetoSmoothing, normalised_weights, pareto_k_threshold, pareto_smooth,
};
pub use prediction_error::{
    ComputationalError, DEFAULT_MODELLING_ERROR_PRIOR, ErrorModel, MODELLING_ERROR_NAME,
    Observations, PredictionErrorLikelihood,
};
pub use proposal::{CovarianceFactor, Proposal};
pub use sampler::{Basis, BasisRun, BasisState, Control, Observer, Silent, StopReason};
pub use settings::{
    BasisSettings, CheckedSettings, MAX_MIXING_LEVEL, MAX_STEPS, MinStepAction, Mixing, Resampling,
};
pub use summary::{
    Marginal1d, Marginal2d, PosteriorSummary, marginal_1d, marginal_2d, marginal_range,
};
