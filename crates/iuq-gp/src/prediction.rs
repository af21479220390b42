//! Batch prediction: posterior mean and variance at many points.
//!
//! For test points x*₁…x*_m (scaled like the training inputs) and K* the n×m cross-kernel
//! matrix, in standardised units
//!
//! μ = K*ᵀα,   var_f = c − ‖L⁻¹k*‖² (latent function),   var_y = var_f + σ² (a new observation),
//!
//! mapped back to original units (ȳ + s·μ, s²·var). Points are processed in blocks of
//! [`BLOCK`], and inside a block in groups of 8 points: each group builds its n×8 slice of K*
//! row-major (vectorised across the 8 points, `exp` four rows at a time) and takes the means
//! as dot products with α; the variances of 8 groups at a time come from one packed forward
//! substitution L⁻¹K* (`forward_substitution`: a register-tiled, GEMM-shaped kernel at
//! ≈ 75 % of the core's peak, where faer's general triangular solve reached ≈ 45 %).
//! Blocks run in parallel (rayon) and sequentially inside; [`crate::GpBank`] runs the blocks
//! of all its GPs in one parallel loop. No inverse is formed. Negative variances from
//! round-off are clipped to 0 (as scikit-learn does).
//!
//! Every point's mean and variance are computed by the same operations in the same order
//! whatever the other points of the batch, so the results depend neither on the batch nor on
//! the number of threads. Precision: the variance is a difference c − ‖L⁻¹k*‖² and carries a
//! round-off of order 1e−16·c·n (standardised units) — far below any useful variance.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::data::validate_points;
use crate::error::Result;
use crate::forward_substitution::LANES;
use crate::gaussian_process::GaussianProcess;
use crate::vector_math::{exp, multiversion};

/// Points per block (the unit of parallel work).
pub const BLOCK: usize = 256;

/// Groups of [`LANES`] points per call of the packed substitution (64 points: 256 KB of
/// right-hand sides at n = 500, which stay in the L2 cache).
const GROUPS: usize = 8;

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
    /// The cross-kernel rows of a group of [`LANES`] points, row-major:
    /// `out[i·LANES + t] = c·exp(Σ_k h_k (x_k[i] − p_k[t])²)` (h_k = −½/l_k², the sum in input
    /// order, as the training kernel matrix is computed) for the n training points i (`x`
    /// column-major), and the dot products Σ_i α_i·out[i·LANES + t] (fused multiply-adds in
    /// increasing i). Vectorised across the points of the group, in three passes (exponents
    /// input by input, `exp` four rows at a time, scaling and dots) so that the `exp`
    /// polynomials of neighbouring rows overlap instead of waiting for each other.
    fn cross_kernel_rows(
        x: &[f64],
        n: usize,
        points: &[[f64; LANES]],
        neg_half_weights: &[f64],
        c: f64,
        alpha: &[f64],
        out: &mut [f64],
    ) -> [f64; LANES] {
        let out = &mut out[..n * LANES];
        match points.len() {
            1 => exponents::<1>(x, n, points, neg_half_weights, out),
            2 => exponents::<2>(x, n, points, neg_half_weights, out),
            3 => exponents::<3>(x, n, points, neg_half_weights, out),
            4 => exponents::<4>(x, n, points, neg_half_weights, out),
            _ => exponents_any(x, n, points, neg_half_weights, out),
        }
        // Four rows at a time: four independent polynomial chains in flight.
        let mut chunks = out.chunks_exact_mut(4 * LANES);
        for chunk in &mut chunks {
            for v in chunk.iter_mut() {
                *v = exp(*v);
            }
        }
        for v in chunks.into_remainder() {
            *v = exp(*v);
        }
        let mut dots = [0.0; LANES];
        for (row, &a) in out.chunks_exact_mut(LANES).zip(alpha) {
            for (o, d) in row.iter_mut().zip(dots.iter_mut()) {
                let e = c * *o;
                *o = e;
                *d = a.mul_add(e, *d);
            }
        }
        dots
    }
}

/// `out[i·LANES + t] = Σ_k h_k (x_k[i] − p_k[t])²` for D inputs (the inputs' loop unrolled,
/// points and weights held in registers).
#[inline(always)]
fn exponents<const D: usize>(
    x: &[f64],
    n: usize,
    points: &[[f64; LANES]],
    neg_half_weights: &[f64],
    out: &mut [f64],
) {
    let (Ok(points), Ok(weights)) = (
        <&[[f64; LANES]; D]>::try_from(points),
        <&[f64; D]>::try_from(neg_half_weights),
    ) else {
        return exponents_any(x, n, points, neg_half_weights, out);
    };
    for (i, row) in out.chunks_exact_mut(LANES).enumerate().take(n) {
        let mut s = [0.0; LANES];
        for k in 0..D {
            let xk = x[k * n + i];
            for (s, &pt) in s.iter_mut().zip(&points[k]) {
                let t = xk - pt;
                *s += weights[k] * t * t;
            }
        }
        row.copy_from_slice(&s);
    }
}

/// [`exponents`] for any number of inputs.
#[inline(always)]
fn exponents_any(
    x: &[f64],
    n: usize,
    points: &[[f64; LANES]],
    neg_half_weights: &[f64],
    out: &mut [f64],
) {
    for (i, row) in out.chunks_exact_mut(LANES).enumerate().take(n) {
        let mut s = [0.0; LANES];
        for (k, (p, &w)) in points.iter().zip(neg_half_weights).enumerate() {
            let xk = x[k * n + i];
            for (s, &pt) in s.iter_mut().zip(p) {
                let t = xk - pt;
                *s += w * t * t;
            }
        }
        row.copy_from_slice(&s);
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
        validate_points(points, "prediction point", Some(self.dimension()))?;
        let m = points.len();
        let mut mean = vec![0.0; m];
        let mut variance = vec![0.0; if with_variance { m } else { 0 }];
        if with_variance {
            mean.par_chunks_mut(BLOCK)
                .zip(variance.par_chunks_mut(BLOCK))
                .zip(points.par_chunks(BLOCK))
                .for_each(|((mc, vc), pc)| self.predict_block(pc, mc, Some(vc)));
        } else {
            mean.par_chunks_mut(BLOCK)
                .zip(points.par_chunks(BLOCK))
                .for_each(|(mc, pc)| self.predict_block(pc, mc, None));
        }
        Ok((mean, variance))
    }

    /// Means (and latent variances when `variance` is given) at validated `points`, in
    /// original units, sequentially: groups of [`LANES`] points, each with its n×[`LANES`]
    /// cross-kernel slice and the means as dot products with α, and the variances of
    /// [`GROUPS`] groups at a time from one packed forward substitution. A point's results do
    /// not depend on the other points.
    pub(crate) fn predict_block(
        &self,
        points: &[Vec<f64>],
        mean: &mut [f64],
        mut variance: Option<&mut [f64]>,
    ) {
        let d = self.dimension();
        let n = self.x.n;
        let neg_half_weights: Vec<f64> = self
            .hyperparameters
            .inverse_squared_length_scales(d)
            .iter()
            .map(|w| -0.5 * w)
            .collect();
        let signal = self.hyperparameters.signal_variance;
        let scaling = self.output_scaling;
        let size = self.packed_factor.padded_rows() * LANES;
        // Rows n.. of every group stay zero (the substitution keeps them zero).
        let mut rows = vec![0.0; size * if variance.is_some() { GROUPS } else { 1 }];
        let mut norms = [[0.0; LANES]; GROUPS];
        let mut scaled = vec![[0.0; LANES]; d];
        for (c, chunk) in points.chunks(LANES * GROUPS).enumerate() {
            let groups = chunk.len().div_ceil(LANES);
            for (g, group) in chunk.chunks(LANES).enumerate() {
                let b = group.len();
                let start = c * LANES * GROUPS + g * LANES;
                // Lanes past the end of a short group repeat its last point (discarded).
                for t in 0..LANES {
                    let point = &group[t.min(b - 1)];
                    for (k, lanes) in scaled.iter_mut().enumerate() {
                        lanes[t] = self.input_scaling.apply(k, point[k]);
                    }
                }
                let offset = if variance.is_some() { g * size } else { 0 };
                let dots = cross_kernel_rows(
                    &self.x.values,
                    n,
                    &scaled,
                    &neg_half_weights,
                    signal,
                    &self.alpha,
                    &mut rows[offset..offset + n * LANES],
                );
                for (m, dot) in mean[start..start + b].iter_mut().zip(dots) {
                    *m = scaling.invert(dot);
                }
            }
            if let Some(variance) = variance.as_deref_mut() {
                self.packed_factor
                    .squared_norms(&mut rows[..groups * size], &mut norms[..groups]);
                let start = c * LANES * GROUPS;
                for (v, q) in variance[start..start + chunk.len()]
                    .iter_mut()
                    .zip(norms.iter().flatten())
                {
                    *v = (signal - q).max(0.0) * scaling.std * scaling.std;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::FitOptions;
    use crate::kernel::{Hyperparameters, Kernel};
    use crate::test_data::spec_data;
    use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
    use faer::{MatMut, MatRef, Par};

    /// scikit-learn's fitted θ on the GP reference data of docs/methods.md §7 (standardised y, raw
    /// inputs): GaussianProcessRegressor(C*RBF([.5]*3) + White(1e-3), alpha=1e-10,
    /// normalize_y=True, n_restarts_optimizer=10, random_state=0).kernel_.theta.
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
        let gp = GaussianProcess::with_hyperparameters(&x, &y, h, &opts.check().unwrap()).unwrap();
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
        // scikit-learn's rounded reference values (docs/methods.md §7).
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
        let gp = GaussianProcess::with_hyperparameters(
            &x,
            &y,
            h,
            &FitOptions::default().check().unwrap(),
        )
        .unwrap();
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
            // Every point goes through the same operations whatever its batch.
            assert_eq!(one.mean[0], all.mean[i], "{i}");
            assert_eq!(one.variance[0], all.variance[i], "{i}");
        }
        // The packed forward substitution agrees with faer's triangular solve to round-off.
        let n = gp.x.n;
        let mut ws = crate::log_marginal_likelihood::LmlWorkspace::new(n);
        ws.factorize(&gp.x, &gp.hyperparameters, gp.jitter).unwrap();
        let cholesky = ws.into_factor().0;
        let weights = gp.hyperparameters.inverse_squared_length_scales(3);
        let c = gp.hyperparameters.signal_variance;
        let s2 = gp.output_scaling.std.powi(2);
        for (i, point) in many.iter().enumerate().step_by(17) {
            let mut col = vec![0.0; n];
            let scaled: Vec<f64> = (0..3)
                .map(|k| gp.input_scaling.apply(k, point[k]))
                .collect();
            crate::log_marginal_likelihood::rbf_column(
                &gp.x.values,
                n,
                0,
                &scaled,
                &weights,
                c,
                &mut col,
            );
            solve_lower_triangular_in_place(
                MatRef::from_column_major_slice(&cholesky, n, n),
                MatMut::from_column_major_slice_mut(&mut col, n, 1),
                Par::Seq,
            );
            let reference = (c - col.iter().map(|v| v * v).sum::<f64>()).max(0.0) * s2;
            // The variance c − ‖L⁻¹k*‖² cancels: round-off is relative to c·s².
            assert!((all.variance[i] - reference).abs() <= 1e-12 * c * s2, "{i}");
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
            &FitOptions::default().check().unwrap(),
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
        let gp = GaussianProcess::with_hyperparameters(
            &x,
            &y,
            h,
            &FitOptions::default().check().unwrap(),
        )
        .unwrap();
        let n = gp.x.n;
        let mut ws = crate::log_marginal_likelihood::LmlWorkspace::new(n);
        ws.factorize(&gp.x, &gp.hyperparameters, gp.jitter).unwrap();
        let cholesky = ws.into_factor().0;
        let l = MatRef::from_column_major_slice(&cholesky, n, n);
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
