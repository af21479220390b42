//! From the pipeline's results to the report: posterior summaries, the propagation of each
//! posterior to the outputs, GP diagnostics, Sobol' indices and run statistics, handed to
//! `iuq_report::write_report`, plus `DIR/pipeline.json` with the summary numbers.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

use serde_json::{Value, json};

use super::emulator::Emulator;
use iuq_campaign::StatusCounts;
use iuq_report::{
    CellPortrait, CellPortraits, CheckedPoint, ComparedParameter, ComparedTraces, DataSeries,
    ElongationTrace, GpDiagnostic, MapRunsAtPoint, MismatchTest, ModelPosteriorReport,
    ModelPosteriorStageRow, ParameterSummary, PosteriorCheckReport, PosteriorResult,
    PropagatedOutput, RunStatistics, SamplerStage, SensitivityIndex, SensitivityResult,
    StudyReport, write_report,
};
use iuq_sensitivity::SensitivityReport;

use crate::error::{Context, Result};
use crate::likelihood_section::DataLikelihood;
use crate::pipeline::adaptive::AdaptiveOutcome;
use crate::pipeline::adaptive_report;
use crate::pipeline::model_posterior::ModelPosteriorOutcome;
use crate::pipeline::model_runs::ModelRuns;
use crate::pipeline::posterior_check::{CheckedRun, PosteriorCheck};
use crate::pipeline::run_groups::GroupRuns;
use crate::pipeline::settings::PipelineSettings;
use crate::pipeline::surrogate::Surrogate;
use crate::posterior::SampledPosterior;
use crate::study::{ModelSection, Study};
use crate::table_io::write_atomically;
use iuq_core::weighted_statistics::quantile_sorted;

/// The runs informing one data point: training and test sets (successful runs) and the
/// failures of its run group.
#[derive(Debug, Clone)]
pub struct PointRuns {
    /// The data point's abscissa.
    pub x: f64,
    /// Parameters of the successful training runs (initial and adaptive).
    pub training_x: Vec<Vec<f64>>,
    /// The model's output there.
    pub training_y: Vec<f64>,
    /// Their computational stds.
    pub training_std: Vec<f64>,
    /// Parameters of the successful test runs.
    pub test_x: Vec<Vec<f64>>,
    /// The model's output there.
    pub test_y: Vec<f64>,
    /// Their computational stds.
    pub test_std: Vec<f64>,
    /// Reasons of the failed runs.
    pub failures: Vec<String>,
}

/// Everything the pipeline computed, borrowed for the report.
pub struct PipelineResults<'a> {
    /// The study.
    pub study: &'a Study,
    /// Its data.
    pub data: &'a DataLikelihood,
    /// Its pipeline settings.
    pub settings: &'a PipelineSettings,
    /// Runs per data point.
    pub point_runs: &'a [PointRuns],
    /// (Q2 on the test set, leave-one-out Q2) per data point.
    pub gp_checks: &'a [(f64, f64)],
    /// The emulator of the outputs (a GP per data point, or a reduced basis).
    pub emulator: &'a Emulator,
    /// Sobol' indices on the surrogate.
    pub surrogate_sobol: &'a SensitivityReport,
    /// Sobol' indices from model runs.
    pub model_sobol: Option<&'a SensitivityReport>,
    /// The posterior on the GP bank.
    pub gp_posterior: &'a SampledPosterior,
    /// The posterior on the cell model (BASIS on the model).
    pub model_posterior: Option<&'a SampledPosterior>,
    /// The model's posterior from the surrogate's (certified importance stages).
    pub reweighted: Option<&'a ModelPosteriorOutcome>,
    /// The cell at the model posterior's MAP in pictures (cell-model studies).
    pub portraits: Option<&'a [iuq_rbc::ShearPortrait]>,
    /// The cell at the surrogate posterior's MAP, whose elongation traces the report sets
    /// beside the model MAP's.
    pub compared_portraits: Option<&'a [iuq_rbc::ShearPortrait]>,
    /// The campaign store's runs by status and the reasons of its failed runs.
    pub campaign_runs: (StatusCounts, Vec<String>),
    /// The adaptive engine's rounds, when it ran.
    pub adaptive: Option<&'a AdaptiveOutcome>,
    /// The model run at the posterior, when it was.
    pub posterior_check: Option<&'a PosteriorCheck>,
    /// The runs by run group.
    pub groups: &'a [GroupRuns],
    /// The model's campaign (how groups map to data points).
    pub model_runs: &'a ModelRuns,
    /// The surrogate (its failure classifiers draw the failure map).
    pub surrogate: &'a Surrogate,
    /// The cheap model of `[low_fidelity]`, if any.
    pub low_fidelity: Option<&'a super::low_fidelity::LowFidelity>,
}

/// How the report names the data and the model: the cell model's physical labels, or the data
/// file's column names.
struct Labels {
    x_label: String,
    y_label: String,
    model_source: &'static str,
    rbc: bool,
    x_column: String,
    y_column: String,
}

impl Labels {
    fn of(study: &Study, data: &DataLikelihood) -> Self {
        let rbc = matches!(study.model, ModelSection::RbcShear { .. });
        Self {
            x_label: if rbc {
                "shear stress (Pa)".into()
            } else {
                data.x_column.clone()
            },
            y_label: if rbc {
                "elongation index EL (–)".into()
            } else {
                data.y_column.clone()
            },
            model_source: if rbc { "cell model" } else { "model" },
            rbc,
            x_column: data.x_column.clone(),
            y_column: data.y_column.clone(),
        }
    }

    /// "at 1.36 Pa" (the cell model) or "at t_min = 0.5".
    fn at(&self, x: f64) -> String {
        if self.rbc {
            format!("at {x} Pa")
        } else {
            format!("at {} = {x}", self.x_column)
        }
    }

    /// The label of the model's output at abscissa `x`.
    fn output(&self, x: f64) -> String {
        if self.rbc {
            format!("EL at {x} Pa")
        } else {
            format!("{} at {} = {x}", self.y_column, self.x_column)
        }
    }
}

/// The model parameters' part of posterior samples (σ_m, when estimated, is the last column).
fn model_part(samples: &[Vec<f64>], d: usize) -> Vec<Vec<f64>> {
    samples.iter().map(|s| s[..d].to_vec()).collect()
}

/// The model's weighted posterior as a report source: its weighted summary, and as samples an
/// equally weighted systematic resample (u_k = (k + ½)/S, no random draw) of its population for
/// the density plots; its propagated output is the model's own (each resampled member's stored
/// run, and the model run at its MAP), the surrogate's prediction only where a run is missing.
/// Also returns how many propagated values (samples and MAP values) came from the surrogate.
fn reweighted_result(
    source: &str,
    outcome: &ModelPosteriorOutcome,
    emulator: &Emulator,
    stresses: &[f64],
    d: usize,
) -> Result<(PosteriorResult, usize)> {
    let p = &outcome.posterior;
    let weights = p.weights();
    let n = p.samples.len();
    let mut samples = Vec::with_capacity(n);
    let mut resampled = Vec::with_capacity(n);
    let mut cumulative = 0.0;
    let mut i = 0;
    for k in 0..n {
        let u = (k as f64 + 0.5) / n as f64;
        while i + 1 < n && cumulative + weights[i] < u {
            cumulative += weights[i];
            i += 1;
        }
        samples.push(p.samples[i].clone());
        resampled.push(i);
    }
    let quantile = |k: usize, q: f64| {
        let column: Vec<f64> = p.samples.iter().map(|s| s[k]).collect();
        iuq_core::weighted_statistics::weighted_quantiles(&column, &weights, &[q])
            .map(|v| v[0])
            .unwrap_or(f64::NAN)
    };
    let summary = p
        .names
        .iter()
        .enumerate()
        .map(|(k, name)| ParameterSummary {
            name: name.clone(),
            map: p.map[k],
            mean: p.mean[k],
            std: p.std[k],
            q05: quantile(k, 0.05),
            q50: quantile(k, 0.5),
            q95: quantile(k, 0.95),
        })
        .collect();
    let theta = model_part(&samples, d);
    let map = vec![p.map[..d].to_vec()];
    let mut propagated = Vec::with_capacity(stresses.len());
    let means = emulator.predict_means(&theta)?;
    let at_map = emulator.predict_means(&map)?;
    let mut from_surrogate = 0;
    for (j, ((mut samples, at_map), s)) in means.into_iter().zip(at_map).zip(stresses).enumerate() {
        for (value, &i) in samples.iter_mut().zip(&resampled) {
            match outcome
                .member_outputs
                .get(i)
                .and_then(|o| o.as_ref())
                .and_then(|o| o.get(j))
            {
                Some(&run) => *value = run,
                None => from_surrogate += 1,
            }
        }
        let map_prediction = match outcome.map_runs.get(j).and_then(|r| r.1) {
            Some(run) => run,
            None => {
                from_surrogate += 1;
                at_map[0]
            }
        };
        propagated.push(PropagatedOutput {
            x: *s,
            samples,
            map_prediction,
        });
    }
    Ok((
        PosteriorResult {
            source: source.into(),
            summary,
            log_evidence: outcome.log_evidence,
            samples,
            stages: Vec::new(),
            propagated,
        },
        from_surrogate,
    ))
}

/// The model posterior's section of the report: Table 2 (from the GP posterior's summary and
/// the model posterior's weighted one), the weights, the stages and the model at both MAPs.
fn model_posterior_report(
    outcome: &ModelPosteriorOutcome,
    gp: &SampledPosterior,
    data: &DataLikelihood,
    labels: &Labels,
) -> ModelPosteriorReport {
    let p = &outcome.posterior;
    let relative = |m: f64, s: f64| (s != 0.0).then(|| (m - s) / s.abs());
    let parameters = p
        .names
        .iter()
        .enumerate()
        .map(|(k, name)| {
            let s = (gp.summary.map[k], gp.summary.mean[k], gp.summary.std[k]);
            let m = (p.map[k], p.mean[k], p.std[k]);
            ComparedParameter {
                name: name.clone(),
                surrogate: s,
                model: m,
                relative_difference: (relative(m.0, s.0), relative(m.1, s.1), relative(m.2, s.2)),
                mcse: (p.mcse_mean[k], p.mcse_std[k]),
            }
        })
        .collect();
    let measurement_std = data.observations.measurement_std.clone();
    ModelPosteriorReport {
        surrogate_source: "GP surrogate".into(),
        model_source: labels.model_source.into(),
        certified: p.certified(),
        stop: p.stop.to_string(),
        samples: p.samples.len(),
        pareto_k: p.pareto_k,
        pareto_k_threshold: p.pareto_k_threshold,
        effective_sample_size: p.effective_sample_size,
        ancestors: p.ancestors,
        model_runs: outcome.model_runs,
        failures: p.failures,
        corrections: p.corrections.len(),
        probe_pairs: outcome.probe.as_ref().map_or(0, |probe| probe.pairs),
        irregular_outputs: outcome
            .probe
            .as_ref()
            .map(|probe| {
                probe
                    .outputs
                    .iter()
                    .filter(|o| o.irregular)
                    .map(|o| o.name.clone())
                    .collect()
            })
            .unwrap_or_default(),
        pseudo_marginal: outcome.pseudo_marginal,
        proposal_mismatch: p.proposal_mismatch.as_ref().map(|t| MismatchTest {
            mean_shift: t.mean_shift,
            spread_divergence: t.spread_divergence,
            p_value: t.p_value,
            level: iuq_basis::moment_matching::MISMATCH_LEVEL,
            widening: iuq_basis::moment_matching::DEFENSIVE_WIDENING,
            corrected: !p.corrections.is_empty(),
        }),
        correction_not_made: p.correction_not_made.clone(),
        correction_moment_matched: p.corrections.iter().any(|c| c.moment_matched),
        correction_tempering: p.corrections.iter().find_map(|c| c.tempering),
        correction_defensive_normal: p.corrections.iter().any(|c| c.defensive_normal),
        both_batches: p.both_batches,
        paired: p.paired.is_some(),
        corrections_refused: p
            .corrections
            .iter()
            .flat_map(|c| c.refused.iter().cloned())
            .collect(),
        replicates: outcome.replicates,
        parameters,
        log_weights: p
            .raw_log_weights
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .collect(),
        stages: p
            .stages
            .iter()
            .map(|s| ModelPosteriorStageRow {
                stage: s.stage,
                beta: s.beta,
                cv: s.cv,
                pareto_k: s.pareto_k,
                effective_sample_size: s.effective_sample_size,
                model_evaluations: s.model_evaluations,
                acceptance: s.screen_acceptance.zip(s.confirm_acceptance),
                spread_ratio: s.spread_ratio,
            })
            .collect(),
        map_runs: outcome
            .map_runs
            .iter()
            .enumerate()
            .map(|(j, (at_s, at_m))| {
                MapRunsAtPoint::new(
                    data.x[j],
                    (
                        data.observations.values[j],
                        measurement_std.as_ref().map_or(0.0, |s| s[j]),
                    ),
                    *at_s,
                    *at_m,
                )
            })
            .collect(),
    }
}

fn posterior_result(
    source: &str,
    sampled: &SampledPosterior,
    emulator: &Emulator,
    stresses: &[f64],
    d: usize,
) -> Result<PosteriorResult> {
    let state = &sampled.run.state;
    let names = &state.parameter_names;
    let summary = names
        .iter()
        .enumerate()
        .map(|(k, name)| {
            let mut column: Vec<f64> = state.samples.iter().map(|s| s[k]).collect();
            column.sort_by(f64::total_cmp);
            ParameterSummary {
                name: name.clone(),
                map: sampled.summary.map[k],
                mean: sampled.summary.mean[k],
                std: sampled.summary.std[k],
                q05: quantile_sorted(&column, 0.05),
                q50: quantile_sorted(&column, 0.5),
                q95: quantile_sorted(&column, 0.95),
            }
        })
        .collect();
    let stages = state
        .diagnostics
        .iter()
        .map(|g| SamplerStage {
            stage: g.stage,
            annealing_exponent: g.exponent,
            cv: g.cv,
            acceptance: g.acceptance_rate,
            log_evidence: g.log_evidence,
            evaluations: g.evaluations,
            seconds: g.wall_seconds,
        })
        .collect();
    // Propagation through the surrogate (for both posteriors: a run of the cell model per
    // posterior sample would cost as much as the whole sampling again).
    let theta = model_part(&state.samples, d);
    let map = vec![sampled.summary.map[..d].to_vec()];
    let mut propagated = Vec::with_capacity(stresses.len());
    let means = emulator.predict_means(&theta)?;
    let at_map = emulator.predict_means(&map)?;
    for ((samples, at_map), s) in means.into_iter().zip(at_map).zip(stresses) {
        propagated.push(PropagatedOutput {
            x: *s,
            samples,
            map_prediction: at_map[0],
        });
    }
    Ok(PosteriorResult {
        source: source.into(),
        summary,
        log_evidence: state.log_evidence,
        samples: state.samples.clone(),
        stages,
        propagated,
    })
}

fn sensitivity_results(
    report: &SensitivityReport,
    source: &str,
    stresses: &[f64],
    labels: &Labels,
) -> Vec<SensitivityResult> {
    report
        .outputs
        .iter()
        .zip(stresses)
        .map(|(o, s)| SensitivityResult {
            output_label: labels.output(*s),
            x: *s,
            source: source.into(),
            indices: report
                .inputs
                .iter()
                .enumerate()
                .map(|(k, p)| SensitivityIndex {
                    parameter: p.clone(),
                    first_order: o.first_order[k],
                    first_order_low: o.first_order[k] - o.first_order_conf[k],
                    first_order_high: o.first_order[k] + o.first_order_conf[k],
                    total: o.total[k],
                    total_low: o.total[k] - o.total_conf[k],
                    total_high: o.total[k] + o.total_conf[k],
                })
                .collect(),
        })
        .collect()
}

fn posterior_json(p: &PosteriorResult) -> Value {
    let rows: Vec<Value> = p
        .summary
        .iter()
        .map(|s| json!({"parameter": s.name, "map": s.map, "mean": s.mean, "std": s.std, "q05": s.q05, "q95": s.q95}))
        .collect();
    json!({"source": p.source, "log_evidence": p.log_evidence, "stages": p.stages.len(), "parameters": rows})
}

/// Build the report of `results`, write it into `out`, and return the posterior tables as JSON.
/// `stage_seconds` gets the wall time of this last stage (started at `started`).
pub fn write_pipeline_report(
    results: &PipelineResults<'_>,
    out: &Path,
    stage_seconds: &mut [(String, f64)],
    started: Instant,
) -> Result<Value> {
    let study = results.study;
    let d = study.space.dimension();
    let labels = Labels::of(study, results.data);
    let stresses: Vec<f64> = results.point_runs.iter().map(|r| r.x).collect();
    let (posteriors, propagated_by_surrogate) = posterior_results(results, &labels, &stresses, d)?;
    let mut sensitivity = Vec::new();
    if let Some(m) = results.model_sobol {
        sensitivity.extend(sensitivity_results(m, "model runs", &stresses, &labels));
    }
    sensitivity.extend(sensitivity_results(
        results.surrogate_sobol,
        "surrogate",
        &stresses,
        &labels,
    ));
    let gp_diagnostics = gp_diagnostics(results, &labels)?;
    let (counts, failed_reasons) = &results.campaign_runs;
    let mut failures: BTreeMap<String, usize> = BTreeMap::new();
    for reason in failed_reasons {
        *failures.entry(short_reason(reason)).or_default() += 1;
    }
    let runs = counts.total() as usize;
    let failed = counts.failed as usize;
    let data = results.data;
    let y_err = data
        .observations
        .measurement_std
        .clone()
        .unwrap_or_else(|| vec![0.0; data.x.len()]);
    let provenance = provenance(results, propagated_by_surrogate);
    if let Some(last) = stage_seconds.last_mut() {
        last.1 = started.elapsed().as_secs_f64();
    }
    let report = StudyReport {
        two_fidelity: two_fidelity_points(results)?,
        two_fidelity_components: two_fidelity_components(results)?,
        title: format!("Calibration study `{}`", study.name),
        study_name: study.name.clone(),
        provenance,
        parameters: results.gp_posterior.run.state.parameter_names.clone(),
        data: DataSeries {
            x_label: labels.x_label.clone(),
            y_label: labels.y_label.clone(),
            x: data.x.clone(),
            y: data.observations.values.clone(),
            y_err,
        },
        posteriors,
        sensitivity,
        gp_diagnostics,
        convergence: results.adaptive.map(adaptive_report::convergence),
        failure_map: adaptive_report::failure_map(
            results.groups,
            results.surrogate,
            &study.space,
            &results.gp_posterior.summary.mean,
            &|g| match results.model_runs.group_abscissa(g) {
                Some(x) => format!("runs {}", labels.at(x)),
                None => "all runs".to_string(),
            },
        )?,
        runs_per_point: adaptive_report::runs_per_point(
            results.groups,
            results.model_runs,
            &data.x,
        ),
        posterior_check: results
            .posterior_check
            .map(|c| posterior_check_report(c, &labels)),
        model_posterior: results
            .reweighted
            .map(|m| model_posterior_report(m, results.gp_posterior, data, &labels)),
        cell_portraits: cell_portraits(results, &labels),
        run_statistics: RunStatistics {
            runs,
            succeeded: counts.succeeded as usize,
            failed,
            failures_by_reason: failures.into_iter().collect(),
            stage_seconds: stage_seconds.to_vec(),
        },
    };
    write_report(&report, out).context("writing the report")?;
    let summary = json!({
        "posteriors": report.posteriors.iter().map(posterior_json).collect::<Vec<_>>(),
        "q2": results.point_runs.iter().zip(results.gp_checks).map(|(r, (q2, loo))| json!({"x": r.x, "q2": finite_or_null(*q2), "loo_q2": finite_or_null(*loo)})).collect::<Vec<_>>(),
        "adaptive": results.adaptive,
        "posterior_check": results.posterior_check.map(PosteriorCheck::point_summaries),
        "sensitivity": sobol_json(results.surrogate_sobol),
        "model_sensitivity": results.model_sobol.map(sobol_json),
        "model_posterior": results.reweighted.map(ModelPosteriorOutcome::to_json),
    });
    write_atomically(
        &out.join("pipeline.json"),
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )?;
    Ok(summary["posteriors"].clone())
}

/// The posteriors of the report: the GP surrogate's, then the model's (BASIS on the model, or
/// the surrogate's reweighted), each propagated to the outputs at `stresses`; with how many of
/// the reweighted posterior's propagated values are the surrogate's (its failed runs).
fn posterior_results(
    results: &PipelineResults<'_>,
    labels: &Labels,
    stresses: &[f64],
    d: usize,
) -> Result<(Vec<PosteriorResult>, usize)> {
    let mut posteriors = vec![posterior_result(
        "GP surrogate",
        results.gp_posterior,
        results.emulator,
        stresses,
        d,
    )?];
    if let Some(m) = results.model_posterior {
        posteriors.push(posterior_result(
            labels.model_source,
            m,
            results.emulator,
            stresses,
            d,
        )?);
    }
    let mut propagated_by_surrogate = 0;
    if let Some(m) = results.reweighted {
        let (result, from_surrogate) =
            reweighted_result(labels.model_source, m, results.emulator, stresses, d)?;
        posteriors.push(result);
        propagated_by_surrogate = from_surrogate;
    }
    Ok((posteriors, propagated_by_surrogate))
}

/// Each data point's GP against its test runs, with its hyper-parameters in input units (only
/// points with a test set of at least 2 runs and finite Q2s).
fn gp_diagnostics(results: &PipelineResults<'_>, labels: &Labels) -> Result<Vec<GpDiagnostic>> {
    let mut gp_diagnostics = Vec::new();
    let per_output: &[iuq_gp::GaussianProcess] = results.emulator.per_output_gps().unwrap_or(&[]);
    for ((r, gp), (q2, loo)) in results
        .point_runs
        .iter()
        .zip(per_output)
        .zip(results.gp_checks)
    {
        // The diagnostic plots test runs against predictions; without a test set (the default
        // of adaptive studies) `pipeline.json` keeps the leave-one-out Q2.
        if r.test_y.len() < 2 || !q2.is_finite() || !loo.is_finite() {
            continue;
        }
        let prediction = gp.predict(&r.test_x)?;
        let h = gp.hyperparameters();
        let mut hyperparameters = vec![("signal variance".to_string(), h.signal_variance)];
        let lengths = gp.length_scales_in_input_units();
        for (name, l) in results.study.space.names().iter().zip(&lengths) {
            hyperparameters.push((format!("length scale {name}"), *l));
        }
        hyperparameters.push(("noise variance".to_string(), h.noise_variance));
        gp_diagnostics.push(GpDiagnostic {
            output_label: labels.output(r.x),
            x: r.x,
            q2: *q2,
            loo_q2: *loo,
            simulated: r.test_y.clone(),
            predicted: prediction.mean.clone(),
            predicted_std: prediction.std(),
            hyperparameters,
        });
    }
    Ok(gp_diagnostics)
}

/// Where the report comes from: the version, the command, the files, the designs, the sampler
/// and how the posteriors were propagated (`propagated_by_surrogate` of the reweighted
/// posterior's values by the surrogate).
fn provenance(
    results: &PipelineResults<'_>,
    propagated_by_surrogate: usize,
) -> Vec<(String, String)> {
    vec![
        (
            "iuq version".to_string(),
            env!("CARGO_PKG_VERSION").to_string(),
        ),
        (
            "command".to_string(),
            std::env::args().collect::<Vec<_>>().join(" "),
        ),
        (
            "study file".to_string(),
            results.study.path.display().to_string(),
        ),
        ("data".to_string(), results.data.file.display().to_string()),
        (
            "training design".to_string(),
            format!(
                "maximin LHS, {} runs per run group, seed {} + group index",
                results.settings.training_runs, results.settings.training_seed
            ),
        ),
        (
            "test design".to_string(),
            format!(
                "scrambled Sobol', {} runs per run group, seed {}",
                results.settings.test_runs, results.settings.test_seed
            ),
        ),
        (
            "sampler".to_string(),
            format!(
                "BASIS, N = {}, seed {}",
                results.gp_posterior.run.state.samples.len(),
                results.gp_posterior.run.state.settings.seed
            ),
        ),
        (
            "propagation".to_string(),
            if results.reweighted.is_some() {
                let mut text = "GP surrogate means at every sample of its posterior; the model's own runs at the members of the model's posterior and at its MAP".to_string();
                if propagated_by_surrogate > 0 {
                    text.push_str(&format!(
                        " ({propagated_by_surrogate} of its values the surrogate's, where a run failed)"
                    ));
                }
                text
            } else {
                "GP surrogate means at every posterior sample (both posteriors)".to_string()
            },
        ),
    ]
}

/// The cell's shape at the model posterior's MAP, per data point, with the elongation traces
/// at the surrogate posterior's MAP to compare, when they were simulated.
fn cell_portraits(results: &PipelineResults<'_>, labels: &Labels) -> Option<CellPortraits> {
    results.portraits.map(|portraits| CellPortraits {
        source: format!("the {} posterior's MAP", labels.model_source),
        portraits: portraits
            .iter()
            .map(|p| CellPortrait {
                x: p.stress,
                elongation_index: p.elongation_index,
                trace: p.trace.clone(),
                window: p.window,
                outline: p.outline.clone(),
                ellipse: p.ellipse,
                side: p.side.clone(),
            })
            .collect(),
        compared: results.compared_portraits.map(|compared| ComparedTraces {
            source: "the GP surrogate posterior's MAP".to_string(),
            traces: compared
                .iter()
                .map(|p| ElongationTrace {
                    x: p.stress,
                    elongation_index: p.elongation_index,
                    trace: p.trace.clone(),
                })
                .collect(),
        }),
    })
}

/// A number for JSON, `null` when not finite (a Q2 without test runs).
fn finite_or_null(v: f64) -> Value {
    if v.is_finite() { json!(v) } else { Value::Null }
}

/// The cause of a failure, so that equal causes count together: the first line, its last
/// `: `-separated part (without the process wrapper and the step), and the number of the mesh
/// element replaced by `N` ("triangle 591 area change …" → "triangle N area change …").
fn short_reason(reason: &str) -> String {
    let line = reason.lines().next().unwrap_or(reason);
    let line = line
        .rsplit(": ")
        .next()
        .unwrap_or(line)
        .trim_end_matches(')');
    let mut words: Vec<&str> = Vec::new();
    for word in line.split_whitespace() {
        let element = matches!(
            words.last(),
            Some(&"triangle") | Some(&"vertex") | Some(&"edge")
        );
        let index = word.chars().all(|c| c.is_ascii_digit() || c == '-');
        words.push(if element && index { "N" } else { word });
    }
    words.join(" ").chars().take(120).collect()
}

/// JSON of a Sobol' report, by output and parameter.
pub fn sobol_json(report: &SensitivityReport) -> Value {
    let outputs: Vec<Value> = report
        .outputs
        .iter()
        .map(|o| {
            json!({
                "output": o.output,
                "S1": o.first_order, "S1_conf": o.first_order_conf,
                "ST": o.total, "ST_conf": o.total_conf,
                "variance": o.variance,
            })
        })
        .collect();
    json!({
        "inputs": report.inputs,
        "outputs": outputs,
        "evaluations": report.evaluations,
        "failed_evaluations": report.failed_evaluations,
        "failure_handling": report.failure_handling(),
    })
}

/// The posterior check as the report shows it.
fn posterior_check_report(check: &PosteriorCheck, labels: &Labels) -> PosteriorCheckReport {
    let points = check
        .points
        .iter()
        .map(|p| {
            let ok: Vec<&CheckedRun> = p.samples.iter().filter(|r| r.model.is_some()).collect();
            let diagnostic: Vec<f64> = p
                .runs()
                .filter(|r| r.model.is_some())
                .filter_map(|r| r.diagnostics.first().copied())
                .collect();
            let mut abs: Vec<f64> = diagnostic.iter().map(|v| v.abs()).collect();
            abs.sort_by(f64::total_cmp);
            CheckedPoint {
                x: p.x,
                map_model: p.map.model.map(|m| (m, p.map.model_std.unwrap_or(0.0))),
                map_surrogate: (p.map.surrogate, p.map.surrogate_std),
                model: ok.iter().filter_map(|r| r.model).collect(),
                surrogate: ok.iter().map(|r| r.surrogate).collect(),
                surrogate_std: ok.iter().map(|r| r.surrogate_std).collect(),
                model_std: ok.iter().map(|r| r.model_std.unwrap_or(0.0)).collect(),
                diagnostic_median_abs: (!abs.is_empty()).then(|| quantile_sorted(&abs, 0.5)),
                diagnostic_largest_abs: abs.last().copied(),
                diagnostic,
                failed: p.failures(),
                rmse: p.rmse(),
                within_two_std: p.within_two_std(),
            }
        })
        .collect();
    PosteriorCheckReport {
        source: "GP surrogate".into(),
        samples: check.samples.len(),
        diagnostic: labels.rbc.then(|| "EL drift over the window".to_string()),
        points,
        test: check_test_sentence(check),
    }
}

/// The check's test in words ([`super::posterior_check::CheckVerdict`]).
fn check_test_sentence(check: &PosteriorCheck) -> String {
    let v = &check.verdict;
    let rule = format!(
        "Test (family-wise significance {}): the largest |z| = |model − surrogate|/predictive std over all runs must stay below {:.2}, and no data point may have more runs outside 2σ than a binomial with the 4.55 % a right predictive std gives makes likely (p ≥ {:.2e}).",
        v.significance,
        v.z_bound,
        v.significance / (2.0 * check.points.len().max(1) as f64)
    );
    if v.passed {
        format!("{rule} Passed (largest |z| {:.2}).", v.largest_z)
    } else {
        let at: Vec<String> = v
            .failed_points
            .iter()
            .map(|&j| {
                format!(
                    "{} ({} runs outside 2σ, p = {:.1e})",
                    check.points[j].x, v.outside[j], v.tail_probability[j]
                )
            })
            .collect();
        format!(
            "{rule} Failed at {} (largest |z| {:.2}).",
            at.join(", "),
            v.largest_z
        )
    }
}

/// Per data point, the two-fidelity emulator's ρ, its use of the cheap model and the runs of
/// each fidelity (empty with one fidelity).
fn two_fidelity_points(results: &PipelineResults<'_>) -> Result<Vec<iuq_report::TwoFidelityPoint>> {
    let (Some(bank), Some(low)) = (results.emulator.two_fidelity(), results.low_fidelity) else {
        return Ok(Vec::new());
    };
    let runs = results.model_runs;
    let mut points = Vec::with_capacity(bank.gps().len());
    for (j, gp) in bank.gps().iter().enumerate() {
        let (g, k) = (0..runs.groups())
            .find_map(|g| {
                let r = runs.group_outputs(g);
                r.contains(&j).then(|| (g, j - r.start))
            })
            .unwrap_or((0, j));
        points.push(iuq_report::TwoFidelityPoint {
            x: results.data.x[j],
            rho: gp.rho(),
            uses_low_fidelity: gp.uses_low_fidelity(),
            explained_share: gp.explained_share(),
            discrepancy_std: gp.discrepancy_std(),
            expensive_runs: results.groups[g].training(k).y.len(),
            cheap_runs: low.training(j)?.y.len(),
        });
    }
    Ok(points)
}

/// Per principal component of a reduced basis of two fidelities, ρ_k, its use of the cheap
/// model and the runs of each fidelity (empty otherwise).
fn two_fidelity_components(
    results: &PipelineResults<'_>,
) -> Result<Vec<iuq_report::TwoFidelityComponent>> {
    let (Some(basis), Some(low)) = (results.emulator.reduced_basis(), results.low_fidelity) else {
        return Ok(Vec::new());
    };
    if !basis.is_two_fidelity() {
        return Ok(Vec::new());
    }
    let expensive_runs = results
        .groups
        .first()
        .map_or(0, |g| g.training_curves().inputs.len());
    let cheap_runs = low.training_curves()?.inputs.len();
    Ok(basis
        .component_gps()
        .iter()
        .zip(basis.explained_variance())
        .enumerate()
        .filter_map(|(k, (c, &share))| {
            c.two_fidelity().map(|gp| iuq_report::TwoFidelityComponent {
                component: k + 1,
                explained_variance: share,
                rho: gp.rho(),
                uses_low_fidelity: gp.uses_low_fidelity(),
                explained_share: gp.explained_share(),
                discrepancy_std: gp.discrepancy_std(),
                expensive_runs,
                cheap_runs,
            })
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::short_reason;

    #[test]
    fn failures_of_the_same_cause_share_their_short_reason() {
        let a = "exited with status 1 (stderr: error: mesh broke at step 13018: triangle 591 area change -0.300 beyond the area singularity |α| = 0.3)";
        let b = "exited with status 1 (stderr: error: mesh broke at step 9082: triangle 516 area change -0.300 beyond the area singularity |α| = 0.3)";
        assert_eq!(short_reason(a), short_reason(b));
        assert_eq!(
            short_reason(a),
            "triangle N area change -0.300 beyond the area singularity |α| = 0.3"
        );
        assert_eq!(
            short_reason("edge 12-40 strain 3.001 beyond the link singularity |ε| = 3"),
            "edge N strain 3.001 beyond the link singularity |ε| = 3"
        );
        assert_eq!(short_reason("timed out after 6h"), "timed out after 6h");
    }
}
