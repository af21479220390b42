//! Sampler settings, validated once before any work (a "checked parameters" struct in the
//! manner of linfa): [`BasisSettings`] is plain data, [`BasisSettings::check`] turns it into a
//! [`CheckedSettings`] that the sampler alone accepts.

use serde::{Deserialize, Serialize};

use crate::error::{BasisError, Result};

/// How the population is resampled in proportion to its importance weights.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Resampling {
    /// N independent draws from the categorical distribution of the weights (Wu et al. 2017;
    /// Ching & Chen 2007). Counts are multinomial.
    #[default]
    Multinomial,
    /// One uniform offset u ~ U(0, 1/N) and the N points u + k/N (Kitagawa 1996): lower variance
    /// of the counts, each n_i within one of N·w̄_i.
    Systematic,
}

impl Resampling {
    /// The name used in study files and outputs.
    pub fn name(self) -> &'static str {
        match self {
            Resampling::Multinomial => "multinomial",
            Resampling::Systematic => "systematic",
        }
    }
}

/// What to do when the exponent step solved from the CV target is below
/// [`BasisSettings::min_step`] (e.g. when more than half of the population failed, so that the
/// CV exceeds γ = 1 for every positive step).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MinStepAction {
    /// Take the minimum step instead (recorded as `step_clamped` in the stage's diagnostics);
    /// [`BasisSettings::max_stages`] still bounds the run.
    #[default]
    Clamp,
    /// Stop with [`crate::StopReason::StepBelowMinimum`].
    Stop,
}

/// Settings of a BASIS run (Wu et al. 2017, "A Bayesian annealed sequential importance
/// sampling", section 3; the study's values are the defaults).
///
/// Build with [`Default`] and struct update syntax, then [`check`](Self::check):
/// ```
/// use iuq_basis::BasisSettings;
/// let settings = BasisSettings { samples: 2000, burn_in: 10, seed: 7, ..Default::default() }
///     .check()
///     .unwrap();
/// assert_eq!(settings.samples, 2000);
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BasisSettings {
    /// Population size N (default 1000; the study used 1000 with the expensive model and 10 000
    /// with the surrogate).
    pub samples: usize,
    /// Discarded MCMC steps n_burn before each chain's first sample (default 0; 10 with a
    /// surrogate).
    pub burn_in: usize,
    /// Maximum chain length l_max (default 1: every resampled copy moves once, which balances
    /// the load perfectly). A copy count n_i is split into ⌈n_i/l_max⌉ chains of near-equal
    /// length.
    pub max_chain_length: usize,
    /// Target γ of the coefficient of variation of the importance weights (default 1; with the
    /// population CV used here, γ = 1 means ESS = N/2).
    pub cv_target: f64,
    /// Proposal scale β: the proposal covariance is β² times the weighted population covariance
    /// (default 0.2, i.e. × 0.04).
    pub proposal_scale: f64,
    /// Resampling scheme (default multinomial).
    pub resampling: Resampling,
    /// Smallest accepted exponent step (default 1e-6).
    pub min_step: f64,
    /// What to do when the solved step is below `min_step` (default: clamp).
    pub on_min_step: MinStepAction,
    /// Maximum number of annealing stages after the prior stage before p reaches 1 (default
    /// 100); the final pass at p = 1 is not counted against it.
    pub max_stages: usize,
    /// Seed of every random stream (default 0). Stream (seed, stage, chain) is independent of
    /// the number of threads.
    pub seed: u64,
}

impl Default for BasisSettings {
    fn default() -> Self {
        Self {
            samples: 1000,
            burn_in: 0,
            max_chain_length: 1,
            cv_target: 1.0,
            proposal_scale: 0.2,
            resampling: Resampling::Multinomial,
            min_step: 1e-6,
            on_min_step: MinStepAction::Clamp,
            max_stages: 100,
            seed: 0,
        }
    }
}

/// The largest population accepted (2^32 − 1 members would already need ~100 GB).
pub const MAX_SAMPLES: usize = 1 << 31;

impl BasisSettings {
    /// Validate every setting and return the checked settings the sampler accepts.
    ///
    /// Rules: `samples` ≥ 2 (and below [`MAX_SAMPLES`]); `max_chain_length` ≥ 1; `cv_target`
    /// finite and > 0; `proposal_scale` finite and > 0; `min_step` in (0, 1); `max_stages` ≥ 1.
    pub fn check(self) -> Result<CheckedSettings> {
        let invalid = |setting: &'static str, reason: String| {
            Err(BasisError::InvalidSettings { setting, reason })
        };
        if self.samples < 2 {
            return invalid(
                "samples",
                format!("at least 2 samples are needed, got {}", self.samples),
            );
        }
        if self.samples > MAX_SAMPLES {
            return invalid(
                "samples",
                format!("at most {MAX_SAMPLES} samples, got {}", self.samples),
            );
        }
        if self.max_chain_length < 1 {
            return invalid("max_chain_length", "must be at least 1, got 0".into());
        }
        if !(self.cv_target.is_finite() && self.cv_target > 0.0) {
            return invalid(
                "cv_target",
                format!("must be finite and positive, got {}", self.cv_target),
            );
        }
        if !(self.proposal_scale.is_finite() && self.proposal_scale > 0.0) {
            return invalid(
                "proposal_scale",
                format!("must be finite and positive, got {}", self.proposal_scale),
            );
        }
        if !(self.min_step > 0.0 && self.min_step < 1.0) {
            return invalid(
                "min_step",
                format!("must lie strictly between 0 and 1, got {}", self.min_step),
            );
        }
        if self.max_stages < 1 {
            return invalid("max_stages", "must be at least 1, got 0".into());
        }
        Ok(CheckedSettings(self))
    }
}

/// Settings that passed [`BasisSettings::check`]; read them through `Deref`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(transparent)]
pub struct CheckedSettings(BasisSettings);

impl CheckedSettings {
    /// The settings as plain data.
    pub fn settings(&self) -> &BasisSettings {
        &self.0
    }
}

impl std::ops::Deref for CheckedSettings {
    type Target = BasisSettings;
    fn deref(&self) -> &BasisSettings {
        &self.0
    }
}

impl<'de> Deserialize<'de> for CheckedSettings {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        BasisSettings::deserialize(deserializer)?
            .check()
            .map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_the_study_settings_and_valid() {
        let s = BasisSettings::default().check().unwrap();
        assert_eq!(s.cv_target, 1.0);
        assert_eq!(s.proposal_scale, 0.2);
        assert_eq!(s.max_chain_length, 1);
        assert_eq!(s.resampling, Resampling::Multinomial);
    }

    #[test]
    fn each_invalid_setting_is_rejected_by_name() {
        let d = BasisSettings::default();
        let cases = [
            (BasisSettings { samples: 1, ..d }, "samples"),
            (
                BasisSettings {
                    max_chain_length: 0,
                    ..d
                },
                "max_chain_length",
            ),
            (
                BasisSettings {
                    cv_target: 0.0,
                    ..d
                },
                "cv_target",
            ),
            (
                BasisSettings {
                    cv_target: f64::NAN,
                    ..d
                },
                "cv_target",
            ),
            (
                BasisSettings {
                    proposal_scale: -0.2,
                    ..d
                },
                "proposal_scale",
            ),
            (
                BasisSettings {
                    proposal_scale: f64::INFINITY,
                    ..d
                },
                "proposal_scale",
            ),
            (BasisSettings { min_step: 0.0, ..d }, "min_step"),
            (BasisSettings { min_step: 1.0, ..d }, "min_step"),
            (BasisSettings { max_stages: 0, ..d }, "max_stages"),
        ];
        for (settings, name) in cases {
            match settings.check() {
                Err(BasisError::InvalidSettings { setting, .. }) => assert_eq!(setting, name),
                other => panic!("{name}: expected rejection, got {other:?}"),
            }
        }
    }

    #[test]
    fn checked_settings_round_trip_through_json_and_are_revalidated() {
        let s = BasisSettings {
            seed: 9,
            resampling: Resampling::Systematic,
            ..Default::default()
        }
        .check()
        .unwrap();
        let text = serde_json::to_string(&s).unwrap();
        let back: CheckedSettings = serde_json::from_str(&text).unwrap();
        assert_eq!(back, s);
        let bad = text.replace("\"samples\":1000", "\"samples\":0");
        assert!(serde_json::from_str::<CheckedSettings>(&bad).is_err());
    }
}
