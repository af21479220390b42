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

pub(crate) mod bridge;
mod correction;
pub(crate) mod members;
pub(crate) mod records;
pub(crate) mod settings;

use bridge::{MethodInputs, StageWeights};
use correction::{CorrectedBatch, FirstBatch, correct_first_batch};
use members::{
    Best, BoxedCorrection, CorrectedLikelihood, Members, coefficient_of_variation, evaluate,
    largest_finite, log_ratios, recorded_spread_ratio,
};
use records::{EventObserver, report};
pub use records::{
    ModelPosterior, ModelPosteriorEvent, ModelPosteriorStage, ModelPosteriorStop,
    SurrogateCorrection, SurrogatePopulation, Tempering,
};
pub use settings::{
    MIN_CORRECTED_WITHIN_BATCH, MIN_SAMPLES, ModelPosteriorSettings, NEARLY_EQUAL_CV, STREAM_BASE,
    selected_members,
};

use iuq_core::ParameterSpace;
use iuq_core::weighted_statistics::{effective_sample_size, weighted_quantiles};

use crate::ancestral_variance::ancestral_errors;
use crate::annealing::{log_evidence_increment, next_step};
use crate::error::{BasisError, Result};
use crate::heavy_tail_errors::{CLT_PARETO_K, pareto_convergence_rate, subsampling_errors};
use crate::likelihood::LogLikelihood;
use crate::moment_matching::ProposalMismatch;
use crate::paired_estimate::paired_moments;
use crate::pareto_smoothing::{
    ParetoSmoothing, normalised_weights, pareto_k_threshold, pareto_smooth,
};
use crate::pseudo_marginal::noisy_estimate;
use crate::sampler::{Control, Observer};
use crate::spread_ratio::within_proposal_spread;

/// The model's posterior from the surrogate's `population` (see the module documentation):
/// `surrogate` and `model` are the two log-likelihoods of the same parameters on `space`;
/// `observer` sees each correction before its batch, every stage as it ends and the state
/// after every bridge ([`ModelPosteriorEvent::Bridged`]); its [`Control::Stop`] ends the method
/// with [`BasisError::Interrupted`] (unless the event was its last stage).
pub fn model_posterior(
    space: &ParameterSpace,
    population: SurrogatePopulation<'_>,
    surrogate: &dyn LogLikelihood,
    model: &dyn LogLikelihood,
    settings: &ModelPosteriorSettings,
    observer: &mut dyn for<'a> Observer<ModelPosteriorEvent<'a>>,
) -> Result<ModelPosterior> {
    run_method(
        space, population, surrogate, model, settings, None, observer,
    )
}

/// [`model_posterior`] going on from `checkpoint`, the state a run of the same inputs reported
/// after one of its bridges ([`ModelPosteriorEvent::Bridged`]): the first batch and any
/// correction are made again (the same model points in the same order, which a campaign store
/// answers from its runs), the stages up to the checkpoint are not, and the result is the
/// uninterrupted run's, bit for bit.
///
/// # Errors
/// As [`model_posterior`]; [`BasisError::CheckpointMismatch`] where `checkpoint` is not a
/// state of this run's tempering (another member count or other stages before it).
pub fn resume_model_posterior(
    space: &ParameterSpace,
    population: SurrogatePopulation<'_>,
    surrogate: &dyn LogLikelihood,
    model: &dyn LogLikelihood,
    settings: &ModelPosteriorSettings,
    checkpoint: Tempering,
    observer: &mut dyn for<'a> Observer<ModelPosteriorEvent<'a>>,
) -> Result<ModelPosterior> {
    run_method(
        space,
        population,
        surrogate,
        model,
        settings,
        Some(checkpoint),
        observer,
    )
}

/// The body of [`model_posterior`] and [`resume_model_posterior`].
fn run_method(
    space: &ParameterSpace,
    population: SurrogatePopulation<'_>,
    surrogate: &dyn LogLikelihood,
    model: &dyn LogLikelihood,
    settings: &ModelPosteriorSettings,
    resume: Option<Tempering>,
    observer: &mut dyn for<'a> Observer<ModelPosteriorEvent<'a>>,
) -> Result<ModelPosterior> {
    settings.check()?;
    check_inputs(space, &population, surrogate, model)?;
    let s = settings.samples.min(population.samples.len());
    // Refused before any model run: a state of another member count, or of a method that
    // does not temper.
    if let Some(checkpoint) = &resume
        && (checkpoint.members.theta.len() != s || settings.pseudo_marginal)
    {
        return Err(BasisError::CheckpointMismatch(format!(
            "the tempering state holds {} members; this run weighs {s}{}",
            checkpoint.members.theta.len(),
            if settings.pseudo_marginal {
                " in one step (pseudo_marginal), without stages"
            } else {
                ""
            }
        )));
    }
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
        if resume.is_some() {
            return Err(BasisError::CheckpointMismatch(
                "this run's two batches hold in one step, without the stages the tempering state comes from".into(),
            ));
        }
        state.adopt_mixture(certified, observer)
    } else {
        state.temper(&inputs, resume, observer)?
    };
    state.into_posterior(space, settings, weights, population.samples)
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
        resume: Option<Tempering>,
        observer: &mut EventObserver<'_>,
    ) -> Result<TemperedWeights> {
        let mut tempering = match resume {
            Some(resumed) => {
                resumed.check_resumes(self, bridge.settings)?;
                resumed
            }
            None => Tempering {
                origin: Tempering::origin_of(&self.members, bridge.settings),
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
            },
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
        population: &[Vec<f64>],
    ) -> Result<ModelPosterior> {
        // One certified step from the first batch: its members are the uniform subset
        // `selected_members` of the population, which the paired estimate needs.
        let first_batch_step = stop == ModelPosteriorStop::Certified
            && !settings.pseudo_marginal
            && self.corrections.is_empty()
            && !self.both_batches
            && self.stages.len() == 1;
        let Members {
            theta,
            surrogate: ls,
            model: lm,
            prior: lp,
        } = self.members;
        let (weights, mut mean, mut std, quantiles) =
            weighted_moments(&theta, &smoothed, &settings.probabilities)?;
        let mut errors = ancestral_errors(&theta, &weights, &self.ancestor, &mean, &std);
        // Heavy-tailed weights: the larger of the delta method's error and the subsampling one,
        // and no pairing (whose error is a delta method too).
        let heavy_tail_errors = (pareto_k > CLT_PARETO_K)
            .then(|| {
                let rate = pareto_convergence_rate(pareto_k, theta.len());
                subsampling_errors(&theta, &weights, &self.ancestor, rate)
            })
            .flatten();
        if let Some(heavy) = &heavy_tail_errors {
            for (e, h) in errors.mean.iter_mut().zip(&heavy.mean) {
                *e = e.max(*h);
            }
            for (e, h) in errors.std.iter_mut().zip(&heavy.std) {
                *e = e.max(*h);
            }
        }
        let paired = (first_batch_step && pareto_k <= CLT_PARETO_K)
            .then(|| {
                paired_moments(
                    population,
                    &selected_members(population.len(), settings),
                    &weights,
                )
            })
            .flatten()
            .filter(|p| {
                largest_relative(&p.mcse_mean, &p.std) < largest_relative(&errors.mean, &std)
            });
        let paired = paired.map(|p| {
            mean = p.mean;
            std = p.std;
            errors.mean = p.mcse_mean;
            errors.std = p.mcse_std;
            p.errors
        });
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
            heavy_tail_errors,
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
            paired,
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

/// max_k error_k/std_k (infinite where a std is 0).
fn largest_relative(error: &[f64], std: &[f64]) -> f64 {
    error
        .iter()
        .zip(std)
        .map(|(e, s)| if *s > 0.0 { e / s } else { f64::INFINITY })
        .fold(0.0, f64::max)
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
        report(observer, ModelPosteriorEvent::Bridged(self))?;
        Ok(None)
    }

    /// Whether this state can go on in `state`'s run: it began from the same members (θ, both
    /// log-likelihoods, log-priors) under the same settings, and its own parts fit together.
    fn check_resumes(&self, state: &MethodState, settings: &ModelPosteriorSettings) -> Result<()> {
        let mismatch = |what: String| Err(BasisError::CheckpointMismatch(what));
        if self.origin != Tempering::origin_of(&state.members, settings) {
            return mismatch(
                "the tempering state began from other members or under other settings than this run's"
                    .into(),
            );
        }
        let s = self.members.theta.len();
        let d = state.members.theta.first().map_or(0, Vec::len);
        let lengths = [
            self.members.surrogate.len(),
            self.members.model.len(),
            self.members.prior.len(),
            self.ancestor.len(),
        ];
        if s != state.members.theta.len()
            || lengths.iter().any(|&n| n != s)
            || self.members.theta.iter().any(|t| t.len() != d)
            || self.ancestor.iter().any(|&a| a >= s)
        {
            return mismatch(format!(
                "the tempering state's members do not fit together or this run's {} members of {d} parameters",
                state.members.theta.len()
            ));
        }
        if !(self.beta > 0.0 && self.beta < 1.0)
            || self.stages.last().map(|stage| stage.beta) != Some(self.beta)
        {
            return mismatch(format!(
                "the tempering state's β = {} is not that of its last stage, between 0 and 1",
                self.beta
            ));
        }
        Ok(())
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
