//! When to stop refining: the posterior has stopped moving, and the surrogate is sure of the
//! log-likelihood where the posterior lies.
//!
//! Between consecutive rounds, the shift of parameter k is
//! δ_k = max(|μ_k − μ'_k|, |σ_k − σ'_k|)/σ_k (posterior mean μ and std σ of this round, μ', σ'
//! of the previous one), and the round's surrogate spread is
//! u = E_posterior[√(Σ_t Var[ℓ_t(θ)])], the posterior mean of the surrogate's std of the
//! log-likelihood (see [`crate::acquisition`]). The loop has converged when max_k δ_k <
//! `tolerance` and u < `log_likelihood_tolerance`: the first guards the summaries a user reads,
//! the second that they are not the same wrong answer twice (a surrogate that has not yet seen
//! the posterior region can be stable and wrong). The criterion is that of Dakota's
//! posterior-adaptive surrogates and GPry's (El Gammal et al. 2023) in spirit: judge convergence on
//! the posterior, not on the surrogate's global error.

use serde::{Deserialize, Serialize};

use crate::error::{AdaptiveError, Result};

/// The posterior mean and standard deviation of each parameter after one round.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PosteriorMoments {
    /// Posterior mean per parameter.
    pub mean: Vec<f64>,
    /// Posterior standard deviation per parameter.
    pub std: Vec<f64>,
}

/// The stopping rule of the adaptive loop.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ConvergenceCriterion {
    /// Largest shift of a posterior mean or std between rounds, in posterior stds.
    pub tolerance: f64,
    /// Largest posterior-mean std of the log-likelihood due to the surrogate (nats).
    pub log_likelihood_tolerance: f64,
}

impl Default for ConvergenceCriterion {
    fn default() -> Self {
        Self {
            tolerance: 0.1,
            log_likelihood_tolerance: 0.05,
        }
    }
}

/// The judgement of one round.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RoundAssessment {
    /// max_k δ_k against the previous round (`None` in the first round).
    pub shift: Option<f64>,
    /// The shift of each parameter (empty in the first round).
    pub shifts: Vec<f64>,
    /// u, the posterior mean of the surrogate's std of the log-likelihood.
    pub log_likelihood_std: f64,
    /// Both criteria hold.
    pub converged: bool,
}

impl ConvergenceCriterion {
    /// Checks that both tolerances are positive and finite.
    pub fn check(self) -> Result<Self> {
        for (what, v) in [
            ("convergence tolerance", self.tolerance),
            ("log-likelihood tolerance", self.log_likelihood_tolerance),
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

    /// Judge a round from its moments, the previous round's, and u.
    ///
    /// # Errors
    /// Moments of different lengths.
    pub fn assess(
        &self,
        previous: Option<&PosteriorMoments>,
        current: &PosteriorMoments,
        log_likelihood_std: f64,
    ) -> Result<RoundAssessment> {
        let d = current.mean.len();
        if current.std.len() != d {
            return Err(AdaptiveError::LengthMismatch {
                what: "posterior stds vs. means",
                expected: d,
                actual: current.std.len(),
            });
        }
        let shifts = match previous {
            None => Vec::new(),
            Some(p) => {
                if p.mean.len() != d || p.std.len() != d {
                    return Err(AdaptiveError::LengthMismatch {
                        what: "previous round's moments vs. this round's",
                        expected: d,
                        actual: p.mean.len().min(p.std.len()),
                    });
                }
                (0..d)
                    .map(|k| {
                        let (dm, ds) = (
                            (current.mean[k] - p.mean[k]).abs(),
                            (current.std[k] - p.std[k]).abs(),
                        );
                        // f64::max would drop a NaN; a NaN moment must show.
                        let moved = if dm.is_nan() || ds.is_nan() {
                            f64::NAN
                        } else {
                            dm.max(ds)
                        };
                        if moved == 0.0 {
                            0.0
                        } else {
                            moved / current.std[k]
                        }
                    })
                    .collect()
            }
        };
        // A NaN shift (a NaN moment) is no evidence of convergence: it counts as infinite.
        let shift = if previous.is_some() {
            Some(
                shifts
                    .iter()
                    .map(|s| if s.is_nan() { f64::INFINITY } else { *s })
                    .fold(0.0, f64::max),
            )
        } else {
            None
        };
        let converged = shift.is_some_and(|s| s < self.tolerance)
            && log_likelihood_std < self.log_likelihood_tolerance;
        Ok(RoundAssessment {
            shift,
            shifts,
            log_likelihood_std,
            converged,
        })
    }
}

/// u = the posterior mean of √(Σ_t Var[ℓ_t]): `variances[i]` is the summed log-likelihood
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
        PosteriorMoments {
            mean: mean.to_vec(),
            std: std.to_vec(),
        }
    }

    #[test]
    fn shifts_are_measured_in_posterior_stds() {
        let c = ConvergenceCriterion::default().check().unwrap();
        let a = moments([1.0, 10.0], [0.5, 2.0]);
        let first = c.assess(None, &a, 0.01).unwrap();
        assert!(!first.converged && first.shift.is_none());
        let b = moments([1.02, 10.1], [0.51, 2.0]);
        let second = c.assess(Some(&a), &b, 0.01).unwrap();
        assert!((second.shifts[0] - 0.02 / 0.51).abs() < 1e-12);
        assert!((second.shifts[1] - 0.1 / 2.0).abs() < 1e-12);
        assert!(second.converged);
        // A NaN moment is not convergence.
        let nan = moments([f64::NAN, 10.0], [0.5, 2.0]);
        assert!(!c.assess(Some(&a), &nan, 0.01).unwrap().converged);
        // The same moments with an unsure surrogate are not converged.
        assert!(!c.assess(Some(&a), &b, 0.5).unwrap().converged);
        // A std that moved by 20 % is not converged.
        let d = moments([1.0, 10.0], [0.6, 2.0]);
        assert!(!c.assess(Some(&a), &d, 0.01).unwrap().converged);
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
        let short = PosteriorMoments {
            mean: vec![1.0],
            std: vec![1.0],
        };
        assert!(c.assess(Some(&short), &a, 0.0).is_err());
    }

    #[test]
    fn the_spread_is_the_mean_std() {
        assert_eq!(surrogate_log_likelihood_std(&[], &[]), 0.0);
        assert!((surrogate_log_likelihood_std(&[0.04, 0.16], &[1.0, 1.0]) - 0.3).abs() < 1e-12);
        // A sample standing for three of the population counts three times.
        assert!((surrogate_log_likelihood_std(&[0.04, 0.16], &[3.0, 1.0]) - 0.25).abs() < 1e-12);
    }
}
