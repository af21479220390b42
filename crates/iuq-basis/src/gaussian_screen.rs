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
use crate::prediction_error::{ComputationalError, ErrorModel, LN_2PI, Observations};

/// The quadratic form of one affine screen against one data set (module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct GaussianScreen {
    /// c*, the weighted least-squares coefficients of the data.
    centre: Vec<f64>,
    /// L, M = L·Lᵀ, k × k row-major (lower triangle).
    factor: Vec<f64>,
    /// R + Σ_j ln(2π Σ_jj): −2 ln f at c*.
    floor: f64,
}

impl GaussianScreen {
    /// The form of `screen` against `observations` under `errors`; `None` where the variances
    /// depend on θ (an estimated modelling error, the relative computational error), where a
    /// variance is not positive and finite (the term-by-term likelihood then names the datum),
    /// or where M is singular.
    pub fn new(
        screen: &AffineScreen,
        observations: &Observations,
        errors: &ErrorModel,
    ) -> Option<Self> {
        if errors.modelling_error.is_some()
            || errors.computational_error == ComputationalError::Relative
        {
            return None;
        }
        let (m, k) = (screen.outputs(), screen.coefficients());
        let y = &observations.values;
        if y.len() != m || screen.stds.len() != m || screen.loadings.len() != m * k || k == 0 {
            return None;
        }
        let measurement = observations.measurement_std.as_deref();
        let mut weight = Vec::with_capacity(m);
        let mut floor = 0.0;
        for j in 0..m {
            let variance = errors
                .datum_variance(
                    j,
                    y[j],
                    measurement.map(|s| s[j]),
                    screen.offset[j],
                    screen.stds[j],
                    0.0,
                )
                .ok()?;
            weight.push(1.0 / variance);
            floor += LN_2PI + variance.ln();
        }
        let column = |l: usize| &screen.loadings[l * m..(l + 1) * m];
        let residual: Vec<f64> = (0..m).map(|j| y[j] - screen.offset[j]).collect();
        let mut gram = vec![0.0; k * k];
        let mut projection = vec![0.0; k];
        for a in 0..k {
            for b in 0..=a {
                let v: f64 = (0..m)
                    .map(|j| column(a)[j] * weight[j] * column(b)[j])
                    .sum();
                gram[a * k + b] = v;
                gram[b * k + a] = v;
            }
            projection[a] = (0..m).map(|j| column(a)[j] * weight[j] * residual[j]).sum();
        }
        let factor = cholesky(&gram, k)?;
        let centre = cholesky_solve(&factor, k, &projection);
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
                .map(|l| self.factor[l * k + i] * (c[l] - self.centre[l]))
                .sum();
            form += v * v;
        }
        Ok(-0.5 * (self.floor + form))
    }
}

/// The lower Cholesky factor of the symmetric k × k `matrix` (row-major), `None` unless it is
/// positive definite.
fn cholesky(matrix: &[f64], k: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0; k * k];
    for i in 0..k {
        for j in 0..=i {
            let s: f64 =
                matrix[i * k + j] - (0..j).map(|p| l[i * k + p] * l[j * k + p]).sum::<f64>();
            if i == j {
                if !(s > 0.0 && s.is_finite()) {
                    return None;
                }
                l[i * k + i] = s.sqrt();
            } else {
                l[i * k + j] = s / l[j * k + j];
            }
        }
    }
    Some(l)
}

/// x with L·Lᵀ·x = b.
fn cholesky_solve(l: &[f64], k: usize, b: &[f64]) -> Vec<f64> {
    let mut z = vec![0.0; k];
    for i in 0..k {
        z[i] = (b[i] - (0..i).map(|p| l[i * k + p] * z[p]).sum::<f64>()) / l[i * k + i];
    }
    let mut x = vec![0.0; k];
    for i in (0..k).rev() {
        x[i] = (z[i] - (i + 1..k).map(|p| l[p * k + i] * x[p]).sum::<f64>()) / l[i * k + i];
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three data, two coefficients, measurement stds and an absolute computational std.
    fn problem() -> (AffineScreen, Observations) {
        let screen = AffineScreen {
            offset: vec![1.0, 2.0, 0.5],
            loadings: vec![1.0, 0.5, -0.3, 0.2, 1.5, 0.7],
            stds: vec![0.05, 0.1, 0.02],
        };
        let observations = Observations {
            values: vec![1.3, 2.9, 0.4],
            measurement_std: Some(vec![0.1, 0.2, 0.15]),
        };
        (screen, observations)
    }

    fn errors(computational_error: ComputationalError) -> ErrorModel {
        ErrorModel {
            measurement_error: true,
            computational_error,
            modelling_error: None,
        }
    }

    /// The term-by-term sum of the prediction-error likelihood at the screen's outputs.
    fn term_by_term(
        screen: &AffineScreen,
        observations: &Observations,
        e: &ErrorModel,
        c: &[f64],
    ) -> f64 {
        let q = screen.outputs_of(c);
        let sd = observations.measurement_std.as_ref().unwrap();
        (0..q.len())
            .map(|j| {
                e.datum_log_likelihood(
                    j,
                    observations.values[j],
                    Some(sd[j]),
                    q[j],
                    screen.stds[j],
                    0.0,
                )
                .unwrap()
            })
            .sum()
    }

    /// The quadratic form equals the term-by-term likelihood to rounding (relative 1e-12) at
    /// points near and far from c*, for each θ-independent computational error.
    #[test]
    fn the_form_equals_the_term_by_term_likelihood() {
        let (screen, observations) = problem();
        for convention in [
            ComputationalError::Absolute,
            ComputationalError::AbsoluteTimesData,
            ComputationalError::None,
        ] {
            let e = errors(convention);
            let form = GaussianScreen::new(&screen, &observations, &e).unwrap();
            for c in [[0.0, 0.0], [0.3, -0.2], [5.0, 7.0], [-40.0, 12.0]] {
                let exact = term_by_term(&screen, &observations, &e, &c);
                let quick = form.log_likelihood(&c).unwrap();
                assert!(
                    (quick - exact).abs() <= 1e-12 * exact.abs().max(1.0),
                    "{convention:?} at {c:?}: {quick} vs {exact}"
                );
            }
        }
    }

    /// Variances that depend on θ leave the form out; bad coefficients are failures.
    #[test]
    fn theta_dependent_variances_have_no_form_and_bad_coefficients_fail() {
        let (screen, observations) = problem();
        assert!(
            GaussianScreen::new(
                &screen,
                &observations,
                &errors(ComputationalError::Relative)
            )
            .is_none()
        );
        let with_sigma_m = ErrorModel {
            modelling_error: Some(iuq_core::Prior::Uniform(0.001, 0.1)),
            ..errors(ComputationalError::Absolute)
        };
        assert!(GaussianScreen::new(&screen, &observations, &with_sigma_m).is_none());
        // No variance at all (no measurement std, no computational std): no form.
        let bare = Observations {
            values: observations.values.clone(),
            measurement_std: None,
        };
        assert!(GaussianScreen::new(&screen, &bare, &errors(ComputationalError::None)).is_none());
        let form = GaussianScreen::new(
            &screen,
            &observations,
            &errors(ComputationalError::Absolute),
        )
        .unwrap();
        assert!(form.log_likelihood(&[f64::NAN, 0.0]).is_err());
        assert!(form.log_likelihood(&[0.0]).is_err());
    }
}
