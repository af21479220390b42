//! Where the surrogate extrapolates: posterior mass far from every model run.
//!
//! The distance of θ to the runs, in the GP's length scales l_k, is
//! d(θ) = min_i √(Σ_k ((θ_k − x_ik)/l_k)²); beyond about one length scale the GP's correlation
//! with the nearest run, exp(−d²/2), falls below 0.6 and its prediction there leans on the prior
//! rather than on runs. The share of posterior samples with d > threshold is what a report shows
//! as "posterior mass where the surrogate extrapolates".

use rayon::prelude::*;

use crate::error::{AdaptiveError, Result};

/// d(θ): the distance from `point` to the nearest of `runs` in units of `length_scales`
/// (infinite when there are no runs).
pub fn nearest_run_distance(point: &[f64], runs: &[Vec<f64>], length_scales: &[f64]) -> f64 {
    runs.iter()
        .map(|x| distance(point, x, length_scales))
        .fold(f64::INFINITY, f64::min)
}

/// √(Σ_k ((p_k − x_k)/l_k)²).
fn distance(point: &[f64], run: &[f64], length_scales: &[f64]) -> f64 {
    point
        .iter()
        .zip(run)
        .zip(length_scales)
        .map(|((p, q), l)| ((p - q) / l).powi(2))
        .sum::<f64>()
        .sqrt()
}

/// The share of `samples` farther than `threshold` length scales from every run.
///
/// # Errors
/// Non-positive length scales or threshold, or points whose length differs from the number of
/// length scales.
pub fn extrapolation_share(
    samples: &[Vec<f64>],
    runs: &[Vec<f64>],
    length_scales: &[f64],
    threshold: f64,
) -> Result<f64> {
    if length_scales.iter().any(|l| !(l.is_finite() && *l > 0.0)) {
        return Err(AdaptiveError::InvalidParameter {
            what: "length scales",
            reason: format!("{length_scales:?} must be positive and finite"),
        });
    }
    if !(threshold.is_finite() && threshold > 0.0) {
        return Err(AdaptiveError::InvalidParameter {
            what: "extrapolation threshold",
            reason: format!("{threshold} must be positive and finite"),
        });
    }
    let d = length_scales.len();
    if let Some(p) = samples.iter().chain(runs).find(|p| p.len() != d) {
        return Err(AdaptiveError::LengthMismatch {
            what: "point coordinates vs. length scales",
            expected: d,
            actual: p.len(),
        });
    }
    if samples.is_empty() {
        return Ok(0.0);
    }
    // A sample is near as soon as one run lies within the threshold, which for a posterior
    // sample is usually among the first runs looked at.
    let far = samples
        .par_iter()
        .filter(|s| {
            !runs
                .iter()
                .any(|x| distance(s, x, length_scales) <= threshold)
        })
        .count();
    Ok(far as f64 / samples.len() as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distances_are_in_length_scales() {
        let runs = vec![vec![0.0, 0.0], vec![10.0, 0.0]];
        let l = [2.0, 0.5];
        assert!(
            (nearest_run_distance(&[1.0, 0.5], &runs, &l) - (0.25f64 + 1.0).sqrt()).abs() < 1e-12
        );
        assert!(nearest_run_distance(&[1.0, 0.5], &[], &l).is_infinite());
        let samples = vec![
            vec![0.5, 0.1],
            vec![5.0, 0.0],
            vec![9.0, 0.2],
            vec![5.0, 3.0],
        ];
        let share = extrapolation_share(&samples, &runs, &l, 1.0).unwrap();
        assert!((share - 0.5).abs() < 1e-12);
        assert!(extrapolation_share(&samples, &runs, &[1.0], 1.0).is_err());
        assert!(extrapolation_share(&samples, &runs, &l, 0.0).is_err());
        assert!(extrapolation_share(&samples, &runs, &[0.0, 1.0], 1.0).is_err());
    }
}
