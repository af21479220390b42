//! Two fidelities of many data points with one discrepancy shared across them.
//!
//! Where a model runs once per data point (one run per (θ, t_j)), [`MultiFidelityGp::fit`]
//! fits a discrepancy per data point, and each needs 2·(d + 1) expensive runs of its own before
//! the cheap model is used there ([`crate::multi_fidelity::min_high_fidelity_runs`]): ten
//! data points, sixty expensive runs. But the discrepancy of neighbouring data points is usually one smooth
//! function of the abscissa too, as in Kennedy & O'Hagan's (2001, "Bayesian calibration of
//! computer models", JRSS B 63(3)) δ(x) over the experimental inputs. So here
//!
//! y_H(θ, t_j) = ρ·f_L,j(θ) + s_j·δ(θ, t_j),
//!
//! with f_L,j the GP of the cheap runs at data point j (as per point), one ρ for all data points,
//! and one GP δ on (θ, t) fitted to the scaled residuals (y_H − ρ·μ_L,j(θ))/s_j of every
//! expensive run of every data point. s_j, the std of the cheap runs' outputs at point j, puts
//! data points of different magnitudes (a decaying curve) on one scale. ρ maximises δ's
//! leave-one-out log predictive density (the grid of [`MultiFidelityGp::fit`]), in the outputs'
//! units (the scaled density less Σ ln s_j).
//!
//! The shared model is used where it has at least 2·(d + 2) expensive runs in all (δ has d + 1
//! inputs), ρ's cheap outputs explain at least [`crate::multi_fidelity::MIN_EXPLAINED`] of the
//! scaled runs' variance, and its leave-one-out density over all expensive runs beats, by
//! [`crate::multi_fidelity::RHO_PRICE`], both the expensive runs without the cheap model (the
//! per-point single-fidelity GPs' summed densities, and the pooled GP at ρ = 0, so that the gain
//! is the cheap model's, not the pooling's) and, where every point has the 2·(d + 1) expensive
//! runs its own discrepancy needs, the per-point emulators' summed densities (each point's
//! two-fidelity GP where that is used; with fewer runs a point's density over its handful says
//! little). Otherwise, or where the pooled fit fails, the per-point emulators are returned
//! unchanged. Each data point's emulator stays a [`MultiFidelityGp`]
//! (its predictions at (θ, t_j), [`MultiFidelityGp::shared_point`]); its recorded leave-one-out
//! densities and explained share are then the pooled ones.
//!
//! **Correlated errors.** δ's errors at two data points are correlated (by
//! r_jk = exp(−½((t_j − t_k)/l_t)²) a priori, l_t δ's length scale in t), but the likelihood and
//! the engine take each data point's predictive variance as independent of the others'. So δ's
//! variance at point j is taken m_j = Σ_k r_jk times: with D the diagonal of δ's stds,
//! D·diag(R·1)·D − D·R·D = D·(diag(R·1) − R)·D is positive semidefinite (diag(R·1) − R is the
//! Laplacian of a graph with the non-negative weights r_jk), so the inflated independent
//! variances bound the correlated covariance, with δ's prior correlation standing in for its
//! posterior one. Without it a cheap model at cost ratio 1,000 left a 10-point curve's
//! posterior 0.24 stds off at the stop (C2ST 0.557): independent errors average out over the
//! data points, correlated ones do not.
//!
//! ```
//! use iuq_gp::{FitOptions, PointRuns, fit_shared_discrepancy};
//!
//! // Ten data points t = 0..9 of a decay; the cheap model's trend in t is 3 % off a step.
//! let expensive = |th: &[f64], t: f64| th[0] * (-th[1] * t).exp() + 0.3 * (th[1] * t).sin();
//! let cheap = |th: &[f64], t: f64| th[0] * (-th[1] * t).exp() * (1.0 + 0.03 * t);
//! let grid = |n: usize, shift: usize| -> Vec<Vec<f64>> {
//!     (0..n)
//!         .map(|i| {
//!             let u = ((i * 7 + shift * 3) % n) as f64 / n as f64;
//!             vec![1.0 + 9.0 * (i as f64 + 0.5) / n as f64, 0.05 + 0.95 * u]
//!         })
//!         .collect()
//! };
//! let runs: Vec<(f64, Vec<Vec<f64>>, Vec<f64>, Vec<Vec<f64>>, Vec<f64>)> = (0..10)
//!     .map(|j| {
//!         let t = j as f64;
//!         let (lx, hx) = (grid(24, j), grid(3, j + 1));
//!         let ly = lx.iter().map(|x| cheap(x, t)).collect();
//!         let hy = hx.iter().map(|x| expensive(x, t)).collect();
//!         (t, lx, ly, hx, hy)
//!     })
//!     .collect();
//! let points: Vec<PointRuns<'_>> = runs
//!     .iter()
//!     .map(|(t, lx, ly, hx, hy)| PointRuns {
//!         abscissa: *t,
//!         low_x: lx,
//!         low_y: ly,
//!         high_x: hx,
//!         high_y: hy,
//!     })
//!     .collect();
//! let options = FitOptions::default().check()?;
//! let gps = fit_shared_discrepancy(&points, &options)?;
//! // 30 expensive runs in all, 3 per point: too few for any point's own discrepancy.
//! assert!(gps.iter().all(|gp| gp.uses_low_fidelity() && gp.shared_point().is_some()));
//! # Ok::<(), iuq_gp::GpError>(())
//! ```

use rayon::prelude::*;

use crate::error::{GpError, Result};
use crate::fit::{CheckedFitOptions, FitOptions};
use crate::gaussian_process::GaussianProcess;
use crate::multi_fidelity::{
    MultiFidelityGp, RHO_PRICE, SharedPoint, least_squares_slope, loo_log_density,
    min_high_fidelity_runs, search_rho, variance, variance_scale,
};

/// The runs of both fidelities at one data point.
#[derive(Debug, Clone, Copy)]
pub struct PointRuns<'a> {
    /// The data point's abscissa t_j.
    pub abscissa: f64,
    /// The cheap model's runs: parameter vectors.
    pub low_x: &'a [Vec<f64>],
    /// The cheap model's output at each.
    pub low_y: &'a [f64],
    /// The expensive model's runs: parameter vectors.
    pub high_x: &'a [Vec<f64>],
    /// The expensive model's output at each.
    pub high_y: &'a [f64],
}

/// Every data point's two-fidelity emulator: on the shared discrepancy where it wins (module
/// docs), else each point's own [`MultiFidelityGp::fit`]. The shared δ is fitted with
/// `options`; point j's own GPs with `point_options(j)`.
///
/// # Errors
/// Those of [`MultiFidelityGp::fit`] at any point, or of δ's fit; a non-finite abscissa.
pub fn fit_shared_discrepancy_with(
    points: &[PointRuns<'_>],
    options: &CheckedFitOptions,
    point_options: &(dyn Fn(usize) -> Result<CheckedFitOptions> + Sync),
) -> Result<Vec<MultiFidelityGp>> {
    if let Some(bad) = points.iter().find(|p| !p.abscissa.is_finite()) {
        return Err(GpError::InvalidParameter {
            what: "abscissa",
            reason: format!("{} is not finite", bad.abscissa),
        });
    }
    let per_point: Vec<MultiFidelityGp> = points
        .par_iter()
        .enumerate()
        .map(|(j, p)| {
            MultiFidelityGp::fit(p.low_x, p.low_y, p.high_x, p.high_y, &point_options(j)?)
        })
        .collect::<Result<_>>()?;
    let Some(d) = points.iter().find_map(|p| p.high_x.first().map(Vec::len)) else {
        return Ok(per_point);
    };
    let runs: usize = points.iter().map(|p| p.high_x.len()).sum();
    if points.len() < 2 || runs < min_high_fidelity_runs(d + 1) {
        return Ok(per_point);
    }
    let Ok(Some((shared, scales))) = fit_pooled(points, &per_point, options) else {
        return Ok(per_point);
    };
    let length = shared.discrepancy.length_scales_in_input_units()[d];
    let correlated = |t: f64| -> f64 {
        points
            .iter()
            .map(|q| (-0.5 * ((t - q.abscissa) / length).powi(2)).exp())
            .sum()
    };
    Ok(per_point
        .into_iter()
        .zip(points.iter().zip(&scales))
        .map(|(own, (p, &scale))| MultiFidelityGp {
            low: own.low,
            single: own.single,
            shared: Some(SharedPoint {
                abscissa: p.abscissa,
                scale,
                correlated_points: correlated(p.abscissa),
            }),
            ..shared.clone()
        })
        .collect())
}

/// The pooled two-fidelity GP (its `shared` left `None`) and each point's s_j, where it wins
/// (module docs); `None` where it does not.
fn fit_pooled(
    points: &[PointRuns<'_>],
    per_point: &[MultiFidelityGp],
    options: &CheckedFitOptions,
) -> Result<Option<(MultiFidelityGp, Vec<f64>)>> {
    let separate: f64 = per_point
        .iter()
        .map(|gp| {
            let (two, single) = gp.loo_log_densities();
            if gp.uses_low_fidelity() { two } else { single }
        })
        .sum();
    let single: f64 = per_point.iter().map(|gp| gp.loo_log_densities().1).sum();
    let pooled = Pooled::new(points, per_point)?;
    let discrepancy_at = |rho: f64| -> Result<(f64, GaussianProcess)> {
        let gp = GaussianProcess::fit(&pooled.inputs, &pooled.residuals(rho), options)?;
        Ok((loo_log_density(gp.leave_one_out()) - pooled.log_scales, gp))
    };
    let (alone, _) = discrepancy_at(0.0)?;
    let slope = least_squares_slope(&pooled.low, &pooled.high);
    // ρ = 0 was scored above.
    let (rho, (density, discrepancy)) = search_rho(slope, 1, &discrepancy_at)?;
    let total = variance(&pooled.high);
    let explained = if total > 0.0 {
        1.0 - variance(&pooled.residuals(rho)) / total
    } else {
        0.0
    };
    let shared = MultiFidelityGp {
        low: per_point[0].low.clone(),
        discrepancy_variance_scale: variance_scale(discrepancy.leave_one_out()),
        discrepancy,
        single: per_point[0].single.clone(),
        rho,
        two_fidelity_loo_log_density: density,
        single_fidelity_loo_log_density: single.max(alone),
        explained,
        enough_high_runs: true,
        shared: None,
    };
    let own_discrepancies = per_point.iter().all(|gp| gp.enough_high_runs);
    let wins =
        shared.uses_low_fidelity() && !(own_discrepancies && density <= separate + RHO_PRICE);
    Ok(wins.then_some((shared, pooled.scales)))
}

/// [`fit_shared_discrepancy_with`] with `options` for every GP (point j's own with the seed
/// `options.seed + j + 1`).
///
/// # Errors
/// As [`fit_shared_discrepancy_with`].
pub fn fit_shared_discrepancy(
    points: &[PointRuns<'_>],
    options: &CheckedFitOptions,
) -> Result<Vec<MultiFidelityGp>> {
    fit_shared_discrepancy_with(points, options, &|j| {
        FitOptions {
            seed: options.seed.wrapping_add(j as u64 + 1),
            ..*options.options()
        }
        .check()
    })
}

/// Every expensive run of every data point, scaled by its point's s_j, with δ's inputs (θ, t_j).
struct Pooled {
    inputs: Vec<Vec<f64>>,
    /// y_H/s_j.
    high: Vec<f64>,
    /// μ_L,j(θ)/s_j at each run.
    low: Vec<f64>,
    /// s_j of each point.
    scales: Vec<f64>,
    /// Σ over runs of ln s_j: the scaled densities less this are in the outputs' units.
    log_scales: f64,
}

impl Pooled {
    fn new(points: &[PointRuns<'_>], per_point: &[MultiFidelityGp]) -> Result<Self> {
        let mut pooled = Pooled {
            inputs: Vec::new(),
            high: Vec::new(),
            low: Vec::new(),
            scales: Vec::with_capacity(points.len()),
            log_scales: 0.0,
        };
        for (p, gp) in points.iter().zip(per_point) {
            let spread = variance(p.low_y).sqrt();
            let scale = if spread.is_finite() && spread > 0.0 {
                spread
            } else {
                1.0
            };
            pooled.scales.push(scale);
            let at_high = gp.low.predict_mean(p.high_x)?;
            for ((x, y), l) in p.high_x.iter().zip(p.high_y).zip(at_high) {
                pooled
                    .inputs
                    .push(x.iter().copied().chain([p.abscissa]).collect());
                pooled.high.push(y / scale);
                pooled.low.push(l / scale);
                pooled.log_scales += scale.ln();
            }
        }
        Ok(pooled)
    }

    /// The scaled residuals y_H/s_j − ρ·μ_L,j/s_j.
    fn residuals(&self, rho: f64) -> Vec<f64> {
        self.high
            .iter()
            .zip(&self.low)
            .map(|(y, l)| y - rho * l)
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn expensive(th: &[f64], t: f64) -> f64 {
        th[0] * (-th[1] * t).exp() + 0.3 * (th[1] * t).sin()
    }

    /// `n` points of [1, 10] × [0.05, 1], a stratified design shuffled by `shift`.
    fn design(n: usize, shift: usize) -> Vec<Vec<f64>> {
        (0..n)
            .map(|i| {
                let u = ((i * 7 + shift * 3) % n) as f64 / n as f64;
                vec![1.0 + 9.0 * (i as f64 + 0.5) / n as f64, 0.05 + 0.95 * u]
            })
            .collect()
    }

    type Runs = Vec<(f64, Vec<Vec<f64>>, Vec<f64>, Vec<Vec<f64>>, Vec<f64>)>;

    fn runs(cheap: &dyn Fn(&[f64], f64) -> f64, high: usize) -> Runs {
        (0..10)
            .map(|j| {
                let t = j as f64;
                let (lx, hx) = (design(24, j), design(high, j + 1));
                let ly = lx.iter().map(|x| cheap(x, t)).collect();
                let hy = hx.iter().map(|x| expensive(x, t)).collect();
                (t, lx, ly, hx, hy)
            })
            .collect()
    }

    fn points(runs: &Runs) -> Vec<PointRuns<'_>> {
        runs.iter()
            .map(|(t, lx, ly, hx, hy)| PointRuns {
                abscissa: *t,
                low_x: lx,
                low_y: ly,
                high_x: hx,
                high_y: hy,
            })
            .collect()
    }

    /// RMS error of `gps` against the expensive model on 40 test points per data point.
    fn rms(gps: &[MultiFidelityGp]) -> f64 {
        let test = design(40, 5);
        let mut sum = 0.0;
        for (j, gp) in gps.iter().enumerate() {
            let mean = gp.predict(&test).unwrap().mean;
            for (x, m) in test.iter().zip(mean) {
                sum += (m - expensive(x, j as f64)).powi(2);
            }
        }
        (sum / (gps.len() * test.len()) as f64).sqrt()
    }

    #[test]
    fn one_discrepancy_for_all_points_uses_a_cheap_model_each_point_alone_could_not() {
        // The cheap model's trend in t is 3 % off a step; 3 expensive runs per data point
        // (30 in all): each point alone is below 2·(d + 1) = 6, so per point only the expensive
        // runs' GP predicts.
        let runs = runs(&|th, t| th[0] * (-th[1] * t).exp() * (1.0 + 0.03 * t), 3);
        let options = FitOptions::default().check().unwrap();
        let shared = fit_shared_discrepancy(&points(&runs), &options).unwrap();
        let alone: Vec<MultiFidelityGp> = runs
            .iter()
            .map(|(_, lx, ly, hx, hy)| MultiFidelityGp::fit(lx, ly, hx, hy, &options).unwrap())
            .collect();
        assert!(alone.iter().all(|gp| !gp.uses_low_fidelity()));
        assert!(shared.iter().all(|gp| gp.uses_low_fidelity()));
        assert_eq!(shared[4].shared_point().unwrap().abscissa, 4.0);
        let (with, without) = (rms(&shared), rms(&alone));
        println!("RMS error: shared discrepancy {with:.4}, each point alone {without:.4}");
        assert!(with < 0.25 * without, "{with} against {without}");
        // The two variances add up to the latent variance the prediction reports.
        let at = design(5, 2);
        let (low, delta) = shared[3].fidelity_variances(&at).unwrap();
        let total = shared[3].predict(&at).unwrap().variance;
        for ((l, e), v) in low.iter().zip(&delta).zip(&total) {
            assert!(
                (l + e - v).abs() <= 1e-12 * v.max(1e-300),
                "{l} + {e} ≠ {v}"
            );
        }
        // A serialised emulator predicts the same.
        let back: MultiFidelityGp =
            serde_json::from_str(&serde_json::to_string(&shared[3]).unwrap()).unwrap();
        assert_eq!(
            back.predict(&at).unwrap().mean,
            shared[3].predict(&at).unwrap().mean
        );
    }

    #[test]
    fn an_unrelated_cheap_model_leaves_each_point_its_own_emulator() {
        let runs = runs(&|th, t| (7.0 * th[1] * t + th[0]).cos(), 8);
        let options = FitOptions::default().check().unwrap();
        let gps = fit_shared_discrepancy(&points(&runs), &options).unwrap();
        assert!(gps.iter().all(|gp| gp.shared_point().is_none()));
    }

    #[test]
    fn a_non_finite_abscissa_is_an_error() {
        let runs = runs(&|th, t| th[0] * (-th[1] * t).exp(), 3);
        let mut points = points(&runs);
        points[2].abscissa = f64::NAN;
        let options = FitOptions::default().check().unwrap();
        assert!(matches!(
            fit_shared_discrepancy(&points, &options),
            Err(GpError::InvalidParameter { .. })
        ));
    }
}
