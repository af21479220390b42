//! Monte Carlo standard errors of an importance-weighted estimate whose weights are heavy-tailed.
//!
//! Above a Pareto shape k̂ of ½ the importance weights have no finite variance, so the central
//! limit theorem behind the self-normalised delta method (and its ancestral grouping,
//! [`crate::ancestral_variance`]) no longer holds: the error shrinks more slowly than S^(−½), and
//! the delta method, computed from the weights that were drawn (which rarely include the few
//! that would dominate), understates it. Pareto smoothing keeps the estimate's variance finite
//! up to k̂ < 1, at the *relative convergence rate* of Vehtari, Simpson, Gelman, Yao & Gabry
//! (2024, "Pareto smoothed importance sampling", JMLR 25(72), Appendix B): the estimate's
//! variance falls locally as S^(−rate) with
//!
//! rate(k, S) = [2(k − 1)·S^(2k+1) + (1 − 2k)·S^(2k) + S²] / [(S − 1)(S − S^(2k))]
//!
//! for 0 < k < 1, k ≠ ½ (1 for k ≤ 0, 1 − 1/ln S at k = ½, 0 above 1).
//!
//! The error is then estimated by subsampling (Politis, Romano & Wolf 1999, "Subsampling",
//! Springer, §2–3: a statistic's distribution at a smaller sample size, rescaled by its known
//! rate): the members are dealt, one ancestor's group at a time, into B ≈ √G batches of the G
//! groups; each batch gives its own self-normalised mean and std; their variance across batches,
//! the variance at a sample B times smaller, scales to the whole sample by B^(−rate). At rate 1
//! this is the batch-means estimate. Where the weights are heavy-tailed the model posterior
//! reports the larger of it and the delta method.
//!
//! ```
//! use iuq_basis::heavy_tail_errors::{pareto_convergence_rate, subsampling_errors};
//!
//! // Light tails converge at nearly the central limit theorem's rate; heavier ones more slowly.
//! assert!(pareto_convergence_rate(0.3, 800) > 0.95);
//! let rate = pareto_convergence_rate(0.64, 800);
//! assert!(rate > 0.6 && rate < 0.75, "{rate}");
//!
//! // 400 equally weighted members, each its own ancestor, spread evenly over [0, 1): at rate 1
//! // the batch means' error of the mean is at most the independent formula's 0.29/√400 (each
//! // batch of these evenly spread values is spread evenly too).
//! let theta: Vec<Vec<f64>> = (0..400).map(|i| vec![(i * 263 % 400) as f64 / 400.0]).collect();
//! let weights = vec![1.0 / 400.0; 400];
//! let ancestor: Vec<usize> = (0..400).collect();
//! let errors = subsampling_errors(&theta, &weights, &ancestor, 1.0).unwrap();
//! assert_eq!(errors.batches, 20);
//! assert!(errors.mean[0] < 0.0145, "{}", errors.mean[0]);
//! ```

use serde::{Deserialize, Serialize};

/// The Pareto shape above which the importance weights' variance is infinite and the delta
/// method's standard error no longer holds.
pub const CLT_PARETO_K: f64 = 0.5;

/// The fewest ancestor groups for a subsampling estimate: 25, so that there are at least 5
/// batches to take a variance over.
pub const MIN_GROUPS: usize = 25;

/// The standard errors from subsampling, with what they were computed from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HeavyTailErrors {
    /// The relative convergence rate used ([`pareto_convergence_rate`]).
    pub convergence_rate: f64,
    /// The number of batches B.
    pub batches: usize,
    /// The error of each weighted mean.
    pub mean: Vec<f64>,
    /// The error of each weighted std.
    pub std: Vec<f64>,
}

/// The relative convergence rate of a Pareto-smoothed importance-sampling estimate from `samples`
/// weights of Pareto shape `k` (Vehtari et al. 2024, Appendix B): the exponent with which its
/// variance falls in S locally, 1 under the central limit theorem (k ≤ 0), just below 1 for
/// finite S up to k = ½ (1 − 1/ln S there), falling to 0 at k = 1.
pub fn pareto_convergence_rate(k: f64, samples: usize) -> f64 {
    let s = samples.max(2) as f64;
    if k.is_nan() || k >= 1.0 {
        return 0.0;
    }
    if k <= 0.0 {
        return 1.0;
    }
    if (k - 0.5).abs() < 1e-9 {
        return 1.0 - 1.0 / s.ln();
    }
    let rate =
        (2.0 * (k - 1.0) * s.powf(2.0 * k + 1.0) + (1.0 - 2.0 * k) * s.powf(2.0 * k) + s * s)
            / ((s - 1.0) * (s - s.powf(2.0 * k)));
    rate.clamp(0.0, 1.0)
}

/// The subsampling standard errors of the weighted means and stds of `theta` under the
/// normalised `weights`, members grouped by `ancestor` (equal labels share an ancestor), at the
/// relative convergence rate `convergence_rate`. `None` with fewer than [`MIN_GROUPS`] groups.
pub fn subsampling_errors(
    theta: &[Vec<f64>],
    weights: &[f64],
    ancestor: &[usize],
    convergence_rate: f64,
) -> Option<HeavyTailErrors> {
    let d = theta.first()?.len();
    let mut order: Vec<usize> = (0..theta.len()).collect();
    order.sort_by_key(|&i| (ancestor[i], i));
    // Group g of the ancestors (in their labels' order) goes to batch g mod B.
    let mut group_of = vec![0; theta.len()];
    let mut groups = 0;
    for (position, &i) in order.iter().enumerate() {
        if position > 0 && ancestor[order[position - 1]] != ancestor[i] {
            groups += 1;
        }
        group_of[i] = groups;
    }
    let groups = groups + 1;
    if groups < MIN_GROUPS {
        return None;
    }
    let batches = ((groups as f64).sqrt().round() as usize).max(5);
    let mut sums = vec![(0.0, vec![0.0; d], vec![0.0; d]); batches];
    for (i, t) in theta.iter().enumerate() {
        let (w, first, second) = &mut sums[group_of[i] % batches];
        *w += weights[i];
        for k in 0..d {
            first[k] += weights[i] * t[k];
            second[k] += weights[i] * t[k] * t[k];
        }
    }
    let moments: Vec<(Vec<f64>, Vec<f64>)> = sums
        .iter()
        .filter(|(w, _, _)| *w > 0.0)
        .map(|(w, first, second)| {
            let mean: Vec<f64> = first.iter().map(|f| f / w).collect();
            let std = second
                .iter()
                .zip(&mean)
                .map(|(s, m)| (s / w - m * m).max(0.0).sqrt())
                .collect();
            (mean, std)
        })
        .collect();
    if moments.len() < 2 {
        return None;
    }
    let scale = (batches as f64).powf(-convergence_rate);
    Some(HeavyTailErrors {
        convergence_rate,
        batches,
        mean: (0..d)
            .map(|k| scaled_spread(moments.iter().map(|m| m.0[k]), scale))
            .collect(),
        std: (0..d)
            .map(|k| scaled_spread(moments.iter().map(|m| m.1[k]), scale))
            .collect(),
    })
}

/// √(scale · the sample variance of `values`).
fn scaled_spread(values: impl Iterator<Item = f64> + Clone, scale: f64) -> f64 {
    let n = values.clone().count() as f64;
    let mean = values.clone().sum::<f64>() / n;
    let variance = values.map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (variance * scale).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rate_is_the_central_limit_theorems_for_light_tails_and_falls_beyond_a_half() {
        assert_eq!(pareto_convergence_rate(-0.2, 400), 1.0);
        assert_eq!(pareto_convergence_rate(0.5, 400), 1.0 - 1.0 / 400f64.ln());
        assert!(pareto_convergence_rate(0.1, 800) > 0.99);
        // The formula's removable singularity at k = ½: continuous through it, and within
        // 0.003 of the limit 1 − 1/ln S the reference code uses there (0.8356 against 0.8331).
        let below = pareto_convergence_rate(0.5 - 1e-6, 400);
        let above = pareto_convergence_rate(0.5 + 1e-6, 400);
        assert!((below - above).abs() < 1e-5, "{below} {above}");
        assert!((below - pareto_convergence_rate(0.5, 400)).abs() < 3e-3);
        // Vehtari et al.'s figures: about 0.67 at k = 0.64 and 0.57 at k = 0.7 for S = 800.
        assert!((pareto_convergence_rate(0.64, 800) - 0.6703).abs() < 1e-4);
        assert!((pareto_convergence_rate(0.7, 800) - 0.5716).abs() < 1e-4);
        let rates: Vec<f64> = [0.55, 0.6, 0.65, 0.7, 0.9]
            .iter()
            .map(|&k| pareto_convergence_rate(k, 800))
            .collect();
        assert!(rates.windows(2).all(|w| w[1] < w[0]), "{rates:?}");
        assert_eq!(pareto_convergence_rate(1.2, 800), 0.0);
        assert_eq!(pareto_convergence_rate(f64::NAN, 800), 0.0);
    }

    #[test]
    fn batch_means_of_independent_members_match_the_independent_formula_on_average() {
        // Equal weights, members i.i.d. N(0, 1) from a fixed LCG: the batch-means error of the
        // mean estimates 1/√S = 0.05 at S = 400; averaged over 50 samples its relative spread
        // (√(2/(B − 1)) = 0.32 each at B = 20) falls to 0.05, so 0.05 within ±20 %.
        let mut state = 12345u64;
        let mut uniform = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let mut total = 0.0;
        for _ in 0..50 {
            let theta: Vec<Vec<f64>> = (0..400)
                .map(|_| {
                    let (u, v) = (uniform(), uniform());
                    vec![(-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()]
                })
                .collect();
            let w = vec![1.0 / 400.0; 400];
            let a: Vec<usize> = (0..400).collect();
            total += subsampling_errors(&theta, &w, &a, 1.0).unwrap().mean[0];
        }
        let average = total / 50.0;
        assert!((average - 0.05).abs() < 0.01, "{average}");
    }

    #[test]
    fn members_of_one_ancestor_stay_in_one_batch_and_few_groups_give_none() {
        // 30 ancestors, each copied 10 times: the copies' identical values sit in one batch, so
        // the batches differ as the ancestors do (a 10-fold copy does not shrink the error).
        let theta: Vec<Vec<f64>> = (0..300).map(|i| vec![(i / 10) as f64]).collect();
        let w = vec![1.0 / 300.0; 300];
        let copies: Vec<usize> = (0..300).map(|i| i / 10).collect();
        let own: Vec<usize> = (0..300).collect();
        let grouped = subsampling_errors(&theta, &w, &copies, 1.0).unwrap();
        let independent = subsampling_errors(&theta, &w, &own, 1.0).unwrap();
        assert_eq!(grouped.batches, 5);
        assert!(
            grouped.mean[0] > 2.0 * independent.mean[0],
            "{grouped:?} {independent:?}"
        );
        let few: Vec<usize> = (0..300).map(|i| i / 20).collect();
        assert!(subsampling_errors(&theta, &w, &few, 1.0).is_none());
    }
}
