//! Affine maps between the unit cube, where designs are built, and a box of parameter bounds.
//!
//! Coordinate `k` maps as `x_k = l_k + u_k·(h_k − l_k)` and back as `u_k = (x_k − l_k)/(h_k − l_k)`
//! for bounds `(l_k, h_k)`. Uniform priors on a box are the usual case: a design that fills the
//! unit cube then fills the box.

use crate::error::{DoeError, Result};

/// Checks that `bounds` is non-empty, finite, ordered (`lower < upper`) with a finite width.
fn check_bounds(bounds: &[(f64, f64)]) -> Result<()> {
    if bounds.is_empty() {
        return Err(DoeError::InvalidDimension {
            dim: 0,
            reason: "at least one pair of bounds is needed".into(),
        });
    }
    for (index, &(lower, upper)) in bounds.iter().enumerate() {
        if !(lower.is_finite() && upper.is_finite() && lower < upper && (upper - lower).is_finite())
        {
            return Err(DoeError::InvalidBounds {
                index,
                lower,
                upper,
            });
        }
    }
    Ok(())
}

/// Applies `f(value, lower, upper)` to every coordinate, validating shapes and finiteness.
fn map_points(
    points: &[Vec<f64>],
    bounds: &[(f64, f64)],
    f: impl Fn(f64, f64, f64) -> f64,
) -> Result<Vec<Vec<f64>>> {
    check_bounds(bounds)?;
    points
        .iter()
        .enumerate()
        .map(|(row, point)| {
            if point.len() != bounds.len() {
                return Err(DoeError::DimensionMismatch {
                    row,
                    expected: bounds.len(),
                    actual: point.len(),
                });
            }
            point
                .iter()
                .zip(bounds)
                .enumerate()
                .map(|(column, (&value, &(lower, upper)))| {
                    if value.is_finite() {
                        Ok(f(value, lower, upper))
                    } else {
                        Err(DoeError::NonFinite { row, column, value })
                    }
                })
                .collect()
        })
        .collect()
}

/// Maps points of the unit cube to the box `bounds` (one `(lower, upper)` pair per coordinate):
/// `x_k = l_k + u_k·(h_k − l_k)`.
///
/// Errors for invalid bounds (non-finite, `lower >= upper`, or an infinite width), rows whose
/// length differs from `bounds.len()`, or non-finite coordinates. Coordinates outside `[0, 1]`
/// are mapped by the same affine formula (outside the box).
pub fn scale_to_bounds(points: &[Vec<f64>], bounds: &[(f64, f64)]) -> Result<Vec<Vec<f64>>> {
    map_points(points, bounds, |u, lower, upper| {
        lower + u * (upper - lower)
    })
}

/// Maps points of the box `bounds` back to the unit cube, `u_k = (x_k − l_k)/(h_k − l_k)`: the
/// inverse of [`scale_to_bounds`], with the same validation.
pub fn scale_to_unit_cube(points: &[Vec<f64>], bounds: &[(f64, f64)]) -> Result<Vec<Vec<f64>>> {
    map_points(points, bounds, |x, lower, upper| {
        (x - lower) / (upper - lower)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn round_trip_and_corners() {
        let bounds = [(10.0, 300.0), (-1.0, 1.0)];
        let unit = vec![vec![0.0, 1.0], vec![0.5, 0.25]];
        let x = scale_to_bounds(&unit, &bounds).expect("valid");
        assert_eq!(x, vec![vec![10.0, 1.0], vec![155.0, -0.5]]);
        let back = scale_to_unit_cube(&x, &bounds).expect("valid");
        for (r, s) in back.iter().zip(&unit) {
            for (a, b) in r.iter().zip(s) {
                assert_relative_eq!(a, b, epsilon = 1e-15);
            }
        }
    }

    #[test]
    fn invalid_input_is_an_error() {
        let p = vec![vec![0.5]];
        assert!(matches!(
            scale_to_bounds(&p, &[(1.0, 1.0)]),
            Err(DoeError::InvalidBounds { index: 0, .. })
        ));
        assert!(scale_to_bounds(&p, &[(2.0, 1.0)]).is_err());
        assert!(scale_to_bounds(&p, &[(f64::NAN, 1.0)]).is_err());
        assert!(scale_to_bounds(&p, &[(-f64::MAX, f64::MAX)]).is_err());
        assert!(scale_to_bounds(&p, &[]).is_err());
        assert!(matches!(
            scale_to_bounds(&p, &[(0.0, 1.0), (0.0, 1.0)]),
            Err(DoeError::DimensionMismatch { row: 0, .. })
        ));
        assert!(matches!(
            scale_to_unit_cube(&[vec![f64::INFINITY]], &[(0.0, 1.0)]),
            Err(DoeError::NonFinite {
                row: 0,
                column: 0,
                ..
            })
        ));
        assert_eq!(
            scale_to_bounds(&[], &[(0.0, 1.0)]).expect("empty ok"),
            Vec::<Vec<f64>>::new()
        );
    }
}
