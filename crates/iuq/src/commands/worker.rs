//! `iuq worker --manifest FILE --index N`: execute one task of a job array (used by the Slurm and
//! HyperQueue executors). The task's outcome — success or a failure of the model — is written to
//! its `result.json`; the exit code is 0 unless the manifest itself cannot be used.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use serde_json::json;

use iuq_campaign::worker::run_manifest_task;
use iuq_study::campaign_runs::campaign_error;

use crate::input_error::input_error;
use crate::report_output::emit;

/// Arguments of `iuq worker`.
#[derive(Debug, Args)]
pub struct WorkerArgs {
    /// The array manifest written by the coordinator.
    #[arg(long)]
    pub manifest: PathBuf,
    /// The task's index in the manifest.
    #[arg(long, conflicts_with = "index_env")]
    pub index: Option<usize>,
    /// The environment variable holding the index (e.g. HQ_TASK_ID, SLURM_ARRAY_TASK_ID).
    #[arg(long)]
    pub index_env: Option<String>,
}

/// Run `iuq worker`.
pub fn run(args: &WorkerArgs, json: bool) -> Result<()> {
    let index = match (&args.index, &args.index_env) {
        (Some(i), _) => *i,
        (None, Some(var)) => std::env::var(var)
            .map_err(|_| input_error(format!("--index-env: the variable {var} is not set")))?
            .trim()
            .parse()
            .map_err(|_| input_error(format!("--index-env: {var} is not an index")))?,
        (None, None) => return Err(input_error("--index or --index-env is needed")),
    };
    // A scheduler stops a worker by signalling it; the model it runs goes with it (the
    // handler `main` installs for every command).
    let report = run_manifest_task(&args.manifest, index).map_err(campaign_error)?;
    let value = json!({
        "index": index,
        "host": report.host,
        "exit_code": report.exit_code,
        "signal": report.signal,
        "runs": report.runs.iter().map(|r| json!({"run_id": r.run_id, "attempt": r.attempt, "outcome": r.kind.as_str(), "reason": r.reason})).collect::<Vec<_>>(),
    });
    emit(json, &value, || {
        report
            .runs
            .iter()
            .map(|r| {
                format!(
                    "run {} attempt {}: {}{}",
                    r.run_id,
                    r.attempt,
                    r.kind,
                    r.reason
                        .as_ref()
                        .map_or_else(String::new, |x| format!(" ({x})"))
                )
            })
            .collect::<Vec<_>>()
            .join("\n")
    });
    Ok(())
}
