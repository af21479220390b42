//! `iuq retry STUDY [--failed] [--lost]`: put failed runs back to pending and run them again.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;

use iuq_study::campaign_runs::{campaign_error, open_campaign};
use iuq_study::campaign_study::load_study;

use crate::commands::run::{drive, summary, summary_text};
use crate::report_output::emit;

/// Arguments of `iuq retry`.
#[derive(Debug, Args)]
pub struct RetryArgs {
    /// The study file.
    pub study: PathBuf,
    /// Retry runs that failed (model failures, infrastructure failures, timeouts).
    #[arg(long)]
    pub failed: bool,
    /// Retry runs whose last execution was lost.
    #[arg(long)]
    pub lost: bool,
    /// Runs at once (overrides `executor.max_parallel`).
    #[arg(long)]
    pub max_parallel: Option<usize>,
    /// Seconds between log lines when stderr is not a terminal.
    #[arg(long, default_value_t = 5.0, value_parser = super::run::log_interval_seconds)]
    pub log_interval: f64,
}

/// Run `iuq retry` (with neither flag, both).
pub fn run(args: &RetryArgs, json: bool) -> Result<()> {
    let (failed, lost) = if args.failed || args.lost {
        (args.failed, args.lost)
    } else {
        (true, true)
    };
    let study = load_study(&args.study)?;
    let (mut campaign, resume) = open_campaign(study, args.max_parallel)?;
    let reset = campaign
        .reset_for_retry(failed, lost)
        .map_err(campaign_error)?;
    let counts = drive(&mut campaign, json, args.log_interval)?;
    let mut value = summary(&campaign, &counts, &resume);
    value["retried"] = serde_json::json!(reset);
    emit(json, &value, || {
        format!("retried {reset} runs\n{}", summary_text(&value))
    });
    Ok(())
}
