//! Sobol' analysis of a model: build the Saltelli design on the prior, evaluate it as one batch,
//! estimate indices for every output, attach confidence intervals, and account for failed runs.
//!
//! Failed runs: a failure at any of the d + 2 rows of base point j removes the whole group j
//! (its f_A, f_B and every f_ABi) before estimation, for every output, so that each estimator
//! still averages matched rows. The number of dropped groups and the failure reasons are
//! reported; they are never silently absorbed.

use std::collections::BTreeMap;

use iuq_core::{Model, ParameterSpace};
use iuq_doe::{SaltelliDesign, Scrambling};

use crate::confidence::{ConfidenceHalfWidths, bootstrap_half_widths, combine_replicates};
use crate::error::{Result, SensitivityError};
use crate::estimator::{SaltelliValues, SobolEstimate, estimate_indices};

/// How confidence intervals are obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IntervalMethod {
    /// One scrambled design; bootstrap of its base points (SALib's method).
    Bootstrap {
        /// Number of bootstrap resamples (SALib's default is 100).
        resamples: usize,
    },
    /// `count` independently scrambled designs of N base points each (count·N·(d+2) runs).
    Replicates {
        /// Number of independent scramblings (≥ 2).
        count: usize,
    },
}

/// Options of a Sobol' analysis.
#[derive(Debug, Clone, PartialEq)]
pub struct SensitivityOptions {
    /// Base points N per design (a power of two keeps the Sobol' balance properties).
    pub base_points: usize,
    /// Seed of the scrambling and of the bootstrap.
    pub seed: u64,
    /// Confidence-interval method.
    pub interval: IntervalMethod,
    /// Confidence level of the intervals, e.g. 0.95.
    pub confidence_level: f64,
    /// Minimum fraction of base points that must survive failures (default 0.5).
    pub min_usable_fraction: f64,
}

impl Default for SensitivityOptions {
    fn default() -> Self {
        Self {
            base_points: 1024,
            seed: 0,
            interval: IntervalMethod::Bootstrap { resamples: 100 },
            confidence_level: 0.95,
            min_usable_fraction: 0.5,
        }
    }
}

/// The most bootstrap resamples (defined with the bootstrap).
pub use crate::confidence::MAX_RESAMPLES;

/// The most independent scramblings for replicate intervals (each a whole Saltelli design).
pub const MAX_REPLICATES: usize = 1 << 16;

impl SensitivityOptions {
    /// Checks the base points (at least 2), the interval method (2 to [`MAX_REPLICATES`]
    /// replicates, or 1 to [`MAX_RESAMPLES`] bootstrap resamples), the confidence level (in (0, 1)) and the usable fraction (in
    /// [0, 1]), and returns the options as the value [`analyse`] takes.
    ///
    /// # Errors
    /// The first invalid option, named.
    pub fn check(self) -> Result<CheckedSensitivityOptions> {
        if self.base_points < 2 {
            return Err(SensitivityError::InvalidOption(format!(
                "at least 2 base points are needed, got {}",
                self.base_points
            )));
        }
        match self.interval {
            IntervalMethod::Replicates { count } if count < 2 => {
                return Err(SensitivityError::InvalidOption(format!(
                    "at least 2 replicates are needed, got {count}"
                )));
            }
            IntervalMethod::Replicates { count } if count > MAX_REPLICATES => {
                return Err(SensitivityError::InvalidOption(format!(
                    "at most {MAX_REPLICATES} replicates, got {count}"
                )));
            }
            IntervalMethod::Bootstrap { resamples: 0 } => {
                return Err(SensitivityError::InvalidOption(
                    "at least 1 bootstrap resample is needed".into(),
                ));
            }
            IntervalMethod::Bootstrap { resamples } if resamples > MAX_RESAMPLES => {
                return Err(SensitivityError::InvalidOption(format!(
                    "at most {MAX_RESAMPLES} bootstrap resamples, got {resamples}"
                )));
            }
            _ => {}
        }
        if !(self.confidence_level > 0.0 && self.confidence_level < 1.0) {
            return Err(SensitivityError::InvalidOption(format!(
                "the confidence level must lie in (0, 1), got {}",
                self.confidence_level
            )));
        }
        if !(0.0..=1.0).contains(&self.min_usable_fraction) {
            return Err(SensitivityError::InvalidOption(format!(
                "the minimum usable fraction must lie in [0, 1], got {}",
                self.min_usable_fraction
            )));
        }
        Ok(CheckedSensitivityOptions(self))
    }
}

/// Options that passed [`SensitivityOptions::check`]; read them through `Deref`.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckedSensitivityOptions(SensitivityOptions);

impl CheckedSensitivityOptions {
    /// The options as plain data.
    pub fn options(&self) -> &SensitivityOptions {
        &self.0
    }
}

impl std::ops::Deref for CheckedSensitivityOptions {
    type Target = SensitivityOptions;
    fn deref(&self) -> &SensitivityOptions {
        &self.0
    }
}

/// First-order and total indices of one output, with confidence half-widths.
#[derive(Debug, Clone, PartialEq)]
pub struct OutputIndices {
    /// Name of the output.
    pub output: String,
    /// S_i per input.
    pub first_order: Vec<f64>,
    /// S_Ti per input.
    pub total: Vec<f64>,
    /// Confidence half-width of each S_i.
    pub first_order_conf: Vec<f64>,
    /// Confidence half-width of each S_Ti.
    pub total_conf: Vec<f64>,
    /// The output variance V.
    pub variance: f64,
}

/// The result of a Sobol' analysis.
#[derive(Debug, Clone, PartialEq)]
pub struct SensitivityReport {
    /// Input names, the order of every index vector.
    pub inputs: Vec<String>,
    /// Indices per output.
    pub outputs: Vec<OutputIndices>,
    /// Model evaluations requested.
    pub evaluations: usize,
    /// Evaluations that failed.
    pub failed_evaluations: usize,
    /// Base-point groups (over all replicates) dropped because one of their runs failed.
    pub dropped_groups: usize,
    /// Base-point groups in total.
    pub total_groups: usize,
    /// Failure reasons and how often each occurred.
    pub failure_reasons: BTreeMap<String, usize>,
}

impl SensitivityReport {
    /// How failed runs were handled, in words, for reports.
    pub fn failure_handling(&self) -> String {
        if self.failed_evaluations == 0 {
            "no run failed".to_string()
        } else {
            format!(
                "{} of {} runs failed; each failure removed its whole group of d + 2 rows: {} of {} base points dropped",
                self.failed_evaluations, self.evaluations, self.dropped_groups, self.total_groups
            )
        }
    }
}

/// Run a Sobol' analysis of `model` with inputs distributed as `space`'s priors.
///
/// The design is scrambled (a randomised quasi-Monte Carlo estimate); unit-cube points are mapped
/// through each prior's quantile function.
pub fn analyse(
    model: &dyn Model,
    space: &ParameterSpace,
    options: &CheckedSensitivityOptions,
) -> Result<SensitivityReport> {
    let d = space.dimension();
    if model.input_dimension() != d {
        return Err(SensitivityError::InvalidOption(format!(
            "the model takes {} inputs but the parameter space has {d}",
            model.input_dimension()
        )));
    }
    let designs = match options.interval {
        IntervalMethod::Bootstrap { .. } => 1,
        IntervalMethod::Replicates { count } => count,
    };
    let mut rows = Vec::new();
    let mut saltelli = Vec::with_capacity(designs);
    for replicate in 0..designs {
        let design = SaltelliDesign::new(
            options.base_points,
            d,
            Scrambling::LinearMatrixWithShift {
                seed: options.seed,
                replicate: replicate as u64,
            },
        )?;
        for unit in design.rows() {
            rows.push(space.from_unit_cube(&unit)?);
        }
        saltelli.push(design);
    }
    let outcomes = model.evaluate_batch(&rows)?;
    if outcomes.len() != rows.len() {
        return Err(SensitivityError::InvalidInput(format!(
            "the model returned {} outcomes for {} points",
            outcomes.len(),
            rows.len()
        )));
    }
    let mut failure_reasons = BTreeMap::new();
    let mut failed_evaluations = 0;
    for outcome in &outcomes {
        if let Err(failure) = outcome {
            failed_evaluations += 1;
            *failure_reasons.entry(failure.reason.clone()).or_insert(0) += 1;
        }
    }
    let group = d + 2;
    let per_design = options.base_points * group;
    let output_names = model.output_names().to_vec();
    let mut dropped_groups = 0;
    // values[design][output]
    let mut values: Vec<Vec<SaltelliValues>> = Vec::with_capacity(designs);
    for (k, design) in saltelli.iter().enumerate() {
        let slice = &outcomes[k * per_design..(k + 1) * per_design];
        let keep: Vec<usize> = (0..options.base_points)
            .filter(|&j| slice[j * group..(j + 1) * group].iter().all(|o| o.is_ok()))
            .collect();
        dropped_groups += options.base_points - keep.len();
        let usable = keep.len();
        if (usable as f64) < options.min_usable_fraction * options.base_points as f64 || usable < 2
        {
            return Err(SensitivityError::TooManyFailures {
                output: output_names.join(", "),
                usable,
                total: options.base_points,
            });
        }
        let per_output = (0..output_names.len())
            .map(|o| {
                let scalar: Vec<f64> = slice
                    .iter()
                    .map(|r| {
                        r.as_ref()
                            .map_or(f64::NAN, |e| e.outputs.get(o).copied().unwrap_or(f64::NAN))
                    })
                    .collect();
                let split = design.split_outputs(&scalar)?;
                Ok(SaltelliValues {
                    f_a: split.f_a,
                    f_b: split.f_b,
                    f_ab: split.f_ab,
                }
                .select(&keep))
            })
            .collect::<Result<Vec<_>>>()?;
        values.push(per_output);
    }
    let mut outputs = Vec::with_capacity(output_names.len());
    for (o, name) in output_names.iter().enumerate() {
        let (estimate, half): (SobolEstimate, ConfidenceHalfWidths) = match options.interval {
            IntervalMethod::Bootstrap { resamples } => {
                let v = &values[0][o];
                let estimate = estimate_indices(v, name)?;
                let half = bootstrap_half_widths(
                    v,
                    &estimate,
                    resamples,
                    options.confidence_level,
                    options.seed,
                    o as u64,
                )?;
                (estimate, half)
            }
            IntervalMethod::Replicates { .. } => {
                let estimates = values
                    .iter()
                    .map(|per_output| estimate_indices(&per_output[o], name))
                    .collect::<Result<Vec<_>>>()?;
                combine_replicates(&estimates, options.confidence_level)?
            }
        };
        outputs.push(OutputIndices {
            output: name.clone(),
            first_order: estimate.first_order,
            total: estimate.total,
            first_order_conf: half.first_order,
            total_conf: half.total,
            variance: estimate.variance,
        });
    }
    Ok(SensitivityReport {
        inputs: space.names(),
        outputs,
        evaluations: rows.len(),
        failed_evaluations,
        dropped_groups,
        total_groups: designs * options.base_points,
        failure_reasons,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use iuq_core::{ExpressionModel, Parameter, Prior};
    use std::f64::consts::PI;

    const ISHIGAMI: &str = "sin(x1) + 7*sin(x2)^2 + 0.1*x3^4*sin(x1)";
    const S1: [f64; 3] = [0.313_905_191_147_811, 0.442_411_144_790_041, 0.0];
    const ST: [f64; 3] = [
        0.557_588_855_209_959,
        0.442_411_144_790_041,
        0.243_683_664_062_148,
    ];

    fn ishigami_space() -> ParameterSpace {
        ParameterSpace::new(
            ["x1", "x2", "x3"]
                .iter()
                .map(|n| Parameter {
                    name: n.to_string(),
                    prior: Prior::Uniform(-PI, PI),
                })
                .collect(),
        )
        .unwrap()
    }

    fn ishigami(formula: &str) -> ExpressionModel {
        ExpressionModel::new(
            vec!["x1".into(), "x2".into(), "x3".into()],
            &[("f".into(), formula.into())],
        )
        .unwrap()
    }

    #[test]
    fn ishigami_indices_at_n_2_pow_13_are_within_0_01() {
        let options = SensitivityOptions {
            base_points: 1 << 13,
            seed: 2024,
            ..Default::default()
        };
        let report = analyse(
            &ishigami(ISHIGAMI),
            &ishigami_space(),
            &options.check().unwrap(),
        )
        .unwrap();
        assert_eq!(report.evaluations, (1 << 13) * 5);
        assert_eq!(report.failed_evaluations, 0);
        let f = &report.outputs[0];
        for i in 0..3 {
            assert!(
                (f.first_order[i] - S1[i]).abs() < 0.01,
                "S1[{i}] = {}",
                f.first_order[i]
            );
            assert!(
                (f.total[i] - ST[i]).abs() < 0.01,
                "ST[{i}] = {}",
                f.total[i]
            );
            // the bootstrap half-width must cover the reference in this well-resolved case
            assert!(f.first_order_conf[i] > 0.0 && f.first_order_conf[i] < 0.05);
        }
    }

    #[test]
    fn replicate_intervals_cover_the_reference() {
        let options = SensitivityOptions {
            base_points: 1 << 11,
            seed: 7,
            interval: IntervalMethod::Replicates { count: 8 },
            ..Default::default()
        };
        let report = analyse(
            &ishigami(ISHIGAMI),
            &ishigami_space(),
            &options.check().unwrap(),
        )
        .unwrap();
        assert_eq!(report.evaluations, 8 * (1 << 11) * 5);
        let f = &report.outputs[0];
        for i in 0..3 {
            // 3 half-widths: a 95 % interval misses with probability 5 %, 3 half-widths almost never.
            assert!(
                (f.first_order[i] - S1[i]).abs() < 3.0 * f.first_order_conf[i] + 1e-4,
                "S1[{i}]"
            );
            assert!(
                (f.total[i] - ST[i]).abs() < 3.0 * f.total_conf[i] + 1e-4,
                "ST[{i}]"
            );
        }
    }

    #[test]
    fn failures_drop_whole_groups_and_are_reported() {
        // ln(x3 + 2.5) fails (NaN) where x3 < -2.5: about 10 % of the rows.
        let model = ExpressionModel::new(
            vec!["x1".into(), "x2".into(), "x3".into()],
            &[("f".into(), format!("{ISHIGAMI} + 0*ln(x3 + 2.5)"))],
        )
        .unwrap();
        let options = SensitivityOptions {
            base_points: 1 << 12,
            seed: 3,
            ..Default::default()
        };
        let report = analyse(&model, &ishigami_space(), &options.check().unwrap()).unwrap();
        assert!(report.failed_evaluations > 0);
        assert!(report.dropped_groups > 0 && report.dropped_groups < report.total_groups);
        assert_eq!(
            report.failure_reasons.values().sum::<usize>(),
            report.failed_evaluations
        );
        assert!(report.failure_handling().contains("dropped"));
        for v in report.outputs[0]
            .first_order
            .iter()
            .chain(&report.outputs[0].total)
        {
            assert!(v.is_finite());
        }
    }

    #[test]
    fn a_model_failing_almost_everywhere_is_an_error() {
        let model = ishigami(&format!("{ISHIGAMI} + 0*ln(x3 - 3)"));
        let options = SensitivityOptions {
            base_points: 256,
            ..Default::default()
        };
        assert!(matches!(
            analyse(&model, &ishigami_space(), &options.check().unwrap()),
            Err(SensitivityError::TooManyFailures { .. })
        ));
    }
}
