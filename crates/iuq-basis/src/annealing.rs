//! The annealing schedule and the evidence (BASIS steps 2 and 3 in docs/methods.md §5; Ching &
//! Chen 2007, eq. 17; Wu et al. 2017, section 3).
//!
//! Stage k targets f(D|θ)^{p_k}·π(θ), 0 = p_0 < p_1 < … < p_m = 1. Going from p to p + dp, the
//! population drawn at p is weighted by w_i = f(D|θ_i)^{dp}; the next exponent is the one whose
//! weights have a given coefficient of variation γ.
//!
//! **CV convention**: CV = std(w)/mean(w) with the *population* standard deviation (ddof = 0,
//! as `numpy.std`), over all N members (failed members, ln f = −∞, have w = 0). With this
//! convention ESS/N = 1/(1 + CV²) exactly, where ESS = 1/Σw̄_i² (Kish), so γ = 1 means
//! ESS = N/2.

use serde::{Deserialize, Serialize};

/// Largest finite value of `log_likelihood`, or `None` when none is finite.
pub fn max_finite(log_likelihood: &[f64]) -> Option<f64> {
    log_likelihood
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(None, |m, v| Some(m.map_or(v, |m: f64| m.max(v))))
}

/// Unnormalised weights w_i = exp(dp·(ll_i − max ll)) ∈ [0, 1]; 0 for non-finite ll_i (also
/// when dp = 0, where the formula would give 0·∞).
pub fn incremental_weights(log_likelihood: &[f64], dp: f64, max_ll: f64) -> Vec<f64> {
    log_likelihood
        .iter()
        .map(|&ll| {
            if ll.is_finite() {
                (dp * (ll - max_ll)).exp()
            } else {
                0.0
            }
        })
        .collect()
}

/// Coefficient of variation std(w)/mean(w) of weights, with the population std (ddof = 0);
/// +∞ when the mean is 0.
pub fn coefficient_of_variation(weights: &[f64]) -> f64 {
    let n = weights.len() as f64;
    let mean = weights.iter().sum::<f64>() / n;
    if mean <= 0.0 || !mean.is_finite() {
        return f64::INFINITY;
    }
    let variance = weights.iter().map(|w| (w - mean).powi(2)).sum::<f64>() / n;
    variance.sqrt() / mean
}

/// The CV of the weights of step `dp`.
pub fn cv_of_step(log_likelihood: &[f64], dp: f64, max_ll: f64) -> f64 {
    coefficient_of_variation(&incremental_weights(log_likelihood, dp, max_ll))
}

/// The next exponent step, solved from the CV target.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ExponentStep {
    /// The step dp, with p + dp ≤ 1.
    pub step: f64,
    /// The CV of the weights of that step.
    pub cv: f64,
    /// Whether the step reaches p = 1 (the CV at dp = 1 − p is within the target).
    pub reaches_one: bool,
    /// Bisection iterations used (0 when p = 1 is reached directly).
    pub iterations: usize,
}

/// Relative tolerance of the bisection on dp: it stops when (hi − lo) ≤ 1e-10·hi.
pub const BISECTION_RELATIVE_TOLERANCE: f64 = 1e-10;
/// Largest number of bisection iterations (2^−400 is far below any useful step).
pub const BISECTION_MAX_ITERATIONS: usize = 400;

/// Solve CV(dp) = γ for dp ∈ (0, 1 − p] by bisection (BASIS step 2, docs/methods.md §5).
///
/// If CV(1 − p) ≤ γ the step is 1 − p (p' = 1). Otherwise CV is increasing in dp and the
/// bisection keeps lo with CV(lo) ≤ γ < CV(hi) until (hi − lo) ≤ 1e-10·hi; the step returned is
/// lo, so that the CV never exceeds the target — unless lo is still 0 (CV(0⁺) > γ, which happens
/// when more than N·γ²/(1 + γ²) members have failed), in which case it is hi, a tiny step the
/// caller compares with its minimum. `max_ll` must be finite.
pub fn next_step(log_likelihood: &[f64], p: f64, cv_target: f64, max_ll: f64) -> ExponentStep {
    let remaining = 1.0 - p;
    let cv_full = cv_of_step(log_likelihood, remaining, max_ll);
    if cv_full <= cv_target {
        return ExponentStep {
            step: remaining,
            cv: cv_full,
            reaches_one: true,
            iterations: 0,
        };
    }
    let (mut lo, mut hi) = (0.0f64, remaining);
    let mut iterations = 0;
    while iterations < BISECTION_MAX_ITERATIONS && hi - lo > BISECTION_RELATIVE_TOLERANCE * hi {
        let mid = 0.5 * (lo + hi);
        if cv_of_step(log_likelihood, mid, max_ll) <= cv_target {
            lo = mid;
        } else {
            hi = mid;
        }
        iterations += 1;
    }
    let step = if lo > 0.0 { lo } else { hi };
    ExponentStep {
        step,
        cv: cv_of_step(log_likelihood, step, max_ll),
        reaches_one: false,
        iterations,
    }
}

/// The evidence increment of a step (BASIS step 3, docs/methods.md §5):
/// ln E[f^{dp}] ≈ m + ln Σ_i exp(dp·ll_i − m) − ln N, with m = max_i dp·ll_i over finite ll_i
/// (failed members contribute 0 to the sum). Exactly 0 for dp = 0.
pub fn log_evidence_increment(log_likelihood: &[f64], dp: f64, max_ll: f64) -> f64 {
    if dp == 0.0 {
        return 0.0;
    }
    let m = dp * max_ll;
    let sum: f64 = log_likelihood
        .iter()
        .filter(|v| v.is_finite())
        .map(|&ll| (dp * ll - m).exp())
        .sum();
    m + sum.ln() - (log_likelihood.len() as f64).ln()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cv_is_the_population_cv_and_ess_relation_holds() {
        let w = [1.0, 2.0, 3.0, 6.0];
        // numpy: np.std(w)/np.mean(w)
        let cv = coefficient_of_variation(&w);
        assert!((cv - 0.623_609_564_462_323_5).abs() < 1e-15, "{cv}");
        let total: f64 = w.iter().sum();
        let ess = 1.0 / w.iter().map(|x| (x / total).powi(2)).sum::<f64>();
        assert!((ess / 4.0 - 1.0 / (1.0 + cv * cv)).abs() < 1e-14);
        assert_eq!(coefficient_of_variation(&[0.0, 0.0]), f64::INFINITY);
    }

    #[test]
    fn bisection_hits_the_target_or_reaches_one() {
        let ll: Vec<f64> = (0..1000).map(|i| -0.05 * i as f64).collect();
        let max = max_finite(&ll).unwrap();
        let s = next_step(&ll, 0.0, 1.0, max);
        assert!(!s.reaches_one);
        assert!(s.cv <= 1.0 && (s.cv - 1.0).abs() < 1e-6, "{s:?}");
        assert!(s.step > 0.0 && s.step < 1.0);
        // flat likelihood: straight to one
        let flat = vec![-3.0; 10];
        let s = next_step(&flat, 0.4, 1.0, -3.0);
        assert!(s.reaches_one && s.step == 0.6 && s.cv == 0.0);
    }

    #[test]
    fn more_than_half_failed_gives_a_tiny_step() {
        let mut ll = vec![f64::NEG_INFINITY; 60];
        ll.extend((0..40).map(|i| -(i as f64)));
        let max = max_finite(&ll).unwrap();
        let s = next_step(&ll, 0.0, 1.0, max);
        assert!(s.step < 1e-100, "{s:?}");
        assert!(s.step > 0.0);
    }

    #[test]
    fn evidence_increment_is_log_mean_of_powered_likelihoods() {
        let ll = [-1.0, -2.0, f64::NEG_INFINITY, -0.5];
        let dp: f64 = 0.3;
        let direct = ((-dp).exp() + (-2.0 * dp).exp() + (-0.5 * dp).exp()) / 4.0;
        let inc = log_evidence_increment(&ll, dp, -0.5);
        assert!((inc - direct.ln()).abs() < 1e-14);
        assert_eq!(log_evidence_increment(&ll, 0.0, -0.5), 0.0);
        // large magnitudes do not overflow
        let big = [-1e6, -1e6 - 1.0];
        let inc = log_evidence_increment(&big, 1.0, -1e6);
        let expected = -1e6 + (1.0 + (-1.0f64).exp()).ln() - 2.0f64.ln();
        assert!((inc - expected).abs() < 1e-9);
    }
}
