//! `iuq status STUDY`: runs per status, attempts per outcome, and the failures with reasons.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use serde_json::{Map, Value, json};

use iuq_campaign::{CampaignStore, store_path};
use iuq_study::campaign_runs::{campaign_error, load_study};

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
    let path = store_path(&study);
    let store = CampaignStore::open_existing(&path).map_err(campaign_error)?;
    let counts = store.counts(None).map_err(campaign_error)?;
    let attempts = store.attempt_kinds().map_err(campaign_error)?;
    let failures = store.failures().map_err(campaign_error)?;
    let names = study.space.names();
    let failure_values: Vec<Value> = failures
        .iter()
        .map(|f| {
            let parameters: Map<String, Value> =
                names.iter().cloned().zip(f.parameters.iter().map(|v| json!(v))).collect();
            json!({"run_id": f.run_id, "parameters": parameters, "attempts": f.attempts, "kind": f.kind, "reason": f.reason})
        })
        .collect();
    let attempts_map: Map<String, Value> = attempts
        .iter()
        .map(|(k, n)| (k.clone(), json!(n)))
        .collect();
    let value = json!({
        "study": study.name,
        "store": path.display().to_string(),
        "journal_mode": store.journal_mode(),
        "counts": counts,
        "total": counts.total(),
        "attempts": attempts_map,
        "failures": failure_values,
    });
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
