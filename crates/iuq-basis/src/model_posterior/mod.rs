//! From a surrogate's posterior to the model's own: importance stages certified by Pareto
//! smoothing, bridged by delayed-acceptance moves where one stage does not hold.
//!
//! The surrogate posterior q(θ) ∝ π(θ)·L_s(θ) (a BASIS population on a GP bank) and the model's
//! π(θ)·L_m(θ) differ by the likelihood ratio exp(r), r = ℓ_m − ℓ_s. The tempered targets
//! π_β ∝ π·L_s^{1−β}·L_m^β, β from 0 to 1, join them:
//!
//! 1. `samples` members of the surrogate population (uniformly, without replacement) are run
//!    through the model in one batch: ℓ_m, hence r (a failed run: r = −∞, weight 0).
//! 2. **Correction.** Where those weights would not hold in one stage (the CV rule does not
//!    reach β = 1, k̂ exceeds its threshold, or the weighted std of some parameter exceeds the
//!    batch's by more than [`crate::spread_ratio::WIDER_THAN_PROPOSAL`]: a narrow proposal's
//!    tail that k̂ underestimates), the surrogate is corrected: ℓ_s + r̂, with r̂ a
//!    quadratic least-squares fit of r over the batch ([`crate::quadratic_regression`]; a
//!    surrogate posterior that is shifted, too wide or too narrow differs from the model's by
//!    exactly such an r), the corrected surrogate's posterior is sampled by BASIS (surrogate
//!    evaluations only), and a new batch of `samples` members of it is run through the model;
//!    both batches are then weighed as one sample of the mixture of the two posteriors
//!    ([`crate::batch_mixture`]), which is the estimate when its k̂ (or nearly equal weights)
//!    holds and its spread ratio against the wider batch does; otherwise the stages go on from the corrected batch alone, with the corrected
//!    surrogate as the surrogate (r becomes r − r̂). At most
//!    `corrections` times (0 or 1): this costs one batch where a bridge costs one per stage.
//!    A corrected posterior that keeps less than half its population inside the batch's range
//!    of some parameter ([`MIN_CORRECTED_WITHIN_BATCH`]) is refused before any model run: the
//!    fit extrapolates there. The moment-matched log-ratio of the batch's weights
//!    ([`crate::moment_matching::GaussianLogRatio`], bounded by construction) is then tried in
//!    its place; if it is refused too, the stages go on from the first batch.
//! 3. Stage k from β: the step Δβ by the coefficient-of-variation rule of BASIS (CV of
//!    exp(Δβ·r) equal to `cv_target`, `bridge_cv_target` after a bridge, or the whole 1 − β
//!    when it stays within it; Wu et al. 2017), then, while the Pareto-smoothed weights' k̂
//!    (Vehtari et al. 2024) exceeds its threshold min(1 − 1/log₁₀ S, 0.7), the step is halved
//!    (down to `min_step`) until k̂ holds or the weights are nearly equal (CV ≤
//!    [`NEARLY_EQUAL_CV`]): every stage's incremental weights are certified. A step to β = 1 is
//!    also halved (once: the halved step no longer reaches 1) where its spread ratio exceeds
//!    [`crate::spread_ratio::WIDER_THAN_PROPOSAL`]
//!    (shorter steps are followed by a bridge, which spreads the population). One stage when
//!    the surrogate is good.
//! 4. When β reaches 1 the population with its smoothed weights is the model's posterior.
//!    Otherwise the population is resampled by the weights and every copy makes `moves`
//!    delayed-acceptance moves at β (Christen & Fox 2005; with a surrogate subchain as the
//!    proposal, Lykkegaard et al. 2023, MLDA): `subchain` random-walk Metropolis steps
//!    (covariance `scale`²·Cov_w(θ), as BASIS's proposal) on the screening density
//!    π̃_β = π·L_s·exp(β·r̂), where r̂ is a quadratic least-squares fit of r over the population
//!    (the surrogate corrected by what the model's runs have shown so far, without which a
//!    surrogate posterior narrower than the model's keeps the chains from its tails); the
//!    subchain's end θ* is then run through the model and accepted with
//!    ln u < β·((r − r̂)(θ*) − (r − r̂)(θ)) = ln[π_β(θ*)·π̃_β(θ) / (π_β(θ)·π̃_β(θ*))], which
//!    makes the move reversible with respect to π_β (π̃_β's subchain is reversible with respect
//!    to π̃_β). Only the proposals the surrogate lets through cost a model run; both acceptance
//!    rates are reported. Then the next stage.
//! 5. After `max_stages` stages without reaching β = 1 (or a step below `min_step`) the run
//!    stops uncertified, with the weights of the remaining step and their k̂.
//! 6. **A noisy model** (`pseudo_marginal`: a chaotic or stochastic model, whose runs at nearly
//!    equal parameters differ by more than their own reported spread): a run's likelihood is
//!    then one unbiased draw of the likelihood averaged over the model's irregular part, the
//!    weights exp(r) stay unbiased (pseudo-marginal importance sampling, Andrieu & Roberts
//!    2009), and the estimate is one full step, certified by k̂ (or nearly equal weights),
//!    after a moment-matched correction where the first batch shows the surrogate off, or,
//!    where that correction would extrapolate, a defensive batch from a normal fitted to the
//!    weights, or from the surrogate's posterior tempered where no such normal can be drawn
//!    ([`crate::pseudo_marginal`], [`crate::defensive_normal`], [`crate::defensive_tempering`]).
//!    Steps 2–4 are left out: a quadratic fit of a noisy r fits
//!    its mean, which by Jensen's inequality lies below the log of the mean weight, and a
//!    Metropolis chain on a noisy ratio sticks where a lucky run landed.
//!
//! The final population is summarised with its normalised smoothed weights w̄: mean
//! μ = Σ w̄θ, std σ = √(Σ w̄(θ − μ)²), weighted quantiles; the Monte Carlo standard errors of
//! self-normalised importance sampling (Vehtari et al. 2024, eq. 6 and the delta method)
//! MCSE(μ) = √(Σ w̄²(θ − μ)²), MCSE(σ) = √(Σ w̄²((θ − μ)² − σ²)²)/(2σ); after bridging stages
//! the terms are summed within each ancestor's group before squaring
//! ([`crate::ancestral_variance`]), for the correlation the resampling leaves between members.
//! The MAP is
//! the model-evaluated point with the largest ℓ_m + ln π.
//!
//! Every random draw is keyed by (seed, stage, chain) and each batch of likelihood evaluations
//! is made in a fixed order, so the result does not depend on the number of threads; a rerun
//! requests the same model points in the same order, which is what lets a campaign store resume
//! an interrupted run without repeating a finished model run.

mod bridge;
mod correction;

pub(crate) use bridge::MethodInputs;
use bridge::StageWeights;
use correction::{CorrectedBatch, FirstBatch, correct_first_batch};
use serde::{Deserialize, Serialize};

use iuq_core::ParameterSpace;
use iuq_core::random::stream;
use iuq_core::weighted_statistics::{effective_sample_size, weighted_quantiles};

use crate::ancestral_variance::ancestral_errors;
use crate::annealing::{log_evidence_increment, next_step};
use crate::error::{BasisError, Result};
use crate::likelihood::{LogLikelihood, PointLogLikelihood};
use crate::member_selection::nested_selection;
use crate::moment_matching::ProposalMismatch;
use crate::pareto_smoothing::{
    ParetoSmoothing, normalised_weights, pareto_k_threshold, pareto_smooth,
};
use crate::pseudo_marginal::{Members, noisy_estimate};
use crate::sampler::{Control, Observer};
use crate::spread_ratio::{widest_spread_ratio, within_proposal_spread};

/// A stage's weights whose CV is at most this are certified whatever their k̂: so nearly equal
/// (ESS/S ≥ 0.99) that their tail cannot carry the estimate. k̂ is a shape, blind to the
/// weights' spread: for a small step the weights exp(Δβ·r) ≈ 1 + Δβ·r keep the tail shape of r
/// itself, and a few members with a large r would hold k̂ up however small the step.
pub const NEARLY_EQUAL_CV: f64 = 0.1;

/// A correction whose posterior keeps less than this share of its population inside the range
/// (minimum to maximum) of some parameter over the batch it was fitted on is not made: most of
/// its mass would lie where no run informed the fit, and a second batch there is spent on the
/// fit's extrapolation (the stages go on from the first batch instead, exactly, at the price of
/// bridges). Parameter by parameter, not the joint box: a correct correction widening a narrow
/// surrogate posterior in every one of d parameters keeps about p^d inside the box when it
/// keeps p inside each range (in 10-D, 0.92 each and 0.43 jointly: refused, the stages bridged
/// from the first batch for 1,200–1,500 model evaluations where the correction and both
/// batches need 600), whereas an extrapolating fit leaves some range altogether.
pub const MIN_CORRECTED_WITHIN_BATCH: f64 = 0.5;

/// The smallest population: k̂ needs a tail of 5 weights, ⌈min(0.2·S, 3√S)⌉ ≥ 5 from S = 21.
pub const MIN_SAMPLES: usize = 25;

/// First stream stage of the model-posterior sampler (stage k uses `STREAM_BASE + k`; the
/// selection of the surrogate members uses `STREAM_BASE`).
pub const STREAM_BASE: u64 = iuq_core::random::stages::MODEL_POSTERIOR_BASE;

/// Settings of [`model_posterior`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelPosteriorSettings {
    /// Members of the surrogate population run through the model (the model posterior's sample
    /// size S).
    pub samples: usize,
    /// Seed of every random draw.
    pub seed: u64,
    /// The CV target γ of the first stage's step (BASIS's rule; 1 as in BASIS).
    pub cv_target: f64,
    /// The CV target of the stages after a bridge, whose population comes from short MCMC
    /// chains of resampled members and shows its tails less well than an independent sample of
    /// the surrogate's posterior, so that k̂ alone is not enough there (0.5; with 1 the
    /// bridged stds of a test problem came out 7 % narrow on average over seeds).
    pub bridge_cv_target: f64,
    /// Largest number of stages (each after the first costs a bridge of model runs).
    pub max_stages: usize,
    /// Corrections of the surrogate, 0 or 1 (one costs `samples` model evaluations): where the
    /// first batch's weights do not hold in one stage, the surrogate's log-likelihood is
    /// corrected by a quadratic fit of r and the corrected surrogate's posterior sampled anew;
    /// for a noisy model ([`Self::pseudo_marginal`]), where a permutation test finds the
    /// surrogate off, the step's k̂ does not hold or its spread ratio exceeds
    /// [`crate::spread_ratio::WIDER_THAN_PROPOSAL`], by the moment-matched log-ratio of
    /// [`crate::moment_matching`] (or, where that is refused, a defensive batch from a normal
    /// fitted to the first batch's weights, [`crate::defensive_normal`], or from the
    /// surrogate's posterior tempered where no such normal can be drawn,
    /// [`crate::defensive_tempering`]), both batches then weighed as one mixture sample.
    pub corrections: usize,
    /// Delayed-acceptance moves per member after a bridging stage.
    pub moves: usize,
    /// Surrogate Metropolis steps in each move's subchain.
    pub subchain: usize,
    /// Proposal scale β of the surrogate steps (covariance β²·Cov_w(θ)).
    pub scale: f64,
    /// Smallest tempering step.
    pub min_step: f64,
    /// The probabilities of the reported quantiles.
    pub probabilities: Vec<f64>,
    /// The model's log-likelihood is a noisy estimate: a chaotic or stochastic model, whose
    /// output moves by more than its own reported spread under a negligible change of the
    /// parameters, so that a run's likelihood L̂ is one draw whose mean over the model's
    /// irregular part is the likelihood L (pseudo-marginal; Andrieu & Roberts 2009). Importance
    /// weights L̂/L_s stay unbiased, so the estimate is one full step certified by k̂ (or
    /// nearly equal weights), after a moment-matched correction (or a defensive batch from a
    /// normal fitted to the weights, or from the surrogate's posterior tempered where no such
    /// normal can be drawn) where the first batch shows the surrogate off
    /// ([`crate::pseudo_marginal`]); no quadratic fit and no bridge, whose
    /// fits and Metropolis ratios assume a reproducible r (a noisy r makes the chains stick
    /// where a lucky run landed).
    #[serde(default)]
    pub pseudo_marginal: bool,
}

impl Default for ModelPosteriorSettings {
    fn default() -> Self {
        Self {
            samples: 300,
            seed: 1,
            cv_target: 1.0,
            bridge_cv_target: 0.5,
            max_stages: 6,
            corrections: 1,
            moves: 1,
            subchain: 20,
            scale: 0.4,
            min_step: 1e-4,
            probabilities: vec![0.025, 0.05, 0.25, 0.5, 0.75, 0.95, 0.975],
            pseudo_marginal: false,
        }
    }
}

impl ModelPosteriorSettings {
    /// Refuse settings outside their ranges ([`BasisError::InvalidSettings`], named as the keys).
    pub fn check(&self) -> Result<()> {
        let bad = |setting: &'static str, reason: &str| {
            Err(BasisError::InvalidSettings {
                setting,
                reason: reason.to_string(),
            })
        };
        if self.samples < MIN_SAMPLES {
            return bad(
                "samples",
                &format!("must be at least {MIN_SAMPLES} (k̂ needs a tail of 5 weights)"),
            );
        }
        if !(self.cv_target.is_finite() && self.cv_target > 0.0) {
            return bad("cv_target", "must be a positive number");
        }
        if !(self.bridge_cv_target.is_finite() && self.bridge_cv_target > 0.0) {
            return bad("bridge_cv_target", "must be a positive number");
        }
        if self.max_stages == 0 {
            return bad("max_stages", "must be at least 1");
        }
        if self.corrections > 1 {
            return bad("corrections", "must be 0 or 1");
        }
        if self.moves == 0 {
            return bad("moves", "must be at least 1");
        }
        if self.subchain == 0 {
            return bad("subchain", "must be at least 1");
        }
        if !(self.scale.is_finite() && self.scale > 0.0) {
            return bad("scale", "must be a positive number");
        }
        if !(self.min_step.is_finite() && self.min_step > 0.0 && self.min_step < 1.0) {
            return bad("min_step", "must lie in (0, 1)");
        }
        if self.probabilities.iter().any(|p| !(0.0..=1.0).contains(p)) {
            return bad("probabilities", "must lie in [0, 1]");
        }
        Ok(())
    }
}

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

/// One stage of [`model_posterior`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelPosteriorStage {
    /// 1, 2, …
    pub stage: usize,
    /// β after the stage.
    pub beta: f64,
    /// The step Δβ taken.
    pub step: f64,
    /// CV of the stage's incremental weights exp(Δβ·r).
    pub cv: f64,
    /// k̂ of those weights.
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
    /// mostly outside the batch, [`MIN_CORRECTED_WITHIN_BATCH`], or one BASIS could not sample).
    #[serde(default)]
    pub refused: Vec<String>,
}

/// A correction of the surrogate's log-likelihood, chosen at run time among the candidates.
type BoxedCorrection = Box<dyn Fn(&[f64]) -> f64 + Send + Sync>;

/// ℓ_s + r̂: the surrogate corrected by a fit of the model–surrogate difference (a quadratic
/// fit of r, or the moment-matched log-ratio of a noisy model's weights).
pub(crate) struct CorrectedLikelihood<'a, F: Fn(&[f64]) -> f64 + Send + Sync> {
    pub(crate) base: &'a dyn LogLikelihood,
    pub(crate) correction: F,
}

impl<F: Fn(&[f64]) -> f64 + Send + Sync> LogLikelihood for CorrectedLikelihood<'_, F> {
    fn parameter_count(&self) -> usize {
        self.base.parameter_count()
    }

    fn log_likelihood_batch(&self, points: &[Vec<f64>]) -> Result<Vec<PointLogLikelihood>> {
        Ok(self
            .base
            .log_likelihood_batch(points)?
            .into_iter()
            .zip(points)
            .map(|(v, x)| v.map(|v| v + (self.correction)(x)))
            .collect())
    }
}

/// Why [`model_posterior`] stopped.
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
    /// bridge's resampling ([`crate::ancestral_variance`]; without a bridge, member by member).
    pub mcse_mean: Vec<f64>,
    /// Monte Carlo standard error of each std (the delta method, grouped as `mcse_mean`).
    pub mcse_std: Vec<f64>,
    /// Distinct ancestors of the weighted members (S without a bridge; a bridge's resampling
    /// leaves fewer, and with very few the standard errors are unreliable).
    #[serde(default)]
    pub ancestors: usize,
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
    /// The corrections of the surrogate made (see [`ModelPosteriorSettings::corrections`]).
    pub corrections: Vec<SurrogateCorrection>,
    /// For a noisy model: the test of the first batch's weights for a mismatch of the
    /// surrogate's posterior ([`crate::moment_matching::proposal_mismatch`]; `None`: not made,
    /// with `corrections = 0`, a reproducible model, or too few effective weights).
    #[serde(default)]
    pub proposal_mismatch: Option<ProposalMismatch>,
    /// Why a correction that was wanted was not made: for a noisy model, every candidate (the
    /// moment-matched correction and the defensive batch) refused or impossible to sample; for
    /// a reproducible model, a corrected posterior mostly outside the batch its correction was
    /// fitted on ([`MIN_CORRECTED_WITHIN_BATCH`]). `None` when none was wanted or it was made.
    #[serde(default)]
    pub correction_not_made: Option<String>,
    /// Whether the final population is both batches of a correction, weighed as one sample of
    /// the mixture of the surrogate's posterior and the corrected one
    /// ([`crate::batch_mixture`]; always after a noisy model's correction, after a reproducible
    /// model's when their k̂ holds), rather than the corrected batch's stages alone.
    #[serde(default)]
    pub both_batches: bool,
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

/// The likelihoods, with batch failures turned into errors naming what was evaluated.
pub(crate) fn evaluate(
    likelihood: &dyn LogLikelihood,
    points: &[Vec<f64>],
    what: &str,
) -> Result<Vec<f64>> {
    if points.is_empty() {
        return Ok(Vec::new());
    }
    let values = likelihood
        .log_likelihood_batch(points)
        .map_err(|e| match e {
            BasisError::ModelInput(_) => e,
            e => BasisError::ModelBatch(format!("{what}: {e}")),
        })?;
    if values.len() != points.len() {
        return Err(BasisError::ModelBatch(format!(
            "{what}: {} values for {} points",
            values.len(),
            points.len()
        )));
    }
    Ok(values
        .into_iter()
        .map(|v| match v {
            Ok(v) if v.is_finite() => v,
            _ => f64::NEG_INFINITY,
        })
        .collect())
}

/// The indices (ascending) of the members of a surrogate population of `population_size` that
/// [`model_posterior`] runs through the model first: `min(samples, population_size)` of them,
/// drawn without replacement by `seed`, nested in `samples` ([`crate::member_selection`]: a
/// larger `samples` keeps these members and adds others, so their model runs are reused). A
/// caller that probes the model at the same members (e.g. whether its output is reproducible)
/// gets the points the method will request anyway.
pub fn selected_members(population_size: usize, settings: &ModelPosteriorSettings) -> Vec<usize> {
    let s = settings.samples.min(population_size);
    nested_selection(
        &mut stream(settings.seed, STREAM_BASE, 0),
        population_size,
        s,
    )
}

/// What [`model_posterior`] reports to its [`Observer`] as it goes, for progress lines: a user
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
}

/// The observer of [`model_posterior`]'s events, inside the method.
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

/// The model's posterior from the surrogate's `population` (see the module documentation):
/// `surrogate` and `model` are the two log-likelihoods of the same parameters on `space`;
/// `observer` sees each correction before its batch and every stage as it ends; its
/// [`Control::Stop`] ends the method with [`BasisError::Interrupted`] (unless the event was its
/// last stage).
pub fn model_posterior(
    space: &ParameterSpace,
    population: SurrogatePopulation<'_>,
    surrogate: &dyn LogLikelihood,
    model: &dyn LogLikelihood,
    settings: &ModelPosteriorSettings,
    observer: &mut dyn for<'a> Observer<ModelPosteriorEvent<'a>>,
) -> Result<ModelPosterior> {
    settings.check()?;
    check_inputs(space, &population, surrogate, model)?;
    let s = settings.samples.min(population.samples.len());
    let widths: Vec<f64> = space.ranges().iter().map(|(lo, hi)| hi - lo).collect();
    let mut state = MethodState::first_batch(model, &population, settings)?;
    let corrected_holder: CorrectedLikelihood<'_, BoxedCorrection>;
    // After a correction: both batches as one sample of ½q + ½q_c, tried before the stages.
    let mut mixture: Option<BatchMixture> = None;
    let mut surrogate = surrogate;
    if settings.corrections > 0 && !settings.pseudo_marginal {
        let inputs = MethodInputs {
            space,
            surrogate,
            model,
            settings,
            widths: &widths,
        };
        if let Some((likelihood, both)) = state.correct(&inputs, &population, observer)? {
            corrected_holder = likelihood;
            surrogate = &corrected_holder;
            mixture = Some(both);
        }
    }
    // Each member's ancestor in the batch the stages started from (itself until a bridge
    // resamples): the grouping of the standard errors ([`crate::ancestral_variance`]).
    state.ancestor = (0..state.members.theta.len()).collect();
    let inputs = MethodInputs {
        space,
        surrogate,
        model,
        settings,
        widths: &widths,
    };
    let weights = if settings.pseudo_marginal {
        state.pseudo_marginal(&inputs, population, observer)?
    } else if let Some(certified) =
        mixture.and_then(|(members, raw)| certified_mixture(members, raw, s, state.failures))
    {
        state.adopt_mixture(certified, observer)
    } else {
        state.temper(&inputs, observer)?
    };
    state.into_posterior(space, settings, weights)
}

/// Both batches as one sample of their even mixture, with their raw log-weights.
type BatchMixture = (Members, Vec<f64>);

/// The state of [`model_posterior`] between its phases (argmin's shape): the members the
/// weights are for, the model runs made, the stages and corrections so far.
struct MethodState {
    members: Members,
    /// Each member's ancestor in the batch the stages started from.
    ancestor: Vec<usize>,
    evaluations: usize,
    failures: usize,
    best: Best,
    /// Model evaluations and failures of the batch the first stage weighs.
    stage_evaluations: (usize, usize),
    log_evidence_ratio: f64,
    stages: Vec<ModelPosteriorStage>,
    /// The k̂ threshold the final weights are held to.
    threshold: f64,
    corrections: Vec<SurrogateCorrection>,
    correction_not_made: Option<String>,
    mismatch: Option<ProposalMismatch>,
    both_batches: bool,
}

impl MethodState {
    /// The first batch: the [`selected_members`] of `population`, run through the model.
    fn first_batch(
        model: &dyn LogLikelihood,
        population: &SurrogatePopulation<'_>,
        settings: &ModelPosteriorSettings,
    ) -> Result<Self> {
        let n = population.samples.len();
        let s = settings.samples.min(n);
        let chosen = selected_members(n, settings);
        let theta: Vec<Vec<f64>> = chosen
            .iter()
            .map(|&i| population.samples[i].clone())
            .collect();
        let ls: Vec<f64> = chosen
            .iter()
            .map(|&i| population.log_likelihood[i])
            .collect();
        let lp: Vec<f64> = chosen.iter().map(|&i| population.log_prior[i]).collect();
        let lm = evaluate(
            model,
            &theta,
            "the model at the surrogate's posterior samples",
        )?;
        let failures = lm.iter().filter(|v| !v.is_finite()).count();
        let mut best = Best::default();
        best.offer(&theta, &lm, &lp);
        Ok(Self {
            members: Members {
                theta,
                surrogate: ls,
                model: lm,
                prior: lp,
            },
            ancestor: Vec::new(),
            evaluations: s,
            failures,
            best,
            stage_evaluations: (s, failures),
            log_evidence_ratio: 0.0,
            stages: Vec::new(),
            threshold: pareto_k_threshold(s),
            corrections: Vec::new(),
            correction_not_made: None,
            mismatch: None,
            both_batches: false,
        })
    }

    /// Corrects the surrogate where the first batch does not hold in one stage
    /// ([`correct_first_batch`]); after a correction the members are the second batch, and the
    /// corrected surrogate comes back with both batches' mixture.
    fn correct<'a>(
        &mut self,
        inputs: &MethodInputs<'a>,
        population: &SurrogatePopulation<'_>,
        observer: &mut EventObserver<'_>,
    ) -> Result<Option<(CorrectedLikelihood<'a, BoxedCorrection>, BatchMixture)>> {
        let s = inputs.settings.samples.min(population.samples.len());
        let first = Members {
            theta: self.members.theta.clone(),
            surrogate: self.members.surrogate.clone(),
            model: self.members.model.clone(),
            prior: self.members.prior.clone(),
        };
        match correct_first_batch(inputs, population, first, self.threshold, observer)? {
            FirstBatch::Kept { not_corrected } => {
                self.correction_not_made = not_corrected;
                Ok(None)
            }
            FirstBatch::Corrected(corrected) => {
                let CorrectedBatch {
                    record,
                    likelihood,
                    log_evidence_ratio: ratio,
                    batch,
                    mixture,
                } = *corrected;
                self.corrections.push(record);
                self.log_evidence_ratio += ratio;
                let batch_failures = batch.model.iter().filter(|v| !v.is_finite()).count();
                self.evaluations += s;
                self.failures += batch_failures;
                self.stage_evaluations = (s, batch_failures);
                self.members = batch;
                self.best.offer(
                    &self.members.theta,
                    &self.members.model,
                    &self.members.prior,
                );
                Ok(Some((likelihood, mixture)))
            }
        }
    }

    /// The members, leaving empty ones in their place.
    fn take_members(&mut self) -> Members {
        Members {
            theta: std::mem::take(&mut self.members.theta),
            surrogate: std::mem::take(&mut self.members.surrogate),
            model: std::mem::take(&mut self.members.model),
            prior: std::mem::take(&mut self.members.prior),
        }
    }

    /// A noisy model's weights: the pseudo-marginal estimate ([`noisy_estimate`]).
    fn pseudo_marginal(
        &mut self,
        inputs: &MethodInputs<'_>,
        population: SurrogatePopulation<'_>,
        observer: &mut EventObserver<'_>,
    ) -> Result<TemperedWeights> {
        let first = self.take_members();
        let estimate = noisy_estimate(
            inputs,
            population,
            first,
            self.failures,
            &mut self.best,
            observer,
        )?;
        // The method's last stage: nothing is left to stop.
        observer.observe(&ModelPosteriorEvent::Stage(&estimate.stage));
        self.stages.push(estimate.stage);
        self.members = estimate.members;
        self.ancestor = (0..self.members.theta.len()).collect();
        self.evaluations += estimate.evaluations;
        self.failures += estimate.failures;
        self.corrections.extend(estimate.correction);
        self.log_evidence_ratio += estimate.log_evidence_ratio;
        self.threshold = estimate.threshold;
        self.mismatch = estimate.mismatch;
        self.correction_not_made = estimate.not_corrected;
        self.both_batches = !self.corrections.is_empty();
        Ok((
            estimate.raw,
            estimate.smoothing.log_weights,
            estimate.smoothing.pareto_k,
            estimate.stop,
        ))
    }

    /// Both batches' certified mixture ([`certified_mixture`]) as the one full step.
    fn adopt_mixture(
        &mut self,
        (members, raw, smoothing, stage): (Members, Vec<f64>, ParetoSmoothing, ModelPosteriorStage),
        observer: &mut EventObserver<'_>,
    ) -> TemperedWeights {
        self.log_evidence_ratio = log_evidence_increment(&raw, 1.0, largest_finite(&raw));
        self.threshold = pareto_k_threshold(raw.len());
        self.both_batches = true;
        // The method's last stage: nothing is left to stop.
        observer.observe(&ModelPosteriorEvent::Stage(&stage));
        self.stages.push(stage);
        self.members = members;
        self.ancestor = (0..self.members.theta.len()).collect();
        (
            raw,
            smoothing.log_weights,
            smoothing.pareto_k,
            ModelPosteriorStop::Certified,
        )
    }

    /// The tempered stages from the members to the model's posterior ([`Tempering`]).
    fn temper(
        &mut self,
        bridge: &MethodInputs<'_>,
        observer: &mut EventObserver<'_>,
    ) -> Result<TemperedWeights> {
        let mut tempering = Tempering {
            members: self.take_members(),
            ancestor: std::mem::take(&mut self.ancestor),
            beta: 0.0,
            log_evidence_ratio: self.log_evidence_ratio,
            stages: std::mem::take(&mut self.stages),
            stage_evaluations: self.stage_evaluations,
            bridge_rates: (None, None),
            evaluations: self.evaluations,
            failures: self.failures,
            best: std::mem::take(&mut self.best),
        };
        let weights = loop {
            if let Some(done) = tempering.step(bridge, self.threshold, observer)? {
                break done;
            }
        };
        self.members = tempering.members;
        self.ancestor = tempering.ancestor;
        self.log_evidence_ratio = tempering.log_evidence_ratio;
        self.stages = tempering.stages;
        self.evaluations = tempering.evaluations;
        self.failures = tempering.failures;
        self.best = tempering.best;
        Ok(weights)
    }

    /// The posterior of the members weighed by the final `weights`: moments, quantiles, their
    /// standard errors and the MAP point.
    fn into_posterior(
        self,
        space: &ParameterSpace,
        settings: &ModelPosteriorSettings,
        (raw, smoothed, pareto_k, stop): TemperedWeights,
    ) -> Result<ModelPosterior> {
        let Members {
            theta,
            surrogate: ls,
            model: lm,
            prior: lp,
        } = self.members;
        let (weights, mean, std, quantiles) =
            weighted_moments(&theta, &smoothed, &settings.probabilities)?;
        let errors = ancestral_errors(&theta, &weights, &self.ancestor, &mean, &std);
        let Some((map, map_log_likelihood, map_log_prior)) = self.best.point else {
            return Err(BasisError::NoFiniteLikelihood {
                stage: self.stages.len(),
                failures: self.failures,
            });
        };
        Ok(ModelPosterior {
            names: space.names(),
            effective_sample_size: effective_sample_size(&weights),
            samples: theta,
            log_weights: smoothed,
            raw_log_weights: raw,
            model_log_likelihood: lm,
            surrogate_log_likelihood: ls,
            log_prior: lp,
            stages: self.stages,
            pareto_k,
            pareto_k_threshold: self.threshold,
            stop,
            mean,
            std,
            mcse_mean: errors.mean,
            mcse_std: errors.std,
            ancestors: errors.ancestors,
            probabilities: settings.probabilities.clone(),
            quantiles,
            map,
            map_log_likelihood,
            map_log_prior,
            log_evidence_ratio: self.log_evidence_ratio,
            corrections: self.corrections,
            proposal_mismatch: self.mismatch,
            correction_not_made: self.correction_not_made,
            both_batches: self.both_batches,
            model_evaluations: self.evaluations,
            failures: self.failures,
        })
    }
}

/// The surrogate population and both likelihoods fit `space`: samples of its dimension, one
/// finite log-likelihood and log-prior each, at least [`MIN_SAMPLES`] of them.
fn check_inputs(
    space: &ParameterSpace,
    population: &SurrogatePopulation<'_>,
    surrogate: &dyn LogLikelihood,
    model: &dyn LogLikelihood,
) -> Result<()> {
    let d = space.dimension();
    let n = population.samples.len();
    if n == 0
        || population.log_likelihood.len() != n
        || population.log_prior.len() != n
        || population.samples.iter().any(|s| s.len() != d)
    {
        return Err(BasisError::InvalidData(format!(
            "the surrogate population needs samples of {d} parameters with one log-likelihood and log-prior each ({n} samples, {} and {})",
            population.log_likelihood.len(),
            population.log_prior.len()
        )));
    }
    for (what, l) in [("surrogate", surrogate), ("model", model)] {
        if l.parameter_count() != d {
            return Err(BasisError::InvalidLikelihood(format!(
                "the {what} likelihood takes {} parameters, the space has {d}",
                l.parameter_count()
            )));
        }
    }
    if let Some(i) = (0..n).find(|&i| {
        !population.log_likelihood[i].is_finite() || !population.log_prior[i].is_finite()
    }) {
        return Err(BasisError::InvalidData(format!(
            "member {i} of the surrogate population has a non-finite log-likelihood or log-prior"
        )));
    }
    if n < MIN_SAMPLES {
        return Err(BasisError::InvalidData(format!(
            "the surrogate population has {n} members, fewer than the {MIN_SAMPLES} k̂ needs"
        )));
    }
    Ok(())
}

/// The normalised weights of `log_weights`, and the weighted mean, std and quantiles at
/// `probabilities` of every parameter of `theta`.
#[allow(clippy::type_complexity)]
fn weighted_moments(
    theta: &[Vec<f64>],
    log_weights: &[f64],
    probabilities: &[f64],
) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>, Vec<Vec<f64>>)> {
    let d = theta.first().map_or(0, Vec::len);
    let weights = normalised_weights(log_weights);
    let mut mean = vec![0.0; d];
    for (t, w) in theta.iter().zip(&weights) {
        for k in 0..d {
            mean[k] += w * t[k];
        }
    }
    let std: Vec<f64> = (0..d)
        .map(|k| {
            theta
                .iter()
                .zip(&weights)
                .map(|(t, w)| w * (t[k] - mean[k]).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .collect();
    let quantiles = (0..d)
        .map(|k| {
            let values: Vec<f64> = theta.iter().map(|t| t[k]).collect();
            weighted_quantiles(&values, &weights, probabilities)
        })
        .collect::<std::result::Result<Vec<_>, _>>()?;
    Ok((weights, mean, std, quantiles))
}

/// The tempered stages from the (corrected) surrogate's posterior, β = 0, to the model's,
/// β = 1: the state between two stages, one [`Tempering::step`] per stage (argmin's shape).
struct Tempering {
    members: Members,
    /// Each member's ancestor in the batch the stages started from (itself until a bridge
    /// resamples): the grouping of the standard errors ([`crate::ancestral_variance`]).
    ancestor: Vec<usize>,
    beta: f64,
    log_evidence_ratio: f64,
    stages: Vec<ModelPosteriorStage>,
    /// Model evaluations and failures of the batch the next stage weighs.
    stage_evaluations: (usize, usize),
    /// The last bridge's screen and confirmation acceptance rates.
    bridge_rates: (Option<f64>, Option<f64>),
    evaluations: usize,
    failures: usize,
    best: Best,
}

/// A finished tempering: the raw and Pareto-smoothed log-weights of the final step, its k̂ and
/// why it stopped.
type TemperedWeights = (Vec<f64>, Vec<f64>, f64, ModelPosteriorStop);

impl Tempering {
    /// One stage: the largest step of β whose weights hold (k̂ below `threshold`, or nearly
    /// equal weights; a step to 1 also within the members' spread), halved down to
    /// `min_step`; then, short of β = 1, a bridge. `Some` when the stages are done.
    fn step(
        &mut self,
        bridge: &MethodInputs<'_>,
        threshold: f64,
        observer: &mut EventObserver<'_>,
    ) -> Result<Option<TemperedWeights>> {
        let settings = bridge.settings;
        let s = self.members.theta.len();
        let r: Vec<f64> = log_ratios(&self.members.model, &self.members.surrogate);
        let max_r = largest_finite(&r);
        if !max_r.is_finite() {
            return Err(BasisError::NoFiniteLikelihood {
                stage: self.stages.len() + 1,
                failures: s,
            });
        }
        let cv_target = if self.stages.is_empty() {
            settings.cv_target
        } else {
            settings.bridge_cv_target
        };
        let rule = next_step(&r, self.beta, cv_target, max_r);
        let mut step = rule.step;
        let scaled = |step: f64| -> Vec<f64> { r.iter().map(|v| step * v).collect() };
        let mut smoothing = pareto_smooth(&scaled(step));
        // A step to β = 1 is the estimate: its target must not be wider than the
        // population (a narrow proposal's weights hide their tail from k̂). A step short of
        // it is followed by a bridge, whose moves spread the population.
        let holds = |smoothing: &crate::ParetoSmoothing, step: f64| {
            (smoothing.pareto_k <= threshold
                || coefficient_of_variation(&scaled(step)) <= NEARLY_EQUAL_CV)
                && (!(rule.reaches_one && step == rule.step)
                    || within_proposal_spread(&self.members.theta, &smoothing.log_weights, 1))
        };
        while !holds(&smoothing, step) && step / 2.0 >= settings.min_step {
            step /= 2.0;
            smoothing = pareto_smooth(&scaled(step));
        }
        let reaches_one = rule.reaches_one && step == rule.step;
        let next_beta = if reaches_one { 1.0 } else { self.beta + step };
        let raw = scaled(step);
        let record = ModelPosteriorStage {
            stage: self.stages.len() + 1,
            beta: next_beta,
            step,
            cv: coefficient_of_variation(&raw),
            pareto_k: smoothing.pareto_k,
            cv_step: rule.step,
            effective_sample_size: effective_sample_size(&normalised_weights(
                &smoothing.log_weights,
            )),
            model_evaluations: self.stage_evaluations.0,
            failures: self.stage_evaluations.1,
            screen_acceptance: self.bridge_rates.0,
            confirm_acceptance: self.bridge_rates.1,
            spread_ratio: recorded_spread_ratio(&self.members.theta, &smoothing.log_weights, 1),
        };
        let control = observer.observe(&ModelPosteriorEvent::Stage(&record));
        self.stages.push(record);
        let certified_step = holds(&smoothing, step);
        if reaches_one && certified_step {
            self.log_evidence_ratio += log_evidence_increment(&r, step, max_r);
            return Ok(Some((
                raw,
                smoothing.log_weights,
                smoothing.pareto_k,
                ModelPosteriorStop::Certified,
            )));
        }
        if !certified_step || self.stages.len() >= settings.max_stages {
            // The rest of the way in one step, uncertified.
            let rest = scaled(1.0 - self.beta);
            self.log_evidence_ratio += log_evidence_increment(&r, 1.0 - self.beta, max_r);
            let last = pareto_smooth(&rest);
            let stop = if certified_step {
                ModelPosteriorStop::MaxStages { beta: next_beta }
            } else {
                ModelPosteriorStop::StepBelowMinimum { beta: self.beta }
            };
            return Ok(Some((rest, last.log_weights, last.pareto_k, stop)));
        }
        // A bridge follows: the observer may stop the method here.
        if control == Control::Stop {
            return Err(BasisError::Interrupted);
        }
        self.log_evidence_ratio += log_evidence_increment(&r, step, max_r);
        self.beta = next_beta;

        // The bridge: resample by the stage's weights, then delayed-acceptance moves at β.
        let weights = StageWeights {
            stage: self.stages.len(),
            beta: self.beta,
            log_ratios: &r,
            log_weights: &smoothing.log_weights,
        };
        let moved = bridge.bridge(
            &weights,
            &mut self.members,
            &mut self.ancestor,
            &mut self.best,
        )?;
        self.evaluations += moved.evaluations;
        self.failures += moved.failures;
        self.stage_evaluations = (moved.evaluations, moved.failures);
        self.bridge_rates = (
            Some(moved.screen_acceptance),
            Some(moved.confirm_acceptance),
        );
        Ok(None)
    }
}

/// Both batches' mixture weights ([`crate::batch_mixture`]) as the model posterior's one full
/// step, with its stage record, when their k̂ holds at the threshold of their joint size (or
/// they are nearly equal); `None` otherwise (the stages go on from the corrected batch).
fn certified_mixture(
    members: Members,
    raw: Vec<f64>,
    batch: usize,
    failures: usize,
) -> Option<(Members, Vec<f64>, ParetoSmoothing, ModelPosteriorStage)> {
    if !largest_finite(&raw).is_finite() {
        return None;
    }
    let smoothing = pareto_smooth(&raw);
    let cv = coefficient_of_variation(&raw);
    if smoothing.pareto_k > pareto_k_threshold(raw.len()) && cv > NEARLY_EQUAL_CV {
        return None;
    }
    if !within_proposal_spread(&members.theta, &smoothing.log_weights, 2) {
        return None;
    }
    let stage =
        ModelPosteriorStage::full_step(&members.theta, 2, &smoothing, cv, 2 * batch, failures);
    Some((members, raw, smoothing, stage))
}

/// A step's [`ModelPosteriorStage::spread_ratio`]: the widest ratio of weighted std to the
/// proposal's over `points` (`batches` batches), 0 where it cannot be computed.
pub(crate) fn recorded_spread_ratio(
    points: &[Vec<f64>],
    log_weights: &[f64],
    batches: usize,
) -> f64 {
    widest_spread_ratio(points, log_weights, batches).map_or(0.0, |(_, ratio)| ratio)
}

/// Why a corrected posterior's `samples` are refused against the `batch` its correction was
/// fitted on ("keeps N % of its population inside the range of P …"), where less than
/// [`MIN_CORRECTED_WITHIN_BATCH`] of them lie inside the batch's range of some parameter P;
/// `None` when they do not.
pub(crate) fn outside_batch(
    space: &ParameterSpace,
    samples: &[Vec<f64>],
    batch: &[Vec<f64>],
) -> Option<String> {
    let (parameter, within) = least_share_within_ranges(samples, batch);
    (within < MIN_CORRECTED_WITHIN_BATCH).then(|| {
        format!(
            "keeps {:.0} % of its population inside the range of {} over the batch it was \
             fitted on (at least {:.0} % needed)",
            100.0 * within,
            space.names()[parameter],
            100.0 * MIN_CORRECTED_WITHIN_BATCH
        )
    })
}

/// The parameter whose range over `batch` (minimum to maximum) holds the smallest share of
/// `samples`, and that share (parameter 0 and share 0 for an empty batch).
fn least_share_within_ranges(samples: &[Vec<f64>], batch: &[Vec<f64>]) -> (usize, f64) {
    let Some(d) = batch.first().map(Vec::len) else {
        return (0, 0.0);
    };
    (0..d)
        .map(|k| {
            let (lo, hi) = batch
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| {
                    (lo.min(t[k]), hi.max(t[k]))
                });
            let inside = samples.iter().filter(|t| t[k] >= lo && t[k] <= hi).count();
            (k, inside as f64 / samples.len().max(1) as f64)
        })
        .fold((0, f64::INFINITY), |least, (k, share)| {
            if share < least.1 { (k, share) } else { least }
        })
}

/// The largest finite value (−∞ when there is none: every model run failed).
pub(crate) fn largest_finite(values: &[f64]) -> f64 {
    values
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(f64::NEG_INFINITY, f64::max)
}

/// r_i = ℓ_m,i − ℓ_s,i, −∞ where it is not finite (a failed model run).
pub(crate) fn log_ratios(model: &[f64], surrogate: &[f64]) -> Vec<f64> {
    model
        .iter()
        .zip(surrogate)
        .map(|(m, s)| {
            let r = m - s;
            if r.is_finite() { r } else { f64::NEG_INFINITY }
        })
        .collect()
}

/// CV (population std / mean) of the weights exp(lw − max lw), as BASIS's rule measures it;
/// failed members count as 0.
pub(crate) fn coefficient_of_variation(log_weights: &[f64]) -> f64 {
    crate::annealing::coefficient_of_variation(&normalised_weights(log_weights))
}

/// The best model-evaluated point so far (largest ℓ_m + ln π; the first one on ties).
#[derive(Default)]
pub(crate) struct Best {
    point: Option<(Vec<f64>, f64, f64)>,
}

impl Best {
    pub(crate) fn offer(&mut self, points: &[Vec<f64>], lm: &[f64], lp: &[f64]) {
        for ((p, &m), &q) in points.iter().zip(lm).zip(lp) {
            if !(m + q).is_finite() {
                continue;
            }
            let better = match &self.point {
                Some((_, bm, bq)) => m + q > bm + bq,
                None => true,
            };
            if better {
                self.point = Some((p.clone(), m, q));
            }
        }
    }
}
