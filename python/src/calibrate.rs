//! The engine of `iuq.calibrate`: the calibration pipeline of a study whose model is a Python
//! function (`[model] kind = "callable"`).
//!
//! The pipeline runs its model through a campaign, whose worker threads would call the function
//! one run each. Python code, though, is best run on the thread that called `calibrate` (the
//! main thread): only there does a Ctrl-C raise `KeyboardInterrupt`, also inside the user's
//! function. So each worker hands its run to that thread ([`Request`]) and waits; the caller's
//! thread, which the pipeline asks every few milliseconds whether to stop (its observer, with
//! [`PipelineEvent::Working`] when nothing else happens), evaluates every run waiting in one call of the function
//! (a batch of up to `max_parallel` rows) and answers each worker.
//!
//! A `KeyboardInterrupt` (in the function or between calls), or an exception of the function
//! with `on_error="raise"`, stops the pipeline: the runs under way are answered as interrupted
//! (filed as lost, so a later call runs them again), every finished run stays in the store, and
//! the exception is raised once the pipeline has stopped.

use std::sync::{Arc, Mutex, mpsc};

use pyo3::prelude::*;

use iuq_campaign::{InProcessError, InProcessModel, InProcessOutputs, SharedModel};
use iuq_core::Model;
use iuq_core::{Control, Observer};
use iuq_study::pipeline::PipelineEvent;

use crate::callable::PyModel;
use crate::progress::ProgressObserver;

/// One run waiting for the caller's thread.
struct Request {
    parameters: Vec<f64>,
    reply: mpsc::SyncSender<Result<InProcessOutputs, InProcessError>>,
}

/// The in-process model the campaign sees: it forwards each run to the caller's thread.
struct ForwardedModel {
    requests: Mutex<mpsc::Sender<Request>>,
}

impl InProcessModel for ForwardedModel {
    fn evaluate(&self, parameters: &[f64]) -> Result<InProcessOutputs, InProcessError> {
        let (reply, answer) = mpsc::sync_channel(1);
        let request = Request {
            parameters: parameters.to_vec(),
            reply,
        };
        let sent = self
            .requests
            .lock()
            .map_err(|_| InProcessError::Interrupted)?
            .send(request);
        if sent.is_err() {
            return Err(InProcessError::Interrupted);
        }
        answer.recv().unwrap_or(Err(InProcessError::Interrupted))
    }
}

/// The caller's side: progress lines, and the Python models (the study's, and the cheap one of
/// `[low_fidelity]` where there is one) evaluated for the waiting runs.
pub struct CalibrationObserver {
    progress: ProgressObserver,
    models: Vec<(mpsc::Receiver<Request>, PyModel)>,
    stopped: bool,
    error: Option<PyErr>,
}

/// The model the pipeline is given and the observer that evaluates it on the caller's thread.
pub fn forwarded_models(
    models: Vec<PyModel>,
    progress: Option<Py<PyAny>>,
) -> (Vec<SharedModel>, CalibrationObserver) {
    let mut shared = Vec::with_capacity(models.len());
    let mut served = Vec::with_capacity(models.len());
    for model in models {
        let (sender, requests) = mpsc::channel();
        shared.push(SharedModel(Arc::new(ForwardedModel {
            requests: Mutex::new(sender),
        })));
        served.push((requests, model));
    }
    let observer = CalibrationObserver {
        progress: ProgressObserver::new(progress),
        models: served,
        stopped: false,
        error: None,
    };
    (shared, observer)
}

impl CalibrationObserver {
    /// The exception that stopped the pipeline (a `KeyboardInterrupt`, the model's own, or the
    /// progress callback's), taken.
    pub fn take_error(&mut self) -> Option<PyErr> {
        self.error.take().or_else(|| self.progress.take_error())
    }

    fn stop(&mut self, error: Option<PyErr>) {
        self.stopped = true;
        if self.error.is_none() {
            self.error = error;
        }
    }

    fn evaluate_waiting(&mut self) {
        for k in 0..self.models.len() {
            self.evaluate_waiting_of(k);
        }
    }

    /// The waiting runs of model `k`, in one call of it.
    fn evaluate_waiting_of(&mut self, k: usize) {
        let batch: Vec<Request> = self.models[k].0.try_iter().collect();
        if batch.is_empty() {
            return;
        }
        if self.stopped {
            for request in batch {
                let _ = request.reply.send(Err(InProcessError::Interrupted));
            }
            return;
        }
        let points: Vec<Vec<f64>> = batch.iter().map(|r| r.parameters.clone()).collect();
        match self.models[k].1.evaluate_batch(&points) {
            Ok(outcomes) => {
                for (request, outcome) in batch.into_iter().zip(outcomes) {
                    let answer = match outcome {
                        Ok(e) => Ok((e.outputs, e.computational_std)),
                        Err(f) => Err(InProcessError::Failed(f.reason)),
                    };
                    let _ = request.reply.send(answer);
                }
            }
            Err(_) => {
                let error = self.models[k].1.take_error();
                self.stop(error);
                for request in batch {
                    let _ = request.reply.send(Err(InProcessError::Interrupted));
                }
            }
        }
    }
}

impl Observer<PipelineEvent<'_>> for CalibrationObserver {
    /// The event as a progress line; then the waiting runs are evaluated, and a Ctrl-C or a
    /// failed model stops the pipeline.
    fn observe(&mut self, event: &PipelineEvent<'_>) -> Control {
        self.progress.show(event);
        self.evaluate_waiting();
        if !self.stopped
            && let Err(e) = Python::with_gil(|py| py.check_signals())
        {
            self.stop(Some(e));
        }
        if self.stopped {
            Control::Stop
        } else {
            Control::Continue
        }
    }
}
