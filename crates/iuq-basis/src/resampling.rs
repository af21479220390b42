//! Resampling a weighted population into copy counts n_i with Σ n_i = N (BASIS step 5,
//! docs/methods.md §5).
//!
//! Both schemes place N sorted points u_1 ≤ … ≤ u_N in [0, 1) and count how many fall in each
//! member's slice of the cumulative weights, in O(N). Multinomial draws the N points as sorted
//! uniforms (generated in order as normalised cumulative sums of exponential spacings), which is
//! exactly N independent categorical draws; systematic uses u_k = (k + u)/N with one uniform u.

use rand::Rng;
use rand_distr::{Distribution, Exp1};

use crate::settings::Resampling;

/// Copy counts n_i for normalised weights `weights` (Σ = 1) and `n` draws.
///
/// Members with zero weight are never copied; rounding in the cumulative sum is absorbed by the
/// last member with positive weight.
pub fn resample<R: Rng + ?Sized>(
    weights: &[f64],
    n: usize,
    scheme: Resampling,
    rng: &mut R,
) -> Vec<usize> {
    let points = match scheme {
        Resampling::Multinomial => sorted_uniforms(n, rng),
        Resampling::Systematic => {
            let u: f64 = rng.random::<f64>();
            (0..n).map(|k| (k as f64 + u) / n as f64).collect()
        }
    };
    counts_from_sorted_points(weights, &points)
}

/// N sorted U(0,1) draws: the normalised partial sums of N + 1 standard exponentials (the
/// order statistics of uniforms; Devroye 1986, ch. V.2).
fn sorted_uniforms<R: Rng + ?Sized>(n: usize, rng: &mut R) -> Vec<f64> {
    let spacings: Vec<f64> = (0..=n).map(|_| Exp1.sample(rng)).collect();
    let total: f64 = spacings.iter().sum();
    let mut acc = 0.0;
    spacings[..n]
        .iter()
        .map(|e| {
            acc += e;
            acc / total
        })
        .collect()
}

fn counts_from_sorted_points(weights: &[f64], points: &[f64]) -> Vec<usize> {
    let mut counts = vec![0usize; weights.len()];
    let Some(last_positive) = weights.iter().rposition(|&w| w > 0.0) else {
        return counts;
    };
    let mut member = 0usize;
    let mut upper = weights[0];
    for &u in points {
        while u >= upper && member < last_positive {
            member += 1;
            upper += weights[member];
        }
        // never copy a zero-weight member, even at a rounding boundary
        let mut chosen = member;
        while weights[chosen] <= 0.0 && chosen < last_positive {
            chosen += 1;
        }
        counts[chosen] += 1;
    }
    counts
}

#[cfg(test)]
mod tests {
    use super::*;
    use iuq_core::random::stream;

    #[test]
    fn counts_sum_to_n_and_skip_zero_weights() {
        let w = [0.0, 0.5, 0.0, 0.25, 0.25, 0.0];
        for scheme in [Resampling::Multinomial, Resampling::Systematic] {
            let mut rng = stream(1, 0, 0);
            let c = resample(&w, 1000, scheme, &mut rng);
            assert_eq!(c.iter().sum::<usize>(), 1000);
            assert_eq!((c[0], c[2], c[5]), (0, 0, 0));
            if scheme == Resampling::Systematic {
                assert!((c[1] as i64 - 500).abs() <= 1 && (c[3] as i64 - 250).abs() <= 1);
            }
        }
    }

    #[test]
    fn multinomial_counts_have_multinomial_moments() {
        let w = [0.1, 0.2, 0.3, 0.4];
        let n = 100;
        let reps = 4000;
        let mut sum = [0.0; 4];
        let mut sum_sq = [0.0; 4];
        for r in 0..reps {
            let mut rng = stream(2, 0, r);
            let c = resample(&w, n, Resampling::Multinomial, &mut rng);
            for i in 0..4 {
                sum[i] += c[i] as f64;
                sum_sq[i] += (c[i] as f64).powi(2);
            }
        }
        for i in 0..4 {
            let mean = sum[i] / reps as f64;
            let var = sum_sq[i] / reps as f64 - mean * mean;
            let expected_var = n as f64 * w[i] * (1.0 - w[i]);
            // sd of the mean is sqrt(var/reps); the variance estimate is within ~10 %
            assert!((mean - n as f64 * w[i]).abs() < 5.0 * (expected_var / reps as f64).sqrt());
            assert!(
                (var / expected_var - 1.0).abs() < 0.12,
                "{i}: {var} vs {expected_var}"
            );
        }
    }
}
