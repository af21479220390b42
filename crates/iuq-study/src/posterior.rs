//! The posterior of a study, sampled with BASIS (Wu et al. 2017): the likelihood a study's
//! `[likelihood]` defines ([`build_posterior`], [`build_posterior_with`]) and a BASIS run that
//! writes its results into a directory ([`sample_posterior`]):
//! - `checkpoint.json` — the state after every stage, written atomically (format:
//!   `iuq_basis::checkpoint`); a run resumed from it continues bit-identically;
//! - `stages.json` (every diagnostic, failure reasons included) and `stages.csv` (the numeric
//!   ones), rewritten after every stage;
//! - `samples.csv` — the final population: one column per parameter (with `sigma_m` when the
//!   modelling error is estimated), then `ll` (log-likelihood) and `lp` (log-prior);
//! - `summary.json` — evidence, stop reason, settings, MAP, mean, std, quantiles, failures;
//! - `marginals.json` — 1-D (200 points) and 2-D (50×50) Gaussian KDE marginals.

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde_json::{Map, Value, json};

use iuq_basis::checkpoint::to_json;
use iuq_basis::{
    Basis, BasisError, BasisState, Control, CurveModel, ErrorModel, LogDensityLikelihood,
    LogLikelihood, Observer, PosteriorSummary, PredictionErrorLikelihood, StopReason, marginal_1d,
    marginal_2d, marginal_range,
};
use iuq_core::{Model, ParameterSpace};

use crate::error::{BadInput, Context, Result, input_error};
use crate::likelihood_section::{LikelihoodSection, parse_likelihood};
use crate::study::Study;
use crate::table_io::{write_atomically, write_numeric_csv};

/// The likelihood of a study, with its sampled parameter space.
pub struct StudyPosterior {
    /// The sampled parameters (the study's, and σ_m when the modelling error is estimated).
    pub space: ParameterSpace,
    /// ln f(D | θ).
    pub likelihood: Box<dyn LogLikelihood>,
    /// What the likelihood is, for the summary.
    pub description: Value,
}

/// The likelihood of `study`, with the study's own model ([`Study::model`]) when the
/// `[likelihood]` needs one.
pub fn build_posterior(study: &Study) -> Result<StudyPosterior> {
    build_posterior_with(study, || study.model())
}

/// The likelihood of `study`, comparing the outputs of the model `model()` builds with the data
/// (`model` is called only when the `[likelihood]` needs a model: data without `prediction`).
pub fn build_posterior_with<M: Model + 'static>(
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

/// Writes the checkpoint and the stage table after every stage, hands the state to the caller's
/// observer, and stops after `stop_after`. A checkpoint it cannot write stops the run, and the
/// run's result is that error (`error`).
struct StageWriter<'a> {
    out: PathBuf,
    stop_after: Option<usize>,
    on_stage: &'a mut dyn Observer<BasisState>,
    error: Option<BasisError>,
}

impl Observer<BasisState> for StageWriter<'_> {
    fn observe(&mut self, state: &BasisState) -> Control {
        if let Err(e) = write_checkpoint(&self.out, state) {
            self.error = Some(BasisError::Observer(e.to_string()));
            return Control::Stop;
        }
        if self.on_stage.observe(state) == Control::Stop {
            return Control::Stop;
        }
        if self.stop_after.is_some_and(|s| state.stage >= s) {
            return Control::Stop;
        }
        Control::Continue
    }
}

/// Write `checkpoint.json` (the state, atomically) and the stage tables into `out`.
pub fn write_checkpoint(out: &Path, state: &BasisState) -> Result<()> {
    let text = to_json(state)?;
    write_atomically(&out.join("checkpoint.json"), text.as_bytes())?;
    write_stages(out, state)
}

/// Write the diagnostics of every stage so far: `stages.json` (all of them, failure reasons
/// included) and `stages.csv` (the numeric ones), atomically.
pub fn write_stages(out: &Path, state: &BasisState) -> Result<()> {
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

/// A JSON object of `values` keyed by `names` (in order).
pub fn by_name(names: &[String], values: &[f64]) -> Value {
    Value::Object(
        names
            .iter()
            .zip(values)
            .map(|(k, v)| (k.clone(), json!(v)))
            .collect::<Map<_, _>>(),
    )
}

/// The marginals of a population as JSON: 1-D Gaussian KDEs on 200 points and 2-D ones on
/// 50×50, each on the KDE's natural range clipped to the prior's (`marginals.json`).
pub fn marginals(state: &BasisState, space: &ParameterSpace) -> Value {
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
pub struct SampledPosterior {
    /// The run (final state and stop reason).
    pub run: iuq_basis::BasisRun,
    /// MAP, mean, std and quantiles.
    pub summary: PosteriorSummary,
    /// Wall-clock seconds of this invocation.
    pub seconds: f64,
}

/// Where and how [`sample_posterior`] runs and writes.
pub struct SamplingJob<'a> {
    /// The study's name, labelling the summary.
    pub study_name: &'a str,
    /// The study file, labelling the summary and named in errors.
    pub study_file: &'a Path,
    /// The folder every result file is written into.
    pub out: &'a Path,
    /// An earlier run's state to resume (read from `resume_dir`, named in errors).
    pub checkpoint: Option<BasisState>,
    /// Where `checkpoint` was read from.
    pub resume_dir: Option<&'a Path>,
    /// Stop (resumably) after this stage.
    pub stop_after: Option<usize>,
    /// Write `marginals.json`, the KDE marginals (2,500 grid points × N samples per pair of
    /// parameters: most of a small run's time; the adaptive rounds' replicates leave it out).
    pub marginals: bool,
}

/// Sample `posterior` with BASIS and write every result file into the job's `out` (checkpoint
/// after each stage, `stages.json/csv`, `samples.csv`, `marginals.json` unless the job leaves
/// it out, `summary.json`), resuming the job's `checkpoint` where it has one. After every
/// stage, once its checkpoint is written, `on_stage` sees the state (for progress reports); the
/// run stops (resumably) after the job's `stop_after`.
pub fn sample_posterior(
    job: SamplingJob<'_>,
    posterior: &StudyPosterior,
    settings: iuq_basis::CheckedSettings,
    on_stage: &mut dyn Observer<BasisState>,
) -> Result<SampledPosterior> {
    let SamplingJob {
        study_name,
        study_file,
        out,
        checkpoint,
        resume_dir,
        stop_after,
        marginals: with_marginals,
    } = job;
    let out = out.to_path_buf();
    std::fs::create_dir_all(&out)
        .map_err(|e| input_error(format!("cannot create {}: {e}", out.display())).with_source(e))?;
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
    let mut writer = StageWriter {
        out: out.clone(),
        stop_after,
        on_stage,
        error: None,
    };
    let started = Instant::now();
    let result = match checkpoint {
        Some(state) => basis.resume(state, &mut writer),
        None => basis.run(&mut writer),
    };
    // A checkpoint that could not be written ends the run with its error.
    let result = match writer.error.take() {
        Some(error) => Err(error),
        None => result,
    };
    let run = result.context("BASIS run failed")?;
    let state = &run.state;
    // The final state is also the last checkpoint (a resumed finished run rewrites it).
    write_checkpoint(&out, state)?;

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
    if with_marginals {
        let marginals = marginals(state, &posterior.space);
        write_atomically(
            &out.join("marginals.json"),
            serde_json::to_string(&marginals)?.as_bytes(),
        )?;
    }

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
        seconds: started.elapsed().as_secs_f64(),
        run,
        summary,
    })
}
