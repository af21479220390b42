//! Whether the round's surrogate posterior depends on how it was sampled: the check that keeps
//! a biased sampler from being taken for a converged posterior.
//!
//! The replicates of a round are split into two groups, A sampled with the study's settings and
//! B with chains that mix harder (`iuq_basis::CheckedSettings::with_stronger_mixing`). Both
//! sample the same surrogate posterior; if both are right their moments differ by Monte Carlo
//! noise only. Replicates with the *same* settings cannot see a bias they share (a population
//! whose chains barely move is wrong alike with every seed), so their spread alone understates
//! the error — the check of "independent samplers with different settings" (Gelman & Rubin
//! 1992, in the spirit of Vehtari et al. 2021's R̂ over chains with dispersed starts).
//!
//! For parameter k: d_k = max(|μ̄_A − μ̄_B|, |σ̄_A − σ̄_B|) minus z times the Monte Carlo error
//! of that difference (z = [`crate::NOISE_MULTIPLE`]; the error from the replicates' spread
//! within the groups, pooled, zero when each group has one replicate), in posterior stds σ_k.
//! The sampler disagrees when max_k d_k exceeds the tolerance.

use serde::{Deserialize, Serialize};

use crate::convergence::NOISE_MULTIPLE;

/// One replicate's (means, stds).
type Replicate = (Vec<f64>, Vec<f64>);
/// Which value of a replicate a statistic reads.
type Pick<'a> = &'a dyn Fn(&Replicate) -> f64;
use crate::error::{AdaptiveError, Result};

/// The comparison of two groups of replicate samplers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SamplerAgreement {
    /// max_k d_k: the largest difference of a posterior mean or std between the groups beyond
    /// the noise, in posterior stds.
    pub disagreement: f64,
    /// The largest noise allowance z·e_k/σ_k used, in posterior stds.
    pub noise: f64,
    /// `disagreement` exceeds the tolerance: the posterior depends on the sampler's settings.
    pub disagrees: bool,
}

/// Compare replicate moments `(mean, std)` of group `a` (the settings in use) and group `b` (the
/// stronger mixing), with the pooled posterior stds `scale`, against `tolerance` (posterior
/// stds).
///
/// # Errors
/// An empty group or moments of different lengths.
pub fn sampler_agreement(
    a: &[(Vec<f64>, Vec<f64>)],
    b: &[(Vec<f64>, Vec<f64>)],
    scale: &[f64],
    tolerance: f64,
) -> Result<SamplerAgreement> {
    if a.is_empty() || b.is_empty() {
        return Err(AdaptiveError::InvalidParameter {
            what: "sampler agreement",
            reason: "each group needs at least one replicate".into(),
        });
    }
    let d = scale.len();
    for (mean, std) in a.iter().chain(b) {
        if mean.len() != d || std.len() != d {
            return Err(AdaptiveError::LengthMismatch {
                what: "replicate moments",
                expected: d,
                actual: mean.len().min(std.len()),
            });
        }
    }
    let average = |group: &[Replicate], pick: Pick<'_>| {
        group.iter().map(pick).sum::<f64>() / group.len() as f64
    };
    // Pooled within-group variance of one replicate's value, and the error of the difference
    // of the two groups' averages.
    let difference_error = |pick: Pick<'_>| {
        let (ma, mb) = (average(a, pick), average(b, pick));
        let squares: f64 = a.iter().map(|r| (pick(r) - ma).powi(2)).sum::<f64>()
            + b.iter().map(|r| (pick(r) - mb).powi(2)).sum::<f64>();
        let dof = a.len() + b.len() - 2;
        if dof == 0 {
            return 0.0;
        }
        let variance = squares / dof as f64;
        (variance * (1.0 / a.len() as f64 + 1.0 / b.len() as f64)).sqrt()
    };
    let (mut disagreement, mut noise): (f64, f64) = (0.0, 0.0);
    for k in 0..d {
        let s = scale[k];
        if s.is_nan() || s <= 0.0 {
            continue;
        }
        let mean = |r: &Replicate| r.0[k];
        let std = |r: &Replicate| r.1[k];
        let (em, es) = (
            NOISE_MULTIPLE * difference_error(&mean),
            NOISE_MULTIPLE * difference_error(&std),
        );
        let dm = (average(a, &mean) - average(b, &mean)).abs() - em;
        let ds = (average(a, &std) - average(b, &std)).abs() - es;
        let beyond = if dm.is_nan() || ds.is_nan() {
            f64::INFINITY
        } else {
            dm.max(ds).max(0.0) / s
        };
        disagreement = disagreement.max(beyond);
        noise = noise.max(em.max(es) / s);
    }
    Ok(SamplerAgreement {
        disagreement,
        noise,
        disagrees: disagreement > tolerance,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn replicate(mean: f64, std: f64) -> (Vec<f64>, Vec<f64>) {
        (vec![mean, 0.0], vec![std, 1.0])
    }

    #[test]
    fn groups_that_differ_by_noise_agree_and_a_shared_bias_shows() {
        // Means scattered by 0.02 std within each group, the groups 0.01 apart: agreement.
        let a = [replicate(1.00, 1.0), replicate(1.02, 1.0)];
        let b = [replicate(1.01, 1.0), replicate(0.99, 1.0)];
        let r = sampler_agreement(&a, &b, &[1.0, 1.0], 0.1).unwrap();
        assert!(!r.disagrees, "{r:?}");
        assert_eq!(r.disagreement, 0.0);
        // Group A shifted by 0.5 std with the same small scatter: a bias the spread within A
        // could never show.
        let a = [replicate(1.50, 1.0), replicate(1.52, 1.0)];
        let r = sampler_agreement(&a, &b, &[1.0, 1.0], 0.1).unwrap();
        assert!(r.disagrees, "{r:?}");
        // |Δμ| = 0.51, noise 2·√(v·(1/2 + 1/2)) with v = (2·0.01² + 2·0.01²)/2 = 2e-4
        let expected = 0.51 - 2.0 * (2e-4f64).sqrt();
        assert!((r.disagreement - expected).abs() < 1e-12, "{r:?}");
    }

    #[test]
    fn a_std_too_narrow_disagrees_and_noise_is_allowed_for() {
        let a = [replicate(0.0, 0.6), replicate(0.0, 0.62)];
        let b = [replicate(0.0, 1.0), replicate(0.0, 1.02)];
        let r = sampler_agreement(&a, &b, &[1.0, 1.0], 0.1).unwrap();
        assert!(r.disagrees && r.disagreement > 0.3, "{r:?}");
        // Wide scatter within the groups: the same difference is noise.
        let a = [replicate(0.0, 0.2), replicate(0.0, 1.0)];
        let b = [replicate(0.0, 0.6), replicate(0.0, 1.4)];
        let r = sampler_agreement(&a, &b, &[1.0, 1.0], 0.1).unwrap();
        assert!(!r.disagrees, "{r:?}");
    }

    #[test]
    fn single_replicates_compare_without_noise_and_bad_input_is_an_error() {
        let r = sampler_agreement(
            &[replicate(0.2, 1.0)],
            &[replicate(0.0, 1.0)],
            &[2.0, 1.0],
            0.05,
        )
        .unwrap();
        assert!((r.disagreement - 0.1).abs() < 1e-12 && r.disagrees && r.noise == 0.0);
        assert!(sampler_agreement(&[], &[replicate(0.0, 1.0)], &[1.0, 1.0], 0.1).is_err());
        assert!(
            sampler_agreement(&[replicate(0.0, 1.0)], &[replicate(0.0, 1.0)], &[1.0], 0.1).is_err()
        );
    }
}
