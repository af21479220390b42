//! Predictivity: Q2 on a test set and the closed-form leave-one-out Q2.
//!
//! Q2 = 1 − Σ_i (q_i − q̂_i)² / Σ_i (q_i − q̄)², q the observed and q̂ the predicted values
//! (1: perfect; 0: no better than the mean of the test set).
//!
//! Leave-one-out without refitting (Rasmussen & Williams 2006, §5.4.2): with K the training
//! covariance (noise included) and α = K⁻¹ỹ, the residual of predicting ỹ_i from the other
//! points with the same hyper-parameters is r_i = ỹ_i − μ_{−i} = α_i/[K⁻¹]_ii and its
//! predictive variance is 1/[K⁻¹]_ii; residuals are reported in original units (× s_y).

use serde::{Deserialize, Serialize};

use crate::data::validate_values;
use crate::error::{GpError, Result};
use crate::gaussian_process::GaussianProcess;
use crate::scaling::OutputScaling;

/// Q2 = 1 − Σ(q − q̂)²/Σ(q − q̄)² of predictions `predicted` of `observed`.
///
/// # Errors
/// Different lengths, fewer than 2 values, non-finite values, or constant observations
/// (Q2 undefined).
pub fn q2(observed: &[f64], predicted: &[f64]) -> Result<f64> {
    if observed.len() != predicted.len() {
        return Err(GpError::LengthMismatch {
            what: "predictions vs. observations",
            expected: observed.len(),
            actual: predicted.len(),
        });
    }
    if observed.len() < 2 {
        return Err(GpError::TooFewPoints {
            required: 2,
            actual: observed.len(),
        });
    }
    validate_values(observed, "observed value")?;
    validate_values(predicted, "predicted value")?;
    let n = observed.len() as f64;
    let mean = observed.iter().sum::<f64>() / n;
    let total: f64 = observed.iter().map(|q| (q - mean) * (q - mean)).sum();
    if total == 0.0 {
        return Err(GpError::InvalidParameter {
            what: "Q2 observations",
            reason: "the observed values are all equal: Q2 is undefined".into(),
        });
    }
    let residual: f64 = observed
        .iter()
        .zip(predicted)
        .map(|(q, p)| (q - p) * (q - p))
        .sum();
    Ok(1.0 - residual / total)
}

/// Closed-form leave-one-out results of a GP, in original output units.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LeaveOneOut {
    /// r_i = y_i − μ_{−i}(x_i) = s_y·α_i/[K⁻¹]_ii.
    pub residuals: Vec<f64>,
    /// Predictive variance of y_i from the other points, s_y²/[K⁻¹]_ii (noise included).
    pub variances: Vec<f64>,
    /// 1 − Σ r_i²/Σ(y_i − ȳ)²; `None` for a constant output.
    pub q2: Option<f64>,
}

/// Leave-one-out residuals, variances and Q2 from α and diag(K⁻¹) (standardised units) and the
/// original outputs `y`.
pub(crate) fn closed_form_leave_one_out(
    alpha: &[f64],
    kinv_diagonal: &[f64],
    y: &[f64],
    scaling: &OutputScaling,
) -> LeaveOneOut {
    let residuals: Vec<f64> = alpha
        .iter()
        .zip(kinv_diagonal)
        .map(|(a, k)| scaling.std * a / k)
        .collect();
    let variances: Vec<f64> = kinv_diagonal
        .iter()
        .map(|k| scaling.std * scaling.std / k)
        .collect();
    let n = y.len() as f64;
    let mean = y.iter().sum::<f64>() / n;
    let total: f64 = y.iter().map(|v| (v - mean) * (v - mean)).sum();
    let residual: f64 = residuals.iter().map(|r| r * r).sum();
    let q2 = (total > 0.0 && residual.is_finite()).then(|| 1.0 - residual / total);
    LeaveOneOut {
        residuals,
        variances,
        q2,
    }
}

impl GaussianProcess {
    /// Q2 of the GP's mean on a test set (`x_test`, `y_test`), original units.
    ///
    /// # Errors
    /// Invalid test points (see [`GaussianProcess::predict_mean`]) or see [`q2`].
    pub fn q2(&self, x_test: &[Vec<f64>], y_test: &[f64]) -> Result<f64> {
        if x_test.len() != y_test.len() {
            return Err(GpError::LengthMismatch {
                what: "test outputs vs. test points",
                expected: x_test.len(),
                actual: y_test.len(),
            });
        }
        let predicted = self.predict_mean(x_test)?;
        q2(y_test, &predicted)
    }

    /// The closed-form leave-one-out residuals, variances and Q2.
    pub fn leave_one_out(&self) -> &LeaveOneOut {
        &self.leave_one_out
    }

    /// The leave-one-out Q2 (`None` for a constant output).
    pub fn loo_q2(&self) -> Option<f64> {
        self.leave_one_out.q2
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::ColumnMajor;
    use crate::fit::FitOptions;
    use crate::kernel::Hyperparameters;
    use crate::log_marginal_likelihood::LmlWorkspace;
    use crate::test_data::spec_data;

    #[test]
    fn q2_definition_and_errors() {
        let q = [1.0, 2.0, 3.0, 4.0];
        assert_eq!(q2(&q, &q).unwrap(), 1.0);
        assert_eq!(q2(&q, &[2.5; 4]).unwrap(), 0.0);
        assert!((q2(&q, &[1.0, 2.0, 3.0, 5.0]).unwrap() - (1.0 - 1.0 / 5.0)).abs() < 1e-15);
        assert!(q2(&q, &q[..3]).is_err());
        assert!(q2(&[1.0], &[1.0]).is_err());
        assert!(q2(&[1.0, 1.0], &[1.0, 2.0]).is_err());
        assert!(q2(&[1.0, f64::NAN], &[1.0, 2.0]).is_err());
    }

    /// The closed form against refitting without each point (same hyper-parameters).
    #[test]
    fn closed_form_matches_brute_force_refits() {
        let (x, y) = spec_data();
        let (x, y) = (x[..20].to_vec(), y[..20].to_vec());
        let h = Hyperparameters {
            signal_variance: 1.3,
            length_scales: vec![0.3, 0.6, 0.9],
            noise_variance: 1e-3,
        };
        let options = FitOptions::default();
        let gp =
            GaussianProcess::with_hyperparameters(&x, &y, h.clone(), &options.check().unwrap())
                .unwrap();
        let loo = gp.leave_one_out();
        let mut sum_r2 = 0.0;
        for i in 0..x.len() {
            // Brute force on the GP's own scaled/standardised data: drop point i.
            let xs = gp.x.without(i);
            let ys: Vec<f64> = (0..x.len())
                .filter(|&j| j != i)
                .map(|j| gp.output_scaling.apply(y[j]))
                .collect();
            let mut ws = LmlWorkspace::new(xs.n);
            ws.factorize(&xs, &h, options.jitter).unwrap();
            ws.solve(&ys);
            let point = gp.x.point(i);
            let mut k = vec![0.0; xs.n];
            crate::log_marginal_likelihood::rbf_column(
                &xs.values,
                xs.n,
                0,
                &point,
                &h.inverse_squared_length_scales(3),
                h.signal_variance,
                &mut k,
            );
            let mean: f64 = k.iter().zip(ws.alpha()).map(|(a, b)| a * b).sum();
            let r = y[i] - gp.output_scaling.invert(mean);
            assert!(
                (r - loo.residuals[i]).abs() < 1e-8 * (1.0 + r.abs()),
                "point {i}: brute {r} vs closed form {}",
                loo.residuals[i]
            );
            // Variance: K_ii − kᵀK₋ᵢ⁻¹k + noise, via a triangular solve.
            let v = {
                let cols = ColumnMajor {
                    n: xs.n,
                    d: 3,
                    values: k.clone(),
                };
                let l = faer::MatRef::from_column_major_slice(ws.cholesky(), xs.n, xs.n);
                let mut kk = cols.values;
                faer::linalg::triangular_solve::solve_lower_triangular_in_place(
                    l,
                    faer::MatMut::from_column_major_slice_mut(&mut kk, xs.n, 1),
                    faer::Par::Seq,
                );
                h.signal_variance + h.noise_variance + options.jitter
                    - kk.iter().map(|a| a * a).sum::<f64>()
            };
            let v = v * gp.output_scaling.std.powi(2);
            assert!(
                (v - loo.variances[i]).abs() < 1e-8 * v,
                "{v} vs {}",
                loo.variances[i]
            );
            sum_r2 += r * r;
        }
        let mean = y.iter().sum::<f64>() / y.len() as f64;
        let total: f64 = y.iter().map(|v| (v - mean).powi(2)).sum();
        assert!((gp.loo_q2().unwrap() - (1.0 - sum_r2 / total)).abs() < 1e-10);
    }
}
