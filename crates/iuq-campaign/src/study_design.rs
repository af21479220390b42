//! The study file's `[design]`: what it asks for ([`StudyDesign`], defined and read with the rest
//! of the study in [`crate::study`]) and the points it makes for `iuq run` ([`design_points`]):
//! built on the unit cube and mapped through the priors (so non-uniform priors get designs
//! distributed as the prior), or read from a file. (The designs a campaign store has recorded,
//! whoever asked for them, are [`crate::store::recorded_designs`].)

use iuq_doe::{LhsMethod, Scrambling, latin_hypercube, sobol_points};

use crate::decoder::read_csv_text;
use crate::error::{CampaignError, Result};
use crate::study::CampaignStudy;

pub use crate::study::StudyDesign;

/// The points of the study's design (an input error when the study has none).
pub fn design_points(study: &CampaignStudy) -> Result<Vec<Vec<f64>>> {
    let file = study.path.display().to_string();
    let spec = study.design.as_ref().ok_or_else(|| {
        CampaignError::study(
            &file,
            "design",
            "missing: `iuq run` needs a [design] (kind = \"lhs\", n = …)",
        )
    })?;
    let d = study.space.dimension();
    let unit = match spec {
        StudyDesign::Lhs { n, seed } => latin_hypercube(*n, d, LhsMethod::maximin(), *seed)
            .map_err(|e| CampaignError::study(&file, "design", e.to_string()))?,
        StudyDesign::Sobol { n, seed } => sobol_points(
            d,
            *n,
            Scrambling::LinearMatrixWithShift {
                seed: *seed,
                replicate: 0,
            },
        )
        .map_err(|e| CampaignError::study(&file, "design", e.to_string()))?,
        StudyDesign::File { path } => return read_design_file(study, path),
    };
    unit.iter()
        .enumerate()
        .map(|(i, u)| {
            let x = study
                .space
                .from_unit_cube(u)
                .map_err(|e| CampaignError::study(&file, "design", e.to_string()))?;
            if x.iter().all(|v| v.is_finite()) {
                Ok(x)
            } else {
                Err(CampaignError::study(
                    &file,
                    "design",
                    format!("point {i} maps to a non-finite parameter value through the priors"),
                ))
            }
        })
        .collect()
}

fn read_design_file(study: &CampaignStudy, path: &std::path::Path) -> Result<Vec<Vec<f64>>> {
    let file = study.path.display().to_string();
    let err = |reason: String| {
        CampaignError::study(
            &file,
            "design.file",
            format!("{}: {reason}", path.display()),
        )
    };
    let text = std::fs::read_to_string(path).map_err(|e| err(format!("cannot read: {e}")))?;
    let (header, rows) = read_csv_text(&text).map_err(err)?;
    let columns = study
        .space
        .names()
        .iter()
        .map(|name| {
            header.iter().position(|h| h == name).ok_or_else(|| {
                err(format!(
                    "no column `{name}` (columns: {})",
                    header.join(", ")
                ))
            })
        })
        .collect::<Result<Vec<usize>>>()?;
    rows.iter()
        .enumerate()
        .map(|(i, row)| {
            columns
                .iter()
                .map(|&k| {
                    let cell = row.get(k).map_or("", String::as_str);
                    cell.parse::<f64>()
                        .ok()
                        .filter(|v| v.is_finite())
                        .ok_or_else(|| {
                            err(format!(
                                "data row {}, column `{}`: `{cell}` is not a finite number",
                                i + 1,
                                header[k]
                            ))
                        })
                })
                .collect()
        })
        .collect()
}
