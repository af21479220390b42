//! The worker: executes one task (prepares its directory, runs the command under supervision,
//! decodes the outputs) and writes `iuq-status.json` and `iuq-result.json` atomically into it.
//!
//! Every executor runs tasks through [`execute_task`]: the local executor in its own threads,
//! Slurm and HyperQueue through `iuq worker --manifest FILE --index N`, which reads the task from
//! an array manifest written by the coordinator ([`ArrayManifest`]). Workers never touch the
//! campaign store; the coordinator ingests their result files.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use serde::{Deserialize, Serialize};

use iuq_core::Expression;

use crate::atomic_file::write_atomically;
use crate::decoder::{OutputDecoder, check_finite, parse_cell, read_csv_text};
use crate::error::{CampaignError, Result};
use crate::outcome::{OutcomeKind, RunResult, TaskReport, host_name, unix_now};
use crate::run_directory::{
    RESULT_FILE, STATUS_FILE, STDERR_FILE, STDOUT_FILE, Task, prepare, run_values,
};
use crate::study::{CommandKind, CommandSpec};
use crate::supervised_process::{OutputLogs, run_supervised, signal_name};
use crate::template::format_value;
use iuq_study_file::check_duration;

/// Bytes of standard error kept with each attempt.
pub const STDERR_TAIL_BYTES: u64 = 2000;

/// A command specification with its expressions and decoder compiled.
#[derive(Debug, Clone)]
pub struct CompiledSpec {
    /// The specification.
    pub spec: CommandSpec,
    derived: Vec<Expression>,
    decoder: Option<OutputDecoder>,
}

impl CompiledSpec {
    /// Compile `spec`.
    pub fn new(spec: CommandSpec) -> Result<Self> {
        for (name, seconds) in [
            ("timeout", spec.timeout),
            ("kill_grace", Some(spec.kill_grace)),
        ] {
            if let Some(seconds) = seconds {
                check_duration(seconds).map_err(|reason| CampaignError::Format {
                    path: "worker spec".into(),
                    reason: format!("{name}: {reason}"),
                })?;
            }
        }
        let derived = spec
            .derived_expressions()
            .map_err(|r| CampaignError::Format {
                path: "worker spec".into(),
                reason: r,
            })?;
        let decoder = spec.output_decoder().map_err(|r| CampaignError::Format {
            path: "worker spec".into(),
            reason: r,
        })?;
        Ok(Self {
            spec,
            derived,
            decoder,
        })
    }

    /// Read a specification written by [`write_spec`].
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| CampaignError::io(path, e))?;
        let spec: CommandSpec = serde_json::from_str(&text).map_err(|e| CampaignError::Format {
            path: path.display().to_string(),
            reason: e.to_string(),
        })?;
        Self::new(spec)
    }
}

/// Write the worker specification of `spec` into `campaign_dir` (once per content hash) and
/// return its path.
pub fn write_spec(campaign_dir: &Path, spec: &CommandSpec) -> Result<PathBuf> {
    let hash = spec.hash();
    let path = campaign_dir.join(format!("worker-spec-{}.json", &hash[..16]));
    if !path.exists() {
        let text = serde_json::to_vec_pretty(spec).map_err(|e| CampaignError::Format {
            path: path.display().to_string(),
            reason: e.to_string(),
        })?;
        write_atomically(&path, &text, true)?;
    }
    Ok(path)
}

/// The tasks of one job array, read by `iuq worker --manifest FILE --index N`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ArrayManifest {
    /// The worker specification file.
    pub spec: PathBuf,
    /// The tasks, by array index.
    pub tasks: Vec<Task>,
}

/// What `status.json` says about a task.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TaskStatus {
    /// `running` or `finished`.
    pub state: String,
    /// The host.
    pub host: String,
    /// The command's pid (= its process-group id), once started.
    pub pid: Option<u32>,
    /// Kernel start time of that process (clock ticks since boot), to tell it from a reused pid.
    pub pid_start: Option<u64>,
    /// `(run_id, attempt)` of each run of the task.
    pub runs: Vec<(i64, u32)>,
    /// When the worker started, seconds since the epoch.
    pub started_at: f64,
}

/// The kernel start time of process `pid` (field 22 of `/proc/PID/stat`).
pub fn process_start_ticks(pid: u32) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let after = stat.rsplit_once(')')?.1;
    after.split_whitespace().nth(19)?.parse().ok()
}

/// The report in `directory/iuq-result.json`, when it exists and parses.
pub fn read_report(directory: &Path) -> Option<TaskReport> {
    let text = std::fs::read(directory.join(RESULT_FILE)).ok()?;
    serde_json::from_slice(&text).ok()
}

/// The status in `directory/iuq-status.json`, when it exists and parses.
pub fn read_status(directory: &Path) -> Option<TaskStatus> {
    let text = std::fs::read(directory.join(STATUS_FILE)).ok()?;
    serde_json::from_slice(&text).ok()
}

fn all_runs(task: &Task, kind: OutcomeKind, reason: &str) -> Vec<RunResult> {
    task.runs
        .iter()
        .map(|r| RunResult::failure(r.run_id, r.attempt, kind, reason))
        .collect()
}

/// The program to start for a command whose first word is `program`: the word `iuq` names the
/// iuq executable ([`iuq_executable`]: campaigns of `iuq rbc shear` then need no `PATH` set-up
/// and use the same version as the coordinator); anything else is taken as written.
fn program(program: &str) -> std::ffi::OsString {
    if program == SELF_PROGRAM
        && let Some(exe) = iuq_executable()
    {
        return exe.into_os_string();
    }
    program.into()
}

/// The iuq executable that the command word `iuq` and the workers of cluster executors run:
/// `$IUQ_EXECUTABLE` when set, else the running executable when it is an `iuq` binary, else
/// `None` (the word is then looked up on `PATH`). A library host that is not `iuq` — a Python
/// interpreter, a test binary — thus never runs itself by mistake.
pub fn iuq_executable() -> Option<std::path::PathBuf> {
    if let Some(path) = std::env::var_os("IUQ_EXECUTABLE").filter(|p| !p.is_empty()) {
        return Some(path.into());
    }
    let exe = std::env::current_exe().ok()?;
    let stem = exe.file_stem()?.to_string_lossy().into_owned();
    (stem == SELF_PROGRAM).then_some(exe)
}

/// The command word that names the running iuq executable (see `program`).
pub const SELF_PROGRAM: &str = "iuq";

fn last_line(text: &str) -> Option<&str> {
    text.lines().rev().map(str::trim).find(|l| !l.is_empty())
}

/// Execute `task`: prepare its directory, run the command, decode the outputs, and write
/// `status.json` and `result.json` atomically (`durable`: also fsync'd, for workers on other
/// hosts). Never fails: every problem becomes a failure of the task's runs with a reason.
pub fn execute_task(compiled: &CompiledSpec, task: &Task, durable: bool) -> TaskReport {
    let spec = &compiled.spec;
    let host = host_name();
    let started_at = unix_now();
    let runs_key: Vec<(i64, u32)> = task.runs.iter().map(|r| (r.run_id, r.attempt)).collect();
    let mut report = TaskReport {
        runs: Vec::new(),
        exit_code: None,
        signal: None,
        host: host.clone(),
        pid: None,
        started_at,
        finished_at: started_at,
        stderr_tail: String::new(),
    };
    if task.runs.is_empty() {
        finish(task, &mut report, durable);
        return report;
    }
    if let Err(reason) = prepare(spec, &compiled.derived, task) {
        report.runs = all_runs(
            task,
            OutcomeKind::Infrastructure,
            &format!("cannot prepare the run directory: {reason}"),
        );
        finish(task, &mut report, durable);
        return report;
    }
    let first = &task.runs[0];
    let values = run_values(spec, &compiled.derived, first);
    let args: Vec<String> = spec
        .command
        .iter()
        .map(|t| {
            t.render(|name| {
                values
                    .iter()
                    .find(|(n, _)| n == name)
                    .map(|(_, v)| format_value(*v))
            })
        })
        .collect();
    if args.is_empty() {
        report.runs = all_runs(
            task,
            OutcomeKind::SpawnFailed,
            "the model's command is empty",
        );
        finish(task, &mut report, durable);
        return report;
    }
    let logs = OutputLogs {
        stdout: task.directory.join(STDOUT_FILE),
        stderr: task.directory.join(STDERR_FILE),
        tail_bytes: STDERR_TAIL_BYTES as usize,
    };
    let mut command = Command::new(program(&args[0]));
    command
        .args(&args[1..])
        .current_dir(&task.directory)
        .stdin(Stdio::null())
        .env("IUQ_RUN_ID", first.run_id.to_string())
        .env("IUQ_ATTEMPT", first.attempt.to_string())
        .env("IUQ_RUN_DIR", &task.directory)
        .env("IUQ_STUDY_DIR", &spec.study_dir);
    for (k, v) in &spec.env {
        command.env(k, v);
    }
    let status_path = task.directory.join(STATUS_FILE);
    let exit = run_supervised(
        &mut command,
        spec.timeout.map(Duration::from_secs_f64),
        Duration::from_secs_f64(spec.kill_grace),
        &logs,
        |pid| {
            let status = TaskStatus {
                state: "running".into(),
                host: host.clone(),
                pid: Some(pid),
                pid_start: process_start_ticks(pid),
                runs: runs_key.clone(),
                started_at,
            };
            if let Ok(text) = serde_json::to_vec(&status) {
                let _ = write_atomically(&status_path, &text, false);
            }
        },
    );
    let exit = match exit {
        Ok(supervised) => {
            report.stderr_tail = supervised.stderr_tail;
            supervised.exit
        }
        Err(e) => {
            report.runs = all_runs(
                task,
                OutcomeKind::SpawnFailed,
                &format!("cannot start `{}`: {e}", args[0]),
            );
            finish(task, &mut report, durable);
            return report;
        }
    };
    report.pid = Some(exit.pid);
    report.exit_code = exit.exit_code;
    report.signal = exit.signal;
    report.started_at = exit.started_at;
    let hint = last_line(&report.stderr_tail)
        .map(|l| format!(" (stderr: {})", l.chars().take(200).collect::<String>()))
        .unwrap_or_default();
    let stopped_with_process = crate::supervised_process::termination_signal()
        .filter(|_| exit.signal.is_some() || exit.exit_code != Some(0));
    report.runs = if let Some(stop) = stopped_with_process {
        all_runs(
            task,
            OutcomeKind::Lost,
            &format!(
                "stopped by {} with the process that ran it",
                signal_name(stop)
            ),
        )
    } else if exit.timed_out {
        all_runs(
            task,
            OutcomeKind::Timeout,
            &format!(
                "ran past the timeout of {} s and was stopped with {}",
                spec.timeout.unwrap_or(0.0),
                exit.signal.map_or_else(|| "SIGTERM".into(), signal_name)
            ),
        )
    } else if let Some(signal) = exit.signal {
        all_runs(
            task,
            OutcomeKind::Signal,
            &format!("killed by {}{hint}", signal_name(signal)),
        )
    } else if let Some(code) = exit.exit_code.filter(|c| *c != 0) {
        all_runs(
            task,
            OutcomeKind::ExitStatus,
            &format!("exited with status {code}{hint}"),
        )
    } else {
        decode_outputs(compiled, task)
    };
    finish(task, &mut report, durable);
    report
}

fn decode_outputs(compiled: &CompiledSpec, task: &Task) -> Vec<RunResult> {
    let spec = &compiled.spec;
    match (&spec.kind, &compiled.decoder) {
        (CommandKind::Command, Some(decoder)) => {
            let run = &task.runs[0];
            vec![match decoder.decode(&task.directory) {
                Ok((outputs, std)) => RunResult {
                    run_id: run.run_id,
                    attempt: run.attempt,
                    kind: OutcomeKind::Succeeded,
                    reason: None,
                    outputs,
                    std,
                },
                Err((kind, reason)) => RunResult::failure(run.run_id, run.attempt, kind, reason),
            }]
        }
        (CommandKind::BatchCommand { output, .. }, _) => decode_batch(spec, output, task),
        (CommandKind::Command, None) => all_runs(task, OutcomeKind::BadOutput, "no output decoder"),
    }
}

/// Decode the output CSV of a `batch-command` task: one row per input row, in order; an `error`
/// column, when present and non-empty, fails that row with its text.
fn decode_batch(spec: &CommandSpec, output: &str, task: &Task) -> Vec<RunResult> {
    let path = task.directory.join(output);
    let text = match std::fs::read(&path) {
        Ok(b) => String::from_utf8_lossy(&b).into_owned(),
        Err(_) => {
            return all_runs(
                task,
                OutcomeKind::MissingOutput,
                &format!("output file `{output}` was not written"),
            );
        }
    };
    let (header, rows) = match read_csv_text(&text) {
        Ok(t) => t,
        Err(e) => {
            return all_runs(
                task,
                OutcomeKind::BadOutput,
                &format!("output file `{output}`: {e}"),
            );
        }
    };
    if rows.len() != task.runs.len() {
        return all_runs(
            task,
            OutcomeKind::BadOutput,
            &format!(
                "output file `{output}` has {} rows for {} input rows",
                rows.len(),
                task.runs.len()
            ),
        );
    }
    let mut columns = Vec::with_capacity(spec.outputs.len());
    for name in &spec.outputs {
        match header.iter().position(|h| h == name) {
            Some(k) => columns.push(k),
            None => {
                return all_runs(
                    task,
                    OutcomeKind::BadOutput,
                    &format!(
                        "output file `{output}` has no column `{name}` (columns: {})",
                        header.join(", ")
                    ),
                );
            }
        }
    }
    let error_column = header.iter().position(|h| h == "error");
    task.runs
        .iter()
        .zip(&rows)
        .map(|(run, row)| {
            let cell = |k: usize| row.get(k).map_or("", String::as_str);
            if let Some(e) = error_column.map(cell).filter(|e| !e.is_empty()) {
                return RunResult::failure(
                    run.run_id,
                    run.attempt,
                    OutcomeKind::BadOutput,
                    format!("the model reported: {e}"),
                );
            }
            let mut outputs = Vec::with_capacity(columns.len());
            for (&k, name) in columns.iter().zip(&spec.outputs) {
                match parse_cell(cell(k)) {
                    Some(v) => outputs.push(v),
                    None => {
                        return RunResult::failure(
                            run.run_id,
                            run.attempt,
                            OutcomeKind::BadOutput,
                            format!(
                                "output file `{output}`, column `{name}`: `{}` is not a number",
                                cell(k)
                            ),
                        );
                    }
                }
            }
            if let Err((kind, reason)) = check_finite(&spec.outputs, &outputs, None, output) {
                return RunResult::failure(run.run_id, run.attempt, kind, reason);
            }
            RunResult {
                run_id: run.run_id,
                attempt: run.attempt,
                kind: OutcomeKind::Succeeded,
                reason: None,
                outputs,
                std: None,
            }
        })
        .collect()
}

fn finish(task: &Task, report: &mut TaskReport, durable: bool) {
    report.finished_at = unix_now();
    let book = &task.directory;
    let _ = std::fs::create_dir_all(book);
    if let Ok(text) = serde_json::to_vec(report) {
        let _ = write_atomically(&book.join(RESULT_FILE), &text, durable);
    }
    if !durable {
        // Local runs: the result file supersedes the start status (the coordinator, on this
        // host, reads both); one write fewer per run.
        return;
    }
    let status = TaskStatus {
        state: "finished".into(),
        host: report.host.clone(),
        pid: report.pid,
        pid_start: None,
        runs: task.runs.iter().map(|r| (r.run_id, r.attempt)).collect(),
        started_at: report.started_at,
    };
    if let Ok(text) = serde_json::to_vec(&status) {
        let _ = write_atomically(&book.join(STATUS_FILE), &text, durable);
    }
}

/// `iuq worker --manifest FILE --index N`: execute task `index` of an array manifest. The
/// report is also returned (the CLI prints a one-line summary).
pub fn run_manifest_task(manifest: &Path, index: usize) -> Result<TaskReport> {
    let text = std::fs::read_to_string(manifest).map_err(|e| CampaignError::io(manifest, e))?;
    let manifest_data: ArrayManifest =
        serde_json::from_str(&text).map_err(|e| CampaignError::Format {
            path: manifest.display().to_string(),
            reason: e.to_string(),
        })?;
    let task = manifest_data.tasks.get(index).ok_or_else(|| {
        CampaignError::BadInput(format!(
            "{}: no task with index {index} ({} tasks)",
            manifest.display(),
            manifest_data.tasks.len()
        ))
    })?;
    if task.runs.is_empty() {
        return Err(CampaignError::BadInput(format!(
            "{}: task {index} has no runs",
            manifest.display()
        )));
    }
    let compiled = CompiledSpec::read(&manifest_data.spec)?;
    Ok(execute_task(&compiled, task, true))
}
