//! The bridge between two tempering stages of the model posterior: resample the members by
//! the stage's weights, then move each copy by delayed-acceptance Metropolis–Hastings at the new
//! β — a subchain on the (corrected) surrogate screens every step, the model confirms where the
//! subchain ended (Christen & Fox 2005), so that most rejected proposals cost no model run. The
//! moves' target is π(θ)·L_s(θ)·(L_m/L_s)^β; the surrogate's subchain targets
//! π·L_s·e^{β·r̂(θ)}, r̂ a quadratic fit of the members' log-ratios r = ℓ_m − ℓ_s (zero where it
//! cannot be fitted), so that the screen already leans towards the model.

use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;

use iuq_core::ParameterSpace;

use super::members::{Best, Members, evaluate};
use super::settings::{ModelPosteriorSettings, STREAM_BASE};
use crate::error::Result;
use crate::likelihood::LogLikelihood;
use crate::pareto_smoothing::normalised_weights;
use crate::proposal::Proposal;
use crate::quadratic_regression::QuadraticFit;
use crate::resampling::resample;
use crate::settings::Resampling;
use iuq_core::random::StreamRng;
use iuq_core::random::stream;

/// What the method's steps read besides the members: the space, both likelihoods and the
/// settings.
pub(crate) struct MethodInputs<'a> {
    pub(crate) space: &'a ParameterSpace,
    pub(crate) surrogate: &'a dyn LogLikelihood,
    pub(crate) model: &'a dyn LogLikelihood,
    pub(crate) settings: &'a ModelPosteriorSettings,
    /// The prior ranges' widths (the proposal's scale where the members have no spread).
    pub(crate) widths: &'a [f64],
}

/// The stage a bridge follows: its number, the β it stepped to, the members' log-ratios
/// r = ℓ_m − ℓ_s and the stage's log-weights.
pub(super) struct StageWeights<'a> {
    pub(super) stage: usize,
    pub(super) beta: f64,
    pub(super) log_ratios: &'a [f64],
    pub(super) log_weights: &'a [f64],
}

/// What a bridge's moves cost and how often they moved.
pub(super) struct BridgeMoves {
    /// Model evaluations (the confirmations).
    pub(super) evaluations: usize,
    /// Confirmations whose model run failed.
    pub(super) failures: usize,
    /// Share of the surrogate's proposals the screen accepted.
    pub(super) screen_acceptance: f64,
    /// Share of the screened subchains' ends the model confirmed.
    pub(super) confirm_acceptance: f64,
}

impl MethodInputs<'_> {
    /// The bridge after stage `weights.stage`: resample `members` by the stage's weights and
    /// move them; `members` and each member's `ancestor` are replaced by the moved population,
    /// and every model evaluation is offered to `best`.
    pub(super) fn bridge(
        &self,
        weights: &StageWeights<'_>,
        members: &mut Members,
        ancestor: &mut Vec<usize>,
        best: &mut Best,
    ) -> Result<BridgeMoves> {
        let (space, settings, widths) = (self.space, self.settings, self.widths);
        let StageWeights {
            stage,
            beta,
            log_ratios: r,
            log_weights,
        } = *weights;
        let d = space.dimension();
        let s = members.theta.len();
        let stage_key = STREAM_BASE + stage as u64;
        let weights = normalised_weights(log_weights);
        let proposal = Proposal::new(&members.theta, &weights, settings.scale, widths)?;
        let discrepancy = QuadraticFit::fit(&members.theta, r);
        let correction = |x: &[f64]| discrepancy.as_ref().map_or(0.0, |f| beta * f.predict(x));
        let mut resampling_rng =
            stream(settings.seed, stage_key, crate::sampler::RESAMPLING_STREAM);
        let counts = resample(&weights, s, Resampling::Multinomial, &mut resampling_rng);
        let mut chains: Vec<Chain> = Vec::with_capacity(s);
        let mut descent: Vec<usize> = Vec::with_capacity(s);
        for (i, &c) in counts.iter().enumerate() {
            for _ in 0..c {
                descent.push(ancestor[i]);
                let index = chains.len() as u64;
                chains.push(Chain {
                    theta: members.theta[i].clone(),
                    surrogate: members.surrogate[i],
                    model: members.model[i],
                    prior: members.prior[i],
                    rng: stream(settings.seed, stage_key, index),
                });
            }
        }
        let (mut screened, mut screen_accepted) = (0usize, 0usize);
        let (mut confirmed, mut confirm_accepted, mut confirm_failed) = (0usize, 0usize, 0usize);
        for _ in 0..settings.moves {
            // The surrogate subchain of every chain, one batch per step.
            // (θ, ℓ_s, ln π, β·r̂) at each subchain's position.
            let mut ends: Vec<(Vec<f64>, f64, f64, f64)> = chains
                .iter()
                .map(|c| (c.theta.clone(), c.surrogate, c.prior, correction(&c.theta)))
                .collect();
            for _ in 0..settings.subchain {
                let proposals: Vec<(Vec<f64>, f64)> = chains
                    .par_iter_mut()
                    .zip(&ends)
                    .map(|(chain, (at, _, _, _))| {
                        let z: Vec<f64> = (0..d)
                            .map(|_| StandardNormal.sample(&mut chain.rng))
                            .collect();
                        let u: f64 = chain.rng.random();
                        (proposal.step(at, &z), u)
                    })
                    .collect();
                let inside: Vec<usize> = (0..chains.len())
                    .filter(|&c| space.in_support(&proposals[c].0))
                    .collect();
                let points: Vec<Vec<f64>> =
                    inside.iter().map(|&c| proposals[c].0.clone()).collect();
                let values = evaluate(self.surrogate, &points, "the surrogate in a bridge")?;
                screened += chains.len();
                for (&c, v) in inside.iter().zip(values) {
                    let prior = space
                        .log_prior(&proposals[c].0)
                        .unwrap_or(f64::NEG_INFINITY);
                    let (_, ls_at, lp_at, rc_at) = &ends[c];
                    let rc = correction(&proposals[c].0);
                    let log_ratio = (v + prior + rc) - (ls_at + lp_at + rc_at);
                    if v.is_finite() && prior.is_finite() && proposals[c].1.ln() < log_ratio {
                        ends[c] = (proposals[c].0.clone(), v, prior, rc);
                        screen_accepted += 1;
                    }
                }
            }
            // The model confirms the subchains that moved, in one batch.
            let confirm_u: Vec<f64> = chains.iter_mut().map(|c| c.rng.random()).collect();
            let moved: Vec<usize> = (0..chains.len())
                .filter(|&c| ends[c].0 != chains[c].theta)
                .collect();
            let points: Vec<Vec<f64>> = moved.iter().map(|&c| ends[c].0.clone()).collect();
            let values = evaluate(self.model, &points, "the model in a bridge")?;
            confirmed += points.len();
            best.offer(
                &points,
                &values,
                &moved.iter().map(|&c| ends[c].2).collect::<Vec<_>>(),
            );
            for (&c, v) in moved.iter().zip(values) {
                if !v.is_finite() {
                    confirm_failed += 1;
                    continue;
                }
                let (at, ls_at, lp_at, rc_at) = &ends[c];
                let chain = &chains[c];
                let log_ratio = (beta * (v - ls_at) - rc_at)
                    - (beta * (chain.model - chain.surrogate) - correction(&chain.theta));
                if confirm_u[c].ln() < log_ratio {
                    let chain = &mut chains[c];
                    chain.theta = at.clone();
                    chain.surrogate = *ls_at;
                    chain.prior = *lp_at;
                    chain.model = v;
                    confirm_accepted += 1;
                }
            }
        }
        *ancestor = descent;
        members.theta = chains.iter().map(|c| c.theta.clone()).collect();
        members.surrogate = chains.iter().map(|c| c.surrogate).collect();
        members.model = chains.iter().map(|c| c.model).collect();
        members.prior = chains.iter().map(|c| c.prior).collect();
        Ok(BridgeMoves {
            evaluations: confirmed,
            failures: confirm_failed,
            screen_acceptance: screen_accepted as f64 / screened.max(1) as f64,
            confirm_acceptance: confirm_accepted as f64 / confirmed.max(1) as f64,
        })
    }
}

/// One chain's state in a bridge.
struct Chain {
    theta: Vec<f64>,
    surrogate: f64,
    model: f64,
    prior: f64,
    rng: StreamRng,
}
