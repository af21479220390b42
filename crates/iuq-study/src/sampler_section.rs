//! The `[sampler]` section of a study: the BASIS settings, each overridable on the command line.
//!
//! ```toml
//! [sampler]
//! samples = 10000            # N (default 1000)
//! burn = "auto"              # "auto" (default): moves until the chains decorrelate, at an
//!                            # adapted scale; a number: that many steps at proposal_scale
//! correlation = 0.3          # with "auto": the correlation a chain may keep with its start
//! max_burn = 50              # with "auto": steps per stage at most
//! max_chain = 1              # l_max (default 1)
//! seed = 1                   # (default 0)
//! cv_target = 1.0            # γ (default 1)
//! proposal_scale = 0.2       # β (default 0.2 with a numeric burn; not with "auto")
//! resampling = "multinomial" # | "systematic"
//! min_step = 1e-6            # smallest exponent step (default 1e-6)
//! on_min_step = "clamp"      # | "stop"
//! max_stages = 100           # annealing stages before p = 1 (default 100)
//! delayed_acceptance = true  # screen moves on a surrogate's means first (default true)
//! ```

use iuq_basis::{BasisError, BasisSettings, CheckedSettings, MinStepAction, Mixing, Resampling};

use iuq_study_file::StudySection;

use crate::error::{Result, input_error};
use crate::study::Study;

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
        "correlation" => ("correlation", None),
        "max_burn_in" => ("max_burn", None),
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
    parse_section(
        StudySection::optional(study.sampler.as_ref(), "sampler", &file),
        overrides,
    )
}

/// Read the `[model_sampler]` section (BASIS on the model itself in `iuq pipeline`) as
/// [`parse_sampler`] reads `[sampler]`, but with the published study's chains where the section
/// says nothing of the mixing: one step without burn-in (`burn = 0`; `max_chain` defaults to 1
/// in both sections), samples × stages model evaluations. A `burn` (a count or `"auto"`),
/// `correlation` or `max_burn` given in the section is honoured.
pub fn parse_model_sampler(study: &Study, overrides: &SamplerOverrides) -> Result<CheckedSettings> {
    let file = study.path.display().to_string();
    let mut section = StudySection::optional(study.model_sampler.as_ref(), "model_sampler", &file);
    let mixing_given = ["burn", "correlation", "max_burn"]
        .iter()
        .any(|key| section.value(key).is_some());
    let burn = overrides
        .burn
        .or((!mixing_given).then_some(PUBLISHED_MODEL_BURN_IN));
    parse_section(section, &SamplerOverrides { burn, ..*overrides })
}

/// Burn-in steps of BASIS on the model by default: none, as the published study's chains of one
/// step (each model evaluation a stage's proposal, none spent decorrelating).
pub const PUBLISHED_MODEL_BURN_IN: usize = 0;

fn parse_section(mut s: StudySection<'_>, overrides: &SamplerOverrides) -> Result<CheckedSettings> {
    let d = BasisSettings::default();
    let resampling = match s.choice("resampling", &["multinomial", "systematic"])? {
        None => d.resampling,
        Some("multinomial") => Resampling::Multinomial,
        Some(_) => Resampling::Systematic,
    };
    let on_min_step = match s.choice("on_min_step", &["clamp", "stop"])? {
        None => d.on_min_step,
        Some("clamp") => MinStepAction::Clamp,
        Some(_) => MinStepAction::Stop,
    };
    // The mixing: fixed when a number of steps or a scale is given (on the command line or in
    // the file), adaptive otherwise.
    let burn = match s.value("burn") {
        None => None,
        Some(toml::Value::String(text)) if text == "auto" => None,
        Some(toml::Value::Integer(_)) => s.count("burn", 0)?,
        Some(other) => {
            return Err(s
                .error(
                    "burn",
                    format!("must be \"auto\" or a count of steps ≥ 0, got {other}"),
                )
                .into());
        }
    };
    let burn = overrides.burn.or(burn);
    let proposal_scale = s.number("proposal_scale")?;
    let correlation = s.number("correlation")?;
    let max_burn = s.count("max_burn", 1)?;
    let mixing = if burn.is_some() || proposal_scale.is_some() {
        for (key, given) in [
            ("correlation", correlation.is_some()),
            ("max_burn", max_burn.is_some()),
        ] {
            if given {
                return Err(s
                    .error(
                        key,
                        "applies to burn = \"auto\" only, and a number of steps or a proposal_scale is given",
                    )
                    .into());
            }
        }
        Mixing::Fixed
    } else {
        let Mixing::Adaptive {
            correlation: c,
            max_burn_in: m,
        } = Mixing::ADAPTIVE
        else {
            return Err(s.section_error("the default mixing is not adaptive").into());
        };
        Mixing::Adaptive {
            correlation: correlation.unwrap_or(c),
            max_burn_in: max_burn.unwrap_or(m),
        }
    };
    let settings = BasisSettings {
        samples: overrides
            .samples
            .or(s.count("samples", 0)?)
            .unwrap_or(d.samples),
        burn_in: burn.unwrap_or(d.burn_in),
        max_chain_length: overrides
            .max_chain
            .or(s.count("max_chain", 0)?)
            .unwrap_or(d.max_chain_length),
        cv_target: s.number("cv_target")?.unwrap_or(d.cv_target),
        proposal_scale: proposal_scale.unwrap_or(d.proposal_scale),
        mixing,
        resampling,
        min_step: s.number("min_step")?.unwrap_or(d.min_step),
        on_min_step,
        max_stages: s.count("max_stages", 0)?.unwrap_or(d.max_stages),
        seed: overrides.seed.or(s.seed("seed")?).unwrap_or(d.seed),
        delayed_acceptance: s
            .boolean("delayed_acceptance")?
            .unwrap_or(d.delayed_acceptance),
    };
    s.finish()?;
    settings.check().map_err(|e| match &e {
        BasisError::InvalidSettings { setting, reason } => {
            let setting = *setting;
            let (key, flag) = names_of(setting);
            let from_flag = match setting {
                "samples" => overrides.samples.is_some(),
                "burn_in" => overrides.burn.is_some(),
                "max_chain_length" => overrides.max_chain.is_some(),
                "seed" => overrides.seed.is_some(),
                _ => false,
            };
            match (from_flag, flag) {
                (true, Some(flag)) => input_error(format!("{flag}: {reason}")).with_source(e),
                _ => s.error(key, reason.clone()).into(),
            }
        }
        other => s.section_error(other.to_string()).into(),
    })
}
