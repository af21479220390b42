//! The gradient of a GP's posterior mean with respect to its inputs: what a gradient-based
//! optimiser or sampler asks of a surrogate (UM-Bridge's `/Gradient` and `/ApplyJacobian`).
//!
//! For the squared-exponential kernel, with x̃_k = (x_k − a_k)/r_k the input scaling, s_y the
//! output scale and α = K⁻¹ỹ,
//!
//! μ(x) = ȳ + s_y · Σᵢ αᵢ · c·exp(−½ Σ_j (x̃_j − x̃ᵢⱼ)²/l_j²),
//!
//! ∂μ/∂x_k = (s_y / r_k) · Σᵢ αᵢ · c·exp(−½ Σ_j (x̃_j − x̃ᵢⱼ)²/l_j²) · (−(x̃_k − x̃ᵢₖ)/l_k²).
//!
//! O(n·d) per point, with the GP's own α: the mean equals [`GaussianProcess::predict_mean`]'s
//! to round-off.

use crate::data::validate_points;
use crate::error::Result;
use crate::gaussian_process::GaussianProcess;

impl GaussianProcess {
    /// The posterior mean at `point` (original units) and its gradient ∂μ/∂x_k (see the
    /// module).
    pub fn mean_and_gradient(&self, point: &[f64]) -> Result<(f64, Vec<f64>)> {
        let d = self.dimension();
        validate_points(
            std::slice::from_ref(&point.to_vec()),
            "gradient point",
            Some(d),
        )?;
        let h = &self.hyperparameters;
        let inverse_squared: Vec<f64> = (0..d)
            .map(|k| {
                let l = if h.length_scales.len() == 1 {
                    h.length_scales[0]
                } else {
                    h.length_scales[k]
                };
                1.0 / (l * l)
            })
            .collect();
        let scaled: Vec<f64> = (0..d)
            .map(|k| self.input_scaling.apply(k, point[k]))
            .collect();
        let n = self.x.n;
        let column = |k: usize| &self.x.values[k * n..(k + 1) * n];
        let mut value = 0.0;
        let mut gradient = vec![0.0; d];
        let mut difference = vec![0.0; d];
        for (i, &a) in self.alpha.iter().enumerate() {
            let mut r2 = 0.0;
            for k in 0..d {
                let t = scaled[k] - column(k)[i];
                difference[k] = t;
                r2 += t * t * inverse_squared[k];
            }
            let w = a * h.signal_variance * (-0.5 * r2).exp();
            value += w;
            for k in 0..d {
                gradient[k] -= w * difference[k] * inverse_squared[k];
            }
        }
        let scale = self.output_scaling.std;
        for (k, g) in gradient.iter_mut().enumerate() {
            *g *= scale / self.input_scaling.range[k];
        }
        Ok((self.output_scaling.mean + scale * value, gradient))
    }
}

#[cfg(test)]
mod tests {
    use crate::fit::{FitOptions, fit};

    #[test]
    fn the_gradient_matches_central_differences_and_the_mean_the_prediction() {
        // A smooth function of two inputs on different scales.
        let points: Vec<Vec<f64>> = (0..30)
            .map(|i| {
                let u = (i as f64 * 0.618_033_988_75).fract();
                let v = (i as f64 * 0.754_877_666_25).fract();
                vec![10.0 * u, 100.0 + 50.0 * v]
            })
            .collect();
        let values: Vec<f64> = points
            .iter()
            .map(|p| (0.3 * p[0]).sin() + 0.02 * p[1])
            .collect();
        let gp = fit(&points, &values, &FitOptions::default().check().unwrap()).unwrap();
        for probe in [vec![3.3, 120.0], vec![7.1, 141.5], vec![0.4, 104.0]] {
            let (mean, gradient) = gp.mean_and_gradient(&probe).unwrap();
            let predicted = gp.predict_mean(std::slice::from_ref(&probe)).unwrap()[0];
            // Both sum n terms αᵢ·kᵢ in different orders: round-off up to about
            // n·ε·s_y·c·Σ|αᵢ| (α is large and of both signs for a near-interpolating GP).
            let terms: f64 = gp.alpha.iter().map(|a| a.abs()).sum::<f64>()
                * gp.hyperparameters.signal_variance
                * gp.output_scaling.std;
            let bound = 4.0 * gp.alpha.len() as f64 * f64::EPSILON * terms;
            assert!(
                (mean - predicted).abs() <= bound,
                "{mean} vs {predicted} (bound {bound})"
            );
            for k in 0..2 {
                // A step of 1e-3 of the input's range: truncation error h²·|μ'''|/6 < 1e-6, and
                // the means' round-off (≈1e-9) over 2h stays below 1e-7.
                let h = 1e-3 * if k == 0 { 10.0 } else { 50.0 };
                let mut up = probe.clone();
                let mut down = probe.clone();
                up[k] += h;
                down[k] -= h;
                let m = gp.predict_mean(&[up, down]).unwrap();
                let central = (m[0] - m[1]) / (2.0 * h);
                assert!(
                    (gradient[k] - central).abs() < 2e-5 * (1.0 + central.abs()),
                    "∂μ/∂x_{k} at {probe:?}: {} vs {central}",
                    gradient[k]
                );
            }
        }
        assert!(gp.mean_and_gradient(&[1.0]).is_err());
        assert!(gp.mean_and_gradient(&[f64::NAN, 1.0]).is_err());
    }
}
