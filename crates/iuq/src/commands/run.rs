//! `iuq run STUDY`: run the study's design as a campaign of model runs (resuming whatever an
//! earlier coordinator left), with a progress bar on a terminal and log lines otherwise.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::Result;
use clap::Args;
use serde_json::{Value, json};

use iuq_campaign::study_design::design_points;
use iuq_campaign::{Campaign, Progress, ResumeSummary, StatusCounts};
use iuq_core::Control;
use iuq_study::campaign_runs::{campaign_error, open_campaign, progress_line};
use iuq_study::campaign_study::load_study;

use crate::report_output::emit;

/// Arguments of `iuq run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// The study file (TOML) with a `[model]` of kind "command" or "batch-command" and a
    /// `[design]`.
    // The help text is given here: in a doc comment, rustdoc reads a bare [model] as a link.
    #[arg(
        help = "The study file (TOML) with a [model] of kind \"command\" or \"batch-command\" and a [design]"
    )]
    pub study: PathBuf,
    /// Runs at once (overrides `executor.max_parallel`).
    #[arg(long)]
    pub max_parallel: Option<usize>,
    /// Seconds between log lines when stderr is not a terminal.
    #[arg(long, default_value_t = 5.0, value_parser = log_interval_seconds)]
    pub log_interval: f64,
}

/// `--log-interval`: seconds from 0.1 to a day (a value that is no duration is an input error).
pub fn log_interval_seconds(text: &str) -> std::result::Result<f64, String> {
    let seconds: f64 = text
        .trim()
        .parse()
        .map_err(|_| format!("`{text}` is not a number of seconds"))?;
    if (0.1..=86_400.0).contains(&seconds) {
        Ok(seconds)
    } else {
        Err(format!("{seconds} s is not from 0.1 s to a day (86400 s)"))
    }
}

/// Run every pending run of the campaign, showing progress on stderr: a progress bar with ETA
/// when stderr is a terminal (and `--json` is off), log lines every `log_interval` otherwise.
pub fn drive(campaign: &mut Campaign, json: bool, log_interval: f64) -> Result<StatusCounts> {
    let name = campaign.study().name.clone();
    let interactive = !json && std::io::stderr().is_terminal();
    if interactive {
        let bar = indicatif::ProgressBar::new(0);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{prefix} [{bar:40}] {pos}/{len} {msg} (elapsed {elapsed}, ETA {eta})",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> "),
        );
        bar.set_prefix(name.clone());
        let counts = campaign
            .run(Duration::from_millis(200), &mut |p: &Progress| {
                bar.set_length(p.counts.total());
                bar.set_position(p.counts.finished());
                bar.set_message(format!(
                    "{} failed, {} running",
                    p.counts.failed + p.counts.cancelled,
                    p.counts.running
                ));
                Control::Continue
            })
            .map_err(campaign_error)?;
        bar.finish();
        Ok(counts)
    } else {
        let interval = Duration::from_secs_f64(log_interval);
        let counts = campaign
            .run(interval, &mut |p: &Progress| {
                eprintln!("{}", progress_line(&name, p));
                Control::Continue
            })
            .map_err(campaign_error)?;
        Ok(counts)
    }
}

/// The summary printed by `iuq run` and `iuq retry`.
pub fn summary(campaign: &Campaign, counts: &StatusCounts, resume: &ResumeSummary) -> Value {
    json!({
        "study": campaign.study().name,
        "directory": campaign.directory().display().to_string(),
        "store": campaign.store().path().display().to_string(),
        "executor": campaign.study().executor.kind.as_str(),
        "counts": counts,
        "total": counts.total(),
        "resumed": resume,
    })
}

/// Human text of a summary.
pub fn summary_text(v: &Value) -> String {
    let c = &v["counts"];
    let mut text = format!(
        "campaign {}: {} runs, {} succeeded, {} failed, {} cancelled\nstore: {}",
        v["study"].as_str().unwrap_or_default(),
        v["total"],
        c["succeeded"],
        c["failed"],
        c["cancelled"],
        v["store"].as_str().unwrap_or_default()
    );
    let r = &v["resumed"];
    if r["ingested"].as_u64().unwrap_or(0)
        + r["lost"].as_u64().unwrap_or(0)
        + r["reattached"].as_u64().unwrap_or(0)
        > 0
    {
        text.push_str(&format!(
            "\nresumed: {} results ingested, {} executions reattached, {} lost (retried by policy)",
            r["ingested"], r["reattached"], r["lost"]
        ));
    }
    if let Some(n) = r["restarted"].as_u64().filter(|&n| n > 0) {
        text.push_str(&format!(
            "\n{n} runs whose command could not start last time were run again"
        ));
    }
    if c["failed"].as_u64().unwrap_or(0) > 0 {
        text.push_str("\nsee `iuq status` for the failures and their reasons");
    }
    text
}

/// Run `iuq run`.
pub fn run(args: &RunArgs, json: bool) -> Result<()> {
    let study = load_study(&args.study)?;
    let points = design_points(&study).map_err(campaign_error)?;
    let (mut campaign, resume) = open_campaign(study, args.max_parallel)?;
    campaign
        .add_points("design", &points)
        .map_err(campaign_error)?;
    let counts = drive(&mut campaign, json, args.log_interval)?;
    let value = summary(&campaign, &counts, &resume);
    emit(json, &value, || summary_text(&value));
    Ok(())
}
