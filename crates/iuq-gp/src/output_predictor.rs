//! What a sequential design needs of the emulator of one model output: its prediction, its
//! posterior covariance between points, and how much noise a new run of it would carry. A
//! [`GaussianProcess`] of the output is one, a two-fidelity [`MultiFidelityGp`] another, and an
//! output of a reduced basis a third (`crate::ReducedBasisOutput`: a linear combination of the
//! components' emulators, [`ComponentGp`]).

use crate::component_gp::ComponentGp;
use crate::error::Result;
use crate::gaussian_process::GaussianProcess;
use crate::multi_fidelity::MultiFidelityGp;
use crate::prediction::Prediction;

/// The emulator of one model output, as the adaptive engine uses it.
pub trait OutputPredictor: Sync {
    /// The mean, latent variance and noise variance at `points` (output units).
    ///
    /// # Errors
    /// Points of the wrong dimension or not finite.
    fn predict(&self, points: &[Vec<f64>]) -> Result<Prediction>;

    /// cov[f(a_i), f(b_j) | runs], the latent posterior covariance (output units).
    ///
    /// # Errors
    /// Points of the wrong dimension or not finite.
    fn posterior_covariance(&self, a: &[Vec<f64>], b: &[Vec<f64>]) -> Result<Vec<Vec<f64>>>;

    /// The variance a new run adds to what it tells of the latent output: its fitted noise and
    /// the jitter, in output units (`prediction` from [`OutputPredictor::predict`]).
    fn run_noise_variance(&self, prediction: &Prediction) -> f64;

    /// Where the output is a fixed combination of latent components it shares with other
    /// outputs (an output of a reduced basis), those components and the weights of their
    /// covariances, so that a caller treating many outputs computes each component's
    /// covariance once: [`OutputPredictor::posterior_covariance`] is then
    /// Σ_k weights_k · cov_k, summed in k's order. `None` (the default): the output's own.
    fn shared_components(&self) -> Option<SharedComponents<'_>> {
        None
    }
}

/// The components an output shares with others and the weights of their covariances
/// ([`OutputPredictor::shared_components`]).
#[derive(Debug, Clone)]
pub struct SharedComponents<'a> {
    /// The components' emulators (`crate::ReducedBasis::component_gps`).
    pub components: &'a [ComponentGp],
    /// a_jk² per component k.
    pub weights: Vec<f64>,
}

impl SharedComponents<'_> {
    /// Σ_k weights_k · `component_covariances[k]` (each a × b), summed in k's order as a
    /// reduced basis's output's `posterior_covariance` does.
    pub fn combine(&self, component_covariances: &[Vec<Vec<f64>>]) -> Vec<Vec<f64>> {
        let rows = component_covariances.first().map_or(0, Vec::len);
        let columns = component_covariances
            .first()
            .and_then(|c| c.first())
            .map_or(0, Vec::len);
        let mut total = vec![vec![0.0; columns]; rows];
        for (w, c) in self.weights.iter().zip(component_covariances) {
            for (row, component) in total.iter_mut().zip(c) {
                for (v, x) in row.iter_mut().zip(component) {
                    *v += w * x;
                }
            }
        }
        total
    }
}

impl OutputPredictor for GaussianProcess {
    fn predict(&self, points: &[Vec<f64>]) -> Result<Prediction> {
        GaussianProcess::predict(self, points)
    }

    fn posterior_covariance(&self, a: &[Vec<f64>], b: &[Vec<f64>]) -> Result<Vec<Vec<f64>>> {
        GaussianProcess::posterior_covariance(self, a, b)
    }

    fn run_noise_variance(&self, prediction: &Prediction) -> f64 {
        let s = self.output_scaling().std;
        prediction.noise_variance + self.jitter() * s * s
    }
}

impl OutputPredictor for MultiFidelityGp {
    fn predict(&self, points: &[Vec<f64>]) -> Result<Prediction> {
        MultiFidelityGp::predict(self, points)
    }

    fn posterior_covariance(&self, a: &[Vec<f64>], b: &[Vec<f64>]) -> Result<Vec<Vec<f64>>> {
        MultiFidelityGp::posterior_covariance(self, a, b)
    }

    /// A new high-fidelity run's noise: that of the GP in charge (δ's, or the single-fidelity
    /// GP's), in the output's units.
    fn run_noise_variance(&self, prediction: &Prediction) -> f64 {
        MultiFidelityGp::run_noise_variance(self, prediction)
    }
}

impl OutputPredictor for ComponentGp {
    fn predict(&self, points: &[Vec<f64>]) -> Result<Prediction> {
        ComponentGp::predict(self, points)
    }

    fn posterior_covariance(&self, a: &[Vec<f64>], b: &[Vec<f64>]) -> Result<Vec<Vec<f64>>> {
        ComponentGp::posterior_covariance(self, a, b)
    }

    fn run_noise_variance(&self, prediction: &Prediction) -> f64 {
        OutputPredictor::run_noise_variance(self.in_charge(), prediction)
    }
}
