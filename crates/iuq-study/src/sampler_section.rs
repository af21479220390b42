//! The `[sampler]` section of a study: the BASIS settings, each overridable on the command line.
//!
//! ```toml
//! [sampler]
//! samples = 10000            # N (default 1000)
//! burn = 10                  # n_burn (default 0)
//! max_chain = 1              # l_max (default 1)
//! seed = 1                   # (default 0)
//! cv_target = 1.0            # γ (default 1)
//! proposal_scale = 0.2       # β (default 0.2)
//! resampling = "multinomial" # | "systematic"
//! min_step = 1e-6            # smallest exponent step (default 1e-6)
//! on_min_step = "clamp"      # | "stop"
//! max_stages = 100           # annealing stages before p = 1 (default 100)
//! ```

use iuq_basis::{BasisError, BasisSettings, CheckedSettings, MinStepAction, Resampling};

use crate::error::{Result, input_error};
use crate::study::Study;

/// The keys the `[sampler]` section accepts.
pub const SAMPLER_KEYS: [&str; 10] = [
    "samples",
    "burn",
    "max_chain",
    "seed",
    "cv_target",
    "proposal_scale",
    "resampling",
    "min_step",
    "on_min_step",
    "max_stages",
];

/// Command-line overrides of the section.
#[derive(Debug, Clone, Copy, Default)]
pub struct SamplerOverrides {
    /// `--samples`.
    pub samples: Option<usize>,
    /// `--burn`.
    pub burn: Option<usize>,
    /// `--max-chain`.
    pub max_chain: Option<usize>,
    /// `--seed`.
    pub seed: Option<u64>,
}

/// The study key and command-line flag of each setting of [`BasisSettings`].
fn names_of(setting: &str) -> (&'static str, Option<&'static str>) {
    match setting {
        "samples" => ("samples", Some("--samples")),
        "burn_in" => ("burn", Some("--burn")),
        "max_chain_length" => ("max_chain", Some("--max-chain")),
        "seed" => ("seed", Some("--seed")),
        "cv_target" => ("cv_target", None),
        "proposal_scale" => ("proposal_scale", None),
        "resampling" => ("resampling", None),
        "min_step" => ("min_step", None),
        "on_min_step" => ("on_min_step", None),
        _ => ("max_stages", None),
    }
}

/// Read the `[sampler]` section (defaults where absent), apply the overrides and check the
/// settings. Errors name the file and key, or the flag when the value came from one.
pub fn parse_sampler(study: &Study, overrides: &SamplerOverrides) -> Result<CheckedSettings> {
    let file = study.path.display().to_string();
    let empty = toml::Table::new();
    let table = study.sampler.as_ref().unwrap_or(&empty);
    if let Some(key) = table.keys().find(|k| !SAMPLER_KEYS.contains(&k.as_str())) {
        return Err(input_error(format!(
            "{file}: key `sampler.{key}`: unknown key (expected one of {})",
            SAMPLER_KEYS.join(", ")
        )));
    }
    let count = |key: &str| -> Result<Option<u64>> {
        match table.get(key) {
            None => Ok(None),
            Some(v) => v
                .as_integer()
                .and_then(|i| u64::try_from(i).ok())
                .map(Some)
                .ok_or_else(|| {
                    input_error(format!(
                        "{file}: key `sampler.{key}`: expected a non-negative integer, got {v}"
                    ))
                }),
        }
    };
    let real = |key: &str| -> Result<Option<f64>> {
        match table.get(key) {
            None => Ok(None),
            Some(v) => v
                .as_float()
                .or_else(|| v.as_integer().map(|i| i as f64))
                .map(Some)
                .ok_or_else(|| {
                    input_error(format!(
                        "{file}: key `sampler.{key}`: expected a number, got {v}"
                    ))
                }),
        }
    };
    let word = |key: &str| -> Result<Option<String>> {
        match table.get(key) {
            None => Ok(None),
            Some(v) => v.as_str().map(|s| Some(s.to_string())).ok_or_else(|| {
                input_error(format!(
                    "{file}: key `sampler.{key}`: expected a string, got {v}"
                ))
            }),
        }
    };
    let usize_of = |v: Option<u64>, key: &str| -> Result<Option<usize>> {
        v.map(|v| {
            usize::try_from(v)
                .map_err(|_| input_error(format!("{file}: key `sampler.{key}`: {v} is too large")))
        })
        .transpose()
    };
    let d = BasisSettings::default();
    let resampling = match word("resampling")?.as_deref() {
        None => d.resampling,
        Some("multinomial") => Resampling::Multinomial,
        Some("systematic") => Resampling::Systematic,
        Some(other) => {
            return Err(input_error(format!(
                "{file}: key `sampler.resampling`: unknown scheme `{other}` (multinomial or systematic)"
            )));
        }
    };
    let on_min_step = match word("on_min_step")?.as_deref() {
        None => d.on_min_step,
        Some("clamp") => MinStepAction::Clamp,
        Some("stop") => MinStepAction::Stop,
        Some(other) => {
            return Err(input_error(format!(
                "{file}: key `sampler.on_min_step`: unknown action `{other}` (clamp or stop)"
            )));
        }
    };
    let settings = BasisSettings {
        samples: overrides
            .samples
            .or(usize_of(count("samples")?, "samples")?)
            .unwrap_or(d.samples),
        burn_in: overrides
            .burn
            .or(usize_of(count("burn")?, "burn")?)
            .unwrap_or(d.burn_in),
        max_chain_length: overrides
            .max_chain
            .or(usize_of(count("max_chain")?, "max_chain")?)
            .unwrap_or(d.max_chain_length),
        cv_target: real("cv_target")?.unwrap_or(d.cv_target),
        proposal_scale: real("proposal_scale")?.unwrap_or(d.proposal_scale),
        resampling,
        min_step: real("min_step")?.unwrap_or(d.min_step),
        on_min_step,
        max_stages: usize_of(count("max_stages")?, "max_stages")?.unwrap_or(d.max_stages),
        seed: overrides.seed.or(count("seed")?).unwrap_or(d.seed),
    };
    settings.check().map_err(|e| match e {
        BasisError::InvalidSettings { setting, reason } => {
            let (key, flag) = names_of(setting);
            let from_flag = match setting {
                "samples" => overrides.samples.is_some(),
                "burn_in" => overrides.burn.is_some(),
                "max_chain_length" => overrides.max_chain.is_some(),
                "seed" => overrides.seed.is_some(),
                _ => false,
            };
            match (from_flag, flag) {
                (true, Some(flag)) => input_error(format!("{flag}: {reason}")),
                _ => input_error(format!("{file}: key `sampler.{key}`: {reason}")),
            }
        }
        other => input_error(format!("{file}: section `[sampler]`: {other}")),
    })
}
