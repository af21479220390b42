//! The cell at a MAP at every stress, in pictures (`rbc-shear` studies): the native cell model
//! run again at the MAP with its shape read through the whole run ([`iuq_rbc::shear_portrait`]),
//! for the report's shapes and elongation-against-strain figures (the model posterior's MAP, and
//! the surrogate posterior's beside it in the latter).
//!
//! The portraits are recorded in the campaign store as a derived result (key
//! [`PORTRAITS_KEY`], fingerprinted by the MAP, the stresses, the `[model]` section and iuq's
//! version), so a replay of the study reads them back instead of running the cell model again.

use rayon::prelude::*;

use iuq_rbc::{ShearPortrait, shear_portrait};

use super::model_runs::ModelRuns;
use crate::error::{Result, StudyError};
use crate::study::{ModelSection, Study};

/// Key of the portraits in the campaign store's derived results.
pub const PORTRAITS_KEY: &str = "cell-portraits-at-map";

/// Points of each run's elongation trace.
const TRACE_POINTS: usize = 80;

/// The cell at `map` (the model's parameters; `whose` names it in messages, e.g. "the model
/// posterior's MAP") at every stress of `runs`, read back from the campaign store or run now
/// (in parallel) and recorded; `None` for a study whose model is not the cell model.
pub fn portraits_at(
    study: &Study,
    runs: &ModelRuns,
    map: &[f64],
    whose: &str,
    message: &mut dyn FnMut(String),
) -> Result<Option<Vec<ShearPortrait>>> {
    let ModelSection::RbcShear { table } = &study.model else {
        return Ok(None);
    };
    let model = study.rbc_shear_model()?;
    let stresses: Vec<f64> = (0..runs.groups())
        .filter_map(|g| runs.group_abscissa(g))
        .collect();
    let fingerprint = iuq_campaign::study::hex_sha256(
        format!(
            "iuq {} portraits v1 trace {TRACE_POINTS}\nmap {:?}\nstresses {:?}\nmodel {}",
            env!("CARGO_PKG_VERSION"),
            map.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            stresses.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            toml::Value::Table(table.clone())
        )
        .as_bytes(),
    );
    if let Some(text) = runs.derived_result(PORTRAITS_KEY, &fingerprint)? {
        let portraits: Vec<ShearPortrait> = serde_json::from_str(&text).map_err(|e| {
            StudyError::failure(format!(
                "the cell portraits recorded in the campaign store do not parse: {e}"
            ))
            .with_source(e)
        })?;
        return Ok(Some(portraits));
    }
    message(format!(
        "the cell at {whose} in pictures: {} runs of the cell model in this process (recorded in the campaign store for replays)",
        stresses.len()
    ));
    let cell = model
        .cell_parameters(map)
        .map_err(|e| StudyError::failure(format!("the cell at {whose}: {e}")).with_source(e))?;
    let portraits = stresses
        .par_iter()
        .map(|&stress| {
            let mut experiment = model.experiment(&cell, stress);
            experiment.parallel = false;
            shear_portrait(&experiment, TRACE_POINTS).map_err(|e| {
                StudyError::failure(format!("the cell at {whose} at {stress} Pa: {e}"))
                    .with_source(e)
            })
        })
        .collect::<Result<Vec<_>>>()?;
    runs.record_derived_result(
        PORTRAITS_KEY,
        &fingerprint,
        &serde_json::to_string(&portraits)?,
    )?;
    Ok(Some(portraits))
}
