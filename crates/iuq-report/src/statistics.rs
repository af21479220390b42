//! Small descriptive statistics the figures and derived tables need (quantiles, means, ranges).

/// Mean of `values` (NaN for an empty slice).
pub(crate) fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

/// Quantile `p` ∈ [0, 1] of sorted values with linear interpolation between order statistics
/// (numpy's default, "type 7"); NaN for an empty slice.
pub(crate) fn quantile_sorted(sorted: &[f64], p: f64) -> f64 {
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

/// Smallest and largest value of an iterator of finite values, or `None` when it is empty.
pub(crate) fn extent(values: impl IntoIterator<Item = f64>) -> Option<(f64, f64)> {
    values.into_iter().fold(None, |acc, v| match acc {
        None => Some((v, v)),
        Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
    })
}

/// `(lo, hi)` widened by `fraction` of its width on each side; a zero-width range is widened
/// by `fraction` of its magnitude (or by `fraction` itself at zero), so an axis is never empty.
pub(crate) fn padded(lo: f64, hi: f64, fraction: f64) -> (f64, f64) {
    let width = hi - lo;
    let pad = if width > 0.0 {
        width * fraction
    } else if lo != 0.0 {
        lo.abs() * fraction
    } else {
        fraction
    };
    (lo - pad, hi + pad)
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
    fn padding_never_leaves_an_empty_range() {
        assert_eq!(padded(0.0, 0.0, 0.1), (-0.1, 0.1));
        let (lo, hi) = padded(2.0, 2.0, 0.1);
        assert!(lo < 2.0 && hi > 2.0);
    }
}
