//! Input scaling to the unit cube and output standardisation.
//!
//! The GP works on x̃_k = (x_k − a_k)/r_k and ỹ = (y − ȳ)/s_y. By default a_k, r_k are the
//! training minimum and range of input k (so training inputs fill [0, 1]^d and the default
//! length-scale bounds mean the same thing for every input), and ȳ, s_y are the training mean
//! and standard deviation (ddof 0, as scikit-learn's `normalize_y`). Either can be switched
//! off, giving the identity map (a = 0, r = 1; ȳ = 0, s = 1), which is exact in floating point.

use serde::{Deserialize, Serialize};

/// x̃_k = (x_k − lower_k)/range_k for every input k.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InputScaling {
    /// Offsets a_k (training minimum, or 0).
    pub lower: Vec<f64>,
    /// Ranges r_k > 0 (training max − min, or 1; 1 for a constant input).
    pub range: Vec<f64>,
}

impl InputScaling {
    /// The identity map in `dimension` inputs.
    pub fn identity(dimension: usize) -> Self {
        Self {
            lower: vec![0.0; dimension],
            range: vec![1.0; dimension],
        }
    }

    /// The map of the training points' bounding box onto the unit cube (points validated:
    /// rectangular, finite, non-empty). A constant input gets range 1.
    pub(crate) fn unit_cube(points: &[Vec<f64>], dimension: usize) -> Self {
        let mut lower = vec![f64::INFINITY; dimension];
        let mut upper = vec![f64::NEG_INFINITY; dimension];
        for p in points {
            for k in 0..dimension {
                lower[k] = lower[k].min(p[k]);
                upper[k] = upper[k].max(p[k]);
            }
        }
        let range = lower
            .iter()
            .zip(&upper)
            .map(|(lo, hi)| {
                let r = hi - lo;
                if r > 0.0 && r.is_finite() { r } else { 1.0 }
            })
            .collect();
        Self { lower, range }
    }

    /// Number of inputs.
    pub fn dimension(&self) -> usize {
        self.lower.len()
    }

    /// Inputs whose training values are all equal (points validated and non-empty).
    pub(crate) fn constant_inputs(points: &[Vec<f64>], dimension: usize) -> Vec<usize> {
        (0..dimension)
            .filter(|&k| points.iter().all(|p| p[k] == points[0][k]))
            .collect()
    }

    /// x̃_k = (x_k − a_k)/r_k (k < dimension).
    #[inline]
    pub(crate) fn apply(&self, k: usize, x: f64) -> f64 {
        (x - self.lower[k]) / self.range[k]
    }
}

/// ỹ = (y − mean)/std.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OutputScaling {
    /// The offset ȳ (training mean, or 0).
    pub mean: f64,
    /// The scale s_y > 0 (training std with ddof 0, or 1; 1 for a constant output).
    pub std: f64,
}

impl OutputScaling {
    /// The identity map.
    pub fn identity() -> Self {
        Self {
            mean: 0.0,
            std: 1.0,
        }
    }

    /// Standardisation by the mean and std (ddof 0) of `y` (non-empty, finite); a constant
    /// output gets std 1, as in scikit-learn.
    pub fn standardize(y: &[f64]) -> Self {
        let n = y.len().max(1) as f64;
        let mean = y.iter().sum::<f64>() / n;
        let var = y.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n;
        let std = var.sqrt();
        Self {
            mean,
            std: if std > 0.0 && std.is_finite() {
                std
            } else {
                1.0
            },
        }
    }

    /// ỹ = (y − ȳ)/s_y.
    #[inline]
    pub fn apply(&self, y: f64) -> f64 {
        (y - self.mean) / self.std
    }

    /// y = ȳ + s_y·ỹ.
    #[inline]
    pub fn invert(&self, y: f64) -> f64 {
        self.mean + self.std * y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_cube_and_standardisation() {
        let pts = vec![vec![1.0, 5.0], vec![3.0, 5.0], vec![2.0, 5.0]];
        let s = InputScaling::unit_cube(&pts, 2);
        assert_eq!(s.lower, vec![1.0, 5.0]);
        assert_eq!(s.range, vec![2.0, 1.0]);
        assert_eq!(s.apply(0, 3.0), 1.0);
        assert_eq!(InputScaling::constant_inputs(&pts, 2), vec![1]);
        let o = OutputScaling::standardize(&[1.0, 3.0]);
        assert_eq!((o.mean, o.std), (2.0, 1.0));
        assert_eq!(o.invert(o.apply(7.5)), 7.5);
        assert_eq!(OutputScaling::standardize(&[4.0, 4.0]).std, 1.0);
        assert_eq!(InputScaling::identity(2).apply(1, 0.3), 0.3);
    }
}
