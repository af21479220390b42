//! `iuq pipeline STUDY`: the calibration study end to end (see [`iuq_study::pipeline`]): model
//! runs through the campaign, one GP per stress, Sobol' indices, BASIS, the report in
//! `DIR/report.html`. Progress goes to stderr: `pipeline: …` lines, and every BASIS stage as
//! `iuq basis` shows it.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;

use iuq_core::{Control, Observer};
use iuq_study::Study;
use iuq_study::campaign_runs::progress_line;
use iuq_study::pipeline::{PipelineEvent, PipelineOptions};

use crate::commands::basis::StageProgress;
use crate::report_output::emit;

/// Arguments of `iuq pipeline`.
#[derive(Debug, Args)]
pub struct PipelineArgs {
    /// The study file (TOML): `[parameters]`, a `[model]` of any kind and a `[likelihood]` with
    /// data (docs/pipeline-study-file.md).
    pub study: PathBuf,
    /// Output directory of the report and every stage's results (default: `<study stem>-report`
    /// in the current directory).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Model runs at once (overrides `executor.max_parallel`; default: the number of cores).
    #[arg(long)]
    pub max_parallel: Option<usize>,
    /// Also compute the model's own posterior through the campaign, with `[model_posterior]`:
    /// by default from the surrogate's, by importance stages certified with Pareto-smoothed k̂
    /// (a few hundred model runs); `method = "basis"` samples the model with plain BASIS and
    /// `[model_sampler]` (samples × stages × run groups runs).
    #[arg(long)]
    pub model_posterior: bool,
    /// Recompute every model run: move the campaign directory aside (to `<dir>.previous-N`)
    /// instead of reusing the results it holds.
    #[arg(long)]
    pub fresh: bool,
    /// Stop after the training and test runs (e.g. to make the campaign in a batch job).
    #[arg(long)]
    pub runs_only: bool,
    /// Recompute every adaptive round's surrogate, posterior and surrogate error instead of
    /// reading back what the campaign store recorded for the same runs and settings (a
    /// recomputation that differs from the record is reported).
    #[arg(long)]
    pub recompute_rounds: bool,
}

/// Prints the pipeline's events on stderr (a Ctrl-C ends the process).
#[derive(Default)]
struct StderrObserver {
    basis: Option<StageProgress>,
}

impl Observer<PipelineEvent<'_>> for StderrObserver {
    fn observe(&mut self, event: &PipelineEvent<'_>) -> Control {
        match event {
            PipelineEvent::Message(line) => eprintln!("pipeline: {line}"),
            PipelineEvent::CampaignProgress { label, progress } => {
                eprintln!("pipeline: {label}: {}", progress_line("runs", progress));
            }
            PipelineEvent::BasisStarted { .. } => self.basis = Some(StageProgress::start()),
            PipelineEvent::BasisStage(state) => {
                if let Some(basis) = &self.basis {
                    basis.report(state);
                }
            }
            PipelineEvent::BasisFinished => {
                if let Some(basis) = self.basis.take() {
                    basis.finish();
                }
            }
            PipelineEvent::Working => {}
        }
        Control::Continue
    }
}

/// Run `iuq pipeline`.
pub fn run(args: &PipelineArgs, json_output: bool) -> Result<()> {
    let study = Study::load(&args.study)?;
    let stem = study
        .path
        .file_stem()
        .map_or_else(|| "study".into(), |s| s.to_string_lossy().into_owned());
    let options = PipelineOptions {
        out: args
            .out
            .clone()
            .unwrap_or_else(|| PathBuf::from(format!("{stem}-report"))),
        // 0 is rejected by the pipeline, after the study's own checks.
        max_parallel: args.max_parallel,
        model_posterior: args.model_posterior,
        fresh: args.fresh,
        runs_only: args.runs_only,
        recompute_rounds: args.recompute_rounds,
        callable: None,
        low_fidelity_callable: None,
        // The process ends on a Ctrl-C anyway; a stop asked otherwise waits for the pipeline.
        interrupt_grace: None,
    };
    let outcome = iuq_study::pipeline::run(&study, &options, &mut StderrObserver::default())?;
    let out = &outcome.out;
    let value = outcome.summary();
    match &outcome.report {
        None => {
            emit(json_output, &value, || {
                format!(
                    "{} model runs of `{}` done ({} failed); results in {}",
                    outcome.runs,
                    outcome.study,
                    outcome.failed,
                    out.display()
                )
            });
        }
        Some(report) => {
            emit(json_output, &value, || {
                let adaptive = match &outcome.adaptive {
                    Some(a) => format!(
                        "; {} model runs in {} adaptive rounds, {} ({})",
                        outcome.runs,
                        a.rounds.len(),
                        if a.converged {
                            "converged"
                        } else {
                            "not converged"
                        },
                        a.stop_reason
                    ),
                    None => format!("; {} model runs", outcome.runs),
                };
                format!(
                    "study `{}`: report in {} ({:.1} s){adaptive}",
                    outcome.study,
                    report.display(),
                    outcome.seconds
                )
            });
        }
    }
    Ok(())
}
