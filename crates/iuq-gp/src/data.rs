//! Validation of user-supplied points and values, and the column-major layout the kernel loops
//! use (one contiguous slice per input, so that distance loops vectorise).

use crate::error::{GpError, Result};

/// Checks that `points` is non-empty, rectangular, of dimension ≥ 1 (equal to `expected` when
/// given) and finite; returns the dimension.
pub(crate) fn validate_points(
    points: &[Vec<f64>],
    what: &'static str,
    expected: Option<usize>,
) -> Result<usize> {
    let dimension = match (expected, points.first()) {
        (Some(d), _) => d,
        (None, Some(p)) => p.len(),
        (None, None) => 0,
    };
    if dimension == 0 {
        return Err(GpError::ZeroDimension);
    }
    for (index, p) in points.iter().enumerate() {
        if p.len() != dimension {
            return Err(GpError::DimensionMismatch {
                what,
                index,
                expected: dimension,
                actual: p.len(),
            });
        }
        if let Some(&value) = p.iter().find(|v| !v.is_finite()) {
            return Err(GpError::NonFinite { what, index, value });
        }
    }
    Ok(dimension)
}

/// Checks that every value is finite.
pub(crate) fn validate_values(values: &[f64], what: &'static str) -> Result<()> {
    match values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        Some((index, &value)) => Err(GpError::NonFinite { what, index, value }),
        None => Ok(()),
    }
}

/// Points stored input by input: `values[k·n + i]` is coordinate k of point i.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ColumnMajor {
    /// Number of points.
    pub n: usize,
    /// Number of inputs.
    pub d: usize,
    /// The coordinates, one contiguous column of length n per input.
    pub values: Vec<f64>,
}

impl ColumnMajor {
    /// Transposes `points` (all of length `d`) into columns, mapping each coordinate through
    /// `map(k, value)`.
    pub fn from_rows(points: &[Vec<f64>], d: usize, map: impl Fn(usize, f64) -> f64) -> Self {
        let n = points.len();
        let mut values = vec![0.0; n * d];
        for (i, p) in points.iter().enumerate() {
            for (k, &v) in p.iter().enumerate().take(d) {
                values[k * n + i] = map(k, v);
            }
        }
        Self { n, d, values }
    }

    /// Column k (coordinate k of every point).
    pub fn column(&self, k: usize) -> &[f64] {
        &self.values[k * self.n..(k + 1) * self.n]
    }

    /// The coordinates of point i.
    #[cfg(test)]
    pub fn point(&self, i: usize) -> Vec<f64> {
        (0..self.d).map(|k| self.values[k * self.n + i]).collect()
    }

    /// The points without point `skip` (for leave-one-out checks).
    #[cfg(test)]
    pub fn without(&self, skip: usize) -> Self {
        let n = self.n - 1;
        let mut values = Vec::with_capacity(n * self.d);
        for k in 0..self.d {
            let c = self.column(k);
            values.extend(
                c.iter()
                    .enumerate()
                    .filter(|(i, _)| *i != skip)
                    .map(|(_, v)| v),
            );
        }
        Self {
            n,
            d: self.d,
            values,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validation_catches_ragged_empty_and_non_finite() {
        assert_eq!(validate_points(&[], "p", None), Err(GpError::ZeroDimension));
        assert!(validate_points(&[vec![]], "p", None).is_err());
        assert!(matches!(
            validate_points(&[vec![1.0, 2.0], vec![1.0]], "p", None),
            Err(GpError::DimensionMismatch { index: 1, .. })
        ));
        assert!(matches!(
            validate_points(&[vec![1.0, f64::NAN]], "p", None),
            Err(GpError::NonFinite { .. })
        ));
        assert!(validate_points(&[vec![1.0]], "p", Some(2)).is_err());
        assert_eq!(validate_points(&[vec![1.0, 2.0]], "p", None), Ok(2));
        assert!(validate_values(&[1.0, f64::INFINITY], "y").is_err());
    }

    #[test]
    fn column_major_roundtrip() {
        let rows = vec![vec![1.0, 2.0], vec![3.0, 4.0], vec![5.0, 6.0]];
        let c = ColumnMajor::from_rows(&rows, 2, |_, v| v);
        assert_eq!(c.values, vec![1.0, 3.0, 5.0, 2.0, 4.0, 6.0]);
        assert_eq!(c.point(1), vec![3.0, 4.0]);
        assert_eq!(c.without(1).values, vec![1.0, 5.0, 2.0, 6.0]);
    }
}
