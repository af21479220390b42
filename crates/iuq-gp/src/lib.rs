//! Gaussian-process regression for iuq (docs/methods.md §2): the surrogate that stands in for an
//! expensive model.
//!
//! - [`Kernel`]: k(x, x') = c·exp(−½‖(x − x')/l‖²) + σ²δ(x, x'), ARD or isotropic length
//!   scales, c and σ² estimated or fixed; hyper-parameters θ = (ln c, ln l…, ln σ²).
//! - [`log_marginal_likelihood()`]: LML = −½yᵀα − Σ ln L_ii − (n/2) ln 2π and its analytic
//!   gradient ½ tr((ααᵀ − K⁻¹)∂K/∂θ), O(n³) + O(n²d).
//! - [`fit()`] / [`GaussianProcess::fit`]: multi-start bounded quasi-Newton maximisation of the
//!   LML on unit-cube inputs and standardised outputs ([`FitOptions`], [`Bounds`]), screened
//!   on a subset for large n ([`screening`]), with [`FitDiagnostics`] flagging degenerate
//!   optima.
//! - [`GaussianProcess::predict`]: blocked, parallel posterior mean and variance (latent and
//!   with noise) in original units.
//! - [`q2()`], [`GaussianProcess::loo_q2`]: test-set and closed-form leave-one-out Q2.
//! - [`GaussianProcess::to_json_string`] / [`GaussianProcess::from_json_str`]: persistence.
//! - [`GpBank`]: one GP per output, an [`iuq_core::Model`].
//! - [`ReducedBasis`]: GPs on the leading principal components of a curve-valued model's runs
//!   (Higdon et al. 2008), with the truncation error as variance; an [`iuq_core::Model`].
//! - [`GaussianProcess::posterior_covariance`]: cov[f(a), f(b) | data], for sequential designs.
//! - [`MultiFidelityGp`]: an expensive model's output as ρ·(a cheap model's) + a GP discrepancy
//!   (recursive co-kriging), used only where it predicts the expensive runs better.
//! - [`MultiFidelityBank`]: one [`MultiFidelityGp`] per output, an [`iuq_core::Model`].
//! - [`fit_shared_discrepancy`]: the data points of a model run once per data point, their
//!   discrepancies one GP in (θ, abscissa) (`shared_discrepancy`).
//! - [`FailureClassifier`]: GP classification (Laplace) of where the model fails.
//!
//! The crate does no I/O.
//!
//! ```
//! use iuq_gp::{FitOptions, GaussianProcess};
//!
//! // A GP of sin(x) from 12 runs, checked between them.
//! let x: Vec<Vec<f64>> = (0..12).map(|i| vec![i as f64 * 0.5]).collect();
//! let y: Vec<f64> = x.iter().map(|p| p[0].sin()).collect();
//! let gp = GaussianProcess::fit(&x, &y, &FitOptions::default().check()?)?;
//! let at = vec![vec![1.25], vec![3.75]];
//! let prediction = gp.predict(&at)?;
//! for (p, m) in at.iter().zip(&prediction.mean) {
//!     assert!((m - p[0].sin()).abs() < 0.02, "{m} against {}", p[0].sin());
//! }
//! # Ok::<(), iuq_gp::GpError>(())
//! ```

#![warn(missing_docs)]
// No panic reachable from user input: a library reports every failure in its error type.
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

pub mod bank;
pub mod bounds;
pub mod classification;
pub mod component_gp;
mod data;
pub mod diagnostics;
pub mod error;
pub mod fit;
mod forward_substitution;
pub mod gaussian_process;
pub mod kernel;
pub mod log_marginal_likelihood;
pub mod mean_gradient;
pub mod multi_fidelity;
pub mod multi_fidelity_bank;
mod multi_start;
pub mod optimizer;
pub mod output_predictor;
pub mod persistence;
mod posterior_covariance;
pub mod prediction;
pub mod reduced_basis;
pub mod reduced_basis_output;
pub mod scaling;
pub mod screening;
pub mod shared_discrepancy;
#[cfg(test)]
mod test_data;
pub mod validation;
mod vector_math;

pub use bank::{BANK_FORMAT, BANK_FORMAT_VERSION, GpBank, PredictiveStd};
pub use bounds::Bounds;
pub use classification::{CheckedClassifierOptions, ClassifierOptions, FailureClassifier};
pub use component_gp::ComponentGp;
pub use diagnostics::{FitDiagnostics, FitWarning, RunReport, StartReport};
pub use error::{GpError, Result};
pub use fit::{CheckedFitOptions, FitOptions, MAX_RESTARTS, fit, fit_warm};
pub use gaussian_process::GaussianProcess;
pub use kernel::{Hyperparameters, Kernel, LengthScales, Variance};
pub use log_marginal_likelihood::{LogMarginalLikelihood, log_marginal_likelihood};
pub use multi_fidelity::{MultiFidelityGp, SharedPoint};
pub use multi_fidelity_bank::MultiFidelityBank;
pub use optimizer::{
    Minimum, Objective, OptimizerOptions, Termination, minimize_bounded, minimize_bounded_objective,
};
pub use output_predictor::{OutputPredictor, SharedComponents};
pub use prediction::Prediction;
pub use reduced_basis::{ReducedBasis, ReducedBasisOptions};
pub use reduced_basis_output::ReducedBasisOutput;
pub use scaling::{InputScaling, OutputScaling};
pub use shared_discrepancy::{PointRuns, fit_shared_discrepancy, fit_shared_discrepancy_with};
pub use validation::{LeaveOneOut, q2};
