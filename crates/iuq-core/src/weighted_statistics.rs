//! Weighted sample statistics: normalised weights, effective sample size, mean, covariance and
//! quantiles (and the unweighted type-7 quantile of sorted values). Weights need not be normalised; they must be finite, non-negative and not all zero.

use crate::error::{CoreError, Result};

/// How a weighted covariance is normalised, with weights w̄ summing to one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CovarianceNormalisation {
    /// Σ_i w̄_i (x_i − μ)(x_i − μ)ᵀ — the plug-in estimate (BASIS proposal covariance).
    Biased,
    /// Σ_i w̄_i (x_i − μ)(x_i − μ)ᵀ / (1 − Σ_i w̄_i²) — reliability-weighted unbiased estimate
    /// (`numpy.cov(aweights=w)`, used by `scipy.stats.gaussian_kde`).
    Unbiased,
}

/// Quantile `p` ∈ [0, 1] of sorted values with linear interpolation between order statistics
/// (numpy's default, "type 7"); NaN for an empty slice.
pub fn quantile_sorted(sorted: &[f64], p: f64) -> f64 {
    match sorted.len() {
        0 => f64::NAN,
        1 => sorted[0],
        n => {
            let position = p.clamp(0.0, 1.0) * (n - 1) as f64;
            let below = position.floor() as usize;
            let above = (below + 1).min(n - 1);
            let fraction = position - below as f64;
            sorted[below] + fraction * (sorted[above] - sorted[below])
        }
    }
}

/// Weights scaled to sum to one, after checking they are finite, non-negative and not all zero.
pub fn normalised_weights(weights: &[f64]) -> Result<Vec<f64>> {
    if weights.is_empty() {
        return Err(CoreError::InvalidStatisticInput("no weights".into()));
    }
    if let Some(w) = weights.iter().find(|w| !w.is_finite() || **w < 0.0) {
        return Err(CoreError::InvalidStatisticInput(format!(
            "weights must be finite and non-negative, found {w}"
        )));
    }
    let total: f64 = weights.iter().sum();
    if total <= 0.0 {
        return Err(CoreError::InvalidStatisticInput(
            "weights sum to zero".into(),
        ));
    }
    Ok(weights.iter().map(|w| w / total).collect())
}

/// Kish's effective sample size n_eff = 1/Σ w̄_i² of normalised weights.
pub fn effective_sample_size(normalised: &[f64]) -> f64 {
    1.0 / normalised.iter().map(|w| w * w).sum::<f64>()
}

fn check_points(points: &[Vec<f64>], weights: &[f64]) -> Result<usize> {
    if points.is_empty() {
        return Err(CoreError::InvalidStatisticInput("no points".into()));
    }
    if points.len() != weights.len() {
        return Err(CoreError::InvalidStatisticInput(format!(
            "{} points but {} weights",
            points.len(),
            weights.len()
        )));
    }
    let d = points[0].len();
    if let Some(p) = points.iter().find(|p| p.len() != d) {
        return Err(CoreError::DimensionMismatch {
            expected: d,
            actual: p.len(),
        });
    }
    Ok(d)
}

/// Weighted mean μ = Σ_i w̄_i x_i of d-dimensional points.
pub fn weighted_mean(points: &[Vec<f64>], weights: &[f64]) -> Result<Vec<f64>> {
    let d = check_points(points, weights)?;
    let w = normalised_weights(weights)?;
    let mut mean = vec![0.0; d];
    for (p, wi) in points.iter().zip(&w) {
        for (m, x) in mean.iter_mut().zip(p) {
            *m += wi * x;
        }
    }
    Ok(mean)
}

/// Weighted covariance matrix (row-major d×d) with the given normalisation.
pub fn weighted_covariance(
    points: &[Vec<f64>],
    weights: &[f64],
    normalisation: CovarianceNormalisation,
) -> Result<Vec<Vec<f64>>> {
    let d = check_points(points, weights)?;
    let w = normalised_weights(weights)?;
    let mean = weighted_mean(points, &w)?;
    let mut cov = vec![vec![0.0; d]; d];
    for (p, wi) in points.iter().zip(&w) {
        for a in 0..d {
            let da = p[a] - mean[a];
            for b in 0..=a {
                cov[a][b] += wi * da * (p[b] - mean[b]);
            }
        }
    }
    let scale = match normalisation {
        CovarianceNormalisation::Biased => 1.0,
        CovarianceNormalisation::Unbiased => {
            let sum_sq: f64 = w.iter().map(|x| x * x).sum();
            if sum_sq >= 1.0 {
                return Err(CoreError::InvalidStatisticInput(
                    "an unbiased covariance needs at least two points with positive weight".into(),
                ));
            }
            1.0 / (1.0 - sum_sq)
        }
    };
    for a in 0..d {
        for b in 0..=a {
            cov[a][b] *= scale;
            cov[b][a] = cov[a][b];
        }
    }
    Ok(cov)
}

/// Weighted quantiles of scalar values at probabilities `probabilities` ∈ [0, 1].
///
/// The values are sorted and value k is placed at the cumulative probability
/// c_k = (Σ_{i≤k} w̄_i − w̄_k/2); quantiles interpolate linearly between these points and are
/// clamped to the extremes. With equal weights this is Hazen's definition
/// (`numpy.quantile(method="hazen")`).
pub fn weighted_quantiles(
    values: &[f64],
    weights: &[f64],
    probabilities: &[f64],
) -> Result<Vec<f64>> {
    if values.len() != weights.len() {
        return Err(CoreError::InvalidStatisticInput(format!(
            "{} values but {} weights",
            values.len(),
            weights.len()
        )));
    }
    if let Some(p) = probabilities.iter().find(|p| !(0.0..=1.0).contains(*p)) {
        return Err(CoreError::InvalidStatisticInput(format!(
            "quantile probability {p} is outside [0, 1]"
        )));
    }
    if values.iter().any(|v| v.is_nan()) {
        return Err(CoreError::InvalidStatisticInput(
            "values contain NaN".into(),
        ));
    }
    let w = normalised_weights(weights)?;
    let mut order: Vec<usize> = (0..values.len()).filter(|&i| w[i] > 0.0).collect();
    order.sort_by(|&a, &b| values[a].total_cmp(&values[b]));
    let mut positions = Vec::with_capacity(order.len());
    let mut cumulative = 0.0;
    for &i in &order {
        positions.push(cumulative + 0.5 * w[i]);
        cumulative += w[i];
    }
    Ok(probabilities
        .iter()
        .map(|&p| {
            let k = positions.partition_point(|&c| c < p);
            if k == 0 {
                values[order[0]]
            } else if k == order.len() {
                values[order[order.len() - 1]]
            } else {
                let (c0, c1) = (positions[k - 1], positions[k]);
                let (v0, v1) = (values[order[k - 1]], values[order[k]]);
                v0 + (p - c0) / (c1 - c0) * (v1 - v0)
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_interpolate_like_numpy() {
        let values = [1.0, 2.0, 3.0, 4.0];
        assert_eq!(quantile_sorted(&values, 0.0), 1.0);
        assert_eq!(quantile_sorted(&values, 1.0), 4.0);
        assert!((quantile_sorted(&values, 0.5) - 2.5).abs() < 1e-12);
        assert!((quantile_sorted(&values, 0.25) - 1.75).abs() < 1e-12);
    }

    #[test]
    fn mean_and_covariance_match_numpy() {
        // numpy: np.average(x, axis=0, weights=w); np.cov(x.T, aweights=w) and bias=True
        let x = vec![
            vec![1.0, 2.0],
            vec![2.0, 1.0],
            vec![4.0, 5.0],
            vec![0.0, -1.0],
        ];
        let w = [1.0, 2.0, 3.0, 4.0];
        let mean = weighted_mean(&x, &w).unwrap();
        assert!((mean[0] - 1.7).abs() < 1e-15 && (mean[1] - 1.5).abs() < 1e-15);
        let biased = weighted_covariance(&x, &w, CovarianceNormalisation::Biased).unwrap();
        let unbiased = weighted_covariance(&x, &w, CovarianceNormalisation::Unbiased).unwrap();
        let expected_biased = [[2.81, 4.05], [4.05, 6.25]];
        let expected_unbiased = [
            [4.014_285_714_285_713, 5.785_714_285_714_285],
            [5.785_714_285_714_285, 8.928_571_428_571_429],
        ];
        for a in 0..2 {
            for b in 0..2 {
                assert!((biased[a][b] - expected_biased[a][b]).abs() < 1e-12);
                assert!((unbiased[a][b] - expected_unbiased[a][b]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn equal_weight_quantiles_are_hazen() {
        // numpy.quantile([3, 1, 4, 1, 5, 9, 2, 6], [0, .1, .25, .5, .9, 1], method="hazen")
        let v = [3.0, 1.0, 4.0, 1.0, 5.0, 9.0, 2.0, 6.0];
        let q = weighted_quantiles(&v, &[1.0; 8], &[0.0, 0.1, 0.25, 0.5, 0.9, 1.0]).unwrap();
        let expected = [1.0, 1.0, 1.5, 3.5, 8.1, 9.0];
        for (a, b) in q.iter().zip(expected) {
            assert!((a - b).abs() < 1e-12, "{q:?}");
        }
    }

    #[test]
    fn zero_weight_values_are_ignored() {
        // 1 sits at c = 1/8, 3 at c = 1/4 + 3/8 = 5/8: the median interpolates to 2.5.
        let q = weighted_quantiles(&[1.0, 2.0, 3.0], &[1.0, 0.0, 3.0], &[0.5]).unwrap();
        assert!((q[0] - 2.5).abs() < 1e-12, "{q:?}");
    }

    #[test]
    fn bad_weights_are_rejected() {
        assert!(normalised_weights(&[1.0, -1.0]).is_err());
        assert!(normalised_weights(&[0.0, 0.0]).is_err());
        assert!(normalised_weights(&[f64::NAN]).is_err());
        assert!(weighted_mean(&[vec![1.0]], &[1.0, 2.0]).is_err());
        assert!(weighted_quantiles(&[1.0], &[1.0], &[1.5]).is_err());
        assert!(
            weighted_covariance(
                &[vec![1.0], vec![2.0]],
                &[1.0, 0.0],
                CovarianceNormalisation::Unbiased
            )
            .is_err()
        );
    }

    #[test]
    fn effective_sample_size_of_equal_weights_is_n() {
        let w = normalised_weights(&[2.0; 10]).unwrap();
        assert!((effective_sample_size(&w) - 10.0).abs() < 1e-12);
    }
}
