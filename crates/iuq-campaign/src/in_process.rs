//! Models computed inside the coordinator's process — a formula, a UM-Bridge server, the native
//! cell model, a Python function — instead of by a command: their runs are recorded, stored,
//! counted, reused and resumed by the campaign exactly as a command's, and the local executor
//! calls [`InProcessModel::evaluate`] on its worker threads where it would start a process.
//!
//! A run of an in-process model cannot be killed at a timeout and dies with the coordinator; a
//! resumed campaign finds it lost and runs it again (the retry policy's `lost`).

use std::sync::Arc;

use crate::outcome::{OutcomeKind, RunResult, TaskReport, host_name, unix_now};
use crate::run_directory::Task;

/// The outputs of one in-process run and, when known, their computational standard deviations.
pub type InProcessOutputs = (Vec<f64>, Option<Vec<f64>>);

/// A model evaluated in this process: `parameters` are a run's values in the campaign's
/// parameter order; the result is the outputs in the campaign's output order, or the reason the
/// run failed.
pub trait InProcessModel: Send + Sync {
    /// Evaluate one run.
    fn evaluate(&self, parameters: &[f64]) -> Result<InProcessOutputs, String>;
}

/// A shared in-process model, as [`crate::CampaignOptions`] carries it.
#[derive(Clone)]
pub struct SharedModel(pub Arc<dyn InProcessModel>);

impl std::fmt::Debug for SharedModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("SharedModel(in-process)")
    }
}

/// Execute `task` with `model`: one evaluation per run, outputs checked for length and
/// finiteness as a command's decoded outputs are.
pub fn execute_in_process(model: &dyn InProcessModel, task: &Task, outputs: usize) -> TaskReport {
    let started_at = unix_now();
    let runs = task
        .runs
        .iter()
        .map(|run| {
            let failure =
                |kind, reason: String| RunResult::failure(run.run_id, run.attempt, kind, reason);
            match model.evaluate(&run.parameters) {
                Err(reason) => failure(OutcomeKind::ExitStatus, reason),
                Ok((values, _)) if values.len() != outputs => failure(
                    OutcomeKind::BadOutput,
                    format!(
                        "the model returned {} outputs, expected {outputs}",
                        values.len()
                    ),
                ),
                Ok((values, std)) if values.iter().any(|v| !v.is_finite()) => {
                    let _ = std;
                    failure(
                        OutcomeKind::NonFinite,
                        format!("the model returned a non-finite output: {values:?}"),
                    )
                }
                Ok((values, std)) => {
                    let std = std.filter(|s| s.len() == values.len());
                    RunResult {
                        run_id: run.run_id,
                        attempt: run.attempt,
                        kind: OutcomeKind::Succeeded,
                        reason: None,
                        outputs: values,
                        std,
                    }
                }
            }
        })
        .collect();
    TaskReport {
        runs,
        exit_code: None,
        signal: None,
        host: host_name(),
        pid: None,
        started_at,
        finished_at: unix_now(),
        stderr_tail: String::new(),
    }
}
