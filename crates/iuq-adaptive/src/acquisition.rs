//! How uncertain a GP leaves a Gaussian log-likelihood term.
//!
//! For a datum y with total variance s² (measurement and modelling error) and a surrogate
//! prediction f ~ N(μ, v) of the model output, the log-likelihood term
//! ℓ = −(y − f)²/(2s²) − ½ ln(2πs²) is a random variable; with r = y − μ and e = f − μ ~ N(0, v),
//! (y − f)² = (r − e)² has variance 4r²v + 2v², so
//!
//! Var\[ℓ\] = (r²·v + v²/2)/s⁴.
//!
//! Summed over independent GPs it is the variance of the whole log-likelihood. What moves the
//! posterior, though, is the error of the likelihood L = e^ℓ itself: for a small spread,
//! Var\[L\] ≈ L²·Var\[ℓ\]. The acquisition of a candidate θ is therefore
//!
//! a(θ) = p_answer(θ) · (L̄(θ)π(θ) / max_θ' L̄(θ')π(θ'))² · Σ_t Var[ℓ_t(θ)],
//!
//! the variance of the (unnormalised) posterior density there relative to its largest value over
//! the candidates, times the probability that the model answers. Without the squared density
//! the variance of ℓ grows with the residual r² into the posterior's tails, and runs would go
//! there; with it they go where the posterior mass is uncertain. This is the form of GPry's
//! acquisition (El Gammal, Schöneberg, Torrado & Fidler 2023: exp(2ζ·μ_log p)·σ_log p, here with
//! ζ = 1 and the variance) and of the integrated likelihood variance that the sequential design
//! for calibration of Sürer, Plumlee & Wild (2023) drives down.

/// Var[ln N(y | f, s²)] for f ~ N(`mean`, `variance`) and total data variance `total_variance`:
/// (r²v + v²/2)/s⁴ with r = y − mean. Zero for a non-positive or non-finite variance, and
/// infinite for a non-positive total variance.
pub fn log_likelihood_variance(datum: f64, mean: f64, variance: f64, total_variance: f64) -> f64 {
    if !(variance.is_finite() && variance > 0.0) {
        return 0.0;
    }
    if total_variance.is_nan() || total_variance <= 0.0 {
        return f64::INFINITY;
    }
    let r = datum - mean;
    (r * r * variance + 0.5 * variance * variance) / (total_variance * total_variance)
}

/// The weights (L̄π/max L̄π)² · p_answer of candidates with log posterior densities
/// `log_density` (ℓ̄ + ln π, up to a constant) and answer probabilities `answer_probability`. A
/// candidate with a non-finite log density gets weight 0.
pub fn likelihood_weights(log_density: &[f64], answer_probability: &[f64]) -> Vec<f64> {
    let max = log_density
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(f64::NEG_INFINITY, f64::max);
    log_density
        .iter()
        .zip(answer_probability)
        .map(|(l, p)| {
            if l.is_finite() && max.is_finite() {
                (2.0 * (l - max)).exp() * p
            } else {
                0.0
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// The closed form against a Monte Carlo estimate of the variance of ℓ, within 4 standard
    /// errors of the estimator (the variance of a sample variance of n draws is
    /// (μ₄ − σ⁴(n − 3)/(n − 1))/n, estimated from the same draws).
    #[test]
    fn the_closed_form_matches_monte_carlo() {
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(7);
        for (y, mu, v, s2) in [
            (1.0, 0.7, 0.04, 0.01),
            (0.0, 0.0, 0.5, 2.0),
            (3.0, 1.0, 1.0, 4.0),
        ] {
            let normal = Normal::new(mu, f64::sqrt(v)).unwrap();
            let n = 200_000;
            let ell: Vec<f64> = (0..n)
                .map(|_| {
                    let f: f64 = normal.sample(&mut rng);
                    -(y - f) * (y - f) / (2.0 * s2)
                })
                .collect();
            let mean = ell.iter().sum::<f64>() / n as f64;
            let var = ell.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
            let m4 = ell.iter().map(|l| (l - mean).powi(4)).sum::<f64>() / n as f64;
            let se = ((m4 - var * var * (n as f64 - 3.0) / (n as f64 - 1.0)) / n as f64).sqrt();
            let exact = log_likelihood_variance(y, mu, v, s2);
            assert!((var - exact).abs() < 4.0 * se, "{var} vs {exact} (se {se})");
        }
    }

    #[test]
    fn weights_are_the_squared_relative_density_times_the_answer_probability() {
        let w = likelihood_weights(
            &[-1.0, -2.0, f64::NEG_INFINITY, -1.0],
            &[1.0, 1.0, 1.0, 0.5],
        );
        assert_eq!(w[0], 1.0);
        assert!((w[1] - (-2.0f64).exp()).abs() < 1e-15);
        assert_eq!(w[2], 0.0);
        assert_eq!(w[3], 0.5);
    }

    #[test]
    fn degenerate_inputs() {
        assert_eq!(log_likelihood_variance(1.0, 0.0, 0.0, 1.0), 0.0);
        assert_eq!(log_likelihood_variance(1.0, 0.0, f64::NAN, 1.0), 0.0);
        assert!(log_likelihood_variance(1.0, 0.0, 1.0, 0.0).is_infinite());
    }
}
