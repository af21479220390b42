//! Confidence intervals of Sobol' indices.
//!
//! - Bootstrap (as SALib): resample the N base points with replacement, re-estimate, and report
//!   the half-width z_{(1+c)/2}·sd of the resampled estimates (sd with ddof 1).
//! - Replicates: R independent scramblings of the Sobol' design give R independent estimates;
//!   report their mean and the half-width t_{R−1,(1+c)/2}·sd/√R. For quasi-random designs this is
//!   the honest interval: the bootstrap treats the points as i.i.d., which they are not.

use rand::Rng;
use rayon::prelude::*;

use iuq_core::normal;
use iuq_core::random::{stages, stream};

use crate::error::{Result, SensitivityError};
use crate::estimator::{SaltelliValues, SobolEstimate, indices_with_variance, pooled_variance};

/// The most bootstrap resamples: each resample's random stream is keyed by its index in 20 bits.
pub const MAX_RESAMPLES: usize = 1 << 20;

/// Half-widths of the confidence intervals of S_i and S_Ti.
#[derive(Debug, Clone, PartialEq)]
pub struct ConfidenceHalfWidths {
    /// Half-width for each first-order index.
    pub first_order: Vec<f64>,
    /// Half-width for each total index.
    pub total: Vec<f64>,
}

fn check_level(level: f64) -> Result<()> {
    if !(level > 0.0 && level < 1.0) {
        return Err(SensitivityError::InvalidOption(format!(
            "confidence level {level} must lie strictly between 0 and 1"
        )));
    }
    Ok(())
}

/// Bootstrap half-widths from `resamples` resamples of the base points, drawn from the keyed
/// stream `(seed, BOOTSTRAP, stream_index)`; `estimate` supplies V for degenerate resamples.
pub fn bootstrap_half_widths(
    values: &SaltelliValues,
    estimate: &SobolEstimate,
    resamples: usize,
    level: f64,
    seed: u64,
    stream_index: u64,
) -> Result<ConfidenceHalfWidths> {
    check_level(level)?;
    if resamples < 2 {
        return Err(SensitivityError::InvalidOption(format!(
            "at least 2 bootstrap resamples are needed, got {resamples}"
        )));
    }
    if resamples > MAX_RESAMPLES {
        return Err(SensitivityError::InvalidOption(format!(
            "at most {MAX_RESAMPLES} bootstrap resamples, got {resamples}"
        )));
    }
    values.validate()?;
    let n = values.base_points();
    let estimates: Vec<SobolEstimate> = (0..resamples)
        .into_par_iter()
        .map(|r| {
            let mut rng = stream(seed, stages::BOOTSTRAP, (stream_index << 20) + r as u64);
            let rows: Vec<usize> = (0..n).map(|_| rng.random_range(0..n)).collect();
            let sample = values.select(&rows);
            let v = pooled_variance(&sample.f_a, &sample.f_b);
            let v = if v > 0.0 { v } else { estimate.variance };
            indices_with_variance(&sample, v)
        })
        .collect();
    let z = normal::quantile(0.5 + level / 2.0);
    let d = estimate.first_order.len();
    let spread = |pick: &dyn Fn(&SobolEstimate) -> f64| {
        sample_std(&estimates.iter().map(pick).collect::<Vec<_>>())
    };
    Ok(ConfidenceHalfWidths {
        first_order: (0..d).map(|i| z * spread(&|e| e.first_order[i])).collect(),
        total: (0..d).map(|i| z * spread(&|e| e.total[i])).collect(),
    })
}

/// Combine R ≥ 2 independent replicate estimates: mean indices and t-based half-widths.
pub fn combine_replicates(
    replicates: &[SobolEstimate],
    level: f64,
) -> Result<(SobolEstimate, ConfidenceHalfWidths)> {
    check_level(level)?;
    let r = replicates.len();
    if r < 2 {
        return Err(SensitivityError::InvalidOption(format!(
            "at least 2 replicates are needed for an interval, got {r}"
        )));
    }
    let d = replicates[0].first_order.len();
    let t = student_t_quantile(0.5 + level / 2.0, (r - 1) as u32);
    let column =
        |pick: &dyn Fn(&SobolEstimate) -> f64| replicates.iter().map(pick).collect::<Vec<f64>>();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let mut estimate = SobolEstimate {
        first_order: Vec::with_capacity(d),
        total: Vec::with_capacity(d),
        variance: mean(&column(&|e| e.variance)),
    };
    let mut half = ConfidenceHalfWidths {
        first_order: Vec::with_capacity(d),
        total: Vec::with_capacity(d),
    };
    for i in 0..d {
        let s1 = column(&|e| e.first_order[i]);
        let st = column(&|e| e.total[i]);
        estimate.first_order.push(mean(&s1));
        estimate.total.push(mean(&st));
        half.first_order
            .push(t * sample_std(&s1) / (r as f64).sqrt());
        half.total.push(t * sample_std(&st) / (r as f64).sqrt());
    }
    Ok((estimate, half))
}

/// Sample standard deviation (ddof 1).
fn sample_std(v: &[f64]) -> f64 {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    (v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0)).sqrt()
}

/// P(|T| ≤ t) for Student's t with an integer number ν ≥ 1 of degrees of freedom, by the
/// finite series of Abramowitz & Stegun 26.7.3–26.7.4 (θ = atan(t/√ν)).
fn student_t_central_probability(t: f64, nu: u32) -> f64 {
    let theta = (t / f64::from(nu).sqrt()).atan();
    let (sin, cos) = theta.sin_cos();
    let cos2 = cos * cos;
    if nu % 2 == 1 {
        // (2/π)[θ + sinθ(cosθ + (2/3)cos³θ + … + (2·4···(ν−3))/(1·3···(ν−2)) cos^{ν−2}θ)]
        let mut series = 0.0;
        if nu > 1 {
            let mut term = cos;
            series = term;
            let mut k = 2;
            while k + 1 < nu {
                term *= cos2 * f64::from(k) / f64::from(k + 1);
                series += term;
                k += 2;
            }
        }
        2.0 / std::f64::consts::PI * (theta + sin * series)
    } else {
        // sinθ[1 + ½cos²θ + (1·3)/(2·4)cos⁴θ + … + (1·3···(ν−3))/(2·4···(ν−2)) cos^{ν−2}θ]
        let mut term = 1.0;
        let mut series = 1.0;
        let mut k = 1;
        while k + 1 < nu {
            term *= cos2 * f64::from(k) / f64::from(k + 1);
            series += term;
            k += 2;
        }
        sin * series
    }
}

/// Quantile of Student's t distribution with an integer number ν ≥ 1 of degrees of freedom,
/// for p ∈ (0, 1): bisection on the exact distribution function to machine precision.
pub fn student_t_quantile(p: f64, nu: u32) -> f64 {
    if !(p > 0.0 && p < 1.0) || nu == 0 {
        return f64::NAN;
    }
    if p == 0.5 {
        return 0.0;
    }
    let target = (2.0 * p - 1.0).abs();
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    while student_t_central_probability(hi, nu) < target {
        hi *= 2.0;
        if hi > 1e300 {
            break;
        }
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid == lo || mid == hi {
            break;
        }
        if student_t_central_probability(mid, nu) < target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let t = 0.5 * (lo + hi);
    if p < 0.5 { -t } else { t }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn t_quantiles_match_scipy() {
        // scipy.stats.t.ppf(0.975, [1, 2, 3, 9, 30])
        let cases = [
            (1, 12.706_204_736_174_694),
            (2, 4.302_652_729_749_462),
            (3, 3.182_446_305_283_707_8),
            (9, 2.262_157_162_798_205),
            (30, 2.042_272_456_301_237_8),
        ];
        for (nu, expected) in cases {
            let t = student_t_quantile(0.975, nu);
            assert!(
                (t - expected).abs() < 1e-12 * expected,
                "nu = {nu}: {t} vs {expected}"
            );
            assert!((student_t_quantile(0.025, nu) + expected).abs() < 1e-12 * expected);
        }
        // scipy.stats.t.ppf(0.9, 4)
        assert!((student_t_quantile(0.9, 4) - 1.533_206_274_058_944).abs() < 1e-12);
    }

    #[test]
    fn replicate_combination_is_mean_and_t_interval() {
        let make = |s: f64| SobolEstimate {
            first_order: vec![s],
            total: vec![2.0 * s],
            variance: 1.0,
        };
        let reps = [make(0.30), make(0.32), make(0.34)];
        let (est, half) = combine_replicates(&reps, 0.95).unwrap();
        assert!((est.first_order[0] - 0.32).abs() < 1e-15);
        let expected = student_t_quantile(0.975, 2) * 0.02 / 3f64.sqrt();
        assert!((half.first_order[0] - expected).abs() < 1e-12);
        assert!((half.total[0] - 2.0 * expected).abs() < 1e-12);
        assert!(combine_replicates(&reps[..1], 0.95).is_err());
        assert!(combine_replicates(&reps, 1.5).is_err());
    }
}
