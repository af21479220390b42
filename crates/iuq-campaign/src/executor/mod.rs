//! Executors: where tasks run. The coordinator submits tasks, waits for events (a task started,
//! a run finished) and, after a crash, hands the executor the tasks an earlier coordinator left
//! open so that it can reattach to them or declare them lost.
//!
//! | executor | tasks run as | state from |
//! |---|---|---|
//! | [`local`] | processes of this machine, `max_parallel` at once | the worker threads |
//! | [`slurm`] | `sbatch` job arrays (throttled, chunked below MaxArraySize) running `iuq worker` | `squeue`, `scontrol`, the workers' `result.json` (never `sacct`) |
//! | [`hyperqueue`] | `hq submit --array` task arrays running `iuq worker` | `hq --output-mode=json job info`, the workers' `result.json` |

pub mod hyperqueue;
mod job_array;
pub mod local;
pub mod slurm;

use std::time::{Duration, Instant};

use crate::error::Result;
use crate::outcome::{OutcomeKind, RunResult, TaskReport};
use crate::run_directory::Task;
use crate::study::ExecutorKind;

/// A task with the attempt row of each of its runs (parallel to `task.runs`).
#[derive(Debug, Clone, PartialEq)]
pub struct SubmittedTask {
    /// The task.
    pub task: Task,
    /// The store's attempt id of each run of the task.
    pub attempt_ids: Vec<i64>,
}

/// A task left open by an earlier coordinator, with the scheduler ids known for it.
#[derive(Debug, Clone, PartialEq)]
pub struct OpenTask {
    /// The task and its attempts.
    pub submitted: SubmittedTask,
    /// The scheduler's id of the task, when the store has one.
    pub external_id: Option<String>,
}

/// Something that happened to a submitted task.
#[derive(Debug, Clone, PartialEq)]
pub enum ExecutorEvent {
    /// The attempt started.
    Started {
        /// The attempt.
        attempt_id: i64,
        /// The scheduler's id, when known.
        external_id: Option<String>,
        /// The host it runs on, when known.
        host: Option<String>,
        /// When it started (seconds since the epoch).
        started_at: f64,
    },
    /// The attempt ended.
    Finished {
        /// The attempt.
        attempt_id: i64,
        /// Its result.
        result: RunResult,
        /// The report of the task it ran in, when the worker wrote one.
        report: Option<TaskReport>,
    },
}

/// An executor of tasks.
pub trait Executor: Send {
    /// Which executor this is.
    fn kind(&self) -> ExecutorKind;

    /// How many tasks may be in flight at once.
    fn capacity(&self) -> usize;

    /// Tasks submitted and not yet finished.
    fn in_flight(&self) -> usize;

    /// Submit tasks; returns the scheduler's id of each attempt where one is known at once.
    fn submit(&mut self, tasks: Vec<SubmittedTask>) -> Result<Vec<(i64, String)>>;

    /// Wait up to `timeout` for events (returns early as soon as there are some).
    fn wait(&mut self, timeout: Duration) -> Result<Vec<ExecutorEvent>>;

    /// Take over tasks submitted by an earlier coordinator of this executor kind whose results
    /// were not found: keep tracking those still running, and return events for the others
    /// (finished, or lost).
    fn reattach(&mut self, tasks: Vec<OpenTask>) -> Result<Vec<ExecutorEvent>>;

    /// Start none of the submitted tasks that have not started yet (the campaign was asked to
    /// stop): each is reported finished with its runs lost, "interrupted before it started",
    /// so that a later campaign runs them; tasks under way go on. An executor whose tasks
    /// start elsewhere (a scheduler's queue) has nothing to hold back.
    fn stop_starting(&mut self) {}

    /// Start submitted tasks again after [`Executor::stop_starting`]: the campaign is run again
    /// after it stopped (every task held back then has been reported, so none is waiting).
    fn resume_starting(&mut self) {}
}

/// Events for every run of `task` from its worker report; runs missing from the report fail as
/// infrastructure failures.
pub fn report_events(task: &SubmittedTask, report: TaskReport) -> Vec<ExecutorEvent> {
    task.task
        .runs
        .iter()
        .zip(&task.attempt_ids)
        .map(|(run, &attempt_id)| {
            let result = report
                .runs
                .iter()
                .find(|r| r.run_id == run.run_id && r.attempt == run.attempt)
                .cloned()
                .unwrap_or_else(|| {
                    RunResult::failure(
                        run.run_id,
                        run.attempt,
                        OutcomeKind::Infrastructure,
                        "the worker's report does not mention this run",
                    )
                });
            ExecutorEvent::Finished {
                attempt_id,
                result,
                report: Some(report.clone()),
            }
        })
        .collect()
}

/// `Finished` events failing every run of `task` with `kind` and `reason`.
pub fn failure_events(task: &SubmittedTask, kind: OutcomeKind, reason: &str) -> Vec<ExecutorEvent> {
    task.task
        .runs
        .iter()
        .zip(&task.attempt_ids)
        .map(|(run, &attempt_id)| ExecutorEvent::Finished {
            attempt_id,
            result: RunResult::failure(run.run_id, run.attempt, kind, reason),
            report: None,
        })
        .collect()
}

/// True when `report` is the report of exactly this attempt of the task (not a stale one).
pub fn report_matches(task: &SubmittedTask, report: &TaskReport) -> bool {
    task.task.runs.iter().all(|run| {
        report
            .runs
            .iter()
            .any(|r| r.run_id == run.run_id && r.attempt == run.attempt)
    })
}

/// Run an external program (a scheduler's CLI) and return its standard output; a failure to
/// start it or a non-zero exit is an executor error naming the command and its stderr.
pub fn run_cli(executor: &'static str, program: &str, args: &[String]) -> Result<String> {
    let output = std::process::Command::new(program)
        .args(args)
        .stdin(std::process::Stdio::null())
        .output()
        .map_err(|e| {
            crate::error::CampaignError::executor(executor, format!("cannot run `{program}`: {e}"))
        })?;
    if !output.status.success() {
        return Err(crate::error::CampaignError::executor(
            executor,
            format!(
                "`{program} {}` failed ({}): {}",
                args.join(" "),
                output.status,
                String::from_utf8_lossy(&output.stderr).trim()
            ),
        ));
    }
    Ok(String::from_utf8_lossy(&output.stdout).into_owned())
}

/// Quote `s` for a POSIX shell script.
pub fn shell_quote(s: &str) -> String {
    if !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "/._-=:+,@".contains(c))
    {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', "'\\''"))
    }
}

/// For the schedulers that are polled (Slurm, HyperQueue): sleep until the next poll is due, but
/// at most `timeout`; true when a poll is due now.
pub(crate) fn sleep_until_poll_due(
    last_poll: Option<Instant>,
    interval: Duration,
    timeout: Duration,
) -> bool {
    let due = last_poll.map_or(Duration::ZERO, |t| interval.saturating_sub(t.elapsed()));
    std::thread::sleep(due.min(timeout));
    last_poll.is_none_or(|t| t.elapsed() >= interval)
}
