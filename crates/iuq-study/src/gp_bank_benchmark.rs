//! The benchmark problem of `iuq bench basis-gp-bank` (and of its Python reference,
//! scripts/bench/basis_gp_bank.py): BASIS on a four-parameter posterior whose model is a bank of
//! eight GPs, the size of the red-cell study's surrogate, with synthetic data so that it needs no
//! cell-model runs.
//!
//! The GPs learn a smooth stand-in for the elongation curve ([`synthetic_elongation_index`]) on
//! a maximin Latin hypercube over the red-cell study's prior box ([`RBC_PRIOR`]); the data are
//! that curve at [`RBC_TRUTH`] plus Gaussian measurement errors of std [`MEASUREMENT_STD`]
//! drawn from a keyed stream, so that the problem is the same on every machine for a seed.

use iuq_basis::{ComputationalError, DEFAULT_MODELLING_ERROR_PRIOR, ErrorModel, Observations};
use iuq_core::{Model, Parameter, ParameterSpace, Prior};
use iuq_gp::{FitOptions, GpBank};

use crate::error::{Result, input_error};

/// Shear stresses (Pa) of the synthetic elongation curve: one GP each.
pub const SHEAR_STRESSES: [f64; 8] = [0.3, 0.6, 1.2, 2.4, 4.8, 9.6, 19.2, 38.4];

/// The prior box: kLink U(10, 300), kBend U(50, 400), viscosityRatio U(1, 15), as in the
/// red-cell studies.
pub const RBC_PRIOR: [(&str, f64, f64); 3] = [
    ("kLink", 10.0, 300.0),
    ("kBend", 50.0, 400.0),
    ("viscosityRatio", 1.0, 15.0),
];

/// The parameters the synthetic data are generated at.
pub const RBC_TRUTH: [f64; 3] = [120.0, 180.0, 6.0];

/// Measurement std of every synthetic datum.
pub const MEASUREMENT_STD: f64 = 0.008;

/// A smooth stand-in for the elongation index EI(τ) of a red blood cell at shear stress `tau`
/// (a saturating Hill-type curve, as fitted to ektacytometry data) whose plateau, half-saturation
/// stress and steepness depend on (kLink, kBend, viscosityRatio). Not a physical model: it only
/// gives the benchmark's GPs curves of the right shape and smoothness.
pub fn synthetic_elongation_index(theta: &[f64], tau: f64) -> f64 {
    let (g, b, v) = (theta[0] / 100.0, theta[1] / 100.0, theta[2]);
    let plateau = 0.64 - 0.008 * (v - 1.0) - 0.015 * b;
    let half = 0.35 * g.powf(0.75) * (1.0 + 0.12 * b) * (1.0 + 0.05 * (v - 1.0));
    let steepness = 0.9 + 0.025 * (v - 1.0) + 0.04 * g.ln();
    let t = (tau / half).powf(steepness);
    plateau * t / (1.0 + t)
}

/// A standard normal deviate keyed by (seed, index) (inverse CDF of a SplitMix64 uniform).
fn keyed_normal(seed: u64, index: u64) -> f64 {
    let h = iuq_core::random::splitmix64(iuq_core::random::splitmix64(seed ^ 0x6461_7461) ^ index);
    let u = ((h >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
    iuq_core::normal::quantile(u)
}

/// The names of the GP bank's inputs (the parameters) and outputs (`EI_<τ>Pa`).
pub fn bank_names() -> (Vec<String>, Vec<String>) {
    (
        RBC_PRIOR.iter().map(|p| p.0.to_string()).collect(),
        SHEAR_STRESSES.iter().map(|t| format!("EI_{t}Pa")).collect(),
    )
}

/// The benchmark problem, ready for BASIS.
#[derive(Debug, Clone)]
pub struct GpBankBenchmark {
    /// The surrogate: one GP per shear stress.
    pub bank: GpBank,
    /// Seconds the GPs took to fit (`None` for a bank given to [`GpBankBenchmark::new`]).
    pub fit_seconds: Option<f64>,
    /// The synthetic data with their measurement stds.
    pub observations: Observations,
    /// The error model: measurement error, the given computational-error convention and the
    /// modelling error σ_m with its default prior.
    pub errors: ErrorModel,
    /// The model parameters with their priors.
    pub model_space: ParameterSpace,
}

impl GpBankBenchmark {
    /// The problem for `data_seed`: the GPs fitted on `training` maximin-LHS runs of the
    /// synthetic curve (fit seed `data_seed`), or `bank` when given (it must have the
    /// benchmark's inputs and outputs), and the data.
    ///
    /// # Errors
    /// Fewer than 2 training runs, a bank of another problem, or a failed fit.
    pub fn new(
        training: usize,
        data_seed: u64,
        computational_error: ComputationalError,
        bank: Option<GpBank>,
    ) -> Result<Self> {
        let (input_names, output_names) = bank_names();
        let (bank, fit_seconds) = match bank {
            Some(bank) => {
                if bank.input_names() != input_names.as_slice()
                    || bank.output_names() != output_names.as_slice()
                {
                    return Err(input_error(format!(
                        "not a bank of this benchmark (inputs {:?}, outputs {:?})",
                        bank.input_names(),
                        bank.output_names()
                    )));
                }
                (bank, None)
            }
            None => {
                if training < 2 {
                    return Err(input_error(format!(
                        "{training} training runs: at least 2 are needed"
                    )));
                }
                let bounds: Vec<(f64, f64)> = RBC_PRIOR.iter().map(|p| (p.1, p.2)).collect();
                let unit = iuq_doe::latin_hypercube(
                    training,
                    RBC_PRIOR.len(),
                    iuq_doe::LhsMethod::maximin(),
                    data_seed,
                )?;
                let x = iuq_doe::scale_to_bounds(&unit, &bounds)?;
                let outputs: Vec<Vec<f64>> = SHEAR_STRESSES
                    .iter()
                    .map(|&tau| {
                        x.iter()
                            .map(|p| synthetic_elongation_index(p, tau))
                            .collect()
                    })
                    .collect();
                let options = FitOptions {
                    seed: data_seed,
                    ..FitOptions::default()
                };
                let start = std::time::Instant::now();
                let bank = GpBank::fit(input_names, output_names, &x, &outputs, &options.check()?)?;
                (bank, Some(start.elapsed().as_secs_f64()))
            }
        };
        let values: Vec<f64> = SHEAR_STRESSES
            .iter()
            .enumerate()
            .map(|(j, &tau)| {
                synthetic_elongation_index(&RBC_TRUTH, tau)
                    + MEASUREMENT_STD * keyed_normal(data_seed, j as u64)
            })
            .collect();
        let measurement_std = vec![MEASUREMENT_STD; values.len()];
        let model_space = ParameterSpace::new(
            RBC_PRIOR
                .iter()
                .map(|p| Parameter {
                    name: p.0.to_string(),
                    prior: Prior::Uniform(p.1, p.2),
                })
                .collect(),
        )?;
        Ok(Self {
            bank,
            fit_seconds,
            observations: Observations {
                values,
                measurement_std: Some(measurement_std),
            },
            errors: ErrorModel {
                measurement_error: true,
                computational_error,
                modelling_error: Some(DEFAULT_MODELLING_ERROR_PRIOR),
            },
            model_space,
        })
    }

    /// Five points of the prior box (a Kronecker sequence) at which a reference implementation
    /// checks that it predicts as this bank does.
    pub fn check_points() -> Vec<Vec<f64>> {
        const STEPS: [f64; 3] = [0.7548776662, 0.5698402910, 0.4301597090];
        (0..5)
            .map(|i| {
                RBC_PRIOR
                    .iter()
                    .zip(STEPS)
                    .map(|((_, lo, hi), step)| {
                        let u = (0.5 + (i + 1) as f64 * step).rem_euclid(1.0);
                        lo + u * (hi - lo)
                    })
                    .collect()
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_curve_saturates_and_the_data_lie_near_it() {
        let curve: Vec<f64> = SHEAR_STRESSES
            .iter()
            .map(|&t| synthetic_elongation_index(&RBC_TRUTH, t))
            .collect();
        assert!(curve.windows(2).all(|w| w[0] < w[1]), "{curve:?}");
        assert!(curve[7] < 0.64);
        let problem = GpBankBenchmark::new(12, 3, ComputationalError::Relative, None).unwrap();
        // Eight data within 4 measurement stds of the curve (the chance of one beyond: 5e-4).
        for (y, c) in problem.observations.values.iter().zip(&curve) {
            assert!((y - c).abs() < 4.0 * MEASUREMENT_STD, "{y} vs {c}");
        }
        // The same seed, the same data; a bank of another problem is refused.
        let again = GpBankBenchmark::new(2, 3, ComputationalError::Relative, None).unwrap();
        assert_eq!(again.observations, problem.observations);
        let mut other = problem.bank.clone();
        other = GpBank::from_json_str(
            &other
                .to_json_string()
                .unwrap()
                .replace("EI_0.3Pa", "EI_0.4Pa"),
        )
        .unwrap();
        assert!(GpBankBenchmark::new(2, 3, ComputationalError::Relative, Some(other)).is_err());
        assert!(GpBankBenchmark::new(1, 3, ComputationalError::Relative, None).is_err());
    }
}
