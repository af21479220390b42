//! How far apart two rounds' posteriors lie as distributions, beyond the samplers' own noise: a
//! sliced Wasserstein-1 distance in posterior standard deviations.
//!
//! The moments a round reports (a mean and a std per parameter) can stand still while the
//! posterior's shape, its correlations or a tail still move. The distance projects both rounds'
//! samples on a set of directions — every parameter's axis, and [`RANDOM_DIRECTIONS`] (at least
//! 2d) unit directions in the coordinates whitened by this round's posterior covariance, so
//! that a shift across a thin, correlated posterior counts as much as one along it — and
//! compares the projections' quantiles at the levels 1/(L+1), …, L/(L+1) (L =
//! [`QUANTILE_LEVELS`]):
//!
//! W_j = (1/L) Σ_l |Q_l(current) − Q_l(previous)| / s_j,
//!
//! s_j the std of this round's projection j. For one-dimensional distributions this is the
//! Wasserstein-1 distance restricted to the central 80 % of the mass (Rabin et al. 2011, sliced
//! Wasserstein; Bonneel et al. 2015), in units of the posterior's spread. For a Gaussian moved by
//! δ stds along a direction, W_j = δ, and the best classifier between the two tells them apart
//! with accuracy Φ(δ/2): a distance below 0.1 means a classifier two-sample test (C2ST) below
//! 0.52 in that direction.
//!
//! Each round's samples come from R independent replicate samplers; the Monte Carlo error of a
//! pooled quantile is the replicates' spread over √R (a sequential Monte Carlo population
//! descends from few lineages, so its quantiles scatter far more than those of independent
//! draws). A shift counts only beyond z = [`crate::NOISE_MULTIPLE`] times the error of the
//! difference: δ_j = max(W_j − ν_j, 0) with ν_j = z·(1/L) Σ_l √(e_l² + e'_l²)/s_j, and the noise ν_j
//! must itself be below the tolerance for the distance to be resolved — the same rule as
//! [`crate::convergence`]'s moment shift, on whole distributions.

use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;
use serde::{Deserialize, Serialize};

use crate::NOISE_MULTIPLE;
use crate::error::{AdaptiveError, Result};

/// Quantile levels per projection: 1/(L+1), …, L/(L+1), the central 80 % for L = 9 (the tails
/// beyond are noisier than what they add).
pub const QUANTILE_LEVELS: usize = 9;

/// Random directions in whitened coordinates besides the parameters' axes: at least this many,
/// and at least 2d.
pub const RANDOM_DIRECTIONS: usize = 8;

/// Seed of the random directions (fixed: two rounds are always compared along the same ones).
const DIRECTION_SEED: u64 = 0x5eed_d157;

/// The distance between two rounds' posteriors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PosteriorDistance {
    /// max_j δ_j: the largest shift of a projection beyond the samplers' noise, in stds.
    pub distance: f64,
    /// max_j ν_j: the largest noise on a projection's distance, in stds (the distance is
    /// resolved only where this is below the tolerance).
    pub noise: f64,
    /// The direction of the largest shift: `Some(k)` parameter k's axis, `None` a whitened
    /// random direction.
    pub largest_along: Option<usize>,
    /// Directions compared.
    pub directions: usize,
}

/// A round's posterior samples, as its R replicate samplers left them: `replicates[r][i]` is
/// sample i of replicate r (equally weighted, as BASIS's final population is), each of the
/// same dimension.
pub type ReplicateSamples<'a> = &'a [Vec<Vec<f64>>];

/// The sliced distance between `previous` and `current` (module docs), along the parameters'
/// axes and random directions whitened by `current`'s pooled covariance.
///
/// # Errors
/// A round without samples, or samples of different dimensions.
pub fn posterior_distance(
    previous: ReplicateSamples<'_>,
    current: ReplicateSamples<'_>,
) -> Result<PosteriorDistance> {
    let d = dimension(current, "this round's samples")?;
    if dimension(previous, "the previous round's samples")? != d {
        return Err(AdaptiveError::LengthMismatch {
            what: "the previous round's parameters vs. this round's",
            expected: d,
            actual: dimension(previous, "the previous round's samples")?,
        });
    }
    let directions_compared = d + RANDOM_DIRECTIONS.max(2 * d);
    let finite =
        |round: ReplicateSamples<'_>| round.iter().flatten().flatten().all(|v| v.is_finite());
    if !(finite(previous) && finite(current)) {
        // A sample that is not a number is no evidence that the posterior stands still.
        return Ok(PosteriorDistance {
            distance: f64::INFINITY,
            noise: f64::INFINITY,
            largest_along: None,
            directions: directions_compared,
        });
    }
    let pooled: Vec<&[f64]> = current.iter().flatten().map(Vec::as_slice).collect();
    let (mean, covariance) = mean_and_covariance(&pooled, d);
    let whitening = whitening(&covariance, d);
    let directions = directions(d, &whitening);
    let mut result = PosteriorDistance {
        distance: 0.0,
        noise: 0.0,
        largest_along: None,
        directions: directions.len(),
    };
    for (j, direction) in directions.iter().enumerate() {
        let project = |round: ReplicateSamples<'_>| -> Vec<Vec<f64>> {
            round
                .iter()
                .map(|samples| {
                    samples
                        .iter()
                        .map(|s| (0..d).map(|k| direction[k] * (s[k] - mean[k])).sum())
                        .collect()
                })
                .collect()
        };
        let (now, before) = (project(current), project(previous));
        let scale = std_of(now.iter().flatten().copied());
        if scale <= 0.0 {
            // A direction along which this round's posterior has no spread (one distinct
            // sample): nothing to measure the shift against.
            continue;
        }
        let (q_now, e_now) = quantiles_with_errors(&now);
        let (q_before, e_before) = quantiles_with_errors(&before);
        let levels = QUANTILE_LEVELS as f64;
        let gap: f64 = (0..QUANTILE_LEVELS)
            .map(|l| (q_now[l] - q_before[l]).abs())
            .sum::<f64>()
            / levels
            / scale;
        let noise: f64 = NOISE_MULTIPLE
            * (0..QUANTILE_LEVELS)
                .map(|l| (e_now[l].powi(2) + e_before[l].powi(2)).sqrt())
                .sum::<f64>()
            / levels
            / scale;
        let shift = (gap - noise).max(0.0);
        if shift > result.distance {
            result.distance = shift;
            result.largest_along = (j < d).then_some(j);
        }
        result.noise = result.noise.max(noise);
    }
    Ok(result)
}

fn dimension(round: ReplicateSamples<'_>, what: &'static str) -> Result<usize> {
    let Some(first) = round.iter().flatten().next() else {
        return Err(AdaptiveError::InvalidParameter {
            what,
            reason: "no samples".into(),
        });
    };
    let d = first.len();
    if let Some(other) = round.iter().flatten().find(|s| s.len() != d) {
        return Err(AdaptiveError::LengthMismatch {
            what,
            expected: d,
            actual: other.len(),
        });
    }
    Ok(d)
}

fn mean_and_covariance(samples: &[&[f64]], d: usize) -> (Vec<f64>, Vec<f64>) {
    let n = samples.len() as f64;
    let mut mean = vec![0.0; d];
    for s in samples {
        for k in 0..d {
            mean[k] += s[k] / n;
        }
    }
    let mut covariance = vec![0.0; d * d];
    for s in samples {
        for a in 0..d {
            for b in 0..=a {
                covariance[a * d + b] += (s[a] - mean[a]) * (s[b] - mean[b]) / n;
            }
        }
    }
    for a in 0..d {
        for b in 0..a {
            covariance[b * d + a] = covariance[a * d + b];
        }
    }
    (mean, covariance)
}

/// The lower Cholesky factor L of `covariance` (row-major d×d), or of its diagonal where the
/// covariance is singular (a parameter the posterior pins down completely): whitened coordinates
/// are z = L⁻¹(θ − μ).
fn whitening(covariance: &[f64], d: usize) -> Vec<f64> {
    let mut l = vec![0.0; d * d];
    for a in 0..d {
        for b in 0..=a {
            let mut sum = covariance[a * d + b];
            for k in 0..b {
                sum -= l[a * d + k] * l[b * d + k];
            }
            if a == b {
                if sum <= 1e-12 * covariance[a * d + a].abs().max(f64::MIN_POSITIVE) {
                    return diagonal_factor(covariance, d);
                }
                l[a * d + a] = sum.sqrt();
            } else {
                l[a * d + b] = sum / l[b * d + b];
            }
        }
    }
    l
}

fn diagonal_factor(covariance: &[f64], d: usize) -> Vec<f64> {
    let mut l = vec![0.0; d * d];
    for a in 0..d {
        l[a * d + a] = covariance[a * d + a].max(0.0).sqrt();
    }
    l
}

/// Every parameter's axis, then the random unit directions u in whitened coordinates mapped
/// back to parameter space: the projection u·z = u·L⁻¹(θ − μ) = (L⁻ᵀu)·(θ − μ).
fn directions(d: usize, l: &[f64]) -> Vec<Vec<f64>> {
    let mut all: Vec<Vec<f64>> = (0..d)
        .map(|k| (0..d).map(|i| f64::from(u8::from(i == k))).collect())
        .collect();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(DIRECTION_SEED);
    for _ in 0..RANDOM_DIRECTIONS.max(2 * d) {
        let mut u: Vec<f64> = (0..d).map(|_| StandardNormal.sample(&mut rng)).collect();
        let norm = u.iter().map(|v| v * v).sum::<f64>().sqrt();
        u.iter_mut().for_each(|v| *v /= norm);
        // Back substitution for w = L⁻ᵀu (Lᵀ is upper triangular); a zero pivot (no spread)
        // leaves that coordinate out.
        let mut w = vec![0.0; d];
        for a in (0..d).rev() {
            let pivot = l[a * d + a];
            if pivot == 0.0 {
                continue;
            }
            let mut sum = u[a];
            for b in a + 1..d {
                sum -= l[b * d + a] * w[b];
            }
            w[a] = sum / pivot;
        }
        all.push(w);
    }
    all
}

fn std_of(values: impl Iterator<Item = f64> + Clone) -> f64 {
    let (n, sum) = values
        .clone()
        .fold((0.0, 0.0), |(n, s), v| (n + 1.0, s + v));
    let mean = sum / n;
    (values.map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt()
}

/// The pooled quantiles of the replicates' projections at the levels, and their Monte Carlo
/// errors: the replicates' own quantiles' sample std over √R (zero with one replicate).
fn quantiles_with_errors(replicates: &[Vec<f64>]) -> (Vec<f64>, Vec<f64>) {
    let pooled: Vec<f64> = replicates.iter().flatten().copied().collect();
    let q = quantiles(pooled);
    let own: Vec<Vec<f64>> = replicates
        .iter()
        .filter(|r| !r.is_empty())
        .map(|r| quantiles(r.clone()))
        .collect();
    let r = own.len() as f64;
    let errors = (0..QUANTILE_LEVELS)
        .map(|l| {
            if own.len() < 2 {
                return 0.0;
            }
            let m = own.iter().map(|o| o[l]).sum::<f64>() / r;
            let variance = own.iter().map(|o| (o[l] - m).powi(2)).sum::<f64>() / (r - 1.0);
            (variance / r).sqrt()
        })
        .collect();
    (q, errors)
}

/// Quantiles at l/(L+1), l = 1…L, linearly interpolated between order statistics (Hyndman &
/// Fan's type 7).
fn quantiles(mut values: Vec<f64>) -> Vec<f64> {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    (1..=QUANTILE_LEVELS)
        .map(|l| {
            let h = (n - 1) as f64 * l as f64 / (QUANTILE_LEVELS + 1) as f64;
            let (lo, frac) = (h.floor() as usize, h - h.floor());
            let hi = (lo + 1).min(n - 1);
            values[lo] + frac * (values[hi] - values[lo])
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand_distr::Normal;

    /// R replicates of n draws of a correlated 2-d Gaussian (ρ = 0.95, stds 1 and 2), the
    /// first coordinate moved by `shift` stds, and the whole moved by `across` stds of its thin
    /// principal direction.
    fn gaussian(
        replicates: usize,
        n: usize,
        seed: u64,
        shift: f64,
        across: f64,
    ) -> Vec<Vec<Vec<f64>>> {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let normal = Normal::new(0.0, 1.0).unwrap();
        let rho: f64 = 0.95;
        // The thin direction's std: the covariance [[1, 2ρ], [2ρ, 4]]'s smaller eigenvalue.
        let (a, b, c) = (1.0, 2.0 * rho, 4.0);
        let small = 0.5 * (a + c - ((a - c) * (a - c) + 4.0 * b * b).sqrt());
        // Unit eigenvector of the smaller eigenvalue.
        let (vx, vy) = (b, small - a);
        let norm = (vx * vx + vy * vy).sqrt();
        let thin = [vx / norm, vy / norm];
        (0..replicates)
            .map(|_| {
                (0..n)
                    .map(|_| {
                        let (z1, z2): (f64, f64) =
                            (normal.sample(&mut rng), normal.sample(&mut rng));
                        let x = z1;
                        let y = 2.0 * (rho * z1 + (1.0 - rho * rho).sqrt() * z2);
                        vec![
                            x + shift + across * small.sqrt() * thin[0],
                            y + across * small.sqrt() * thin[1],
                        ]
                    })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn the_same_posterior_sampled_twice_is_at_distance_zero_with_a_small_noise() {
        let a = gaussian(4, 2000, 1, 0.0, 0.0);
        let b = gaussian(4, 2000, 2, 0.0, 0.0);
        let d = posterior_distance(&a, &b).unwrap();
        assert_eq!(d.directions, 2 + RANDOM_DIRECTIONS);
        // The noise of a quantile of 8000 independent draws is about 1.3/√8000 = 0.015 stds
        // (1/f(q) of a normal, averaged over the levels), z = 2 times √2 of it for a difference:
        // about 0.04; the distance must be below it in every direction.
        assert_eq!(d.distance, 0.0, "{d:?}");
        assert!(d.noise > 0.02 && d.noise < 0.1, "{d:?}");
    }

    #[test]
    fn a_shift_is_measured_in_the_posterior_s_own_metric() {
        // Moved by 0.2 stds along both marginals, (0.2, 0.4): nearly along the long axis, whose
        // Mahalanobis length is 0.20; the distance reads it less the noise (about 0.03).
        let a = gaussian(4, 4000, 3, 0.0, 0.0);
        let mut b = gaussian(4, 4000, 4, 0.2, 0.0);
        b.iter_mut().flatten().for_each(|s| s[1] += 0.4);
        let d = posterior_distance(&a, &b).unwrap();
        assert!(d.distance > 0.13 && d.distance < 0.21, "{d:?}");
        // Moved by 0.2 stds in x alone, across the correlation: Mahalanobis length
        // 0.2/√(1 − 0.95²) = 0.64, which the best of the random directions sees nearly whole
        // where the marginals read 0.2 and 0.
        let b = gaussian(4, 4000, 4, 0.2, 0.0);
        let d = posterior_distance(&a, &b).unwrap();
        assert!(d.distance > 0.5 && d.distance < 0.65, "{d:?}");
        assert_eq!(d.largest_along, None);
    }

    #[test]
    fn a_shift_across_a_thin_correlated_posterior_shows_where_the_marginals_barely_move() {
        // Moved by 0.5 stds of the thin direction, which is about 0.1 of the marginals' stds:
        // the whitened directions see it at up to 0.5.
        let a = gaussian(4, 4000, 5, 0.0, 0.0);
        let b = gaussian(4, 4000, 6, 0.0, 0.5);
        let d = posterior_distance(&a, &b).unwrap();
        assert!(d.distance > 0.25, "{d:?}");
        assert_eq!(d.largest_along, None, "{d:?}");
    }

    #[test]
    fn one_replicate_gives_no_noise_estimate_and_a_nan_sample_is_no_convergence() {
        let a = gaussian(1, 500, 7, 0.0, 0.0);
        let b = gaussian(1, 500, 8, 0.0, 0.0);
        let d = posterior_distance(&a, &b).unwrap();
        assert_eq!(d.noise, 0.0);
        let mut c = b.clone();
        c[0][3][0] = f64::NAN;
        let e = posterior_distance(&a, &c).unwrap();
        assert!(e.distance.is_infinite() && e.noise.is_infinite(), "{e:?}");
    }

    #[test]
    fn rounds_of_different_dimensions_or_without_samples_are_errors() {
        let a = gaussian(2, 10, 9, 0.0, 0.0);
        let b: Vec<Vec<Vec<f64>>> = vec![vec![vec![0.0; 3]; 10]; 2];
        assert!(matches!(
            posterior_distance(&a, &b),
            Err(AdaptiveError::LengthMismatch { .. })
        ));
        assert!(matches!(
            posterior_distance(&a, &[]),
            Err(AdaptiveError::InvalidParameter { .. })
        ));
    }
}
