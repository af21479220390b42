//! Prior distributions of single parameters: sampling, log-density, support and quantiles.

use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use crate::error::{CoreError, Result};
use crate::normal::{self, LN_SQRT_2PI};

/// The prior of one parameter.
///
/// In a study file a prior is written as a one-key table, e.g. `{ uniform = [10, 300] }`,
/// `{ normal = [mean, std] }`, `{ log_normal = [mu, sigma] }` (the normal law of `ln x`) or
/// `{ truncated_normal = [mean, std, lower, upper] }`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Prior {
    /// U(lower, upper).
    Uniform(f64, f64),
    /// N(mean, std²).
    Normal(f64, f64),
    /// ln x ~ N(mu, sigma²).
    LogNormal(f64, f64),
    /// N(mean, std²) restricted to [lower, upper].
    TruncatedNormal(f64, f64, f64, f64),
}

impl Prior {
    /// Check that the prior defines a proper distribution; `parameter` names it in the error.
    pub fn validate(&self, parameter: &str) -> Result<()> {
        let fail = |reason: String| {
            Err(CoreError::InvalidPrior {
                parameter: parameter.to_string(),
                reason,
            })
        };
        let all_finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        match *self {
            Prior::Uniform(lo, hi) => {
                if !all_finite(&[lo, hi]) {
                    return fail("uniform bounds must be finite".into());
                }
                if lo >= hi {
                    return fail(format!(
                        "uniform lower bound {lo} must be below upper bound {hi}"
                    ));
                }
            }
            Prior::Normal(m, s) | Prior::LogNormal(m, s) => {
                if !all_finite(&[m, s]) {
                    return fail("location and scale must be finite".into());
                }
                if s <= 0.0 {
                    return fail(format!("scale {s} must be positive"));
                }
            }
            Prior::TruncatedNormal(m, s, lo, hi) => {
                if !all_finite(&[m, s]) || lo.is_nan() || hi.is_nan() {
                    return fail("mean and std must be finite and bounds not NaN".into());
                }
                if s <= 0.0 {
                    return fail(format!("std {s} must be positive"));
                }
                if lo >= hi {
                    return fail(format!("lower bound {lo} must be below upper bound {hi}"));
                }
                let mass = normal::cdf((hi - m) / s) - normal::cdf((lo - m) / s);
                if mass <= 1e-300 {
                    return fail("the truncation interval holds no probability mass".into());
                }
            }
        }
        Ok(())
    }

    /// The support as a closed interval (infinite ends where unbounded).
    pub fn support(&self) -> (f64, f64) {
        match *self {
            Prior::Uniform(lo, hi) | Prior::TruncatedNormal(_, _, lo, hi) => (lo, hi),
            Prior::Normal(..) => (f64::NEG_INFINITY, f64::INFINITY),
            Prior::LogNormal(..) => (0.0, f64::INFINITY),
        }
    }

    /// True when `x` lies in the support (for the log-normal: `x > 0`).
    pub fn in_support(&self, x: f64) -> bool {
        if !x.is_finite() {
            return false;
        }
        match *self {
            Prior::LogNormal(..) => x > 0.0,
            _ => {
                let (lo, hi) = self.support();
                lo <= x && x <= hi
            }
        }
    }

    /// Natural log of the density at `x`; −∞ outside the support.
    pub fn log_density(&self, x: f64) -> f64 {
        if !self.in_support(x) {
            return f64::NEG_INFINITY;
        }
        match *self {
            Prior::Uniform(lo, hi) => -(hi - lo).ln(),
            Prior::Normal(m, s) => {
                let z = (x - m) / s;
                -0.5 * z * z - s.ln() - LN_SQRT_2PI
            }
            Prior::LogNormal(mu, sigma) => {
                let lx = x.ln();
                let z = (lx - mu) / sigma;
                -0.5 * z * z - sigma.ln() - LN_SQRT_2PI - lx
            }
            Prior::TruncatedNormal(m, s, lo, hi) => {
                let z = (x - m) / s;
                let mass = normal::cdf((hi - m) / s) - normal::cdf((lo - m) / s);
                -0.5 * z * z - s.ln() - LN_SQRT_2PI - mass.ln()
            }
        }
    }

    /// The quantile function F⁻¹(u), u ∈ (0, 1): maps a unit-cube design onto the prior.
    pub fn quantile(&self, u: f64) -> f64 {
        match *self {
            Prior::Uniform(lo, hi) => lo + u * (hi - lo),
            Prior::Normal(m, s) => m + s * normal::quantile(u),
            Prior::LogNormal(mu, sigma) => (mu + sigma * normal::quantile(u)).exp(),
            Prior::TruncatedNormal(m, s, lo, hi) => {
                let a = normal::cdf((lo - m) / s);
                let b = normal::cdf((hi - m) / s);
                (m + s * normal::quantile(a + u * (b - a))).clamp(lo, hi)
            }
        }
    }

    /// One draw from the prior.
    pub fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> f64 {
        match *self {
            Prior::Uniform(lo, hi) => lo + rng.random::<f64>() * (hi - lo),
            Prior::Normal(m, s) => {
                let z: f64 = StandardNormal.sample(rng);
                m + s * z
            }
            Prior::LogNormal(mu, sigma) => {
                let z: f64 = StandardNormal.sample(rng);
                (mu + sigma * z).exp()
            }
            Prior::TruncatedNormal(..) => {
                // Inverse-transform sampling: exact, and never loops for far-out intervals.
                let u: f64 = rng.random::<f64>();
                self.quantile(u.clamp(f64::MIN_POSITIVE, 1.0 - f64::EPSILON))
            }
        }
    }

    /// A finite interval holding the bulk of the prior: the support for bounded priors, the
    /// 1e-6 and 1 − 1e-6 quantiles otherwise. Used to scale designs and plots.
    pub fn plotting_range(&self) -> (f64, f64) {
        let (lo, hi) = self.support();
        let lo = if lo.is_finite() {
            lo
        } else {
            self.quantile(1e-6)
        };
        let hi = if hi.is_finite() {
            hi
        } else {
            self.quantile(1.0 - 1e-6)
        };
        (lo, hi)
    }

    /// Mean of the prior.
    pub fn mean(&self) -> f64 {
        match *self {
            Prior::Uniform(lo, hi) => 0.5 * (lo + hi),
            Prior::Normal(m, _) => m,
            Prior::LogNormal(mu, sigma) => (mu + 0.5 * sigma * sigma).exp(),
            Prior::TruncatedNormal(m, s, lo, hi) => {
                let (a, b) = ((lo - m) / s, (hi - m) / s);
                let mass = normal::cdf(b) - normal::cdf(a);
                m + s * (normal::pdf(a) - normal::pdf(b)) / mass
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::random::stream;

    #[test]
    fn log_densities_match_scipy() {
        // scipy.stats: uniform(10, 290).logpdf(50), norm(1, 2).logpdf(0.3),
        // lognorm(s=0.5, scale=exp(1)).logpdf(2.0), truncnorm((0-1)/2, (3-1)/2, 1, 2).logpdf(0.5)
        let cases = [
            (Prior::Uniform(10.0, 300.0), 50.0, -5.669_880_922_980_52),
            (Prior::Normal(1.0, 2.0), 0.3, -1.673_335_713_764_617_9),
            (Prior::LogNormal(1.0, 0.5), 2.0, -1.107_255_838_801_294_3),
            (
                Prior::TruncatedNormal(1.0, 2.0, 0.0, 3.0),
                0.5,
                -1.013_740_081_211_754_5,
            ),
        ];
        for (prior, x, expected) in cases {
            let got = prior.log_density(x);
            assert!(
                (got - expected).abs() < 1e-12,
                "{prior:?}: {got} vs {expected}"
            );
        }
        assert_eq!(Prior::Uniform(0.0, 1.0).log_density(1.5), f64::NEG_INFINITY);
        assert_eq!(
            Prior::LogNormal(0.0, 1.0).log_density(0.0),
            f64::NEG_INFINITY
        );
    }

    #[test]
    fn invalid_priors_are_rejected_with_a_reason() {
        assert!(Prior::Uniform(3.0, 1.0).validate("k").is_err());
        assert!(Prior::Normal(0.0, -1.0).validate("k").is_err());
        assert!(Prior::Uniform(0.0, f64::INFINITY).validate("k").is_err());
        assert!(
            Prior::TruncatedNormal(0.0, 1.0, 2.0, 1.0)
                .validate("k")
                .is_err()
        );
        let err = Prior::Uniform(3.0, 1.0).validate("kLink").unwrap_err();
        assert!(err.to_string().contains("kLink"));
        assert!(
            Prior::TruncatedNormal(0.0, 1.0, -1.0, 2.0)
                .validate("k")
                .is_ok()
        );
    }

    #[test]
    fn samples_have_the_prior_mean_and_stay_in_support() {
        let priors = [
            Prior::Uniform(-2.0, 5.0),
            Prior::Normal(1.0, 3.0),
            Prior::LogNormal(0.2, 0.4),
            Prior::TruncatedNormal(0.0, 1.0, 0.5, 4.0),
        ];
        let n = 200_000;
        for (k, prior) in priors.iter().enumerate() {
            let mut rng = stream(11, 0, k as u64);
            let draws: Vec<f64> = (0..n).map(|_| prior.sample(&mut rng)).collect();
            assert!(draws.iter().all(|&x| prior.in_support(x)));
            let mean = draws.iter().sum::<f64>() / n as f64;
            let var = draws.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
            let tolerance = 5.0 * (var / n as f64).sqrt();
            assert!(
                (mean - prior.mean()).abs() < tolerance,
                "{prior:?}: {mean} vs {}",
                prior.mean()
            );
        }
    }

    #[test]
    fn quantile_maps_the_unit_interval_onto_the_support() {
        let p = Prior::TruncatedNormal(1.0, 2.0, 0.0, 3.0);
        assert!((p.quantile(0.0) - 0.0).abs() < 1e-12);
        assert!((p.quantile(1.0) - 3.0).abs() < 1e-12);
        let u = Prior::Uniform(10.0, 300.0);
        assert!((u.quantile(0.5) - 155.0).abs() < 1e-12);
        let ln = Prior::LogNormal(0.0, 1.0);
        assert!((ln.quantile(0.5) - 1.0).abs() < 1e-15);
    }
}
