//! A two-fidelity Gaussian process: an expensive model's output emulated as a scaled cheap
//! model's plus a GP discrepancy, the recursive co-kriging of Le Gratiet & Garnier (2014) on the
//! autoregressive model of Kennedy & O'Hagan (2000):
//!
//! f_H(x) = ρ·f_L(x) + δ(x),  f_L ~ GP fitted on the low-fidelity runs, δ ~ GP independent of it.
//!
//! 1. f_L is a [`GaussianProcess`] on the low-fidelity runs (x_L, y_L).
//! 2. At every high-fidelity run x_H the low fidelity's value l(x_H) is f_L's posterior mean
//!    there (the recursive formulation's plug-in; its variance there is left out of δ's fit).
//!    The mean, not a low run at the same point, also where the designs are nested: δ is then
//!    fitted on exactly what the prediction ρ·μ_L + μ_δ adds it to. (Where the low GP smooths
//!    its runs — a noisy or erratic cheap model — a raw run would teach δ the cheap model's
//!    noise, and the predictions off the runs would be biased by it.)
//! 3. ρ maximises the two-fidelity model's leave-one-out log predictive density of the high
//!    runs (below), with δ a [`GaussianProcess`] fitted on the residuals y_H − ρ·l(x_H) for each
//!    ρ tried: a grid of 9 values from 0 to twice the least-squares slope of y_H on l(x_H), then
//!    a grid 8 times finer around the best. (The least-squares slope alone is biased wherever δ
//!    correlates with f_L on the few high runs.)
//! 4. Prediction: mean ρ·μ_L(x) + μ_δ(x), latent variance ρ²·σ²_L(x) + c·σ²_δ(x), the noise
//!    variance δ's (that of a new high-fidelity run), with c ≥ 1 δ's mean squared standardised
//!    leave-one-out residual (a GP on few runs is overconfident; `variance_scale`).
//!
//! **When it beats a single-fidelity GP, and when not.** A single-fidelity GP is fitted on the
//! high-fidelity runs too, and the two are compared by their leave-one-out log predictive
//! densities over the high-fidelity runs (Rasmussen & Williams 2006, §5.4.2; closed form, no
//! refits): Σ_i −½[ln 2πv_i + r_i²/v_i] with r_i, v_i the residual and predictive variance of
//! y_H,i from the other high runs (for the two-fidelity model, δ's at the chosen ρ). ρ = 0 is the
//! single-fidelity GP itself, so the two-fidelity density is never lower; the emulator predicts
//! with both fidelities only where it is higher by more than [`RHO_PRICE`] (one nat, Akaike's
//! price of the parameter ρ; [`MultiFidelityGp::uses_low_fidelity`]), the scaled low
//! fidelity explains at least half of the high runs' variance ([`MIN_EXPLAINED`]), and there
//! are at least 2·(d + 1) high runs ([`min_high_fidelity_runs`]). A low fidelity that does
//! not correlate with the high one (its trend wrong, or noise) leaves the single-fidelity GP in
//! charge, so that it does not make the emulator worse than the high-fidelity runs alone.
//!
//! ```
//! use iuq_gp::{FitOptions, MultiFidelityGp};
//!
//! // The cheap model sin(3x) at 30 points, the expensive 2·sin(3x) + 0.3x at 6.
//! let low_x: Vec<Vec<f64>> = (0..30).map(|i| vec![i as f64 / 29.0 * 2.0]).collect();
//! let low_y: Vec<f64> = low_x.iter().map(|p| (3.0 * p[0]).sin()).collect();
//! let high_x: Vec<Vec<f64>> = (0..6).map(|i| vec![0.1 + i as f64 / 5.0 * 1.8]).collect();
//! let high_y: Vec<f64> = high_x.iter().map(|p| 2.0 * (3.0 * p[0]).sin() + 0.3 * p[0]).collect();
//! let options = FitOptions::default().check()?;
//! let gp = MultiFidelityGp::fit(&low_x, &low_y, &high_x, &high_y, &options)?;
//! assert!(gp.uses_low_fidelity());
//! assert!((gp.rho() - 2.0).abs() < 0.2, "ρ = {}", gp.rho());
//! let at = vec![vec![0.55]];
//! let mean = gp.predict(&at)?.mean[0];
//! let truth = 2.0 * (3.0f64 * 0.55).sin() + 0.3 * 0.55;
//! assert!((mean - truth).abs() < 0.05, "{mean} against {truth}");
//! # Ok::<(), iuq_gp::GpError>(())
//! ```

use serde::{Deserialize, Serialize};

use crate::data::validate_points;
use crate::error::{GpError, Result};
use crate::fit::CheckedFitOptions;
use crate::gaussian_process::GaussianProcess;
use crate::prediction::Prediction;
use crate::validation::LeaveOneOut;

/// The gain in leave-one-out log predictive density (nats) the two fidelities must show over
/// the high-fidelity runs alone to be used: 1, Akaike's price of the one parameter ρ they add.
pub const RHO_PRICE: f64 = 1.0;

/// The share of the high-fidelity runs' variance that ρ·l(x_H) must explain for the low
/// fidelity to be used: 1 − var(y_H − ρ·l)/var(y_H) ≥ ½. Below it the discrepancy carries most
/// of the output, and a gain in leave-one-out density comes from fitting a GP to nearly the
/// same numbers again (a different optimum of its hyperparameters), not from the cheap model.
pub const MIN_EXPLAINED: f64 = 0.5;

/// The fewest high-fidelity runs, per input dimension d, with which the low fidelity is used:
/// 2·(d + 1), twice the d + 2 numbers (ρ, δ's length scales and variance) fitted to them less
/// one. With fewer, ρ and δ fitted to a handful of points can agree with each other and with
/// the leave-one-out test and still be off where the posterior lies (a calibration with 4
/// successful expensive runs per data point ended 3 posterior stds off; with 8, exact).
pub fn min_high_fidelity_runs(dimension: usize) -> usize {
    2 * (dimension + 1)
}

/// A two-fidelity emulator of one output (module docs).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MultiFidelityGp {
    pub(crate) low: GaussianProcess,
    pub(crate) discrepancy: GaussianProcess,
    pub(crate) single: GaussianProcess,
    pub(crate) rho: f64,
    pub(crate) two_fidelity_loo_log_density: f64,
    pub(crate) single_fidelity_loo_log_density: f64,
    pub(crate) explained: f64,
    #[serde(default = "one")]
    pub(crate) discrepancy_variance_scale: f64,
    #[serde(default)]
    pub(crate) enough_high_runs: bool,
    /// Where δ is shared across data points ([`crate::shared_discrepancy`]): this point's
    /// abscissa, appended to θ as δ's last input, and the scale s_j its outputs were divided by
    /// for δ's fit.
    #[serde(default)]
    pub(crate) shared: Option<SharedPoint>,
}

/// A data point's place in a discrepancy shared across data points.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SharedPoint {
    /// The point's abscissa t_j, δ's last input.
    pub abscissa: f64,
    /// s_j: δ models (y_H − ρ·f_L)/s_j at this point.
    pub scale: f64,
    /// m_j = Σ_k exp(−½((t_j − t_k)/l_t)²) over the data points sharing δ (≥ 1): δ's variance
    /// at this point is taken m_j times, so that the data points' independent variances bound
    /// their correlated ones ([`crate::shared_discrepancy`]).
    #[serde(default = "one")]
    pub correlated_points: f64,
}

pub(crate) fn one() -> f64 {
    1.0
}

impl MultiFidelityGp {
    /// Fit on the low-fidelity runs (`low_x`, `low_y`) and the high-fidelity runs (`high_x`,
    /// `high_y`), nested or not, every GP with `options`.
    ///
    /// # Errors
    /// Fewer than 2 runs of a fidelity, points of different dimensions, non-finite values, or
    /// any error of [`GaussianProcess::fit`].
    pub fn fit(
        low_x: &[Vec<f64>],
        low_y: &[f64],
        high_x: &[Vec<f64>],
        high_y: &[f64],
        options: &CheckedFitOptions,
    ) -> Result<Self> {
        let d = low_x.first().map(Vec::len);
        validate_points(high_x, "high-fidelity point", d)?;
        if high_x.len() != high_y.len() {
            return Err(GpError::LengthMismatch {
                what: "high-fidelity outputs vs. points",
                expected: high_x.len(),
                actual: high_y.len(),
            });
        }
        let low = GaussianProcess::fit(low_x, low_y, options)?;
        let at_high = low.predict_mean(high_x)?;
        let single = GaussianProcess::fit(high_x, high_y, options)?;
        let discrepancy_at = |rho: f64| -> Result<(f64, GaussianProcess)> {
            let residuals: Vec<f64> = high_y
                .iter()
                .zip(&at_high)
                .map(|(y, l)| y - rho * l)
                .collect();
            let gp = GaussianProcess::fit(high_x, &residuals, options)?;
            Ok((loo_log_density(gp.leave_one_out()), gp))
        };
        let slope = least_squares_slope(&at_high, high_y);
        let (rho, (density, discrepancy)) = search_rho(slope, 0, &discrepancy_at)?;
        let residuals: Vec<f64> = high_y
            .iter()
            .zip(&at_high)
            .map(|(y, l)| y - rho * l)
            .collect();
        let total = variance(high_y);
        let explained = if total > 0.0 {
            1.0 - variance(&residuals) / total
        } else {
            0.0
        };
        let discrepancy_variance_scale = variance_scale(discrepancy.leave_one_out());
        Ok(Self {
            shared: None,
            enough_high_runs: high_x.len() >= min_high_fidelity_runs(d.unwrap_or(0)),
            discrepancy_variance_scale,
            explained,
            two_fidelity_loo_log_density: density,
            single_fidelity_loo_log_density: loo_log_density(single.leave_one_out()),
            low,
            discrepancy,
            single,
            rho,
        })
    }

    /// ρ, the scale of the low fidelity in the high one.
    pub fn rho(&self) -> f64 {
        self.rho
    }

    /// Whether the emulator predicts with both fidelities: their leave-one-out log predictive
    /// density over the high-fidelity runs is above the single-fidelity GP's by more than
    /// [`RHO_PRICE`].
    pub fn uses_low_fidelity(&self) -> bool {
        self.enough_high_runs
            && self.explained >= MIN_EXPLAINED
            && self.two_fidelity_loo_log_density > self.single_fidelity_loo_log_density + RHO_PRICE
    }

    /// c ≥ 1, the factor on δ's latent variance: the mean squared standardised leave-one-out
    /// residual of δ at the high-fidelity runs, where above 1 (`variance_scale`).
    pub fn discrepancy_variance_scale(&self) -> f64 {
        self.discrepancy_variance_scale
    }

    /// 1 − var(y_H − ρ·l(x_H))/var(y_H): the share of the high-fidelity runs' variance the
    /// scaled low fidelity explains ([`MIN_EXPLAINED`]).
    pub fn explained_share(&self) -> f64 {
        self.explained
    }

    /// The leave-one-out log predictive densities of the high-fidelity runs, (two fidelities,
    /// high fidelity alone).
    pub fn loo_log_densities(&self) -> (f64, f64) {
        (
            self.two_fidelity_loo_log_density,
            self.single_fidelity_loo_log_density,
        )
    }

    /// The GP of the low fidelity.
    pub fn low_fidelity(&self) -> &GaussianProcess {
        &self.low
    }

    /// The GP δ of the discrepancy y_H − ρ·f_L (where shared across data points, of
    /// (y_H − ρ·f_L)/s_j on (θ, t_j): [`Self::shared_point`]).
    pub fn discrepancy(&self) -> &GaussianProcess {
        &self.discrepancy
    }

    /// Where δ is shared across data points, this point's abscissa and scale.
    pub fn shared_point(&self) -> Option<SharedPoint> {
        self.shared
    }

    /// The std of δ's training outputs in this output's units (its fit's output scaling,
    /// times s_j where shared).
    pub fn discrepancy_std(&self) -> f64 {
        self.discrepancy.output_scaling().std * self.delta_scale()
    }

    /// s_j where δ is shared, else 1.
    fn delta_scale(&self) -> f64 {
        self.shared.map_or(1.0, |p| p.scale)
    }

    /// The factor on δ's latent variance: s_j²·m_j where δ is shared, else 1.
    fn delta_variance_factor(&self) -> f64 {
        self.shared
            .map_or(1.0, |p| p.scale * p.scale * p.correlated_points)
    }

    /// δ's inputs for `points`: θ, with the abscissa appended where δ is shared.
    fn delta_inputs<'a>(&self, points: &'a [Vec<f64>]) -> std::borrow::Cow<'a, [Vec<f64>]> {
        match self.shared {
            None => std::borrow::Cow::Borrowed(points),
            Some(p) => std::borrow::Cow::Owned(
                points
                    .iter()
                    .map(|x| x.iter().copied().chain([p.abscissa]).collect())
                    .collect(),
            ),
        }
    }

    /// A new high-fidelity run's noise variance with `prediction` from [`Self::predict`] (whose
    /// noise variance is already in output units): plus the jitter of the GP in charge.
    pub fn run_noise_variance(&self, prediction: &Prediction) -> f64 {
        let gp = self.in_charge();
        let s = gp.output_scaling().std
            * if self.uses_low_fidelity() {
                self.delta_scale()
            } else {
                1.0
            };
        prediction.noise_variance + gp.jitter() * s * s
    }

    /// The GP of the high-fidelity runs alone.
    pub fn single_fidelity(&self) -> &GaussianProcess {
        &self.single
    }

    /// The high fidelity's posterior mean and variances at `points`: ρ·μ_L + μ_δ and
    /// ρ²·σ²_L + σ²_δ where the two fidelities are used, else the single-fidelity GP's.
    ///
    /// # Errors
    /// A point of the wrong dimension or with a non-finite coordinate.
    pub fn predict(&self, points: &[Vec<f64>]) -> Result<Prediction> {
        if !self.uses_low_fidelity() {
            return self.single.predict(points);
        }
        let low = self.low.predict(points)?;
        let s = self.delta_scale();
        let mut delta = self.discrepancy.predict(&self.delta_inputs(points))?;
        let factor = self.delta_variance_factor();
        delta.mean.iter_mut().for_each(|m| *m *= s);
        delta.variance.iter_mut().for_each(|v| *v *= factor);
        delta.noise_variance *= s * s;
        let rho2 = self.rho * self.rho;
        let c = self.discrepancy_variance_scale;
        Ok(Prediction {
            mean: low
                .mean
                .iter()
                .zip(&delta.mean)
                .map(|(l, e)| self.rho * l + e)
                .collect(),
            variance: low
                .variance
                .iter()
                .zip(&delta.variance)
                .map(|(l, e)| rho2 * l + c * e)
                .collect(),
            noise_variance: delta.noise_variance,
        })
    }
}

impl MultiFidelityGp {
    /// The predictive mean alone at `points`: ρ·μ_L + μ_δ where the two fidelities are used,
    /// else the single-fidelity GP's (as [`MultiFidelityGp::predict`]'s mean, without the
    /// variances).
    ///
    /// # Errors
    /// A point of the wrong dimension or with a non-finite coordinate.
    pub fn predict_mean(&self, points: &[Vec<f64>]) -> Result<Vec<f64>> {
        if !self.uses_low_fidelity() {
            return self.single.predict_mean(points);
        }
        let low = self.low.predict_mean(points)?;
        let delta = self.discrepancy.predict_mean(&self.delta_inputs(points))?;
        let s = self.delta_scale();
        Ok(low
            .iter()
            .zip(&delta)
            .map(|(l, e)| self.rho * l + s * e)
            .collect())
    }

    /// The two parts of the latent variance at `points`: (ρ²·σ²_L, what a low-fidelity run
    /// there would remove; σ²_δ, what only a high-fidelity run removes). Where the emulator
    /// uses the high-fidelity runs alone, the first part is 0 and the second their GP's
    /// variance. The adaptive engine weighs them against the fidelities' costs.
    ///
    /// # Errors
    /// A point of the wrong dimension or with a non-finite coordinate.
    pub fn fidelity_variances(&self, points: &[Vec<f64>]) -> Result<(Vec<f64>, Vec<f64>)> {
        if !self.uses_low_fidelity() {
            return Ok((
                vec![0.0; points.len()],
                self.single.predict(points)?.variance,
            ));
        }
        let rho2 = self.rho * self.rho;
        let low = self.low.predict(points)?.variance;
        let c = self.discrepancy_variance_scale * self.delta_variance_factor();
        Ok((
            low.into_iter().map(|v| rho2 * v).collect(),
            self.discrepancy
                .predict(&self.delta_inputs(points))?
                .variance
                .into_iter()
                .map(|v| c * v)
                .collect(),
        ))
    }
}

impl MultiFidelityGp {
    /// ρ²·cov_L(a, b) + c·cov_δ(a, b) (f_L and δ independent), or the single-fidelity GP's:
    /// the latent posterior covariance between the points `a` and `b`.
    ///
    /// # Errors
    /// A point of the wrong dimension or with a non-finite coordinate.
    pub fn posterior_covariance(&self, a: &[Vec<f64>], b: &[Vec<f64>]) -> Result<Vec<Vec<f64>>> {
        if !self.uses_low_fidelity() {
            return self.single.posterior_covariance(a, b);
        }
        let rho2 = self.rho * self.rho;
        let scale = self.discrepancy_variance_scale * self.delta_variance_factor();
        let mut covariance = self
            .discrepancy
            .posterior_covariance(&self.delta_inputs(a), &self.delta_inputs(b))?;
        for (row, low) in covariance
            .iter_mut()
            .zip(self.low.posterior_covariance(a, b)?)
        {
            for (c, l) in row.iter_mut().zip(low) {
                *c = scale * *c + rho2 * l;
            }
        }
        Ok(covariance)
    }

    /// The GP fitted to the high-fidelity runs that is in charge of their noise: δ where both
    /// fidelities are used, else the single-fidelity GP. A new high-fidelity run carries its
    /// noise.
    pub fn in_charge(&self) -> &GaussianProcess {
        if self.uses_low_fidelity() {
            &self.discrepancy
        } else {
            &self.single
        }
    }
}

/// ρ's grid search: k·`slope`/4 for k = `first`…8, then steps of `slope`/32 within ±4 of the
/// best; the ρ with the highest `score` (δ's leave-one-out density, and δ).
pub(crate) fn search_rho(
    slope: f64,
    first: i32,
    score: &dyn Fn(f64) -> Result<(f64, GaussianProcess)>,
) -> Result<(f64, (f64, GaussianProcess))> {
    let coarse: Vec<f64> = (first..=8).map(|k| slope * k as f64 / 4.0).collect();
    let (rho, (density, discrepancy)) = best_of(&coarse, score)?;
    let fine: Vec<f64> = (-4..=4)
        .filter(|&k| k != 0)
        .map(|k| rho + slope * k as f64 / 32.0)
        .collect();
    let (rho_fine, (density_fine, discrepancy_fine)) = best_of(&fine, score)?;
    Ok(if density_fine > density {
        (rho_fine, (density_fine, discrepancy_fine))
    } else {
        (rho, (density, discrepancy))
    })
}

/// The value of `values` whose `score` (a density, and the GP that gave it) is highest; the
/// first on ties.
fn best_of(
    values: &[f64],
    score: &dyn Fn(f64) -> Result<(f64, GaussianProcess)>,
) -> Result<(f64, (f64, GaussianProcess))> {
    let mut best: Option<(f64, (f64, GaussianProcess))> = None;
    for &v in values {
        let scored = score(v)?;
        if best.as_ref().is_none_or(|(_, (d, _))| scored.0 > *d) {
            best = Some((v, scored));
        }
    }
    best.ok_or(GpError::InvalidParameter {
        what: "ρ grid",
        reason: "no value to try".into(),
    })
}

/// The sample variance (divisor n) of `values`.
pub(crate) fn variance(values: &[f64]) -> f64 {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    values.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n
}

/// The least-squares slope of `y` on `x` with an intercept (0 when `x` is constant).
pub(crate) fn least_squares_slope(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = x.iter().map(|a| (a - mx) * (a - mx)).sum();
    if sxx > 0.0 { sxy / sxx } else { 0.0 }
}

/// max(1, mean_i r_i²/v_i) over δ's leave-one-out residuals r_i and predictive variances v_i:
/// a GP fitted on the few high-fidelity runs tends to be overconfident (its hyperparameters
/// fitted to the same points), and its standardised leave-one-out residuals say by how much; the
/// cross-validation estimate of the variance's scale (Bachoc 2013, "Cross validation and
/// maximum likelihood estimations of hyper-parameters of Gaussian processes with model
/// misspecification"). Never below 1: a GP that looks too cautious keeps its variance.
pub(crate) fn variance_scale(loo: &LeaveOneOut) -> f64 {
    let n = loo.residuals.len();
    if n == 0 {
        return 1.0;
    }
    let mean = loo
        .residuals
        .iter()
        .zip(&loo.variances)
        .map(|(r, v)| r * r / v)
        .sum::<f64>()
        / n as f64;
    if mean.is_finite() { mean.max(1.0) } else { 1.0 }
}

/// Σ_i −½[ln 2πv_i + r_i²/v_i] over the leave-one-out residuals and variances.
pub(crate) fn loo_log_density(loo: &LeaveOneOut) -> f64 {
    loo.residuals
        .iter()
        .zip(&loo.variances)
        .map(|(r, v)| -0.5 * ((2.0 * std::f64::consts::PI * v).ln() + r * r / v))
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::FitOptions;

    fn grid(n: usize, lo: f64, hi: f64) -> Vec<Vec<f64>> {
        (0..n)
            .map(|i| vec![lo + (hi - lo) * i as f64 / (n - 1) as f64])
            .collect()
    }

    fn high(x: &[f64]) -> f64 {
        2.0 * (6.0 * x[0]).sin() + 0.3 * x[0]
    }

    /// A test-set Q2 of predictions `mean` of `truth` at `points`.
    fn q2_of(mean: &[f64], points: &[Vec<f64>]) -> f64 {
        let truth: Vec<f64> = points.iter().map(|p| high(p)).collect();
        crate::validation::q2(&truth, mean).unwrap()
    }

    /// With a low fidelity that carries the high one's shape (two periods of a sine), 8 high
    /// runs and 30 low ones predict the high fidelity far better than the 8 high runs alone on
    /// a test grid of 101 points (a tenth of their residual variance or less), and ρ is found
    /// (2 within 10 %).
    #[test]
    fn a_correlated_low_fidelity_beats_the_high_runs_alone() {
        let low_x = grid(30, 0.0, 2.0);
        let low_y: Vec<f64> = low_x.iter().map(|p| (6.0 * p[0]).sin()).collect();
        let high_x = grid(8, 0.1, 1.9);
        let high_y: Vec<f64> = high_x.iter().map(|p| high(p)).collect();
        let options = FitOptions::default().check().unwrap();
        let gp = MultiFidelityGp::fit(&low_x, &low_y, &high_x, &high_y, &options).unwrap();
        assert!(gp.uses_low_fidelity(), "{:?}", gp.loo_log_densities());
        assert!((gp.rho() - 2.0).abs() < 0.2, "ρ = {}", gp.rho());
        let test = grid(101, 0.0, 2.0);
        let two = q2_of(&gp.predict(&test).unwrap().mean, &test);
        let one = q2_of(&gp.single_fidelity().predict_mean(&test).unwrap(), &test);
        assert!(
            two > 0.99 && 1.0 - two < 0.1 * (1.0 - one),
            "Q2 two fidelities {two}, high alone {one}"
        );
    }

    /// A low fidelity unrelated to the high one (a fast oscillation): the emulator keeps the
    /// single-fidelity GP, so its predictions are exactly those of the high runs alone.
    #[test]
    fn an_uncorrelated_low_fidelity_leaves_the_high_runs_in_charge() {
        let low_x = grid(30, 0.0, 2.0);
        let low_y: Vec<f64> = low_x.iter().map(|p| (23.0 * p[0]).cos()).collect();
        let high_x = grid(8, 0.0, 2.0);
        let high_y: Vec<f64> = high_x.iter().map(|p| high(p)).collect();
        let options = FitOptions::default().check().unwrap();
        let gp = MultiFidelityGp::fit(&low_x, &low_y, &high_x, &high_y, &options).unwrap();
        assert!(!gp.uses_low_fidelity(), "{:?}", gp.loo_log_densities());
        let test = grid(41, 0.0, 2.0);
        assert_eq!(
            gp.predict(&test).unwrap(),
            gp.single_fidelity().predict(&test).unwrap()
        );
    }

    /// The same correlated pair as above with 3 high runs, fewer than 2·(d + 1) = 4: the low
    /// fidelity is not used, however well ρ fits them; with 4 it is. The discrepancy's variance
    /// scale is never below 1, and equals δ's mean squared standardised leave-one-out residual.
    #[test]
    fn too_few_high_runs_leave_the_high_runs_in_charge() {
        let low_x = grid(30, 0.0, 2.0);
        let low_y: Vec<f64> = low_x.iter().map(|p| (6.0 * p[0]).sin()).collect();
        let options = FitOptions::default().check().unwrap();
        assert_eq!(min_high_fidelity_runs(1), 4);
        for (n, used) in [(3, false), (4, true)] {
            let high_x = grid(n, 0.1, 1.9);
            let high_y: Vec<f64> = high_x.iter().map(|p| 2.0 * (6.0 * p[0]).sin()).collect();
            let gp = MultiFidelityGp::fit(&low_x, &low_y, &high_x, &high_y, &options).unwrap();
            assert_eq!(gp.uses_low_fidelity(), used, "{n} high runs");
            let loo = gp.discrepancy.leave_one_out();
            let mean = loo
                .residuals
                .iter()
                .zip(&loo.variances)
                .map(|(r, v)| r * r / v)
                .sum::<f64>()
                / n as f64;
            assert_eq!(gp.discrepancy_variance_scale(), mean.max(1.0));
        }
    }

    #[test]
    fn bad_input_is_an_error() {
        let low_x = grid(10, 0.0, 1.0);
        let low_y: Vec<f64> = low_x.iter().map(|p| p[0]).collect();
        let options = FitOptions::default().check().unwrap();
        let two_d = vec![vec![0.1, 0.2], vec![0.3, 0.4]];
        assert!(MultiFidelityGp::fit(&low_x, &low_y, &two_d, &[1.0, 2.0], &options).is_err());
        assert!(MultiFidelityGp::fit(&low_x, &low_y, &low_x[..3], &[1.0], &options).is_err());
    }
}
