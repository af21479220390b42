//! What a sequential design needs of the emulator of one model output: its prediction, its
//! posterior covariance between points, and how much noise a new run of it would carry. A
//! [`GaussianProcess`] of the output is one; an output of a [`ReducedBasis`] is another
//! ([`ReducedBasisOutput`]: a linear combination of the components' GPs).

use crate::error::Result;
use crate::gaussian_process::GaussianProcess;
use crate::prediction::Prediction;
use crate::reduced_basis::ReducedBasis;

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
    /// outputs (an output of a [`ReducedBasis`]), those components and the weights of their
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
    /// The emulator whose component GPs ([`ReducedBasis::component_gps`]) they are.
    pub basis: &'a ReducedBasis,
    /// a_jk² per component k.
    pub weights: Vec<f64>,
}

impl SharedComponents<'_> {
    /// Σ_k weights_k · `component_covariances[k]` (each a × b), summed in k's order as
    /// [`ReducedBasisOutput::posterior_covariance`] does.
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

/// Output j of a [`ReducedBasis`]: y_j = μ_j + Σ_k a_jk c_k with independent component GPs, so
/// that cov[y_j(a), y_j(b)] = Σ_k a_jk² cov[c_k(a), c_k(b)] (the truncation error is a variance
/// of each point alone, not a covariance between points).
#[derive(Debug, Clone, Copy)]
pub struct ReducedBasisOutput<'a> {
    /// The emulator.
    pub basis: &'a ReducedBasis,
    /// The output's index.
    pub output: usize,
}

impl OutputPredictor for ReducedBasisOutput<'_> {
    fn predict(&self, points: &[Vec<f64>]) -> Result<Prediction> {
        self.basis.predict_output(self.output, points)
    }

    fn posterior_covariance(&self, a: &[Vec<f64>], b: &[Vec<f64>]) -> Result<Vec<Vec<f64>>> {
        let mut total = vec![vec![0.0; b.len()]; a.len()];
        for (k, gp) in self.basis.component_gps().iter().enumerate() {
            let w = self.basis.loading(self.output, k).powi(2);
            let c = gp.posterior_covariance(a, b)?;
            for (row, component) in total.iter_mut().zip(&c) {
                for (v, x) in row.iter_mut().zip(component) {
                    *v += w * x;
                }
            }
        }
        Ok(total)
    }

    fn shared_components(&self) -> Option<SharedComponents<'_>> {
        Some(SharedComponents {
            basis: self.basis,
            weights: (0..self.basis.component_gps().len())
                .map(|k| self.basis.loading(self.output, k).powi(2))
                .collect(),
        })
    }

    fn run_noise_variance(&self, prediction: &Prediction) -> f64 {
        let jitter: f64 = self
            .basis
            .component_gps()
            .iter()
            .enumerate()
            .map(|(k, gp)| {
                let s = gp.output_scaling().std;
                self.basis.loading(self.output, k).powi(2) * gp.jitter() * s * s
            })
            .sum();
        prediction.noise_variance + jitter
    }
}
