//! The blocked forward substitution behind predictive variances: ‖L⁻¹k*‖² for groups of
//! [`LANES`] points at once, at matrix-multiply speed.
//!
//! The variance of a prediction needs v = L⁻¹k* (n²/2 fused multiply-adds per point), which
//! is almost all of the cost of predicting with variance at n ≈ 500. Here the factor L is
//! stored once per GP in a packed form ([`PackedFactor`]): panels of [`ROWS`] rows, each with
//! its off-diagonal part −L[panel, 0..r₀] laid out column by column and its negated diagonal
//! block and reciprocal pivots apart. For a group of [`LANES`] points whose kernel columns are
//! stored row-major (`v[k·LANES + t]` = k*_t[k]), each panel is one register tile: the
//! [`ROWS`]×[`LANES`] values start as the kernel rows, take −Σ_{k<r₀} L_ik·v_k (a GEMM-shaped
//! update, vectors of [`LANES`] points times broadcast factor entries) and then the in-tile
//! substitution, and are written back as rows of v. Every point therefore gets exactly the
//! textbook forward substitution
//!
//! v_i = (k_i − Σ_{m<i} L_im·v_m)·(1/L_ii),   the sum taken in increasing m by fused multiply-adds,
//!
//! and ‖v‖² = Σ over panels (in order) of the panel's Σ_i v_i² (fused multiply-adds in
//! increasing i). The result for a point does not depend on the other points of its group,
//! on the batch or on the number of threads. The kernel is chosen at run time: plain Rust on
//! arrays of [`LANES`] lanes compiled for AVX-512 (a tile of 24 rows, one register per row) and
//! for the baseline (3 rows), and AVX2+FMA intrinsics (6 rows, two registers per row), for
//! which the compiler had left the plain Rust in scalar code with spills (1.2 GFMA/s per core
//! at n = 500 on an AMD EPYC core without AVX-512; 11.3 with the intrinsics). A 24-row tile on
//! AVX2's 16 registers would spill. Every variant performs the same operations in the same
//! order, so all agree bit for bit with an unvectorised reference (tested). On an AVX-512
//! development machine (quiet) the 24-row tile ran at 24.8 GFMA/s per core at n = 500, 74 % of
//! the core's measured peak of 33.6, where faer's general triangular solve on blocks of
//! 128–1024 points reached 14–15.5 (≈ 45 %) (`cargo test --release -p iuq-gp -- --ignored
//! --nocapture --test-threads=1 kernel_throughput profile_prediction`).
//!
//! Accuracy: forward substitution is backward stable, like faer's blocked triangular solve it
//! replaces (tested to agree to round-off). An explicit inverse L⁻¹ would allow a plain matrix
//! product, but it loses about a digit on ill-conditioned K (cond(K) ≈ 1e13 for a
//! deterministic simulator at the noise bound σ² = 1e−8: errors of the latent variance ≈ 20×
//! those of the substitution against an 80-bit reference), so it is not used. Single
//! precision is useless here: the variance is the difference c − ‖v‖² with ‖v‖² ≈ c, and at
//! c ≈ 1e3, σ² = 1e−8 an f32 substitution gets it wrong by ≈ c itself (measured: errors of
//! 5e2 on variances of 3e−9); the project's rule (f64 unless a test shows f32 is enough)
//! keeps f64.

/// Rows of L per panel (the height of the register tile).
pub(crate) const ROWS: usize = 24;
/// Points per group (the width of the register tile: one AVX-512 vector of f64).
pub(crate) const LANES: usize = 8;

/// The Cholesky factor L (n×n, lower) packed for [`PackedFactor::squared_norms`].
#[derive(Debug, Clone, Default)]
pub(crate) struct PackedFactor {
    panels: usize,
    /// Panel p (rows r₀ = p·ROWS …): −L[r₀ + i, k] at `off_diagonal[offset(p) + k·ROWS + i]`,
    /// k < r₀, offset(p) = ROWS²·p(p − 1)/2.
    off_diagonal: Vec<f64>,
    /// Panel p: −L[r₀ + i, r₀ + m] at `diagonal[p·ROWS² + i·ROWS + m]` for m < i, else 0.
    diagonal: Vec<f64>,
    /// 1/L_ii, 0 for the padding rows i ≥ n.
    reciprocal: Vec<f64>,
}

impl PackedFactor {
    /// Packs the lower triangle of the column-major n×n factor `l`.
    pub(crate) fn new(l: &[f64], n: usize) -> Self {
        let panels = n.div_ceil(ROWS);
        let entry = |i: usize, k: usize| if i < n { -l[k * n + i] } else { 0.0 };
        let mut off_diagonal =
            Vec::with_capacity(ROWS * ROWS * panels * panels.saturating_sub(1) / 2);
        let mut diagonal = vec![0.0; panels * ROWS * ROWS];
        let mut reciprocal = vec![0.0; panels * ROWS];
        for p in 0..panels {
            let r0 = p * ROWS;
            for k in 0..r0 {
                off_diagonal.extend((0..ROWS).map(|i| entry(r0 + i, k)));
            }
            for i in 0..ROWS {
                if r0 + i >= n {
                    continue;
                }
                for m in 0..i {
                    diagonal[p * ROWS * ROWS + i * ROWS + m] = entry(r0 + i, r0 + m);
                }
                reciprocal[p * ROWS + i] = 1.0 / l[(r0 + i) * n + r0 + i];
            }
        }
        Self {
            panels,
            off_diagonal,
            diagonal,
            reciprocal,
        }
    }

    /// Rows of the padded right-hand side: n rounded up to a multiple of [`ROWS`].
    pub(crate) fn padded_rows(&self) -> usize {
        self.panels * ROWS
    }

    /// Replaces the groups of [`LANES`] right-hand sides in `v` (`groups` blocks of
    /// `padded_rows()` rows of [`LANES`] values each, rows ≥ n zero) by L⁻¹·v and writes
    /// their squared norms to `norms` (one array per group).
    ///
    /// Panel by panel: the off-diagonal update of every group in chunks of [`K_CHUNK`]
    /// columns (so that the chunk of the factor stays in the L1 cache while the groups pass
    /// through it; a tile's partial sums wait in `v` between chunks, stored exactly), then
    /// the in-tile substitution of every group. Compiled for AVX-512, AVX2+FMA and the
    /// baseline (see [`blocked_squared_norms`]), chosen at run time; per value, the operations of
    /// [`Self::squared_norms_reference`] in the same order.
    pub(crate) fn squared_norms(&self, v: &mut [f64], norms: &mut [[f64; LANES]]) {
        let size = self.padded_rows() * LANES;
        assert_eq!(v.len(), size * norms.len(), "right-hand side size");
        blocked_squared_norms(self, v, norms);
    }

    /// The panel slices of panel p: (off-diagonal part, diagonal block, reciprocals).
    #[inline(always)]
    fn panel(&self, p: usize) -> (&[f64], &[f64], &[f64]) {
        let r0 = p * ROWS;
        let start = ROWS * ROWS * (p * p.saturating_sub(1) / 2);
        (
            &self.off_diagonal[start..start + r0 * ROWS],
            &self.diagonal[p * ROWS * ROWS..(p + 1) * ROWS * ROWS],
            &self.reciprocal[p * ROWS..(p + 1) * ROWS],
        )
    }

    /// The reference: group by group, panel by panel, without chunks or vector extensions.
    #[cfg(test)]
    pub(crate) fn squared_norms_reference(&self, v: &mut [f64], norms: &mut [[f64; LANES]]) {
        let size = self.padded_rows() * LANES;
        assert_eq!(v.len(), size * norms.len(), "right-hand side size");
        for (group, total) in v.chunks_exact_mut(size).zip(norms.iter_mut()) {
            *total = [0.0; LANES];
            for p in 0..self.panels {
                let (a, diagonal, reciprocal) = self.panel(p);
                let r0 = p * ROWS;
                let (done, rest) = group.split_at_mut(r0 * LANES);
                let tile = &mut rest[..ROWS * LANES];
                update::<ROWS>(a, done, tile, 0);
                let s = solve(diagonal, reciprocal, tile);
                for (t, s) in total.iter_mut().zip(s) {
                    *t += s;
                }
            }
        }
    }
}

/// Columns of the factor per chunk of the off-diagonal update: 128·ROWS doubles = 24 KiB,
/// half of a 48 KiB L1 data cache.
const K_CHUNK: usize = 128;

/// [`PackedFactor::squared_norms`] (sizes checked by the caller), dispatched at run time to
/// the variant compiled for the CPU. The variants differ only in how many rows of a tile
/// the off-diagonal update holds in registers at once ([`TileKernel::SUB`]): the whole tile
/// (24 rows of 8 lanes: 24 of AVX-512's 32 vector registers), 6 rows with AVX2+FMA (12 of its
/// 16 registers of 4 doubles, written with intrinsics: [`avx2`]), and 3 rows on the x86-64
/// baseline (SSE2, 16 registers of 2 doubles; 6 on other architectures, e.g. NEON's 32). Every
/// variant performs the same operations on every value in the same order, so all agree bit for
/// bit.
fn blocked_squared_norms(packed: &PackedFactor, v: &mut [f64], norms: &mut [[f64; LANES]]) {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx512f,avx2,fma")]
        unsafe fn v4(packed: &PackedFactor, v: &mut [f64], norms: &mut [[f64; LANES]]) {
            blocked_squared_norms_with::<Portable<24>>(packed, v, norms)
        }
        #[target_feature(enable = "avx2,fma")]
        unsafe fn v3(packed: &PackedFactor, v: &mut [f64], norms: &mut [[f64; LANES]]) {
            blocked_squared_norms_with::<avx2::Avx2>(packed, v, norms)
        }
        if std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the CPU supports every feature `v4` is compiled for.
            return unsafe { v4(packed, v, norms) };
        }
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the CPU supports every feature `v3` is compiled for.
            return unsafe { v3(packed, v, norms) };
        }
        blocked_squared_norms_with::<Portable<3>>(packed, v, norms)
    }
    #[cfg(not(target_arch = "x86_64"))]
    blocked_squared_norms_with::<Portable<6>>(packed, v, norms)
}

/// The two register-tile operations of the substitution, per instruction set: the off-diagonal
/// update of [`Self::SUB`] rows of a tile ([`update`]'s contract) and the in-tile substitution
/// ([`solve`]'s). Every implementation performs the same operations on every value in the same
/// order.
trait TileKernel {
    /// Rows of a tile the update holds in registers at once (divides [`ROWS`]).
    const SUB: usize;
    /// The update of rows `first..first + SUB` of `tile` by the columns of `a` and rows of `v`.
    fn update(a: &[f64], v: &[f64], tile: &mut [f64], first: usize);
    /// The substitution of one tile; returns Σ_i v_i² over its rows.
    fn solve(diagonal: &[f64], reciprocal: &[f64], tile: &mut [f64]) -> [f64; LANES];
}

/// Plain Rust on arrays of [`LANES`] lanes, vectorised by the compiler where the instruction
/// set of the calling function allows it (AVX-512: one register per row of a tile).
struct Portable<const SUB: usize>;

impl<const SUB: usize> TileKernel for Portable<SUB> {
    const SUB: usize = SUB;
    #[inline(always)]
    fn update(a: &[f64], v: &[f64], tile: &mut [f64], first: usize) {
        update::<SUB>(a, v, tile, first)
    }
    #[inline(always)]
    fn solve(diagonal: &[f64], reciprocal: &[f64], tile: &mut [f64]) -> [f64; LANES] {
        solve(diagonal, reciprocal, tile)
    }
}

/// The packed substitution with the tile operations of `K`, the off-diagonal update done
/// `K::SUB` rows of a tile at a time (see [`blocked_squared_norms`]).
#[inline(always)]
fn blocked_squared_norms_with<K: TileKernel>(
    packed: &PackedFactor,
    v: &mut [f64],
    norms: &mut [[f64; LANES]],
) {
    const { assert!(K::SUB > 0 && ROWS % K::SUB == 0) };
    let size = packed.padded_rows() * LANES;
    for total in norms.iter_mut() {
        *total = [0.0; LANES];
    }
    for p in 0..packed.panels {
        let (a, diagonal, reciprocal) = packed.panel(p);
        let r0 = p * ROWS;
        let mut k0 = 0;
        while k0 < r0 {
            let k1 = (k0 + K_CHUNK).min(r0);
            let chunk = &a[k0 * ROWS..k1 * ROWS];
            for group in v.chunks_exact_mut(size) {
                let (done, rest) = group.split_at_mut(r0 * LANES);
                let done = &done[k0 * LANES..k1 * LANES];
                for first in (0..ROWS).step_by(K::SUB) {
                    K::update(chunk, done, &mut rest[..ROWS * LANES], first);
                }
            }
            k0 = k1;
        }
        for (group, total) in v.chunks_exact_mut(size).zip(norms.iter_mut()) {
            let tile = &mut group[r0 * LANES..(r0 + ROWS) * LANES];
            let s = K::solve(diagonal, reciprocal, tile);
            for (t, s) in total.iter_mut().zip(s) {
                *t += s;
            }
        }
    }
}

/// c = fma(a, b, c) lane by lane (one vector instruction).
#[inline(always)]
fn fma_lanes(a: f64, b: &[f64; LANES], c: &mut [f64; LANES]) {
    for (c, &b) in c.iter_mut().zip(b) {
        *c = a.mul_add(b, *c);
    }
}

/// Calls `$body` with `$i` bound to each of 0..ROWS as a constant: the rows of a tile are
/// written out instead of looped over, so that the compiler keeps one vector register per row
/// (a loop over rows gets vectorised across rows, with gathers, instead).
macro_rules! for_each_row {
    ($i:ident => $body:expr) => {
        for_each_row!(@ $i => $body; 0 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20 21 22 23)
    };
    (@ $i:ident => $body:expr; $($n:literal)*) => {
        $( { const $i: usize = $n; $body; } )*
    };
}

/// The off-diagonal update of rows `first..first + SUB` of one tile:
/// tile_i = fma(−L_ik, v_k, tile_i) for the columns k of `a` (ROWS negated values per column)
/// and the rows of `v` (LANES values per row), in order. The SUB × LANES values are held in
/// registers (one vector per row with AVX-512, two with AVX2).
#[inline(always)]
#[expect(
    clippy::expect_used,
    reason = "the slices' lengths are fixed by chunks_exact and the tile's layout: no input reaches the panics"
)]
fn update<const SUB: usize>(a: &[f64], v: &[f64], tile: &mut [f64], first: usize) {
    let tile = &mut tile[first * LANES..(first + SUB) * LANES];
    let mut acc = [[0.0f64; LANES]; SUB];
    for (row, t) in acc.iter_mut().zip(tile.chunks_exact(LANES)) {
        row.copy_from_slice(t);
    }
    for (vk, ak) in v.chunks_exact(LANES).zip(a.chunks_exact(ROWS)) {
        let vk: [f64; LANES] = vk.try_into().expect("LANES values");
        let ak: &[f64; SUB] = ak[first..first + SUB].try_into().expect("SUB values");
        for_each_row!(I => if I < SUB {
            fma_lanes(ak[I], &vk, &mut acc[I])
        });
    }
    for (row, t) in acc.iter().zip(tile.chunks_exact_mut(LANES)) {
        t.copy_from_slice(row);
    }
}

/// Row I of the in-tile substitution: x = acc_I; x = fma(−L_Im, v_m, x) for m < I in
/// order; v_I = x·(1/L_II).
#[inline(always)]
fn solve_row<const I: usize>(
    acc: &mut [[f64; LANES]; ROWS],
    diagonal: &[f64; ROWS * ROWS],
    reciprocal: &[f64; ROWS],
) {
    let mut x = acc[I];
    for m in 0..I {
        fma_lanes(diagonal[I * ROWS + m], &acc[m], &mut x);
    }
    let r = reciprocal[I];
    for x in x.iter_mut() {
        *x *= r;
    }
    acc[I] = x;
}

/// The in-tile substitution of one tile (after its off-diagonal update): writes v back and
/// returns Σ_i v_i² over its rows (fused multiply-adds in increasing i).
#[inline(always)]
#[expect(
    clippy::expect_used,
    reason = "the diagonal block and reciprocals are ROWS² and ROWS values by the tile's layout: no input reaches the panics"
)]
fn solve(diagonal: &[f64], reciprocal: &[f64], tile: &mut [f64]) -> [f64; LANES] {
    let diagonal: &[f64; ROWS * ROWS] = diagonal.try_into().expect("ROWS² values");
    let reciprocal: &[f64; ROWS] = reciprocal.try_into().expect("ROWS values");
    let mut acc = [[0.0f64; LANES]; ROWS];
    for (row, t) in acc.iter_mut().zip(tile.chunks_exact(LANES)) {
        row.copy_from_slice(t);
    }
    for_each_row!(I => solve_row::<I>(&mut acc, diagonal, reciprocal));
    let mut s = [0.0f64; LANES];
    for_each_row!(I => {
        let row = acc[I];
        for (x, &y) in s.iter_mut().zip(&row) {
            *x = y.mul_add(y, *x);
        }
    });
    for (row, t) in acc.iter().zip(tile.chunks_exact_mut(LANES)) {
        t.copy_from_slice(row);
    }
    s
}

/// The tile operations with AVX2 and FMA intrinsics: a row of a tile is two registers of four
/// lanes. Written out because the compiler's vectoriser left [`Portable`]'s arrays in scalar
/// code with spills for this instruction set (1.2 GFMA/s at n = 500 on an AMD EPYC core).
#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::{LANES, ROWS, TileKernel};
    use std::arch::x86_64::{
        __m256d, _mm256_fmadd_pd, _mm256_loadu_pd, _mm256_mul_pd, _mm256_set1_pd,
        _mm256_setzero_pd, _mm256_storeu_pd,
    };

    /// Rows of a tile the update holds in registers: 12 of AVX2's 16 vector registers.
    const SUB: usize = 6;

    /// [`TileKernel`] for AVX2 + FMA; only called from functions compiled for both (the
    /// dispatch's `v3`), into which it is inlined.
    pub(super) struct Avx2;

    /// Lanes `4h..4h + 4` of row `i` of a row-major tile of [`LANES`] lanes.
    ///
    /// # Safety
    /// `(i + 1)·LANES ≤ tile.len()`, `h < 2`, and the CPU supports AVX.
    #[inline(always)]
    unsafe fn load(tile: &[f64], i: usize, h: usize) -> __m256d {
        // SAFETY: in bounds by the caller's contract.
        unsafe { _mm256_loadu_pd(tile.as_ptr().add(i * LANES + 4 * h)) }
    }

    /// Stores `x` as lanes `4h..4h + 4` of row `i` (the contract of [`load`]).
    #[inline(always)]
    unsafe fn store(tile: &mut [f64], i: usize, h: usize, x: __m256d) {
        // SAFETY: in bounds by the caller's contract.
        unsafe { _mm256_storeu_pd(tile.as_mut_ptr().add(i * LANES + 4 * h), x) }
    }

    impl TileKernel for Avx2 {
        const SUB: usize = SUB;

        #[inline(always)]
        fn update(a: &[f64], v: &[f64], tile: &mut [f64], first: usize) {
            let columns = (v.len() / LANES).min(a.len() / ROWS);
            let tile = &mut tile[first * LANES..(first + SUB) * LANES];
            // SAFETY: `tile` holds SUB rows (sliced above), `v` and `a` at least `columns` rows
            // of LANES and ROWS values, and first + SUB ≤ ROWS (the callers step `first` by SUB
            // through 0..ROWS); AVX2 and FMA by the caller's compilation (type docs).
            unsafe {
                let mut lo = [_mm256_setzero_pd(); SUB];
                let mut hi = [_mm256_setzero_pd(); SUB];
                for i in 0..SUB {
                    lo[i] = load(tile, i, 0);
                    hi[i] = load(tile, i, 1);
                }
                for k in 0..columns {
                    let vk = &v[k * LANES..];
                    let (v_lo, v_hi) = (load(vk, 0, 0), load(vk, 0, 1));
                    let ak = a.as_ptr().add(k * ROWS + first);
                    for i in 0..SUB {
                        let aik = _mm256_set1_pd(*ak.add(i));
                        lo[i] = _mm256_fmadd_pd(aik, v_lo, lo[i]);
                        hi[i] = _mm256_fmadd_pd(aik, v_hi, hi[i]);
                    }
                }
                for i in 0..SUB {
                    store(tile, i, 0, lo[i]);
                    store(tile, i, 1, hi[i]);
                }
            }
        }

        #[inline(always)]
        fn solve(diagonal: &[f64], reciprocal: &[f64], tile: &mut [f64]) -> [f64; LANES] {
            let diagonal = &diagonal[..ROWS * ROWS];
            let reciprocal = &reciprocal[..ROWS];
            let tile = &mut tile[..ROWS * LANES];
            let mut total = [0.0; LANES];
            // SAFETY: the slices above hold ROWS² values, ROWS values and ROWS rows; AVX2 and
            // FMA by the caller's compilation (type docs).
            unsafe {
                let mut acc = [[_mm256_setzero_pd(); 2]; ROWS];
                for (i, row) in acc.iter_mut().enumerate() {
                    *row = [load(tile, i, 0), load(tile, i, 1)];
                }
                for i in 0..ROWS {
                    let mut x = acc[i];
                    for m in 0..i {
                        let l = _mm256_set1_pd(diagonal[i * ROWS + m]);
                        x[0] = _mm256_fmadd_pd(l, acc[m][0], x[0]);
                        x[1] = _mm256_fmadd_pd(l, acc[m][1], x[1]);
                    }
                    let r = _mm256_set1_pd(reciprocal[i]);
                    acc[i] = [_mm256_mul_pd(x[0], r), _mm256_mul_pd(x[1], r)];
                }
                let mut s = [_mm256_setzero_pd(); 2];
                for (i, row) in acc.iter().enumerate() {
                    for h in 0..2 {
                        s[h] = _mm256_fmadd_pd(row[h], row[h], s[h]);
                        store(tile, i, h, row[h]);
                    }
                }
                store(&mut total[..], 0, 0, s[0]);
                store(&mut total[..], 0, 1, s[1]);
            }
            total
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::linalg::triangular_solve::solve_lower_triangular_in_place;
    use faer::{MatMut, MatRef, Par};

    /// A well-conditioned lower factor with n not a multiple of ROWS.
    fn factor(n: usize) -> Vec<f64> {
        let mut l = vec![0.0; n * n];
        for k in 0..n {
            for i in k..n {
                let h = ((i * 7919 + k * 104_729) % 1000) as f64 / 1000.0;
                l[k * n + i] = if i == k {
                    2.0 + h
                } else {
                    0.3 * (h - 0.5) / (1.0 + (i - k) as f64).sqrt()
                };
            }
        }
        l
    }

    #[test]
    fn matches_a_triangular_solve_and_every_path_agrees() {
        const GROUPS: usize = 3;
        for n in [1, 5, 24, 25, 61, 130, 300] {
            let l = factor(n);
            let packed = PackedFactor::new(&l, n);
            let rows = packed.padded_rows();
            let size = rows * LANES;
            let value =
                |g: usize, k: usize, t: usize| ((k * 31 + t * 17 + g * 7) % 97) as f64 / 97.0 - 0.3;
            let mut rhs = vec![0.0; GROUPS * size];
            for g in 0..GROUPS {
                for k in 0..n {
                    for t in 0..LANES {
                        rhs[g * size + k * LANES + t] = value(g, k, t);
                    }
                }
            }
            let mut a = rhs.clone();
            let mut norms = [[0.0; LANES]; GROUPS];
            packed.squared_norms(&mut a, &mut norms);
            let mut b = rhs.clone();
            let mut norms_portable = [[0.0; LANES]; GROUPS];
            packed.squared_norms_reference(&mut b, &mut norms_portable);
            assert_eq!(
                a, b,
                "n = {n}: the dispatched and the reference path differ"
            );
            assert_eq!(norms, norms_portable);
            for g in 0..GROUPS {
                // Reference: faer's solve on the column-major copy.
                let mut cols = vec![0.0; n * LANES];
                for k in 0..n {
                    for t in 0..LANES {
                        cols[t * n + k] = value(g, k, t);
                    }
                }
                solve_lower_triangular_in_place(
                    MatRef::from_column_major_slice(&l, n, n),
                    MatMut::from_column_major_slice_mut(&mut cols, n, LANES),
                    Par::Seq,
                );
                for t in 0..LANES {
                    let mut reference = 0.0;
                    for k in 0..n {
                        let x = cols[t * n + k];
                        let y = a[g * size + k * LANES + t];
                        assert!(
                            (y - x).abs() <= 1e-13 * (1.0 + x.abs()),
                            "n = {n}, group {g}"
                        );
                        reference += x * x;
                    }
                    let q = norms[g][t];
                    assert!(
                        (q - reference).abs() <= 1e-13 * reference,
                        "n = {n}, group {g}"
                    );
                    for k in n..rows {
                        assert_eq!(a[g * size + k * LANES + t], 0.0);
                    }
                }
            }
            // Every tile kernel (AVX-512's 24 rows, the baseline's 3, 1, and the AVX2
            // intrinsics where this CPU has them) gives the reference's results bit for bit.
            type Run = fn(&PackedFactor, &mut [f64], &mut [[f64; LANES]]);
            let mut runs: Vec<(&str, Run)> = vec![
                ("portable 24", blocked_squared_norms_with::<Portable<24>>),
                ("portable 6", blocked_squared_norms_with::<Portable<6>>),
                ("portable 3", blocked_squared_norms_with::<Portable<3>>),
                ("portable 1", blocked_squared_norms_with::<Portable<1>>),
            ];
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                runs.push(("avx2", blocked_squared_norms_with::<avx2::Avx2>));
            }
            for (kernel, run) in runs {
                let mut c = rhs.clone();
                let mut norms_sub = [[0.0; LANES]; GROUPS];
                run(&packed, &mut c, &mut norms_sub);
                assert_eq!(c, b, "n = {n}: the {kernel} kernel differs");
                assert_eq!(norms_sub, norms_portable, "n = {n}: the {kernel} kernel");
            }
            // A column's result does not depend on its neighbours or on the other groups.
            let mut single = vec![0.0; size];
            for k in 0..n {
                single[k * LANES + 3] = rhs[size + k * LANES + 3];
            }
            let mut alone = [[0.0; LANES]];
            packed.squared_norms(&mut single, &mut alone);
            assert_eq!(alone[0][3], norms[1][3]);
            assert_eq!(alone[0][0], 0.0);
        }
    }
}

#[cfg(test)]
mod timing {
    use super::*;

    /// Throughput of the kernel in scalar fused multiply-adds per second, best and median of
    /// 9 runs of 0.3 s (not a test; `cargo test --release -p iuq-gp -- --ignored --nocapture
    /// kernel_throughput`). Compare with the core's peak (2 AVX-512 FMA units: 16 per cycle).
    #[test]
    #[ignore]
    fn kernel_throughput() {
        for n in [96usize, 240, 500, 1000] {
            let mut l = vec![0.0; n * n];
            for k in 0..n {
                for i in k..n {
                    l[k * n + i] = if i == k { 2.0 } else { 0.001 };
                }
            }
            let packed = PackedFactor::new(&l, n);
            let rows = packed.padded_rows();
            let rhs: Vec<f64> = (0..rows * LANES)
                .map(|i| if i / LANES < n { 0.5 } else { 0.0 })
                .collect();
            let block = 8;
            let rhs = rhs.repeat(block);
            let mut v = rhs.clone();
            let mut norms = vec![[0.0; LANES]; block];
            let mut sink = 0.0;
            let mut rates = Vec::new();
            for _ in 0..9 {
                let mut groups = 0usize;
                let wall = std::time::Instant::now();
                while wall.elapsed().as_secs_f64() < 0.3 {
                    for _ in 0..4 {
                        v.copy_from_slice(&rhs);
                        packed.squared_norms(&mut v, &mut norms);
                        sink += norms[0][0];
                    }
                    groups += 4 * block;
                }
                let wall = wall.elapsed().as_secs_f64();
                let fma = (groups * LANES) as f64 * (n * n) as f64 / 2.0;
                rates.push(fma / wall / 1e9);
            }
            rates.sort_by(f64::total_cmp);
            println!(
                "n = {n}: GFMA per wall second: best {:.1}, median {:.1} ({sink:.1})",
                rates[8], rates[4]
            );
        }
    }
}
