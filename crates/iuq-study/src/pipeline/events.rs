//! What the pipeline reports while it works ([`PipelineEvent`], [`PipelineObserver`]) and how its
//! thread sends it: [`Events`], which also carries the observer's request to stop.

use std::path::Path;
use std::sync::mpsc;

use iuq_basis::BasisState;
use iuq_campaign::campaign_model::ProgressObserver;
use iuq_campaign::{Interrupt, Progress};
use iuq_core::{Control, Observer};

use crate::error::{Result, StudyError};
use crate::posterior::{SampledPosterior, sample_posterior};
use crate::study::Study;

/// The label of a round's replicates in the pipeline's events (their folders get no
/// `marginals.json`).
pub(super) const ROUND_LABEL: &str = "adaptive round";

/// How often the pipeline asks its observer whether to stop when nothing else happens
/// ([`PipelineEvent::Working`]).
pub const POLL_INTERVAL: std::time::Duration = std::time::Duration::from_millis(5);

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

/// Receives the [`PipelineEvent`]s of a pipeline on the thread that called [`run`](super::run) and says
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

/// An event on its way from the pipeline's thread to the observer.
pub(super) enum OwnedEvent {
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
    pub(super) fn borrowed(&self) -> PipelineEvent<'_> {
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
pub(super) struct Events {
    pub(super) sender: mpsc::Sender<OwnedEvent>,
    /// Raised when the observer asks the pipeline to stop.
    pub(super) interrupt: Interrupt,
}

impl Events {
    pub(super) fn send(&self, event: OwnedEvent) {
        let _ = self.sender.send(event);
    }

    /// [`StudyError::Interrupted`] once the observer has asked the pipeline to stop.
    pub(super) fn check_interrupt(&self) -> Result<()> {
        if self.interrupt.is_raised() {
            Err(StudyError::Interrupted)
        } else {
            Ok(())
        }
    }

    pub(super) fn message(&self, line: String) {
        self.send(OwnedEvent::Message(line));
    }

    /// Sample `posterior` with BASIS into `dir` (resuming `checkpoint`, read from `dir`),
    /// reporting the start, every stage and the end under `label`.
    pub(super) fn sample(
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
            marginals: label != ROUND_LABEL,
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

    /// The campaign's progress observer, forwarding to the pipeline's observer; it stops the
    /// campaign once the pipeline's observer has asked the pipeline to stop.
    pub(super) fn campaign_progress(&self, label: &'static str) -> ProgressObserver {
        let sender = self.sender.clone();
        let interrupt = self.interrupt.clone();
        Box::new(move |progress: &Progress| {
            let _ = sender.send(OwnedEvent::CampaignProgress {
                label,
                progress: progress.clone(),
            });
            if interrupt.is_raised() {
                Control::Stop
            } else {
                Control::Continue
            }
        })
    }
}
