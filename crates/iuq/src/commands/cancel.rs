//! `iuq cancel STUDY --design ID…`: set a design's pending runs aside.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use serde_json::json;

use iuq_study::campaign_runs::{campaign_error, open_campaign};
use iuq_study::campaign_study::load_study;

use crate::report_output::emit;

/// Arguments of `iuq cancel`.
#[derive(Debug, Args)]
pub struct CancelArgs {
    /// The study file.
    pub study: PathBuf,
    /// The id of a design whose pending runs nothing should run (`iuq status` lists the
    /// designs); repeat for several.
    #[arg(long = "design", required = true)]
    pub designs: Vec<i64>,
}

/// Run `iuq cancel`: every design is checked before any is cancelled, so that a bad id
/// changes nothing.
pub fn run(args: &CancelArgs, json: bool) -> Result<()> {
    let study = load_study(&args.study)?;
    let (campaign, _) = open_campaign(study, None)?;
    let known = campaign
        .store()
        .design_summaries()
        .map_err(campaign_error)?;
    if let Some(missing) = args
        .designs
        .iter()
        .find(|id| !known.iter().any(|d| d.id == **id))
    {
        // The same error as cancelling it would give, before anything changed.
        campaign
            .store()
            .cancel_design(*missing)
            .map_err(campaign_error)?;
    }
    let mut done = Vec::new();
    for &id in &args.designs {
        done.push(campaign.store().cancel_design(id).map_err(campaign_error)?);
    }
    let value = json!({ "cancelled": done });
    emit(json, &value, || {
        done.iter()
            .map(|c| {
                let counts = &c.design.counts;
                format!(
                    "design {} (`{}`, {} points): {} pending runs cancelled; {} succeeded, {} failed, {} queued or running left as they are (a design that asks for a cancelled run again runs it)",
                    c.design.id,
                    c.design.label,
                    c.design.size,
                    c.cancelled,
                    counts.succeeded,
                    counts.failed,
                    counts.queued + counts.running
                )
            })
            .collect::<Vec<_>>()
            .join("\n")
    });
    Ok(())
}
