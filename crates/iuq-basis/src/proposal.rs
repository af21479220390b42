//! The Gaussian random-walk proposal of the MCMC moves (BASIS step 4, docs/methods.md §5; Ching
//! & Chen 2007, eq. 21): Σ_p = β²·Σ_i w̄_i (θ_i − μ)(θ_i − μ)ᵀ, μ = Σ_i w̄_i θ_i, with the
//! normalised weights w̄ of the new exponent. Moves are θ' = θ + L·z, z ~ N(0, I), L Lᵀ = Σ_p.
//!
//! Σ_p can be singular (a weight concentrated on a few members, a parameter the likelihood
//! pins down): the Cholesky factorisation is retried with a jitter ε·(tr Σ_p/d)·I for
//! ε = 1e-12, 1e-11, …, 1e-4, and if all fail the proposal falls back to the diagonal of Σ_p,
//! each variance floored at (1e-6·β·w_k)² with w_k the width of parameter k's prior range, so
//! that a move is always possible.

use serde::{Deserialize, Serialize};

use iuq_core::weighted_statistics::{CovarianceNormalisation, weighted_covariance};

use crate::error::Result;

/// How the proposal's Cholesky factor was obtained.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum CovarianceFactor {
    /// Σ_p factorised as it is.
    Full,
    /// Σ_p + jitter·I factorised; `jitter` is the absolute value added to the diagonal.
    Jittered {
        /// The value added to each diagonal element.
        jitter: f64,
    },
    /// Every jitter failed: the diagonal of Σ_p (floored) is used.
    Diagonal,
}

/// A Gaussian random-walk proposal: the lower Cholesky factor L of its covariance.
#[derive(Debug, Clone, PartialEq)]
pub struct Proposal {
    /// Lower-triangular L (row-major, d×d) with L Lᵀ the proposal covariance.
    pub cholesky: Vec<Vec<f64>>,
    /// How L was obtained.
    pub factor: CovarianceFactor,
}

/// Relative jitters tried, in order, before the diagonal fallback.
pub const JITTERS: [f64; 9] = [1e-12, 1e-11, 1e-10, 1e-9, 1e-8, 1e-7, 1e-6, 1e-5, 1e-4];

impl Proposal {
    /// The proposal of population `points` with normalised or unnormalised `weights`, scale
    /// `beta` and prior range widths `widths` (for the diagonal floor).
    pub fn new(points: &[Vec<f64>], weights: &[f64], beta: f64, widths: &[f64]) -> Result<Self> {
        let mut covariance = weighted_covariance(points, weights, CovarianceNormalisation::Biased)?;
        for row in &mut covariance {
            for c in row.iter_mut() {
                *c *= beta * beta;
            }
        }
        Ok(Self::from_covariance(&covariance, beta, widths))
    }

    /// Factorise `covariance` with escalating jitter, else fall back to the diagonal.
    pub fn from_covariance(covariance: &[Vec<f64>], beta: f64, widths: &[f64]) -> Self {
        if let Some(l) = cholesky_lower(covariance) {
            return Self {
                cholesky: l,
                factor: CovarianceFactor::Full,
            };
        }
        let d = covariance.len();
        let mean_diagonal = (0..d).map(|k| covariance[k][k]).sum::<f64>() / d as f64;
        if mean_diagonal.is_finite() && mean_diagonal > 0.0 {
            for relative in JITTERS {
                let jitter = relative * mean_diagonal;
                let mut a = covariance.to_vec();
                for (k, row) in a.iter_mut().enumerate() {
                    row[k] += jitter;
                }
                if let Some(l) = cholesky_lower(&a) {
                    return Self {
                        cholesky: l,
                        factor: CovarianceFactor::Jittered { jitter },
                    };
                }
            }
        }
        let mut l = vec![vec![0.0; d]; d];
        for k in 0..d {
            let floor = (1e-6 * beta * widths.get(k).copied().unwrap_or(1.0)).powi(2);
            let v = covariance[k][k];
            let v = if v.is_finite() { v.max(floor) } else { floor };
            l[k][k] = v.sqrt();
        }
        Self {
            cholesky: l,
            factor: CovarianceFactor::Diagonal,
        }
    }

    /// θ + L·z.
    pub fn step(&self, theta: &[f64], z: &[f64]) -> Vec<f64> {
        self.cholesky
            .iter()
            .zip(theta)
            .map(|(row, t)| t + row.iter().zip(z).map(|(l, z)| l * z).sum::<f64>())
            .collect()
    }
}

/// Lower Cholesky factor of a small symmetric matrix, or `None` if it is not (numerically)
/// positive definite.
pub fn cholesky_lower(a: &[Vec<f64>]) -> Option<Vec<Vec<f64>>> {
    let d = a.len();
    let mut l = vec![vec![0.0; d]; d];
    for i in 0..d {
        for j in 0..=i {
            let s: f64 = a[i][j] - (0..j).map(|k| l[i][k] * l[j][k]).sum::<f64>();
            if i == j {
                if !(s > 0.0 && s.is_finite()) {
                    return None;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    Some(l)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn full_covariance_is_beta_squared_times_weighted_covariance() {
        let pts = vec![
            vec![1.0, 2.0],
            vec![2.0, 1.0],
            vec![4.0, 5.0],
            vec![0.0, -1.0],
        ];
        let p = Proposal::new(&pts, &[1.0, 2.0, 3.0, 4.0], 0.2, &[1.0, 1.0]).unwrap();
        assert_eq!(p.factor, CovarianceFactor::Full);
        let l = &p.cholesky;
        // L Lᵀ = 0.04 * [[2.81, 4.05], [4.05, 6.25]] (numpy, bias=True)
        let c00 = l[0][0] * l[0][0];
        let c10 = l[1][0] * l[0][0];
        let c11 = l[1][0] * l[1][0] + l[1][1] * l[1][1];
        assert!((c00 - 0.04 * 2.81).abs() < 1e-14);
        assert!((c10 - 0.04 * 4.05).abs() < 1e-14);
        assert!((c11 - 0.04 * 6.25).abs() < 1e-14);
        assert_eq!(p.step(&[1.0, 1.0], &[0.0, 0.0]), vec![1.0, 1.0]);
    }

    #[test]
    fn singular_covariance_is_jittered_and_zero_falls_back_to_diagonal() {
        // collinear points: rank 1
        let pts = vec![vec![0.0, 0.0], vec![1.0, 1.0], vec![2.0, 2.0]];
        let p = Proposal::new(&pts, &[1.0, 1.0, 1.0], 0.2, &[1.0, 1.0]).unwrap();
        assert!(
            matches!(p.factor, CovarianceFactor::Jittered { .. }),
            "{p:?}"
        );
        // all weight on one point: zero covariance
        let p = Proposal::new(&pts, &[0.0, 1.0, 0.0], 0.2, &[10.0, 20.0]).unwrap();
        assert_eq!(p.factor, CovarianceFactor::Diagonal);
        assert!((p.cholesky[0][0] - 2e-6).abs() < 1e-18);
        assert!((p.cholesky[1][1] - 4e-6).abs() < 1e-18);
    }
}
