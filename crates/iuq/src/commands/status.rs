//! `iuq status STUDY`: runs per status, attempts per outcome, and the failures with reasons.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;

use iuq_study::campaign_runs::{CampaignStatus, human_duration};
use iuq_study::campaign_study::load_study;

use crate::report_output::{emit, short};

/// Arguments of `iuq status`.
#[derive(Debug, Args)]
pub struct StatusArgs {
    /// The study file.
    pub study: PathBuf,
    /// Failures listed in the text output (all of them are in the JSON).
    #[arg(long, default_value_t = 20)]
    pub max_failures: usize,
}

/// Run `iuq status`.
pub fn run(args: &StatusArgs, json: bool) -> Result<()> {
    let study = load_study(&args.study)?;
    let status = CampaignStatus::read(&study)?;
    let value = status.to_json();
    let (counts, attempts, failures, names) = (
        &status.counts,
        &status.attempts,
        &status.failures,
        &status.parameter_names,
    );
    emit(json, &value, || {
        let mut text = format!(
            "campaign {}: {} runs\n  pending {}  queued {}  running {}  succeeded {}  failed {}  cancelled {}",
            study.name,
            counts.total(),
            counts.pending,
            counts.queued,
            counts.running,
            counts.succeeded,
            counts.failed,
            counts.cancelled
        );
        if !attempts.is_empty() {
            text.push_str("\nattempts by outcome: ");
            text.push_str(
                &attempts
                    .iter()
                    .map(|(k, n)| format!("{k} {n}"))
                    .collect::<Vec<_>>()
                    .join(", "),
            );
        }
        let open: Vec<_> = status
            .designs
            .iter()
            .filter(|d| d.counts.pending + d.counts.queued + d.counts.running > 0)
            .collect();
        if !status.designs.is_empty() {
            text.push_str(&format!(
                "\ndesigns: {}, {} with runs left{}",
                status.designs.len(),
                open.len(),
                if open.is_empty() { "" } else { ":" }
            ));
            for d in &open {
                let c = &d.counts;
                text.push_str(&format!(
                    "\n  {} `{}`: {} points, {} succeeded, {} failed, {} cancelled, {} pending, {} queued or running",
                    d.id,
                    d.label,
                    d.size,
                    c.succeeded,
                    c.failed,
                    c.cancelled,
                    c.pending,
                    c.queued + c.running
                ));
                if let (Some(first), Some(last)) = (d.first_started_at, d.last_finished_at) {
                    text.push_str(&format!(
                        "; run time {} over {}",
                        human_duration(d.run_seconds),
                        human_duration(last - first)
                    ));
                }
            }
        }
        if !failures.is_empty() {
            text.push_str("\nfailures:");
            for f in failures.iter().take(args.max_failures) {
                let params = names
                    .iter()
                    .zip(&f.parameters)
                    .map(|(n, v)| format!("{n}={}", short(*v)))
                    .collect::<Vec<_>>()
                    .join(" ");
                text.push_str(&format!(
                    "\n  run {} [{}] {}: {}",
                    f.run_id, params, f.kind, f.reason
                ));
            }
            if failures.len() > args.max_failures {
                text.push_str(&format!(
                    "\n  … and {} more (see --json)",
                    failures.len() - args.max_failures
                ));
            }
        }
        text
    });
    Ok(())
}
