//! The prediction-error likelihood of an affine screen as a quadratic form in its coefficients.
//!
//! Where a model's screen is affine, q(θ) = μ + A·c(θ) with θ-independent stds
//! ([`iuq_core::affine_screen`]), and the likelihood's variances Σ_jj do not depend on θ either
//! (no estimated modelling error, a computational error that does not scale with q), the screen's
//!
//! −2 ln f = Σ_j [(ŷ_j − q_j)²/Σ_jj + ln(2π Σ_jj)]
//!
//! is, with e = ŷ − μ and W = Σ⁻¹, the quadratic form
//!
//! (e − Ac)ᵀW(e − Ac) = R + (c − c*)ᵀ M (c − c*),  M = AᵀWA,  c* = M⁻¹AᵀWe,  R = (e − Ac*)ᵀW(e − Ac*),
//!
//! (the weighted least-squares projection of the data on the screen's span and its residual),
//! computed once, after which a point costs O(k²) for k coefficients rather than O(m·k) to
//! rebuild the m outputs and O(m) for the terms. The form is centred at c*, so the residual
//! carries no cancellation. The values equal the term-by-term sum to rounding; the screen of
//! delayed-acceptance moves only decides which proposals the full likelihood sees, and the
//! second stage's ratio keeps the chains' target exact whatever the screen is.

use iuq_core::EvaluationFailure;
use iuq_core::affine_screen::AffineScreen;

use crate::likelihood::PointLogLikelihood;
use crate::proposal::cholesky_lower;

/// ln(2π).
const LN_2PI: f64 = 1.837_877_066_409_345_5;

/// The quadratic form of one affine screen against one data set (module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct GaussianScreen {
    /// c*, the weighted least-squares coefficients of the data.
    centre: Vec<f64>,
    /// L, M = L·Lᵀ (lower triangle).
    factor: Vec<Vec<f64>>,
    /// R + Σ_j ln(2π Σ_jj): −2 ln f at c*.
    floor: f64,
}

impl GaussianScreen {
    /// The form of `screen` against the data `values` with the θ-independent variances
    /// Σ_jj `variances` (the prediction-error likelihood decides when they are:
    /// `iuq_basis::prediction_error`); `None` where the sizes disagree, a variance is not
    /// positive and finite, or M is singular.
    pub fn new(screen: &AffineScreen, values: &[f64], variances: &[f64]) -> Option<Self> {
        let (m, k) = (screen.outputs(), screen.coefficients());
        let y = values;
        if y.len() != m
            || variances.len() != m
            || screen.loadings.len() != m * k
            || k == 0
            || !variances.iter().all(|v| *v > 0.0 && v.is_finite())
        {
            return None;
        }
        let weight: Vec<f64> = variances.iter().map(|v| 1.0 / v).collect();
        let floor: f64 = variances.iter().map(|v| LN_2PI + v.ln()).sum();
        let column = |l: usize| &screen.loadings[l * m..(l + 1) * m];
        let residual: Vec<f64> = (0..m).map(|j| y[j] - screen.offset[j]).collect();
        let mut gram = vec![vec![0.0; k]; k];
        let mut projection = vec![0.0; k];
        for a in 0..k {
            for b in 0..=a {
                let v: f64 = (0..m)
                    .map(|j| column(a)[j] * weight[j] * column(b)[j])
                    .sum();
                gram[a][b] = v;
                gram[b][a] = v;
            }
            projection[a] = (0..m).map(|j| column(a)[j] * weight[j] * residual[j]).sum();
        }
        let factor = cholesky_lower(&gram)?;
        // Positive beyond rounding: a pivot² below 10⁻¹² of its diagonal is a singular M.
        if (0..k).any(|i| factor[i][i] * factor[i][i] <= 1e-12 * gram[i][i]) {
            return None;
        }
        let centre = cholesky_solve(&factor, &projection);
        let fitted_residual: f64 = (0..m)
            .map(|j| {
                let fitted: f64 = (0..k).map(|l| column(l)[j] * centre[l]).sum();
                let r = residual[j] - fitted;
                r * r * weight[j]
            })
            .sum();
        Some(Self {
            centre,
            factor,
            floor: floor + fitted_residual,
        })
    }

    /// ln f at the screen's coefficients `c`: −½ (R + ‖Lᵀ(c − c*)‖² + Σ_j ln(2π Σ_jj)); a
    /// non-finite coefficient is a failure, as a non-finite output is.
    pub fn log_likelihood(&self, c: &[f64]) -> PointLogLikelihood {
        let k = self.centre.len();
        if c.len() != k {
            return Err(EvaluationFailure::new(format!(
                "model returned {} screening coefficients, expected {k}",
                c.len()
            )));
        }
        if !c.iter().all(|v| v.is_finite()) {
            return Err(EvaluationFailure::new("model returned a non-finite output"));
        }
        let mut form = 0.0;
        for i in 0..k {
            // (Lᵀδ)_i = Σ_{l ≥ i} L_li δ_l
            let v: f64 = (i..k)
                .map(|l| self.factor[l][i] * (c[l] - self.centre[l]))
                .sum();
            form += v * v;
        }
        Ok(-0.5 * (self.floor + form))
    }
}

/// x with L·Lᵀ·x = b.
fn cholesky_solve(l: &[Vec<f64>], b: &[f64]) -> Vec<f64> {
    let k = b.len();
    let mut z = vec![0.0; k];
    for i in 0..k {
        z[i] = (b[i] - (0..i).map(|p| l[i][p] * z[p]).sum::<f64>()) / l[i][i];
    }
    let mut x = vec![0.0; k];
    for i in (0..k).rev() {
        x[i] = (z[i] - (i + 1..k).map(|p| l[p][i] * x[p]).sum::<f64>()) / l[i][i];
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three data, two coefficients.
    fn problem() -> (AffineScreen, Vec<f64>, Vec<f64>) {
        let screen = AffineScreen {
            offset: vec![1.0, 2.0, 0.5],
            loadings: vec![1.0, 0.5, -0.3, 0.2, 1.5, 0.7],
            stds: vec![0.05, 0.1, 0.02],
        };
        (screen, vec![1.3, 2.9, 0.4], vec![0.0125, 0.05, 0.0229])
    }

    /// −½ Σ_j [(y_j − q_j)²/v_j + ln(2π v_j)] at the screen's outputs, term by term.
    fn term_by_term(screen: &AffineScreen, y: &[f64], v: &[f64], c: &[f64]) -> f64 {
        let q = screen.outputs_of(c);
        -0.5 * (0..q.len())
            .map(|j| (y[j] - q[j]).powi(2) / v[j] + LN_2PI + v[j].ln())
            .sum::<f64>()
    }

    /// The quadratic form equals the term-by-term likelihood to rounding (relative 1e-12) at
    /// points near and far from c*.
    #[test]
    fn the_form_equals_the_term_by_term_likelihood() {
        let (screen, y, v) = problem();
        let form = GaussianScreen::new(&screen, &y, &v).unwrap();
        for c in [[0.0, 0.0], [0.3, -0.2], [5.0, 7.0], [-40.0, 12.0]] {
            let exact = term_by_term(&screen, &y, &v, &c);
            let quick = form.log_likelihood(&c).unwrap();
            assert!(
                (quick - exact).abs() <= 1e-12 * exact.abs().max(1.0),
                "at {c:?}: {quick} vs {exact}"
            );
        }
    }

    /// A variance that is not positive, sizes that disagree or collinear loadings give no form;
    /// bad coefficients are failures.
    #[test]
    fn bad_inputs_give_no_form_and_bad_coefficients_fail() {
        let (screen, y, v) = problem();
        assert!(GaussianScreen::new(&screen, &y, &[0.0125, 0.0, 0.0229]).is_none());
        assert!(GaussianScreen::new(&screen, &y[..2], &v).is_none());
        let collinear = AffineScreen {
            loadings: vec![1.0, 0.5, -0.3, 2.0, 1.0, -0.6],
            ..screen.clone()
        };
        assert!(GaussianScreen::new(&collinear, &y, &v).is_none());
        let form = GaussianScreen::new(&screen, &y, &v).unwrap();
        assert!(form.log_likelihood(&[f64::NAN, 0.0]).is_err());
        assert!(form.log_likelihood(&[0.0]).is_err());
    }
}
