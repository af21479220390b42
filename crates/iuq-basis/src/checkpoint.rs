//! Checkpoints: the [`BasisState`] after a stage as self-describing JSON, enough to resume the
//! run bit-identically.
//!
//! Format (version 1), one JSON object:
//! ```text
//! {
//!   "format": "iuq-basis-checkpoint",
//!   "version": 1,
//!   "parameter_names": ["kLink", ..., "sigma_m"],
//!   "settings": { "samples", "burn_in", "max_chain_length", "cv_target", "proposal_scale",
//!                 "resampling": "multinomial" | "systematic", "min_step",
//!                 "on_min_step": "clamp" | "stop", "max_stages", "seed" },
//!   "stage": k,                       // last completed stage; the random-stream position
//!   "exponent": p,                    // annealing exponent of the population
//!   "log_evidence": ln Z so far,
//!   "samples": [[θ_1], ..., [θ_N]],   // the population, N rows in parameter order
//!   "log_likelihood": [...],          // ln f(D|θ_i); null = −∞ (a failed member, stage 0 only)
//!   "log_prior": [...],               // ln π(θ_i)
//!   "evaluations": total model evaluations,
//!   "diagnostics": [ per-stage objects, see StageDiagnostics ],
//!   "stop_reason": null | { "kind": "converged" | "max_stages" | "step_below_minimum", ... }
//! }
//! ```
//! Numbers are written in the shortest form that reads back to the same `f64` (serde_json with
//! `float_roundtrip`), so the population, log-likelihoods and evidence of a resumed run are
//! bit-identical. The library writes and reads strings; writing the file atomically is the
//! caller's business.

use serde::{Deserialize, Serialize};

use crate::error::{BasisError, Result};
use crate::sampler::BasisState;
use crate::settings::MAX_STEPS;

/// The `format` field of a checkpoint.
pub const CHECKPOINT_FORMAT: &str = "iuq-basis-checkpoint";
/// The version of the format written by this crate (and the only one read).
pub const CHECKPOINT_VERSION: u32 = 1;

#[derive(Serialize)]
struct CheckpointRef<'a> {
    format: &'static str,
    version: u32,
    #[serde(flatten)]
    state: &'a BasisState,
}

#[derive(Deserialize)]
struct CheckpointHeader {
    format: Option<String>,
    version: Option<u32>,
}

#[derive(Deserialize)]
struct CheckpointOwned {
    #[allow(dead_code)]
    format: String,
    #[allow(dead_code)]
    version: u32,
    #[serde(flatten)]
    state: BasisState,
}

/// The checkpoint of `state` as JSON text.
pub fn to_json(state: &BasisState) -> Result<String> {
    serde_json::to_string(&CheckpointRef {
        format: CHECKPOINT_FORMAT,
        version: CHECKPOINT_VERSION,
        state,
    })
    .map_err(|e| BasisError::Checkpoint(e.to_string()))
}

/// Read a checkpoint, checking its format, version and internal consistency (population size,
/// dimensions, finite values, one diagnostics entry per stage, exponent in [0, 1]).
pub fn from_json(text: &str) -> Result<BasisState> {
    let header: CheckpointHeader =
        serde_json::from_str(text).map_err(|e| BasisError::Checkpoint(e.to_string()))?;
    match header.format.as_deref() {
        Some(CHECKPOINT_FORMAT) => {}
        Some(other) => {
            return Err(BasisError::Checkpoint(format!(
                "format is `{other}`, expected `{CHECKPOINT_FORMAT}`"
            )));
        }
        None => {
            return Err(BasisError::Checkpoint(format!(
                "no `format` field (expected `{CHECKPOINT_FORMAT}`)"
            )));
        }
    }
    match header.version {
        Some(CHECKPOINT_VERSION) => {}
        Some(v) => {
            return Err(BasisError::Checkpoint(format!(
                "version {v} is not supported (this build reads version {CHECKPOINT_VERSION})"
            )));
        }
        None => return Err(BasisError::Checkpoint("no `version` field".into())),
    }
    let owned: CheckpointOwned =
        serde_json::from_str(text).map_err(|e| BasisError::Checkpoint(e.to_string()))?;
    let state = owned.state;
    validate(&state)?;
    Ok(state)
}

fn validate(state: &BasisState) -> Result<()> {
    let bad = |m: String| Err(BasisError::Checkpoint(m));
    let n = state.settings.samples;
    let d = state.parameter_names.len();
    if d == 0 {
        return bad("no parameter names".into());
    }
    if state.samples.len() != n || state.log_likelihood.len() != n || state.log_prior.len() != n {
        return bad(format!(
            "{} samples, {} log-likelihoods, {} log-priors; settings.samples = {n}",
            state.samples.len(),
            state.log_likelihood.len(),
            state.log_prior.len()
        ));
    }
    if let Some(i) = state.samples.iter().position(|x| x.len() != d) {
        return bad(format!("sample {i} does not have {d} values"));
    }
    if state.samples.iter().flatten().any(|v| !v.is_finite())
        || state.log_prior.iter().any(|v| !v.is_finite())
    {
        return bad("samples and log-priors must be finite".into());
    }
    if state
        .log_likelihood
        .iter()
        .any(|v| v.is_nan() || *v == f64::INFINITY)
    {
        return bad("log-likelihoods must be finite or null".into());
    }
    if !(0.0..=1.0).contains(&state.exponent) || !state.log_evidence.is_finite() {
        return bad(format!(
            "exponent {} must lie in [0, 1] and the log-evidence {} be finite",
            state.exponent, state.log_evidence
        ));
    }
    if state.stage > MAX_STEPS || state.evaluations > usize::MAX / 2 {
        return bad(format!(
            "stage {} or evaluations {} out of range (stages at most {MAX_STEPS})",
            state.stage, state.evaluations
        ));
    }
    if state.diagnostics.len() != state.stage + 1 {
        return bad(format!(
            "{} diagnostics entries for stage {} (one per stage expected)",
            state.diagnostics.len(),
            state.stage
        ));
    }
    Ok(())
}

/// Serde helper for log-likelihood vectors: −∞ (a failed member) as `null`.
pub use crate::json_numbers::negative_infinity_as_null;
