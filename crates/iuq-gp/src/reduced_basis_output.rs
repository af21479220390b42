//! One output of a [`ReducedBasis`] as the adaptive engine sees an output's emulator: y_j = μ_j +
//! Σ_k a_jk c_k, its prediction, covariance and run noise from the components'.

use crate::error::Result;
use crate::output_predictor::{OutputPredictor, SharedComponents};
use crate::prediction::Prediction;
use crate::reduced_basis::ReducedBasis;

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
            components: self.basis.component_gps(),
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
            .map(|(k, component)| {
                let gp = component.in_charge();
                let s = gp.output_scaling().std;
                self.basis.loading(self.output, k).powi(2) * gp.jitter() * s * s
            })
            .sum();
        prediction.noise_variance + jitter
    }
}
