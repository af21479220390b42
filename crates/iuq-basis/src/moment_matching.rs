//! A moment-matched correction of a surrogate posterior, for a model whose likelihood is a noisy
//! estimate, and a permutation test that tells the proposal's mismatch from the weights' noise.
//!
//! With a reproducible model the difference r = ℓ_m − ℓ_s is a function of θ and a quadratic
//! least-squares fit of it corrects the surrogate ([`crate::quadratic_regression`]). With a noisy
//! one (a chaotic or stochastic model: each run's likelihood L̂ is one draw whose mean over the
//! model's irregular part is L) a fit of r̂ = ln L̂ − ℓ_s fits E[ln L̂] − ℓ_s, which by Jensen's
//! inequality lies below ln L − ℓ_s by a gap that itself depends on θ. The importance weights
//! L̂/L_s are unbiased, though, and so are the self-normalised moments they give: the
//! correction here is the Gaussian log-ratio
//!
//! g(θ) = ln N(θ; μ_w, f²Σ_w) − ln N(θ; μ_q, Σ_q),
//!
//! (μ_w, Σ_w) the batch's importance-weighted mean and covariance, (μ_q, Σ_q) its unweighted
//! ones (the proposal's), f = [`DEFENSIVE_WIDENING`] (1: the moments themselves). For a Gaussian
//! proposal q, q·e^g is the Gaussian with the target's moments (stds widened f times); otherwise it carries q's shape with the target's location and spread (the moment
//! matching of population Monte Carlo; Cappé et al. 2004). g is evaluated at θ clamped to the
//! box of the batch widened by its own width on every side, as the quadratic fit is, and held
//! below a ceiling: its largest value over [`CEILING_DRAWS`] draws of the target normal (about
//! the target's 1-in-10,000 contour). Where Σ_w is wider than Σ_q, g grows outwards, and a
//! surrogate posterior whose tails are heavier than a Gaussian's (a GP's likelihood flattens
//! away from its runs) would otherwise put the corrected mass where the target has none: on a
//! whole-curve test problem, e^{8.5} of the corrected evidence, its batch's mean k 0.09 off a
//! posterior of std 0.012. Beyond the ceiling q·e^g has q's tails. (A ceiling at the largest g
//! over the batch itself stops the widening where a narrow proposal's batch ends: on the
//! 2-D test problem with a surrogate posterior 0.7 times as wide, the std came out 2 MCSE low
//! on average; with the target's contour, 0.2.)
//!
//! Whether the proposal is off at all is a question the weights' noise can fake: with noisy
//! weights the weighted moments differ from the unweighted ones even when q is the target.
//! [`proposal_mismatch`] measures the shift of the mean and the divergence of the spread and
//! compares each with its distribution when the same weights are handed to the members at
//! random (a permutation test: under "the weights do not depend on θ" every permutation is as
//! likely as the observed one, so the p-value is exact up to the permutations' count).

use rand::seq::SliceRandom;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use iuq_core::random::stream;
use iuq_core::weighted_statistics::effective_sample_size;

use crate::pareto_smoothing::normalised_weights;
use crate::proposal::cholesky_lower;

/// Stream stage of the permutations (each permutation b uses index b), apart from every
/// sampler's and the model posterior's stages.
pub const PERMUTATION_STREAM: u64 = iuq_core::random::stages::MISMATCH_PERMUTATION;

/// Stream stage of the draws that set [`GaussianLogRatio`]'s ceiling.
pub const CEILING_STREAM: u64 = iuq_core::random::stages::CORRECTION_CEILING;

/// Draws of the target normal over which [`GaussianLogRatio`]'s ceiling is the largest g: about
/// its 1-in-10,000 contour in any dimension.
pub const CEILING_DRAWS: usize = 10_000;

/// Permutations of [`proposal_mismatch`] (p-values in steps of 1/1000).
pub const PERMUTATIONS: usize = 999;

/// The p-value below which [`proposal_mismatch`] calls the proposal off (a false alarm costs one
/// batch of model runs, never a bias).
pub const MISMATCH_LEVEL: f64 = 0.01;

/// The factor by which a correction widens the weighted stds. The weighted covariance of a
/// first batch drawn from a proposal narrower than the target misses the target's tails, so a
/// correction matched to it exactly is still too narrow; over 20 seeds of a 2-D chaotic test
/// problem whose surrogate posterior was half as wide as the model's, the corrected estimate was
/// certified 13 times with the weighted stds, 19 times widened by 1.2 and 20 by 1.4, its std
/// about 1 MCSE low on average in every case. 1.2 costs a matching proposal little: the
/// importance weights' second moment grows by (f²/√(2f² − 1)) per dimension, 5 % at f = 1.2
/// (1.6× over 10 dimensions), 15 % at 1.4.
pub const DEFENSIVE_WIDENING: f64 = 1.2;

/// A multivariate normal's mean, Cholesky factor and log-determinant/2.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Normal {
    pub(crate) mean: Vec<f64>,
    pub(crate) lower: Vec<Vec<f64>>,
    pub(crate) half_log_det: f64,
}

impl Normal {
    /// The normal with the weighted moments of `points` (`weights` normalised), with a ridge of
    /// 1e-10 of each variance; `None` when the covariance is not positive definite.
    fn of(points: &[Vec<f64>], weights: &[f64]) -> Option<Self> {
        let d = points.first()?.len();
        let mut mean = vec![0.0; d];
        for (p, w) in points.iter().zip(weights) {
            for k in 0..d {
                mean[k] += w * p[k];
            }
        }
        let mut cov = vec![vec![0.0; d]; d];
        for (p, w) in points.iter().zip(weights) {
            for a in 0..d {
                for b in 0..=a {
                    cov[a][b] += w * (p[a] - mean[a]) * (p[b] - mean[b]);
                }
            }
        }
        for a in 0..d {
            cov[a][a] *= 1.0 + 1e-10;
        }
        Self::with_covariance(mean, cov)
    }

    /// The normal N(`mean`, Σ) from the lower triangle of `cov` (the upper is filled from it);
    /// `None` when Σ is not positive definite.
    pub(crate) fn with_covariance(mean: Vec<f64>, mut cov: Vec<Vec<f64>>) -> Option<Self> {
        let d = mean.len();
        for a in 0..d {
            for b in 0..a {
                cov[b][a] = cov[a][b];
            }
        }
        if (0..d).any(|a| !(cov[a][a] > 0.0 && cov[a][a].is_finite())) {
            return None;
        }
        let lower = cholesky_lower(&cov)?;
        let half_log_det = (0..d).map(|a| lower[a][a].ln()).sum();
        Some(Self {
            mean,
            lower,
            half_log_det,
        })
    }

    /// The same normal with every std multiplied by `factor`.
    fn widened(mut self, factor: f64) -> Self {
        for row in &mut self.lower {
            for v in row.iter_mut() {
                *v *= factor;
            }
        }
        self.half_log_det += self.mean.len() as f64 * factor.ln();
        self
    }

    /// ln N(x; μ, Σ) + (d/2)·ln 2π.
    pub(crate) fn log_density(&self, x: &[f64]) -> f64 {
        let d = self.mean.len();
        let mut z = vec![0.0; d];
        for a in 0..d {
            let s: f64 = (0..a).map(|b| self.lower[a][b] * z[b]).sum();
            z[a] = (x[a] - self.mean[a] - s) / self.lower[a][a];
        }
        -0.5 * z.iter().map(|v| v * v).sum::<f64>() - self.half_log_det
    }
}

/// g(θ) = ln N(θ; μ_w, f²Σ_w) − ln N(θ; μ_q, Σ_q): the log-ratio that moves a proposal with the
/// batch's moments to the moments its importance weights give, stds widened f times (see the
/// module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct GaussianLogRatio {
    target: Normal,
    proposal: Normal,
    bounds: Vec<(f64, f64)>,
    ceiling: f64,
}

/// The weighted and the equally weighted normal of `points` (`None`: fewer than 2(d + 1)
/// effective weights, or a singular covariance).
fn batch_moments(points: &[Vec<f64>], log_weights: &[f64]) -> Option<(Normal, Normal)> {
    let d = points.first()?.len();
    if points.len() != log_weights.len() || points.iter().any(|p| p.len() != d) {
        return None;
    }
    let weights = normalised_weights(log_weights);
    if weights.iter().any(|w| !w.is_finite())
        || effective_sample_size(&weights) < 2.0 * (d as f64 + 1.0)
    {
        return None;
    }
    let equal = vec![1.0 / points.len() as f64; points.len()];
    Some((Normal::of(points, &weights)?, Normal::of(points, &equal)?))
}

impl GaussianLogRatio {
    /// The log-ratio of the batch `points` with their (unnormalised, possibly −∞) `log_weights`,
    /// towards a target whose stds are `widening` times the weighted ones (see
    /// [`DEFENSIVE_WIDENING`]; 1: the weighted moments), its ceiling drawn by `seed`; `None`
    /// when the weights' effective sample size is below 2(d + 1) (too few to estimate a
    /// covariance) or a covariance is singular.
    pub fn fit(points: &[Vec<f64>], log_weights: &[f64], widening: f64, seed: u64) -> Option<Self> {
        if !(widening.is_finite() && widening > 0.0) {
            return None;
        }
        let (target, proposal) = batch_moments(points, log_weights)?;
        let d = proposal.mean.len();
        let bounds = (0..d)
            .map(|k| {
                let (lo, hi) = points
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                        (a.min(p[k]), b.max(p[k]))
                    });
                (lo - (hi - lo), hi + (hi - lo))
            })
            .collect();
        let mut ratio = Self {
            target: target.widened(widening),
            proposal,
            bounds,
            ceiling: f64::INFINITY,
        };
        let mut rng = stream(seed, CEILING_STREAM, 0);
        let mut ceiling = f64::NEG_INFINITY;
        for _ in 0..CEILING_DRAWS {
            let z: Vec<f64> = (0..d).map(|_| StandardNormal.sample(&mut rng)).collect();
            let x: Vec<f64> = (0..d)
                .map(|a| {
                    ratio.target.mean[a]
                        + (0..=a)
                            .map(|b| ratio.target.lower[a][b] * z[b])
                            .sum::<f64>()
                })
                .collect();
            ceiling = ceiling.max(ratio.log_ratio(&x));
        }
        ratio.ceiling = ceiling;
        Some(ratio)
    }

    /// g(θ), θ clamped to the batch's widened box, and at most the ceiling (NaN for a θ of
    /// another dimension than the batch's).
    pub fn log_ratio(&self, theta: &[f64]) -> f64 {
        if theta.len() != self.bounds.len() {
            return f64::NAN;
        }
        let x: Vec<f64> = theta
            .iter()
            .zip(&self.bounds)
            .map(|(v, (lo, hi))| v.clamp(*lo, *hi))
            .collect();
        (self.target.log_density(&x) - self.proposal.log_density(&x)).min(self.ceiling)
    }

    /// The importance-weighted mean μ_w the correction moves to.
    pub fn target_mean(&self) -> &[f64] {
        &self.target.mean
    }
}

/// The outcome of [`proposal_mismatch`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProposalMismatch {
    /// Mahalanobis distance of the weighted mean from the proposal's, in the proposal's
    /// covariance: √((μ_w − μ_q)ᵀ Σ_q⁻¹ (μ_w − μ_q)).
    pub mean_shift: f64,
    /// The Kullback–Leibler divergence of the weighted covariance from the proposal's,
    /// ½(tr A − d − ln det A), A = Σ_q⁻¹Σ_w (0: equal spreads).
    pub spread_divergence: f64,
    /// Bonferroni's p-value of the two: 2·min(p_mean, p_spread), each the share of
    /// permutations of the weights over the members whose statistic is at least as large
    /// ((1 + count)/(1 + permutations)); at most 1.
    pub p_value: f64,
    /// Permutations made.
    pub permutations: usize,
}

impl ProposalMismatch {
    /// Whether the mismatch exceeds what the weights' noise explains at [`MISMATCH_LEVEL`].
    pub fn significant(&self) -> bool {
        self.p_value < MISMATCH_LEVEL
    }
}

/// (mean shift, spread divergence) of `points` weighted by `log_weights` against their equal
/// weights (`None` without a fit).
fn mismatch_statistics(points: &[Vec<f64>], log_weights: &[f64]) -> Option<(f64, f64)> {
    let (t, q) = batch_moments(points, log_weights)?;
    let (t, q) = (&t, &q);
    let d = t.mean.len();
    let solve = |v: &[f64]| -> Vec<f64> {
        let mut z = vec![0.0; d];
        for a in 0..d {
            let s: f64 = (0..a).map(|b| q.lower[a][b] * z[b]).sum();
            z[a] = (v[a] - s) / q.lower[a][a];
        }
        z
    };
    let shift: Vec<f64> = (0..d).map(|k| t.mean[k] - q.mean[k]).collect();
    let mean_shift = solve(&shift).iter().map(|v| v * v).sum::<f64>().sqrt();
    // tr(Σ_q⁻¹Σ_w) = ‖L_q⁻¹L_w‖²_F, ln det(Σ_q⁻¹Σ_w) = 2(ln|L_w| − ln|L_q|).
    let trace: f64 = (0..d)
        .map(|c| {
            let column: Vec<f64> = (0..d).map(|a| t.lower[a][c]).collect();
            solve(&column).iter().map(|v| v * v).sum::<f64>()
        })
        .sum();
    let log_det = 2.0 * (t.half_log_det - q.half_log_det);
    Some((mean_shift, 0.5 * (trace - d as f64 - log_det)))
}

/// The proposal's mismatch with the importance target: how far the weighted mean lies from the
/// proposal's and how far the weighted covariance from its, each tested against
/// [`PERMUTATIONS`] random reassignments of the same `log_weights` to the `points` (seeded by
/// `seed`; the same for any thread count). `None` when the moments cannot be fitted (too few
/// effective weights: the weights' noise is then all one can see).
///
/// Two statistics, not one: on 300 draws in 3-D with log-normal weight noise (σ = 1) a shift of
/// 0.4 std is found 95 % of the time by the mean's distance alone and 18 % by a single
/// statistic of the whole Gaussian log-ratio (the CV of e^g), whose covariance terms drown one
/// direction's signal; the spread is tested apart because a proposal narrower than the target
/// is the mismatch that biases importance sampling most.
pub fn proposal_mismatch(
    points: &[Vec<f64>],
    log_weights: &[f64],
    seed: u64,
) -> Option<ProposalMismatch> {
    let (mean_shift, spread_divergence) = mismatch_statistics(points, log_weights)?;
    let (exceed_mean, exceed_spread) = (0..PERMUTATIONS)
        .into_par_iter()
        .map(|b| {
            let mut permuted = log_weights.to_vec();
            permuted.shuffle(&mut stream(seed, PERMUTATION_STREAM, b as u64));
            // A permutation whose weights cannot be fitted shows no mismatch.
            match mismatch_statistics(points, &permuted) {
                Some((m, s)) => (
                    usize::from(m >= mean_shift),
                    usize::from(s >= spread_divergence),
                ),
                None => (0, 0),
            }
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    let p = |exceed: usize| (1 + exceed) as f64 / (1 + PERMUTATIONS) as f64;
    Some(ProposalMismatch {
        mean_shift,
        spread_divergence,
        p_value: (2.0 * p(exceed_mean).min(p(exceed_spread))).min(1.0),
        permutations: PERMUTATIONS,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn draws(n: usize, d: usize, seed: u64) -> Vec<Vec<f64>> {
        let mut rng = stream(seed, 1, 0);
        (0..n)
            .map(|_| (0..d).map(|_| StandardNormal.sample(&mut rng)).collect())
            .collect()
    }

    #[test]
    fn the_log_ratio_of_exact_gaussian_weights_is_the_gaussians_log_ratio() {
        // Proposal N(0, I) in 2-D, target N((0.5, −0.3), diag(0.8², 1.2²)): with 20,000 draws the
        // fitted g matches ln N_target − ln N_proposal up to a constant, to the moments' MCSE.
        let points = draws(20_000, 2, 3);
        let (m, s) = ([0.5, -0.3], [0.8, 1.2]);
        let exact = |x: &[f64]| -> f64 {
            (0..2)
                .map(|k| -0.5 * ((x[k] - m[k]) / s[k]).powi(2) - s[k].ln() + 0.5 * x[k] * x[k])
                .sum()
        };
        let lw: Vec<f64> = points.iter().map(|p| exact(p)).collect();
        let g = GaussianLogRatio::fit(&points, &lw, 1.0, 1).unwrap();
        for k in 0..2 {
            assert!(
                (g.target_mean()[k] - m[k]).abs() < 0.03,
                "{:?}",
                g.target_mean()
            );
        }
        let at = |x: [f64; 2]| g.log_ratio(&x) - exact(&x);
        let offset = at([0.0, 0.0]);
        for x in [[1.0, 1.0], [-1.0, 0.5], [0.5, -1.5]] {
            assert!((at(x) - offset).abs() < 0.1, "{x:?}: {}", at(x) - offset);
        }
    }

    #[test]
    fn pure_noise_in_the_weights_is_not_called_a_mismatch_and_a_shift_or_a_narrow_proposal_is() {
        // Weights with log-normal noise (σ = 1) and no θ-dependence: the p-value is uniform (or,
        // Bonferroni's, conservative), so at level 0.05 at most about 1 in 20 of 40 seeds is
        // called off; under Binomial(40, 0.05) 5 or more has probability 0.048, 6 or more 0.014
        // and 7 or more 0.0034: the count is held below 7.
        let mut alarms = 0;
        for seed in 0..40 {
            let points = draws(300, 3, 100 + seed);
            let mut rng = stream(seed, 2, 0);
            let lw: Vec<f64> = (0..300)
                .map(|_| {
                    let z: f64 = StandardNormal.sample(&mut rng);
                    z
                })
                .collect();
            let m = proposal_mismatch(&points, &lw, seed).unwrap();
            if m.p_value < 0.05 {
                alarms += 1;
            }
        }
        assert!(alarms < 7, "{alarms} false alarms of 40");
        // The same noise on a target shifted by 0.4 std in x0: significant.
        let points = draws(300, 3, 7);
        let mut rng = stream(7, 2, 0);
        let lw: Vec<f64> = points
            .iter()
            .map(|p| {
                let z: f64 = StandardNormal.sample(&mut rng);
                z + 0.4 * p[0]
            })
            .collect();
        let m = proposal_mismatch(&points, &lw, 7).unwrap();
        assert!(m.significant(), "{m:?}");
        // …and a target 1.6 times as wide in x0 (a proposal too narrow): significant.
        let lw: Vec<f64> = points
            .iter()
            .map(|p| {
                let z: f64 = StandardNormal.sample(&mut rng);
                z + 0.3 * p[0] * p[0]
            })
            .collect();
        let m = proposal_mismatch(&points, &lw, 7).unwrap();
        assert!(m.significant(), "{m:?}");
        // Too few effective weights: no test.
        let mut lw = vec![f64::NEG_INFINITY; 300];
        lw[..5].fill(0.0);
        assert!(proposal_mismatch(&points, &lw, 1).is_none());
    }

    #[test]
    fn the_permutation_test_is_the_same_for_any_thread_count() {
        let points = draws(200, 2, 5);
        let lw: Vec<f64> = points.iter().map(|p| 0.2 * p[1]).collect();
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| proposal_mismatch(&points, &lw, 9));
        let many = rayon::ThreadPoolBuilder::new()
            .num_threads(4)
            .build()
            .unwrap()
            .install(|| proposal_mismatch(&points, &lw, 9));
        assert_eq!(one, many);
    }
}
