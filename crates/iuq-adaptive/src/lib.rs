//! Sequential design for calibration: where to run an expensive model next so that a
//! surrogate-based posterior converges with few runs, and when to stop.
//!
//! One round of the adaptive engine ([`engine`]: its state and step; the study layer in
//! `iuq-study` drives it, owning the model runs, the campaign and the files): fit the surrogates
//! (one GP per data point, and where runs fail a [`iuq_gp::FailureClassifier`]), sample the
//! posterior on them, then
//!
//! 1. score candidate parameter vectors — the distinct posterior samples, so that runs go where
//!    the posterior lies — by how uncertain the surrogate leaves the posterior density there
//!    ([`acquisition`]: the variance of the Gaussian log-likelihood under the GP, times the
//!    squared relative density and the probability that the model answers there);
//! 2. share the round's runs among the run groups by each group's part of the surrogate error
//!    ([`allocation`]) and pick each group's batch greedily, conditioning the GPs on every pick before the next one
//!    ("kriging believer"), so that a batch spreads out instead of piling up ([`batch`]);
//! 3. stop when the posterior has stopped moving and the surrogate's uncertainty could not move
//!    it either ([`convergence`], [`moment_error`]), and report how much
//!    posterior mass lies far from every run ([`extrapolation`]).
//!
//! | module | what |
//! |---|---|
//! | [`acquisition`] | the log-likelihood variance Var_f[ln N(y | f, s²)] of a GP prediction |
//! | [`allocation`] | how many runs each run group gets in a round, by its part of ε |
//! | [`batch`] | greedy batch selection with kriging-believer variance updates |
//! | [`moment_acquisition`] | the batch that most shrinks the first-order error of the posterior moments |
//! | [`engine`] | the loop's state and step: judge a round, decide the next (argmin's shape) |
//! | [`convergence`] | the stopping rule: posterior shift beyond the sampler's noise, surrogate error |
//! | [`mod@posterior_distance`] | the sliced Wasserstein distance between two rounds' posteriors, beyond noise |
//! | [`moment_error`] | the error ε of the posterior moments under the GPs' error |
//! | [`mod@sampler_agreement`] | whether the posterior depends on how it was sampled (replicates with stronger mixing) |
//! | [`extrapolation`] | the share of posterior samples far from every run, in length scales |
//! | [`error`] | the crate's error type [`AdaptiveError`] |
//!
//! The crate does no I/O.
//!
//! ```
//! use iuq_adaptive::posterior_distance;
//!
//! // Two rounds' posteriors, two replicates each: the second moved by half a std in x.
//! let round = |shift: f64| -> Vec<Vec<Vec<f64>>> {
//!     (0..2)
//!         .map(|r| (0..400).map(|i| {
//!             let u = (i as f64 + 0.5 + 0.25 * r as f64) / 400.0;
//!             vec![(u - 0.5) * 3.46 + shift, ((7.0 * u) % 1.0 - 0.5) * 3.46]
//!         }).collect())
//!         .collect()
//! };
//! let same = posterior_distance(&round(0.0), &round(0.0))?;
//! assert_eq!(same.distance, 0.0);
//! let moved = posterior_distance(&round(0.0), &round(0.5))?;
//! assert!(moved.distance > 0.3, "{moved:?}");
//! # Ok::<(), iuq_adaptive::AdaptiveError>(())
//! ```

#![warn(missing_docs)]
// No panic reachable from user input: a library reports every failure in its error type.
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

pub mod acquisition;
pub mod allocation;
pub mod batch;
pub mod convergence;
pub mod engine;
pub mod error;
pub mod extrapolation;
pub mod moment_acquisition;
pub mod moment_error;
pub mod posterior_distance;
pub mod sampler_agreement;

pub use acquisition::{likelihood_weights, log_likelihood_variance};
pub use allocation::group_batches;
pub use batch::{LikelihoodTerm, Selection, select_batch};
pub use convergence::{
    ConvergenceCriterion, NOISE_MULTIPLE, PosteriorMoments, RoundAssessment,
    surrogate_log_likelihood_std,
};
pub use engine::{
    AdaptiveEngine, EngineSettings, EngineState, Judgement, MoreSamples, Next, RoundEvent,
    RoundReading, RoundSampling, StoppingRule,
};
pub use error::{AdaptiveError, Result};
pub use extrapolation::{extrapolation_share, nearest_run_distance};
pub use moment_acquisition::{
    SensitivityTerm, select_batch_for_moments, select_batch_for_moments_by_sensitivity,
};
pub use moment_error::{
    ComponentErrors, MomentError, MomentTerm, linearised_moment_error, sampled_moment_error,
    sampled_moment_errors_by_group, sampled_moment_errors_by_group_from_components,
};
pub use posterior_distance::{PosteriorDistance, posterior_distance};
pub use sampler_agreement::{SamplerAgreement, sampler_agreement};
