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

/// How the chains of a stage mix: fixed-length chains at a fixed scale, as Wu et al. (2017)
/// ran them, or the length and scale adapted from the run itself.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Mixing {
    /// [`BasisSettings::burn_in`] discarded steps at scale [`BasisSettings::proposal_scale`]
    /// (the published BASIS). Fine in two or three dimensions; in ten, β = 0.2 moves a chain
    /// about a fifth of a posterior std per step and a short burn-in leaves the population
    /// biased (docs/methods.md §5, "How the chains mix").
    Fixed,
    /// The scale of stage k from the acceptance rate a of stage k − 1, β_k = 1/9 + 8/9·a
    /// (Muto & Beck 2008, as PyMC's SMC and TMCMC codes use it), starting from
    /// min(1, 2.38/√d) (Roberts, Gelman & Gilks 1997); the burn-in goes on, after at least
    /// [`BasisSettings::burn_in`] steps, until no parameter's correlation between the chains'
    /// starting points and their current points exceeds `correlation` (the duplicates that
    /// resampling made have moved apart; PyMC 3's SMC stops its moves on the same measure),
    /// or `max_burn_in` steps.
    Adaptive {
        /// The largest correlation left between a chain's start and its state (default 0.3:
        /// two copies of one member then keep a correlation of about 0.09).
        correlation: f64,
        /// The most burn-in steps of a stage (default 50); a stage that needs more is
        /// reported by its `start_correlation`.
        max_burn_in: usize,
    },
}

impl Mixing {
    /// The default of [`BasisSettings`]: adaptive, correlation 0.3, at most 50 steps.
    pub const ADAPTIVE: Mixing = Mixing::Adaptive {
        correlation: 0.3,
        max_burn_in: 50,
    };

    /// `Fixed`, what a checkpoint written before this setting existed ran with.
    fn fixed() -> Mixing {
        Mixing::Fixed
    }
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
    /// Discarded MCMC steps n_burn before each chain's first sample (default 0), the least
    /// number of them with [`Mixing::Adaptive`].
    pub burn_in: usize,
    /// Maximum chain length l_max (default 1: every resampled copy moves once, which balances
    /// the load perfectly). A copy count n_i is split into ⌈n_i/l_max⌉ chains of near-equal
    /// length.
    pub max_chain_length: usize,
    /// Target γ of the coefficient of variation of the importance weights (default 1; with the
    /// population CV used here, γ = 1 means ESS = N/2).
    pub cv_target: f64,
    /// Proposal scale β: the proposal covariance is β² times the weighted population covariance
    /// (default 0.2, i.e. × 0.04). Used with [`Mixing::Fixed`]; [`Mixing::Adaptive`] sets its
    /// own.
    pub proposal_scale: f64,
    /// How the chains mix (default [`Mixing::ADAPTIVE`]; a checkpoint without it ran
    /// [`Mixing::Fixed`]).
    #[serde(default = "Mixing::fixed")]
    pub mixing: Mixing,
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
    /// Delayed acceptance (default true; a checkpoint without it ran without): where the
    /// likelihood has a cheap screen ([`crate::LogLikelihood::screening_log_likelihood_batch`],
    /// a surrogate's means without their predictive variances), every move is first accepted
    /// or rejected on the screen and only the proposals it lets through are evaluated, then
    /// accepted with the ratio of the likelihood to the screen (Christen & Fox 2005). The
    /// chains' invariant law stays the exact tempered posterior; what changes is the cost.
    #[serde(default)]
    pub delayed_acceptance: bool,
}

impl Default for BasisSettings {
    fn default() -> Self {
        Self {
            samples: 1000,
            burn_in: 0,
            max_chain_length: 1,
            cv_target: 1.0,
            proposal_scale: 0.2,
            mixing: Mixing::ADAPTIVE,
            resampling: Resampling::Multinomial,
            min_step: 1e-6,
            on_min_step: MinStepAction::Clamp,
            max_stages: 100,
            seed: 0,
            delayed_acceptance: true,
        }
    }
}

/// The largest population accepted (2^32 − 1 members would already need ~100 GB).
pub const MAX_SAMPLES: usize = 1 << 31;

/// The most MCMC steps per chain and stage (`burn_in`, `max_burn_in`, `max_chain_length`) and the
/// most stages (`max_stages`): 2²⁰, beyond any affordable run, low enough that the step counts
/// and their sums never overflow.
pub const MAX_STEPS: usize = 1 << 20;

impl BasisSettings {
    /// Validate every setting and return the checked settings the sampler accepts.
    ///
    /// Rules: `samples` ≥ 2 (and below [`MAX_SAMPLES`]); `max_chain_length` ≥ 1; `burn_in`,
    /// `max_chain_length`, `max_burn_in` and `max_stages` at most [`MAX_STEPS`]; `cv_target`
    /// finite and > 0; `proposal_scale` finite and > 0; `min_step` in (0, 1); `max_stages` ≥ 1;
    /// with [`Mixing::Adaptive`], `correlation` in (0, 1) and `max_burn_in` ≥ max(1, `burn_in`).
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
        for (setting, steps) in [
            ("burn_in", self.burn_in),
            ("max_chain_length", self.max_chain_length),
            ("max_stages", self.max_stages),
        ] {
            if steps > MAX_STEPS {
                return invalid(setting, format!("at most {MAX_STEPS}, got {steps}"));
            }
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
        if let Mixing::Adaptive {
            correlation,
            max_burn_in,
        } = self.mixing
        {
            if !(correlation > 0.0 && correlation < 1.0) {
                return invalid(
                    "correlation",
                    format!("must lie strictly between 0 and 1, got {correlation}"),
                );
            }
            if max_burn_in > MAX_STEPS {
                return invalid(
                    "max_burn_in",
                    format!("at most {MAX_STEPS}, got {max_burn_in}"),
                );
            }
            if max_burn_in < self.burn_in.max(1) {
                return invalid(
                    "max_burn_in",
                    format!(
                        "must be at least 1 and at least burn_in = {}, got {max_burn_in}",
                        self.burn_in
                    ),
                );
            }
        }
        Ok(CheckedSettings(self))
    }
}

/// The strongest level [`CheckedSettings::with_stronger_mixing`] goes to.
pub const MAX_MIXING_LEVEL: u32 = 4;

/// Settings that passed [`BasisSettings::check`]; read them through `Deref`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(transparent)]
pub struct CheckedSettings(BasisSettings);

impl CheckedSettings {
    /// The settings as plain data.
    pub fn settings(&self) -> &BasisSettings {
        &self.0
    }

    /// The same settings with the chains mixing harder, `level` steps up (0: unchanged; at most
    /// [`MAX_MIXING_LEVEL`]): a second sampler whose posterior must agree with this one's if
    /// both are right (the adaptive engine's check of its sampler). [`Mixing::Fixed`] becomes
    /// [`Mixing::ADAPTIVE`] at level 1 (with at least the same burn-in); each further level
    /// halves the correlation target and doubles `max_burn_in`.
    pub fn with_stronger_mixing(&self, level: u32) -> CheckedSettings {
        let level = level.min(MAX_MIXING_LEVEL);
        if level == 0 {
            return *self;
        }
        let mut s = self.0;
        let (base, halvings) = match s.mixing {
            Mixing::Fixed => (Mixing::ADAPTIVE, level - 1),
            adaptive => (adaptive, level),
        };
        if let Mixing::Adaptive {
            correlation,
            max_burn_in,
        } = base
        {
            let factor = 1usize << halvings;
            s.mixing = Mixing::Adaptive {
                correlation: correlation / factor as f64,
                max_burn_in: max_burn_in.max(s.burn_in) * factor,
            };
        }
        CheckedSettings(s)
    }

    /// The same settings with [`Mixing::Adaptive`]'s `max_burn_in` at most `cap` (never below
    /// `burn_in`): a population that only has to locate a posterior, not to resolve it (the
    /// adaptive engine's exploring rounds), stops its chains' burn-in early. [`Mixing::Fixed`]
    /// is unchanged.
    pub fn with_burn_in_cap(&self, cap: usize) -> CheckedSettings {
        let mut s = self.0;
        if let Mixing::Adaptive {
            correlation,
            max_burn_in,
        } = s.mixing
        {
            s.mixing = Mixing::Adaptive {
                correlation,
                max_burn_in: max_burn_in.min(cap.max(s.burn_in).max(1)),
            };
        }
        CheckedSettings(s)
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
    fn a_burn_in_cap_lowers_only_an_adaptive_max_burn_in_and_never_below_the_burn_in() {
        let adaptive = BasisSettings::default().check().unwrap();
        let capped = |s: &CheckedSettings, cap| s.with_burn_in_cap(cap).mixing;
        assert_eq!(
            capped(&adaptive, 20),
            Mixing::Adaptive {
                correlation: 0.3,
                max_burn_in: 20
            }
        );
        assert_eq!(capped(&adaptive, 80), adaptive.mixing);
        let burn = BasisSettings {
            burn_in: 30,
            ..Default::default()
        }
        .check()
        .unwrap();
        assert_eq!(
            capped(&burn, 20),
            Mixing::Adaptive {
                correlation: 0.3,
                max_burn_in: 30
            }
        );
        let fixed = BasisSettings {
            mixing: Mixing::Fixed,
            ..Default::default()
        }
        .check()
        .unwrap();
        assert_eq!(capped(&fixed, 5), Mixing::Fixed);
    }

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
    fn stronger_mixing_turns_fixed_chains_adaptive_then_tightens_them() {
        let fixed = BasisSettings {
            burn_in: 40,
            mixing: Mixing::Fixed,
            ..Default::default()
        }
        .check()
        .unwrap();
        assert_eq!(fixed.with_stronger_mixing(0), fixed);
        assert_eq!(
            fixed.with_stronger_mixing(1).mixing,
            Mixing::Adaptive {
                correlation: 0.3,
                max_burn_in: 50
            }
        );
        assert_eq!(
            fixed.with_stronger_mixing(2).mixing,
            Mixing::Adaptive {
                correlation: 0.15,
                max_burn_in: 100
            }
        );
        let adaptive = BasisSettings::default().check().unwrap();
        assert_eq!(
            adaptive.with_stronger_mixing(1).mixing,
            Mixing::Adaptive {
                correlation: 0.15,
                max_burn_in: 100
            }
        );
        assert_eq!(
            adaptive.with_stronger_mixing(99),
            adaptive.with_stronger_mixing(MAX_MIXING_LEVEL)
        );
        // every level passes the checks
        for level in 0..=MAX_MIXING_LEVEL {
            adaptive
                .with_stronger_mixing(level)
                .settings()
                .check()
                .unwrap();
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
