//! A quadratic least-squares fit of a function of the parameters, f̂(θ) = c + bᵀu + Σ_{k≤l}
//! a_kl·u_k·u_l on standardised coordinates u = (θ − m)/s: the cheap stand-in for the
//! model–surrogate log-likelihood difference r(θ) with which [`crate::model_posterior`](mod@crate::model_posterior)'s
//! delayed-acceptance moves screen proposals (a Gaussian-shaped correction: a surrogate
//! posterior shifted or too narrow differs from the model's by exactly such an r).
//!
//! The normal equations are solved by Cholesky with a ridge of 1e-8·(mean diagonal); with fewer
//! than twice as many distinct points as quadratic terms the fit is linear, and with fewer than
//! twice as many as linear terms there is no fit. A prediction is made at θ clamped to the box
//! of the fitted points widened by its own width on every side: a quadratic extrapolated
//! without bound (an upward curvature where the surrogate's log-likelihood flattens) would make
//! the corrected surrogate improper or pile its mass at the prior's corners, while within three
//! times the points' extent it still reaches a posterior twice as wide as theirs. Any bounded
//! stand-in keeps the importance weights and the delayed acceptance exact.

use crate::proposal::cholesky_lower;

/// A fitted quadratic (or linear) function of θ.
#[derive(Debug, Clone, PartialEq)]
pub struct QuadraticFit {
    centre: Vec<f64>,
    scale: Vec<f64>,
    quadratic: bool,
    coefficients: Vec<f64>,
    bounds: Vec<(f64, f64)>,
}

impl QuadraticFit {
    /// The least-squares fit of `values` at `points` (non-finite values are left out), or `None`
    /// when too few points remain or the system is singular.
    pub fn fit(points: &[Vec<f64>], values: &[f64]) -> Option<Self> {
        let kept: Vec<usize> = (0..points.len().min(values.len()))
            .filter(|&i| values[i].is_finite())
            .collect();
        let d = points.first()?.len();
        let n = kept.len() as f64;
        if kept.is_empty() {
            return None;
        }
        let bounds: Vec<(f64, f64)> = (0..d)
            .map(|k| {
                let (lo, hi) = kept
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &i| {
                        (a.min(points[i][k]), b.max(points[i][k]))
                    });
                (lo - (hi - lo), hi + (hi - lo))
            })
            .collect();
        let mut distinct: Vec<&Vec<f64>> = kept.iter().map(|&i| &points[i]).collect();
        distinct.sort_by(|a, b| {
            a.iter()
                .zip(b.iter())
                .map(|(x, y)| x.total_cmp(y))
                .find(|o| o.is_ne())
                .unwrap_or(std::cmp::Ordering::Equal)
        });
        distinct.dedup();
        let distinct = distinct.len();
        let centre: Vec<f64> = (0..d)
            .map(|k| kept.iter().map(|&i| points[i][k]).sum::<f64>() / n)
            .collect();
        let scale: Vec<f64> = (0..d)
            .map(|k| {
                let v = kept
                    .iter()
                    .map(|&i| (points[i][k] - centre[k]).powi(2))
                    .sum::<f64>()
                    / n;
                if v > 0.0 { v.sqrt() } else { 1.0 }
            })
            .collect();
        for quadratic in [true, false] {
            let mut fit = Self {
                centre: centre.clone(),
                scale: scale.clone(),
                quadratic,
                coefficients: Vec::new(),
                bounds: bounds.clone(),
            };
            let terms = fit.features(&points[kept[0]]).len();
            if distinct < 2 * terms {
                continue;
            }
            let mut normal = vec![vec![0.0; terms]; terms];
            let mut rhs = vec![0.0; terms];
            for &i in &kept {
                let f = fit.features(&points[i]);
                for a in 0..terms {
                    rhs[a] += f[a] * values[i];
                    for b in 0..=a {
                        normal[a][b] += f[a] * f[b];
                    }
                }
            }
            let ridge = 1e-8 * (0..terms).map(|a| normal[a][a]).sum::<f64>() / terms as f64;
            for a in 0..terms {
                normal[a][a] += ridge;
                for b in 0..a {
                    normal[b][a] = normal[a][b];
                }
            }
            let Some(l) = cholesky_lower(&normal) else {
                continue;
            };
            let mut y = vec![0.0; terms];
            for a in 0..terms {
                y[a] = (rhs[a] - (0..a).map(|b| l[a][b] * y[b]).sum::<f64>()) / l[a][a];
            }
            let mut c = vec![0.0; terms];
            for a in (0..terms).rev() {
                c[a] = (y[a] - (a + 1..terms).map(|b| l[b][a] * c[b]).sum::<f64>()) / l[a][a];
            }
            fit.coefficients = c;
            return Some(fit);
        }
        None
    }

    /// 1, u_k, then (quadratic fits) u_k·u_l for k ≤ l.
    fn features(&self, theta: &[f64]) -> Vec<f64> {
        let u: Vec<f64> = theta
            .iter()
            .zip(&self.centre)
            .zip(&self.scale)
            .map(|((t, c), s)| (t - c) / s)
            .collect();
        let mut f = Vec::with_capacity(1 + u.len() * (u.len() + 3) / 2);
        f.push(1.0);
        f.extend(&u);
        if self.quadratic {
            for k in 0..u.len() {
                for l in k..u.len() {
                    f.push(u[k] * u[l]);
                }
            }
        }
        f
    }

    /// f̂ at θ clamped to the widened box of the fitted points.
    pub fn predict(&self, theta: &[f64]) -> f64 {
        let clamped: Vec<f64> = theta
            .iter()
            .zip(&self.bounds)
            .map(|(t, (lo, hi))| t.clamp(*lo, *hi))
            .collect();
        self.features(&clamped)
            .iter()
            .zip(&self.coefficients)
            .map(|(f, c)| f * c)
            .sum()
    }

    /// Whether the fit has the quadratic terms.
    pub fn is_quadratic(&self) -> bool {
        self.quadratic
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_quadratic_and_falls_back_to_linear() {
        let f = |x: &[f64]| 1.0 + 2.0 * x[0] - x[1] + 0.5 * x[0] * x[0] - 3.0 * x[0] * x[1];
        let points: Vec<Vec<f64>> = (0..40)
            .map(|i| vec![(i as f64 * 0.37).sin() * 2.0, (i as f64 * 0.61).cos() + 1.0])
            .collect();
        let values: Vec<f64> = points.iter().map(|p| f(p)).collect();
        let fit = QuadraticFit::fit(&points, &values).unwrap();
        assert!(fit.is_quadratic());
        for p in [[0.3, -0.2], [1.5, 2.0]] {
            assert!((fit.predict(&p) - f(&p)).abs() < 1e-6);
        }
        // Far from its points the fit is held at the edge of the widened box.
        let far = fit.predict(&[100.0, -50.0]);
        let edge = [fit.bounds[0].1, fit.bounds[1].0];
        assert!(edge[0] < 100.0 && edge[1] > -50.0);
        assert!((far - f(&edge)).abs() < 1e-6, "{far}");
        // Repeated points count once: 40 copies of 8 points are 8 points.
        let repeated: Vec<Vec<f64>> = (0..40).map(|i| points[i % 8].clone()).collect();
        let repeated_values: Vec<f64> = repeated.iter().map(|p| f(p)).collect();
        assert!(
            !QuadraticFit::fit(&repeated, &repeated_values)
                .unwrap()
                .is_quadratic()
        );
        // 8 points: too few for 6 quadratic terms (12 needed), enough for 3 linear ones.
        let fit = QuadraticFit::fit(&points[..8], &values[..8]).unwrap();
        assert!(!fit.is_quadratic());
        assert!(QuadraticFit::fit(&points[..5], &values[..5]).is_none());
        // Non-finite values are left out.
        let mut holed = values.clone();
        holed[3] = f64::NEG_INFINITY;
        let fit = QuadraticFit::fit(&points, &holed).unwrap();
        assert!((fit.predict(&points[3]) - values[3]).abs() < 1e-6);
    }
}
