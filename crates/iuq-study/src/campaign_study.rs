//! The campaign a study file stands for, as the campaign verbs (`iuq run`, `status`, `retry`,
//! `cancel`, `export`, `redecode`) read it: a campaign study file itself, or the campaign of a
//! pipeline study's model runs.

use std::path::Path;

use iuq_campaign::CampaignStudy;

use crate::campaign_runs::campaign_error;
use crate::error::Result;
use crate::pipeline::model_runs::pipeline_campaign_study;

/// Read and validate a campaign study file, or a pipeline study file (one whose `[likelihood]`
/// has `data`): then the campaign of its model runs, as `iuq pipeline` writes it into the store.
pub fn load_study(path: &Path) -> Result<CampaignStudy> {
    let is_pipeline_study = std::fs::read_to_string(path)
        .ok()
        .and_then(|text| text.parse::<toml::Table>().ok())
        .and_then(|table| {
            table
                .get("likelihood")
                .and_then(toml::Value::as_table)
                .map(|likelihood| likelihood.contains_key("data"))
        })
        .unwrap_or(false);
    if is_pipeline_study {
        let study = crate::study::Study::load(path)?;
        return pipeline_campaign_study(&study);
    }
    CampaignStudy::load(path).map_err(campaign_error)
}
