//! When to stop refining: the posterior has stopped moving, and the surrogate's own uncertainty
//! could not move it by more than the tolerance either.
//!
//! Between consecutive rounds, the shift of parameter k is
//! δ_k = max(|μ_k − μ'_k| − z·e_μk, |σ_k − σ'_k| − z·e_σk, 0)/σ_k (posterior mean μ and std σ of
//! this round, μ', σ' of the previous one), where e_μk = √(se²(μ_k) + se²(μ'_k)) is the Monte
//! Carlo error of the difference of the means (likewise e_σk of the stds) and z =
//! [`NOISE_MULTIPLE`]: a shift counts only as far as it exceeds the sampler's own noise. The
//! sampler's noise must itself be resolved, ν_k = z·max(e_μk, e_σk)/σ_k below `tolerance`, or
//! no shift could be told from noise (the caller then samples more). The Monte Carlo errors come
//! from independent replicate samplers ([`PosteriorMoments::pooled`]): a sequential Monte Carlo
//! population descends from few lineages, so its moments scatter far more than N independent
//! samples would (on the red-cell study, two BASIS runs of N = 2000 on the same surrogate differ
//! by 0.2–0.3 posterior stds). The round's surrogate error ε is the largest typical change
//! (68.3 % quantile of its absolute value) of a posterior mean or std under draws of the GPs'
//! error, in posterior stds ([`crate::moment_error`]). The loop has converged when max_k δ_k and
//! max_k ν_k are below `tolerance` and m·ε is too, m = `surrogate_error_multiple` (default
//! [`SURROGATE_ERROR_MULTIPLE`] = 2: a moment stands within `tolerance` of the model's posterior
//! at about 95 %, where m = 1 leaves about one in three further): the shift guards the
//! summaries a user reads, ε that they are not the same
//! wrong answer twice (a surrogate that has not yet seen the posterior region can be stable and
//! wrong). u = E_posterior[√(Σ_t Var[ℓ_t(θ)])], the posterior mean of the surrogate's std of
//! the log-likelihood ([`crate::acquisition`]), is reported beside it and compared with
//! `log_likelihood_tolerance` by the caller (whether the surrogate is sure enough to place
//! boundary runs, which candidates are worth a run) but does not decide convergence: it also
//! counts an error the surrogate makes alike over the whole posterior, which moves the evidence
//! and not the posterior, and for a model whose runs scatter it falls only as fast as that
//! scatter averages out. The criterion is that of Dakota's
//! posterior-adaptive surrogates and GPry's (El Gammal et al. 2023) in spirit: judge convergence on
//! the posterior, not on the surrogate's global error.

use serde::{Deserialize, Serialize};

use crate::error::{AdaptiveError, Result};

/// How many Monte Carlo standard errors of a difference of moments a shift must exceed to
/// count (about a 95 % two-sided band for a normal error).
pub const NOISE_MULTIPLE: f64 = 2.0;

/// The default of [`ConvergenceCriterion::surrogate_error_multiple`]: ε, a typical (one-σ)
/// change, counts twice, so that at the stop every posterior mean and std stands within
/// `tolerance` of the model's at about 95 % for a normal error (as [`NOISE_MULTIPLE`] for the
/// sampler's noise).
pub const SURROGATE_ERROR_MULTIPLE: f64 = 2.0;

/// The multiple of the stores recorded before it existed, which held ε itself to `tolerance`.
fn recorded_surrogate_error_multiple() -> f64 {
    1.0
}

/// The posterior mean and standard deviation of each parameter after one round, with their
/// Monte Carlo standard errors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PosteriorMoments {
    /// Posterior mean per parameter.
    pub mean: Vec<f64>,
    /// Posterior standard deviation per parameter.
    pub std: Vec<f64>,
    /// Monte Carlo standard error of each mean (zeros when unknown: one sampler run).
    pub mean_error: Vec<f64>,
    /// Monte Carlo standard error of each standard deviation (zeros when unknown).
    pub std_error: Vec<f64>,
}

impl PosteriorMoments {
    /// Moments without a known Monte Carlo error.
    pub fn exact(mean: Vec<f64>, std: Vec<f64>) -> Self {
        let d = mean.len();
        Self {
            mean,
            std,
            mean_error: vec![0.0; d],
            std_error: vec![0.0; d],
        }
    }

    /// The moments of R independent sampler runs of equal population size pooled: the mean of
    /// the means, the std of the pooled population (√(mean of σ_r² + μ_r², minus μ̄²)), and as
    /// Monte Carlo errors the replicates' sample std over √R (of the means and of the stds).
    /// With one replicate the errors are zero (unknown).
    ///
    /// # Errors
    /// No replicate, or replicates of different lengths.
    pub fn pooled(replicates: &[(Vec<f64>, Vec<f64>)]) -> Result<Self> {
        let Some((first, _)) = replicates.first() else {
            return Err(AdaptiveError::InvalidParameter {
                what: "replicate posteriors",
                reason: "none given".into(),
            });
        };
        let d = first.len();
        for (mean, std) in replicates {
            if mean.len() != d || std.len() != d {
                return Err(AdaptiveError::LengthMismatch {
                    what: "replicate moments",
                    expected: d,
                    actual: mean.len().min(std.len()),
                });
            }
        }
        let r = replicates.len() as f64;
        let average = |values: Vec<f64>| -> f64 { values.iter().sum::<f64>() / r };
        let standard_error = |values: Vec<f64>| -> f64 {
            if values.len() < 2 {
                return 0.0;
            }
            let m = values.iter().sum::<f64>() / r;
            let variance = values.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (r - 1.0);
            (variance / r).sqrt()
        };
        let mut pooled = Self::exact(vec![0.0; d], vec![0.0; d]);
        for k in 0..d {
            let mean = average(replicates.iter().map(|(m, _)| m[k]).collect());
            let second = average(
                replicates
                    .iter()
                    .map(|(m, s)| s[k] * s[k] + m[k] * m[k])
                    .collect(),
            );
            pooled.mean[k] = mean;
            pooled.std[k] = (second - mean * mean).max(0.0).sqrt();
            pooled.mean_error[k] = standard_error(replicates.iter().map(|(m, _)| m[k]).collect());
            pooled.std_error[k] = standard_error(replicates.iter().map(|(_, s)| s[k]).collect());
        }
        Ok(pooled)
    }

    fn check_lengths(&self, what: &'static str, d: usize) -> Result<()> {
        for len in [
            self.mean.len(),
            self.std.len(),
            self.mean_error.len(),
            self.std_error.len(),
        ] {
            if len != d {
                return Err(AdaptiveError::LengthMismatch {
                    what,
                    expected: d,
                    actual: len,
                });
            }
        }
        Ok(())
    }
}

/// The stopping rule of the adaptive loop.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ConvergenceCriterion {
    /// Largest shift of a posterior mean or std between rounds beyond the sampler's noise, largest
    /// noise, and largest surrogate error of a mean or std, in posterior stds.
    pub tolerance: f64,
    /// The posterior-mean std of the log-likelihood due to the surrogate (nats) below which the
    /// surrogate counts as sure where the posterior lies (for the caller's boundary runs and
    /// minimum score; not part of [`ConvergenceCriterion::assess`]).
    pub log_likelihood_tolerance: f64,
    /// How many times the surrogate's error ε counts against `tolerance`: ε is a typical
    /// (68.3 % quantile) change of a moment, so at 1 about one moment in three may still stand
    /// further than `tolerance` from the model's posterior; at [`SURROGATE_ERROR_MULTIPLE`]
    /// (the default) about one in twenty.
    #[serde(default = "recorded_surrogate_error_multiple")]
    pub surrogate_error_multiple: f64,
}

impl Default for ConvergenceCriterion {
    fn default() -> Self {
        Self {
            tolerance: 0.1,
            log_likelihood_tolerance: 0.05,
            surrogate_error_multiple: SURROGATE_ERROR_MULTIPLE,
        }
    }
}

/// The judgement of one round.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RoundAssessment {
    /// max_k δ_k against the previous round, beyond the sampler's noise (`None` in the first
    /// round).
    pub shift: Option<f64>,
    /// The shift of each parameter beyond the sampler's noise (empty in the first round).
    pub shifts: Vec<f64>,
    /// max_k ν_k, the sampler's noise on the shifts in posterior stds (`None` in the first
    /// round).
    pub noise: Option<f64>,
    /// u, the posterior mean of the surrogate's std of the log-likelihood (reported).
    pub log_likelihood_std: f64,
    /// ε, the surrogate's largest first-order error of a posterior mean or std, in posterior
    /// stds.
    pub surrogate_error: f64,
    /// The shift and the noise are below the tolerance, and ε times its multiple.
    pub converged: bool,
}

impl ConvergenceCriterion {
    /// Checks that both tolerances and the surrogate error's multiple are positive and finite.
    pub fn check(self) -> Result<Self> {
        for (what, v) in [
            ("convergence tolerance", self.tolerance),
            ("log-likelihood tolerance", self.log_likelihood_tolerance),
            ("surrogate error multiple", self.surrogate_error_multiple),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(AdaptiveError::InvalidParameter {
                    what,
                    reason: format!("{v} must be positive and finite"),
                });
            }
        }
        Ok(self)
    }

    /// Whether ε no longer keeps a round from converging: `surrogate_error_multiple`·ε below
    /// `tolerance`.
    pub fn surrogate_error_holds(&self, surrogate_error: f64) -> bool {
        self.surrogate_error_multiple * surrogate_error < self.tolerance
    }

    /// Judge a round from its moments, the previous round's, u and ε.
    ///
    /// # Errors
    /// Moments of different lengths.
    pub fn assess(
        &self,
        previous: Option<&PosteriorMoments>,
        current: &PosteriorMoments,
        log_likelihood_std: f64,
        surrogate_error: f64,
    ) -> Result<RoundAssessment> {
        let d = current.mean.len();
        current.check_lengths("this round's moments", d)?;
        let (shifts, noises): (Vec<f64>, Vec<f64>) = match previous {
            None => (Vec::new(), Vec::new()),
            Some(p) => {
                p.check_lengths("previous round's moments vs. this round's", d)?;
                (0..d)
                    .map(|k| {
                        let error = |a: f64, b: f64| NOISE_MULTIPLE * (a * a + b * b).sqrt();
                        let (em, es) = (
                            error(current.mean_error[k], p.mean_error[k]),
                            error(current.std_error[k], p.std_error[k]),
                        );
                        let (dm, ds) = (
                            (current.mean[k] - p.mean[k]).abs() - em,
                            (current.std[k] - p.std[k]).abs() - es,
                        );
                        // f64::max would drop a NaN; a NaN moment must show.
                        let moved = if dm.is_nan() || ds.is_nan() {
                            f64::NAN
                        } else {
                            dm.max(ds).max(0.0)
                        };
                        let noise = em.max(es);
                        let scale = |v: f64| if v == 0.0 { 0.0 } else { v / current.std[k] };
                        (scale(moved), scale(noise))
                    })
                    .unzip()
            }
        };
        // A NaN shift (a NaN moment) is no evidence of convergence: it counts as infinite.
        let largest = |values: &[f64]| {
            values
                .iter()
                .map(|s| if s.is_nan() { f64::INFINITY } else { *s })
                .fold(0.0, f64::max)
        };
        let (shift, noise) = if previous.is_some() {
            (Some(largest(&shifts)), Some(largest(&noises)))
        } else {
            (None, None)
        };
        let converged = shift.is_some_and(|s| s < self.tolerance)
            && noise.is_some_and(|n| n < self.tolerance)
            && self.surrogate_error_holds(surrogate_error);
        Ok(RoundAssessment {
            shift,
            shifts,
            noise,
            log_likelihood_std,
            surrogate_error,
            converged,
        })
    }
}

/// u = the posterior mean of √(Σ_t Var\[ℓ_t\]): `variances[i]` is the summed log-likelihood
/// variance at distinct posterior sample i, which stands for `copies[i]` samples of the
/// population. Zero for no samples.
pub fn surrogate_log_likelihood_std(variances: &[f64], copies: &[f64]) -> f64 {
    let total: f64 = copies.iter().sum();
    if total <= 0.0 {
        return 0.0;
    }
    variances
        .iter()
        .zip(copies)
        .map(|(v, n)| v.max(0.0).sqrt() * n)
        .sum::<f64>()
        / total
}

#[cfg(test)]
mod tests {
    use super::*;

    fn moments(mean: [f64; 2], std: [f64; 2]) -> PosteriorMoments {
        PosteriorMoments::exact(mean.to_vec(), std.to_vec())
    }

    #[test]
    fn shifts_are_measured_in_posterior_stds() {
        let c = ConvergenceCriterion::default().check().unwrap();
        let a = moments([1.0, 10.0], [0.5, 2.0]);
        let first = c.assess(None, &a, 0.01, 0.01).unwrap();
        assert!(!first.converged && first.shift.is_none());
        let b = moments([1.02, 10.1], [0.51, 2.0]);
        let second = c.assess(Some(&a), &b, 0.01, 0.01).unwrap();
        assert!((second.shifts[0] - 0.02 / 0.51).abs() < 1e-12);
        assert!((second.shifts[1] - 0.1 / 2.0).abs() < 1e-12);
        assert!(second.converged);
        // A NaN moment is not convergence.
        let nan = moments([f64::NAN, 10.0], [0.5, 2.0]);
        assert!(!c.assess(Some(&a), &nan, 0.01, 0.01).unwrap().converged);
        // The same moments with a surrogate whose error could move them are not converged.
        assert!(!c.assess(Some(&a), &b, 0.5, 0.5).unwrap().converged);
        // ε counts `surrogate_error_multiple` times: a typical change of 0.06 posterior stds
        // leaves about one moment in three further than 0.1 from the model's at multiple 1.
        assert!(!c.assess(Some(&a), &b, 0.01, 0.06).unwrap().converged);
        let once = ConvergenceCriterion {
            surrogate_error_multiple: 1.0,
            ..c
        };
        assert!(once.assess(Some(&a), &b, 0.01, 0.06).unwrap().converged);
        // A std that moved by 20 % is not converged.
        let d = moments([1.0, 10.0], [0.6, 2.0]);
        assert!(!c.assess(Some(&a), &d, 0.01, 0.01).unwrap().converged);
    }

    #[test]
    fn a_shift_counts_only_beyond_the_sampler_noise() {
        let c = ConvergenceCriterion::default().check().unwrap();
        let mut a = moments([1.0, 10.0], [1.0, 2.0]);
        a.mean_error = vec![0.03, 0.0];
        let mut b = moments([1.2, 10.0], [1.0, 2.0]);
        b.mean_error = vec![0.04, 0.0];
        let judged = c.assess(Some(&a), &b, 0.01, 0.01).unwrap();
        // |Δμ| = 0.2, noise 2·√(0.03² + 0.04²) = 0.1: the shift beyond it is 0.1 std.
        assert!(
            (judged.shifts[0] - 0.1).abs() < 1e-12,
            "{:?}",
            judged.shifts
        );
        assert!((judged.noise.unwrap() - 0.1).abs() < 1e-12);
        // The noise is not resolved at tolerance 0.1: no convergence yet, however small the
        // shift beyond it.
        assert!(!judged.converged);
        let loose = ConvergenceCriterion {
            tolerance: 0.15,
            ..Default::default()
        };
        assert!(loose.assess(Some(&a), &b, 0.01, 0.01).unwrap().converged);
        // A shift within the noise is none.
        b.mean[0] = 1.05;
        let within = loose.assess(Some(&a), &b, 0.01, 0.01).unwrap();
        assert_eq!(within.shifts[0], 0.0);
    }

    #[test]
    fn replicates_pool_into_the_population_moments_and_their_errors() {
        // Two replicates of N each: means 1 and 3, stds 1 and 1; the pooled population
        // (equal halves) has mean 2 and variance 1 + 1 = 2.
        let pooled = PosteriorMoments::pooled(&[
            (vec![1.0, 5.0], vec![1.0, 2.0]),
            (vec![3.0, 5.0], vec![1.0, 4.0]),
        ])
        .unwrap();
        assert!((pooled.mean[0] - 2.0).abs() < 1e-12);
        assert!((pooled.std[0] - 2.0_f64.sqrt()).abs() < 1e-12);
        // Standard errors: sample std of {1, 3} is √2, over √2 → 1; of {2, 4} → 1.
        assert!((pooled.mean_error[0] - 1.0).abs() < 1e-12);
        assert_eq!(pooled.std_error[0], 0.0);
        assert_eq!(pooled.mean_error[1], 0.0);
        assert!((pooled.std_error[1] - 1.0).abs() < 1e-12);
        assert!((pooled.std[1] - 10.0_f64.sqrt()).abs() < 1e-12);
        // One replicate: errors unknown (zero).
        let one = PosteriorMoments::pooled(&[(vec![1.0], vec![0.5])]).unwrap();
        assert_eq!((one.mean_error[0], one.std_error[0]), (0.0, 0.0));
        assert!(PosteriorMoments::pooled(&[]).is_err());
        assert!(
            PosteriorMoments::pooled(&[(vec![1.0], vec![0.5]), (vec![1.0, 2.0], vec![0.5, 1.0])])
                .is_err()
        );
    }

    #[test]
    fn bad_settings_and_sizes_are_errors() {
        assert!(
            ConvergenceCriterion {
                tolerance: 0.0,
                ..Default::default()
            }
            .check()
            .is_err()
        );
        assert!(
            ConvergenceCriterion {
                log_likelihood_tolerance: f64::NAN,
                ..Default::default()
            }
            .check()
            .is_err()
        );
        let c = ConvergenceCriterion::default();
        let a = moments([1.0, 2.0], [1.0, 1.0]);
        let short = PosteriorMoments::exact(vec![1.0], vec![1.0]);
        assert!(c.assess(Some(&short), &a, 0.0, 0.01).is_err());
    }

    #[test]
    fn the_spread_is_the_mean_std() {
        assert_eq!(surrogate_log_likelihood_std(&[], &[]), 0.0);
        assert!((surrogate_log_likelihood_std(&[0.04, 0.16], &[1.0, 1.0]) - 0.3).abs() < 1e-12);
        // A sample standing for three of the population counts three times.
        assert!((surrogate_log_likelihood_std(&[0.04, 0.16], &[3.0, 1.0]) - 0.25).abs() < 1e-12);
    }
}
