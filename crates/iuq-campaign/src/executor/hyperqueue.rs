//! The HyperQueue executor: tasks are submitted as `hq submit --array` task arrays whose tasks run
//! `iuq worker --manifest FILE --index-env HQ_TASK_ID`, and followed through
//! `hq --output-mode=json job info`.
//!
//! The JSON shapes read are those of HyperQueue's JSON output mode (`{"id": N}` from `submit`;
//! from `job info` an array of job details, each with `info.id` and `tasks`, every task with
//! `id`, `state` ∈ waiting|running|finished|failed|canceled and, once started, `worker`; `task
//! list` prints `{"<job id>": [tasks]}`, also accepted). Recorded outputs are tested in
//! `tests/fixtures/hq/`. The `hq` program is `executor.hq`, else `$HQ_BIN`, else `hq`.

use std::collections::HashMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use serde_json::Value;

use crate::atomic_file::write_atomically;
use crate::error::{CampaignError, Result};
use crate::executor::{
    Executor, ExecutorEvent, OpenTask, SubmittedTask, failure_events, report_events,
    report_matches, run_cli, sleep_until_poll_due,
};
use crate::outcome::{OutcomeKind, unix_now};
use crate::study::ExecutorKind;
use crate::worker::{ArrayManifest, read_report};

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
    /// waiting, running, finished, failed or canceled.
    pub state: String,
    /// The worker id running (or that ran) it.
    pub worker: Option<u64>,
    /// The error message of a failed task.
    pub error: Option<String>,
}

/// The job id printed by `hq --output-mode=json submit`.
pub fn parse_submit(text: &str) -> Option<u64> {
    let v: Value = serde_json::from_str(text.trim()).ok()?;
    v.get("id").and_then(Value::as_u64)
}

fn parse_tasks(job: u64, tasks: &Value, out: &mut HashMap<String, HqTaskState>) {
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
                let id = job
                    .get("info")
                    .and_then(|i| i.get("id"))
                    .and_then(Value::as_u64)?;
                if let Some(tasks) = job.get("tasks") {
                    parse_tasks(id, tasks, &mut out);
                }
            }
        }
        Value::Object(map) => {
            for (job, tasks) in map {
                let id: u64 = job.parse().ok()?;
                parse_tasks(id, tasks, &mut out);
            }
        }
        _ => return None,
    }
    Some(out)
}

#[derive(Debug, Clone)]
struct Tracked {
    task: SubmittedTask,
    started: bool,
    missing_polls: u32,
}

/// Runs tasks as HyperQueue task arrays.
#[derive(Debug)]
pub struct HyperQueueExecutor {
    settings: HyperQueueSettings,
    tracked: HashMap<String, Tracked>,
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

    fn hq(&self, args: &[String]) -> Result<String> {
        let mut all = vec!["--output-mode=json".to_string()];
        all.extend(args.iter().cloned());
        run_cli("hyperqueue", &self.settings.hq, &all)
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
            let state = states.get(id);
            match state.map(|s| s.state.as_str()) {
                Some("waiting") => tracked.missing_polls = 0,
                Some("running") => {
                    tracked.missing_polls = 0;
                    if !tracked.started {
                        tracked.started = true;
                        let host = state
                            .and_then(|s| s.worker)
                            .map(|w| format!("hq-worker-{w}"));
                        for &attempt_id in &tracked.task.attempt_ids {
                            events.push(ExecutorEvent::Started {
                                attempt_id,
                                external_id: Some(id.clone()),
                                host: host.clone(),
                                started_at: unix_now(),
                            });
                        }
                    }
                }
                other => {
                    tracked.missing_polls += 1;
                    if !lost_immediately && tracked.missing_polls < MISSING_POLLS_BEFORE_LOST {
                        continue;
                    }
                    let (kind, reason) = match other {
                        Some("canceled") => (
                            OutcomeKind::Cancelled,
                            format!("HyperQueue task {id} was cancelled"),
                        ),
                        Some("failed") => (
                            OutcomeKind::Infrastructure,
                            format!(
                                "HyperQueue task {id} failed without a worker result: {}",
                                state.and_then(|s| s.error.clone()).unwrap_or_default()
                            ),
                        ),
                        Some("finished") => (
                            OutcomeKind::Infrastructure,
                            format!("HyperQueue task {id} finished without a worker result"),
                        ),
                        _ => (
                            OutcomeKind::Lost,
                            format!(
                                "HyperQueue task {id} is not known to the server and left no worker result"
                            ),
                        ),
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
        let stem = format!(
            "array-{}-{}",
            (unix_now() * 1000.0) as u64,
            self.submitted_arrays
        );
        let manifest_path = dir.join(format!("{stem}.json"));
        let manifest = ArrayManifest {
            spec: self.settings.spec_path.clone(),
            tasks: tasks.iter().map(|t| t.task.clone()).collect(),
        };
        let text = serde_json::to_vec(&manifest)
            .map_err(|e| CampaignError::executor("hyperqueue", e.to_string()))?;
        write_atomically(&manifest_path, &text, true)?;
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
            self.tracked.insert(
                id,
                Tracked {
                    task,
                    started: false,
                    missing_polls: 0,
                },
            );
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
                    self.tracked.insert(
                        id,
                        Tracked {
                            task: open.submitted,
                            started: false,
                            missing_polls: 0,
                        },
                    );
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

    #[test]
    fn recorded_submit_output() {
        assert_eq!(
            parse_submit(include_str!("../../tests/fixtures/hq/submit.json")),
            Some(7)
        );
        assert_eq!(parse_submit("{\"error\": \"no server\"}"), None);
    }

    #[test]
    fn recorded_job_info_output() {
        let states =
            parse_task_states(include_str!("../../tests/fixtures/hq/job_info.json")).unwrap();
        assert_eq!(states.len(), 4);
        assert_eq!(states["7.0"].state, "finished");
        assert_eq!(states["7.1"].state, "running");
        assert_eq!(states["7.1"].worker, Some(2));
        assert_eq!(
            states["7.2"].error.as_deref(),
            Some("Program terminated with exit code 137")
        );
        assert_eq!(states["8.0"].state, "waiting");
    }

    #[test]
    fn recorded_task_list_output() {
        let states =
            parse_task_states(include_str!("../../tests/fixtures/hq/task_list.json")).unwrap();
        assert_eq!(states["7.1"].state, "canceled");
        assert_eq!(states["7.2"].worker, Some(3));
        assert!(parse_task_states("not json").is_none());
    }
}
