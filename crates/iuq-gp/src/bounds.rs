//! Bounds of the hyper-parameters for the likelihood maximisation, and why the defaults are
//! what they are.
//!
//! The defaults assume the default scaling: inputs mapped onto the unit cube and outputs
//! standardised (unit variance). Wide "agnostic" bounds such as 1e−5…1e5 on everything let the
//! optimiser run into degenerate optima that are valid maxima of the likelihood but useless
//! surrogates — above all l → 0, where K ≈ (c + σ²)·I, every training point is explained as
//! noise around the mean and the GP predicts the mean between the points. The defaults:
//!
//! - **length scales l ∈ [1e−2, 1e3]** (fractions of the input range). Below 1e−2 of the range
//!   no practical design correlates neighbouring points (even 10⁶ points in 3-D are ≈ 1e−2
//!   apart), so K is numerically diagonal; an optimum at the lower bound is reported as
//!   degenerate. At l = 1e3 an input changes the kernel by at most ½·(1e−3)² ≈ 5e−7 over the
//!   whole range: the input is irrelevant (or enters only through a low-order trend, where only
//!   c/l² matters), so larger values would add nothing but a flat ridge for the optimiser.
//! - **signal variance c ∈ [1e−3, 1e3]** (in units of the output variance). A GP signal far
//!   below the output variance means the data are noise; far above it occurs legitimately only
//!   together with long length scales (a smooth trend over the box: c·(1 − ½Δ²/l²) with c/l²
//!   identified), for which 1e3 leaves room (ratio c/l² down to 1e−3 at l = 1e3, up to 1e7
//!   at l = 1e−2).
//! - **noise variance σ² ∈ [1e−8, 1]** (fraction of the output variance). 1 means pure noise.
//!   1e−8 (a relative noise std of 1e−4) keeps the condition number of K below ≈ n·c/σ²
//!   ≈ 1e13–1e14 for c ≤ 1e3 and n ~ 1e3, where the Cholesky factor and the likelihood are
//!   still accurate; a deterministic simulator's noise optimum sits at this bound, which is
//!   expected and not a warning. The study's scikit-learn default was 1e−5.

use serde::{Deserialize, Serialize};

use crate::error::{GpError, Result};
use crate::kernel::{Kernel, Variance};

/// Lower and upper bound (natural units, `[lower, upper]`) of each hyper-parameter.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Bounds {
    /// Bounds of the signal variance c.
    pub signal_variance: [f64; 2],
    /// Bounds of every length scale l_k.
    pub length_scale: [f64; 2],
    /// Bounds of the noise variance σ².
    pub noise_variance: [f64; 2],
}

impl Default for Bounds {
    /// c ∈ [1e−3, 1e3], l ∈ [1e−2, 1e3], σ² ∈ [1e−8, 1]: see the module documentation.
    fn default() -> Self {
        Self {
            signal_variance: [1e-3, 1e3],
            length_scale: [1e-2, 1e3],
            noise_variance: [1e-8, 1.0],
        }
    }
}

impl Bounds {
    /// scikit-learn's default bounds, 1e−5…1e5 for every hyper-parameter (prone to degenerate
    /// optima; offered for comparisons).
    pub fn scikit_learn() -> Self {
        Self {
            signal_variance: [1e-5, 1e5],
            length_scale: [1e-5, 1e5],
            noise_variance: [1e-5, 1e5],
        }
    }

    /// Checks 0 < lower ≤ upper < ∞ for every range.
    pub fn validate(&self) -> Result<()> {
        for (what, [lo, hi]) in [
            ("signal variance bounds", self.signal_variance),
            ("length scale bounds", self.length_scale),
            ("noise variance bounds", self.noise_variance),
        ] {
            if !(lo > 0.0 && lo <= hi && hi.is_finite()) {
                return Err(GpError::InvalidParameter {
                    what,
                    reason: format!("need 0 < lower ≤ upper < ∞, got [{lo}, {hi}]"),
                });
            }
        }
        Ok(())
    }

    /// The box of θ = (ln c, ln l…, ln σ²) for `kernel` on `dimension` inputs.
    pub fn log_box(&self, kernel: &Kernel, dimension: usize) -> (Vec<f64>, Vec<f64>) {
        let mut lower = Vec::new();
        let mut upper = Vec::new();
        let mut push = |[lo, hi]: [f64; 2]| {
            lower.push(lo.ln());
            upper.push(hi.ln());
        };
        if kernel.signal_variance == Variance::Estimated {
            push(self.signal_variance);
        }
        for _ in 0..kernel.n_length_scales(dimension) {
            push(self.length_scale);
        }
        if kernel.noise_variance == Variance::Estimated {
            push(self.noise_variance);
        }
        (lower, upper)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_box_and_validation() {
        let (lo, hi) = Bounds::default().log_box(&Kernel::ard(), 2);
        assert_eq!(lo.len(), 4);
        assert!((lo[1] - 1e-2f64.ln()).abs() < 1e-15 && (hi[3] - 0.0).abs() < 1e-15);
        let (lo, _) = Bounds::default().log_box(&Kernel::study_original(), 2);
        assert_eq!(lo.len(), 2);
        assert!(Bounds::default().validate().is_ok());
        let bad = Bounds {
            length_scale: [1.0, 0.5],
            ..Default::default()
        };
        assert!(bad.validate().is_err());
        let bad = Bounds {
            noise_variance: [0.0, 1.0],
            ..Default::default()
        };
        assert!(bad.validate().is_err());
    }
}
