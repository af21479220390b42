//! The emulator of one reduced-basis component: a GP on the expensive model's runs, or a
//! two-fidelity GP ([`MultiFidelityGp`]) where a cheap model's runs help.
//!
//! A [`crate::ReducedBasis`] predicts each component's coefficient c_k(θ) and combines them
//! linearly; all it needs of a component is its prediction, mean, posterior covariance and the
//! noise variance a new expensive run carries. Both kinds provide them, so every consumer of the
//! basis (the likelihood, the delayed-acceptance screen, the adaptive engine's batch and
//! surrogate error) works on either without knowing which.
//!
//! ```
//! use iuq_gp::{ComponentGp, FitOptions, GaussianProcess};
//!
//! let x: Vec<Vec<f64>> = (0..8).map(|i| vec![i as f64 / 7.0]).collect();
//! let y: Vec<f64> = x.iter().map(|p| (3.0 * p[0]).sin()).collect();
//! let gp = GaussianProcess::fit(&x, &y, &FitOptions::default().check()?)?;
//! let component = ComponentGp::Single(Box::new(gp.clone()));
//! let at = vec![vec![0.3]];
//! assert_eq!(component.predict_mean(&at)?, gp.predict_mean(&at)?);
//! assert!(component.two_fidelity().is_none());
//! # Ok::<(), iuq_gp::GpError>(())
//! ```

use crate::error::Result;
use crate::gaussian_process::GaussianProcess;
use crate::multi_fidelity::MultiFidelityGp;
use crate::prediction::Prediction;

/// One component's emulator (module docs).
#[derive(Debug, Clone)]
pub enum ComponentGp {
    /// A GP on the expensive model's runs.
    Single(Box<GaussianProcess>),
    /// ρ_k·(the cheap runs' GP) + a GP discrepancy, on the coefficients of both fidelities' runs.
    TwoFidelity(Box<MultiFidelityGp>),
}

impl ComponentGp {
    /// The prediction at `points`: mean, latent variance and a new expensive run's noise.
    ///
    /// # Errors
    /// A point of the wrong dimension or with a non-finite coordinate.
    pub fn predict(&self, points: &[Vec<f64>]) -> Result<Prediction> {
        match self {
            ComponentGp::Single(gp) => gp.predict(points),
            ComponentGp::TwoFidelity(gp) => gp.predict(points),
        }
    }

    /// The predictive mean at `points` alone (no variance computed).
    ///
    /// # Errors
    /// A point of the wrong dimension or with a non-finite coordinate.
    pub fn predict_mean(&self, points: &[Vec<f64>]) -> Result<Vec<f64>> {
        match self {
            ComponentGp::Single(gp) => gp.predict_mean(points),
            ComponentGp::TwoFidelity(gp) => gp.predict_mean(points),
        }
    }

    /// The latent posterior covariance between the points `a` and `b`.
    ///
    /// # Errors
    /// A point of the wrong dimension or with a non-finite coordinate.
    pub fn posterior_covariance(&self, a: &[Vec<f64>], b: &[Vec<f64>]) -> Result<Vec<Vec<f64>>> {
        match self {
            ComponentGp::Single(gp) => gp.posterior_covariance(a, b),
            ComponentGp::TwoFidelity(gp) => gp.posterior_covariance(a, b),
        }
    }

    /// The GP fitted to the expensive runs' coefficients: the component's own, or of a
    /// two-fidelity component the discrepancy δ where the cheap model is used, else the GP of
    /// the expensive runs alone. Its noise and jitter are those of a new expensive run.
    pub fn in_charge(&self) -> &GaussianProcess {
        match self {
            ComponentGp::Single(gp) => gp,
            ComponentGp::TwoFidelity(gp) => gp.in_charge(),
        }
    }

    /// s²·σ²_n: the noise variance of a new expensive run's coefficient, in its units.
    pub fn noise_variance(&self) -> f64 {
        let gp = self.in_charge();
        let s = gp.output_scaling.std;
        s * s * gp.hyperparameters.noise_variance
    }

    /// The two-fidelity GP, where the component has one.
    pub fn two_fidelity(&self) -> Option<&MultiFidelityGp> {
        match self {
            ComponentGp::Single(_) => None,
            ComponentGp::TwoFidelity(gp) => Some(gp),
        }
    }

    /// (what a cheap run at `points` would remove of the latent variance, what only an
    /// expensive run removes): [`MultiFidelityGp::fidelity_variances`], or (0, the GP's
    /// variance) for a single-fidelity component.
    ///
    /// # Errors
    /// A point of the wrong dimension or with a non-finite coordinate.
    pub fn fidelity_variances(&self, points: &[Vec<f64>]) -> Result<(Vec<f64>, Vec<f64>)> {
        match self {
            ComponentGp::Single(gp) => Ok((vec![0.0; points.len()], gp.predict(points)?.variance)),
            ComponentGp::TwoFidelity(gp) => gp.fidelity_variances(points),
        }
    }
}
