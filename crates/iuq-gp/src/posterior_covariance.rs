//! The latent posterior covariance between two sets of points,
//! cov[f(a), f(b) | data] = s_y²·(k(ã, b̃) − k(ã, X̃)ᵀ K⁻¹ k(X̃, b̃)) (Rasmussen & Williams 2006,
//! eq. 2.24), in original output units.
//!
//! Sequential designs need it: conditioning a GP on a point s that has not been run yet changes
//! the variance at x by −cov(x, s)²/(var(s) + σ²) whatever value is later observed at s, which
//! is how a batch of new runs is kept diverse (the "kriging believer" of Ginsbourger et al. 2010).

use faer::linalg::{matmul, triangular_solve};
use faer::{Accum, MatMut, MatRef, Par};

use crate::data::validate_points;
use crate::error::Result;
use crate::gaussian_process::GaussianProcess;
use crate::log_marginal_likelihood::{LmlWorkspace, rbf_column};
use crate::vector_math::exp_in_place;

impl GaussianProcess {
    /// The latent posterior covariance matrix between the points `a` and `b` (original input
    /// units, one row per point): row i, column j is cov[f(a_i), f(b_j)] in original output
    /// units. Its diagonal for `a == b` equals [`GaussianProcess::predict`]'s variances.
    ///
    /// Cost: one O(n³) factorisation of the training kernel matrix, O((|a| + |b|)·n²)
    /// triangular solves and one matrix product of O(|a|·|b|·n); for `a == b` (the covariance
    /// over one set, e.g. the adaptive engine's candidates) the solves and the kernel terms are
    /// made once per point and pair and the matrix is symmetric by construction.
    ///
    /// # Errors
    /// A point of the wrong dimension or with a non-finite coordinate.
    pub fn posterior_covariance(&self, a: &[Vec<f64>], b: &[Vec<f64>]) -> Result<Vec<Vec<f64>>> {
        let d = self.dimension();
        validate_points(a, "covariance point", Some(d))?;
        validate_points(b, "covariance point", Some(d))?;
        let same = a == b;
        let n = self.x.n;
        let mut workspace = LmlWorkspace::new(n);
        workspace.factorize(&self.x, &self.hyperparameters, self.jitter)?;
        let (factor, _) = workspace.into_factor();
        let l = MatRef::from_column_major_slice(&factor, n, n);
        let weights = self.hyperparameters.inverse_squared_length_scales(d);
        let c = self.hyperparameters.signal_variance;
        let scaled = |p: &Vec<f64>| -> Vec<f64> {
            (0..d).map(|k| self.input_scaling.apply(k, p[k])).collect()
        };
        let a_scaled: Vec<Vec<f64>> = a.iter().map(scaled).collect();
        let b_scaled: Vec<Vec<f64>> = if same {
            Vec::new()
        } else {
            b.iter().map(scaled).collect()
        };
        // Columns L⁻¹k(X̃, p) for every point p of a, then of b (unless b is a).
        let m = a_scaled.len() + b_scaled.len();
        let mut columns = vec![0.0; n * m];
        for (j, p) in a_scaled.iter().chain(&b_scaled).enumerate() {
            rbf_column(
                &self.x.values,
                n,
                0,
                p,
                &weights,
                c,
                &mut columns[j * n..(j + 1) * n],
            );
        }
        let mut solved = MatMut::from_column_major_slice_mut(&mut columns, n, m);
        triangular_solve::solve_lower_triangular_in_place(l, solved.as_mut(), Par::Seq);
        let (rows, cols) = (a.len(), b.len());
        let va = MatRef::from_column_major_slice(&columns[..n * rows], n, rows);
        let vb = if same {
            va
        } else {
            MatRef::from_column_major_slice(&columns[n * rows..], n, cols)
        };
        // k(X̃, a)ᵀ K⁻¹ k(X̃, b) = (L⁻¹k_a)ᵀ (L⁻¹k_b), column-major rows × cols.
        let mut explained = vec![0.0; rows * cols];
        matmul::matmul(
            MatMut::from_column_major_slice_mut(&mut explained, rows, cols),
            Accum::Replace,
            va.transpose(),
            vb,
            1.0,
            Par::Seq,
        );
        let b_points = if same { &a_scaled } else { &b_scaled };
        let s2 = self.output_scaling.std * self.output_scaling.std;
        // Row i's prior kernel terms c·exp(−½ Σ_k w_k (a_ik − b_jk)²), the exponentials of a
        // row at once (vectorised).
        let mut covariance = vec![vec![0.0; cols]; rows];
        for (i, (pa, row)) in a_scaled.iter().zip(covariance.iter_mut()).enumerate() {
            let first = if same { i } else { 0 };
            let terms = &mut row[first..];
            for (out, pb) in terms.iter_mut().zip(&b_points[first..]) {
                let squared: f64 = pa
                    .iter()
                    .zip(pb)
                    .zip(&weights)
                    .map(|((x, y), w)| w * (x - y) * (x - y))
                    .sum();
                *out = -0.5 * squared;
            }
            exp_in_place(terms);
            for (j, out) in (first..).zip(terms.iter_mut()) {
                *out = s2 * (c * *out - explained[j * rows + i]);
            }
        }
        if same {
            for i in 0..rows {
                for j in 0..i {
                    covariance[i][j] = covariance[j][i];
                }
            }
        }
        Ok(covariance)
    }
}

#[cfg(test)]
mod tests {
    use crate::{FitOptions, GaussianProcess};

    fn training() -> (Vec<Vec<f64>>, Vec<f64>) {
        let x: Vec<Vec<f64>> = (0..12)
            .map(|i| {
                let t = i as f64 / 11.0;
                vec![t, (3.0 * t).sin()]
            })
            .collect();
        let y = x.iter().map(|p| (4.0 * p[0]).sin() + p[1] * p[1]).collect();
        (x, y)
    }

    #[test]
    fn the_diagonal_equals_the_predicted_variance() {
        let (x, y) = training();
        let gp = GaussianProcess::fit(&x, &y, &FitOptions::default().check().unwrap()).unwrap();
        let points = vec![vec![0.33, 0.2], vec![0.9, -0.4], vec![1.3, 0.8]];
        let covariance = gp.posterior_covariance(&points, &points).unwrap();
        let variance = gp.predict(&points).unwrap().variance;
        for (i, v) in variance.iter().enumerate() {
            let scale = v.abs().max(1e-12);
            assert!(
                (covariance[i][i] - v).abs() <= 1e-6 * scale + 1e-12,
                "{} vs {v}",
                covariance[i][i]
            );
            for j in 0..points.len() {
                assert!((covariance[i][j] - covariance[j][i]).abs() < 1e-10);
            }
        }
    }

    /// Conditioning on a new point s with the believer's value (the predicted mean) gives the
    /// variance v(x) − cov(x, s)²/(v(s) + σ²): checked against a GP refitted with s added at
    /// the same hyper-parameters and scalings.
    #[test]
    fn conditioning_on_a_point_reduces_the_variance_as_a_refit_does() {
        let (x, y) = training();
        let options = FitOptions {
            scale_inputs: false,
            standardize_outputs: false,
            ..FitOptions::default()
        };
        let gp = GaussianProcess::fit(&x, &y, &options.check().unwrap()).unwrap();
        let s = vec![0.55, 0.5];
        // Probes off the training curve x1 = sin(3 x0), where the variance is well above the
        // rounding of its O(1) terms.
        let probe = vec![vec![0.5, 0.4], vec![0.7, -0.3], vec![0.1, 0.9]];
        let cross = gp
            .posterior_covariance(&probe, std::slice::from_ref(&s))
            .unwrap();
        let at_s = gp.predict(std::slice::from_ref(&s)).unwrap();
        let before = gp.predict(&probe).unwrap();
        let mut x2 = x.clone();
        x2.push(s.clone());
        let mut y2 = y.clone();
        y2.push(at_s.mean[0]);
        let refit = GaussianProcess::with_hyperparameters(
            &x2,
            &y2,
            gp.hyperparameters().clone(),
            &options.check().unwrap(),
        )
        .unwrap();
        let after = refit.predict(&probe).unwrap();
        for i in 0..probe.len() {
            // The refit's kernel matrix has the jitter on its diagonal as well as the noise.
            let denominator = at_s.variance[0] + at_s.noise_variance + gp.jitter();
            let expected = before.variance[i] - cross[i][0].powi(2) / denominator;
            assert!(expected < before.variance[i]);
            assert!(
                (after.variance[i] - expected).abs() < 1e-6 * before.variance[i] + 1e-12,
                "{} vs {expected}",
                after.variance[i]
            );
        }
    }
}
