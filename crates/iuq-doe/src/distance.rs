//! Space-filling criteria of a design: the minimum pairwise distance and Morris & Mitchell's φ_p.

use rayon::prelude::*;

/// Squared Euclidean distance of two points (over the coordinates both have).
pub(crate) fn squared_distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// Minimum pairwise Euclidean distance `min_{i<j} ‖x_i − x_j‖` of a design — the maximin
/// criterion (Johnson, Moore & Ylvisaker 1990): the larger, the better the design fills space.
///
/// Returns `f64::INFINITY` for fewer than two points. Rows are compared over the coordinates they
/// share (designs of this crate have rows of equal length); NaN distances are ignored. `O(n² d)`,
/// in parallel over rows; the result does not depend on the number of threads (a minimum is
/// exact whatever the order).
pub fn min_distance(points: &[Vec<f64>]) -> f64 {
    let min_sq = (0..points.len())
        .into_par_iter()
        .map(|i| {
            points[i + 1..]
                .iter()
                .map(|q| squared_distance(&points[i], q))
                .fold(f64::INFINITY, f64::min)
        })
        .reduce(|| f64::INFINITY, f64::min);
    min_sq.sqrt()
}

/// Morris & Mitchell's (1995) criterion `φ_p = (Σ_{i<j} d_ij^(−p))^(1/p)`, with `d_ij` the
/// Euclidean distance of points `i` and `j`: a smooth surrogate of the maximin criterion (as
/// `p → ∞`, `φ_p → 1 / min d_ij`); smaller is better. This is the criterion the optimised Latin
/// hypercube ([`crate::LhsMethod::Optimized`]) minimises.
///
/// Computed with distances scaled by their minimum, so it neither overflows nor underflows for
/// large `p`. Returns 0 for fewer than two points and `f64::INFINITY` if two points coincide.
/// `p` must be positive (`p ≤ 0` gives NaN).
pub fn phi_p(points: &[Vec<f64>], p: f64) -> f64 {
    if p.is_nan() || p <= 0.0 {
        return f64::NAN;
    }
    if points.len() < 2 {
        return 0.0;
    }
    let d_min = min_distance(points);
    if d_min == 0.0 {
        return f64::INFINITY;
    }
    // Σ (d_min / d_ij)^p: every term ≤ 1, the largest equal to 1.
    let sum: f64 = (0..points.len())
        .map(|i| {
            points[i + 1..]
                .iter()
                .map(|q| (d_min / squared_distance(&points[i], q).sqrt()).powf(p))
                .sum::<f64>()
        })
        .sum();
    sum.powf(1.0 / p) / d_min
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn min_distance_of_a_small_design() {
        let pts = vec![vec![0.0, 0.0], vec![3.0, 4.0], vec![1.0, 1.0]];
        assert_relative_eq!(min_distance(&pts), 2f64.sqrt(), max_relative = 1e-15);
        assert_eq!(min_distance(&pts[..1]), f64::INFINITY);
    }

    #[test]
    fn phi_p_matches_the_definition_and_tends_to_the_inverse_min_distance() {
        let pts = vec![vec![0.0, 0.0], vec![3.0, 4.0], vec![1.0, 1.0]];
        let d = [5.0f64, 2f64.sqrt(), 13f64.sqrt()];
        let direct = d.iter().map(|x| x.powf(-2.0)).sum::<f64>().powf(0.5);
        assert_relative_eq!(phi_p(&pts, 2.0), direct, max_relative = 1e-14);
        assert_relative_eq!(phi_p(&pts, 400.0), 1.0 / 2f64.sqrt(), max_relative = 1e-3);
        assert!(phi_p(&pts, 0.0).is_nan());
        assert_eq!(phi_p(&[vec![0.5], vec![0.5]], 2.0), f64::INFINITY);
    }
}
