//! Pareto-smoothed importance sampling (PSIS; Vehtari, Simpson, Gelman, Yao & Gabry 2024,
//! "Pareto smoothed importance sampling", JMLR 25(72)): the diagnostic k̂ of a set of importance
//! weights and the smoothed weights, with the conventions of ArviZ's `psislw` (tested against
//! it).
//!
//! Of S log-weights, the largest M = ⌈min(0.2·S, 3·√S)⌉ (those above the (M+1)-th largest) are
//! the tail. The exceedances exp(lw) − exp(lw_cut) are fitted with a generalised Pareto
//! distribution by the empirical-Bayes estimate of Zhang & Stephens (2009) with ArviZ's weakly
//! informative prior on k (k̂ ← (M·k + 10·0.5)/(M + 10)); the tail weights are replaced by the
//! fitted distribution's quantiles at (i − ½)/M and truncated at the largest raw weight.
//!
//! k̂ is the estimated shape of the weights' upper tail: the importance-sampling estimate has a
//! finite variance for k < ½, and PSIS estimates are reliable for k̂ < min(1 − 1/log₁₀ S, 0.7)
//! ([`pareto_k_threshold`]); above it the proposal (here: a surrogate's posterior) misses part
//! of the target and more samples do not help.

/// PSIS of one set of log-weights.
#[derive(Debug, Clone, PartialEq)]
pub struct ParetoSmoothing {
    /// The smoothed log-weights, normalised to Σ exp = 1 (−∞ stays −∞).
    pub log_weights: Vec<f64>,
    /// The estimated tail shape k̂ (+∞ when the tail has 4 or fewer members, as in ArviZ, except
    /// that weights whose M + 1 largest are all equal, a bounded tail, get 0).
    pub pareto_k: f64,
    /// The tail's size M.
    pub tail_length: usize,
}

/// The sample-size-dependent threshold of k̂ (Vehtari et al. 2024, §3.2.4):
/// min(1 − 1/log₁₀ S, 0.7); below it the PSIS estimate is reliable.
pub fn pareto_k_threshold(samples: usize) -> f64 {
    let s = samples.max(2) as f64;
    (1.0 - 1.0 / s.log10()).min(0.7)
}

/// exp(lw_i − logsumexp(lw)): the normalised weights (all 0 when no log-weight is finite).
pub fn normalised_weights(log_weights: &[f64]) -> Vec<f64> {
    let max = log_weights
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(f64::NEG_INFINITY, f64::max);
    if !max.is_finite() {
        return vec![0.0; log_weights.len()];
    }
    let w: Vec<f64> = log_weights.iter().map(|&v| (v - max).exp()).collect();
    let sum: f64 = w.iter().sum();
    w.into_iter().map(|v| v / sum).collect()
}

/// ln Σ exp(v_i) over the finite values (−∞ when there are none).
pub(crate) fn log_sum_exp(values: &[f64]) -> f64 {
    let max = values
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(f64::NEG_INFINITY, f64::max);
    if !max.is_finite() {
        return f64::NEG_INFINITY;
    }
    max + values.iter().map(|&v| (v - max).exp()).sum::<f64>().ln()
}

/// PSIS of `log_weights` (unnormalised; −∞ for a zero weight, e.g. a failed model run). With no
/// finite log-weight the result is all −∞ and k̂ = +∞.
pub fn pareto_smooth(log_weights: &[f64]) -> ParetoSmoothing {
    let s = log_weights.len();
    let tail_length = (0.2 * s as f64).min(3.0 * (s as f64).sqrt()).ceil() as usize;
    let max = log_weights
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(f64::NEG_INFINITY, f64::max);
    if !max.is_finite() || s == 0 {
        return ParetoSmoothing {
            log_weights: vec![f64::NEG_INFINITY; s],
            pareto_k: f64::INFINITY,
            tail_length,
        };
    }
    let mut x: Vec<f64> = log_weights.iter().map(|&v| v - max).collect();
    let mut order: Vec<usize> = (0..s).collect();
    order.sort_by(|&a, &b| x[a].total_cmp(&x[b]));
    // ArviZ: x_sorted[-M - 1], floored at ln(smallest positive normal double).
    let cut_index = s.saturating_sub(tail_length + 1);
    let cutoff = x[order[cut_index]].max(f64::MIN_POSITIVE.ln());
    let exp_cutoff = cutoff.exp();
    let mut tail: Vec<usize> = (0..s).filter(|&i| x[i] > cutoff).collect();
    let pareto_k = if tail.len() <= 4 && x[order[cut_index]] == 0.0 {
        // The M + 1 largest weights all equal the largest: bounded weights, no tail to fit
        // (ArviZ reports +∞ for any tail of 4 or fewer; a bounded tail is k ≤ 0, reported as 0).
        0.0
    } else if tail.len() <= 4 {
        f64::INFINITY
    } else {
        tail.sort_by(|&a, &b| x[a].total_cmp(&x[b]));
        let exceedances: Vec<f64> = tail.iter().map(|&i| x[i].exp() - exp_cutoff).collect();
        let (k, sigma) = generalised_pareto_fit(&exceedances);
        if !(sigma.is_finite() && sigma > 0.0) {
            // No usable fit (degenerate exceedances): no smoothing, and nothing certified.
            f64::INFINITY
        } else {
            if k.is_finite() {
                let m = tail.len();
                for (r, &i) in tail.iter().enumerate() {
                    let p = (r as f64 + 0.5) / m as f64;
                    let q = generalised_pareto_quantile(p, k, sigma);
                    x[i] = (q + exp_cutoff).ln().min(0.0);
                }
            }
            k
        }
    };
    let total = log_sum_exp(&x);
    for v in &mut x {
        *v -= total;
    }
    ParetoSmoothing {
        log_weights: x,
        pareto_k,
        tail_length,
    }
}

/// Zhang & Stephens' (2009) empirical-Bayes estimate (k, σ) of a generalised Pareto
/// distribution from sorted positive exceedances, with ArviZ's prior on k (10 pseudo-observations
/// at ½) and its grid of 30 + ⌊√n⌋ values of b = −k/σ.
fn generalised_pareto_fit(sorted: &[f64]) -> (f64, f64) {
    const PRIOR_BS: f64 = 3.0;
    const PRIOR_K: f64 = 10.0;
    let n = sorted.len();
    let m = 30 + (n as f64).sqrt() as usize;
    let quartile = sorted[((n as f64 / 4.0 + 0.5) as usize).saturating_sub(1)];
    let largest = sorted[n - 1];
    let b: Vec<f64> = (1..=m)
        .map(|j| {
            (1.0 - (m as f64 / (j as f64 - 0.5)).sqrt()) / (PRIOR_BS * quartile) + 1.0 / largest
        })
        .collect();
    let k_of = |b: f64| sorted.iter().map(|x| (-b * x).ln_1p()).sum::<f64>() / n as f64;
    let length_scale: Vec<f64> = b
        .iter()
        .map(|&bj| {
            let k = k_of(bj);
            n as f64 * ((-(bj / k)).ln() - k - 1.0)
        })
        .collect();
    // weight_j = 1 / Σ_i exp(L_i − L_j)
    let weights: Vec<f64> = length_scale
        .iter()
        .map(|&lj| 1.0 / length_scale.iter().map(|&li| (li - lj).exp()).sum::<f64>())
        .collect();
    let keep: Vec<usize> = (0..m)
        .filter(|&j| weights[j] >= 10.0 * f64::EPSILON)
        .collect();
    let total: f64 = keep.iter().map(|&j| weights[j]).sum();
    let b_post: f64 = keep.iter().map(|&j| b[j] * weights[j] / total).sum();
    let k_post = k_of(b_post);
    let sigma = -k_post / b_post;
    let k = (n as f64 * k_post + PRIOR_K * 0.5) / (n as f64 + PRIOR_K);
    (k, sigma)
}

/// The quantile at probability p ∈ (0, 1) of the generalised Pareto distribution with shape k
/// and scale σ: σ·expm1(−k·ln(1 − p))/k (σ·(−ln(1 − p)) for k = 0); NaN for σ ≤ 0.
fn generalised_pareto_quantile(p: f64, k: f64, sigma: f64) -> f64 {
    if sigma <= 0.0 || !sigma.is_finite() {
        return f64::NAN;
    }
    let q = if k.abs() < f64::EPSILON {
        -(-p).ln_1p()
    } else {
        (-k * (-p).ln_1p()).exp_m1() / k
    };
    q * sigma
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_threshold_follows_the_sample_size() {
        // 1 − 1/log10(S): 0.5 at S = 100, 0.6667 at 1000, capped at 0.7 from S ≈ 2154.
        assert!((pareto_k_threshold(100) - 0.5).abs() < 1e-12);
        assert!((pareto_k_threshold(1000) - (1.0 - 1.0 / 3.0)).abs() < 1e-12);
        assert_eq!(pareto_k_threshold(10_000), 0.7);
    }

    #[test]
    fn weights_without_a_tail_are_flagged_with_infinite_k() {
        let p = pareto_smooth(&[0.0, 1.0, 2.0]);
        assert_eq!(p.pareto_k, f64::INFINITY);
        let total: f64 = p.log_weights.iter().map(|v| v.exp()).sum();
        assert!((total - 1.0).abs() < 1e-12);
        // A model that fails where the surrogate does not: weights 1 or 0, bounded.
        let bounded: Vec<f64> = (0..50)
            .map(|i| if i % 3 == 0 { f64::NEG_INFINITY } else { 0.0 })
            .collect();
        assert_eq!(pareto_smooth(&bounded).pareto_k, 0.0);
        let none = pareto_smooth(&[f64::NEG_INFINITY; 10]);
        assert!(none.log_weights.iter().all(|v| *v == f64::NEG_INFINITY));
        assert_eq!(normalised_weights(&[f64::NEG_INFINITY; 3]), vec![0.0; 3]);
    }

    /// ArviZ 0.23's `_psislw` (cutoff ⌈min(0.2·S, 3√S)⌉, normalised) on three deterministic sets
    /// of S = 200 log-weights in the order i·37 mod S: exact Pareto quantiles of shape 0.3 and
    /// 0.8 (−k₀·ln((i + ½)/S)) and a light-tailed wave (sin 1.7i + 0.01i). The reference's k̂,
    /// four smoothed log-weights (indices 0, 5, 100 and the largest raw weight's) and the
    /// ESS of its weights.
    #[test]
    fn matches_arviz_psislw() {
        let s = 200usize;
        type Case = (&'static str, fn(f64) -> f64, f64, [f64; 4], f64);
        let cases: [Case; 3] = [
            (
                "pareto 0.3",
                |i| -0.3 * ((i + 0.5) / 200.0).ln(),
                0.3490369714739859,
                [
                    -3.856200383918203,
                    -5.6310610027004335,
                    -5.447191856335925,
                    -3.856200383918203,
                ],
                169.321065371156,
            ),
            (
                "pareto 0.8",
                |i| -0.8 * ((i + 0.5) / 200.0).ln(),
                0.7145657269524108,
                [
                    -2.0346440817244478,
                    -6.528122788739841,
                    -6.0378050651011534,
                    -2.0346440817244478,
                ],
                34.6276981124295,
            ),
            (
                "wave",
                |i| (1.7 * i).sin() + 0.01 * i,
                -0.10386524107696929,
                [
                    -6.700213344498689,
                    -4.5541349320823885,
                    -5.353563889001658,
                    -3.781098283766248,
                ],
                104.52306306756307,
            ),
        ];
        for (name, f, k, values, ess) in cases {
            let lw: Vec<f64> = (0..s).map(|i| f(((i * 37) % s) as f64)).collect();
            let largest = (0..s).max_by(|&a, &b| lw[a].total_cmp(&lw[b])).unwrap();
            let p = pareto_smooth(&lw);
            assert_eq!(p.tail_length, 40, "{name}");
            assert!((p.pareto_k - k).abs() < 1e-12, "{name}: k {}", p.pareto_k);
            for (j, v) in [0, 5, 100, largest].into_iter().zip(values) {
                assert!(
                    (p.log_weights[j] - v).abs() < 1e-12,
                    "{name}: lw[{j}] {}",
                    p.log_weights[j]
                );
            }
            assert!(
                (iuq_core::weighted_statistics::effective_sample_size(&normalised_weights(
                    &p.log_weights
                )) - ess)
                    .abs()
                    < 1e-9,
                "{name}"
            );
        }
    }
}
