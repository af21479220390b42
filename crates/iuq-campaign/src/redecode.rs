//! Decoding the outputs of finished runs again from their run directories: after the study's
//! output decoder was fixed or learned to read more (a computational std), the stored outcomes
//! follow without running the model again.
//!
//! Every succeeded run whose directory still exists is decoded with the study's current decoder;
//! its stored outputs are replaced when anything differs. A run whose directory is gone (a clone
//! of a repository that ships the store without its run folders) or whose output no longer
//! decodes keeps its stored outputs and is counted. All replacements are one transaction.

use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::error::{CampaignError, Result};
use crate::store::CampaignStore;
use crate::study::CampaignStudy;

/// What [`redecode`] did.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct RedecodeSummary {
    /// Succeeded runs in the store.
    pub runs: usize,
    /// Runs whose stored outputs were replaced (a value or a std differed).
    pub updated: usize,
    /// Of those, runs where a value (not only a std) differed.
    pub values_changed: usize,
    /// Runs decoded to exactly what the store held.
    pub unchanged: usize,
    /// Runs whose directory no longer exists (outputs kept).
    pub missing_directory: usize,
    /// Runs whose output did not decode, with the reason (outputs kept).
    pub undecodable: Vec<(i64, String)>,
}

/// The run directory of a stored attempt: the recorded path, or, when that is gone, the folder
/// of the same name under the campaign's `runs/` (a campaign directory that was moved).
fn run_directory(recorded: &Path, campaign_directory: &Path) -> Option<PathBuf> {
    if recorded.is_dir() {
        return Some(recorded.to_path_buf());
    }
    let moved = campaign_directory.join("runs").join(recorded.file_name()?);
    moved.is_dir().then_some(moved)
}

/// Decode every succeeded run of `store` again with `study`'s decoder (see the module).
pub fn redecode(
    store: &mut CampaignStore,
    study: &CampaignStudy,
    campaign_directory: &Path,
) -> Result<RedecodeSummary> {
    let decoder = study
        .model
        .output_decoder()
        .map_err(|reason| CampaignError::BadInput(format!("key `model.output`: {reason}")))?
        .ok_or_else(|| {
            CampaignError::BadInput(
                "key `model.kind`: a batch-command model's outputs are not read from the run directories; nothing to decode again".to_string(),
            )
        })?;
    let names = study.model.outputs.clone();
    let runs = store.succeeded_runs()?;
    let mut summary = RedecodeSummary {
        runs: runs.len(),
        ..Default::default()
    };
    let mut replacements = Vec::new();
    for run in runs {
        let Some(directory) = run_directory(&run.directory, campaign_directory) else {
            summary.missing_directory += 1;
            continue;
        };
        let (values, std) = match decoder.decode(&directory) {
            Ok(decoded) => decoded,
            Err((_, reason)) => {
                summary.undecodable.push((run.run_id, reason));
                continue;
            }
        };
        let stored_values: Vec<f64> = run.outputs.iter().map(|o| o.0).collect();
        let stored_std: Vec<Option<f64>> = run.outputs.iter().map(|o| o.1).collect();
        let new_std: Vec<Option<f64>> = match &std {
            Some(s) => s.iter().map(|v| Some(*v)).collect(),
            None => vec![None; values.len()],
        };
        let same_values = stored_values.len() == values.len()
            && stored_values
                .iter()
                .zip(&values)
                .all(|(a, b)| a.to_bits() == b.to_bits());
        let same_std = stored_std.len() == new_std.len()
            && stored_std
                .iter()
                .zip(&new_std)
                .all(|(a, b)| a.map(f64::to_bits) == b.map(f64::to_bits));
        if same_values && same_std {
            summary.unchanged += 1;
            continue;
        }
        summary.updated += 1;
        if !same_values {
            summary.values_changed += 1;
        }
        replacements.push((run.run_id, run.attempt_id, values, std));
    }
    if !replacements.is_empty() {
        store.write(|w| {
            for (run_id, attempt_id, values, std) in &replacements {
                w.replace_outputs(*run_id, *attempt_id, &names, values, std.as_deref())?;
            }
            Ok(())
        })?;
    }
    Ok(summary)
}
