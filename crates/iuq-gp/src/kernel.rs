//! The squared-exponential kernel with white noise, its variants, and its hyper-parameters in
//! log space.
//!
//! k(x, x') = c·exp(−½ Σ_k (x_k − x'_k)²/l_k²) + σ²·δ(x, x')
//!
//! - c: signal variance (estimated, or fixed — the study's original kernel fixed c = 1);
//! - l_k: length scales, one per input (ARD) or one shared by all inputs (isotropic);
//! - σ²: noise variance (white noise, estimated or fixed).
//!
//! The optimiser works on θ = (ln c, ln l_1 … ln l_p, ln σ²), leaving out the fixed ones, in
//! that order (the order of scikit-learn's `ConstantKernel * RBF + WhiteKernel`).

use serde::{Deserialize, Serialize};

use crate::error::{GpError, Result};

/// How many length scales the kernel has.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LengthScales {
    /// Automatic relevance determination: one length scale l_k per input.
    Ard,
    /// One length scale l shared by all inputs: ‖x − x'‖²/l².
    Isotropic,
}

/// Whether a variance hyper-parameter is estimated or held fixed.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Variance {
    /// Estimated by maximising the log marginal likelihood.
    Estimated,
    /// Held at this value (in the units the GP works in: standardised outputs by default).
    Fixed(f64),
}

/// Which squared-exponential kernel to use: the combination of length-scale structure, signal
/// variance c and noise variance σ².
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Kernel {
    /// ARD or isotropic length scales.
    pub length_scales: LengthScales,
    /// The signal variance c.
    pub signal_variance: Variance,
    /// The noise variance σ².
    pub noise_variance: Variance,
}

impl Default for Kernel {
    /// [`Kernel::ard`].
    fn default() -> Self {
        Self::ard()
    }
}

impl Kernel {
    /// c·RBF(l_1 … l_d) + White(σ²) with every hyper-parameter estimated (d + 2 of them).
    pub fn ard() -> Self {
        Self {
            length_scales: LengthScales::Ard,
            signal_variance: Variance::Estimated,
            noise_variance: Variance::Estimated,
        }
    }

    /// c·RBF(l) + White(σ²) with one shared length scale (3 hyper-parameters).
    pub fn isotropic() -> Self {
        Self {
            length_scales: LengthScales::Isotropic,
            ..Self::ard()
        }
    }

    /// The kernel of the study's original code: c fixed at 1 (with standardised outputs, the
    /// output variance), one isotropic length scale, estimated noise.
    pub fn study_original() -> Self {
        Self {
            length_scales: LengthScales::Isotropic,
            signal_variance: Variance::Fixed(1.0),
            noise_variance: Variance::Estimated,
        }
    }

    /// Checks that fixed variances are finite and positive.
    pub fn validate(&self) -> Result<()> {
        for (what, v) in [
            ("fixed signal variance", self.signal_variance),
            ("fixed noise variance", self.noise_variance),
        ] {
            if let Variance::Fixed(value) = v
                && !(value.is_finite() && value > 0.0)
            {
                return Err(GpError::InvalidParameter {
                    what,
                    reason: format!("must be finite and positive, got {value}"),
                });
            }
        }
        Ok(())
    }

    /// Number of length scales for `dimension` inputs: d (ARD) or 1 (isotropic).
    pub fn n_length_scales(&self, dimension: usize) -> usize {
        match self.length_scales {
            LengthScales::Ard => dimension,
            LengthScales::Isotropic => 1,
        }
    }

    /// Number of entries of θ for `dimension` inputs.
    pub fn n_theta(&self, dimension: usize) -> usize {
        usize::from(self.signal_variance == Variance::Estimated)
            + self.n_length_scales(dimension)
            + usize::from(self.noise_variance == Variance::Estimated)
    }

    /// The hyper-parameters encoded by θ = (ln c, ln l…, ln σ²) (fixed entries left out).
    pub fn hyperparameters(&self, theta: &[f64], dimension: usize) -> Result<Hyperparameters> {
        let expected = self.n_theta(dimension);
        if theta.len() != expected {
            return Err(GpError::LengthMismatch {
                what: "θ vs. the kernel's hyper-parameters",
                expected,
                actual: theta.len(),
            });
        }
        if let Some((index, &value)) = theta.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(GpError::NonFinite {
                what: "θ entry",
                index,
                value,
            });
        }
        let mut it = theta.iter().map(|t| t.exp());
        let mut next = || it.next().unwrap_or(f64::NAN);
        let signal_variance = match self.signal_variance {
            Variance::Estimated => next(),
            Variance::Fixed(c) => c,
        };
        let length_scales: Vec<f64> = (0..self.n_length_scales(dimension))
            .map(|_| next())
            .collect();
        let noise_variance = match self.noise_variance {
            Variance::Estimated => next(),
            Variance::Fixed(s) => s,
        };
        let h = Hyperparameters {
            signal_variance,
            length_scales,
            noise_variance,
        };
        h.validate(self, dimension)?;
        Ok(h)
    }

    /// θ = (ln c, ln l…, ln σ²) of `h`, leaving out the fixed entries.
    pub fn theta(&self, h: &Hyperparameters) -> Vec<f64> {
        let mut theta = Vec::with_capacity(h.length_scales.len() + 2);
        if self.signal_variance == Variance::Estimated {
            theta.push(h.signal_variance.ln());
        }
        theta.extend(h.length_scales.iter().map(|l| l.ln()));
        if self.noise_variance == Variance::Estimated {
            theta.push(h.noise_variance.ln());
        }
        theta
    }

    /// Names of the entries of θ, e.g. `["ln c", "ln l1", "ln l2", "ln sigma2"]`.
    pub fn theta_names(&self, dimension: usize) -> Vec<String> {
        let mut names = Vec::new();
        if self.signal_variance == Variance::Estimated {
            names.push("ln c".to_string());
        }
        match self.length_scales {
            LengthScales::Ard => names.extend((1..=dimension).map(|k| format!("ln l{k}"))),
            LengthScales::Isotropic => names.push("ln l".to_string()),
        }
        if self.noise_variance == Variance::Estimated {
            names.push("ln sigma2".to_string());
        }
        names
    }
}

/// Kernel hyper-parameters in natural units (of the scaled inputs and outputs the GP works in).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Hyperparameters {
    /// Signal variance c > 0.
    pub signal_variance: f64,
    /// Length scales l > 0: one per input (ARD) or a single one (isotropic).
    pub length_scales: Vec<f64>,
    /// Noise variance σ² > 0.
    pub noise_variance: f64,
}

impl Hyperparameters {
    /// Checks positivity, finiteness and the number of length scales for `kernel` on
    /// `dimension` inputs.
    pub fn validate(&self, kernel: &Kernel, dimension: usize) -> Result<()> {
        let expected = kernel.n_length_scales(dimension);
        if self.length_scales.len() != expected {
            return Err(GpError::LengthMismatch {
                what: "length scales vs. the kernel",
                expected,
                actual: self.length_scales.len(),
            });
        }
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(self.signal_variance) {
            return Err(GpError::InvalidParameter {
                what: "signal variance",
                reason: format!("must be finite and positive, got {}", self.signal_variance),
            });
        }
        if !positive(self.noise_variance) {
            return Err(GpError::InvalidParameter {
                what: "noise variance",
                reason: format!("must be finite and positive, got {}", self.noise_variance),
            });
        }
        if let Some(l) = self.length_scales.iter().find(|l| !positive(**l)) {
            return Err(GpError::InvalidParameter {
                what: "length scale",
                reason: format!("must be finite and positive, got {l}"),
            });
        }
        Ok(())
    }

    /// The weights w_k = 1/l_k² of the squared distance, expanded to `dimension` entries (the
    /// isotropic length scale repeated).
    pub(crate) fn inverse_squared_length_scales(&self, dimension: usize) -> Vec<f64> {
        (0..dimension)
            .map(|k| {
                let l = if self.length_scales.len() == 1 {
                    self.length_scales[0]
                } else {
                    self.length_scales[k]
                };
                1.0 / (l * l)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn theta_roundtrip_for_every_variant() {
        for kernel in [
            Kernel::ard(),
            Kernel::isotropic(),
            Kernel::study_original(),
            Kernel {
                noise_variance: Variance::Fixed(1e-6),
                ..Kernel::ard()
            },
        ] {
            let d = 3;
            let theta: Vec<f64> = (0..kernel.n_theta(d))
                .map(|i| 0.1 * i as f64 - 0.2)
                .collect();
            let h = kernel.hyperparameters(&theta, d).unwrap();
            assert_eq!(h.length_scales.len(), kernel.n_length_scales(d));
            let back = kernel.theta(&h);
            for (a, b) in theta.iter().zip(&back) {
                assert!((a - b).abs() < 1e-15);
            }
            assert_eq!(kernel.theta_names(d).len(), theta.len());
        }
        assert_eq!(Kernel::ard().n_theta(3), 5);
        assert_eq!(Kernel::isotropic().n_theta(3), 3);
        assert_eq!(Kernel::study_original().n_theta(3), 2);
    }

    #[test]
    fn bad_theta_and_fixed_values_are_errors() {
        let k = Kernel::ard();
        assert!(k.hyperparameters(&[0.0; 4], 3).is_err());
        assert!(
            k.hyperparameters(&[0.0, f64::NAN, 0.0, 0.0, 0.0], 3)
                .is_err()
        );
        assert!(k.hyperparameters(&[800.0, 0.0, 0.0, 0.0, 0.0], 3).is_err());
        let bad = Kernel {
            signal_variance: Variance::Fixed(-1.0),
            ..Kernel::ard()
        };
        assert!(bad.validate().is_err());
        assert!(Kernel::study_original().validate().is_ok());
    }
}
