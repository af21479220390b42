//! The exact log marginal likelihood of a GP and its analytic gradient in log space.
//!
//! With K = c·R + (σ² + j)·I (R the unit-variance squared-exponential matrix, j the jitter
//! that scikit-learn calls `alpha`), K = LLᵀ its Cholesky factor and α = K⁻¹y:
//!
//! LML(θ) = −½ yᵀα − Σ_i ln L_ii − (n/2) ln 2π,
//!
//! ∂LML/∂θ_p = ½ tr((ααᵀ − K⁻¹) ∂K/∂θ_p) = ½ Σ_ij W_ij (∂K/∂θ_p)_ij,  W = ααᵀ − K⁻¹,
//!
//! with ∂K/∂ln c = c·R, ∂K_ij/∂ln l_k = c·R_ij·(x_ik − x_jk)²/l_k² (summed over k for an
//! isotropic l) and ∂K/∂ln σ² = σ²·I (the jitter is a constant). K⁻¹ is formed from the
//! Cholesky factor (only here: predictions never form an inverse). After the O(n³)
//! factorisation and inversion, the gradient is one pass over the lower triangle, O(n²·d),
//! using the symmetry of W and of ∂K (off-diagonal pairs counted once, twice weighted) and the
//! zero diagonal of the length-scale derivatives; no n×n×p tensor is built.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt;
use faer::linalg::triangular_solve;
use faer::{MatMut, MatRef, Par};

use crate::data::{ColumnMajor, validate_points, validate_values};
use crate::error::{GpError, Result};
use crate::kernel::{Hyperparameters, Kernel, LengthScales, Variance};
use crate::vector_math::{exp, multiversion};

/// ln 2π.
const LN_2PI: f64 = 1.837_877_066_409_345_5;

/// The log marginal likelihood at one θ and its gradient with respect to θ.
#[derive(Debug, Clone, PartialEq)]
pub struct LogMarginalLikelihood {
    /// LML(θ) = −½ yᵀK⁻¹y − ½ ln det K − (n/2) ln 2π.
    pub value: f64,
    /// ∂LML/∂θ, in the order of θ = (ln c, ln l…, ln σ²) (fixed entries left out).
    pub gradient: Vec<f64>,
}

/// The log marginal likelihood and its gradient at `theta` on the data (`x`, `y`) as given
/// (no input scaling, no output standardisation), with `jitter` added to the diagonal of K.
///
/// θ = (ln c, ln l_1 … ln l_p, ln σ²), leaving out the entries `kernel` fixes.
///
/// # Errors
/// Fewer than 2 points, ragged or non-finite data, a θ of the wrong length, a negative or
/// non-finite jitter, or a K that is not numerically positive definite.
pub fn log_marginal_likelihood(
    x: &[Vec<f64>],
    y: &[f64],
    kernel: &Kernel,
    theta: &[f64],
    jitter: f64,
) -> Result<LogMarginalLikelihood> {
    kernel.validate()?;
    let d = validate_points(x, "training point", None)?;
    if x.len() < 2 {
        return Err(GpError::TooFewPoints {
            required: 2,
            actual: x.len(),
        });
    }
    if y.len() != x.len() {
        return Err(GpError::LengthMismatch {
            what: "outputs vs. training points",
            expected: x.len(),
            actual: y.len(),
        });
    }
    validate_values(y, "output")?;
    validate_jitter(jitter)?;
    let h = kernel.hyperparameters(theta, d)?;
    let cols = ColumnMajor::from_rows(x, d, |_, v| v);
    let mut ws = LmlWorkspace::new(x.len());
    let mut gradient = vec![0.0; theta.len()];
    let value = ws.evaluate(&cols, y, kernel, &h, jitter, Some(&mut gradient))?;
    Ok(LogMarginalLikelihood { value, gradient })
}

/// Checks that the jitter is finite and non-negative.
pub(crate) fn validate_jitter(jitter: f64) -> Result<()> {
    if jitter.is_finite() && jitter >= 0.0 {
        Ok(())
    } else {
        Err(GpError::InvalidParameter {
            what: "jitter",
            reason: format!("must be finite and non-negative, got {jitter}"),
        })
    }
}

multiversion! {
    /// out[i] = c·exp(−½ Σ_k w_k (x_k[start + i] − p_k)²) for i = 0..n − start: one column of a
    /// (cross-)kernel matrix, `x` column-major with n rows, `p` the other point.
    pub(crate) fn rbf_column(
        x: &[f64],
        n: usize,
        start: usize,
        point: &[f64],
        weights: &[f64],
        c: f64,
        out: &mut [f64],
    ) {
        let out = &mut out[..n - start];
        out.fill(0.0);
        for (k, (&pk, &wk)) in point.iter().zip(weights).enumerate() {
            let col = &x[k * n + start..(k + 1) * n];
            let w = -0.5 * wk;
            for (o, &v) in out.iter_mut().zip(col) {
                let t = v - pk;
                *o += w * t * t;
            }
        }
        for o in out.iter_mut() {
            *o = c * exp(*o);
        }
    }
}

/// Σ_i v_i with eight independent partial sums (vectorisable, fixed order).
#[inline(always)]
pub(crate) fn lane_sum(v: &[f64]) -> f64 {
    let mut lanes = [0.0; 8];
    let chunks = v.chunks_exact(8);
    let rest = chunks.remainder();
    for c in chunks {
        for (l, &x) in lanes.iter_mut().zip(c) {
            *l += x;
        }
    }
    let mut s = ((lanes[0] + lanes[4]) + (lanes[1] + lanes[5]))
        + ((lanes[2] + lanes[6]) + (lanes[3] + lanes[7]));
    for &x in rest {
        s += x;
    }
    s
}

/// Σ_i a_i·b_i with eight independent partial sums (vectorisable, fixed order).
#[inline(always)]
pub(crate) fn lane_dot(a: &[f64], b: &[f64]) -> f64 {
    let m = a.len().min(b.len());
    let (a, b) = (&a[..m], &b[..m]);
    let mut lanes = [0.0; 8];
    let ca = a.chunks_exact(8);
    let cb = b.chunks_exact(8);
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for l in 0..8 {
            lanes[l] += x[l] * y[l];
        }
    }
    let mut s = ((lanes[0] + lanes[4]) + (lanes[1] + lanes[5]))
        + ((lanes[2] + lanes[6]) + (lanes[3] + lanes[7]));
    for (x, y) in ra.iter().zip(rb) {
        s += x * y;
    }
    s
}

/// Σ_i w_i·(x_i − p)² with eight independent partial sums.
#[inline(always)]
fn lane_weighted_square_distance(w: &[f64], x: &[f64], p: f64) -> f64 {
    let m = w.len().min(x.len());
    let (w, x) = (&w[..m], &x[..m]);
    let mut lanes = [0.0; 8];
    let cw = w.chunks_exact(8);
    let cx = x.chunks_exact(8);
    let (rw, rx) = (cw.remainder(), cx.remainder());
    for (a, b) in cw.zip(cx) {
        for l in 0..8 {
            let t = b[l] - p;
            lanes[l] += a[l] * t * t;
        }
    }
    let mut s = ((lanes[0] + lanes[4]) + (lanes[1] + lanes[5]))
        + ((lanes[2] + lanes[6]) + (lanes[3] + lanes[7]));
    for (a, b) in rw.iter().zip(rx) {
        let t = b - p;
        s += a * t * t;
    }
    s
}

multiversion! {
    /// Adds column j's share of the gradient sums: with w_i = (α_iα_j − K⁻¹_ij)·cR_ij over the
    /// rows i > j, acc[0] += Σ_i w_i and acc[1 + k] += Σ_i w_i (x_ik − x_jk)².
    fn gradient_column(
        points: &ColumnMajor,
        j: usize,
        alpha: &[f64],
        kinv_col: &[f64],
        kr_col: &[f64],
        w: &mut [f64],
        acc: &mut [f64],
    ) {
        let (x, n) = (&points.values, points.n);
        let m = n - j - 1;
        let (kinv_col, kr_col, w) = (&kinv_col[..m], &kr_col[..m], &mut w[..m]);
        let a = &alpha[j + 1..j + 1 + m];
        let aj = alpha[j];
        for i in 0..m {
            w[i] = (a[i] * aj - kinv_col[i]) * kr_col[i];
        }
        acc[0] += lane_sum(w);
        for (k, slot) in acc[1..].iter_mut().enumerate() {
            let col = &x[k * n + j + 1..(k + 1) * n];
            *slot += lane_weighted_square_distance(w, col, x[k * n + j]);
        }
    }
}

/// Reusable buffers for repeated LML evaluations on one training set (one per optimiser run).
pub(crate) struct LmlWorkspace {
    n: usize,
    /// c·R, lower triangle, column-major n×n.
    kr: Vec<f64>,
    /// L, lower triangle, column-major n×n.
    chol: Vec<f64>,
    /// K⁻¹, lower triangle, column-major n×n (filled by `invert`).
    kinv: Vec<f64>,
    /// α = K⁻¹y.
    alpha: Vec<f64>,
    /// Per-column weights of the gradient pass.
    w: Vec<f64>,
    /// Scratch memory of faer.
    stack: MemBuffer,
}

impl LmlWorkspace {
    /// Buffers for n training points.
    pub fn new(n: usize) -> Self {
        let par = Par::Seq;
        let req = llt::factor::cholesky_in_place_scratch::<f64>(n, par, Default::default())
            .or(llt::inverse::inverse_scratch::<f64>(n, par));
        Self {
            n,
            kr: vec![0.0; n * n],
            chol: vec![0.0; n * n],
            kinv: vec![0.0; n * n],
            alpha: vec![0.0; n],
            w: vec![0.0; n],
            stack: MemBuffer::new(req),
        }
    }

    /// Builds c·R and K = c·R + (σ² + jitter)I and factorises K = LLᵀ.
    pub fn factorize(&mut self, x: &ColumnMajor, h: &Hyperparameters, jitter: f64) -> Result<()> {
        let n = self.n;
        let weights = h.inverse_squared_length_scales(x.d);
        let c = h.signal_variance;
        let diag = h.noise_variance + jitter;
        let mut point = vec![0.0; x.d];
        for j in 0..n {
            for (k, p) in point.iter_mut().enumerate() {
                *p = x.values[k * n + j];
            }
            let col = &mut self.kr[j * n + j..(j + 1) * n];
            rbf_column(&x.values, n, j, &point, &weights, c, col);
            let lcol = &mut self.chol[j * n + j..(j + 1) * n];
            lcol.copy_from_slice(col);
            lcol[0] += diag;
        }
        let l = MatMut::from_column_major_slice_mut(&mut self.chol, n, n);
        llt::factor::cholesky_in_place(
            l,
            Default::default(),
            Par::Seq,
            MemStack::new(&mut self.stack),
            Default::default(),
        )
        .map_err(|e| match e {
            llt::factor::LltError::NonPositivePivot { index } => {
                GpError::NotPositiveDefinite { pivot: index }
            }
        })?;
        if let Some(pivot) = (0..n).find(|&i| {
            let v = self.chol[i * n + i];
            !(v.is_finite() && v > 0.0)
        }) {
            return Err(GpError::NotPositiveDefinite { pivot });
        }
        Ok(())
    }

    /// α = K⁻¹y from the factor, and LML = −½ yᵀα − Σ ln L_ii − (n/2) ln 2π.
    pub fn solve(&mut self, y: &[f64]) -> f64 {
        let n = self.n;
        self.alpha.copy_from_slice(y);
        let l = MatRef::from_column_major_slice(&self.chol, n, n);
        let mut a = MatMut::from_column_major_slice_mut(&mut self.alpha, n, 1);
        triangular_solve::solve_lower_triangular_in_place(l, a.as_mut(), Par::Seq);
        triangular_solve::solve_upper_triangular_in_place(l.transpose(), a.as_mut(), Par::Seq);
        let fit = lane_dot(y, &self.alpha);
        let log_det_half: f64 = (0..n).map(|i| self.chol[i * n + i].ln()).sum();
        -0.5 * fit - log_det_half - 0.5 * n as f64 * LN_2PI
    }

    /// K⁻¹ (lower triangle) from the factor: K⁻¹ = L⁻ᵀL⁻¹.
    pub fn invert(&mut self) {
        let n = self.n;
        let l = MatRef::from_column_major_slice(&self.chol, n, n);
        let out = MatMut::from_column_major_slice_mut(&mut self.kinv, n, n);
        llt::inverse::inverse(out, l, Par::Seq, MemStack::new(&mut self.stack));
    }

    /// ∂LML/∂θ after `factorize`, `solve` and `invert` at `h`.
    pub fn gradient(
        &mut self,
        x: &ColumnMajor,
        kernel: &Kernel,
        h: &Hyperparameters,
        out: &mut [f64],
    ) {
        let n = self.n;
        let d = x.d;
        let mut acc = vec![0.0; d + 1];
        for j in 0..n.saturating_sub(1) {
            let lo = j * n + j + 1;
            let hi = (j + 1) * n;
            gradient_column(
                x,
                j,
                &self.alpha,
                &self.kinv[lo..hi],
                &self.kr[lo..hi],
                &mut self.w,
                &mut acc,
            );
        }
        // Diagonal: ½ Σ_i (α_i² − K⁻¹_ii) times c (signal) or σ² (noise).
        let trace_w: f64 = (0..n)
            .map(|i| self.alpha[i] * self.alpha[i] - self.kinv[i * n + i])
            .sum();
        let weights = h.inverse_squared_length_scales(d);
        let mut it = out.iter_mut();
        if kernel.signal_variance == Variance::Estimated
            && let Some(g) = it.next()
        {
            *g = acc[0] + 0.5 * h.signal_variance * trace_w;
        }
        match kernel.length_scales {
            LengthScales::Ard => {
                for k in 0..d {
                    if let Some(g) = it.next() {
                        *g = acc[1 + k] * weights[k];
                    }
                }
            }
            LengthScales::Isotropic => {
                if let Some(g) = it.next() {
                    *g = acc[1..].iter().sum::<f64>() * weights[0];
                }
            }
        }
        if kernel.noise_variance == Variance::Estimated
            && let Some(g) = it.next()
        {
            *g = 0.5 * h.noise_variance * trace_w;
        }
    }

    /// LML at `h`, and its gradient into `gradient` when given.
    pub fn evaluate(
        &mut self,
        x: &ColumnMajor,
        y: &[f64],
        kernel: &Kernel,
        h: &Hyperparameters,
        jitter: f64,
        gradient: Option<&mut [f64]>,
    ) -> Result<f64> {
        self.factorize(x, h, jitter)?;
        let value = self.solve(y);
        if let Some(g) = gradient {
            self.invert();
            self.gradient(x, kernel, h, g);
        }
        if value.is_finite() {
            Ok(value)
        } else {
            Err(GpError::NotPositiveDefinite { pivot: 0 })
        }
    }

    /// The Cholesky factor (lower triangle, column-major n×n).
    #[cfg(test)]
    pub fn cholesky(&self) -> &[f64] {
        &self.chol
    }

    /// α = K⁻¹y of the last `solve`.
    pub fn alpha(&self) -> &[f64] {
        &self.alpha
    }

    /// The diagonal of K⁻¹ after `invert`.
    pub fn inverse_diagonal(&self) -> Vec<f64> {
        (0..self.n).map(|i| self.kinv[i * self.n + i]).collect()
    }

    /// Moves the factor and α out.
    pub fn into_factor(self) -> (Vec<f64>, Vec<f64>) {
        (self.chol, self.alpha)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_data::{spec_data, standardized};

    const THETA0: [f64; 5] = [
        0.0,
        -std::f64::consts::LN_2,
        -std::f64::consts::LN_2,
        -std::f64::consts::LN_2,
        -6.907_755_278_982_137,
    ];

    fn assert_rel(actual: f64, expected: f64, tol: f64) {
        let rel = (actual - expected).abs() / expected.abs().max(1e-300);
        assert!(
            rel <= tol,
            "actual {actual}, expected {expected}, rel {rel:e}"
        );
    }

    #[test]
    fn spec_reference_unnormalised() {
        let (x, y) = spec_data();
        let r = log_marginal_likelihood(&x, &y, &Kernel::ard(), &THETA0, 1e-10).unwrap();
        assert_rel(r.value, -10.343558839714, 1e-8);
        let g = [
            41.74700536179,
            -329.701381395262,
            56.779574328817,
            58.974224543587,
            1.549441788443,
        ];
        for (a, e) in r.gradient.iter().zip(g) {
            assert_rel(*a, e, 1e-8);
        }
    }

    #[test]
    fn spec_reference_standardised() {
        let (x, y) = spec_data();
        let ys = standardized(&y);
        let r = log_marginal_likelihood(&x, &ys, &Kernel::ard(), &THETA0, 1e-10).unwrap();
        assert_rel(r.value, -61.084621841727, 1e-8);
        let g = [
            84.801749252827,
            -589.134991402461,
            70.133401697172,
            73.284950809326,
            9.235760130788,
        ];
        for (a, e) in r.gradient.iter().zip(g) {
            assert_rel(*a, e, 1e-8);
        }
    }

    /// Central differences of the value against the analytic gradient, for every variant.
    #[test]
    fn gradient_matches_finite_differences_for_every_kernel_variant() {
        let (x, y) = spec_data();
        let x: Vec<Vec<f64>> = x.into_iter().take(40).collect();
        let y = standardized(&y[..40]);
        let variants = [
            (Kernel::ard(), vec![0.3, -0.5, 0.2, 0.9, -5.0]),
            (Kernel::isotropic(), vec![0.3, -0.7, -5.0]),
            (Kernel::study_original(), vec![-0.7, -5.0]),
            (
                Kernel {
                    noise_variance: Variance::Fixed(1e-3),
                    ..Kernel::ard()
                },
                vec![0.1, -0.4, 0.3, 1.1],
            ),
            (
                Kernel {
                    signal_variance: Variance::Fixed(2.0),
                    ..Kernel::ard()
                },
                vec![-0.4, 0.3, 1.1, -4.0],
            ),
        ];
        for (kernel, theta) in variants {
            let r = log_marginal_likelihood(&x, &y, &kernel, &theta, 1e-10).unwrap();
            assert_eq!(r.gradient.len(), theta.len());
            for p in 0..theta.len() {
                let h = 1e-5;
                let mut tp = theta.clone();
                tp[p] += h;
                let mut tm = theta.clone();
                tm[p] -= h;
                let fp = log_marginal_likelihood(&x, &y, &kernel, &tp, 1e-10)
                    .unwrap()
                    .value;
                let fm = log_marginal_likelihood(&x, &y, &kernel, &tm, 1e-10)
                    .unwrap()
                    .value;
                let fd = (fp - fm) / (2.0 * h);
                let scale = r.gradient[p].abs().max(1.0);
                assert!(
                    (fd - r.gradient[p]).abs() / scale < 1e-6,
                    "{kernel:?} θ{p}: analytic {} vs fd {fd}",
                    r.gradient[p]
                );
            }
        }
    }

    #[test]
    fn bad_inputs_are_errors() {
        let (x, y) = spec_data();
        let k = Kernel::ard();
        assert!(matches!(
            log_marginal_likelihood(&x[..1], &y[..1], &k, &THETA0, 1e-10),
            Err(GpError::TooFewPoints { .. })
        ));
        assert!(log_marginal_likelihood(&x, &y[..10], &k, &THETA0, 1e-10).is_err());
        assert!(log_marginal_likelihood(&x, &y, &k, &THETA0[..4], 1e-10).is_err());
        assert!(log_marginal_likelihood(&x, &y, &k, &THETA0, -1.0).is_err());
        let mut yb = y.clone();
        yb[3] = f64::NAN;
        assert!(log_marginal_likelihood(&x, &yb, &k, &THETA0, 1e-10).is_err());
        // Duplicate points without noise: K is singular.
        let xd = vec![vec![0.5, 0.5, 0.5]; 3];
        let theta = [0.0, 0.0, 0.0, 0.0, -300.0];
        assert!(matches!(
            log_marginal_likelihood(&xd, &[1.0, 2.0, 3.0], &k, &theta, 0.0),
            Err(GpError::NotPositiveDefinite { .. })
        ));
    }

    /// Where the time of one LML + gradient evaluation goes (not a test; run with
    /// `cargo test --release -p iuq-gp -- --ignored --nocapture profile_lml`). Reports the
    /// minimum over repetitions (robust to other load on the machine).
    #[test]
    #[ignore]
    fn profile_lml_and_gradient() {
        use std::time::Instant;
        fn min_ms(reps: usize, mut f: impl FnMut()) -> f64 {
            (0..reps)
                .map(|_| {
                    let t = Instant::now();
                    f();
                    t.elapsed().as_secs_f64() * 1e3
                })
                .fold(f64::INFINITY, f64::min)
        }
        for n in [250, 500, 1000] {
            let (x, y) = crate::test_data::quasi_random_data(n);
            let y = standardized(&y);
            let cols = ColumnMajor::from_rows(&x, 3, |_, v| v);
            let kernel = Kernel::ard();
            let h = kernel
                .hyperparameters(&[1.0, -0.5, 1.0, 2.0, -9.0], 3)
                .unwrap();
            let mut ws = LmlWorkspace::new(n);
            let reps = (2_000_000_000 / (n * n * n)).clamp(5, 200);
            let mut g = vec![0.0; 5];
            ws.factorize(&cols, &h, 1e-10).unwrap();
            let kernel_matrix = ws.kr.clone();
            let t_factor = min_ms(reps, || ws.factorize(&cols, &h, 1e-10).unwrap());
            let mut a = kernel_matrix.clone();
            let t_chol = min_ms(reps, || {
                a.copy_from_slice(&kernel_matrix);
                for i in 0..n {
                    a[i * n + i] += 1e-4;
                }
                llt::factor::cholesky_in_place(
                    MatMut::from_column_major_slice_mut(&mut a, n, n),
                    Default::default(),
                    Par::Seq,
                    MemStack::new(&mut ws.stack),
                    Default::default(),
                )
                .unwrap();
            });
            let t_solve = min_ms(reps, || {
                ws.solve(&y);
            });
            let t_inv = min_ms(reps, || ws.invert());
            let t_grad = min_ms(reps, || ws.gradient(&cols, &kernel, &h, &mut g));
            let mut linv = vec![0.0; n * n];
            let t_tri = min_ms(reps, || {
                faer::linalg::triangular_inverse::invert_lower_triangular(
                    MatMut::from_column_major_slice_mut(&mut linv, n, n),
                    MatRef::from_column_major_slice(&ws.chol, n, n),
                    Par::Seq,
                )
            });
            let mut prod = vec![0.0; n * n];
            let t_gemm = min_ms(reps, || {
                let li = MatRef::from_column_major_slice(&linv, n, n);
                faer::linalg::matmul::matmul(
                    MatMut::from_column_major_slice_mut(&mut prod, n, n),
                    faer::Accum::Replace,
                    li.transpose(),
                    li,
                    1.0,
                    Par::Seq,
                );
            });
            let gf = |flops: f64, ms: f64| flops / ms / 1e6;
            let n3 = (n * n * n) as f64;
            println!(
                "n={n}: build+factorise {t_factor:.3} ms, of which Cholesky {t_chol:.3} ms ({:.1} GF/s); \
                 solve {t_solve:.3}; inverse {t_inv:.3} ms ({:.1} GF/s), of which L⁻¹ {t_tri:.3}; \
                 gradient pass {t_grad:.3} ms; [dense gemm {:.1} GF/s]",
                gf(n3 / 3.0, t_chol),
                gf(2.0 * n3 / 3.0, t_inv),
                gf(2.0 * n3, t_gemm)
            );
        }
    }
}
