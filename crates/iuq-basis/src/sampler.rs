//! The BASIS sampler (docs/methods.md §5; Wu et al. 2017, "A Bayesian annealed sequential
//! importance sampling"; Ching & Chen 2007, TMCMC).
//!
//! The run is a sequence of stages, each a pure function of the previous [`BasisState`], so it
//! can be driven step by step ([`Basis::initialise`], [`Basis::advance`]), run to the end with an
//! [`Observer`] called after every stage ([`Basis::run`]), or resumed from a checkpoint
//! ([`Basis::resume`]).
//!
//! 1. Stage 0: N prior draws θ_i (member i from stream (seed, SAMPLER_BASE + 0, i)), ll_i, lp_i;
//!    p = 0, ln Z = 0.
//! 2. Stage k ≥ 1 from p < 1: the step dp solved from the CV target ([`crate::annealing`]),
//!    p' = p + dp (exactly 1 when the CV of the full step is within the target); ln Z += ln
//!    E[f^dp]; normalised weights w̄ ∝ f^dp; proposal covariance β²·Cov_w̄(θ)
//!    ([`crate::proposal`]); copy counts n_i ([`crate::resampling`], stream (seed,
//!    SAMPLER_BASE + k, [`RESAMPLING_STREAM`])); member i seeds ⌈n_i/l_max⌉ chains of
//!    near-equal lengths summing to n_i; chain c (in member order) draws from stream (seed,
//!    SAMPLER_BASE + k, c) and runs n_burn discarded steps then its length (with
//!    [`Mixing::Adaptive`] the scale β comes from the previous stage's acceptance rate and
//!    n_burn is the first step count after which no parameter's correlation between the chains'
//!    starts and states exceeds the target); each step proposes
//!    θ' = θ + L z, rejects θ' outside the prior support without evaluating it, and accepts with
//!    ln u < p'(ll' − ll) + (lp' − lp); a failed or non-finite evaluation is a rejection. Every
//!    state after a post-burn-in step is a member of the new population (chain by chain, in
//!    chain order); the seed itself is not.
//! 3. When a stage starts at p = 1 it is the final pass (dp = 0, uniform weights, ln Z
//!    unchanged); after it the run stops with [`StopReason::Converged`].
//!
//! Every MCMC step of every chain is one point of a single batch sent to
//! [`LogLikelihood::log_likelihood_batch`]: one batch for stage 0 and one per MCMC step.
//! Everything random is keyed by (seed, stage, chain) and every reduction is sequential, so the
//! result does not depend on the number of rayon threads, and a run resumed from the state after
//! stage k is bit-identical to an uninterrupted one.

use std::collections::{BTreeMap, HashSet};
use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use iuq_core::ParameterSpace;
use iuq_core::normal::quantile;
use iuq_core::random::{stages::SAMPLER_BASE, stream};

use crate::annealing::{incremental_weights, log_evidence_increment, max_finite, next_step};
use crate::diagnostics::{StageDiagnostics, count_failure, merge_failure_reasons};
use crate::error::{BasisError, Result};
use crate::likelihood::{LogLikelihood, PointLogLikelihood};
use crate::proposal::Proposal;
use crate::settings::{CheckedSettings, MinStepAction, Mixing};

/// The stream index (within a stage) of the resampling draws; chains use 0, 1, 2, ….
pub const RESAMPLING_STREAM: u64 = u64::MAX;

/// Why a run stopped.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum StopReason {
    /// p reached 1 and the final resample-and-move pass at p = 1 is done: the population is a
    /// sample of the posterior.
    Converged,
    /// `max_stages` annealing stages were run without reaching p = 1; the population samples
    /// the tempered posterior at `exponent`, and the evidence is incomplete.
    MaxStages {
        /// The limit.
        max_stages: usize,
        /// The exponent reached.
        exponent: f64,
    },
    /// The step solved from the CV target was below the minimum (with
    /// [`MinStepAction::Stop`]); no stage was run for it.
    StepBelowMinimum {
        /// The solved step.
        step: f64,
        /// The minimum.
        min_step: f64,
        /// The exponent reached.
        exponent: f64,
    },
    /// The observer stopped the run after stage `stage`; the state can be resumed.
    Interrupted {
        /// The last completed stage.
        stage: usize,
    },
}

impl StopReason {
    /// A short machine-readable name: `converged`, `max_stages`, `step_below_minimum`,
    /// `interrupted`.
    pub fn name(&self) -> &'static str {
        match self {
            StopReason::Converged => "converged",
            StopReason::MaxStages { .. } => "max_stages",
            StopReason::StepBelowMinimum { .. } => "step_below_minimum",
            StopReason::Interrupted { .. } => "interrupted",
        }
    }
}

impl std::fmt::Display for StopReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StopReason::Converged => {
                f.write_str("converged: p reached 1 and the final pass at p = 1 is done")
            }
            StopReason::MaxStages {
                max_stages,
                exponent,
            } => write!(
                f,
                "stopped: the maximum of {max_stages} stages was reached at p = {exponent} (the evidence is incomplete)"
            ),
            StopReason::StepBelowMinimum {
                step,
                min_step,
                exponent,
            } => write!(
                f,
                "stopped: the annealing step {step:e} solved at p = {exponent} is below the minimum {min_step:e}"
            ),
            StopReason::Interrupted { stage } => {
                write!(f, "interrupted after stage {stage} (resumable)")
            }
        }
    }
}

/// The complete state of a run after a stage: enough to continue it bit-identically (the stage
/// index is the position of every random stream). Serialised by [`crate::checkpoint`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BasisState {
    /// Names of the sampled parameters, in order (the model's, then `sigma_m` if estimated).
    pub parameter_names: Vec<String>,
    /// The settings of the run (with the seed).
    pub settings: CheckedSettings,
    /// Index of the last completed stage (0 = prior draws).
    pub stage: usize,
    /// The annealing exponent p of the population.
    pub exponent: f64,
    /// ln Z accumulated so far (the evidence once p = 1).
    pub log_evidence: f64,
    /// The population θ_i, N vectors.
    pub samples: Vec<Vec<f64>>,
    /// ln f(D | θ_i); −∞ (`null` in JSON) for failed members, which only stage 0 can hold.
    #[serde(with = "crate::json_numbers::negative_infinity_as_null")]
    pub log_likelihood: Vec<f64>,
    /// ln π(θ_i).
    pub log_prior: Vec<f64>,
    /// Points sent to the likelihood (model evaluations) over all stages.
    pub evaluations: usize,
    /// Diagnostics of every stage so far, stage 0 first.
    pub diagnostics: Vec<StageDiagnostics>,
    /// Why the run finished (`None` while it can be advanced).
    pub stop_reason: Option<StopReason>,
}

impl BasisState {
    /// True when the run has finished and cannot be advanced.
    pub fn is_finished(&self) -> bool {
        self.stop_reason.is_some()
    }

    /// Failures over all stages.
    pub fn failures(&self) -> usize {
        self.diagnostics.iter().map(|d| d.failures).sum()
    }

    /// Failures over all stages, by reason.
    pub fn failure_reasons(&self) -> BTreeMap<String, usize> {
        merge_failure_reasons(self.diagnostics.iter().map(|d| &d.failure_reasons))
    }

    /// Proposals outside the prior support over all stages.
    pub fn out_of_support(&self) -> usize {
        self.diagnostics.iter().map(|d| d.out_of_support).sum()
    }

    /// Number of stages after the prior stage (annealing stages and the final pass).
    pub fn stages(&self) -> usize {
        self.stage
    }
}

/// Whether to go on after a stage: iuq's one control answer ([`iuq_core::observer`]); `Stop`
/// ends the run with [`StopReason::Interrupted`] (unless it had finished anyway).
pub use iuq_core::Control;

/// The observer of a run is iuq's one observer shape ([`iuq_core::observer`]): an
/// `Observer<BasisState>` is called with the state after every stage (stage 0 included) — to
/// report progress, write a checkpoint, or stop the run (in the manner of argmin's observers).
/// Any `FnMut(&BasisState) -> Control` is one. An observer whose own work fails (a checkpoint it
/// cannot write) keeps its error and answers [`Control::Stop`]; whoever owns it returns the error
/// once the run has stopped.
pub use iuq_core::Observer;

/// An observer that never stops the run and reports nothing.
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl Observer<BasisState> for Silent {
    fn observe(&mut self, _: &BasisState) -> Control {
        Control::Continue
    }
}

/// The end of a run: the last state and why it stopped.
#[derive(Debug, Clone, PartialEq)]
pub struct BasisRun {
    /// The state after the last completed stage.
    pub state: BasisState,
    /// Why the run stopped.
    pub stop_reason: StopReason,
}

/// The BASIS sampler of a posterior π(θ)·f(D|θ) over `space`.
pub struct Basis<'a, L: ?Sized> {
    space: &'a ParameterSpace,
    likelihood: &'a L,
    settings: CheckedSettings,
    widths: Vec<f64>,
}

impl<'a, L: LogLikelihood + ?Sized> Basis<'a, L> {
    /// A sampler for the prior of `space` and `likelihood` (which must take as many parameters as
    /// `space` has), with checked settings.
    pub fn new(
        space: &'a ParameterSpace,
        likelihood: &'a L,
        settings: CheckedSettings,
    ) -> Result<Self> {
        if likelihood.parameter_count() != space.dimension() {
            return Err(BasisError::InvalidLikelihood(format!(
                "the likelihood takes {} parameters but the parameter space has {} ({})",
                likelihood.parameter_count(),
                space.dimension(),
                space.names().join(", ")
            )));
        }
        let widths = space.ranges().iter().map(|(lo, hi)| hi - lo).collect();
        Ok(Self {
            space,
            likelihood,
            settings,
            widths,
        })
    }

    /// The settings.
    pub fn settings(&self) -> &CheckedSettings {
        &self.settings
    }

    /// Run from the prior to the end, calling `observer` after every stage.
    pub fn run(&self, observer: &mut dyn Observer<BasisState>) -> Result<BasisRun> {
        let state = self.initialise()?;
        if observer.observe(&state) == Control::Stop && !state.is_finished() {
            return Ok(BasisRun {
                stop_reason: StopReason::Interrupted { stage: state.stage },
                state,
            });
        }
        self.continue_run(state, observer)
    }

    /// Continue a run from a state (e.g. read from a checkpoint), calling `observer` after every
    /// new stage. The state must come from a run with the same settings and parameters.
    pub fn resume(
        &self,
        state: BasisState,
        observer: &mut dyn Observer<BasisState>,
    ) -> Result<BasisRun> {
        self.check_compatible(&state)?;
        self.continue_run(state, observer)
    }

    fn continue_run(
        &self,
        mut state: BasisState,
        observer: &mut dyn Observer<BasisState>,
    ) -> Result<BasisRun> {
        loop {
            if let Some(reason) = &state.stop_reason {
                return Ok(BasisRun {
                    stop_reason: reason.clone(),
                    state,
                });
            }
            state = self.advance(state)?;
            if observer.observe(&state) == Control::Stop && !state.is_finished() {
                return Ok(BasisRun {
                    stop_reason: StopReason::Interrupted { stage: state.stage },
                    state,
                });
            }
        }
    }

    /// Check that `state` belongs to a run of this sampler (settings, parameter names,
    /// population size and support).
    pub fn check_compatible(&self, state: &BasisState) -> Result<()> {
        let mismatch = |m: String| Err(BasisError::CheckpointMismatch(m));
        if state.settings != self.settings {
            return mismatch(format!(
                "settings differ: {}",
                settings_differences(&state.settings, &self.settings)
            ));
        }
        if state.parameter_names != self.space.names() {
            return mismatch(format!(
                "the checkpoint's parameters ({}) differ from this run's ({})",
                state.parameter_names.join(", "),
                self.space.names().join(", ")
            ));
        }
        let n = self.settings.samples;
        if state.samples.len() != n || state.log_likelihood.len() != n || state.log_prior.len() != n
        {
            return mismatch(format!(
                "the checkpoint holds {} samples, {} log-likelihoods and {} log-priors; {n} expected",
                state.samples.len(),
                state.log_likelihood.len(),
                state.log_prior.len()
            ));
        }
        if let Some(i) = state.samples.iter().position(|x| !self.space.in_support(x)) {
            return mismatch(format!(
                "sample {i} lies outside the prior support of this run"
            ));
        }
        Ok(())
    }

    /// Evaluate a batch, turning failures and non-finite values into −∞ with a counted reason.
    pub(crate) fn evaluate(
        &self,
        stage: usize,
        points: &[Vec<f64>],
        reasons: &mut BTreeMap<String, usize>,
        failures: &mut usize,
    ) -> Result<Vec<f64>> {
        if points.is_empty() {
            return Ok(Vec::new());
        }
        let values = self.likelihood.log_likelihood_batch(points);
        self.finite_or_failure(stage, points.len(), values, reasons, failures)
    }

    /// A batch's log-likelihoods with failures and non-finite values as −∞, each counted with
    /// its reason.
    fn finite_or_failure(
        &self,
        stage: usize,
        count: usize,
        values: Result<Vec<PointLogLikelihood>>,
        reasons: &mut BTreeMap<String, usize>,
        failures: &mut usize,
    ) -> Result<Vec<f64>> {
        let values = values.map_err(|e| match e {
            BasisError::ModelBatch(reason) => BasisError::Evaluation { stage, reason },
            other => other,
        })?;
        if values.len() != count {
            return Err(BasisError::Evaluation {
                stage,
                reason: format!(
                    "the likelihood returned {} values for {count} points",
                    values.len(),
                ),
            });
        }
        Ok(values
            .into_iter()
            .map(|v: PointLogLikelihood| match v {
                Ok(ll) if ll.is_finite() => ll,
                Ok(ll) => {
                    *failures += 1;
                    count_failure(reasons, &format!("log-likelihood is {ll}"));
                    f64::NEG_INFINITY
                }
                Err(failure) => {
                    *failures += 1;
                    count_failure(reasons, &failure.reason);
                    f64::NEG_INFINITY
                }
            })
            .collect())
    }

    /// Stage 0: N draws from the prior and their log-likelihoods (one batch).
    pub fn initialise(&self) -> Result<BasisState> {
        let start = Instant::now();
        let n = self.settings.samples;
        let seed = self.settings.seed;
        let stage_key = SAMPLER_BASE;
        let samples: Vec<Vec<f64>> = (0..n)
            .into_par_iter()
            .with_min_len(256)
            .map(|i| self.space.sample(&mut stream(seed, stage_key, i as u64)))
            .collect();
        let log_prior = samples
            .iter()
            .map(|x| self.space.log_prior(x))
            .collect::<iuq_core::Result<Vec<f64>>>()?;
        let mut reasons = BTreeMap::new();
        let mut failures = 0;
        let log_likelihood = self.evaluate(0, &samples, &mut reasons, &mut failures)?;
        let max_ll = max_finite(&log_likelihood)
            .ok_or(BasisError::NoFiniteLikelihood { stage: 0, failures })?;
        let diagnostics = StageDiagnostics {
            stage: 0,
            exponent: 0.0,
            step: 0.0,
            cv: 0.0,
            ess_fraction: 1.0,
            step_clamped: false,
            bisection_iterations: 0,
            log_evidence_increment: 0.0,
            log_evidence: 0.0,
            max_log_likelihood: max_ll,
            covariance: None,
            chains: 0,
            proposals: 0,
            accepted: 0,
            proposal_scale: 0.0,
            burn_in: 0,
            start_correlation: 0.0,
            acceptance_rate: 0.0,
            out_of_support: 0,
            failures,
            failure_reasons: reasons,
            evaluations: n,
            batches: 1,
            screenings: 0,
            screened_out: 0,
            unique_fraction: unique_fraction(&samples),
            wall_seconds: start.elapsed().as_secs_f64(),
        };
        Ok(BasisState {
            parameter_names: self.space.names(),
            settings: self.settings,
            stage: 0,
            exponent: 0.0,
            log_evidence: 0.0,
            samples,
            log_likelihood,
            log_prior,
            evaluations: n,
            diagnostics: vec![diagnostics],
            stop_reason: None,
        })
    }

    /// Run the next stage from `state` (BASIS steps 2–7, docs/methods.md §5). A state whose step
    /// would be below the minimum (with [`MinStepAction::Stop`]) comes back finished, with no new
    /// stage. The state is checked first ([`Basis::check_compatible`]).
    pub fn advance(&self, mut state: BasisState) -> Result<BasisState> {
        if let Some(reason) = &state.stop_reason {
            return Err(BasisError::AlreadyFinished(reason.to_string()));
        }
        self.check_compatible(&state)?;
        let start = Instant::now();
        let stage = state.stage + 1;
        let failed_members = state
            .log_likelihood
            .iter()
            .filter(|v| !v.is_finite())
            .count();
        let max_ll = max_finite(&state.log_likelihood).ok_or(BasisError::NoFiniteLikelihood {
            stage: state.stage,
            failures: failed_members,
        })?;
        let next = match self.next_exponent(&state, max_ll) {
            Ok(next) => next,
            Err(stop) => {
                state.stop_reason = Some(stop);
                return Ok(state);
            }
        };
        let weighed = self.weigh(&state, &next, max_ll)?;
        let chains = self.seed_chains(&state, &weighed.weights, stage);
        let chain_count = chains.len();
        let moved = self.run_moves(chains, &weighed.proposal, next.exponent, stage)?;
        let counts = moved.counts;
        let log_evidence = state.log_evidence + weighed.increment;
        let diagnostics = StageDiagnostics {
            stage,
            exponent: next.exponent,
            step: next.step,
            cv: weighed.cv,
            ess_fraction: weighed.ess_fraction,
            step_clamped: next.clamped,
            bisection_iterations: next.iterations,
            log_evidence_increment: weighed.increment,
            log_evidence,
            max_log_likelihood: max_finite(&moved.log_likelihood).unwrap_or(f64::NEG_INFINITY),
            covariance: Some(weighed.proposal.factor),
            chains: chain_count,
            proposals: counts.proposals,
            accepted: counts.accepted,
            proposal_scale: weighed.scale,
            burn_in: counts.burn_in,
            start_correlation: counts.start_correlation,
            acceptance_rate: if counts.proposals > 0 {
                counts.accepted as f64 / counts.proposals as f64
            } else {
                0.0
            },
            out_of_support: counts.out_of_support,
            failures: counts.failures,
            failure_reasons: counts.failure_reasons,
            evaluations: counts.evaluations,
            batches: counts.batches,
            screenings: counts.screenings,
            screened_out: counts.screened_out,
            unique_fraction: unique_fraction(&moved.samples),
            wall_seconds: start.elapsed().as_secs_f64(),
        };
        state.diagnostics.push(diagnostics);
        state.stage = stage;
        state.exponent = next.exponent;
        state.log_evidence = log_evidence;
        state.samples = moved.samples;
        state.log_likelihood = moved.log_likelihood;
        state.log_prior = moved.log_prior;
        state.evaluations += counts.evaluations;
        state.stop_reason = if next.final_pass {
            Some(StopReason::Converged)
        } else if next.exponent < 1.0 && stage >= self.settings.max_stages {
            Some(StopReason::MaxStages {
                max_stages: self.settings.max_stages,
                exponent: next.exponent,
            })
        } else {
            None
        };
        Ok(state)
    }

    /// Step 2: the next exponent from the state's log-likelihoods, or why there is none.
    fn next_exponent(
        &self,
        state: &BasisState,
        max_ll: f64,
    ) -> std::result::Result<NextExponent, StopReason> {
        let settings = &self.settings;
        let p = state.exponent;
        if p >= 1.0 {
            return Ok(NextExponent {
                step: 0.0,
                exponent: 1.0,
                cv: 0.0,
                clamped: false,
                iterations: 0,
                final_pass: true,
            });
        }
        let solved = next_step(&state.log_likelihood, p, settings.cv_target, max_ll);
        let next = |step, exponent, cv, clamped| NextExponent {
            step,
            exponent,
            cv,
            clamped,
            iterations: solved.iterations,
            final_pass: false,
        };
        if solved.reaches_one {
            return Ok(next(solved.step, 1.0, solved.cv, false));
        }
        if solved.step >= settings.min_step {
            return Ok(next(solved.step, p + solved.step, solved.cv, false));
        }
        match settings.on_min_step {
            MinStepAction::Stop => Err(StopReason::StepBelowMinimum {
                step: solved.step,
                min_step: settings.min_step,
                exponent: p,
            }),
            MinStepAction::Clamp => {
                let step = settings.min_step.min(1.0 - p);
                let exponent = if p + step >= 1.0 { 1.0 } else { p + step };
                Ok(next(step, exponent, f64::NAN, true))
            }
        }
    }

    /// Steps 3 and 4: the evidence increment, the normalised weights and the proposal.
    fn weigh(&self, state: &BasisState, next: &NextExponent, max_ll: f64) -> Result<Weighed> {
        let settings = &self.settings;
        let n = settings.samples;
        let increment = log_evidence_increment(&state.log_likelihood, next.step, max_ll);
        let raw_weights = incremental_weights(&state.log_likelihood, next.step, max_ll);
        let cv = if next.cv.is_nan() {
            crate::annealing::coefficient_of_variation(&raw_weights)
        } else {
            next.cv
        };
        let total: f64 = raw_weights.iter().sum();
        let weights: Vec<f64> = raw_weights.iter().map(|w| w / total).collect();
        let ess_fraction = 1.0 / (n as f64 * weights.iter().map(|w| w * w).sum::<f64>());
        let scale = match settings.mixing {
            Mixing::Fixed => settings.proposal_scale,
            Mixing::Adaptive { .. } => adapted_scale(&state.diagnostics, self.space.dimension()),
        };
        let proposal = Proposal::new(&state.samples, &weights, scale, &self.widths)?;
        Ok(Weighed {
            increment,
            cv,
            weights,
            ess_fraction,
            scale,
            proposal,
        })
    }

    /// The parameter space sampled.
    pub(crate) fn space(&self) -> &ParameterSpace {
        self.space
    }

    /// The likelihood's screen of a batch ([`LogLikelihood::screening_log_likelihood_batch`]),
    /// failures and non-finite values turned into −∞ with a counted reason; `None` when the
    /// likelihood has none.
    pub(crate) fn screen(
        &self,
        stage: usize,
        points: &[Vec<f64>],
        reasons: &mut BTreeMap<String, usize>,
        failures: &mut usize,
    ) -> Result<Option<Vec<f64>>> {
        let Some(values) = self.likelihood.screening_log_likelihood_batch(points) else {
            return Ok(None);
        };
        self.finite_or_failure(stage, points.len(), values, reasons, failures)
            .map(Some)
    }
}

/// The exponent of the next stage (step 2).
struct NextExponent {
    step: f64,
    exponent: f64,
    /// NaN when the step was clamped (the weights' CV is computed then).
    cv: f64,
    clamped: bool,
    iterations: usize,
    /// The stage starts at p = 1: the final pass.
    final_pass: bool,
}

/// A stage's weights and proposal (steps 3 and 4).
struct Weighed {
    increment: f64,
    cv: f64,
    weights: Vec<f64>,
    ess_fraction: f64,
    scale: f64,
    proposal: Proposal,
}

/// The acceptance rate the scale of [`Mixing::Adaptive`] aims at: optimal for a random walk
/// in many dimensions (Roberts, Gelman & Gilks 1997).
pub const TARGET_ACCEPTANCE: f64 = 0.234;

/// The proposal scale of [`Mixing::Adaptive`] for the next stage. Before any moves,
/// min(1, 2.38/√d) (Roberts, Gelman & Gilks 1997). After a stage that moved at scale β with
/// acceptance rate a, the scale whose acceptance the random walk's law a(β) = 2Φ(−β√I/2) puts at
/// [`TARGET_ACCEPTANCE`]: β·Φ⁻¹(a*/2)/Φ⁻¹(a/2), held within [β/2, 2β] and (0, 2.38].
fn adapted_scale(diagnostics: &[StageDiagnostics], dimension: usize) -> f64 {
    let initial = (2.38 / (dimension.max(1) as f64).sqrt()).min(1.0);
    let Some(last) = diagnostics
        .iter()
        .rev()
        .find(|d| d.proposals > 0 && d.proposal_scale > 0.0)
    else {
        return initial;
    };
    let beta = last.proposal_scale;
    let a = last.acceptance_rate.clamp(1e-3, 1.0 - 1e-3);
    let ratio = quantile(TARGET_ACCEPTANCE / 2.0) / quantile(a / 2.0);
    (beta * ratio.clamp(0.5, 2.0)).min(2.38)
}

/// "name: checkpoint a, this run b" for every setting that differs.
fn settings_differences(checkpoint: &CheckedSettings, run: &CheckedSettings) -> String {
    let as_map = |s: &CheckedSettings| match serde_json::to_value(s) {
        Ok(serde_json::Value::Object(m)) => m,
        _ => serde_json::Map::new(),
    };
    let (a, b) = (as_map(checkpoint), as_map(run));
    let differences: Vec<String> = a
        .iter()
        .filter(|(k, v)| b.get(*k) != Some(*v))
        .map(|(k, v)| {
            format!(
                "{k}: checkpoint {v}, this run {}",
                b.get(k).map_or("-".to_string(), |w| w.to_string())
            )
        })
        .collect();
    if differences.is_empty() {
        format!("{:?} vs {:?}", checkpoint.settings(), run.settings())
    } else {
        differences.join("; ")
    }
}

/// Distinct members (by bit pattern) divided by the population size.
fn unique_fraction(samples: &[Vec<f64>]) -> f64 {
    if samples.is_empty() {
        return 0.0;
    }
    let distinct: HashSet<Vec<u64>> = samples
        .iter()
        .map(|x| x.iter().map(|v| v.to_bits()).collect())
        .collect();
    distinct.len() as f64 / samples.len() as f64
}
