//! A model's screen whose outputs are affine in a few coefficients, with stds that do not depend
//! on θ: q(θ) = μ + A·c(θ), s(θ) = s. An emulator on a reduced basis (principal components of
//! the runs) screens this way: its screen is the components' GP means mapped through the
//! loadings. A Gaussian likelihood of such a screen is a quadratic form in c, O(k²) per point
//! for k coefficients instead of O(m·k) to rebuild m outputs and O(m) for the likelihood's terms
//! (`iuq_basis::gaussian_screen`); on a 200-point curve with 10 components, most of a delayed-
//! acceptance step's cost.

use crate::error::Result;
use crate::evaluation_failure::EvaluationFailure;

/// The affine map of a screen: q = `offset` + `loadings`·c, with `stds` the same at every θ.
#[derive(Debug, Clone, PartialEq)]
pub struct AffineScreen {
    /// μ, one value per output.
    pub offset: Vec<f64>,
    /// A, outputs × coefficients, column-major (coefficient k's column is
    /// `loadings[k·m..(k + 1)·m]`).
    pub loadings: Vec<f64>,
    /// The screen's computational std of each output.
    pub stds: Vec<f64>,
}

impl AffineScreen {
    /// Number of outputs m.
    pub fn outputs(&self) -> usize {
        self.offset.len()
    }

    /// Number of coefficients k.
    pub fn coefficients(&self) -> usize {
        self.loadings
            .len()
            .checked_div(self.offset.len())
            .unwrap_or(0)
    }

    /// The outputs μ + A·c of coefficients `c`, in the order of the outputs.
    pub fn outputs_of(&self, c: &[f64]) -> Vec<f64> {
        let m = self.outputs();
        let mut q = self.offset.clone();
        for (k, &ck) in c.iter().enumerate() {
            for (qj, a) in q.iter_mut().zip(&self.loadings[k * m..(k + 1) * m]) {
                *qj += a * ck;
            }
        }
        q
    }
}

/// The coefficients c(θ) at one point, or why the screen gives none there.
pub type CoefficientOutcome = std::result::Result<Vec<f64>, EvaluationFailure>;

/// A model whose screen ([`crate::Model::screening_batch`]) is an [`AffineScreen`]: the screen's
/// outcome at θ is exactly μ + A·c(θ) with stds s (to rounding), and it fails exactly where
/// `screening_coefficients` does.
pub trait AffineScreening {
    /// The screen's affine map (the same for every θ).
    fn affine_screen(&self) -> AffineScreen;

    /// c(θ) at every point of `points`, one outcome per point in order; the outer `Err` is a
    /// failure of the whole batch.
    fn screening_coefficients(&self, points: &[Vec<f64>]) -> Result<Vec<CoefficientOutcome>>;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outputs_are_the_offset_plus_the_loadings_times_the_coefficients() {
        // Two outputs, two coefficients: A = [[1, 3], [2, 4]] column-major.
        let screen = AffineScreen {
            offset: vec![10.0, 20.0],
            loadings: vec![1.0, 2.0, 3.0, 4.0],
            stds: vec![0.1, 0.1],
        };
        assert_eq!(screen.outputs(), 2);
        assert_eq!(screen.coefficients(), 2);
        assert_eq!(screen.outputs_of(&[1.0, -1.0]), vec![8.0, 18.0]);
    }
}
