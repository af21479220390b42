//! Small descriptive statistics the figures and derived tables need (quantiles, means, ranges).

/// Mean of `values` (NaN for an empty slice).
pub(crate) fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

pub(crate) use iuq_core::weighted_statistics::quantile_sorted;

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
    fn padding_never_leaves_an_empty_range() {
        assert_eq!(padded(0.0, 0.0, 0.1), (-0.1, 0.1));
        let (lo, hi) = padded(2.0, 2.0, 0.1);
        assert!(lo < 2.0 && hi > 2.0);
    }
}
