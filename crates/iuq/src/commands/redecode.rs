//! `iuq redecode STUDY`: decode the outputs of a campaign's finished runs again from their run
//! directories with the study's current output decoder, without running the model.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;

use iuq_study::campaign_runs::{campaign_error, open_campaign};
use iuq_study::campaign_study::load_study;

use crate::report_output::emit;

/// Arguments of `iuq redecode`.
#[derive(Debug, Args)]
pub struct RedecodeArgs {
    /// The study file (a campaign study, or a pipeline study whose model runs are a campaign).
    pub study: PathBuf,
}

/// Run `iuq redecode`.
pub fn run(args: &RedecodeArgs, json: bool) -> Result<()> {
    let study = load_study(&args.study)?;
    let name = study.name.clone();
    let (mut campaign, _) = open_campaign(study, None)?;
    let summary = campaign.redecode().map_err(campaign_error)?;
    let value = serde_json::json!({
        "study": name,
        "store": campaign.store().path().display().to_string(),
        "runs": summary.runs,
        "updated": summary.updated,
        "values_changed": summary.values_changed,
        "unchanged": summary.unchanged,
        "missing_directory": summary.missing_directory,
        "undecodable": summary.undecodable.iter().map(|(run_id, reason)| serde_json::json!({"run_id": run_id, "reason": reason})).collect::<Vec<_>>(),
    });
    emit(json, &value, || {
        let mut text = format!(
            "campaign {name}: {} succeeded runs decoded again: {} updated ({} with a changed value), {} unchanged, {} without a run directory (kept)",
            summary.runs,
            summary.updated,
            summary.values_changed,
            summary.unchanged,
            summary.missing_directory
        );
        for (run_id, reason) in &summary.undecodable {
            text.push_str(&format!("\n  run {run_id}: not decoded (kept): {reason}"));
        }
        text
    });
    Ok(())
}
