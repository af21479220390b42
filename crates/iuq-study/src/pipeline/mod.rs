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
//! | `options`, `outcome`, `events` | [`PipelineOptions`], [`PipelineOutcome`], [`PipelineEvent`] and the [`PipelineObserver`] |
//! | `stages`, `designs`, `records` | the stages in order over their run context; the data and designs they compute on; what they keep (`model-runs.csv`, stage times, checkpoints) |

pub mod adaptive;
mod adaptive_report;
mod array_outputs;
mod campaign_text;
pub mod cell_model_campaign;
pub mod cell_portraits;
mod designs;
pub mod emulator;
mod events;
pub mod low_fidelity;
pub mod model_posterior;
pub mod model_runs;
mod options;
mod outcome;
pub mod posterior_check;
mod records;
pub mod replicated_likelihood;
pub mod report_data;
pub mod reproducibility_probe;
pub mod run_groups;
pub mod settings;
mod stages;
pub mod surrogate;

use std::sync::mpsc;

use iuq_campaign::Interrupt;
use iuq_core::Control;

use crate::error::{Result, StudyError};
use crate::study::Study;
use events::Events;
pub use events::{POLL_INTERVAL, PipelineEvent, PipelineObserver};
pub use options::PipelineOptions;
pub use outcome::PipelineOutcome;
pub use settings::PIPELINE_FINAL_SAMPLES;

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
