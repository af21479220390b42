//! Where the first batch's weights do not hold in one stage, a correction of the surrogate
//! (the module documentation of [`super`], step 2): a least-squares quadratic fit of the
//! log-ratios r = ℓ_m − ℓ_s over the batch, or else a moment-matched Gaussian log-ratio, whose
//! corrected surrogate's posterior (sampled by BASIS) gives a second batch; both batches then
//! weigh as one sample of their even mixture ([`crate::batch_mixture`]). A correction whose
//! posterior lies mostly outside the first batch's range is refused, with the reason.

use iuq_core::random::stream;

use super::bridge::MethodInputs;
use super::members::{
    BoxedCorrection, CorrectedLikelihood, Members, coefficient_of_variation, evaluate,
    largest_finite, log_ratios, outside_batch, recorded_spread_ratio,
};
use super::records::{
    EventObserver, ModelPosteriorEvent, SurrogateCorrection, SurrogatePopulation, report,
};
use super::settings::{NEARLY_EQUAL_CV, STREAM_BASE};
use crate::annealing::next_step;
use crate::batch_mixture::{log_normalising_ratio, mixture_of_batches};
use crate::error::Result;
use crate::member_selection::nested_selection;
use crate::moment_matching::{DEFENSIVE_WIDENING, GaussianLogRatio};
use crate::pareto_smoothing::pareto_smooth;
use crate::quadratic_regression::QuadraticFit;
use crate::sampler::{Basis, BasisState, Silent};
use crate::settings::{BasisSettings, CheckedSettings};
use crate::spread_ratio::within_proposal_spread;

/// The first batch as the stages start from it.
pub(super) enum FirstBatch<'a> {
    /// No correction: the batch holds in one stage, or every correction was refused (the
    /// reason).
    Kept { not_corrected: Option<String> },
    /// The surrogate corrected, and the second batch drawn from its posterior.
    Corrected(Box<CorrectedBatch<'a>>),
}

/// A correction that was made.
pub(super) struct CorrectedBatch<'a> {
    /// What was corrected and why.
    pub(super) record: SurrogateCorrection,
    /// The corrected surrogate's log-likelihood.
    pub(super) likelihood: CorrectedLikelihood<'a, BoxedCorrection>,
    /// ln(Z_corrected/Z_surrogate), from the corrected surrogate's BASIS run.
    pub(super) log_evidence_ratio: f64,
    /// The second batch, with the corrected surrogate's log-likelihoods.
    pub(super) batch: Members,
    /// Both batches as one sample of the even mixture, with their raw log-weights.
    pub(super) mixture: (Members, Vec<f64>),
}

/// Correct the surrogate where the `first` batch (its model log-likelihoods evaluated) does
/// not hold in one stage at the k̂ `threshold` (module docs).
pub(super) fn correct_first_batch<'a>(
    inputs: &MethodInputs<'a>,
    population: &SurrogatePopulation<'_>,
    first: Members,
    threshold: f64,
    observer: &mut EventObserver<'_>,
) -> Result<FirstBatch<'a>> {
    let settings = inputs.settings;
    let n = population.samples.len();
    let (theta, s) = (&first.theta, first.theta.len());
    let r: Vec<f64> = log_ratios(&first.model, &first.surrogate);
    if holds_in_one_stage(theta, &r, settings.cv_target, threshold) {
        return Ok(FirstBatch::Kept {
            not_corrected: None,
        });
    }
    let candidates = candidate_corrections(theta, &r, settings.seed);
    let basis_settings = BasisSettings {
        samples: n.max(s),
        burn_in: 10,
        seed: settings.seed,
        ..Default::default()
    }
    .check()?;
    let mut refused = Vec::new();
    let accepted = first_within_batch(inputs, theta, candidates, basis_settings, &mut refused);
    match accepted {
        Some((mut record, candidate, state)) => {
            record.refused = refused;
            report(observer, ModelPosteriorEvent::Correction(&record))?;
            let corrected = second_batch(inputs, population, first, record, candidate, state)?;
            Ok(FirstBatch::Corrected(Box::new(corrected)))
        }
        None if !refused.is_empty() => {
            let reason = format!(
                "{}; the stages go on from the first batch",
                refused.join("; ")
            );
            report(observer, ModelPosteriorEvent::CorrectionNotMade(&reason))?;
            Ok(FirstBatch::Kept {
                not_corrected: Some(reason),
            })
        }
        None => Ok(FirstBatch::Kept {
            not_corrected: None,
        }),
    }
}

/// Whether the batch's log-ratios `r` reach β = 1 in one step whose k̂ holds at `threshold`
/// (or whose weights are nearly equal) within the batch's spread: no correction needed.
fn holds_in_one_stage(theta: &[Vec<f64>], r: &[f64], cv_target: f64, threshold: f64) -> bool {
    let max_r = largest_finite(r);
    max_r.is_finite() && {
        let rule = next_step(r, 0.0, cv_target, max_r);
        let smoothing = pareto_smooth(r);
        rule.reaches_one
            && (smoothing.pareto_k <= threshold || coefficient_of_variation(r) <= NEARLY_EQUAL_CV)
            && within_proposal_spread(theta, &smoothing.log_weights, 1)
    }
}

/// The corrections to try, in order, each with its record: the least-squares fit of the
/// log-ratios `r` over the batch `theta`, then the moment-matched Gaussian log-ratio (each
/// where it can be fitted).
fn candidate_corrections(
    theta: &[Vec<f64>],
    r: &[f64],
    seed: u64,
) -> Vec<(SurrogateCorrection, BoxedCorrection)> {
    let smoothing = pareto_smooth(r);
    let record = |quadratic: bool, moment_matched: bool| SurrogateCorrection {
        pareto_k_before: smoothing.pareto_k,
        cv_before: coefficient_of_variation(r),
        spread_ratio_before: recorded_spread_ratio(theta, &smoothing.log_weights, 1),
        model_evaluations: theta.len(),
        quadratic,
        moment_matched,
        tempering: None,
        defensive_normal: false,
        refused: Vec::new(),
    };
    let mut candidates: Vec<(SurrogateCorrection, BoxedCorrection)> = Vec::new();
    if let Some(fit) = QuadraticFit::fit(theta, r) {
        candidates.push((
            record(fit.is_quadratic(), false),
            Box::new(move |x: &[f64]| fit.predict(x)),
        ));
    }
    if let Some(g) = GaussianLogRatio::fit(theta, &smoothing.log_weights, DEFENSIVE_WIDENING, seed)
    {
        candidates.push((
            record(true, true),
            Box::new(move |x: &[f64]| g.log_ratio(x)),
        ));
    }
    candidates
}

/// The first of `candidates` whose corrected surrogate's posterior BASIS samples and which
/// stays within the batch `theta`'s range, with that sample; the reasons the others were
/// refused go to `refused`.
fn first_within_batch<'a>(
    inputs: &MethodInputs<'a>,
    theta: &[Vec<f64>],
    candidates: Vec<(SurrogateCorrection, BoxedCorrection)>,
    basis_settings: CheckedSettings,
    refused: &mut Vec<String>,
) -> Option<(
    SurrogateCorrection,
    CorrectedLikelihood<'a, BoxedCorrection>,
    BasisState,
)> {
    let MethodInputs {
        space, surrogate, ..
    } = *inputs;
    for (record, correction) in candidates {
        let kind = if record.moment_matched {
            "the moment-matched correction"
        } else {
            "the least-squares fit of r"
        };
        let candidate = CorrectedLikelihood {
            base: surrogate,
            correction,
        };
        let state =
            match Basis::new(space, &candidate, basis_settings).and_then(|b| b.run(&mut Silent)) {
                Ok(run) => run.state,
                Err(e) => {
                    refused.push(format!("{kind}: its posterior could not be sampled ({e})"));
                    continue;
                }
            };
        if let Some(why) = outside_batch(space, &state.samples, theta) {
            refused.push(format!("{kind}: its posterior {why}"));
            continue;
        }
        return Some((record, candidate, state));
    }
    None
}

/// The second batch: members of the corrected surrogate's posterior `state` run through the
/// model, and both batches weighed as one sample of their even mixture.
fn second_batch<'a>(
    inputs: &MethodInputs<'a>,
    population: &SurrogatePopulation<'_>,
    first: Members,
    record: SurrogateCorrection,
    candidate: CorrectedLikelihood<'a, BoxedCorrection>,
    state: BasisState,
) -> Result<CorrectedBatch<'a>> {
    let settings = inputs.settings;
    let s = first.theta.len();
    let log_evidence_ratio = state.log_evidence - population.log_evidence;
    let chosen = nested_selection(
        &mut stream(settings.seed, STREAM_BASE, 1),
        state.samples.len(),
        s,
    );
    let theta: Vec<Vec<f64>> = chosen.iter().map(|&i| state.samples[i].clone()).collect();
    let ls: Vec<f64> = chosen.iter().map(|&i| state.log_likelihood[i]).collect();
    let lp: Vec<f64> = chosen.iter().map(|&i| state.log_prior[i]).collect();
    let lm = evaluate(
        inputs.model,
        &theta,
        "the model at the corrected surrogate's posterior samples",
    )?;
    let g = |x: &[f64]| (candidate.correction)(x);
    let on_population: Vec<f64> = population.samples.iter().map(|x| g(x)).collect();
    let on_corrected: Vec<f64> = state.samples.iter().map(|x| g(x)).collect();
    let second = Members {
        theta: theta.clone(),
        surrogate: theta.iter().zip(&ls).map(|(x, l)| l - g(x)).collect(),
        model: lm.clone(),
        prior: lp.clone(),
    };
    let mixture = mixture_of_batches(
        first,
        second,
        &|x: &[f64], _, _| g(x),
        log_normalising_ratio(&on_population, &on_corrected),
    );
    Ok(CorrectedBatch {
        record,
        likelihood: candidate,
        log_evidence_ratio,
        batch: Members {
            theta,
            surrogate: ls,
            model: lm,
            prior: lp,
        },
        mixture,
    })
}
