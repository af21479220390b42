//! Models computed inside the coordinator's process — a formula, a UM-Bridge server, the native
//! cell model, a Python function — instead of by a command: their runs are recorded, stored,
//! counted, reused and resumed by the campaign exactly as a command's, and the local executor
//! calls [`InProcessModel::evaluate`] on its worker threads where it would start a process.
//!
//! A run of an in-process model cannot be killed at a timeout and dies with the coordinator; a
//! resumed campaign finds it lost and runs it again (the retry policy's `lost`). A model that
//! cannot be reached ([`InProcessError::Unavailable`]) is an infrastructure failure, retried by
//! default; a panic of the model is the run's failure.

use std::sync::Arc;

use crate::outcome::{OutcomeKind, RunResult, TaskReport, host_name, unix_now};
use crate::run_directory::Task;

/// The outputs of one in-process run and, when known, their computational standard deviations.
pub type InProcessOutputs = (Vec<f64>, Option<Vec<f64>>);

/// Why an in-process run gave no outputs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum InProcessError {
    /// The model's answer at these parameters is a failure (a solver that diverged, a mesh that
    /// broke): stored as the run's outcome.
    Failed(String),
    /// The model could not be evaluated (a server down, a connection lost): an infrastructure
    /// failure, which the retry policy retries by default.
    Unavailable(String),
    /// The run was stopped before it finished (the user interrupted the program evaluating the
    /// model): filed as lost, so the retry policy runs it again.
    Interrupted,
}

/// A model evaluated in this process: `parameters` are a run's values in the campaign's
/// parameter order; the result is the outputs in the campaign's output order, or why there are
/// none.
pub trait InProcessModel: Send + Sync {
    /// Evaluate one run.
    fn evaluate(&self, parameters: &[f64]) -> Result<InProcessOutputs, InProcessError>;
}

/// A shared in-process model, as [`crate::CampaignOptions`] carries it.
#[derive(Clone)]
pub struct SharedModel(pub Arc<dyn InProcessModel>);

impl PartialEq for SharedModel {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }
}

impl Eq for SharedModel {}

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
            // A panic of the model is the run's failure, not the worker thread's end (which would
            // leave the coordinator waiting for a run that never finishes).
            let evaluated = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                model.evaluate(&run.parameters)
            }))
            .unwrap_or_else(|panic| {
                let message = panic
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| panic.downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "no message".into());
                Err(InProcessError::Failed(format!(
                    "the model panicked: {message}"
                )))
            });
            match evaluated {
                Err(InProcessError::Failed(reason)) => failure(OutcomeKind::ExitStatus, reason),
                Err(InProcessError::Unavailable(reason)) => {
                    failure(OutcomeKind::Infrastructure, reason)
                }
                Err(InProcessError::Interrupted) => {
                    failure(OutcomeKind::Lost, "interrupted before it finished".into())
                }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::run_directory::TaskRun;

    struct Model;

    impl InProcessModel for Model {
        fn evaluate(&self, p: &[f64]) -> Result<InProcessOutputs, InProcessError> {
            match p[0] as i64 {
                0 => Ok((vec![p[0] + 1.0], None)),
                1 => Err(InProcessError::Failed("diverged".into())),
                2 => Err(InProcessError::Unavailable("connection refused".into())),
                3 => Ok((vec![f64::NAN], None)),
                4 => Ok((vec![1.0, 2.0], None)),
                _ => panic!("boom"),
            }
        }
    }

    #[test]
    fn outcomes_failures_unavailability_and_panics_become_run_results() {
        let task = Task {
            directory: std::env::temp_dir(),
            runs: (0..6)
                .map(|i| TaskRun {
                    run_id: i,
                    attempt: 1,
                    parameters: vec![i as f64],
                })
                .collect(),
        };
        let report = execute_in_process(&Model, &task, 1);
        let kinds: Vec<OutcomeKind> = report.runs.iter().map(|r| r.kind).collect();
        assert_eq!(
            kinds,
            vec![
                OutcomeKind::Succeeded,
                OutcomeKind::ExitStatus,
                OutcomeKind::Infrastructure,
                OutcomeKind::NonFinite,
                OutcomeKind::BadOutput,
                OutcomeKind::ExitStatus,
            ]
        );
        assert_eq!(report.runs[0].outputs, vec![1.0]);
        assert!(
            report.runs[5]
                .reason
                .as_deref()
                .unwrap()
                .contains("panicked: boom")
        );
    }
}
