//! The model posterior of a noisy model: one pseudo-marginal importance step, preceded by a
//! moment-matched correction of the surrogate (or a defensive batch from a normal fitted to the
//! weights, or from the surrogate's posterior tempered) where the first batch shows the surrogate's posterior off the model's by more than
//! the weights' noise explains, the step's k̂ does not hold, or its spread ratio exceeds
//! [`crate::spread_ratio::WIDER_THAN_PROPOSAL`].
//!
//! Each run's likelihood L̂ is an unbiased draw of the likelihood L averaged over the model's
//! irregular part, so the weights L̂/L_s are unbiased (Andrieu & Roberts 2009) and one full step
//! from the surrogate's posterior q is a consistent estimate. Consistent is not enough for a few
//! hundred members: where q is shifted or narrower than the target, self-normalised importance
//! sampling is biased towards q by O(1/ESS) and k̂ of noisy weights does not always flag it. So:
//!
//! 1. The first batch of S members of q is run; [`crate::moment_matching::proposal_mismatch`]
//!    tests whether the weighted moments differ from q's more than the same weights dealt to
//!    the members at random would make them.
//! 2. If not, and the step's k̂ holds, and no parameter's weighted std exceeds the batch's by
//!    more than [`crate::spread_ratio::WIDER_THAN_PROPOSAL`] (a target wider than the batch,
//!    whose tail k̂ underestimates and the test, against the weights' noise, can miss), the
//!    estimate is that step.
//! 3. Otherwise (and where `corrections` allows one), the surrogate is corrected
//!    by the moment-matched log-ratio g (ℓ_s + g, [`crate::moment_matching::GaussianLogRatio`],
//!    towards the weighted moments with the stds widened by
//!    [`crate::moment_matching::DEFENSIVE_WIDENING`]), the corrected surrogate's posterior
//!    q_c ∝ q·e^g sampled by BASIS (surrogate evaluations only), and a
//!    second batch of S members of q_c run. Both batches are weighed as one sample of the
//!    mixture ½q + ½q_c (the deterministic-mixture, or balance-heuristic, weights of multiple
//!    importance sampling; Veach & Guibas 1995, Owen & Zhou 2000; [`crate::batch_mixture`]):
//!    w = L̂·π / (½q + ½q_c) ∝ exp(r̂ − ln(½(1 + e^{g − ln c}))), r̂ = ℓ̂_m − ℓ_s,
//!    c = Z_c/Z_s, estimated by bridge sampling between the surrogate population and the
//!    corrected one (Meng & Wong 1996; no model runs). No run is wasted, and the weights' second
//!    moment is never more than twice what the better of the two proposals alone would give,
//!    so a correction that overshoots cannot make the estimate much worse than the first
//!    batch's.
//!
//! The estimate is consistent, not unbiased beyond what self-normalised importance sampling
//! is: g is fitted to the first batch's own weights, and that batch is then weighed again under
//! the mixture (and the choice to correct was made on it), the reuse of adaptive multiple
//! importance sampling (Cornuet et al. 2012), which adds a bias of order 1/S (Marin, Pudlo &
//! Sedki 2019). Measured on the test problems (docs/methods.md §5b), what remains is within
//! about one MCSE.
//!
//! 4. Where that correction cannot be made — its posterior leaves the batch's range of some
//!    parameter ([`crate::model_posterior::MIN_CORRECTED_WITHIN_BATCH`]: g, fitted to the
//!    batch, extrapolates there), fewer than 2(d + 1) effective weights, or BASIS cannot
//!    sample it — the second batch is drawn from a normal fitted to the first batch's weights
//!    ([`crate::defensive_normal`]), or, where no such normal can be fitted or drawn, from the
//!    surrogate's posterior tempered at
//!    β = ½·min_k σ²_q,k/m_w,k ([`crate::defensive_tempering::defensive_tempering`], from ½
//!    down to 0.1), q_β ∝ π·L_s^β, and weighed with the first in the same
//!    mixture (g = (β − 1)·ℓ_s): a defensive proposal that needs no fit, keeps the surrogate's
//!    shape, and caps the weights where the target's tails outreach q's
//!    ([`crate::defensive_tempering`]). It is not held to the batch: its tails are the
//!    surrogate's own. The refused candidates and their reasons are kept with it.
//!
//! Only where the tempered posterior cannot be sampled either does the one step stand, with
//! the reasons kept.
//!
//! The final weights are certified by k̂ over all members (or nearly equal weights), as the one
//! step was; otherwise the stop is [`ModelPosteriorStop::NoisyWeightsTail`]. The evidence ratio
//! Z_m/Z_s is the mean weight (the mixture's density is normalised).

use iuq_core::ParameterSpace;
use iuq_core::random::stream;

use crate::annealing::log_evidence_increment;
use crate::batch_mixture::{log_normalising_ratio, mixture_of_batches};
use crate::defensive_normal::DefensiveNormal;
use crate::defensive_tempering::{TemperedLikelihood, defensive_tempering, tempered_log_ratio};
use crate::error::{BasisError, Result};
use crate::likelihood::LogLikelihood;
use crate::member_selection::nested_selection;
use crate::model_posterior::bridge::MethodInputs;
use crate::model_posterior::members::{
    Best, CorrectedLikelihood, Members, coefficient_of_variation, evaluate, largest_finite,
    log_ratios, outside_batch, recorded_spread_ratio,
};
use crate::model_posterior::records::{
    EventObserver, ModelPosteriorEvent, ModelPosteriorStage, ModelPosteriorStop,
    SurrogateCorrection, SurrogatePopulation, report,
};
use crate::model_posterior::settings::{ModelPosteriorSettings, NEARLY_EQUAL_CV, STREAM_BASE};
use crate::moment_matching::{
    DEFENSIVE_WIDENING, GaussianLogRatio, ProposalMismatch, proposal_mismatch,
};
use crate::pareto_smoothing::{ParetoSmoothing, pareto_k_threshold, pareto_smooth};
use crate::sampler::{Basis, Silent};
use crate::settings::BasisSettings;
use crate::spread_ratio::within_proposal_spread;

/// The weighted members of the pseudo-marginal estimate and how they were reached.
pub(crate) struct NoisyEstimate {
    /// Every member run (both batches after a correction); `surrogate` is the uncorrected ℓ_s.
    pub(crate) members: Members,
    /// The raw log-weights (mixture weights after a correction).
    pub(crate) raw: Vec<f64>,
    pub(crate) smoothing: ParetoSmoothing,
    pub(crate) threshold: f64,
    pub(crate) stop: ModelPosteriorStop,
    pub(crate) stage: ModelPosteriorStage,
    pub(crate) log_evidence_ratio: f64,
    pub(crate) correction: Option<SurrogateCorrection>,
    pub(crate) mismatch: Option<ProposalMismatch>,
    /// Why a correction that was wanted was not made (a clause: "…, but {reason}").
    pub(crate) not_corrected: Option<String>,
    /// Model evaluations of the second batch (0 without a correction).
    pub(crate) evaluations: usize,
    /// Of those, failed runs.
    pub(crate) failures: usize,
}

/// A second batch's proposal q_c ∝ q·e^g, in the order they are tried.
enum Candidate {
    /// The moment-matched log-ratio of the first batch's weights (g a function of θ).
    MomentMatched(GaussianLogRatio),
    /// A normal fitted to the first batch's weights, not multiplied by q
    /// (g = ln N − ln π − ℓ_s, [`crate::defensive_normal`]).
    Normal(DefensiveNormal),
    /// The surrogate's posterior tempered at β (g = (β − 1)·ℓ_s, [`crate::defensive_tempering`]).
    Tempered(f64),
}

impl Candidate {
    /// g at a point θ whose uncorrected surrogate log-likelihood is `surrogate` and log-prior
    /// `prior`.
    fn log_ratio(&self, x: &[f64], surrogate: f64, prior: f64) -> f64 {
        match self {
            Self::MomentMatched(g) => g.log_ratio(x),
            Self::Normal(normal) => normal.log_density(x) - prior - surrogate,
            Self::Tempered(beta) => tempered_log_ratio(*beta, surrogate),
        }
    }

    fn name(&self) -> &'static str {
        match self {
            Self::MomentMatched(_) => "the moment-matched correction",
            Self::Normal(_) => "the defensive normal",
            Self::Tempered(_) => "the defensive tempered batch",
        }
    }
}

/// The second batch's members, drawn from the corrected surrogate's posterior q_c ∝ q·e^g, with
/// their uncorrected ℓ_s, and ln(Z_c/Z_s).
struct CorrectedProposal {
    /// The proposal's whole sample (to check it against the batch).
    population: Vec<Vec<f64>>,
    theta: Vec<Vec<f64>>,
    surrogate: Vec<f64>,
    prior: Vec<f64>,
    log_normalising_ratio: f64,
}

/// A sample of the candidate's q_c at least as large as the surrogate population (BASIS on
/// ℓ_s + g, surrogate evaluations only; or direct draws of the defensive normal, stream
/// (seed, [`STREAM_BASE`], 2), with the surrogate evaluated there), `s` of its members (stream
/// (seed, [`STREAM_BASE`], 1)), and ln(Z_c/Z_s) by bridge sampling between the surrogate
/// population and that sample; `Err`: why the candidate is refused.
fn corrected_proposal(
    space: &ParameterSpace,
    population: SurrogatePopulation<'_>,
    surrogate: &dyn LogLikelihood,
    candidate: &Candidate,
    settings: &ModelPosteriorSettings,
    s: usize,
) -> std::result::Result<CorrectedProposal, String> {
    let n = population.samples.len().max(s);
    let basis_settings = BasisSettings {
        samples: n,
        burn_in: 10,
        seed: settings.seed,
        ..Default::default()
    }
    .check()
    .map_err(|e| e.to_string())?;
    let unsampled = |e: BasisError| format!("its posterior could not be sampled ({e})");
    // (draws, their uncorrected ℓ_s, their log-priors)
    let (samples, uncorrected, priors): (Vec<Vec<f64>>, Vec<f64>, Vec<f64>) = match candidate {
        Candidate::MomentMatched(g) => {
            let corrected = CorrectedLikelihood {
                base: surrogate,
                correction: |x: &[f64]| g.log_ratio(x),
            };
            let state = Basis::new(space, &corrected, basis_settings)
                .and_then(|b| b.run(&mut Silent))
                .map_err(unsampled)?
                .state;
            let ls = state
                .samples
                .iter()
                .zip(&state.log_likelihood)
                .map(|(x, &l)| l - g.log_ratio(x))
                .collect();
            (state.samples, ls, state.log_prior)
        }
        Candidate::Tempered(beta) => {
            let tempered = TemperedLikelihood {
                base: surrogate,
                beta: *beta,
            };
            let state = Basis::new(space, &tempered, basis_settings)
                .and_then(|b| b.run(&mut Silent))
                .map_err(unsampled)?
                .state;
            let ls = state.log_likelihood.iter().map(|l| l / beta).collect();
            (state.samples, ls, state.log_prior)
        }
        Candidate::Normal(normal) => {
            let (draws, priors) = normal
                .sample(space, n, &mut stream(settings.seed, STREAM_BASE, 2))
                .ok_or_else(|| "it lies almost wholly outside the prior's support".to_string())?;
            let ls = evaluate(
                surrogate,
                &draws,
                "the surrogate at the defensive normal's draws",
            )
            .map_err(|e| e.to_string())?;
            if ls.iter().any(|l| !l.is_finite()) {
                return Err("the surrogate has no finite likelihood at some of its draws".into());
            }
            (draws, ls, priors)
        }
    };
    let on_population: Vec<f64> = population
        .samples
        .iter()
        .zip(population.log_likelihood)
        .zip(population.log_prior)
        .map(|((x, &l), &p)| candidate.log_ratio(x, l, p))
        .collect();
    let on_corrected: Vec<f64> = samples
        .iter()
        .zip(&uncorrected)
        .zip(&priors)
        .map(|((x, &l), &p)| candidate.log_ratio(x, l, p))
        .collect();
    let chosen = nested_selection(&mut stream(settings.seed, STREAM_BASE, 1), samples.len(), s);
    let log_normalising_ratio = log_normalising_ratio(&on_population, &on_corrected);
    if !log_normalising_ratio.is_finite() {
        return Err(
            "the ratio of its normalising constant to the surrogate's could not be estimated"
                .into(),
        );
    }
    Ok(CorrectedProposal {
        theta: chosen.iter().map(|&i| samples[i].clone()).collect(),
        surrogate: chosen.iter().map(|&i| uncorrected[i]).collect(),
        prior: chosen.iter().map(|&i| priors[i]).collect(),
        population: samples,
        log_normalising_ratio,
    })
}

/// The pseudo-marginal estimate from the `first` batch (drawn from `population`; `first_failures`
/// of its runs failed), see the module documentation.
pub(crate) fn noisy_estimate(
    inputs: &MethodInputs<'_>,
    population: SurrogatePopulation<'_>,
    first: Members,
    first_failures: usize,
    best: &mut Best,
    observer: &mut EventObserver<'_>,
) -> Result<NoisyEstimate> {
    let settings = inputs.settings;
    let s = first.theta.len();
    let r = log_ratios(&first.model, &first.surrogate);
    if !largest_finite(&r).is_finite() {
        return Err(BasisError::NoFiniteLikelihood {
            stage: 1,
            failures: first_failures,
        });
    }
    let first_smoothing = pareto_smooth(&r);
    let mismatch = if settings.corrections > 0 {
        proposal_mismatch(&first.theta, &first_smoothing.log_weights, settings.seed)
    } else {
        None
    };
    // Correct where the proposal is measurably off, or where the one step would not be
    // certified (a tail the weights cannot carry: the case a correction of the spread helps).
    let tail = first_smoothing.pareto_k > pareto_k_threshold(s)
        && coefficient_of_variation(&r) > NEARLY_EQUAL_CV;
    // A target wider than the batch in some parameter: a tail k̂ underestimates and the
    // permutation test, against the weights' noise, may not find.
    let narrow = !within_proposal_spread(&first.theta, &first_smoothing.log_weights, 1);
    let correct = settings.corrections > 0
        && (tail || narrow || mismatch.as_ref().is_some_and(ProposalMismatch::significant));
    let mut refused = Vec::new();
    let candidates = if correct {
        second_batch_candidates(
            &first.theta,
            &first_smoothing.log_weights,
            settings.seed,
            &mut refused,
        )
    } else {
        Vec::new()
    };
    let accepted = first_accepted(inputs, population, candidates, &first.theta, &mut refused);
    let not_corrected = (correct && accepted.is_none()).then(|| {
        format!(
            "every candidate was refused ({}; a correction was wanted because {})",
            refused.join("; "),
            if tail {
                "the step's k̂ does not hold"
            } else if narrow {
                "the weighted std of a parameter exceeds the batch's by more than the spread ratio's bound"
            } else {
                "the surrogate's posterior is off"
            }
        )
    });
    if let Some(reason) = &not_corrected {
        report(observer, ModelPosteriorEvent::CorrectionNotMade(reason))?;
    }
    let (members, raw, correction, evaluations, failures) = match accepted {
        Some((candidate, proposal)) => {
            let correction = SurrogateCorrection {
                pareto_k_before: first_smoothing.pareto_k,
                cv_before: coefficient_of_variation(&r),
                spread_ratio_before: recorded_spread_ratio(
                    &first.theta,
                    &first_smoothing.log_weights,
                    1,
                ),
                model_evaluations: s,
                quadratic: matches!(candidate, Candidate::MomentMatched(_)),
                moment_matched: matches!(candidate, Candidate::MomentMatched(_)),
                tempering: match candidate {
                    Candidate::Tempered(beta) => Some(beta),
                    _ => None,
                },
                defensive_normal: matches!(candidate, Candidate::Normal(_)),
                refused,
            };
            report(observer, ModelPosteriorEvent::Correction(&correction))?;
            let (members, raw, second_failures) =
                second_batch(inputs.model, first, &candidate, proposal, best)?;
            (members, raw, Some(correction), s, second_failures)
        }
        None => (first, r, None, 0, 0),
    };
    let max_raw = largest_finite(&raw);
    if !max_raw.is_finite() {
        return Err(BasisError::NoFiniteLikelihood {
            stage: 1,
            failures: first_failures + failures,
        });
    }
    let threshold = pareto_k_threshold(raw.len());
    let smoothing = pareto_smooth(&raw);
    let cv = coefficient_of_variation(&raw);
    let stop = if smoothing.pareto_k <= threshold || cv <= NEARLY_EQUAL_CV {
        ModelPosteriorStop::Certified
    } else {
        ModelPosteriorStop::NoisyWeightsTail
    };
    let stage = ModelPosteriorStage::full_step(
        &members.theta,
        if correction.is_some() { 2 } else { 1 },
        &smoothing,
        cv,
        s + evaluations,
        first_failures + failures,
    );
    Ok(NoisyEstimate {
        log_evidence_ratio: log_evidence_increment(&raw, 1.0, max_raw),
        members,
        raw,
        smoothing,
        threshold,
        stop,
        stage,
        correction,
        mismatch,
        not_corrected,
        evaluations,
        failures,
    })
}

/// The candidates for the second batch's proposal, in the order they are tried: the
/// moment-matched correction (where the batch's weights can estimate a covariance; else the
/// reason goes to `refused`), then the defensive normal, then the tempered surrogate posterior,
/// which needs no fit and is not held to the batch (its tails are the surrogate's own, raised).
fn second_batch_candidates(
    theta: &[Vec<f64>],
    log_weights: &[f64],
    seed: u64,
    refused: &mut Vec<String>,
) -> Vec<Candidate> {
    let mut candidates = Vec::new();
    match GaussianLogRatio::fit(theta, log_weights, DEFENSIVE_WIDENING, seed) {
        Some(g) => candidates.push(Candidate::MomentMatched(g)),
        None => refused.push(
            "the moment-matched correction: the first batch's weights have too few effective members to estimate a covariance".to_string(),
        ),
    }
    if let Some(normal) = DefensiveNormal::fit(theta, log_weights) {
        candidates.push(Candidate::Normal(normal));
    }
    candidates.push(Candidate::Tempered(defensive_tempering(theta, log_weights)));
    candidates
}

/// The first of `candidates` whose proposal can be drawn (and, for the moment-matched
/// correction, whose posterior stays within the `first_theta` batch), with that proposal; the
/// reasons the others were refused go to `refused`.
fn first_accepted(
    inputs: &MethodInputs<'_>,
    population: SurrogatePopulation<'_>,
    candidates: Vec<Candidate>,
    first_theta: &[Vec<f64>],
    refused: &mut Vec<String>,
) -> Option<(Candidate, CorrectedProposal)> {
    let MethodInputs {
        space,
        surrogate,
        settings,
        ..
    } = *inputs;
    let s = first_theta.len();
    for candidate in candidates {
        match corrected_proposal(space, population, surrogate, &candidate, settings, s) {
            Ok(proposal) => {
                let held = matches!(candidate, Candidate::MomentMatched(_));
                if let Some(why) = held
                    .then(|| outside_batch(space, &proposal.population, first_theta))
                    .flatten()
                {
                    refused.push(format!("{}: its posterior {why}", candidate.name()));
                    continue;
                }
                return Some((candidate, proposal));
            }
            Err(why) => refused.push(format!("{}: {why}", candidate.name())),
        }
    }
    None
}

/// Runs the model at the second batch drawn from `candidate`'s `proposal` and weighs it with
/// the `first` as one sample of their even mixture: the members, their raw log-weights and the
/// second batch's failed runs.
fn second_batch(
    model: &dyn LogLikelihood,
    first: Members,
    candidate: &Candidate,
    proposal: CorrectedProposal,
    best: &mut Best,
) -> Result<(Members, Vec<f64>, usize)> {
    let second = Members {
        model: evaluate(
            model,
            &proposal.theta,
            "the model at the second batch's samples (the corrected or tempered surrogate's posterior)",
        )?,
        theta: proposal.theta,
        surrogate: proposal.surrogate,
        prior: proposal.prior,
    };
    let second_failures = second.model.iter().filter(|v| !v.is_finite()).count();
    best.offer(&second.theta, &second.model, &second.prior);
    let (members, raw) = mixture_of_batches(
        first,
        second,
        &|x: &[f64], ls: f64, lp: f64| candidate.log_ratio(x, ls, lp),
        proposal.log_normalising_ratio,
    );
    Ok((members, raw, second_failures))
}
