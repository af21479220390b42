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
