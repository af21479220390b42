//! `iuq basis STUDY`: posterior sampling and evidence with BASIS (Wu et al. 2017).
//!
//! Reads the study's parameters and priors, its `[likelihood]` (see [`crate::likelihood_section`])
//! and `[sampler]` ([`crate::sampler_section`]) sections, and writes to the output directory:
//! - `checkpoint.json` — the state after every stage, written atomically (format:
//!   `iuq_basis::checkpoint`); `--resume DIR` continues from `DIR/checkpoint.json`
//!   bit-identically;
//! - `stages.json` (every diagnostic, failure reasons included) and `stages.csv` (the numeric
//!   ones), rewritten after every stage;
//! - `samples.csv` — the final population: one column per parameter (with `sigma_m` when the
//!   modelling error is estimated), then `ll` (log-likelihood) and `lp` (log-prior);
//! - `summary.json` — evidence, stop reason, settings, MAP, mean, std, quantiles, failures;
//! - `marginals.json` — 1-D (200 points) and 2-D (50×50) Gaussian KDE marginals.
//!
//! Progress is reported after every stage on stderr: a progress bar on a terminal, log lines
//! otherwise. A run that stops before p = 1 (stage limit, minimum step) still writes its
//! results, reports why, and exits with 0; `"converged"` in the JSON says whether it reached the
//! posterior.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::{Map, Value, json};

use iuq_basis::checkpoint::{from_json, to_json};
use iuq_basis::summary::DEFAULT_PROBABILITIES;
use iuq_basis::{
    Basis, BasisError, BasisState, Control, CurveModel, ErrorModel, LogDensityLikelihood,
    LogLikelihood, Observer, PosteriorSummary, PredictionErrorLikelihood, StopReason, marginal_1d,
    marginal_2d, marginal_range,
};
use iuq_core::{Model, ParameterSpace};

use crate::input_error::{BadInput, input_error};
use crate::likelihood_section::{LikelihoodSection, parse_likelihood};
use crate::report_output::{emit, short};
use crate::sampler_section::{SamplerOverrides, parse_sampler};
use crate::study::Study;
use crate::table_io::{write_atomically, write_numeric_csv};

/// Arguments of `iuq basis`.
#[derive(Debug, Args)]
pub struct BasisArgs {
    /// The study file (TOML) with `[parameters]`, `[likelihood]` and optionally `[sampler]`.
    pub study: PathBuf,
    /// Population size N (default from `[sampler] samples`, else 1000).
    #[arg(long)]
    pub samples: Option<usize>,
    /// Burn-in steps n_burn of every chain (default from `[sampler] burn`, else 0).
    #[arg(long)]
    pub burn: Option<usize>,
    /// Maximum chain length l_max (default from `[sampler] max_chain`, else 1).
    #[arg(long)]
    pub max_chain: Option<usize>,
    /// Seed of the random streams (default from `[sampler] seed`, else 0).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Output directory (default: `<study name>-basis` in the current directory, or the
    /// `--resume` directory).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Continue the run whose checkpoint is `DIR/checkpoint.json` (same study and settings).
    #[arg(long, value_name = "DIR")]
    pub resume: Option<PathBuf>,
    /// Stop (resumably) after this stage, e.g. to fit a job's time limit; continue later with
    /// `--resume`.
    #[arg(long, value_name = "STAGE")]
    pub stop_after: Option<usize>,
}

/// The likelihood of a study, with its sampled parameter space.
pub(crate) struct StudyPosterior {
    /// The sampled parameters (the study's, and σ_m when the modelling error is estimated).
    pub(crate) space: ParameterSpace,
    /// ln f(D | θ).
    pub(crate) likelihood: Box<dyn LogLikelihood>,
    /// What the likelihood is, for the summary.
    pub(crate) description: Value,
}

fn build_posterior(study: &Study) -> Result<StudyPosterior> {
    build_posterior_with(study, || study.model())
}

/// The likelihood of `study`, comparing the outputs of the model `model()` builds with the data
/// (`model` is called only when the `[likelihood]` needs a model: data without `prediction`).
pub(crate) fn build_posterior_with<M: Model + 'static>(
    study: &Study,
    model: impl FnOnce() -> Result<M>,
) -> Result<StudyPosterior> {
    let file = study.path.display().to_string();
    match parse_likelihood(study)? {
        LikelihoodSection::LogDensity(source) => {
            let likelihood = LogDensityLikelihood::new(&source, &study.space)
                .bad_input(|| format!("{file}: key `likelihood.log_density`"))?;
            Ok(StudyPosterior {
                space: study.space.clone(),
                likelihood: Box::new(likelihood),
                description: json!({"kind": "log_density", "log_density": source}),
            })
        }
        LikelihoodSection::Data(data) => {
            let errors = ErrorModel {
                measurement_error: data.measurement_error,
                computational_error: data.computational_error,
                modelling_error: data.modelling_error,
            };
            let description = json!({
                "kind": "prediction_error",
                "data": data.file.display().to_string(),
                "points": data.x.len(),
                "measurement_error": data.measurement_error && data.observations.measurement_std.is_some(),
                "computational_error": data.computational_error.name(),
                "modelling_error": data.modelling_error,
                "model": if data.prediction.is_some() { "prediction" } else { "model" },
            });
            let n = data.x.len();
            let (space, likelihood): (ParameterSpace, Box<dyn LogLikelihood>) = if let Some(
                formula,
            ) =
                &data.prediction
            {
                let model = CurveModel::new(study.space.names(), formula, data.x.clone())
                    .bad_input(|| format!("{file}: key `likelihood.prediction`"))?;
                let likelihood = PredictionErrorLikelihood::new(model, data.observations, errors)
                    .bad_input(|| format!("{file}: section `[likelihood]`"))?;
                let space = likelihood
                    .parameter_space(&study.space)
                    .bad_input(|| format!("{file}: section `[likelihood]`"))?;
                (space, Box::new(likelihood))
            } else {
                let model = model()?;
                if model.output_dimension() != n {
                    return Err(input_error(format!(
                        "{file}: key `model.outputs`: the model has {} outputs but the data has {n} points (output j is compared with data point j, in file order; or give `likelihood.prediction = \"formula of the parameters and x\"`)",
                        model.output_dimension()
                    )));
                }
                let likelihood = PredictionErrorLikelihood::new(model, data.observations, errors)
                    .bad_input(|| format!("{file}: section `[likelihood]`"))?;
                let space = likelihood
                    .parameter_space(&study.space)
                    .bad_input(|| format!("{file}: section `[likelihood]`"))?;
                (space, Box::new(likelihood))
            };
            Ok(StudyPosterior {
                space,
                likelihood,
                description,
            })
        }
    }
}

/// Writes the checkpoint and the stage table after every stage, reports progress, and stops
/// after `stop_after`.
struct StageReporter {
    out: PathBuf,
    bar: Option<ProgressBar>,
    stop_after: Option<usize>,
    started: Instant,
}

impl StageReporter {
    fn report(&self, state: &BasisState) {
        let Some(d) = state.diagnostics.last() else {
            return;
        };
        let line = format!(
            "stage {}: p = {} (dp {}), CV {}, ESS/N {}, acceptance {}, ln Z so far {}, evaluations {} ({} total), failures {}, {:.2} s",
            d.stage,
            short(d.exponent),
            short(d.step),
            short(d.cv),
            short(d.ess_fraction),
            short(d.acceptance_rate),
            short(d.log_evidence),
            d.evaluations,
            state.evaluations,
            d.failures,
            d.wall_seconds
        );
        match &self.bar {
            Some(bar) => {
                bar.set_position((state.exponent * 1000.0).round() as u64);
                bar.set_message(format!(
                    "stage {} p={} CV={} acc={} lnZ={} evals={} fail={}",
                    d.stage,
                    short(d.exponent),
                    short(d.cv),
                    short(d.acceptance_rate),
                    short(d.log_evidence),
                    state.evaluations,
                    state.failures()
                ));
            }
            None => eprintln!("basis: {line}"),
        }
    }

    fn write(&self, state: &BasisState) -> Result<()> {
        let text = to_json(state)?;
        write_atomically(&self.out.join("checkpoint.json"), text.as_bytes())?;
        write_stages(&self.out, state)
    }
}

impl Observer for StageReporter {
    fn observe(&mut self, state: &BasisState) -> iuq_basis::Result<Control> {
        self.write(state)
            .map_err(|e| BasisError::Observer(format!("{e:#}")))?;
        self.report(state);
        if self.stop_after.is_some_and(|s| state.stage >= s) {
            return Ok(Control::Stop);
        }
        Ok(Control::Continue)
    }
}

fn write_stages(out: &Path, state: &BasisState) -> Result<()> {
    let text = serde_json::to_string_pretty(&state.diagnostics)?;
    write_atomically(&out.join("stages.json"), text.as_bytes())?;
    let columns: Vec<String> = [
        "stage",
        "exponent",
        "step",
        "cv",
        "ess_fraction",
        "step_clamped",
        "log_evidence_increment",
        "log_evidence",
        "max_log_likelihood",
        "chains",
        "proposals",
        "accepted",
        "acceptance_rate",
        "out_of_support",
        "failures",
        "evaluations",
        "batches",
        "unique_fraction",
        "wall_seconds",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let rows: Vec<Vec<f64>> = state
        .diagnostics
        .iter()
        .map(|d| {
            vec![
                d.stage as f64,
                d.exponent,
                d.step,
                d.cv,
                d.ess_fraction,
                f64::from(u8::from(d.step_clamped)),
                d.log_evidence_increment,
                d.log_evidence,
                d.max_log_likelihood,
                d.chains as f64,
                d.proposals as f64,
                d.accepted as f64,
                d.acceptance_rate,
                d.out_of_support as f64,
                d.failures as f64,
                d.evaluations as f64,
                d.batches as f64,
                d.unique_fraction,
                d.wall_seconds,
            ]
        })
        .collect();
    write_numeric_csv(&out.join("stages.csv"), &columns, &rows)
}

fn by_name(names: &[String], values: &[f64]) -> Value {
    Value::Object(
        names
            .iter()
            .zip(values)
            .map(|(k, v)| (k.clone(), json!(v)))
            .collect::<Map<_, _>>(),
    )
}

fn marginals(state: &BasisState, space: &ParameterSpace) -> Value {
    let names = &state.parameter_names;
    let d = names.len();
    let ranges = space.ranges();
    let mut one = Vec::new();
    let mut grid_ranges = Vec::new();
    for (k, name) in names.iter().enumerate() {
        // the KDE's natural range, clipped to the prior's
        let range = marginal_range(&state.samples, k)
            .ok()
            .map(|(lo, hi)| (lo.max(ranges[k].0), hi.min(ranges[k].1)))
            .filter(|(lo, hi)| lo < hi);
        grid_ranges.push(range);
        match range.map(|r| marginal_1d(&state.samples, k, name, 200, Some(r))) {
            Some(Ok(m)) => one.push(json!(m)),
            Some(Err(e)) => one.push(json!({"parameter": name, "error": e.to_string()})),
            None => one.push(
                json!({"parameter": name, "error": "no density: the samples of this parameter are constant"}),
            ),
        }
    }
    let mut two = Vec::new();
    for a in 0..d {
        for b in a + 1..d {
            let ranges = grid_ranges[a].zip(grid_ranges[b]);
            let result = match ranges {
                Some(r) => marginal_2d(
                    &state.samples,
                    (a, b),
                    (&names[a], &names[b]),
                    50,
                    Some(r),
                )
                .map(|m| json!(m))
                .unwrap_or_else(|e| json!({"x_parameter": names[a], "y_parameter": names[b], "error": e.to_string()})),
                None => {
                    json!({"x_parameter": names[a], "y_parameter": names[b], "error": "constant samples"})
                }
            };
            two.push(result);
        }
    }
    json!({"one_dimensional": one, "two_dimensional": two})
}

/// A finished (or stopped) BASIS run with its summary.
pub(crate) struct SampledPosterior {
    /// The run (final state and stop reason).
    pub(crate) run: iuq_basis::BasisRun,
    /// MAP, mean, std and quantiles.
    pub(crate) summary: PosteriorSummary,
    /// Wall-clock seconds of this invocation.
    pub(crate) seconds: f64,
}

/// Sample `posterior` with BASIS and write every result file into `out` (checkpoint after each
/// stage, `stages.json/csv`, `samples.csv`, `marginals.json`, `summary.json`); `checkpoint`
/// resumes an earlier run. `study_name`/`study_file` label the summary; `label` prefixes the
/// progress lines.
#[allow(clippy::too_many_arguments)]
pub(crate) fn sample_posterior(
    study_name: &str,
    study_file: &Path,
    posterior: &StudyPosterior,
    settings: iuq_basis::CheckedSettings,
    out: &Path,
    checkpoint: Option<BasisState>,
    resume_dir: Option<&Path>,
    stop_after: Option<usize>,
) -> Result<SampledPosterior> {
    let out = out.to_path_buf();
    std::fs::create_dir_all(&out)
        .map_err(|e| input_error(format!("cannot create {}: {e}", out.display())))?;
    let basis = Basis::new(&posterior.space, posterior.likelihood.as_ref(), settings)
        .bad_input(|| format!("{}", study_file.display()))?;
    if let Some(state) = &checkpoint {
        basis.check_compatible(state).bad_input(|| {
            format!(
                "--resume: {} does not belong to this study and these settings",
                resume_dir
                    .unwrap_or(Path::new("."))
                    .join("checkpoint.json")
                    .display()
            )
        })?;
    }
    let bar = if std::io::stderr().is_terminal() {
        let bar = ProgressBar::new(1000);
        bar.set_style(
            ProgressStyle::with_template(
                "basis [{elapsed_precise}] {bar:25} p {pos}/{len}‰ {wide_msg}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        // keep the elapsed time moving during long stages (an expensive model)
        bar.enable_steady_tick(std::time::Duration::from_millis(500));
        Some(bar)
    } else {
        None
    };
    let mut reporter = StageReporter {
        out: out.clone(),
        bar,
        stop_after,
        started: Instant::now(),
    };
    let result = match checkpoint {
        Some(state) => basis.resume(state, &mut reporter),
        None => basis.run(&mut reporter),
    };
    if let Some(bar) = &reporter.bar {
        bar.finish_and_clear();
    }
    let run = result.context("BASIS run failed")?;
    let state = &run.state;
    // The final state is also the last checkpoint (a resumed finished run rewrites it).
    reporter.write(state)?;

    let names = &state.parameter_names;
    let summary = PosteriorSummary::from_state(state).context("posterior summary")?;
    let mut columns = names.clone();
    columns.push("ll".into());
    columns.push("lp".into());
    let rows: Vec<Vec<f64>> = state
        .samples
        .iter()
        .zip(&state.log_likelihood)
        .zip(&state.log_prior)
        .map(|((x, ll), lp)| {
            let mut row = x.clone();
            row.push(*ll);
            row.push(*lp);
            row
        })
        .collect();
    write_numeric_csv(&out.join("samples.csv"), &columns, &rows)?;
    let marginals = marginals(state, &posterior.space);
    write_atomically(
        &out.join("marginals.json"),
        serde_json::to_string(&marginals)?.as_bytes(),
    )?;

    let converged = run.stop_reason == StopReason::Converged;
    let quantiles: Map<String, Value> = names
        .iter()
        .zip(&summary.quantiles)
        .map(|(name, q)| {
            let by_p: Map<String, Value> = summary
                .probabilities
                .iter()
                .zip(q)
                .map(|(p, v)| (format!("{p}"), json!(v)))
                .collect();
            (name.clone(), Value::Object(by_p))
        })
        .collect();
    let summary_file = json!({
        "study": study_name,
        "study_file": study_file.display().to_string(),
        "likelihood": posterior.description,
        "settings": state.settings,
        "parameters": names,
        "log_evidence": state.log_evidence,
        "log_evidence_increments": state.diagnostics.iter().map(|d| d.log_evidence_increment).collect::<Vec<_>>(),
        "stages": state.stages(),
        "evaluations": state.evaluations,
        "stop_reason": run.stop_reason,
        "stop_message": run.stop_reason.to_string(),
        "converged": converged,
        "exponent": state.exponent,
        "map": by_name(names, &summary.map),
        "map_log_likelihood": summary.map_log_likelihood,
        "map_log_prior": summary.map_log_prior,
        "mean": by_name(names, &summary.mean),
        "std": by_name(names, &summary.std),
        "quantiles": quantiles,
        "failures": state.failures(),
        "failure_reasons": state.failure_reasons(),
        "out_of_support": state.out_of_support(),
    });
    write_atomically(
        &out.join("summary.json"),
        serde_json::to_string_pretty(&summary_file)?.as_bytes(),
    )?;
    Ok(SampledPosterior {
        seconds: reporter.started.elapsed().as_secs_f64(),
        run,
        summary,
    })
}

/// Run `iuq basis`.
pub fn run(args: &BasisArgs, json_output: bool) -> Result<()> {
    let study = Study::load(&args.study)?;
    let posterior = build_posterior(&study)?;
    let overrides = SamplerOverrides {
        samples: args.samples,
        burn: args.burn,
        max_chain: args.max_chain,
        seed: args.seed,
    };
    let settings = parse_sampler(&study, &overrides)?;
    let checkpoint = match &args.resume {
        None => None,
        Some(dir) => {
            let path = dir.join("checkpoint.json");
            let text = std::fs::read_to_string(&path).map_err(|e| {
                input_error(format!("--resume: cannot read {}: {e}", path.display()))
            })?;
            let state = from_json(&text).bad_input(|| format!("--resume: {}", path.display()))?;
            Some(state)
        }
    };
    let out = match (&args.out, &args.resume) {
        (Some(out), _) => out.clone(),
        (None, Some(dir)) => dir.clone(),
        (None, None) => PathBuf::from(format!("{}-basis", study.name)),
    };
    std::fs::create_dir_all(&out)
        .map_err(|e| input_error(format!("--out: cannot create {}: {e}", out.display())))?;

    let sampled = sample_posterior(
        &study.name,
        &study.path,
        &posterior,
        settings,
        &out,
        checkpoint,
        args.resume.as_deref(),
        args.stop_after,
    )?;
    let (run, summary) = (&sampled.run, &sampled.summary);
    let state = &run.state;
    let names = &state.parameter_names;
    let converged = run.stop_reason == StopReason::Converged;
    let value = json!({
        "study": study.name,
        "log_evidence": state.log_evidence,
        "stages": state.stages(),
        "evaluations": state.evaluations,
        "stop_reason": run.stop_reason.name(),
        "stop_message": run.stop_reason.to_string(),
        "converged": converged,
        "exponent": state.exponent,
        "samples": state.samples.len(),
        "map": by_name(names, &summary.map),
        "mean": by_name(names, &summary.mean),
        "std": by_name(names, &summary.std),
        "map_log_likelihood": summary.map_log_likelihood,
        "map_log_prior": summary.map_log_prior,
        "failures": state.failures(),
        "failure_reasons": state.failure_reasons(),
        "out_of_support": state.out_of_support(),
        "out": out.display().to_string(),
        "wall_seconds": sampled.seconds,
    });
    if !converged {
        eprintln!("basis: {}", run.stop_reason);
    }
    emit(json_output, &value, || {
        let mut text = format!(
            "BASIS posterior of `{}`: ln Z = {} after {} stages, {} evaluations ({} failed, {} proposals outside the prior)\n{}\n\n{:<16} {:>12} {:>12} {:>12} {:>12} {:>12}\n",
            study.name,
            short(state.log_evidence),
            state.stages(),
            state.evaluations,
            state.failures(),
            state.out_of_support(),
            run.stop_reason,
            "parameter",
            "MAP",
            "mean",
            "std",
            "2.5%",
            "97.5%"
        );
        let lo = DEFAULT_PROBABILITIES.iter().position(|p| *p == 0.025);
        let hi = DEFAULT_PROBABILITIES.iter().position(|p| *p == 0.975);
        for (k, name) in names.iter().enumerate() {
            let q =
                |i: Option<usize>| i.map_or("-".to_string(), |i| short(summary.quantiles[k][i]));
            text.push_str(&format!(
                "{:<16} {:>12} {:>12} {:>12} {:>12} {:>12}\n",
                name,
                short(summary.map[k]),
                short(summary.mean[k]),
                short(summary.std[k]),
                q(lo),
                q(hi)
            ));
        }
        text.push_str(&format!("\nresults in {}", out.display()));
        text
    });
    Ok(())
}
