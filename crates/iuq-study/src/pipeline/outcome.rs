//! What the pipeline did: [`PipelineOutcome`], the numbers `iuq pipeline` prints.

use std::path::PathBuf;

use serde_json::Value;

#[cfg(doc)]
use super::PipelineOptions;
use super::adaptive::AdaptiveOutcome;
use super::posterior_check;

/// What the pipeline did: the numbers `iuq pipeline` prints.
#[derive(Debug, Clone, PartialEq)]
pub struct PipelineOutcome {
    /// The study's name.
    pub study: String,
    /// The output directory.
    pub out: PathBuf,
    /// The report page (`None` with [`PipelineOptions::runs_only`]).
    pub report: Option<PathBuf>,
    /// Model runs made by the pipeline in all: the initial and test designs and every adaptive
    /// round, over all run groups (runs reused from the store included).
    pub runs: usize,
    /// How many of them failed.
    pub failed: usize,
    /// Q2 of each stress's GP on its test runs (empty with `runs_only`).
    pub q2: Vec<f64>,
    /// The posterior tables as JSON (as in `pipeline.json`; `null` with `runs_only`).
    pub posterior: Value,
    /// The model's posterior from the surrogate's (summaries, k̂, ESS, MCSE, runs), with
    /// `--model-posterior`.
    pub model_posterior: Option<Value>,
    /// The adaptive engine's rounds, when `[surrogate] adaptive` is given.
    pub adaptive: Option<AdaptiveOutcome>,
    /// The model run at the posterior, when `[surrogate] posterior_check` is given.
    pub posterior_check: Option<posterior_check::PosteriorCheck>,
    /// Wall-clock seconds of each stage, in order.
    pub stage_seconds: Vec<(String, f64)>,
    /// Wall-clock seconds of the whole pipeline.
    pub seconds: f64,
}

impl PipelineOutcome {
    /// The outcome as the JSON object of `iuq pipeline --json` (and the Python package's
    /// `Study.run`): with a report, the runs, convergence, adaptive rounds, Q2, posterior
    /// tables, the posterior check per data point and the wall time of each stage; with
    /// `runs_only`, the runs and where they are.
    pub fn summary(&self) -> Value {
        let out = self.out.display().to_string();
        match &self.report {
            None => serde_json::json!({
                "study": self.study,
                "runs": self.runs,
                "failed": self.failed,
                "out": out,
                "report": Value::Null,
                "seconds": self.seconds,
            }),
            Some(report) => serde_json::json!({
                "study": self.study,
                "out": out,
                "report": report.display().to_string(),
                "runs": self.runs,
                "failed": self.failed,
                // A one-shot design has nothing to converge; an adaptive one says.
                "converged": self.adaptive.as_ref().is_none_or(|a| a.converged),
                "rounds": self.adaptive.as_ref().map_or(0, |a| a.rounds.len()),
                "adaptive": self.adaptive,
                "q2": self.q2,
                "posterior": self.posterior,
                "model_posterior": self.model_posterior,
                // Per data point: the model at the posterior against the surrogate.
                "posterior_check": self.posterior_check.as_ref().map(|c| c.point_summaries()),
                "stage_seconds": self
                    .stage_seconds
                    .iter()
                    .map(|(k, v)| serde_json::json!({"stage": k, "seconds": v}))
                    .collect::<Vec<_>>(),
                "seconds": self.seconds,
            }),
        }
    }
}
