//! Enhanced stochastic evolutionary (ESE) optimisation of a Latin hypercube (Jin, Chen &
//! Sudjianto 2005, "An efficient algorithm for constructing optimal design of computer
//! experiments", J. Stat. Plan. Inference 134, 268–287).
//!
//! The design is improved by exchanging two elements of one column — which keeps it a Latin
//! hypercube — so as to minimise Morris & Mitchell's `φ_p = (Σ_{i<j} d_ij^(−p))^(1/p)`
//! ([`crate::phi_p`]). Each inner step draws `J` random exchanges in column `i mod d`, takes the
//! best, and accepts it if `φ_try − φ ≤ T_h · U` (threshold acceptance, `U ~ U(0,1)`); each outer
//! iteration runs `M` inner steps and then adapts the threshold `T_h`: in the improving phase it
//! lowers `T_h` (×0.8) when many moves are accepted but not all of them improve, and raises it
//! (÷0.8) when few are accepted; in the exploration phase it raises it quickly (÷0.7) while fewer
//! than 10 % of the moves are accepted and lowers it slowly (×0.9) once more than 80 % are. The
//! defaults are those of the paper: `J = min(n_e/5, 50)`, `M = min(2·n_e·d/J, 100)` with
//! `n_e = n(n−1)/2`, `T_h,0 = 0.005·φ_p(X_0)`.
//!
//! An exchange of rows `i1`, `i2` changes only the distances of those two rows, so the change of
//! `Σ d_ij^(−p)` is computed in `O(n·d)` instead of `O(n²·d)`; the `J` trials of a step are
//! evaluated in parallel (they are drawn first and the best is chosen in a fixed order, so the
//! result does not depend on the number of threads). The sum is kept in units of the current
//! minimum distance (re-scaled as it grows), pairs too far apart to matter in double precision
//! are skipped, and the running sum carries a bound on its rounding error: when a move would
//! cancel most of it (the removed pairs dominate, common for `p = 50`), or the bound grows too
//! large, the sum is recomputed exactly.

use rand::Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::distance::squared_distance;
use crate::error::{DoeError, Result};

/// Most candidate exchanges per inner step ([`EseOptions::exchanges`]).
const MAX_EXCHANGES: usize = 100_000;

/// Options of the enhanced stochastic evolutionary optimisation of a Latin hypercube.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(default)]
pub struct EseOptions {
    /// Exponent `p` of the φ_p criterion (default 50; larger values weigh the smallest distance
    /// more, approaching the maximin criterion). Must be in `1..=1000`.
    pub p: u32,
    /// Number of outer iterations (threshold updates; default 10). Each runs `M·J` trial
    /// exchanges of cost `O(n·d)`: at `n = 500`, `d = 3` the default takes about 0.3 s on one
    /// core and reaches a minimum distance of about 0.093 (1 iteration: 0.06, 2: 0.07,
    /// 40: 0.107); larger designs need more iterations for the same quality.
    pub outer_iterations: usize,
    /// Inner steps per outer iteration, `M`; `None` for `min(2·n_e·d/J, 100)` (Jin et al.).
    pub inner_iterations: Option<usize>,
    /// Candidate exchanges per inner step, `J` (at most 100 000); `None` for `min(n_e/5, 50)`
    /// (Jin et al.).
    pub exchanges: Option<usize>,
    /// Points at the centres of their strata, `(k + ½)/n` (default `true`); otherwise at random
    /// positions inside them, fixed before the optimisation (exchanges move whole values).
    pub centred: bool,
}

impl Default for EseOptions {
    fn default() -> Self {
        Self {
            p: 50,
            outer_iterations: 10,
            inner_iterations: None,
            exchanges: None,
            centred: true,
        }
    }
}

impl EseOptions {
    /// Checks the options (`p` in `1..=1000`, at least one outer iteration, `M ≥ 1`,
    /// `1 ≤ J ≤ 100 000`).
    pub(crate) fn validate(&self) -> Result<()> {
        if self.p == 0 || self.p > 1000 {
            return Err(DoeError::InvalidOption {
                name: "p",
                reason: format!("the phi_p exponent must be in 1..=1000, got {}", self.p),
            });
        }
        if self.outer_iterations == 0 {
            return Err(DoeError::InvalidOption {
                name: "outer_iterations",
                reason: "at least one outer iteration is needed".into(),
            });
        }
        if self.inner_iterations == Some(0) {
            return Err(DoeError::InvalidOption {
                name: "inner_iterations",
                reason: "at least one inner iteration is needed".into(),
            });
        }
        if let Some(j) = self.exchanges.filter(|j| !(1..=MAX_EXCHANGES).contains(j)) {
            return Err(DoeError::InvalidOption {
                name: "exchanges",
                reason: format!("the exchanges per step must be in 1..={MAX_EXCHANGES}, got {j}"),
            });
        }
        Ok(())
    }
}

/// `base^e` by binary powering (no final useless squaring, which could underflow). With `e` a
/// constant the loop unrolls into a branch-free chain of multiplications.
#[inline(always)]
fn powu(mut base: f64, mut e: u32) -> f64 {
    let mut acc = 1.0;
    loop {
        if e & 1 == 1 {
            acc *= base;
        }
        e >>= 1;
        if e == 0 {
            return acc;
        }
        base *= base;
    }
}

/// The power `r ↦ r^(p/2)` applied to `r = s²/d²` (so that the weight is `(s/d)^p`).
trait HalfPower: Sync + Copy {
    fn apply(&self, r: f64) -> f64;
}

/// `r^E` for even `p = 2E`, with `E` known at compile time (the common `p = 50`, …).
#[derive(Clone, Copy)]
struct ConstHalfPower<const E: u32>;

impl<const E: u32> HalfPower for ConstHalfPower<E> {
    #[inline(always)]
    fn apply(&self, r: f64) -> f64 {
        powu(r, E)
    }
}

/// `r^(p/2)` for any `p`: `r^(p/2)` for even `p`, `(√r)^p` for odd `p`.
#[derive(Clone, Copy)]
struct DynHalfPower {
    p: u32,
}

impl HalfPower for DynHalfPower {
    #[inline]
    fn apply(&self, r: f64) -> f64 {
        if self.p % 2 == 0 {
            powu(r, self.p / 2)
        } else {
            powu(r.sqrt(), self.p)
        }
    }
}

/// Growth of the minimum distance (relative to the scale `s`) after which the weights are
/// re-scaled: `10^(2/50)`, i.e. a running sum below `10^-2` at `p = 50`.
const RESCALE_RATIO: f64 = 1.096_478_196_143_185;

/// Growth of the minimum distance beyond which a trial's sum is evaluated without the cut-off:
/// `10^(3/50)`, i.e. a sum below `10^-3` at `p = 50`.
const UNRESOLVED_RATIO: f64 = 1.148_153_621_496_883;

/// Pair weights `(s/d)^p`, with the scale `s` the design's minimum distance at the last
/// re-scaling, so that the closest pair weighs about 1 and nothing overflows or underflows.
///
/// Weights of pairs farther apart than `c·s`, `c = 10^(3/50) · 10^(17/p)` (2.5 for `p = 50`),
/// are taken as zero: as long as the sum is above `10^(−3p/50)` (checked, else the sum is
/// evaluated without the cut-off), each dropped weight is below `10^-17` of it — invisible in
/// double precision — and skipping them makes an exchange cost `O(n·d)` cheap operations plus
/// a few powers for the near neighbours.
#[derive(Clone, Copy)]
struct Weights<P> {
    /// `s²`, the squared distance scale.
    s2: f64,
    /// The power `r ↦ r^(p/2)`.
    power: P,
    /// Smallest squared distance used (coincident points get a huge but finite weight).
    d2_floor: f64,
    /// Squared distance beyond which the weight is zero.
    d2_cut: f64,
    /// Sums below this value are evaluated without the cut-off.
    unresolved: f64,
    /// The running sum is re-scaled once it falls below this value.
    rescale_below: f64,
}

impl<P: HalfPower> Weights<P> {
    fn new(p: u32, s2: f64, power: P) -> Self {
        let p = f64::from(p);
        // r = s²/d² ≤ 10^(580/p) keeps each weight r^(p/2) ≤ 1e290.
        let r_max = 10f64.powf(580.0 / p).min(1e300);
        let cut = UNRESOLVED_RATIO * 10f64.powf(17.0 / p);
        Self {
            s2,
            power,
            d2_floor: s2 / r_max,
            d2_cut: s2 * cut * cut,
            unresolved: UNRESOLVED_RATIO.powf(-p),
            rescale_below: RESCALE_RATIO.powf(-p),
        }
    }

    /// The same weights without the cut-off.
    fn without_cutoff(&self) -> Self {
        Self {
            d2_cut: f64::INFINITY,
            ..*self
        }
    }

    #[inline(always)]
    fn weight(&self, d2: f64) -> f64 {
        if d2 > self.d2_cut {
            0.0
        } else {
            self.power.apply(self.s2 / d2.max(self.d2_floor))
        }
    }
}

/// The optimiser's state: the current design and its running φ_p sum.
struct Ese<'a, P> {
    /// The design, row-major (`n` rows of `d`).
    x: &'a mut [f64],
    /// The same design, column-major (`d` columns of `n`).
    cols: Vec<f64>,
    n: usize,
    d: usize,
    /// The φ_p exponent.
    p: u32,
    w: Weights<P>,
    /// `Σ_{i<j} (s/d_ij)^p` of the current design.
    sum: f64,
    /// Bound on the absolute rounding error of `sum`.
    err: f64,
}

/// Relative rounding error assumed for an exactly recomputed sum.
const EXACT_REL_ERR: f64 = 1e-13;

/// Row-pair marker meaning "skip no row" for [`Ese::exact_sum`].
const NO_SKIP: (usize, usize) = (usize::MAX, usize::MAX);

impl<P: HalfPower> Ese<'_, P> {
    fn row(&self, i: usize) -> &[f64] {
        &self.x[i * self.d..(i + 1) * self.d]
    }

    /// Minimum squared pairwise distance of the current design (exact whatever the number of
    /// threads: a minimum does not depend on the order).
    fn min_d2(&self) -> f64 {
        (0..self.n)
            .into_par_iter()
            .map(|i| {
                let ri = self.row(i);
                (i + 1..self.n)
                    .map(|j| squared_distance(ri, self.row(j)))
                    .fold(f64::INFINITY, f64::min)
            })
            .reduce(|| f64::INFINITY, f64::min)
    }

    /// Re-scales the weights to the current minimum distance and recomputes the sum exactly.
    fn rescale(&mut self) {
        let m = self.min_d2();
        let s2 = if m > 0.0 && m.is_finite() {
            m
        } else {
            1.0 / (self.n as f64 * self.n as f64)
        };
        self.w = Weights::new(self.p, s2, self.w.power);
        self.sum = self.exact_sum(&self.w, NO_SKIP);
        self.err = EXACT_REL_ERR * self.sum;
    }

    /// `φ_p` of a design whose scaled sum is `sum`: `sum^(1/p) / s`.
    fn phi(&self, sum: f64) -> f64 {
        sum.powf(1.0 / f64::from(self.p)) / self.w.s2.sqrt()
    }

    /// `Σ` of the pair weights over pairs involving neither `skip.0` nor `skip.1` (exact, in a
    /// fixed order whatever the number of threads).
    fn exact_sum(&self, w: &Weights<P>, skip: (usize, usize)) -> f64 {
        let rows: Vec<f64> = (0..self.n)
            .into_par_iter()
            .map(|i| {
                if i == skip.0 || i == skip.1 {
                    return 0.0;
                }
                let ri = self.row(i);
                (i + 1..self.n)
                    .filter(|&j| j != skip.0 && j != skip.1)
                    .map(|j| w.weight(squared_distance(ri, self.row(j))))
                    .sum::<f64>()
            })
            .collect();
        rows.iter().sum()
    }

    /// Sums of the weights of the pairs `(i1, j)`, `(i2, j)`, `j ∉ {i1, i2}`, before and after
    /// exchanging the elements of rows `i1` and `i2` in column `k` (the pair `(i1, i2)` keeps its
    /// distance). `O(n·d)`: squared distances over the other columns are accumulated column by
    /// column (contiguous, vectorisable), then column `k` is added before/after the exchange and
    /// the weights are evaluated for the pairs within the cut-off only.
    fn exchange_sums(&self, w: &Weights<P>, i1: usize, i2: usize, k: usize) -> (f64, f64) {
        let n = self.n;
        let mut e1 = vec![0.0; n];
        let mut e2 = vec![0.0; n];
        for (l, col) in self.cols.chunks_exact(n).enumerate() {
            if l == k {
                continue;
            }
            let (u, v) = (col[i1], col[i2]);
            for ((e1j, e2j), &c) in e1.iter_mut().zip(e2.iter_mut()).zip(col) {
                let du = u - c;
                let dv = v - c;
                *e1j += du * du;
                *e2j += dv * dv;
            }
        }
        let col_k = &self.cols[k * n..(k + 1) * n];
        let (a, b) = (col_k[i1], col_k[i2]);
        let mut old = 0.0;
        let mut new = 0.0;
        for (j, ((&e1j, &e2j), &c)) in e1.iter().zip(&e2).zip(col_k).enumerate() {
            let ac = (a - c) * (a - c);
            let bc = (b - c) * (b - c);
            if e1j.min(e2j) + ac.min(bc) > w.d2_cut || j == i1 || j == i2 {
                // All four pairs beyond the cut-off (the common case): weights zero.
                continue;
            }
            old += w.weight(e1j + ac) + w.weight(e2j + bc);
            new += w.weight(e1j + bc) + w.weight(e2j + ac);
        }
        (old, new)
    }

    /// The sum (and its error bound) after exchanging rows `i1`, `i2` in column `k`.
    ///
    /// The unchanged pairs' part is recomputed exactly when the exchange would cancel most of
    /// the running sum; when almost no pair is left within the cut-off (the exchange moved the
    /// closest points apart), the whole sum is evaluated without the cut-off.
    fn trial(&self, i1: usize, i2: usize, k: usize) -> (f64, f64) {
        let (old, new) = self.exchange_sums(&self.w, i1, i2, k);
        let mut rest = self.sum - old;
        let mut rest_err = self.err + f64::EPSILON * self.sum;
        let pair = |w: &Weights<P>| w.weight(squared_distance(self.row(i1), self.row(i2)));
        if rest <= 0.0 || rest_err > 1e-9 * rest {
            rest = self.exact_sum(&self.w, (i1, i2)) + pair(&self.w);
            rest_err = EXACT_REL_ERR * rest;
        }
        let total = rest + new;
        if total < self.w.unresolved {
            let w = self.w.without_cutoff();
            let (_, new) = self.exchange_sums(&w, i1, i2, k);
            let total = self.exact_sum(&w, (i1, i2)) + pair(&w) + new;
            return (total, EXACT_REL_ERR * total);
        }
        (total, rest_err + EXACT_REL_ERR * new + f64::EPSILON * total)
    }

    fn swap(&mut self, i1: usize, i2: usize, k: usize) {
        self.x.swap(i1 * self.d + k, i2 * self.d + k);
        self.cols.swap(k * self.n + i1, k * self.n + i2);
    }
}

/// Optimises the Latin hypercube `x` (`n` rows of `d` values, row-major) in place with the ESE
/// algorithm, drawing all randomness from `rng` (sequentially, so the result depends only on the
/// starting design and the stream, not on the number of threads). On return `x` holds the best
/// design met.
pub(crate) fn optimise<R: Rng>(x: &mut [f64], n: usize, d: usize, opts: &EseOptions, rng: &mut R) {
    match opts.p {
        50 => run(x, n, d, opts, rng, ConstHalfPower::<25>),
        10 => run(x, n, d, opts, rng, ConstHalfPower::<5>),
        20 => run(x, n, d, opts, rng, ConstHalfPower::<10>),
        100 => run(x, n, d, opts, rng, ConstHalfPower::<50>),
        p => run(x, n, d, opts, rng, DynHalfPower { p }),
    }
}

/// [`optimise`] with the power of the weights fixed.
fn run<R: Rng, P: HalfPower>(
    x: &mut [f64],
    n: usize,
    d: usize,
    opts: &EseOptions,
    rng: &mut R,
    power: P,
) {
    if n < 3 || d == 0 {
        // With two points every exchange mirrors the design: nothing to optimise.
        return;
    }
    let cols = (0..d)
        .flat_map(|l| x.chunks_exact(d).map(move |row| row[l]))
        .collect();
    let mut ese = Ese {
        x,
        cols,
        n,
        d,
        p: opts.p,
        w: Weights::new(opts.p, 1.0, power),
        sum: 0.0,
        err: 0.0,
    };
    ese.rescale();

    let n_e = n.saturating_mul(n - 1) / 2;
    let j_trials = opts.exchanges.unwrap_or((n_e / 5).clamp(1, 50));
    let m_inner = opts
        .inner_iterations
        .unwrap_or((n_e.saturating_mul(2 * d) / j_trials).clamp(1, 100));

    let mut best = ese.x.to_vec();
    let mut best_phi = ese.phi(ese.sum);
    let mut threshold = 0.005 * best_phi;
    let mut warming = true;
    let mut pairs = Vec::with_capacity(j_trials);

    for outer in 0..opts.outer_iterations {
        if outer > 0 {
            ese.rescale();
        }
        let best_before = best_phi;
        let mut accepted = 0usize;
        let mut improved = 0usize;
        for step in 0..m_inner {
            let k = step % d;
            // Draw the J exchanges first (sequentially), evaluate them in parallel, and take
            // the best, the first one on ties: independent of the number of threads.
            pairs.clear();
            for _ in 0..j_trials {
                let i1 = rng.random_range(0..n);
                let mut i2 = rng.random_range(0..n - 1);
                if i2 >= i1 {
                    i2 += 1;
                }
                pairs.push((i1, i2));
            }
            let ese_ref = &ese;
            let trials: Vec<(f64, f64)> = pairs
                .par_iter()
                .with_min_len(4)
                .map(|&(i1, i2)| ese_ref.trial(i1, i2, k))
                .collect();
            let Some((t, &(sum, err))) = trials
                .iter()
                .enumerate()
                .reduce(|a, b| if b.1.0 < a.1.0 { b } else { a })
            else {
                continue;
            };
            let (i1, i2) = pairs[t];
            let u: f64 = rng.random();
            let phi_try = ese.phi(sum);
            if phi_try - ese.phi(ese.sum) <= threshold * u {
                ese.swap(i1, i2, k);
                ese.sum = sum;
                ese.err = err;
                accepted += 1;
                if phi_try < best_phi {
                    best_phi = phi_try;
                    best.copy_from_slice(ese.x);
                    improved += 1;
                }
                // Keep the scale near the minimum distance (the cut-off follows it) and the
                // running sum accurate.
                if ese.sum < ese.w.rescale_below || ese.err > 1e-10 * ese.sum {
                    ese.rescale();
                }
            }
        }
        let ratio = accepted as f64 / m_inner as f64;
        if best_phi < best_before {
            // Improving phase.
            if ratio > 0.1 && improved < accepted {
                threshold *= 0.8;
            } else if ratio <= 0.1 {
                threshold /= 0.8;
            }
        } else {
            // Exploration phase: warm up until most moves are accepted, then cool slowly.
            if ratio < 0.1 {
                warming = true;
            } else if ratio > 0.8 {
                warming = false;
            }
            if warming {
                threshold /= 0.7;
            } else {
                threshold *= 0.9;
            }
        }
    }
    ese.x.copy_from_slice(&best);
}
