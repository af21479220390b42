//! The HyperQueue executor: tasks are submitted as `hq submit --array` task arrays whose tasks run
//! `iuq worker --manifest FILE --index-env HQ_TASK_ID`, and followed through
//! `hq --output-mode=json job info`.
//!
//! The JSON read is that of HyperQueue's JSON output mode, as recorded from HyperQueue v0.26.2
//! in `tests/fixtures/hq/`: `{"id": N}` from `submit`; from `job info` an array of job details,
//! each with `info.id`, `info.name` and `tasks`, every task with `id`, `state` ∈
//! waiting|running|finished|failed|canceled|aborted, once started `worker` (or `workers` for a
//! multi-node task) and, when failed, `error`; `task list` prints `{"<job id>": [tasks]}`, also
//! accepted. A job the server does not know is left out of `job info` (exit status 0), and a
//! job of another name under a known id (a server restarted without its journal numbers jobs
//! from 1 again) is treated as unknown too. When `hq` fails it prints `{"error": "…"}` on
//! standard output and exits with status 1; that message is what an executor error reports.
//! The `hq` program is `executor.hq`, else `$HQ_BIN`, else `hq`.

use std::collections::HashMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use serde_json::Value;

use crate::error::{CampaignError, Result};
use crate::executor::job_array::{ArrayTask, write_manifest};
use crate::executor::{
    Executor, ExecutorEvent, OpenTask, SubmittedTask, failure_events, report_events,
    report_matches, sleep_until_poll_due,
};
use crate::outcome::OutcomeKind;
use crate::study::ExecutorKind;
use crate::worker::read_report;

/// Polls after which a task that finished (or vanished) without a worker result is given up.
const MISSING_POLLS_BEFORE_LOST: u32 = 3;

/// Consecutive failed scheduler queries tolerated before the campaign stops with an error.
const MAX_FAILED_POLLS: u32 = 20;

/// Settings of the HyperQueue executor.
#[derive(Debug, Clone, PartialEq)]
pub struct HyperQueueSettings {
    /// The `hq` program.
    pub hq: String,
    /// The campaign directory.
    pub campaign_dir: PathBuf,
    /// The worker specification file.
    pub spec_path: PathBuf,
    /// The command that starts the worker.
    pub worker_command: Vec<String>,
    /// Job name of every array of the campaign.
    pub job_name: String,
    /// Extra `hq submit` arguments (resources, time limits).
    pub submit_args: Vec<String>,
    /// Time between polls.
    pub poll_interval: Duration,
}

/// The state of one HyperQueue task as read from JSON output.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HqTaskState {
    /// waiting, running, finished, failed, canceled or aborted.
    pub state: String,
    /// The (first) worker id running it or that ran it.
    pub worker: Option<u64>,
    /// The error message of a failed task.
    pub error: Option<String>,
    /// The name of the task's job (`job info` prints it; `task list` does not).
    pub job_name: Option<String>,
}

/// The job id printed by `hq --output-mode=json submit`.
pub fn parse_submit(text: &str) -> Option<u64> {
    let v: Value = serde_json::from_str(text.trim()).ok()?;
    v.get("id").and_then(Value::as_u64)
}

/// The message of the `{"error": "…"}` object that `hq --output-mode=json` prints on standard
/// output when a command fails.
pub fn parse_error(text: &str) -> Option<String> {
    let v: Value = serde_json::from_str(text.trim()).ok()?;
    v.get("error").and_then(Value::as_str).map(str::to_string)
}

/// What a task that HyperQueue no longer runs ended in, when it left no worker result: `None`
/// while it waits or runs, else the outcome kind and the reason recorded for its runs. `state`
/// is `None` for a task the server does not know.
pub fn classify_task_state(id: &str, state: Option<&HqTaskState>) -> Option<(OutcomeKind, String)> {
    let error = state
        .and_then(|s| s.error.as_deref())
        .unwrap_or("no message");
    Some(match state.map(|s| s.state.as_str()) {
        Some("waiting" | "running") => return None,
        Some("canceled") => (
            OutcomeKind::Cancelled,
            format!("HyperQueue task {id} was cancelled"),
        ),
        Some("aborted") => (
            OutcomeKind::Cancelled,
            format!(
                "HyperQueue aborted task {id} (its job reached its --max-fails limit, or a dependency failed)"
            ),
        ),
        Some("failed") if error == "Time limit reached" => (
            OutcomeKind::Timeout,
            format!(
                "HyperQueue task {id} reached its time limit (--time-limit) without a worker result"
            ),
        ),
        Some("failed") if error.starts_with("Cannot execute") => (
            OutcomeKind::SpawnFailed,
            format!("HyperQueue could not start the worker of task {id}: {error}"),
        ),
        Some("failed") => (
            OutcomeKind::Infrastructure,
            format!("HyperQueue task {id} failed without a worker result: {error}"),
        ),
        Some("finished") => (
            OutcomeKind::Infrastructure,
            format!("HyperQueue task {id} finished without a worker result"),
        ),
        Some(other) => (
            OutcomeKind::Lost,
            format!("HyperQueue task {id} is in state `{other}` and left no worker result"),
        ),
        None => (
            OutcomeKind::Lost,
            format!("HyperQueue task {id} is not known to the server and left no worker result"),
        ),
    })
}

fn parse_tasks(
    job: u64,
    job_name: Option<&str>,
    tasks: &Value,
    out: &mut HashMap<String, HqTaskState>,
) {
    for t in tasks.as_array().into_iter().flatten() {
        let Some(id) = t.get("id").and_then(Value::as_u64) else {
            continue;
        };
        let state = t
            .get("state")
            .and_then(Value::as_str)
            .unwrap_or("")
            .to_string();
        let worker = t.get("worker").and_then(Value::as_u64).or_else(|| {
            t.get("workers")
                .and_then(|w| w.get(0))
                .and_then(Value::as_u64)
        });
        let error = t.get("error").and_then(Value::as_str).map(str::to_string);
        out.insert(
            format!("{job}.{id}"),
            HqTaskState {
                state,
                worker,
                error,
                job_name: job_name.map(str::to_string),
            },
        );
    }
}

/// Task states keyed `"<job>.<task>"` from `hq --output-mode=json job info` (an array of job
/// details) or `hq --output-mode=json task list` (an object keyed by job id).
pub fn parse_task_states(text: &str) -> Option<HashMap<String, HqTaskState>> {
    let v: Value = serde_json::from_str(text.trim()).ok()?;
    let mut out = HashMap::new();
    match &v {
        Value::Array(jobs) => {
            for job in jobs {
                let info = job.get("info")?;
                let id = info.get("id").and_then(Value::as_u64)?;
                let name = info.get("name").and_then(Value::as_str);
                if let Some(tasks) = job.get("tasks") {
                    parse_tasks(id, name, tasks, &mut out);
                }
            }
        }
        Value::Object(map) => {
            for (job, tasks) in map {
                let id: u64 = job.parse().ok()?;
                parse_tasks(id, None, tasks, &mut out);
            }
        }
        _ => return None,
    }
    Some(out)
}

/// Runs tasks as HyperQueue task arrays.
#[derive(Debug)]
pub struct HyperQueueExecutor {
    settings: HyperQueueSettings,
    tracked: HashMap<String, ArrayTask>,
    submitted_arrays: usize,
    /// Consecutive polls whose scheduler query failed.
    failed_polls: u32,
    last_poll: Option<Instant>,
}

impl HyperQueueExecutor {
    /// A HyperQueue executor with `settings`.
    pub fn new(settings: HyperQueueSettings) -> Self {
        Self {
            settings,
            tracked: HashMap::new(),
            submitted_arrays: 0,
            last_poll: None,
            failed_polls: 0,
        }
    }

    /// Run `hq --output-mode=json ARGS` and return its standard output. A failure names the
    /// command and HyperQueue's message, which `hq` prints as JSON on standard output (clap's
    /// usage errors go to standard error).
    fn hq(&self, args: &[String]) -> Result<String> {
        let program = &self.settings.hq;
        let output = std::process::Command::new(program)
            .arg("--output-mode=json")
            .args(args)
            .stdin(std::process::Stdio::null())
            .output()
            .map_err(|e| {
                CampaignError::executor("hyperqueue", format!("cannot run `{program}`: {e}"))
            })?;
        let stdout = String::from_utf8_lossy(&output.stdout).into_owned();
        if output.status.success() {
            return Ok(stdout);
        }
        let stderr = String::from_utf8_lossy(&output.stderr);
        let message = match (parse_error(&stdout), stderr.trim()) {
            (Some(e), "") => e,
            (Some(e), err) => format!("{e}\n{err}"),
            (None, "") => stdout.trim().to_string(),
            (None, err) => err.to_string(),
        };
        Err(CampaignError::executor(
            "hyperqueue",
            format!(
                "`{program} --output-mode=json {}` failed ({}): {message}",
                args.join(" "),
                output.status
            ),
        ))
    }

    fn poll(&mut self, lost_immediately: bool) -> Result<Vec<ExecutorEvent>> {
        self.last_poll = Some(Instant::now());
        let mut jobs: Vec<&str> = self
            .tracked
            .keys()
            .filter_map(|k| k.split('.').next())
            .collect();
        jobs.sort_unstable();
        jobs.dedup();
        let states = if jobs.is_empty() {
            HashMap::new()
        } else {
            let text = match self.hq(&["job".into(), "info".into(), jobs.join(",")]) {
                Ok(t) => {
                    self.failed_polls = 0;
                    t
                }
                // A busy server: try again at the next poll, give up after many failures.
                Err(_) if self.failed_polls < MAX_FAILED_POLLS => {
                    self.failed_polls += 1;
                    return Ok(Vec::new());
                }
                Err(e) => return Err(e),
            };
            parse_task_states(&text).ok_or_else(|| {
                CampaignError::executor(
                    "hyperqueue",
                    format!("cannot read `hq job info` output: {}", text.trim()),
                )
            })?
        };
        let mut events = Vec::new();
        let mut done = Vec::new();
        for (id, tracked) in &mut self.tracked {
            if let Some(report) = read_report(&tracked.task.task.directory)
                .filter(|r| report_matches(&tracked.task, r))
            {
                events.extend(report_events(&tracked.task, report));
                done.push(id.clone());
                continue;
            }
            // A job of another name under this id is not ours (the server was restarted
            // without its journal and numbers jobs from 1 again).
            let state = states.get(id).filter(|s| {
                s.job_name
                    .as_deref()
                    .is_none_or(|n| n == self.settings.job_name)
            });
            match state.map(|s| s.state.as_str()) {
                Some("waiting") => tracked.missing_polls = 0,
                Some("running") => {
                    tracked.missing_polls = 0;
                    let host = state
                        .and_then(|s| s.worker)
                        .map(|w| format!("hq-worker-{w}"));
                    events.extend(tracked.start(id, host));
                }
                _ => {
                    // Ended (or unknown) without a worker result: the result may still be on
                    // its way through a shared file system, so wait a few polls.
                    tracked.missing_polls += 1;
                    if !lost_immediately && tracked.missing_polls < MISSING_POLLS_BEFORE_LOST {
                        continue;
                    }
                    let Some((kind, reason)) = classify_task_state(id, state) else {
                        continue;
                    };
                    events.extend(failure_events(&tracked.task, kind, &reason));
                    done.push(id.clone());
                }
            }
        }
        for id in done {
            self.tracked.remove(&id);
        }
        Ok(events)
    }
}

impl Executor for HyperQueueExecutor {
    fn kind(&self) -> ExecutorKind {
        ExecutorKind::Hyperqueue
    }

    fn capacity(&self) -> usize {
        usize::MAX / 2
    }

    fn in_flight(&self) -> usize {
        self.tracked.len()
    }

    fn submit(&mut self, tasks: Vec<SubmittedTask>) -> Result<Vec<(i64, String)>> {
        if tasks.is_empty() {
            return Ok(Vec::new());
        }
        let dir = self.settings.campaign_dir.join("hyperqueue");
        std::fs::create_dir_all(&dir).map_err(|e| CampaignError::io(&dir, e))?;
        self.submitted_arrays += 1;
        let (_, manifest_path) = write_manifest(
            "hyperqueue",
            &dir,
            self.submitted_arrays,
            &self.settings.spec_path,
            &tasks,
        )?;
        let mut args = vec![
            "submit".to_string(),
            format!("--array=0-{}", tasks.len() - 1),
            format!("--name={}", self.settings.job_name),
            format!("--stdout={}/%{{JOB_ID}}_%{{TASK_ID}}.out", dir.display()),
            format!("--stderr={}/%{{JOB_ID}}_%{{TASK_ID}}.err", dir.display()),
        ];
        args.extend(self.settings.submit_args.iter().cloned());
        args.push("--".into());
        args.extend(self.settings.worker_command.iter().cloned());
        args.extend([
            "--manifest".to_string(),
            manifest_path.display().to_string(),
            "--index-env".to_string(),
            "HQ_TASK_ID".to_string(),
        ]);
        let out = self.hq(&args)?;
        let job = parse_submit(&out).ok_or_else(|| {
            CampaignError::executor(
                "hyperqueue",
                format!("`hq submit` printed no job id: `{}`", out.trim()),
            )
        })?;
        let mut external = Vec::new();
        for (index, task) in tasks.into_iter().enumerate() {
            let id = format!("{job}.{index}");
            for &attempt_id in &task.attempt_ids {
                external.push((attempt_id, id.clone()));
            }
            self.tracked.insert(id, ArrayTask::new(task));
        }
        Ok(external)
    }

    fn wait(&mut self, timeout: Duration) -> Result<Vec<ExecutorEvent>> {
        if self.tracked.is_empty() {
            return Ok(Vec::new());
        }
        if !sleep_until_poll_due(self.last_poll, self.settings.poll_interval, timeout) {
            return Ok(Vec::new());
        }
        self.poll(false)
    }

    fn reattach(&mut self, tasks: Vec<OpenTask>) -> Result<Vec<ExecutorEvent>> {
        let mut events = Vec::new();
        let mut any = false;
        for open in tasks {
            match open.external_id {
                Some(id) => {
                    any = true;
                    self.tracked.insert(id, ArrayTask::new(open.submitted));
                }
                None => events.extend(failure_events(
                    &open.submitted,
                    OutcomeKind::Lost,
                    "the coordinator stopped before the HyperQueue job id was recorded, and no worker result exists",
                )),
            }
        }
        if any {
            events.extend(self.poll(true)?);
        }
        Ok(events)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // The fixtures were recorded from HyperQueue v0.26.2 (see tests/fixtures/hq/README.md):
    // job 1 (--max-fails=0) has a failed and two aborted tasks, job 2 a worker that could not be
    // started, job 3 a task past its time limit, job 4 (the submitted array) a finished, a
    // failed (SIGKILL), a running and a waiting task, job 5 two cancelled tasks.

    #[test]
    fn recorded_submit_output() {
        assert_eq!(
            parse_submit(include_str!("../../tests/fixtures/hq/submit.json")),
            Some(4)
        );
        assert_eq!(
            parse_submit(include_str!("../../tests/fixtures/hq/error.json")),
            None
        );
    }

    #[test]
    fn recorded_error_output() {
        let e = parse_error(include_str!("../../tests/fixtures/hq/error.json")).unwrap();
        assert!(e.starts_with("No running instance of HQ found"), "{e}");
        assert_eq!(parse_error("[]"), None);
    }

    #[test]
    fn recorded_job_info_output() {
        let states =
            parse_task_states(include_str!("../../tests/fixtures/hq/job_info.json")).unwrap();
        assert_eq!(states.len(), 11);
        assert_eq!(states["4.0"].state, "finished");
        assert_eq!(states["4.1"].state, "failed");
        assert_eq!(
            states["4.1"].error.as_deref(),
            Some("Program terminated with exit code -1. Received signal 9 (SIGKILL).")
        );
        assert_eq!(states["4.2"].state, "running");
        assert_eq!(states["4.2"].worker, Some(1));
        assert_eq!(states["4.3"].state, "waiting");
        assert_eq!(states["4.3"].worker, None);
        assert_eq!(states["4.3"].job_name.as_deref(), Some("iuq-fixture"));
        assert_eq!(states["1.1"].state, "aborted");
        assert_eq!(states["5.0"].state, "canceled");
        // A job the server does not know is left out: `hq job info 99` prints `[]`.
        assert_eq!(parse_task_states("[]").map(|s| s.len()), Some(0));
    }

    #[test]
    fn recorded_task_list_output() {
        let states =
            parse_task_states(include_str!("../../tests/fixtures/hq/task_list.json")).unwrap();
        assert_eq!(states.len(), 4);
        assert_eq!(states["4.0"].state, "finished");
        assert_eq!(states["4.1"].state, "failed");
        assert_eq!(states["4.2"].state, "running");
        assert_eq!(states["4.2"].worker, Some(1));
        assert_eq!(states["4.3"].state, "waiting");
        assert_eq!(states["4.3"].job_name, None);
        assert!(parse_task_states("not json").is_none());
        // A multi-node task lists its workers (HyperQueue's `fill_task_started_data`).
        let multi = parse_task_states(
            r#"{"3": [{"id": 0, "state": "running", "started_at": "2026-11-24T16:04:31Z", "workers": [3, 4]}]}"#,
        )
        .unwrap();
        assert_eq!(multi["3.0"].worker, Some(3));
    }

    #[test]
    fn recorded_end_states_are_classified() {
        let states =
            parse_task_states(include_str!("../../tests/fixtures/hq/job_info.json")).unwrap();
        let kind = |id: &str| classify_task_state(id, states.get(id)).map(|(k, _)| k);
        assert_eq!(kind("4.2"), None);
        assert_eq!(kind("4.3"), None);
        assert_eq!(kind("4.0"), Some(OutcomeKind::Infrastructure));
        assert_eq!(kind("4.1"), Some(OutcomeKind::Infrastructure));
        assert_eq!(kind("1.0"), Some(OutcomeKind::Infrastructure));
        assert_eq!(kind("1.1"), Some(OutcomeKind::Cancelled));
        assert_eq!(kind("2.0"), Some(OutcomeKind::SpawnFailed));
        assert_eq!(kind("3.0"), Some(OutcomeKind::Timeout));
        assert_eq!(kind("5.1"), Some(OutcomeKind::Cancelled));
        assert_eq!(kind("9.0"), Some(OutcomeKind::Lost));
        let (_, reason) = classify_task_state("4.1", states.get("4.1")).unwrap();
        assert!(reason.contains("Received signal 9 (SIGKILL)"), "{reason}");
        let (_, reason) = classify_task_state("2.0", states.get("2.0")).unwrap();
        assert!(reason.contains("/nonexistent/iuq"), "{reason}");
    }

    /// A fake `hq` in a fresh directory that prints `stdout` and exits with `status`, and a
    /// HyperQueue executor using it whose jobs are named `job_name`.
    fn fake_hq(
        name: &str,
        stdout: &str,
        status: i32,
        job_name: &str,
    ) -> (PathBuf, HyperQueueExecutor) {
        let dir = std::env::temp_dir().join(format!("iuq-hq-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let hq = dir.join("hq");
        std::fs::write(
            &hq,
            format!("#!/bin/sh\ncat <<'EOF'\n{stdout}EOF\nexit {status}\n"),
        )
        .unwrap();
        std::process::Command::new("chmod")
            .arg("+x")
            .arg(&hq)
            .status()
            .unwrap();
        let executor = HyperQueueExecutor::new(HyperQueueSettings {
            hq: hq.display().to_string(),
            campaign_dir: dir.clone(),
            spec_path: dir.join("spec.json"),
            worker_command: vec!["iuq".into(), "worker".into()],
            job_name: job_name.into(),
            submit_args: Vec::new(),
            poll_interval: Duration::from_millis(10),
        });
        (dir, executor)
    }

    fn open_task(dir: &std::path::Path, run_id: i64, external_id: &str) -> OpenTask {
        OpenTask {
            submitted: SubmittedTask {
                task: crate::run_directory::Task {
                    directory: dir.join(format!("run-{run_id}")),
                    runs: vec![crate::run_directory::TaskRun {
                        run_id,
                        attempt: 1,
                        parameters: vec![1.0],
                    }],
                },
                attempt_ids: vec![run_id * 10],
            },
            external_id: Some(external_id.into()),
        }
    }

    /// The outcome kind of each finished attempt, and the attempts that started.
    fn summary(events: &[ExecutorEvent]) -> (HashMap<i64, OutcomeKind>, Vec<i64>) {
        let mut finished = HashMap::new();
        let mut started = Vec::new();
        for e in events {
            match e {
                ExecutorEvent::Finished {
                    attempt_id, result, ..
                } => {
                    finished.insert(*attempt_id, result.kind);
                }
                ExecutorEvent::Started { attempt_id, .. } => started.push(*attempt_id),
            }
        }
        (finished, started)
    }

    #[test]
    fn reattached_tasks_follow_the_recorded_job_info() {
        let job_info = include_str!("../../tests/fixtures/hq/job_info.json");
        let (dir, mut executor) = fake_hq("reattach", job_info, 0, "iuq-fixture");
        let tasks = [
            (1, "4.1"),
            (2, "4.2"),
            (3, "4.3"),
            (4, "1.1"),
            (5, "3.0"),
            (6, "9.0"),
        ];
        let events = executor
            .reattach(
                tasks
                    .iter()
                    .map(|&(r, id)| open_task(&dir, r, id))
                    .collect(),
            )
            .unwrap();
        let (finished, started) = summary(&events);
        assert_eq!(finished[&10], OutcomeKind::Infrastructure);
        assert_eq!(finished[&40], OutcomeKind::Cancelled);
        assert_eq!(finished[&50], OutcomeKind::Timeout);
        assert_eq!(finished[&60], OutcomeKind::Lost);
        assert_eq!(finished.len(), 4, "{events:?}");
        assert_eq!(started, vec![20]);
        assert_eq!(executor.in_flight(), 2);
        let _ = std::fs::remove_dir_all(&dir);

        // Under another job name the same ids are another campaign's jobs (a server restarted
        // without its journal): not ours, so lost.
        let (dir, mut executor) = fake_hq("other-name", job_info, 0, "iuq-other");
        let events = executor.reattach(vec![open_task(&dir, 2, "4.2")]).unwrap();
        let (finished, started) = summary(&events);
        assert_eq!(finished[&20], OutcomeKind::Lost);
        assert!(started.is_empty());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_failing_hq_reports_its_json_error() {
        let error = include_str!("../../tests/fixtures/hq/error.json");
        let (dir, executor) = fake_hq("error", error, 1, "iuq-test");
        let e = executor
            .hq(&["job".into(), "info".into(), "4".into()])
            .unwrap_err()
            .to_string();
        assert!(e.contains("No running instance of HQ found"), "{e}");
        assert!(e.contains("job info 4"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
