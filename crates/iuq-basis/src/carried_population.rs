//! A posterior population carried to a changed likelihood: reweight, resample, move — one step of
//! a sequential Monte Carlo sampler between successive targets (Del Moral, Doucet & Jasra 2006,
//! "Sequential Monte Carlo samplers", JRSS B 68(3); Chopin 2002, "A sequential particle filter
//! method for static models", Biometrika 89(3)).
//!
//! A finished BASIS run holds N members θ_i of π(θ)·f_old(D|θ). When the likelihood changes to
//! f_new (the adaptive engine's surrogate after a round of runs), the members are weighted by
//!
//! w_i ∝ f_new(D|θ_i) / f_old(D|θ_i),
//!
//! which targets π·f_new exactly, with effective sample size ESS = 1/Σ w̄_i². Where ESS/N is at
//! least 1/(1 + γ²) (γ the sampler's `cv_target`, so the same bound a BASIS stage keeps), the
//! members are resampled systematically to the run's N and moved by BASIS's final pass
//! ([`Basis::advance`] at p = 1: Metropolis chains whose invariant law is π·f_new, with the run's
//! mixing, adaptive burn-in included). The log-evidence carries over:
//! ln Z_new = ln Z_old + ln((1/N) Σ_i f_new(θ_i)/f_old(θ_i)). Where the ESS collapses (the
//! posterior moved further than the population reaches) nothing is carried and the caller anneals
//! from the prior again.
//!
//! The cost: N likelihood evaluations for the weights and one stage of moves, against the whole
//! annealing (for a posterior 10⁻⁶ of its prior about a dozen stages) of a run from the prior.
//!
//! ```
//! use iuq_basis::{Basis, BasisSettings, FnLikelihood, Silent};
//! use iuq_basis::carried_population::{Carried, carry};
//! use iuq_core::{Parameter, ParameterSpace, Prior};
//!
//! let space = ParameterSpace::new(vec![Parameter {
//!     name: "x".into(),
//!     prior: Prior::Uniform(-10.0, 10.0),
//! }])
//! .unwrap();
//! let settings = BasisSettings { samples: 2000, seed: 1, ..Default::default() }.check().unwrap();
//! let old = FnLikelihood::new(1, |x: &[f64]| -0.5 * x[0] * x[0]);
//! let run = Basis::new(&space, &old, settings).unwrap().run(&mut Silent).unwrap();
//! // The likelihood moves by a fifth of its width: N(0.2, 1).
//! let new = FnLikelihood::new(1, |x: &[f64]| -0.5 * (x[0] - 0.2).powi(2));
//! let next = BasisSettings { samples: 2000, seed: 2, ..Default::default() }.check().unwrap();
//! let basis = Basis::new(&space, &new, next).unwrap();
//! let Carried::Ready(state) = carry(&basis, &run.state).unwrap() else { panic!() };
//! let moved = basis.advance(*state).unwrap();
//! let mean = moved.samples.iter().map(|s| s[0]).sum::<f64>() / 2000.0;
//! assert!((mean - 0.2).abs() < 0.15);
//! ```

use std::collections::BTreeMap;
use std::time::Instant;

use iuq_core::random::{stages::SAMPLER_BASE, stream};

use crate::annealing::{incremental_weights, max_finite};
use crate::diagnostics::StageDiagnostics;
use crate::error::{BasisError, Result};
use crate::likelihood::LogLikelihood;
use crate::resampling::resample;
use crate::sampler::{Basis, BasisState};
use crate::settings::Resampling;

/// The stream index of the carry's resampling (stage `SAMPLER_BASE`, so that it shares no stream
/// with a stage's chains, which use indices from 0, or with its resampling, `u64::MAX`).
const CARRY_STREAM: u64 = u64::MAX - 1;

/// What [`carry`] made of a population.
#[derive(Debug, Clone, PartialEq)]
pub enum Carried {
    /// The members reweighted to the new likelihood and resampled to the run's N: an unfinished
    /// state at p = 1 whose next [`Basis::advance`] (the final pass) moves them.
    Ready(Box<BasisState>),
    /// The weights' ESS/N fell below 1/(1 + `cv_target`²): the new posterior lies where the
    /// population does not reach; anneal from the prior instead.
    Collapsed {
        /// ESS/N of the weights f_new/f_old (0 when no member has a finite new likelihood).
        ess_fraction: f64,
    },
}

/// Carry the finished population `previous` (members of π·f_old at p = 1) to `basis`'s
/// likelihood f_new: evaluate f_new at every member, weight by f_new/f_old and, unless the ESS
/// collapses, resample to `basis`'s N (systematically) into a state that [`Basis::advance`]
/// then moves (module documentation). The state holds one diagnostic, stage 0: the reweighting,
/// with its ESS and evidence increment.
pub fn carry<L: LogLikelihood + ?Sized>(
    basis: &Basis<'_, L>,
    previous: &BasisState,
) -> Result<Carried> {
    let start = Instant::now();
    let settings = *basis.settings();
    if previous.exponent < 1.0 || previous.samples.is_empty() {
        return Err(BasisError::Checkpoint(format!(
            "only a finished population at p = 1 can be carried (this one is at p = {}, {} members)",
            previous.exponent,
            previous.samples.len()
        )));
    }
    let (mut reasons, mut failures) = (BTreeMap::new(), 0);
    let log_likelihood = basis.evaluate(0, &previous.samples, &mut reasons, &mut failures)?;
    let log_ratio: Vec<f64> = log_likelihood
        .iter()
        .zip(&previous.log_likelihood)
        .map(|(new, old)| {
            if new.is_finite() && old.is_finite() {
                new - old
            } else {
                f64::NEG_INFINITY
            }
        })
        .collect();
    let Some(max_ratio) = max_finite(&log_ratio) else {
        return Ok(Carried::Collapsed { ess_fraction: 0.0 });
    };
    let raw = incremental_weights(&log_ratio, 1.0, max_ratio);
    let total: f64 = raw.iter().sum();
    let weights: Vec<f64> = raw.iter().map(|w| w / total).collect();
    let members = weights.len() as f64;
    let ess_fraction = 1.0 / (members * weights.iter().map(|w| w * w).sum::<f64>());
    if ess_fraction < 1.0 / (1.0 + settings.cv_target * settings.cv_target) {
        return Ok(Carried::Collapsed { ess_fraction });
    }
    let increment = max_ratio + (total / members).ln();
    let n = settings.samples;
    let mut rng = stream(settings.seed, SAMPLER_BASE, CARRY_STREAM);
    let counts = resample(&weights, n, Resampling::Systematic, &mut rng);
    let mut state = BasisState {
        parameter_names: previous.parameter_names.clone(),
        settings,
        stage: 0,
        exponent: 1.0,
        log_evidence: previous.log_evidence + increment,
        samples: Vec::with_capacity(n),
        log_likelihood: Vec::with_capacity(n),
        log_prior: Vec::with_capacity(n),
        evaluations: previous.samples.len(),
        diagnostics: Vec::new(),
        stop_reason: None,
    };
    for (i, &count) in counts.iter().enumerate() {
        for _ in 0..count {
            state.samples.push(previous.samples[i].clone());
            state.log_likelihood.push(log_likelihood[i]);
            state.log_prior.push(previous.log_prior[i]);
        }
    }
    // The moves start from the scale the previous run's last moves adapted to.
    let moved = previous
        .diagnostics
        .iter()
        .rev()
        .find(|d| d.proposals > 0 && d.proposal_scale > 0.0);
    state.diagnostics.push(StageDiagnostics {
        stage: 0,
        exponent: 1.0,
        step: 0.0,
        cv: (1.0 / ess_fraction - 1.0).max(0.0).sqrt(),
        ess_fraction,
        step_clamped: false,
        bisection_iterations: 0,
        log_evidence_increment: increment,
        log_evidence: state.log_evidence,
        max_log_likelihood: max_finite(&state.log_likelihood).unwrap_or(f64::NEG_INFINITY),
        covariance: None,
        chains: 0,
        proposals: moved.map_or(0, |d| d.proposals),
        accepted: moved.map_or(0, |d| d.accepted),
        proposal_scale: moved.map_or(0.0, |d| d.proposal_scale),
        burn_in: 0,
        start_correlation: 0.0,
        acceptance_rate: moved.map_or(0.0, |d| d.acceptance_rate),
        out_of_support: 0,
        failures,
        failure_reasons: reasons,
        evaluations: previous.samples.len(),
        batches: 1,
        screenings: 0,
        screened_out: 0,
        unique_fraction: counts.iter().filter(|&&c| c > 0).count() as f64 / n as f64,
        wall_seconds: start.elapsed().as_secs_f64(),
    });
    Ok(Carried::Ready(Box::new(state)))
}

/// One population of the finished runs `states` of the same posterior (independent replicates,
/// as the adaptive engine's rounds sample): their members, likelihoods and priors in order, the
/// mean of their log-evidences, their evaluations summed; settings and diagnostics (the moves'
/// adapted scale, which [`carry`] starts from) of the first. [`carry`]ing it to a sampler of N
/// members draws those N from all replicates at once.
pub fn pool(states: &[BasisState]) -> Result<BasisState> {
    let Some(first) = states.first() else {
        return Err(BasisError::Checkpoint("no population to pool".into()));
    };
    let mut pooled = first.clone();
    for state in &states[1..] {
        if state.parameter_names != first.parameter_names {
            return Err(BasisError::Checkpoint(format!(
                "populations of different parameters cannot be pooled ({} against {})",
                state.parameter_names.join(", "),
                first.parameter_names.join(", ")
            )));
        }
        if state.exponent < 1.0 {
            return Err(BasisError::Checkpoint(format!(
                "only finished populations at p = 1 can be pooled (one is at p = {})",
                state.exponent
            )));
        }
        pooled.samples.extend(state.samples.iter().cloned());
        pooled.log_likelihood.extend(&state.log_likelihood);
        pooled.log_prior.extend(&state.log_prior);
        pooled.evaluations += state.evaluations;
    }
    pooled.log_evidence = states.iter().map(|s| s.log_evidence).sum::<f64>() / states.len() as f64;
    Ok(pooled)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::likelihood::FnLikelihood;
    use crate::sampler::Silent;
    use crate::settings::BasisSettings;
    use iuq_core::{Parameter, ParameterSpace, Prior};

    fn space(d: usize) -> ParameterSpace {
        ParameterSpace::new(
            (0..d)
                .map(|k| Parameter {
                    name: format!("x{k}"),
                    prior: Prior::Uniform(-10.0, 10.0),
                })
                .collect(),
        )
        .unwrap()
    }

    fn settings(samples: usize, seed: u64) -> crate::CheckedSettings {
        BasisSettings {
            samples,
            seed,
            ..Default::default()
        }
        .check()
        .unwrap()
    }

    /// ln N(x; m, s²I) up to a constant.
    fn gaussian(m: f64, s: f64) -> impl Fn(&[f64]) -> f64 + Send + Sync {
        move |x: &[f64]| -0.5 * x.iter().map(|v| ((v - m) / s).powi(2)).sum::<f64>()
    }

    /// Carried to a likelihood moved by 0.3 std and narrowed to 0.8 of its width, a 3-parameter
    /// Gaussian posterior has the new moments: each mean within 4 of its Monte Carlo errors and
    /// each std within 10 %. The error of a mean is s/√ESS with ESS ≥ N/5 (the resampled
    /// copies decorrelated by the moves; BASIS populations reach about N/3 here), 0.8/√400 = 0.04,
    /// so 4 errors are 0.16 of the posterior's 0.8.
    #[test]
    fn carried_population_has_the_new_posterior_moments() {
        let d = 3;
        let space = space(d);
        let old = FnLikelihood::new(d, gaussian(0.0, 1.0));
        let run = Basis::new(&space, &old, settings(2000, 1))
            .unwrap()
            .run(&mut Silent)
            .unwrap();
        let new = FnLikelihood::new(d, gaussian(0.3, 0.8));
        let basis = Basis::new(&space, &new, settings(2000, 2)).unwrap();
        let Carried::Ready(state) = carry(&basis, &run.state).unwrap() else {
            panic!("the ESS of a 0.3-std move cannot collapse");
        };
        assert_eq!(state.samples.len(), 2000);
        let moved = basis.advance(*state).unwrap();
        assert!(moved.is_finished());
        for k in 0..d {
            let values: Vec<f64> = moved.samples.iter().map(|s| s[k]).collect();
            let mean = values.iter().sum::<f64>() / values.len() as f64;
            let std = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>()
                / values.len() as f64)
                .sqrt();
            assert!((mean - 0.3).abs() < 0.16, "x{k}: mean {mean}");
            assert!((std / 0.8 - 1.0).abs() < 0.1, "x{k}: std {std}");
        }
        // ln(Z_new/Z_old) = ln ∫exp(−(x−m)²/(2s²)) − ln ∫exp(−x²/2) = d·ln s (both well
        // inside the prior); its Monte Carlo error with ESS ≥ 1000 is below 0.05.
        let increment = moved.log_evidence - run.state.log_evidence;
        let exact = d as f64 * 0.8f64.ln();
        assert!((increment - exact).abs() < 0.05, "{increment} vs {exact}");
    }

    /// A likelihood 8 stds away cannot be reached by reweighting: the carry says so.
    #[test]
    fn a_distant_posterior_collapses_the_weights() {
        let space = space(2);
        let old = FnLikelihood::new(2, gaussian(0.0, 0.5));
        let run = Basis::new(&space, &old, settings(1000, 1))
            .unwrap()
            .run(&mut Silent)
            .unwrap();
        let new = FnLikelihood::new(2, gaussian(4.0, 0.5));
        let basis = Basis::new(&space, &new, settings(1000, 2)).unwrap();
        match carry(&basis, &run.state).unwrap() {
            Carried::Collapsed { ess_fraction } => assert!(ess_fraction < 0.01),
            Carried::Ready(_) => panic!("an 8-std move must collapse the ESS"),
        }
    }

    /// An unfinished population is refused.
    #[test]
    fn an_unfinished_population_is_refused() {
        let space = space(1);
        let old = FnLikelihood::new(1, gaussian(0.0, 0.5));
        let basis = Basis::new(&space, &old, settings(500, 1)).unwrap();
        let state = basis.initialise().unwrap();
        assert!(carry(&basis, &state).is_err());
    }

    /// The same inputs carry to the same state, whatever the thread count.
    #[test]
    fn a_carry_is_reproducible_across_thread_counts() {
        let space = space(2);
        let old = FnLikelihood::new(2, gaussian(0.0, 1.0));
        let run = Basis::new(&space, &old, settings(800, 1))
            .unwrap()
            .run(&mut Silent)
            .unwrap();
        let new = FnLikelihood::new(2, gaussian(0.2, 1.0));
        let moved = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    let basis = Basis::new(&space, &new, settings(800, 2)).unwrap();
                    let Carried::Ready(state) = carry(&basis, &run.state).unwrap() else {
                        panic!("collapsed");
                    };
                    basis.advance(*state).unwrap()
                })
        };
        let (one, two) = (moved(1), moved(2));
        assert_eq!(one.samples, two.samples);
        assert_eq!(one.log_evidence.to_bits(), two.log_evidence.to_bits());
    }

    /// Two replicates pooled hold both populations in order and the mean log-evidence; pooling
    /// populations of different parameters or an unfinished one is refused.
    #[test]
    fn replicates_pool_into_one_population() {
        let space = space(2);
        let likelihood = FnLikelihood::new(2, gaussian(0.0, 1.0));
        let runs: Vec<BasisState> = [1, 2]
            .iter()
            .map(|&seed| {
                Basis::new(&space, &likelihood, settings(300, seed))
                    .unwrap()
                    .run(&mut Silent)
                    .unwrap()
                    .state
            })
            .collect();
        let pooled = pool(&runs).unwrap();
        assert_eq!(pooled.samples.len(), 600);
        assert_eq!(&pooled.samples[..300], &runs[0].samples[..]);
        assert_eq!(&pooled.samples[300..], &runs[1].samples[..]);
        assert_eq!(&pooled.log_likelihood[300..], &runs[1].log_likelihood[..]);
        let mean = 0.5 * (runs[0].log_evidence + runs[1].log_evidence);
        assert_eq!(pooled.log_evidence.to_bits(), mean.to_bits());
        assert_eq!(
            pooled.evaluations,
            runs[0].evaluations + runs[1].evaluations
        );
        // Carried to a sampler of 1000, the pooled members fill it.
        let basis = Basis::new(&space, &likelihood, settings(1000, 3)).unwrap();
        let Carried::Ready(state) = carry(&basis, &pooled).unwrap() else {
            panic!("the same likelihood cannot collapse the weights");
        };
        assert_eq!(state.samples.len(), 1000);
        let mut renamed = runs[1].clone();
        renamed.parameter_names[0] = "y".into();
        assert!(pool(&[runs[0].clone(), renamed]).is_err());
        let unfinished = Basis::new(&space, &likelihood, settings(300, 4))
            .unwrap()
            .initialise()
            .unwrap();
        assert!(pool(&[runs[0].clone(), unfinished]).is_err());
        assert!(pool(&[]).is_err());
    }
}
