//! The pipeline's progress as text lines to a Python callable, and a Ctrl-C as a stop: the
//! observer of `Study.run` and the part of `iuq.calibrate`'s that reports.

use pyo3::prelude::*;

use iuq_core::{Control, Observer};
use iuq_study::campaign_runs::progress_line;
use iuq_study::pipeline::PipelineEvent;

/// Forwards the pipeline's events to a Python callable as text lines (`None`: quiet).
pub struct ProgressObserver {
    callback: Option<Py<PyAny>>,
    error: Option<PyErr>,
    /// A Ctrl-C was seen.
    interrupt: bool,
}

impl ProgressObserver {
    /// Lines to `callback` (`None`: quiet).
    pub fn new(callback: Option<Py<PyAny>>) -> Self {
        Self {
            callback,
            error: None,
            interrupt: false,
        }
    }

    /// The exception the callback raised, if any (taken).
    pub fn take_error(&mut self) -> Option<PyErr> {
        self.error.take()
    }

    fn send(&mut self, line: String) {
        let Some(callback) = &self.callback else {
            return;
        };
        if self.error.is_some() {
            return;
        }
        Python::with_gil(|py| {
            if let Err(e) = callback.bind(py).call1((line,)) {
                self.error = Some(e);
            }
        });
    }
}

impl ProgressObserver {
    /// The event as a line to the callback (if it says anything).
    pub fn show(&mut self, event: &PipelineEvent<'_>) {
        match event {
            PipelineEvent::Message(line) => self.send(format!("pipeline: {line}")),
            PipelineEvent::CampaignProgress { label, progress } => {
                self.send(format!(
                    "pipeline: {label}: {}",
                    progress_line("runs", progress)
                ));
            }
            PipelineEvent::BasisStarted { label } => {
                self.send(format!("basis: sampling the posterior on the {label}"));
            }
            PipelineEvent::BasisStage(state) => {
                if let Some(d) = state.diagnostics.last() {
                    self.send(format!(
                        "basis: stage {}: p = {}, ln Z so far {}, evaluations {}",
                        d.stage, d.exponent, d.log_evidence, state.evaluations
                    ));
                }
            }
            PipelineEvent::BasisFinished | PipelineEvent::Working => {}
        }
    }

    /// A Ctrl-C (a `KeyboardInterrupt` pending on this thread) stops the pipeline; the
    /// exception is raised when it has stopped.
    fn interrupted(&mut self) -> bool {
        if self.error.is_some() {
            return self.interrupt;
        }
        if let Err(e) = Python::with_gil(|py| py.check_signals()) {
            self.error = Some(e);
            self.interrupt = true;
        }
        self.interrupt
    }
}

impl Observer<PipelineEvent<'_>> for ProgressObserver {
    fn observe(&mut self, event: &PipelineEvent<'_>) -> Control {
        self.show(event);
        if self.interrupted() {
            Control::Stop
        } else {
            Control::Continue
        }
    }
}
