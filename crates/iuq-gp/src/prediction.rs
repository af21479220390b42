//! Batch prediction: posterior mean and variance at many points.
//!
//! For test points x*₁…x*_m (scaled like the training inputs) and K* the n×m cross-kernel
//! matrix, in standardised units
//!
//! μ = K*ᵀα,   var_f = c − ‖L⁻¹k*‖² (latent function),   var_y = var_f + σ² (a new observation),
//!
//! mapped back to original units (ȳ + s·μ, s²·var). Points are processed in blocks of
//! [`BLOCK`]: each block builds its n×b slice of K* (vectorised `exp`), takes the means as dot
//! products with α and the variances from one triangular solve L⁻¹K*_block (faer, a
//! level-3 operation); blocks run in parallel (rayon) and sequentially inside, so the results
//! do not depend on the number of threads. No inverse is formed. Negative variances from
//! round-off are clipped to 0 (as scikit-learn does).
//!
//! Precision: the variance is a difference c − ‖L⁻¹k*‖² and carries a round-off of order
//! 1e−16·c·n (standardised units) — far below any useful variance, but it means a point's
//! variance can differ in the last digits between batches of different composition (the
//! triangular solve of a block rounds differently from that of one column). Means do not
//! depend on the batch.

use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
use faer::{MatMut, MatRef, Par};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::data::validate_points;
use crate::error::Result;
use crate::gaussian_process::GaussianProcess;
use crate::log_marginal_likelihood::{lane_dot, rbf_column};
use crate::vector_math::multiversion;

/// Points per block of the cross-kernel matrix (n×256 doubles: 1 MB at n = 500).
pub const BLOCK: usize = 256;

/// Posterior mean and variances at a batch of points, in original output units.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Prediction {
    /// Posterior mean ȳ + s·k*ᵀα.
    pub mean: Vec<f64>,
    /// Variance of the latent function, s²·(c − k*ᵀK⁻¹k*) (no noise term).
    pub variance: Vec<f64>,
    /// The noise variance s²·σ² that a new observation adds.
    pub noise_variance: f64,
}

impl Prediction {
    /// Standard deviation of the latent function, √variance.
    pub fn std(&self) -> Vec<f64> {
        self.variance.iter().map(|v| v.sqrt()).collect()
    }

    /// Variance of a new observation, variance + noise variance (scikit-learn's `predict`
    /// convention when the kernel contains a `WhiteKernel`).
    pub fn variance_with_noise(&self) -> Vec<f64> {
        self.variance
            .iter()
            .map(|v| v + self.noise_variance)
            .collect()
    }

    /// Standard deviation of a new observation, √(variance + noise variance).
    pub fn std_with_noise(&self) -> Vec<f64> {
        self.variance
            .iter()
            .map(|v| (v + self.noise_variance).sqrt())
            .collect()
    }
}

multiversion! {
    /// out[t] = Σ_i a[t·n + i]·b[i]: the columns of a column-major n×m block dotted with b.
    fn column_dots(a: &[f64], n: usize, b: &[f64], out: &mut [f64]) {
        for (o, col) in out.iter_mut().zip(a.chunks_exact(n)) {
            *o = lane_dot(col, b);
        }
    }
}

multiversion! {
    /// out[t] = ‖column t‖² of a column-major n×m block.
    fn column_squared_norms(a: &[f64], n: usize, out: &mut [f64]) {
        for (o, col) in out.iter_mut().zip(a.chunks_exact(n)) {
            *o = lane_dot(col, col);
        }
    }
}

impl GaussianProcess {
    /// Posterior mean and variances (latent, and the noise term) at `points` (original input
    /// units, one row per point), in original output units.
    ///
    /// # Errors
    /// A point of the wrong dimension or with a non-finite coordinate.
    pub fn predict(&self, points: &[Vec<f64>]) -> Result<Prediction> {
        let (mean, variance) = self.predict_blocks(points, true)?;
        let s = self.output_scaling.std;
        Ok(Prediction {
            mean,
            variance,
            noise_variance: s * s * self.hyperparameters.noise_variance,
        })
    }

    /// Posterior mean only (no triangular solve: O(n·d) per point).
    ///
    /// # Errors
    /// A point of the wrong dimension or with a non-finite coordinate.
    pub fn predict_mean(&self, points: &[Vec<f64>]) -> Result<Vec<f64>> {
        Ok(self.predict_blocks(points, false)?.0)
    }

    fn predict_blocks(
        &self,
        points: &[Vec<f64>],
        with_variance: bool,
    ) -> Result<(Vec<f64>, Vec<f64>)> {
        let d = self.dimension();
        validate_points(points, "prediction point", Some(d))?;
        let m = points.len();
        let n = self.x.n;
        let mut mean = vec![0.0; m];
        let mut variance = vec![0.0; if with_variance { m } else { 0 }];
        let weights = self.hyperparameters.inverse_squared_length_scales(d);
        let c = self.hyperparameters.signal_variance;
        let scaling = self.output_scaling;
        let block = |index: usize, mean: &mut [f64], variance: Option<&mut [f64]>| {
            let start = index * BLOCK;
            let b = mean.len();
            let mut ks = vec![0.0; n * b];
            let mut p = vec![0.0; d];
            for (t, col) in ks.chunks_exact_mut(n).enumerate() {
                for (k, pk) in p.iter_mut().enumerate() {
                    *pk = self.input_scaling.apply(k, points[start + t][k]);
                }
                rbf_column(&self.x.values, n, 0, &p, &weights, c, col);
            }
            column_dots(&ks, n, &self.alpha, mean);
            for v in mean.iter_mut() {
                *v = scaling.invert(*v);
            }
            if let Some(variance) = variance {
                let l = MatRef::from_column_major_slice(&self.cholesky, n, n);
                solve_lower_triangular_in_place(
                    l,
                    MatMut::from_column_major_slice_mut(&mut ks, n, b),
                    Par::Seq,
                );
                column_squared_norms(&ks, n, variance);
                for v in variance.iter_mut() {
                    *v = (c - *v).max(0.0) * scaling.std * scaling.std;
                }
            }
        };
        if with_variance {
            mean.par_chunks_mut(BLOCK)
                .zip(variance.par_chunks_mut(BLOCK))
                .enumerate()
                .for_each(|(i, (mc, vc))| block(i, mc, Some(vc)));
        } else {
            mean.par_chunks_mut(BLOCK)
                .enumerate()
                .for_each(|(i, mc)| block(i, mc, None));
        }
        Ok((mean, variance))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::FitOptions;
    use crate::kernel::{Hyperparameters, Kernel};
    use crate::test_data::spec_data;

    /// scikit-learn's fitted θ on the spec data (standardised y, raw inputs):
    /// GaussianProcessRegressor(C*RBF([.5]*3) + White(1e-3), alpha=1e-10, normalize_y=True,
    /// n_restarts_optimizer=10, random_state=0).kernel_.theta.
    const SKLEARN_THETA: [f64; 5] = [
        3.937781193776065,
        -0.6495394625845659,
        1.0656455878254127,
        3.049978690525969,
        -9.112741245593789,
    ];
    const POINTS: [[f64; 3]; 3] = [[0.1, 0.2, 0.3], [0.5, 0.5, 0.5], [0.9, 0.05, 0.7]];

    fn raw_standardised() -> FitOptions {
        FitOptions {
            scale_inputs: false,
            standardize_outputs: true,
            ..Default::default()
        }
    }

    #[test]
    fn matches_scikit_learn_at_its_hyperparameters() {
        let (x, y) = spec_data();
        let opts = raw_standardised();
        let h = Kernel::ard().hyperparameters(&SKLEARN_THETA, 3).unwrap();
        let gp = GaussianProcess::with_hyperparameters(&x, &y, h, &opts).unwrap();
        assert!((gp.log_marginal_likelihood() - 121.03244938819157).abs() < 1e-7);
        let pts: Vec<Vec<f64>> = POINTS.iter().map(|p| p.to_vec()).collect();
        let p = gp.predict(&pts).unwrap();
        // scikit-learn 1.9 at this θ (predict(return_std=True): the std includes the White
        // noise term).
        let mean = [0.7791655196212579, 0.5009130818457446, -0.22985791120070864];
        let std = [
            0.009184160401861763,
            0.008652871344026735,
            0.010347822971766035,
        ];
        let sd = p.std_with_noise();
        for i in 0..3 {
            assert!(
                (p.mean[i] - mean[i]).abs() <= 1e-6 * mean[i].abs(),
                "{i}: {}",
                p.mean[i]
            );
            assert!((sd[i] - std[i]).abs() <= 1e-6 * std[i], "{i}: {}", sd[i]);
        }
        // The spec's rounded reference values.
        let spec_mean = [0.779165520919, 0.500913086381, -0.229857992164];
        let spec_std = [0.00918415919, 0.008652872795, 0.010347819603];
        for i in 0..3 {
            assert!((p.mean[i] - spec_mean[i]).abs() <= 1e-6 * spec_mean[i].abs());
            assert!((sd[i] - spec_std[i]).abs() <= 1e-6 * spec_std[i]);
        }
        // The latent std is smaller than the noisy one by exactly the noise term.
        let latent = p.std();
        for i in 0..3 {
            assert!(latent[i] < sd[i]);
            assert!((latent[i].powi(2) + p.noise_variance - sd[i].powi(2)).abs() < 1e-15);
        }
        // Mean-only prediction agrees with the full one.
        assert_eq!(gp.predict_mean(&pts).unwrap(), p.mean);
    }

    #[test]
    fn interpolates_training_points_and_blocks_agree() {
        let (x, y) = spec_data();
        let h = Hyperparameters {
            signal_variance: 1.0,
            length_scales: vec![0.4, 0.6, 0.8],
            noise_variance: 1e-8,
        };
        let gp = GaussianProcess::with_hyperparameters(&x, &y, h, &FitOptions::default()).unwrap();
        let p = gp.predict(&x).unwrap();
        for (i, yi) in y.iter().enumerate() {
            assert!((p.mean[i] - yi).abs() < 1e-3, "{i}");
            assert!(p.variance[i] < 1e-6);
        }
        // More points than a block: each point's result equals its result alone.
        let many: Vec<Vec<f64>> = (0..(BLOCK + 37))
            .map(|i| {
                let t = i as f64 / (BLOCK + 37) as f64;
                vec![t, (3.0 * t).fract(), (7.0 * t).fract()]
            })
            .collect();
        let all = gp.predict(&many).unwrap();
        for i in [0, 5, BLOCK - 1, BLOCK, BLOCK + 36] {
            let one = gp.predict(&many[i..=i]).unwrap();
            assert!((one.mean[0] - all.mean[i]).abs() <= 1e-14 * (1.0 + all.mean[i].abs()));
            // The variance c − ‖L⁻¹k*‖² cancels: round-off is relative to c·s², and the
            // triangular solve of one column rounds differently from that of a block.
            let scale = gp.hyperparameters().signal_variance * gp.output_scaling().std.powi(2);
            assert!((one.variance[0] - all.variance[i]).abs() <= 1e-12 * scale);
        }
        assert!(gp.predict(&[]).unwrap().mean.is_empty());
    }

    #[test]
    fn bad_prediction_points_are_errors() {
        let (x, y) = spec_data();
        let gp = GaussianProcess::with_hyperparameters(
            &x,
            &y,
            Hyperparameters {
                signal_variance: 1.0,
                length_scales: vec![0.5; 3],
                noise_variance: 1e-4,
            },
            &FitOptions::default(),
        )
        .unwrap();
        assert!(gp.predict(&[vec![0.1, 0.2]]).is_err());
        assert!(gp.predict(&[vec![0.1, f64::NAN, 0.3]]).is_err());
        assert!(gp.predict_mean(&[vec![0.1, 0.2, 0.3, 0.4]]).is_err());
    }

    /// Variants of the variance computation for one block (not a test; run with
    /// `cargo test --release -p iuq-gp -- --ignored --nocapture profile_prediction`).
    #[test]
    #[ignore]
    fn profile_prediction_blocks() {
        use faer::linalg::matmul::triangular::{BlockStructure, matmul};
        use std::time::Instant;
        let (x, y) = crate::test_data::quasi_random_data(500);
        let h = Hyperparameters {
            signal_variance: 300.0,
            length_scales: vec![0.6, 5.0, 60.0],
            noise_variance: 1e-4,
        };
        let gp = GaussianProcess::with_hyperparameters(&x, &y, h, &FitOptions::default()).unwrap();
        let n = gp.x.n;
        let l = MatRef::from_column_major_slice(&gp.cholesky, n, n);
        let mut linv = vec![0.0; n * n];
        faer::linalg::triangular_inverse::invert_lower_triangular(
            MatMut::from_column_major_slice_mut(&mut linv, n, n),
            l,
            Par::Seq,
        );
        for j in 0..n {
            for i in 0..j {
                linv[j * n + i] = 0.0;
            }
        }
        let li = MatRef::from_column_major_slice(&linv, n, n);
        for b in [128usize, 256, 512, 1024] {
            let ks: Vec<f64> = (0..n * b)
                .map(|i| ((i * 7919) % 1000) as f64 * 1e-3)
                .collect();
            let reps = 20;
            let mut work = ks.clone();
            let t = Instant::now();
            for _ in 0..reps {
                work.copy_from_slice(&ks);
                solve_lower_triangular_in_place(
                    l,
                    MatMut::from_column_major_slice_mut(&mut work, n, b),
                    Par::Seq,
                );
            }
            let t_trsm = t.elapsed().as_secs_f64() / reps as f64;
            let mut out = vec![0.0; n * b];
            let t = Instant::now();
            for _ in 0..reps {
                matmul(
                    MatMut::from_column_major_slice_mut(&mut out, n, b),
                    BlockStructure::Rectangular,
                    faer::Accum::Replace,
                    li,
                    BlockStructure::TriangularLower,
                    MatRef::from_column_major_slice(&ks, n, b),
                    BlockStructure::Rectangular,
                    1.0,
                    Par::Seq,
                );
            }
            let t_tri = t.elapsed().as_secs_f64() / reps as f64;
            let t = Instant::now();
            for _ in 0..reps {
                faer::linalg::matmul::matmul(
                    MatMut::from_column_major_slice_mut(&mut out, n, b),
                    faer::Accum::Replace,
                    li,
                    MatRef::from_column_major_slice(&ks, n, b),
                    1.0,
                    Par::Seq,
                );
            }
            let t_gemm = t.elapsed().as_secs_f64() / reps as f64;
            let gf = |t: f64| (n * n * b) as f64 / t / 1e9;
            println!(
                "b={b}: trsm {:.2} ms ({:.1} GF/s), triangular matmul {:.2} ms ({:.1}), dense gemm {:.2} ms ({:.1} GF/s at 2n²b)",
                t_trsm * 1e3,
                gf(t_trsm),
                t_tri * 1e3,
                gf(t_tri),
                t_gemm * 1e3,
                2.0 * gf(t_gemm)
            );
        }
    }
}
