//! What the method takes and gives: the surrogate population it starts from, the records of its
//! stages and corrections, its result, and the events it reports as it goes.

use serde::{Deserialize, Serialize};

use iuq_core::weighted_statistics::effective_sample_size;

use super::members::{Best, Members, recorded_spread_ratio};
use super::settings::ModelPosteriorSettings;
use crate::error::{BasisError, Result};
use crate::heavy_tail_errors::HeavyTailErrors;
use crate::moment_matching::ProposalMismatch;
use crate::paired_estimate::PairedErrors;
use crate::pareto_smoothing::{ParetoSmoothing, normalised_weights};
use crate::sampler::{Control, Observer};

/// The surrogate posterior the method starts from: an equally weighted population with its
/// surrogate log-likelihoods and log-priors (a BASIS final state).
#[derive(Debug, Clone, Copy)]
pub struct SurrogatePopulation<'a> {
    /// The members θ_i.
    pub samples: &'a [Vec<f64>],
    /// ℓ_s(θ_i).
    pub log_likelihood: &'a [f64],
    /// ln π(θ_i).
    pub log_prior: &'a [f64],
    /// The surrogate posterior's log-evidence ln Z_s.
    pub log_evidence: f64,
}

/// One stage of [`model_posterior`](super::model_posterior()).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelPosteriorStage {
    /// 1, 2, …
    pub stage: usize,
    /// β after the stage.
    pub beta: f64,
    /// The step Δβ taken.
    pub step: f64,
    /// CV of the stage's incremental weights exp(Δβ·r).
    #[serde(deserialize_with = "crate::json_numbers::infinity_from_null::deserialize")]
    pub cv: f64,
    /// k̂ of those weights (+∞ where they are nearly equal and have no tail to fit; `null` in
    /// JSON).
    #[serde(deserialize_with = "crate::json_numbers::infinity_from_null::deserialize")]
    pub pareto_k: f64,
    /// The step the CV rule alone gave (larger than `step` when k̂ halved it).
    pub cv_step: f64,
    /// Effective sample size of the smoothed weights.
    pub effective_sample_size: f64,
    /// Model evaluations made before this stage's weights (the initial batch for stage 1, the
    /// bridge's confirmations for later stages).
    pub model_evaluations: usize,
    /// Of those, failed runs.
    pub failures: usize,
    /// Share of the bridge's surrogate steps accepted (none for stage 1).
    pub screen_acceptance: Option<f64>,
    /// Share of the bridge's model confirmations accepted (none for stage 1).
    pub confirm_acceptance: Option<f64>,
    /// The largest ratio, over the parameters, of the step's weighted std to the members'
    /// unweighted std (for both batches weighed together, to the wider batch's;
    /// [`crate::spread_ratio`]). Above [`crate::spread_ratio::WIDER_THAN_PROPOSAL`] a
    /// reproducible model's step to β = 1 is not certified (steps short of it are bridged); a
    /// noisy model's final step is certified by k̂ alone (its first batch's ratio is one of the
    /// triggers of its correction). 0 where it cannot be computed.
    #[serde(default)]
    pub spread_ratio: f64,
}

impl ModelPosteriorStage {
    /// The record of one full step (β from 0 to 1) over the members `points` with the weights
    /// `smoothing` of raw CV `cv`: a noisy model's estimate, or both batches of a correction
    /// weighed together.
    pub(crate) fn full_step(
        points: &[Vec<f64>],
        batches: usize,
        smoothing: &ParetoSmoothing,
        cv: f64,
        model_evaluations: usize,
        failures: usize,
    ) -> Self {
        Self {
            stage: 1,
            beta: 1.0,
            step: 1.0,
            cv,
            pareto_k: smoothing.pareto_k,
            cv_step: 1.0,
            effective_sample_size: effective_sample_size(&normalised_weights(
                &smoothing.log_weights,
            )),
            model_evaluations,
            failures,
            screen_acceptance: None,
            confirm_acceptance: None,
            spread_ratio: recorded_spread_ratio(points, &smoothing.log_weights, batches),
        }
    }
}

/// A correction of the surrogate: the first batch's weights would not hold in one stage (or,
/// for a noisy model, showed the surrogate off), so the surrogate's log-likelihood became
/// ℓ_s + r̂ (r̂ a quadratic fit of the batch's r, or the moment-matched log-ratio of
/// [`crate::moment_matching`]), or for a noisy model whose moment-matched correction was
/// refused, β·ℓ_s ([`crate::defensive_tempering`], `tempering`), and a new batch was drawn from
/// that surrogate's posterior.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SurrogateCorrection {
    /// k̂ of the batch's full-step weights before the correction.
    pub pareto_k_before: f64,
    /// CV of those weights.
    pub cv_before: f64,
    /// The widest ratio of those weights' std to the batch's, over the parameters
    /// ([`crate::spread_ratio`]; above [`crate::spread_ratio::WIDER_THAN_PROPOSAL`] the batch is
    /// corrected whatever k̂ says, for a reproducible model or a noisy one); 0 where it cannot be
    /// computed.
    #[serde(default)]
    pub spread_ratio_before: f64,
    /// Model evaluations of the batch the correction was fitted on.
    pub model_evaluations: usize,
    /// Whether the correction had quadratic terms (else linear; a moment-matched one always
    /// has; false for a defensive batch, whose log-ratio (β − 1)·ℓ_s is neither).
    pub quadratic: bool,
    /// Whether it was the moment-matched log-ratio of the batch's weights
    /// ([`crate::moment_matching`]; a noisy model's only correction, a reproducible model's
    /// second candidate) rather than a least-squares fit of r.
    #[serde(default)]
    pub moment_matched: bool,
    /// For a noisy model's defensive batch, the tempering β of the surrogate's posterior it was
    /// drawn from (π·L_s^β, [`crate::defensive_tempering`]; then neither a fit nor
    /// moment-matched); `None` for a correction by a log-ratio.
    #[serde(default)]
    pub tempering: Option<f64>,
    /// For a noisy model's defensive batch drawn from a normal fitted to the first batch's
    /// weights ([`crate::defensive_normal`]; then neither a fit of r nor moment-matched).
    #[serde(default)]
    pub defensive_normal: bool,
    /// The candidates tried before this one and why each was refused (a corrected posterior
    /// mostly outside the batch, [`MIN_CORRECTED_WITHIN_BATCH`](super::MIN_CORRECTED_WITHIN_BATCH), or one BASIS could not sample).
    #[serde(default)]
    pub refused: Vec<String>,
}

/// Why [`model_posterior`](super::model_posterior()) stopped.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ModelPosteriorStop {
    /// β reached 1 with every stage's k̂ below its threshold.
    Certified,
    /// `max_stages` stages did not reach β = 1.
    MaxStages {
        /// β reached.
        beta: f64,
    },
    /// k̂ stayed above its threshold down to the smallest step (or a step to β = 1 shorter
    /// than twice the smallest kept its target wider than the population: the spread ratio).
    StepBelowMinimum {
        /// β reached.
        beta: f64,
    },
    /// A noisy (pseudo-marginal) model likelihood whose one full step's weights have k̂ above
    /// the threshold: no bridge can follow a likelihood that does not repeat.
    NoisyWeightsTail,
}

impl std::fmt::Display for ModelPosteriorStop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Certified => write!(
                f,
                "certified: every stage's k̂ is below its threshold (or its weights nearly equal)"
            ),
            Self::MaxStages { beta } => write!(
                f,
                "not certified: max_stages stages reached β = {beta:.4} (raise max_stages, moves or samples)"
            ),
            Self::StepBelowMinimum { beta } => write!(
                f,
                "not certified: at β = {beta:.4} even the smallest step's weights have k̂ above the threshold, or the last step's weighted std exceeds the population's by more than the spread ratio's bound (the surrogate posterior misses part of the model's; raise samples or improve the surrogate)"
            ),
            Self::NoisyWeightsTail => write!(
                f,
                "not certified: the model's likelihood is noisy (its output is not reproducible under a negligible change of the parameters) and the one full step's weights have k̂ above the threshold (raise samples; the noise of a single run's likelihood sets the weights' tail)"
            ),
        }
    }
}

/// The model's posterior as a weighted population, with its diagnostics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelPosterior {
    /// Parameter names.
    pub names: Vec<String>,
    /// The final population.
    pub samples: Vec<Vec<f64>>,
    /// Their normalised smoothed log-weights.
    pub log_weights: Vec<f64>,
    /// The final stage's raw log-weights Δβ·r (before smoothing); with `both_batches`, the
    /// mixture weights of both batches ([`crate::batch_mixture`]).
    pub raw_log_weights: Vec<f64>,
    /// ℓ_m of each member (−∞ for a failed run).
    pub model_log_likelihood: Vec<f64>,
    /// ℓ_s of each member.
    pub surrogate_log_likelihood: Vec<f64>,
    /// ln π of each member.
    pub log_prior: Vec<f64>,
    /// Every stage.
    pub stages: Vec<ModelPosteriorStage>,
    /// k̂ of the final weights.
    pub pareto_k: f64,
    /// Its threshold min(1 − 1/log₁₀ S, 0.7).
    pub pareto_k_threshold: f64,
    /// Why it stopped.
    pub stop: ModelPosteriorStop,
    /// Effective sample size of the final weights.
    pub effective_sample_size: f64,
    /// Weighted posterior mean.
    pub mean: Vec<f64>,
    /// Weighted posterior std.
    pub std: Vec<f64>,
    /// Monte Carlo standard error of each mean: self-normalised importance sampling's, its
    /// terms summed within each group of members that descend from one ancestor through a
    /// bridge's resampling ([`crate::ancestral_variance`]; without a bridge, member by member);
    /// where k̂ exceeds ½, the larger of that and the subsampling error
    /// ([`Self::heavy_tail_errors`]).
    pub mcse_mean: Vec<f64>,
    /// Monte Carlo standard error of each std (the delta method, grouped as `mcse_mean`; where
    /// k̂ exceeds ½, the larger of that and the subsampling error).
    pub mcse_std: Vec<f64>,
    /// Distinct ancestors of the weighted members (S without a bridge; a bridge's resampling
    /// leaves fewer, and with very few the standard errors are unreliable).
    #[serde(default)]
    pub ancestors: usize,
    /// Where the final weights' k̂ exceeds ½ (infinite variance): the errors by subsampling at
    /// the Pareto-smoothed estimate's convergence rate ([`crate::heavy_tail_errors`]), which
    /// `mcse_mean` and `mcse_std` are at least. `None` at k̂ ≤ ½ or with too few ancestors.
    #[serde(default)]
    pub heavy_tail_errors: Option<HeavyTailErrors>,
    /// The quantiles' probabilities.
    pub probabilities: Vec<f64>,
    /// `quantiles[k][q]`: weighted quantile q of parameter k.
    pub quantiles: Vec<Vec<f64>>,
    /// The model-evaluated point with the largest ℓ_m + ln π.
    pub map: Vec<f64>,
    /// ℓ_m there.
    pub map_log_likelihood: f64,
    /// ln π there.
    pub map_log_prior: f64,
    /// ln(Z_model/Z_surrogate): Σ_k ln mean_i exp(Δβ_k·r_i) over the stages (the evidence
    /// increments of the tempering, as BASIS accumulates them), plus ln(Z_corrected/Z_s) after a
    /// correction (from the corrected surrogate's BASIS run); for a noisy model, the log of the
    /// mean (mixture) weight: the model's log-evidence is the surrogate's plus this.
    pub log_evidence_ratio: f64,
    /// The corrections of the surrogate made (see [`ModelPosteriorSettings::corrections`](super::ModelPosteriorSettings::corrections)).
    pub corrections: Vec<SurrogateCorrection>,
    /// For a noisy model: the test of the first batch's weights for a mismatch of the
    /// surrogate's posterior ([`crate::moment_matching::proposal_mismatch`]; `None`: not made,
    /// with `corrections = 0`, a reproducible model, or too few effective weights).
    #[serde(default)]
    pub proposal_mismatch: Option<ProposalMismatch>,
    /// Why a correction that was wanted was not made: for a noisy model, every candidate (the
    /// moment-matched correction and the defensive batch) refused or impossible to sample; for
    /// a reproducible model, a corrected posterior mostly outside the batch its correction was
    /// fitted on ([`MIN_CORRECTED_WITHIN_BATCH`](super::MIN_CORRECTED_WITHIN_BATCH)). `None` when none was wanted or it was made.
    #[serde(default)]
    pub correction_not_made: Option<String>,
    /// Whether the final population is both batches of a correction, weighed as one sample of
    /// the mixture of the surrogate's posterior and the corrected one
    /// ([`crate::batch_mixture`]; always after a noisy model's correction, after a reproducible
    /// model's when their k̂ holds), rather than the corrected batch's stages alone.
    #[serde(default)]
    pub both_batches: bool,
    /// Where the estimate is one certified step from the first batch (a uniform subset of the
    /// surrogate population) and pairing it with the population is the more precise estimate:
    /// the two parts of each mean's error ([`crate::paired_estimate`]; `mean`, `std` and their
    /// MCSEs are then the paired estimate's, the quantiles the members' weighted ones). `None`:
    /// the members' weighted moments.
    #[serde(default)]
    pub paired: Option<PairedErrors>,
    /// Model evaluations requested in all (points already stored in a campaign count too).
    pub model_evaluations: usize,
    /// Of those, failed runs.
    pub failures: usize,
}

impl ModelPosterior {
    /// Every stage's k̂ below its threshold and β = 1 reached.
    pub fn certified(&self) -> bool {
        self.stop == ModelPosteriorStop::Certified
    }

    /// The normalised smoothed weights.
    pub fn weights(&self) -> Vec<f64> {
        normalised_weights(&self.log_weights)
    }
}

/// What [`model_posterior`](super::model_posterior()) reports to its [`Observer`] as it goes, for progress lines: a user
/// watching a batch of hundreds of model runs learns what the batch is for before it starts.
#[derive(Debug, Clone, Copy)]
pub enum ModelPosteriorEvent<'a> {
    /// The surrogate was corrected (or, for a noisy model, tempered); the batch at that
    /// surrogate's posterior (this many model evaluations,
    /// [`SurrogateCorrection::model_evaluations`]) starts now.
    Correction(&'a SurrogateCorrection),
    /// A correction was wanted but not made (the clause says why); the method goes on without.
    CorrectionNotMade(&'a str),
    /// A stage ended.
    Stage(&'a ModelPosteriorStage),
    /// A bridge ended: the state between two stages, from which
    /// [`resume_model_posterior`](super::resume_model_posterior()) goes on (serialisable, as
    /// BASIS's [`BasisState`](crate::BasisState) is).
    Bridged(&'a Tempering),
}

/// The observer of [`model_posterior`](super::model_posterior())'s events, inside the method.
pub(crate) type EventObserver<'o> = dyn for<'a> Observer<ModelPosteriorEvent<'a>> + 'o;

/// Tell `observer` of `event` where more work follows it: its [`Control::Stop`] ends the
/// method with [`BasisError::Interrupted`].
pub(crate) fn report(
    observer: &mut EventObserver<'_>,
    event: ModelPosteriorEvent<'_>,
) -> Result<()> {
    match observer.observe(&event) {
        Control::Continue => Ok(()),
        Control::Stop => Err(BasisError::Interrupted),
    }
}

/// The tempered stages from the (corrected) surrogate's posterior, β = 0, to the model's,
/// β = 1: the state between two stages, one step per stage (argmin's shape). Reported after
/// every bridge ([`ModelPosteriorEvent::Bridged`]) and serialisable (JSON: −∞ as `null`), so a
/// run stopped there goes on with [`resume_model_posterior`](super::resume_model_posterior())
/// without the bridges' model runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Tempering {
    /// A digest of the members the stages began from and of the settings: a state goes on
    /// only in the run it came from.
    pub(crate) origin: u64,
    pub(crate) members: Members,
    /// Each member's ancestor in the batch the stages started from (itself until a bridge
    /// resamples): the grouping of the standard errors ([`crate::ancestral_variance`]).
    pub(crate) ancestor: Vec<usize>,
    pub(crate) beta: f64,
    pub(crate) log_evidence_ratio: f64,
    pub(crate) stages: Vec<ModelPosteriorStage>,
    /// Model evaluations and failures of the batch the next stage weighs.
    pub(crate) stage_evaluations: (usize, usize),
    /// The last bridge's screen and confirmation acceptance rates.
    pub(crate) bridge_rates: (Option<f64>, Option<f64>),
    pub(crate) evaluations: usize,
    pub(crate) failures: usize,
    pub(crate) best: Best,
}

impl Tempering {
    /// The stages so far.
    pub fn stages(&self) -> &[ModelPosteriorStage] {
        &self.stages
    }

    /// β reached so far.
    pub fn beta(&self) -> f64 {
        self.beta
    }

    /// Model evaluations so far, every batch and bridge together.
    pub fn model_evaluations(&self) -> usize {
        self.evaluations
    }

    /// The digest of `members` (the bits of every θ, log-likelihood and log-prior) and of
    /// `settings` (their JSON), folded with SplitMix64.
    pub(crate) fn origin_of(members: &Members, settings: &ModelPosteriorSettings) -> u64 {
        let mix = |h: u64, bits: u64| iuq_core::random::splitmix64(h ^ bits);
        let settings_text = serde_json::to_string(settings).unwrap_or_default();
        let mut h = settings_text
            .bytes()
            .fold(0x6d6f_6465_6c5f_706fu64, |h, b| mix(h, u64::from(b)));
        for value in members
            .theta
            .iter()
            .flatten()
            .chain(&members.surrogate)
            .chain(&members.model)
            .chain(&members.prior)
        {
            h = mix(h, value.to_bits());
        }
        h
    }
}
