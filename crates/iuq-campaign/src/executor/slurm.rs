//! The Slurm executor: tasks are submitted as `sbatch` job arrays whose elements run
//! `iuq worker --manifest FILE --index $SLURM_ARRAY_TASK_ID`.
//!
//! - Arrays hold at most `array_chunk` tasks and never more than the cluster's `MaxArraySize`
//!   (from `scontrol show config`); `max_parallel` becomes the array throttle (`--array=0-N%K`).
//! - State comes from `squeue` (one line per array element) and, for an element that left the
//!   queue without a `result.json`, from `scontrol show job`; `sacct` is never used (the
//!   accounting database is often absent or slow).
//! - All jobs of a campaign share one job name (`iuq-<name>-<hash>`), through which a resumed
//!   coordinator finds what the scheduler still runs.

use std::collections::HashMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use crate::atomic_file::write_atomically;
use crate::error::{CampaignError, Result};
use crate::executor::job_array::{ArrayTask, write_manifest};
use crate::executor::{
    Executor, ExecutorEvent, OpenTask, SubmittedTask, failure_events, report_events,
    report_matches, run_cli, shell_quote, sleep_until_poll_due,
};
use crate::outcome::OutcomeKind;
use crate::study::ExecutorKind;
use crate::worker::read_report;

/// Polls without a result after which a task that left the queue is declared lost.
const MISSING_POLLS_BEFORE_LOST: u32 = 3;

/// Consecutive failed scheduler queries tolerated before the campaign stops with an error.
const MAX_FAILED_POLLS: u32 = 20;

/// Settings of the Slurm executor.
#[derive(Debug, Clone, PartialEq)]
pub struct SlurmSettings {
    /// The campaign directory (manifests, scripts and Slurm logs go below it).
    pub campaign_dir: PathBuf,
    /// The worker specification file.
    pub spec_path: PathBuf,
    /// The command that starts the worker, e.g. `["/usr/local/bin/iuq", "worker"]`.
    pub worker_command: Vec<String>,
    /// Job name shared by every array of the campaign.
    pub job_name: String,
    /// Array throttle (`%K`), when set.
    pub throttle: Option<usize>,
    /// Tasks per array at most.
    pub array_chunk: usize,
    /// Extra `sbatch` arguments.
    pub sbatch_args: Vec<String>,
    /// Time between polls of `squeue`.
    pub poll_interval: Duration,
}

/// Runs tasks as Slurm job arrays.
#[derive(Debug)]
pub struct SlurmExecutor {
    settings: SlurmSettings,
    tracked: HashMap<String, ArrayTask>,
    max_array_size: Option<usize>,
    /// Consecutive polls whose scheduler query failed.
    failed_polls: u32,
    submitted_arrays: usize,
    last_poll: Option<Instant>,
}

/// One line of `squeue --array --format=%i|%T|%N`: `(job id, state, node list)`, with bracketed
/// array ranges (`123_[4-6%2]`) expanded into one entry per element.
pub fn parse_squeue(text: &str) -> Vec<(String, String, String)> {
    let mut out = Vec::new();
    for line in text.lines() {
        let mut parts = line.trim().split('|');
        let (Some(id), Some(state)) = (parts.next(), parts.next()) else {
            continue;
        };
        let nodes = parts.next().unwrap_or("").trim().to_string();
        let id = id.trim();
        let state = state.trim().to_string();
        if id.is_empty() {
            continue;
        }
        match id.split_once("_[") {
            Some((job, ranges)) => {
                let ranges = ranges.trim_end_matches(']');
                let ranges = ranges.split('%').next().unwrap_or("");
                for range in ranges.split(',') {
                    let (a, b) = range.split_once('-').unwrap_or((range, range));
                    if let (Ok(a), Ok(b)) = (a.trim().parse::<u64>(), b.trim().parse::<u64>()) {
                        for i in a..=b.min(a + 1_000_000) {
                            out.push((format!("{job}_{i}"), state.clone(), nodes.clone()));
                        }
                    }
                }
            }
            None => out.push((id.to_string(), state, nodes)),
        }
    }
    out
}

/// The `JobState` and `ExitCode` fields of `scontrol show job -o` output.
pub fn parse_scontrol_job(text: &str) -> Option<(String, String, String)> {
    let field = |name: &str| {
        text.split_whitespace()
            .find_map(|kv| kv.strip_prefix(name).and_then(|v| v.strip_prefix('=')))
            .map(str::to_string)
    };
    Some((
        field("JobState")?,
        field("ExitCode").unwrap_or_default(),
        field("Reason").unwrap_or_default(),
    ))
}

/// `MaxArraySize` from `scontrol show config` output.
pub fn parse_max_array_size(text: &str) -> Option<usize> {
    text.lines().find_map(|l| {
        let (k, v) = l.split_once('=')?;
        (k.trim() == "MaxArraySize").then(|| v.trim().parse().ok())?
    })
}

/// What a terminal Slurm job state without a worker result means for the runs of the task.
pub fn classify_job_state(
    state: &str,
    exit_code: &str,
    reason: &str,
) -> Option<(OutcomeKind, String)> {
    let state = state.split_whitespace().next().unwrap_or(state);
    let detail = format!(
        "Slurm job state {state} (exit code {exit_code}, reason {reason}) and no worker result"
    );
    Some(match state {
        "PENDING" | "RUNNING" | "CONFIGURING" | "COMPLETING" | "REQUEUED" | "RESIZING"
        | "SUSPENDED" | "STAGE_OUT" | "SIGNALING" | "REQUEUE_HOLD" | "REQUEUE_FED" => return None,
        "TIMEOUT" | "DEADLINE" => (
            OutcomeKind::Timeout,
            format!("the Slurm time limit was reached: {detail}"),
        ),
        "OUT_OF_MEMORY" => (
            OutcomeKind::Signal,
            format!("killed for exceeding its memory: {detail}"),
        ),
        "CANCELLED" => (OutcomeKind::Cancelled, detail),
        _ => (OutcomeKind::Infrastructure, detail),
    })
}

impl SlurmExecutor {
    /// A Slurm executor with `settings`.
    pub fn new(settings: SlurmSettings) -> Self {
        Self {
            settings,
            tracked: HashMap::new(),
            max_array_size: None,
            submitted_arrays: 0,
            last_poll: None,
            failed_polls: 0,
        }
    }

    fn chunk_size(&mut self) -> usize {
        if self.max_array_size.is_none() {
            self.max_array_size = run_cli("slurm", "scontrol", &["show".into(), "config".into()])
                .ok()
                .and_then(|t| parse_max_array_size(&t))
                .or(Some(1001));
        }
        let max = self.max_array_size.unwrap_or(1001).max(1);
        self.settings.array_chunk.clamp(1, max)
    }

    fn squeue(&self) -> Result<HashMap<String, (String, String)>> {
        let text = run_cli(
            "slurm",
            "squeue",
            &[
                "--noheader".into(),
                "--array".into(),
                format!("--name={}", self.settings.job_name),
                "--format=%i|%T|%N".into(),
            ],
        )?;
        Ok(parse_squeue(&text)
            .into_iter()
            .map(|(id, state, nodes)| (id, (state, nodes)))
            .collect())
    }
}

/// The state of one array element from `scontrol show job -o`, while the controller still knows it.
fn scontrol_state(external_id: &str) -> Option<(String, String, String)> {
    {
        let text = run_cli(
            "slurm",
            "scontrol",
            &["show".into(), "job".into(), "-o".into(), external_id.into()],
        )
        .ok()?;
        // An array job id names the whole array: pick the element's record.
        let line = text
            .lines()
            .find(|l| {
                let (job, index) = external_id.split_once('_').unwrap_or((external_id, ""));
                l.contains(&format!("ArrayJobId={job} "))
                    && l.contains(&format!("ArrayTaskId={index} "))
            })
            .or_else(|| text.lines().next())?;
        parse_scontrol_job(line)
    }
}

impl SlurmExecutor {
    fn poll(&mut self, lost_immediately: bool) -> Result<Vec<ExecutorEvent>> {
        self.last_poll = Some(Instant::now());
        let queue = match self.squeue() {
            Ok(q) => {
                self.failed_polls = 0;
                q
            }
            // A busy controller: try again at the next poll, give up after many failures.
            Err(_) if self.failed_polls < MAX_FAILED_POLLS => {
                self.failed_polls += 1;
                return Ok(Vec::new());
            }
            Err(e) => return Err(e),
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
            match queue.get(id) {
                Some((state, nodes)) => {
                    tracked.missing_polls = 0;
                    if state == "RUNNING" {
                        let host = Some(nodes.clone()).filter(|n| !n.is_empty());
                        events.extend(tracked.start(id, host));
                    }
                }
                None => {
                    tracked.missing_polls += 1;
                    if !lost_immediately && tracked.missing_polls < MISSING_POLLS_BEFORE_LOST {
                        continue;
                    }
                    let verdict = match scontrol_state(id) {
                        Some((state, exit, reason)) => classify_job_state(&state, &exit, &reason),
                        None => Some((
                            OutcomeKind::Lost,
                            format!(
                                "Slurm job {id} is no longer known to the scheduler and left no worker result"
                            ),
                        )),
                    };
                    if let Some((kind, reason)) = verdict {
                        events.extend(failure_events(&tracked.task, kind, &reason));
                        done.push(id.clone());
                    }
                }
            }
        }
        for id in done {
            self.tracked.remove(&id);
        }
        Ok(events)
    }
}

impl Executor for SlurmExecutor {
    fn kind(&self) -> ExecutorKind {
        ExecutorKind::Slurm
    }

    fn capacity(&self) -> usize {
        usize::MAX / 2
    }

    fn in_flight(&self) -> usize {
        self.tracked.len()
    }

    fn submit(&mut self, tasks: Vec<SubmittedTask>) -> Result<Vec<(i64, String)>> {
        let chunk = self.chunk_size();
        let arrays_dir = self.settings.campaign_dir.join("slurm");
        std::fs::create_dir_all(&arrays_dir).map_err(|e| CampaignError::io(&arrays_dir, e))?;
        let mut external = Vec::new();
        for group in tasks.chunks(chunk) {
            self.submitted_arrays += 1;
            let (stem, manifest_path) = write_manifest(
                "slurm",
                &arrays_dir,
                self.submitted_arrays,
                &self.settings.spec_path,
                group,
            )?;
            let mut script = String::from("#!/bin/sh\nexec");
            for part in &self.settings.worker_command {
                script.push(' ');
                script.push_str(&shell_quote(part));
            }
            script.push_str(&format!(
                " --manifest {} --index \"$SLURM_ARRAY_TASK_ID\"\n",
                shell_quote(&manifest_path.display().to_string())
            ));
            let script_path = arrays_dir.join(format!("{stem}.sh"));
            write_atomically(&script_path, script.as_bytes(), true)?;
            let mut array = format!("0-{}", group.len() - 1);
            if let Some(k) = self.settings.throttle {
                array.push_str(&format!("%{k}"));
            }
            let mut args = vec![
                "--parsable".to_string(),
                format!("--array={array}"),
                format!("--job-name={}", self.settings.job_name),
                format!("--output={}", arrays_dir.join("%A_%a.out").display()),
                format!("--chdir={}", self.settings.campaign_dir.display()),
            ];
            args.extend(self.settings.sbatch_args.iter().cloned());
            args.push(script_path.display().to_string());
            let out = run_cli("slurm", "sbatch", &args)?;
            let job_id = out
                .lines()
                .map(str::trim)
                .find(|l| !l.is_empty())
                .and_then(|l| l.split(';').next())
                .filter(|id| id.chars().all(|c| c.is_ascii_digit()) && !id.is_empty())
                .ok_or_else(|| {
                    CampaignError::executor(
                        "slurm",
                        format!("sbatch printed no job id: `{}`", out.trim()),
                    )
                })?
                .to_string();
            for (index, task) in group.iter().enumerate() {
                let id = format!("{job_id}_{index}");
                for &attempt_id in &task.attempt_ids {
                    external.push((attempt_id, id.clone()));
                }
                self.tracked.insert(id, ArrayTask::new(task.clone()));
            }
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
        let mut reattached = Vec::new();
        for open in tasks {
            match open.external_id {
                Some(id) => {
                    reattached.push(id.clone());
                    self.tracked.insert(id, ArrayTask::new(open.submitted));
                }
                None => events.extend(failure_events(
                    &open.submitted,
                    OutcomeKind::Lost,
                    "the coordinator stopped before the Slurm job id was recorded, and no worker result exists",
                )),
            }
        }
        if !reattached.is_empty() {
            events.extend(self.poll(true)?);
        }
        Ok(events)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn squeue_lines_and_array_ranges() {
        let text = "101_0|RUNNING|node1\n101_[2-4%2]|PENDING|\n102_[1,3]|PENDING|(Priority)\n99|COMPLETING|n2\n";
        let parsed = parse_squeue(text);
        let ids: Vec<&str> = parsed.iter().map(|p| p.0.as_str()).collect();
        assert_eq!(
            ids,
            vec!["101_0", "101_2", "101_3", "101_4", "102_1", "102_3", "99"]
        );
        assert_eq!(parsed[0].2, "node1");
    }

    #[test]
    fn scontrol_and_config() {
        let line = "JobId=7 ArrayJobId=5 ArrayTaskId=2 JobName=iuq JobState=NODE_FAIL Reason=NodeDown ExitCode=0:0";
        assert_eq!(
            parse_scontrol_job(line),
            Some(("NODE_FAIL".into(), "0:0".into(), "NodeDown".into()))
        );
        assert_eq!(
            parse_max_array_size("ClusterName = c\nMaxArraySize            = 1001\n"),
            Some(1001)
        );
        assert_eq!(classify_job_state("RUNNING", "", ""), None);
        assert_eq!(
            classify_job_state("NODE_FAIL", "0:0", "x").unwrap().0,
            OutcomeKind::Infrastructure
        );
        assert_eq!(
            classify_job_state("TIMEOUT", "0:0", "x").unwrap().0,
            OutcomeKind::Timeout
        );
        assert_eq!(
            classify_job_state("CANCELLED by 0", "0:15", "x").unwrap().0,
            OutcomeKind::Cancelled
        );
    }
}
