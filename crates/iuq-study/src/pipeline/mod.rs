//! The calibration study end to end (`iuq pipeline STUDY`), as a library: [`run`].
//!
//! 1. the training design (a maximin Latin hypercube per stress) and an independent test design
//!    (scrambled Sobol' points) run through the campaign executor — every result the campaign
//!    store already holds is reused;
//! 2. one GP per stress, validated by Q2 on the test runs (and leave-one-out Q2);
//! 3. Sobol' indices per stress from the surrogate and, with `[sensitivity] model_n`, from model
//!    runs;
//! 4. BASIS on the GP bank and, with [`PipelineOptions::model_posterior`], the model's own
//!    posterior from it through the campaign ([`model_posterior`]: certified importance stages,
//!    `[model_posterior]`; or plain BASIS on the model, `method = "basis"` with
//!    `[model_sampler]`);
//! 5. posterior summaries and the propagation of the posterior to the outputs;
//! 6. the report: `DIR/report.html` with every figure as SVG and PNG and every table as CSV/JSON.
//!
//! While it works, the pipeline reports to a [`PipelineObserver`] (iuq's one observer shape,
//! [`iuq_core::Observer`], of [`PipelineEvent`]s): news, the progress of the campaign's model
//! runs and every BASIS stage; the observer's [`Control`] says whether the pipeline goes on. The
//! stages run on a thread of their own and the events reach the observer on the caller's thread,
//! so an observer need not be `Send`.
//!
//! | module | what |
//! |---|---|
//! | [`model_runs`] | the study's model (any kind) as a campaign; how runs map to data points |
//! | [`cell_model_campaign`] | the cell model's campaign: `iuq rbc shear` runs, or in this process |
//! | [`run_groups`] | the runs made, by run group and origin (initial, test, adaptive round) |
//! | [`surrogate`] | GPs per data point and failure classifiers, as a model for BASIS |
//! | [`adaptive`] | the adaptive engine: new runs where the posterior lies, until it converges |
//! | [`model_posterior`] | the model's own posterior from the surrogate's |
//! | [`cell_portraits`] | the cell at the MAP in pictures (shapes, elongation against strain) |
//! | [`settings`] | the pipeline's settings from `[surrogate]` and `[sensitivity]` |
//! | [`report_data`] | from the results to the report and `pipeline.json` |

pub mod adaptive;
mod adaptive_report;
mod array_outputs;
mod campaign_text;
pub mod cell_model_campaign;
pub mod cell_portraits;
pub mod emulator;
pub mod low_fidelity;
pub mod model_posterior;
pub mod model_runs;
pub mod posterior_check;
pub mod replicated_likelihood;
pub mod report_data;
pub mod reproducibility_probe;
pub mod run_groups;
pub mod settings;
mod stages;
pub mod surrogate;

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Instant;

use serde_json::Value;

use iuq_basis::BasisState;
use iuq_campaign::campaign_model::ProgressObserver;
use iuq_campaign::{Interrupt, Progress, SharedModel};
use iuq_core::{Control, Observer, ParameterSpace};
use iuq_doe::{LhsMethod, Scrambling, latin_hypercube, sobol_points};
use iuq_sensitivity::{IntervalMethod, SensitivityOptions};

use crate::error::{BadInput, Context, Result, StudyError, input_error};
use crate::likelihood_section::{DataLikelihood, LikelihoodSection, parse_likelihood};
use crate::posterior::{SampledPosterior, sample_posterior};
use crate::study::{ModelSection, Study};
use crate::table_io::write_numeric_csv;
use adaptive::AdaptiveOutcome;
use model_runs::ModelRuns;
use report_data::PointRuns;
use run_groups::GroupRuns;
use settings::PipelineSettings;

/// How to run the pipeline (the flags of `iuq pipeline`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PipelineOptions {
    /// Output directory of the report and every stage's results (created when missing).
    pub out: PathBuf,
    /// Model runs at once (overrides `executor.max_parallel`; `None`: the number of cores; 0 is
    /// an input error).
    pub max_parallel: Option<usize>,
    /// Also give the model's own posterior, through the campaign: from the surrogate's by
    /// certified importance stages (`[model_posterior]`, a few hundred runs per run group), or
    /// with `[model_posterior] method = "basis"` by BASIS on the model (`[model_sampler]`:
    /// samples × stages runs per run group).
    pub model_posterior: bool,
    /// Recompute every model run: move the campaign directory aside (to `<dir>.previous-N`)
    /// instead of reusing the results it holds.
    pub fresh: bool,
    /// Stop after the training and test runs (e.g. to make the campaign in a batch job).
    pub runs_only: bool,
    /// Recompute every adaptive round's measurement (surrogate fit, replicate samplers,
    /// surrogate error) instead of reading back the one the campaign store recorded for the
    /// same inputs; a recomputed measurement that differs from the recorded one is reported.
    pub recompute_rounds: bool,
    /// The model of a study whose `[model]` is of kind `callable`: supplied by the program that
    /// runs the study (the Python package's `iuq.calibrate`), evaluated in this process.
    pub callable: Option<SharedModel>,
    /// The cheap model of a `[low_fidelity]` of kind `callable`, supplied as `callable` is.
    pub low_fidelity_callable: Option<SharedModel>,
    /// How long [`run`] waits, once its observer asked it to stop, for the pipeline to reach its
    /// next check (between model runs, sampler stages, adaptive rounds). Past it, `run` returns
    /// [`StudyError::Interrupted`] at once and leaves the pipeline's thread to stop on its own
    /// (a GP fit or a sampler stage on many runs can take seconds); the next [`run`] in this
    /// process waits for such a thread before it starts, so two pipelines never share a store.
    /// `None` (the CLI's): wait for the thread.
    pub interrupt_grace: Option<std::time::Duration>,
}

/// What the pipeline reports while it works.
#[derive(Debug, Clone, Copy)]
pub enum PipelineEvent<'a> {
    /// A line of news: the runs to make, a resumed campaign or posterior, a campaign moved aside
    /// (`iuq pipeline` prints it as `pipeline: <line>`).
    Message(&'a str),
    /// Where the campaign of model runs stands (every 10 s while runs are under way); `label`
    /// names the runs (`model runs`).
    CampaignProgress {
        /// What the runs are.
        label: &'a str,
        /// The campaign's counts, elapsed time and ETA.
        progress: &'a Progress,
    },
    /// A BASIS run starts; `label` says on what (`GP bank`, `cell model`).
    BasisStarted {
        /// What the posterior is sampled on.
        label: &'a str,
    },
    /// A stage of the BASIS run is done and its checkpoint written.
    BasisStage(&'a BasisState),
    /// The BASIS run is over (converged, stopped or failed).
    BasisFinished,
    /// No news: the pipeline is at work. The observer sees it whenever [`POLL_INTERVAL`] passes
    /// without another event, so that it can stop the pipeline or serve a model evaluated on
    /// its thread.
    Working,
}

/// Receives the [`PipelineEvent`]s of a pipeline on the thread that called [`run`] and says
/// whether the pipeline goes on: an [`iuq_core::Observer`] of every `PipelineEvent`, which any
/// `FnMut(&PipelineEvent<'_>) -> Control` is.
///
/// It is called after every event and at least every [`POLL_INTERVAL`]
/// ([`PipelineEvent::Working`]) while the pipeline works, and asked again after it answered
/// [`Control::Stop`]. `Stop` stops the pipeline at its next check (between model runs, sampler
/// stages and adaptive rounds), which then returns [`StudyError::Interrupted`] with every
/// finished model run stored. An embedding program looks for a Ctrl-C here.
pub trait PipelineObserver: for<'a> Observer<PipelineEvent<'a>> {}

impl<T: for<'a> Observer<PipelineEvent<'a>> + ?Sized> PipelineObserver for T {}

/// How often the pipeline asks its observer whether to stop when nothing else happens
/// ([`PipelineEvent::Working`]).
pub const POLL_INTERVAL: std::time::Duration = std::time::Duration::from_millis(5);

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

/// Run the calibration study `study` end to end with `options`, reporting to `observer`.
///
/// Errors are [`StudyError::BadInput`] for a study, data file or option that cannot be used
/// (naming the file, key and reason) and [`StudyError::Failure`] for failed work.
pub fn run(
    study: &Study,
    options: &PipelineOptions,
    observer: &mut dyn PipelineObserver,
) -> Result<PipelineOutcome> {
    wait_for_interrupted_pipelines(observer);
    let (sender, receiver) = mpsc::channel();
    let interrupt = Interrupt::default();
    let stages_interrupt = interrupt.clone();
    let (stages_study, stages_options) = (study.clone(), options.clone());
    let stages = std::thread::Builder::new()
        .name("iuq-pipeline".into())
        // as much stack as a main thread gets
        .stack_size(8 << 20)
        .spawn(move || {
            stages::run_stages(
                &stages_study,
                &stages_options,
                &Events {
                    sender,
                    interrupt: stages_interrupt,
                },
            )
        })
        .map_err(|e| {
            StudyError::failure(format!("cannot start the pipeline's thread: {e}")).with_source(e)
        })?;
    let mut asked_to_stop: Option<std::time::Instant> = None;
    // Ends when the stages are done and every sender (the campaign's progress observer's too)
    // is dropped.
    loop {
        // Asked every time, also once it said stop: the observer may serve the model (a Python
        // function evaluated on this thread) and must go on answering the runs under way.
        let control = match receiver.recv_timeout(POLL_INTERVAL) {
            Ok(event) => observer.observe(&event.borrowed()),
            Err(mpsc::RecvTimeoutError::Timeout) => observer.observe(&PipelineEvent::Working),
            Err(mpsc::RecvTimeoutError::Disconnected) => break,
        };
        if control == Control::Stop {
            interrupt.raise();
            asked_to_stop.get_or_insert_with(std::time::Instant::now);
        }
        if let (Some(asked), Some(grace)) = (asked_to_stop, options.interrupt_grace)
            && asked.elapsed() >= grace
        {
            INTERRUPTED_PIPELINES
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .push(stages);
            return Err(StudyError::Interrupted);
        }
    }
    match stages.join() {
        Ok(result) => result,
        Err(panic) => std::panic::resume_unwind(panic),
    }
}

/// The threads of pipelines that [`run`] returned from before they stopped
/// ([`PipelineOptions::interrupt_grace`]), each stopping at its next check.
static INTERRUPTED_PIPELINES: std::sync::Mutex<
    Vec<std::thread::JoinHandle<Result<PipelineOutcome>>>,
> = std::sync::Mutex::new(Vec::new());

/// Wait until every pipeline thread an interrupted [`run`] left behind has stopped (they may
/// hold the same campaign store), telling `observer` when there is one to wait for.
fn wait_for_interrupted_pipelines(observer: &mut dyn PipelineObserver) {
    let waiting: Vec<_> = INTERRUPTED_PIPELINES
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .drain(..)
        .collect();
    if waiting.iter().any(|t| !t.is_finished()) {
        // Nothing runs yet that a stop could end: the run's first check takes the answer.
        let _ = observer.observe(&PipelineEvent::Message(
            "waiting for the interrupted pipeline to reach its next check and stop",
        ));
    }
    for thread in waiting {
        // Its outcome is an interruption or an error nobody asked for any more.
        let _ = thread.join();
    }
}

/// An event on its way from the pipeline's thread to the observer.
enum OwnedEvent {
    Message(String),
    CampaignProgress {
        label: &'static str,
        progress: Progress,
    },
    BasisStarted {
        label: &'static str,
    },
    BasisStage(Box<BasisState>),
    BasisFinished,
}

impl OwnedEvent {
    fn borrowed(&self) -> PipelineEvent<'_> {
        match self {
            Self::Message(m) => PipelineEvent::Message(m),
            Self::CampaignProgress { label, progress } => {
                PipelineEvent::CampaignProgress { label, progress }
            }
            Self::BasisStarted { label } => PipelineEvent::BasisStarted { label },
            Self::BasisStage(state) => PipelineEvent::BasisStage(state),
            Self::BasisFinished => PipelineEvent::BasisFinished,
        }
    }
}

/// The sending end of the events (an observer that has gone away is not an error).
struct Events {
    sender: mpsc::Sender<OwnedEvent>,
    /// Raised when the observer asks the pipeline to stop.
    interrupt: Interrupt,
}

impl Events {
    fn send(&self, event: OwnedEvent) {
        let _ = self.sender.send(event);
    }

    /// [`StudyError::Interrupted`] once the observer has asked the pipeline to stop.
    fn check_interrupt(&self) -> Result<()> {
        if self.interrupt.is_raised() {
            Err(StudyError::Interrupted)
        } else {
            Ok(())
        }
    }

    fn message(&self, line: String) {
        self.send(OwnedEvent::Message(line));
    }

    /// Sample `posterior` with BASIS into `dir` (resuming `checkpoint`, read from `dir`),
    /// reporting the start, every stage and the end under `label`.
    fn sample(
        &self,
        label: &'static str,
        study: &Study,
        posterior: &crate::posterior::StudyPosterior,
        settings: iuq_basis::CheckedSettings,
        dir: &Path,
        checkpoint: Option<BasisState>,
    ) -> Result<SampledPosterior> {
        self.send(OwnedEvent::BasisStarted { label });
        let job = crate::posterior::SamplingJob {
            study_name: &study.name,
            study_file: &study.path,
            out: dir,
            checkpoint,
            resume_dir: Some(dir),
            stop_after: None,
            // A round's replicates are read for their moments and populations only.
            marginals: label != adaptive::ROUND_LABEL,
        };
        let sampled = sample_posterior(job, posterior, settings, &mut |state: &BasisState| {
            self.send(OwnedEvent::BasisStage(Box::new(state.clone())));
            if self.interrupt.is_raised() {
                Control::Stop
            } else {
                Control::Continue
            }
        });
        self.send(OwnedEvent::BasisFinished);
        self.check_interrupt()?;
        sampled
    }

    /// The campaign's progress observer, forwarding to the pipeline's observer.
    fn campaign_progress(&self, label: &'static str) -> ProgressObserver {
        let sender = self.sender.clone();
        Box::new(move |progress: &Progress| {
            let _ = sender.send(OwnedEvent::CampaignProgress {
                label,
                progress: progress.clone(),
            });
        })
    }
}

/// The final surrogate posterior's population where `[sampler]` gives no `samples` (that of
/// `iuq.calibrate`'s default).
pub const PIPELINE_FINAL_SAMPLES: usize = 10_000;

/// The study's data (the pipeline calibrates a model on data).
fn study_data(study: &Study) -> Result<DataLikelihood> {
    let file = study.path.display();
    match parse_likelihood(study)? {
        LikelihoodSection::Data(data) if data.prediction.is_none() => Ok(data),
        _ => Err(input_error(format!(
            "{file}: section `[likelihood]`: the pipeline calibrates the model on data: give `data = {{ file, x, y, ... }}` without `prediction`"
        ))),
    }
}

/// The initial points of run group g: a maximin Latin hypercube mapped through the priors.
fn training_points(
    space: &ParameterSpace,
    settings: &PipelineSettings,
    g: usize,
) -> Result<Vec<Vec<f64>>> {
    let unit = latin_hypercube(
        settings.training_runs,
        space.dimension(),
        LhsMethod::Maximin {
            candidates: settings.maximin_candidates,
        },
        settings.training_seed.wrapping_add(g as u64),
    )?;
    unit.iter()
        .map(|u| space.from_unit_cube(u).map_err(StudyError::from))
        .collect()
}

/// The test points (the same in every group): scrambled Sobol' points through the priors.
fn test_points(space: &ParameterSpace, settings: &PipelineSettings) -> Result<Vec<Vec<f64>>> {
    if settings.test_runs == 0 {
        return Ok(Vec::new());
    }
    let unit = sobol_points(
        space.dimension(),
        settings.test_runs,
        Scrambling::LinearMatrixWithShift {
            seed: settings.test_seed,
            replicate: 0,
        },
    )?;
    unit.iter()
        .map(|u| space.from_unit_cube(u).map_err(StudyError::from))
        .collect()
}

/// Move `dir` aside to the first free `<dir>.previous-N`.
fn move_aside(dir: &Path) -> Result<Option<PathBuf>> {
    if !dir.exists() {
        return Ok(None);
    }
    for k in 1.. {
        let target = PathBuf::from(format!("{}.previous-{k}", dir.display()));
        if !target.exists() {
            std::fs::rename(dir, &target)
                .with_context(|| format!("cannot move {} aside", dir.display()))?;
            return Ok(Some(target));
        }
    }
    Ok(None)
}

/// Sobol' options of the pipeline with `n` base points.
fn sobol_options(settings: &PipelineSettings, n: usize) -> SensitivityOptions {
    SensitivityOptions {
        base_points: n,
        seed: settings.sobol_seed,
        interval: IntervalMethod::Bootstrap {
            resamples: settings.resamples,
        },
        confidence_level: settings.confidence,
        ..Default::default()
    }
}

/// How a data point is named in messages: "at 1.36 Pa" for the cell model, "at t = 0.5"
/// otherwise.
fn point_description(study: &Study, data: &DataLikelihood, j: usize) -> String {
    match (&study.model, &study.abscissa) {
        (ModelSection::RbcShear { .. }, _) => format!("at {} Pa", data.x[j]),
        (_, Some(name)) => format!("at {name} = {}", data.x[j]),
        (_, None) => format!("at {} = {} (output {})", data.x_column, data.x[j], j + 1),
    }
}

/// The runs of each data point, for the report and `model-runs.csv`.
fn point_runs(groups: &[GroupRuns], runs: &ModelRuns, data: &DataLikelihood) -> Vec<PointRuns> {
    let mut points = Vec::with_capacity(data.x.len());
    for (g, group) in groups.iter().enumerate() {
        for (k, j) in runs.group_outputs(g).enumerate() {
            let training = group.training(k);
            let test = group.test(k);
            points.push(PointRuns {
                x: data.x[j],
                training_x: training.x,
                training_y: training.y,
                training_std: training.std,
                test_x: test.x,
                test_y: test.y,
                test_std: test.std,
                failures: group.failure_reasons(),
            });
        }
    }
    points
}

/// Add the time since `since` to the stage `label` (a stage repeated after a failed posterior
/// check counts every pass).
fn add_seconds(stage_seconds: &mut Vec<(String, f64)>, label: &str, since: Instant) {
    let seconds = since.elapsed().as_secs_f64();
    match stage_seconds.iter_mut().find(|(l, _)| l == label) {
        Some((_, total)) => *total += seconds,
        None => stage_seconds.push((label.to_string(), seconds)),
    }
}

fn resume_checkpoint(dir: &Path, events: &Events) -> Result<Option<BasisState>> {
    let path = dir.join("checkpoint.json");
    if !path.exists() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("cannot read {}", path.display()))?;
    let state = iuq_basis::checkpoint::from_json(&text)
        .bad_input(|| format!("{}: not a BASIS checkpoint", path.display()))?;
    events.message(format!(
        "resuming the model posterior from {}",
        path.display()
    ));
    Ok(Some(state))
}

fn write_runs_csv(path: &Path, names: &[String], runs: &[PointRuns]) -> Result<()> {
    let mut columns = vec!["x".to_string(), "set".to_string()];
    columns.extend(names.iter().cloned());
    columns.push("y".into());
    columns.push("y_std".into());
    let mut rows = Vec::new();
    for r in runs {
        for (set, xs, ys, ss) in [
            (0.0, &r.training_x, &r.training_y, &r.training_std),
            (1.0, &r.test_x, &r.test_y, &r.test_std),
        ] {
            for ((x, y), s) in xs.iter().zip(ys).zip(ss) {
                let mut row = vec![r.x, set];
                row.extend(x.iter().copied());
                row.push(*y);
                row.push(*s);
                rows.push(row);
            }
        }
    }
    write_numeric_csv(path, &columns, &rows)
}
