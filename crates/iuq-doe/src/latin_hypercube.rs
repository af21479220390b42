//! Latin hypercube designs on the unit cube (McKay, Beckman & Conover 1979): random, maximin
//! (best of several random designs) and optimised (enhanced stochastic evolutionary algorithm).
//!
//! In a Latin hypercube of `n` points, every coordinate has exactly one point in each of the `n`
//! strata `[k/n, (k+1)/n)`. All randomness comes from `iuq_core::random::stream(seed,
//! LATIN_HYPERCUBE, index)`: random and optimised designs use `index = 0`, maximin candidate `c`
//! uses `index = c`, so the result depends only on `(n, dim, method, seed)` — never on the number
//! of threads — and maximin candidate 0 is the random design of the same seed.

use iuq_core::random::{StreamRng, stages, stream};
use rand::Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::distance::min_distance;
use crate::error::{DoeError, Result};
use crate::ese::{self, EseOptions};
use crate::size::check_size;

/// Number of maximin candidates used by [`LhsMethod::maximin`].
pub const DEFAULT_MAXIMIN_CANDIDATES: usize = 100;

/// How the points of a Latin hypercube are chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LhsMethod {
    /// Random permutations of the strata per column, each point at a uniformly random position
    /// inside its stratum (pyDOE's `lhs(n, samples)`).
    Random,
    /// The best of `candidates` random designs by minimum pairwise distance (pyDOE's
    /// `lhs(criterion='maximin', iterations=candidates)`). At `n = 500`, `d = 3`, 100 candidates
    /// reach a minimum distance of about 0.022 (pyDOE's default of 5: about 0.018).
    Maximin {
        /// Number of random designs to draw (≥ 1).
        candidates: usize,
    },
    /// Enhanced stochastic evolutionary optimisation of the φ_p criterion (Jin, Chen & Sudjianto
    /// 2005), see [`EseOptions`]: at `n = 500`, `d = 3` it reaches a minimum distance of about
    /// 0.066, three times that of the maximin design.
    Optimized(EseOptions),
}

impl LhsMethod {
    /// The maximin method with [`DEFAULT_MAXIMIN_CANDIDATES`] (100) candidates, as used by the
    /// study this crate reproduces.
    pub fn maximin() -> Self {
        Self::Maximin {
            candidates: DEFAULT_MAXIMIN_CANDIDATES,
        }
    }

    /// The optimised (ESE) method with default options ([`EseOptions::default`]).
    pub fn optimized() -> Self {
        Self::Optimized(EseOptions::default())
    }
}

/// `x` if it is below `upper`, else the largest `f64` below `upper` (`upper > 0`).
fn below(x: f64, upper: f64) -> f64 {
    if x < upper {
        x
    } else {
        f64::from_bits(upper.to_bits() - 1)
    }
}

/// A random Latin hypercube, row-major (`n` rows of `d` values), drawn from `rng`: per column a
/// uniform random permutation of the strata (Fisher–Yates), then the position inside each
/// stratum (its centre when `centred`). The value of stratum `k` lies in `[k/n, (k+1)/n)` as
/// computed in floating point.
fn random_design(n: usize, d: usize, centred: bool, rng: &mut StreamRng) -> Vec<f64> {
    let nf = n as f64;
    let mut x = vec![0.0; n * d];
    let mut perm: Vec<usize> = (0..n).collect();
    for k in 0..d {
        for i in (1..n).rev() {
            let j = rng.random_range(0..=i);
            perm.swap(i, j);
        }
        for (i, &stratum) in perm.iter().enumerate() {
            let u: f64 = if centred { 0.5 } else { rng.random() };
            let lo = stratum as f64;
            let upper = (lo + 1.0) / nf;
            x[i * d + k] = below((lo + u) / nf, upper).max(lo / nf);
        }
    }
    x
}

/// Splits a row-major design into rows.
fn into_rows(x: Vec<f64>, d: usize) -> Vec<Vec<f64>> {
    x.chunks_exact(d).map(<[f64]>::to_vec).collect()
}

/// A Latin hypercube of `n` points in `[0, 1)^dim`, chosen by `method`, reproducible from `seed`.
///
/// Errors for `n = 0`, `dim = 0`, `n · dim` above [`MAX_DESIGN_VALUES`](crate::MAX_DESIGN_VALUES),
/// zero maximin candidates or invalid [`EseOptions`]. The design is returned as `n` rows of `dim` coordinates.
///
/// ```
/// use iuq_doe::{latin_hypercube, min_distance, LhsMethod};
/// let random = latin_hypercube(50, 2, LhsMethod::Random, 1)?;
/// let maximin = latin_hypercube(50, 2, LhsMethod::maximin(), 1)?;
/// assert!(min_distance(&maximin) >= min_distance(&random));
/// # Ok::<(), iuq_doe::DoeError>(())
/// ```
pub fn latin_hypercube(
    n: usize,
    dim: usize,
    method: LhsMethod,
    seed: u64,
) -> Result<Vec<Vec<f64>>> {
    check_size(n, dim, "Latin hypercube")?;
    let unit = |index: u64| stream(seed, stages::LATIN_HYPERCUBE, index);
    match method {
        LhsMethod::Random => Ok(into_rows(random_design(n, dim, false, &mut unit(0)), dim)),
        LhsMethod::Maximin { candidates } => {
            if candidates == 0 {
                return Err(DoeError::InvalidOption {
                    name: "candidates",
                    reason: "maximin needs at least one candidate design".into(),
                });
            }
            // Score every candidate in parallel, keep only (score, index); ties go to the lower
            // index, so the choice is independent of the reduction order.
            let (_, best) = (0..candidates as u64)
                .into_par_iter()
                .map(|c| {
                    let rows = into_rows(random_design(n, dim, false, &mut unit(c)), dim);
                    (min_distance(&rows), c)
                })
                .reduce(
                    || (f64::NEG_INFINITY, u64::MAX),
                    |a, b| {
                        if b.0 > a.0 || (b.0 == a.0 && b.1 < a.1) {
                            b
                        } else {
                            a
                        }
                    },
                );
            let best = if best == u64::MAX { 0 } else { best };
            Ok(into_rows(
                random_design(n, dim, false, &mut unit(best)),
                dim,
            ))
        }
        LhsMethod::Optimized(opts) => {
            opts.validate()?;
            let mut rng = unit(0);
            let mut x = random_design(n, dim, opts.centred, &mut rng);
            ese::optimise(&mut x, n, dim, &opts, &mut rng);
            Ok(into_rows(x, dim))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_stay_inside_their_strata() {
        let mut rng = stream(3, stages::LATIN_HYPERCUBE, 0);
        for n in [1, 2, 3, 7, 100] {
            let x = random_design(n, 2, false, &mut rng);
            for k in 0..2 {
                let mut seen = vec![false; n];
                for i in 0..n {
                    let v = x[i * 2 + k];
                    let s = (0..n)
                        .find(|&s| s as f64 / n as f64 <= v && v < (s as f64 + 1.0) / n as f64)
                        .expect("inside some stratum");
                    assert!(!seen[s]);
                    seen[s] = true;
                }
            }
        }
        assert_eq!(below(1.0, 1.0), 1.0 - f64::EPSILON / 2.0);
    }
}
