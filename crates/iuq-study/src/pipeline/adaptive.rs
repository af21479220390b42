//! The adaptive engine: after the initial design, rounds of
//!
//! 1. fit the surrogate (a GP per data point, a failure classifier per run group with failures);
//! 2. sample its posterior with `replicates` independent BASIS runs of `samples` each (seeds
//!    from the sampler's, the round and the replicate), pooled; their spread is the Monte Carlo
//!    error of the moments;
//! 3. judge convergence (`iuq_adaptive::engine`, whose state and step decide the loop; this module
//!    drives it with the campaign and the files): every parameter's posterior mean and std, and
//!    with `stopping_rule = "distribution"` the posterior as a whole
//!    (`iuq_adaptive::posterior_distance`), moved by less than `tolerance` posterior stds since
//!    the previous round beyond the sampler's noise, and that noise is below `tolerance` (else the
//!    next round's replicates sample twice as many, up to `max_samples`); the GPs' error could
//!    move no posterior mean or
//!    std by more than `tolerance` posterior stds (`iuq_adaptive::moment_error`: the std of the
//!    reweighted moments over [`SURROGATE_ERROR_DRAWS`] joint draws of the GPs' error);
//!    and the region of the posterior where a failure classifier is unsure
//!    (0.1 ≤ p_fail ≤ 0.9) has runs every [`BOUNDARY_RESOLUTION`] posterior stds — else boundary
//!    runs go there, once the surrogate's std of the log-likelihood averaged over the posterior
//!    is below `log_likelihood_tolerance` nats;
//! 4. otherwise score the distinct posterior samples by the variance the surrogate leaves in the
//!    log-likelihood there, times their squared relative posterior density and the probability
//!    that the model answers (`iuq_adaptive::acquisition`), pick up to `batch` runs per run group greedily with
//!    kriging-believer updates (`iuq_adaptive::batch`), keep the best within `max_runs`, and run
//!    them through the campaign as the design `adaptive-round-<k>`.
//!
//! Every second replicate mixes its chains one level harder (`iuq_basis::CheckedSettings::
//! with_stronger_mixing`): when the two groups' posteriors differ beyond their noise by more than
//! `tolerance` (`iuq_adaptive::sampler_agreement`), the round is not converged and later rounds,
//! and the final posterior, sample at the harder level.
//!
//! The loop stops converged, at `max_runs` or `max_rounds`, when the sampler still disagrees at
//! its strongest mixing, or when no candidate's score exceeds the minimum worth a run
//! ((log_likelihood_tolerance/2)² divided by the number of run groups) even among 16 times
//! `candidates` (each round that finds none looks among 4 times more, from twice the samples):
//! every stop short of convergence says why and what to change.
//!
//! Everything is seeded, so a rerun replays the rounds, finding every run in the campaign store:
//! after a crash (or kill -9) it continues where it stopped, running only what was never
//! finished. A round whose design the store already holds (`adaptive-round-<k>`) takes its
//! runs from there, so the replay does not depend on recomputing the choice to the last bit.

use std::path::Path;
use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use iuq_adaptive::engine::{
    AdaptiveEngine, EngineSettings, EngineState, Judgement, RoundEvent, RoundReading,
    RoundSampling, StoppingRule,
};
use iuq_adaptive::{
    ComponentErrors, ConvergenceCriterion, LikelihoodTerm, MomentTerm, PosteriorMoments,
    SamplerAgreement, SensitivityTerm, extrapolation_share, group_batches, likelihood_weights,
    log_likelihood_variance, sampled_moment_errors_by_group,
    sampled_moment_errors_by_group_from_components, sampler_agreement, select_batch,
    select_batch_for_moments, select_batch_for_moments_by_sensitivity,
    surrogate_log_likelihood_std,
};
use iuq_basis::carried_population::{Carried, carry};
use iuq_basis::{Basis, BasisState, MAX_MIXING_LEVEL};
use iuq_core::{Control, Observer};

use super::events::Events;
use super::low_fidelity::{Allocation, LowFidelity, allocation_key};
use super::model_runs::ModelRuns;
use super::posterior_check::{CheckVerdict, PosteriorCheck, retrained_check_label};
use super::run_groups::{GroupRuns, RunOrigin};
use super::settings::{Acquisition, AdaptiveSettings, FinalSample, PosteriorSampling};
use super::surrogate::{Emulation, GpStarts, Surrogate};
use crate::error::{BadInput, Result, StudyError};
use crate::likelihood_section::DataLikelihood;
use crate::posterior::build_posterior_with;
use crate::sampler_section::{SamplerOverrides, parse_sampler};
use crate::study::Study;
use crate::table_io::{write_atomically, write_numeric_csv};

/// Distance to the nearest training run, in length scales, beyond which the surrogate
/// extrapolates.
pub const EXTRAPOLATION_THRESHOLD: f64 = 1.0;

/// Joint draws of the GPs' error over the candidates from which the surrogate error ε is
/// estimated (its relative Monte Carlo error is about 1/√(2·64) ≈ 9 %).
pub const SURROGATE_ERROR_DRAWS: usize = 64;

/// A failure classifier is unsure at θ when 0.1 ≤ p_fail(θ) ≤ 0.9.
const UNSURE: (f64, f64) = (0.1, 0.9);

/// The spacing, in posterior stds, at which boundary runs sample the region where a failure
/// classifier is unsure: a candidate there that is farther than this from every run of its group
/// gets a run.
pub const BOUNDARY_RESOLUTION: f64 = 0.25;

/// How near, in posterior stds, a failed run must be for the posterior to meet the boundary of
/// the failure region there.
pub const BOUNDARY_REACH: f64 = 3.0;

/// The share of the candidates on which a classifier may be unsure near a failed run without
/// boundary runs: a boundary band of a few percent of the posterior need not be resolved
/// further (in many dimensions it could not be, at any affordable number of runs).
pub const BOUNDARY_SHARE: f64 = 0.02;

/// Runs on the boundary of a group's failure region where it meets the posterior: among the
/// candidates on which the classifier is unsure ([`UNSURE`]) and that lie within
/// [`BOUNDARY_REACH`] of a failed run, greedily the one farthest from every run of the group and
/// every earlier pick — distance in posterior stds per parameter — while
/// that distance exceeds [`BOUNDARY_RESOLUTION`], at most `batch`. A run there tells whether the
/// posterior mass there exists; when the unsure region is sampled at that spacing, the
/// classifier's boundary is as sharp as the posterior needs. Returns the unsure share and the
/// picks.
fn boundary_picks(
    p_fail: &[f64],
    candidates: &[Vec<f64>],
    runs: &[Vec<f64>],
    failed: &[bool],
    scale: &[f64],
    batch: usize,
) -> (f64, Vec<usize>) {
    if p_fail.is_empty() {
        return (0.0, Vec::new());
    }
    let distance = |a: &[f64], b: &[f64]| -> f64 {
        a.iter()
            .zip(b)
            .zip(scale)
            .map(|((x, y), s)| ((x - y) / s.max(1e-300)).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    let near_failure = |c: &[f64]| {
        runs.iter()
            .zip(failed)
            .any(|(r, f)| *f && distance(c, r) <= BOUNDARY_REACH)
    };
    let unsure: Vec<usize> = (0..p_fail.len())
        .filter(|&i| (UNSURE.0..=UNSURE.1).contains(&p_fail[i]) && near_failure(&candidates[i]))
        .collect();
    let share = unsure.len() as f64 / p_fail.len() as f64;
    if share <= BOUNDARY_SHARE {
        return (share, Vec::new());
    }
    let mut nearest: Vec<f64> = unsure
        .iter()
        .map(|&i| {
            runs.iter()
                .map(|r| distance(&candidates[i], r))
                .fold(f64::INFINITY, f64::min)
        })
        .collect();
    let mut picks = Vec::new();
    while picks.len() < batch {
        let Some((k, &d)) = nearest.iter().enumerate().fold(
            None,
            |best: Option<(usize, &f64)>, (k, d)| match best {
                Some((_, b)) if *b >= *d => best,
                _ => Some((k, d)),
            },
        ) else {
            break;
        };
        if d <= BOUNDARY_RESOLUTION {
            break;
        }
        let pick = unsure[k];
        picks.push(pick);
        for (n, &i) in nearest.iter_mut().zip(&unsure) {
            *n = n.min(distance(&candidates[i], &candidates[pick]));
        }
    }
    (share, picks)
}

/// One round of the adaptive engine, as `report.json` and the report show it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AdaptiveRound {
    /// The round, from 1.
    pub round: usize,
    /// Model runs made before this round's new runs (initial, test and earlier rounds).
    pub runs: usize,
    /// New runs chosen in this round (0 when the loop stopped at this round for convergence or
    /// `max_runs`).
    pub new_runs: usize,
    /// New runs per run group.
    pub new_runs_per_group: Vec<usize>,
    /// Posterior mean of each sampled parameter.
    pub mean: Vec<f64>,
    /// Posterior std of each sampled parameter.
    pub std: Vec<f64>,
    /// Monte Carlo standard error of each posterior mean (from the replicates' spread).
    pub mean_error: Vec<f64>,
    /// Monte Carlo standard error of each posterior std.
    pub std_error: Vec<f64>,
    /// Posterior samples of the round, all replicates together.
    pub samples: usize,
    /// max_k of the parameters' shifts since the previous round beyond the sampler's noise, in
    /// posterior stds.
    pub shift: Option<f64>,
    /// max_k of the sampler's noise on those shifts (2 Monte Carlo errors of the difference),
    /// in posterior stds: a shift is resolved only when this is below the tolerance.
    pub shift_noise: Option<f64>,
    /// The sliced distance between this round's posterior and the previous one's beyond the
    /// samplers' noise, in posterior stds (`iuq_adaptive::posterior_distance`; `None` in the
    /// first round, with `stopping_rule = "moments"`, or where the previous round's samples are
    /// not in the store).
    pub distance: Option<f64>,
    /// The samplers' noise on that distance, in posterior stds.
    pub distance_noise: Option<f64>,
    /// The surrogate's std of the log-likelihood, averaged over the posterior (nats).
    pub log_likelihood_std: f64,
    /// ε: the largest typical change (68.3 % quantile of its absolute value over draws of the
    /// GPs' error) of a posterior mean or std, in posterior stds (`iuq_adaptive::moment_error`).
    pub surrogate_error: f64,
    /// The typical change of the log evidence under the GPs' error (nats).
    pub log_evidence_error: f64,
    /// ε_g per run group: the surrogate error its GPs alone leave, which shares out the next
    /// round's runs (empty for rounds recorded before it was measured).
    #[serde(default)]
    pub group_surrogate_error: Vec<f64>,
    /// Share of posterior samples farther than one length scale from every training run of
    /// some data point's GP (the largest share over the GPs).
    pub extrapolation_share: f64,
    /// Share of posterior samples where a failure classifier is unsure (0.1 ≤ p_fail ≤ 0.9)
    /// within 3 posterior stds of a failed run: where the posterior meets the boundary of a
    /// failure region (the largest share over the run groups).
    pub unsure_share: f64,
    /// The log evidence of the round's surrogate posterior.
    pub log_evidence: f64,
    /// How much harder than `[sampler]` the round's chains mixed (0: as set; each level is
    /// `iuq_basis::CheckedSettings::with_stronger_mixing`).
    pub mixing_level: u32,
    /// The check of the sampler: the posterior of the replicates that mixed one level harder
    /// against the others (`None`: one replicate, or a round recorded before the check).
    pub sampler_agreement: Option<SamplerAgreement>,
    /// Distinct posterior samples scored as candidates for new runs.
    pub candidates: usize,
    /// Every convergence criterion held.
    pub converged: bool,
    /// Wall-clock seconds of the round.
    pub seconds: f64,
    /// Replicates whose population was carried from the round before (`sampling =
    /// "sequential"`); the others annealed from the prior.
    pub carried_replicates: usize,
    /// Surrogate evaluations of the round's samplers, all replicates together: the round's
    /// sampling cost in model-free operations (0 for a round read back from a store that did
    /// not count them).
    pub surrogate_evaluations: usize,
    /// Points the round's samplers sent to the surrogate's screen (delayed acceptance: means
    /// without predictive variances, O(n) each against O(n²)), all replicates together.
    pub surrogate_screenings: usize,
    /// New runs of the cheap model of `[low_fidelity]` (absent without one).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub new_low_fidelity_runs: Option<usize>,
}

/// What the adaptive engine did.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct AdaptiveOutcome {
    /// Every round.
    pub rounds: Vec<AdaptiveRound>,
    /// Whether the posterior converged by the criterion.
    pub converged: bool,
    /// Why the loop stopped.
    pub stop_reason: String,
    /// The names of the sampled parameters (the columns of `mean` and `std`).
    pub parameters: Vec<String>,
    /// The criterion.
    pub tolerance: f64,
    /// The criterion's log-likelihood part (nats).
    pub log_likelihood_tolerance: f64,
    /// How many times the surrogate's error counts against `tolerance`.
    pub surrogate_error_multiple: f64,
    /// The posterior checks that failed their test and were trained on, in order.
    pub retrained_checks: Vec<RetrainedCheck>,
    /// The mixing level of the last round, at which the final posterior is sampled too.
    pub mixing_level: u32,
    /// The rows of `adaptive/runs.csv` so far.
    #[serde(skip)]
    run_rows: Vec<Vec<f64>>,
    /// The last round's samples per replicate (where kept), the previous round of a loop that
    /// goes on after a failed check.
    #[serde(skip)]
    populations: Option<Vec<Vec<Vec<f64>>>>,
    /// The last round's GP θ per data point: the final surrogate's warm starts, so that it
    /// polishes the optima the last round's surrogate had ([`GpStarts`]).
    #[serde(skip)]
    warm_starts: Option<Vec<Vec<f64>>>,
    /// The last round's replicate populations, where the final sample starts from them
    /// ([`FinalSample::Carried`], the populations kept in the store so that a replay has them).
    #[serde(skip)]
    final_populations: Option<Vec<BasisState>>,
}

/// A posterior check that failed its test: its runs joined the training runs and the rounds went
/// on from the round after `after_round`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RetrainedCheck {
    /// The round after which the check was made (the engine had stopped there).
    pub after_round: usize,
    /// The check's runs, now training runs.
    pub runs: usize,
    /// The abscissae of the data points that failed the test.
    pub failed_at: Vec<f64>,
    /// Its test.
    pub verdict: CheckVerdict,
}

impl AdaptiveOutcome {
    /// The final surrogate's fits: seeded by `seed`, warm-started from the last round's optima.
    pub fn final_gp_starts(&self, seed: u64) -> GpStarts<'_> {
        GpStarts {
            seed,
            warm: self.warm_starts.as_deref(),
        }
    }

    /// The last round's replicates pooled into one population, where the final sample starts
    /// from it ([`FinalSample::Carried`]; `None`: it anneals from the prior).
    pub fn final_population(&self) -> Result<Option<BasisState>> {
        self.final_populations
            .as_deref()
            .filter(|states| !states.is_empty())
            .map(|states| {
                iuq_basis::carried_population::pool(states).map_err(|e| {
                    StudyError::failure(format!("the last round's populations: {e}")).with_source(e)
                })
            })
            .transpose()
    }

    /// Judge the final posterior sample (`mean`, `std`, of the same surrogate as the last round)
    /// against the last round's pooled posterior: where a mean or std differs by more than
    /// `tolerance` posterior stds beyond twice the round's Monte Carlo error, the sample is too
    /// small or too correlated to carry the converged posterior, and the outcome is no longer
    /// converged, with a reason that says what to raise. Nothing changes without a converged
    /// round to compare with.
    pub fn judge_final_sample(&mut self, mean: &[f64], std: &[f64], samples: usize) {
        let Some(round) = self.rounds.last().filter(|_| self.converged) else {
            return;
        };
        let mut largest: (f64, usize) = (0.0, 0);
        for k in 0..round.mean.len().min(mean.len()).min(std.len()) {
            let sd = round.std[k];
            if sd.is_nan() || sd <= 0.0 {
                continue;
            }
            let mean_gap = (mean[k] - round.mean[k]).abs() - 2.0 * round.mean_error[k];
            let std_gap = (std[k] - round.std[k]).abs() - 2.0 * round.std_error[k];
            let gap = mean_gap.max(std_gap).max(0.0) / sd;
            if gap > largest.0 {
                largest = (gap, k);
            }
        }
        if largest.0 >= self.tolerance {
            self.converged = false;
            self.stop_reason = format!(
                "the rounds converged, but the final posterior sample ({samples} samples) differs from the last round's posterior by {:.3} posterior stds on {} beyond the round's Monte Carlo error (tolerance {}): it is too small to carry the converged posterior; raise `[sampler] samples`",
                largest.0,
                self.parameters
                    .get(largest.1)
                    .map_or("a parameter", String::as_str),
                self.tolerance
            );
        }
    }

    /// The last round.
    pub fn last_round(&self) -> usize {
        self.rounds.last().map_or(0, |r| r.round)
    }

    /// Take the runs of the failed check `check` (made after the last round) as training runs:
    /// they join `groups` and `adaptive/runs.csv` (as rows of the last round, a round that made
    /// no runs of its own since the engine stopped there), and the next [`refine`] goes on
    /// from the round after.
    pub(super) fn retrain_on_check(
        &mut self,
        check: &PosteriorCheck,
        verdict: CheckVerdict,
        runs: &ModelRuns,
        groups: &mut [GroupRuns],
    ) -> Result<()> {
        let round = self.last_round();
        let points: Vec<Vec<f64>> = std::iter::once(check.map.clone())
            .chain(check.samples.iter().cloned())
            .collect();
        let requests: Vec<(usize, Vec<f64>)> = (0..groups.len())
            .flat_map(|g| points.iter().map(move |p| (g, p.clone())))
            .collect();
        // Every run is in the store already: this reads them back in the shape training takes,
        // and records the check as one trained on, for a replay to take its points from.
        let outcomes = runs.run(Some(&retrained_check_label(round)), &requests)?;
        for (g, (group, outcomes)) in groups
            .iter_mut()
            .zip(outcomes.chunks(points.len()))
            .enumerate()
        {
            for (theta, outcome) in points.iter().zip(outcomes) {
                let mut row = vec![round as f64, g as f64];
                row.extend(theta);
                row.push(if outcome.is_ok() { 0.0 } else { 1.0 });
                self.run_rows.push(row);
            }
            group.extend(
                RunOrigin::Check { round },
                points.clone(),
                outcomes.to_vec(),
            );
        }
        self.retrained_checks.push(RetrainedCheck {
            after_round: round,
            runs: requests.len(),
            failed_at: verdict
                .failed_points
                .iter()
                .filter_map(|&j| check.points.get(j).map(|p| p.x))
                .collect(),
            verdict,
        });
        self.converged = false;
        Ok(())
    }
}

/// The distinct rows of `samples` (index of the first copy, number of copies), in order of
/// first appearance; when there are more than `limit`, an evenly spaced deterministic subset of
/// them (so that no lineage of the sampler's population is left out).
fn distinct(samples: &[Vec<f64>], limit: usize) -> Vec<(usize, usize)> {
    let mut first: std::collections::HashMap<Vec<u64>, usize> = std::collections::HashMap::new();
    let mut rows: Vec<(usize, usize)> = Vec::new();
    for (i, sample) in samples.iter().enumerate() {
        let key: Vec<u64> = sample.iter().map(|v| v.to_bits()).collect();
        match first.get(&key) {
            Some(&k) => rows[k].1 += 1,
            None => {
                first.insert(key, rows.len());
                rows.push((i, 1));
            }
        }
    }
    if rows.len() <= limit || limit == 0 {
        return rows;
    }
    (0..limit).map(|k| rows[k * rows.len() / limit]).collect()
}

/// s²_j at a posterior sample: the measurement variance (when used) plus (σ_m·y_j)².
pub(super) fn total_variance(data: &DataLikelihood, j: usize, sigma_m: Option<f64>) -> f64 {
    let y = data.observations.values[j];
    let measurement = match (&data.observations.measurement_std, data.measurement_error) {
        (Some(e), true) => e[j] * e[j],
        _ => 0.0,
    };
    let modelling = sigma_m.map_or(0.0, |s| (s * y).powi(2));
    let total = measurement + modelling;
    if total > 0.0 {
        total
    } else {
        // No error term at all: a datum is then exact; keep the score finite.
        1e-12 * y.abs().max(1.0).powi(2)
    }
}

/// Σ_jj at each candidate as the likelihood has it: `data_variance[i][j]` (measurement and
/// modelling error) plus the computational error whose part more runs cannot remove, the GP's
/// noise (the scatter of the runs themselves) and `unresolved[j]` (a reduced basis's truncation
/// error), in the study's convention.
fn likelihood_variances(
    data: &DataLikelihood,
    predictions: &[iuq_gp::Prediction],
    unresolved: &[f64],
    data_variance: &[Vec<f64>],
) -> Vec<Vec<f64>> {
    with_computational_error(data, predictions, data_variance, |p, j, _| {
        p.noise_variance + unresolved[j]
    })
}

/// Σ_jj at each candidate as the surrogate's likelihood had it when the round's posterior was
/// sampled: `data_variance[i][j]` plus the computational error of the bank's reported predictive
/// std (`predictive_std`: the GP's latent variance, and its noise where the bank counts it).
fn sampled_likelihood_variances(
    data: &DataLikelihood,
    predictions: &[iuq_gp::Prediction],
    predictive_std: iuq_gp::PredictiveStd,
    unresolved: &[f64],
    data_variance: &[Vec<f64>],
) -> Vec<Vec<f64>> {
    with_computational_error(data, predictions, data_variance, |p, j, i| {
        p.variance[i] + predictive_std.added_noise_variance(p.noise_variance) + unresolved[j]
    })
}

/// `data_variance[i][j]` plus the study's computational error term for a model std whose
/// square is `model_variance(prediction_j, j, i)` at candidate i.
fn with_computational_error(
    data: &DataLikelihood,
    predictions: &[iuq_gp::Prediction],
    data_variance: &[Vec<f64>],
    model_variance: impl Fn(&iuq_gp::Prediction, usize, usize) -> f64,
) -> Vec<Vec<f64>> {
    data_variance
        .iter()
        .enumerate()
        .map(|(i, row)| {
            row.iter()
                .zip(predictions)
                .zip(&data.observations.values)
                .enumerate()
                .map(|(j, ((s2, p), y))| {
                    let computational = data
                        .computational_error
                        .variance(p.mean[i], model_variance(p, j, i).sqrt(), *y)
                        .unwrap_or(0.0);
                    s2 + computational
                })
                .collect()
        })
        .collect()
}

/// The inputs of one round's scoring: the candidates θ, s²_ij, their log posterior densities
/// (ℓ + ln π of the surrogate posterior), and how many posterior samples each stands for.
struct Candidates {
    theta: Vec<Vec<f64>>,
    /// Every sampled parameter of each candidate (θ, then σ_m where sampled).
    full: Vec<Vec<f64>>,
    variance: Vec<Vec<f64>>,
    log_density: Vec<f64>,
    copies: Vec<f64>,
}

/// A round's posterior: the replicates' final populations pooled.
struct PooledPosterior {
    samples: Vec<Vec<f64>>,
    log_likelihood: Vec<f64>,
    log_prior: Vec<f64>,
    /// The mean of the replicates' log evidence.
    log_evidence: f64,
    moments: PosteriorMoments,
}

fn candidates(
    state: &PooledPosterior,
    d: usize,
    modelling_error: bool,
    data: &DataLikelihood,
    limit: usize,
) -> Candidates {
    let rows = distinct(&state.samples, limit);
    let theta = rows
        .iter()
        .map(|&(i, _)| state.samples[i][..d].to_vec())
        .collect();
    let log_density = rows
        .iter()
        .map(|&(i, _)| state.log_likelihood[i] + state.log_prior[i])
        .collect();
    let copies = rows.iter().map(|&(_, n)| n as f64).collect();
    let full = rows
        .iter()
        .map(|&(i, _)| state.samples[i].clone())
        .collect();
    let variance = rows
        .iter()
        .map(|&(i, _)| {
            let s = &state.samples[i];
            let sigma_m = modelling_error.then(|| s[d]);
            (0..data.x.len())
                .map(|j| total_variance(data, j, sigma_m))
                .collect()
        })
        .collect();
    Candidates {
        theta,
        full,
        variance,
        log_density,
        copies,
    }
}

/// What a round measured on its surrogate posterior: everything the stopping rule and the
/// round's record need. It is recorded in the campaign store under the round's key and the
/// fingerprint of its inputs ([`round_fingerprint`]), so that replaying a study reads it back
/// instead of refitting the surrogate and resampling its posterior. Numbers are kept as their
/// bits, so that what is read back is what was computed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct RoundMeasurement {
    parameters: Vec<String>,
    #[serde(with = "f64_bits::vec")]
    mean: Vec<f64>,
    #[serde(with = "f64_bits::vec")]
    std: Vec<f64>,
    #[serde(with = "f64_bits::vec")]
    mean_error: Vec<f64>,
    #[serde(with = "f64_bits::vec")]
    std_error: Vec<f64>,
    #[serde(with = "f64_bits")]
    log_likelihood_std: f64,
    #[serde(with = "f64_bits")]
    surrogate_error: f64,
    #[serde(with = "f64_bits")]
    log_evidence_error: f64,
    /// ε_g per run group: the error its GPs alone leave (empty in rounds recorded before it
    /// was measured; the round's runs are then shared alike).
    #[serde(with = "f64_bits::vec", default)]
    group_surrogate_error: Vec<f64>,
    #[serde(with = "f64_bits")]
    extrapolation_share: f64,
    #[serde(with = "f64_bits")]
    unsure_share: f64,
    #[serde(with = "f64_bits")]
    log_evidence: f64,
    /// Some run group's failure region wants boundary runs (once the surrogate is sure).
    boundary_wanted: bool,
    /// The check of the sampler (absent in rounds recorded before it was made).
    #[serde(default)]
    sampler_agreement: Option<SamplerAgreement>,
    /// Replicates whose population was carried from the round before (0 in rounds recorded
    /// before `sampling = "sequential"`).
    #[serde(default)]
    carried_replicates: usize,
    /// Surrogate evaluations of the round's samplers, all replicates together (0 in rounds
    /// recorded before it was counted).
    #[serde(default)]
    surrogate_evaluations: usize,
    /// Points sent to the surrogate's screen (0 in rounds recorded before delayed acceptance).
    #[serde(default)]
    surrogate_screenings: usize,
}

impl RoundMeasurement {
    fn moments(&self) -> PosteriorMoments {
        PosteriorMoments {
            mean: self.mean.clone(),
            std: self.std.clone(),
            mean_error: self.mean_error.clone(),
            std_error: self.std_error.clone(),
        }
    }
}

/// f64 serialised as its IEEE-754 bits (JSON numbers are not read back bit for bit by every
/// parser).
mod f64_bits {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(value: &f64, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_u64(value.to_bits())
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(deserializer: D) -> Result<f64, D::Error> {
        u64::deserialize(deserializer).map(f64::from_bits)
    }

    pub mod vec {
        use serde::{Deserialize, Deserializer, Serializer};

        pub fn serialize<S: Serializer>(values: &[f64], serializer: S) -> Result<S::Ok, S::Error> {
            serializer.collect_seq(values.iter().map(|v| v.to_bits()))
        }

        pub fn deserialize<'de, D: Deserializer<'de>>(
            deserializer: D,
        ) -> Result<Vec<f64>, D::Error> {
            Vec::<u64>::deserialize(deserializer)
                .map(|bits| bits.into_iter().map(f64::from_bits).collect())
        }
    }
}

/// The `[sampler]` section without its `delayed_acceptance` key, and whether the moves are
/// screened (the key, default [`iuq_basis::BasisSettings::default`]'s).
fn sampler_without_delayed_acceptance(
    sampler: &Option<toml::Table>,
) -> (Option<toml::Table>, bool) {
    let default = iuq_basis::BasisSettings::default().delayed_acceptance;
    let Some(table) = sampler else {
        return (None, default);
    };
    let mut table = table.clone();
    let delayed = match table.remove("delayed_acceptance") {
        Some(toml::Value::Boolean(b)) => b,
        _ => default,
    };
    (Some(table), delayed)
}

pub(super) use super::events::ROUND_LABEL;

/// Version of a round's measurement: raise it whenever the engine computes a measurement
/// differently, so that measurements recorded by an earlier version are not read back.
const MEASUREMENT_VERSION: u32 = 2;

/// The digest (SHA-256, hex) of everything a round's measurement is computed from: the
/// measurement's version, the priors, the `[likelihood]` and `[sampler]` sections, the data,
/// the seeds, the samples and replicates of the round, the candidates, the error draws, and every
/// run of every group with what it returned. The stopping rule's tolerances and `max_runs` are
/// not in it: the rule is applied to the measurement afresh.
fn round_fingerprint(
    inputs: &RoundInputs<'_>,
    sampling: &RoundSampling,
    groups: &[GroupRuns],
    carried_from: Option<&str>,
) -> Result<String> {
    let RoundInputs {
        study,
        data,
        settings,
        emulation,
        training_seed,
        base_seed,
        ..
    } = *inputs;
    use std::fmt::Write;
    let table = |t: &Option<toml::Table>| {
        t.as_ref()
            .map_or(String::new(), |t| toml::Value::Table(t.clone()).to_string())
    };
    // `delayed_acceptance` enters as what it does, not as text: a section that turns it off
    // reads as the sections of the stores recorded before it existed, and moves screened on the
    // surrogate add a line.
    let (sampler, delayed_acceptance) = sampler_without_delayed_acceptance(&study.sampler);
    let mut text = format!(
        "iuq-study {} measurement {MEASUREMENT_VERSION}\nspace {:?}\nlikelihood {}\nsampler {}\n",
        env!("CARGO_PKG_VERSION"),
        study.space,
        table(&study.likelihood),
        table(&sampler),
    );
    if delayed_acceptance {
        text.push_str("delayed acceptance\n");
    }
    let _ = write!(
        text,
        "data x {:?} y {:?} std {:?} modelling {:?} measurement {} computational {:?}\n\
         seeds {training_seed} {base_seed} samples {} replicates {} candidates {} draws {SURROGATE_ERROR_DRAWS} boundary runs {}\n",
        data.x,
        data.observations.values,
        data.observations.measurement_std,
        data.modelling_error,
        data.measurement_error,
        data.computational_error,
        sampling.samples,
        settings.replicates,
        sampling.candidates,
        settings.batch > 0,
    );
    // Level 0 leaves the text as it was before the sampler was checked, so that the rounds a
    // store recorded then are read back.
    if sampling.mixing_level > 0 {
        let _ = writeln!(text, "mixing level {}", sampling.mixing_level);
    }
    if let Emulation::ReducedBasis { settings, scale } = emulation {
        let _ = writeln!(text, "reduced basis {settings:?} scale {scale:?}");
    }
    // A sequential round's posterior depends on the population it carries, that is on the
    // round it comes from (whose fingerprint chains every earlier one); a round sampled from the
    // prior leaves the text as it was before sequential rounds.
    if settings.sampling == PosteriorSampling::Sequential {
        let _ = writeln!(
            text,
            "sequential from {}",
            carried_from.unwrap_or("the prior")
        );
    }
    for (g, group) in groups.iter().enumerate() {
        let _ = writeln!(
            text,
            "group {g} points {:?} outcomes {:?}",
            group.points, group.outcomes
        );
    }
    if let Some(low) = inputs.low_fidelity {
        text.push_str(&low.fingerprint_text()?);
    }
    Ok(iuq_campaign::study::hex_sha256(text.as_bytes()))
}

/// What a freshly measured round keeps for choosing its new runs.
struct RoundScoring {
    surrogate: Surrogate,
    candidates: Candidates,
    likelihood_variance: Vec<Vec<f64>>,
    /// Boundary runs (group, candidate), at most `batch` per group.
    boundary: Vec<(usize, usize)>,
}

/// What a round's samplers need besides the surrogate's posterior.
struct RoundContext<'a> {
    study: &'a Study,
    settings: &'a AdaptiveSettings,
    base_seed: u64,
    round: usize,
    sampling: &'a RoundSampling,
    dir: &'a Path,
    events: &'a Events,
}

/// A round's posterior from its replicates: pooled, with the check of the sampler.
struct ReplicateSampling {
    pooled: PooledPosterior,
    parameters: Vec<String>,
    sampler_check: Option<SamplerAgreement>,
    /// Replicates whose population was carried from the round before.
    carried_replicates: usize,
    /// Surrogate evaluations of all replicates' samplers.
    surrogate_evaluations: usize,
    /// Points all replicates' samplers sent to the surrogate's screen.
    surrogate_screenings: usize,
}

/// One replicate's sampling: its final state and summary moments, with the evaluations its
/// carried population's reweighting spent where it collapsed.
struct ReplicateRun {
    state: BasisState,
    moments: (Vec<f64>, Vec<f64>),
    carried: bool,
    collapsed_evaluations: usize,
}

/// Sample the surrogate `posterior` with the round's replicates, each from its population
/// carried from the round before where `sampling = "sequential"`, `carried` holds one and the
/// reweighting's ESS holds (`iuq_basis::carried_population`), else from the prior; `carried`
/// receives each replicate's new population. Every second replicate mixes a level harder: the
/// check of the sampler. The replicates run side by side (each from its own seed, so the pooled
/// result is the same for any number of threads) and are pooled in their order.
fn sample_replicates(
    ctx: &RoundContext<'_>,
    posterior: &crate::posterior::StudyPosterior,
    carried: &mut [Option<BasisState>],
) -> Result<ReplicateSampling> {
    let mut pooled = PooledPosterior {
        samples: Vec::new(),
        log_likelihood: Vec::new(),
        log_prior: Vec::new(),
        log_evidence: 0.0,
        moments: PosteriorMoments::exact(Vec::new(), Vec::new()),
    };
    let mut parameters = Vec::new();
    let mut replicate_moments = Vec::with_capacity(ctx.settings.replicates);
    let (mut carried_replicates, mut surrogate_evaluations) = (0usize, 0usize);
    let mut surrogate_screenings = 0usize;
    // With two replicates or more, every second one mixes a level harder: the check of the
    // sampler (`iuq_adaptive::sampler_agreement`).
    let checked = ctx.settings.replicates >= 2;
    let previous: Vec<Option<&BasisState>> = (0..ctx.settings.replicates)
        .map(|r| carried.get(r).and_then(Option::as_ref))
        .collect();
    let runs: Vec<Result<ReplicateRun>> = previous
        .par_iter()
        .enumerate()
        .with_max_len(1)
        .map(|(replicate, previous)| {
            sample_replicate(ctx, posterior, replicate, checked, *previous)
        })
        .collect();
    for (replicate, run) in runs.into_iter().enumerate() {
        let run = run?;
        let state = run.state;
        carried_replicates += usize::from(run.carried);
        // A carried state counts its reweighting's evaluations as well as its moves'.
        surrogate_evaluations += run.collapsed_evaluations + state.evaluations;
        surrogate_screenings += state
            .diagnostics
            .iter()
            .map(|d| d.screenings)
            .sum::<usize>();
        if let Some(slot) = carried.get_mut(replicate) {
            *slot = Some(state.clone());
        }
        parameters = state.parameter_names.clone();
        pooled.samples.extend(state.samples);
        pooled.log_likelihood.extend(state.log_likelihood);
        pooled.log_prior.extend(state.log_prior);
        pooled.log_evidence += state.log_evidence / ctx.settings.replicates as f64;
        replicate_moments.push(run.moments);
    }
    pooled.moments = PosteriorMoments::pooled(&replicate_moments).map_err(|e| {
        StudyError::failure(format!("adaptive round {}: {e}", ctx.round)).with_source(e)
    })?;
    let sampler_check = if checked {
        let group = |parity: usize| -> Vec<(Vec<f64>, Vec<f64>)> {
            replicate_moments
                .iter()
                .enumerate()
                .filter(|(r, _)| r % 2 == parity)
                .map(|(_, m)| m.clone())
                .collect()
        };
        let (as_set, harder) = (group(0), group(1));
        Some(
            sampler_agreement(
                &as_set,
                &harder,
                &pooled.moments.std,
                ctx.settings.tolerance,
            )
            .map_err(|e| {
                StudyError::failure(format!("adaptive round {}: {e}", ctx.round)).with_source(e)
            })?,
        )
    } else {
        None
    };
    Ok(ReplicateSampling {
        pooled,
        parameters,
        sampler_check,
        carried_replicates,
        surrogate_evaluations,
        surrogate_screenings,
    })
}

/// Replicate `replicate` of the round: its sampler (seeded by round and replicate, a mixing
/// level harder for every second one where the sampler is `checked`), started from `previous`
/// reweighted to this surrogate where it carries, else from the prior.
fn sample_replicate(
    ctx: &RoundContext<'_>,
    posterior: &crate::posterior::StudyPosterior,
    replicate: usize,
    checked: bool,
    previous: Option<&BasisState>,
) -> Result<ReplicateRun> {
    let harder = u32::from(checked && replicate % 2 == 1);
    let sampler = parse_sampler(
        ctx.study,
        &SamplerOverrides {
            samples: Some(ctx.sampling.samples),
            seed: Some(
                ctx.base_seed
                    .wrapping_add((ctx.round * ctx.settings.replicates + replicate) as u64),
            ),
            ..Default::default()
        },
    )?
    .with_stronger_mixing(ctx.sampling.mixing_level + harder);
    let sampler = match ctx.sampling.burn_in_cap(ctx.settings.samples, harder) {
        Some(cap) => sampler.with_burn_in_cap(cap),
        None => sampler,
    };
    let failure = |e: iuq_basis::BasisError| {
        StudyError::failure(format!("adaptive round {}: {e}", ctx.round)).with_source(e)
    };
    // A population carried from the round before, reweighted to this surrogate (None: the
    // first round, `sampling = "from-prior"`, or an ESS that collapsed).
    let carries = ctx.settings.sampling == PosteriorSampling::Sequential;
    let mut collapsed_evaluations = 0;
    let start = match previous.filter(|_| carries) {
        Some(previous) => {
            let basis = Basis::new(&posterior.space, posterior.likelihood.as_ref(), sampler)
                .map_err(failure)?;
            match carry(&basis, previous).map_err(failure)? {
                Carried::Ready(state) => Some(*state),
                Carried::Collapsed { ess_fraction } => {
                    collapsed_evaluations = previous.samples.len();
                    ctx.events.message(format!(
                        "adaptive round {}: replicate {}: the previous population's ESS fell to {:.1} % under this surrogate; annealing from the prior",
                        ctx.round,
                        replicate + 1,
                        100.0 * ess_fraction
                    ));
                    None
                }
            }
        }
        None => None,
    };
    let carried = start.is_some();
    let sampled = ctx.events.sample(
        ROUND_LABEL,
        ctx.study,
        posterior,
        sampler,
        &ctx.dir
            .join(format!("round-{}", ctx.round))
            .join(format!("replicate-{}", replicate + 1)),
        start,
    )?;
    Ok(ReplicateRun {
        state: sampled.run.state,
        moments: (sampled.summary.mean, sampled.summary.std),
        carried,
        collapsed_evaluations,
    })
}

/// The surrogate at the candidates: each output's prediction and, per candidate and output, the
/// likelihood's variance with the GP's latent variance and without it.
#[derive(Clone, Copy)]
struct CandidatePredictions<'a> {
    predictions: &'a [iuq_gp::Prediction],
    likelihood_variance: &'a [Vec<f64>],
    sampled_variance: &'a [Vec<f64>],
}

/// ε and ε_g per run group: the typical change of the posterior moments, in posterior stds,
/// over [`SURROGATE_ERROR_DRAWS`] joint draws of the GPs' error at the candidates `c`
/// (`iuq_adaptive::moment_error`; through the components where the emulator is a reduced basis).
fn surrogate_errors(
    emulator: &super::emulator::Emulator,
    at: &CandidatePredictions<'_>,
    data: &DataLikelihood,
    c: &Candidates,
    group_outputs: &[std::ops::Range<usize>],
    seed: u64,
) -> Result<(iuq_adaptive::MomentError, Vec<f64>)> {
    let CandidatePredictions {
        predictions,
        likelihood_variance,
        sampled_variance,
    } = *at;
    let outputs = predictions.len();
    // ε: how far the GPs' error could move the posterior moments, over joint draws of it.
    let mut residuals = Vec::with_capacity(outputs);
    let mut variances = Vec::with_capacity(outputs);
    let mut sampled_variances = Vec::with_capacity(outputs);
    // Per output, its GP's covariance over the candidates (the outputs in parallel); a reduced
    // basis's outputs carry none (their errors are drawn through the components').
    let covariances: Vec<Vec<Vec<f64>>> = emulator
        .output_covariances(&c.theta)?
        .unwrap_or_else(|| vec![Vec::new(); outputs]);
    for (j, p) in predictions.iter().enumerate() {
        let y = data.observations.values[j];
        residuals.push(p.mean.iter().map(|m| y - m).collect::<Vec<f64>>());
        variances.push(
            likelihood_variance
                .iter()
                .map(|v| v[j])
                .collect::<Vec<f64>>(),
        );
        sampled_variances.push(sampled_variance.iter().map(|v| v[j]).collect::<Vec<f64>>());
    }
    let terms: Vec<MomentTerm<'_>> = (0..outputs)
        .map(|j| MomentTerm {
            residual: &residuals[j],
            variance: &variances[j],
            sampled_variance: &sampled_variances[j],
            covariance: &covariances[j],
        })
        .collect();
    let (surrogate_error, group_errors) = match emulator.reduced_basis() {
        None => sampled_moment_errors_by_group(
            &c.full,
            &c.copies,
            &terms,
            group_outputs,
            SURROGATE_ERROR_DRAWS,
            seed,
        ),
        Some(basis) => {
            let component_covariances = basis
                .component_gps()
                .par_iter()
                .map(|gp| gp.posterior_covariance(&c.theta, &c.theta))
                .collect::<iuq_gp::Result<Vec<_>>>()?;
            let loadings: Vec<Vec<f64>> = (0..outputs)
                .map(|j| {
                    (0..basis.components())
                        .map(|k| basis.loading(j, k))
                        .collect()
                })
                .collect();
            sampled_moment_errors_by_group_from_components(
                &c.full,
                &c.copies,
                &terms,
                ComponentErrors {
                    covariances: &component_covariances,
                    loadings: &loadings,
                },
                group_outputs,
                SURROGATE_ERROR_DRAWS,
                seed,
            )
        }
    }
    .map_err(|e| StudyError::failure(e.to_string()).with_source(e))?;
    let group_surrogate_error: Vec<f64> = group_errors.iter().map(|e| e.largest()).collect();
    Ok((surrogate_error, group_surrogate_error))
}

/// u: the posterior mean of the surrogate's std of the log-likelihood at the candidates, each
/// weighted by the `copies` of the population it stands for (`iuq_adaptive::acquisition`).
fn posterior_log_likelihood_std(
    data: &DataLikelihood,
    predictions: &[iuq_gp::Prediction],
    likelihood_variance: &[Vec<f64>],
    copies: &[f64],
) -> f64 {
    let spread: Vec<f64> = (0..likelihood_variance.len())
        .map(|i| {
            predictions
                .iter()
                .enumerate()
                .map(|(j, p)| {
                    log_likelihood_variance(
                        data.observations.values[j],
                        p.mean[i],
                        p.variance[i],
                        likelihood_variance[i][j],
                    )
                })
                .sum()
        })
        .collect();
    surrogate_log_likelihood_std(&spread, copies)
}

/// Where a classifier is unsure over the posterior, runs on the boundary of its failure region
/// (the acquisition does not go there: the GPs are sure of their extrapolation, the classifier
/// is not): the largest unsure share over the run groups, and up to `per_group` boundary picks
/// (group, candidate) each. They are made only once the GPs are sure where the posterior lies
/// (the caller's decision): before, the posterior is not yet where it will be, and far from
/// every run the classifier is unsure of everything.
fn failure_boundaries(
    surrogate: &Surrogate,
    groups: &[GroupRuns],
    candidates: &[Vec<f64>],
    posterior_std: &[f64],
    per_group: usize,
) -> Result<(f64, Vec<(usize, usize)>)> {
    let mut boundary: Vec<(usize, usize)> = Vec::new();
    let mut unsure_share: f64 = 0.0;
    for (g, group) in groups.iter().enumerate() {
        if surrogate.classifiers[g].is_none() {
            continue;
        }
        let p_fail = surrogate.group_failure_probability(g, candidates)?;
        let (_, failed) = group.failure_labels();
        let (share, picks) = boundary_picks(
            &p_fail,
            candidates,
            &group.points,
            &failed,
            posterior_std,
            per_group,
        );
        unsure_share = unsure_share.max(share);
        boundary.extend(picks.into_iter().map(|i| (g, i)));
    }
    Ok((unsure_share, boundary))
}

/// Fit the surrogate of `groups`, sample its posterior with the replicates, and measure the
/// round: moments, u, ε, extrapolation, the failure boundaries.
fn measure_round(
    inputs: &RoundInputs<'_>,
    round: usize,
    sampling: &RoundSampling,
    groups: &[GroupRuns],
    carry: &mut RoundCarry,
) -> Result<(RoundMeasurement, RoundScoring)> {
    let RoundInputs {
        study,
        data,
        settings,
        emulation,
        training_seed,
        base_seed,
        runs,
        dir,
        events,
        describe,
        ..
    } = *inputs;
    let d = study.space.dimension();
    let modelling_error = data.modelling_error.is_some();
    let surrogate = Surrogate::fit(
        groups,
        runs,
        inputs.low_fidelity,
        &study.space,
        GpStarts {
            seed: training_seed,
            warm: carry.warm_starts.as_deref(),
        },
        emulation,
        describe,
    )?;
    carry.warm_starts = surrogate.emulator.warm_starts();
    let posterior = build_posterior_with(study, || Ok(surrogate.clone()))?;
    let context = RoundContext {
        study,
        settings,
        base_seed,
        round,
        sampling,
        dir,
        events,
    };
    let ReplicateSampling {
        pooled,
        parameters,
        sampler_check,
        carried_replicates,
        surrogate_evaluations,
        surrogate_screenings,
    } = sample_replicates(&context, &posterior, &mut carry.populations)?;
    let moments = pooled.moments.clone();
    let state = &pooled;
    // The measurement (u, ε) is made on `candidates` distinct samples; a round that looks wider
    // for runs (after one that found none worth making) scores more of them below, without
    // making ε, whose cost grows with the cube of the candidates, dearer.
    let c = candidates(state, d, modelling_error, data, settings.candidates);
    // The surrogate's predictions at the candidates, per data point.
    let emulator = &surrogate.emulator;
    let predictions = emulator.predict(&c.theta)?;
    let outputs = predictions.len();
    let unresolved: Vec<f64> = (0..outputs)
        .map(|j| emulator.unresolved_variance(j))
        .collect();
    let likelihood_variance = likelihood_variances(data, &predictions, &unresolved, &c.variance);
    let sampled_variance = sampled_likelihood_variances(
        data,
        &predictions,
        emulator.predictive_std(),
        &unresolved,
        &c.variance,
    );
    let u = posterior_log_likelihood_std(data, &predictions, &likelihood_variance, &c.copies);
    // ε, and ε_g: the same measure with only group g's likelihood terms (its share of the runs).
    let group_outputs: Vec<std::ops::Range<usize>> =
        (0..groups.len()).map(|g| runs.group_outputs(g)).collect();
    let at_candidates = CandidatePredictions {
        predictions: &predictions,
        likelihood_variance: &likelihood_variance,
        sampled_variance: &sampled_variance,
    };
    let (surrogate_error, group_surrogate_error) = surrogate_errors(
        emulator,
        &at_candidates,
        data,
        &c,
        &group_outputs,
        base_seed.wrapping_add(round as u64),
    )
    .map_err(|e| match e {
        StudyError::Failure(_) => e.context(format_args!("adaptive round {round}")),
        other => other,
    })?;
    let posterior_theta: Vec<Vec<f64>> = state.samples.iter().map(|s| s[..d].to_vec()).collect();
    let extrapolation = posterior_extrapolation(emulator, &posterior_theta)?;
    let (c, likelihood_variance) = if sampling.candidates > settings.candidates {
        let wide = candidates(state, d, modelling_error, data, sampling.candidates);
        let predictions = emulator.predict(&wide.theta)?;
        let variance = likelihood_variances(data, &predictions, &unresolved, &wide.variance);
        (wide, variance)
    } else {
        (c, likelihood_variance)
    };
    let (unsure_share, boundary) = failure_boundaries(
        &surrogate,
        groups,
        &c.theta,
        &moments.std[..d],
        settings.batch.max(1),
    )?;
    let measurement = RoundMeasurement {
        parameters,
        mean: moments.mean,
        std: moments.std,
        mean_error: moments.mean_error,
        std_error: moments.std_error,
        log_likelihood_std: u,
        surrogate_error: surrogate_error.largest(),
        log_evidence_error: surrogate_error.log_evidence,
        group_surrogate_error,
        extrapolation_share: extrapolation,
        unsure_share,
        log_evidence: state.log_evidence,
        boundary_wanted: !boundary.is_empty(),
        sampler_agreement: sampler_check,
        carried_replicates,
        surrogate_evaluations,
        surrogate_screenings,
    };
    Ok((
        measurement,
        RoundScoring {
            surrogate,
            candidates: c,
            likelihood_variance,
            boundary,
        },
    ))
}

/// What every round of one [`refine`] reads: the study, its data and settings, the campaign and
/// where the rounds' files go.
pub(super) struct RoundInputs<'a> {
    pub(super) study: &'a Study,
    pub(super) data: &'a DataLikelihood,
    pub(super) settings: &'a AdaptiveSettings,
    pub(super) emulation: &'a Emulation,
    /// Seed of the training designs (the GPs' fits are seeded by it).
    pub(super) training_seed: u64,
    /// The `[sampler]` seed, from which every round's replicates are seeded.
    pub(super) base_seed: u64,
    pub(super) runs: &'a ModelRuns,
    /// The cheap model of `[low_fidelity]`, if any.
    pub(super) low_fidelity: Option<&'a LowFidelity>,
    /// `adaptive/` of the report folder.
    pub(super) dir: &'a Path,
    pub(super) events: &'a Events,
    /// The run's description, for the surrogate's messages.
    pub(super) describe: &'a dyn Fn(usize) -> String,
    /// Measure every round again rather than read its recorded measurement.
    pub(super) recompute: bool,
}

impl RoundInputs<'_> {
    /// Whether the rounds' populations are kept (in the store and for the next round): to carry
    /// them (`sampling = "sequential"`) or to measure the distance between rounds.
    fn keeps_populations(&self) -> bool {
        self.settings.sampling == PosteriorSampling::Sequential
            || self.settings.stopping_rule == StoppingRule::Distribution
    }
}

/// A round as measured or read back: its measurement, what choosing runs needs (a freshly
/// measured round only) and its fingerprint.
struct MeasuredRound {
    measurement: RoundMeasurement,
    scoring: Option<RoundScoring>,
    fingerprint: String,
}

/// The samples of every replicate's population, where each is known.
fn populations_of(carried: &[Option<BasisState>]) -> Option<Vec<Vec<Vec<f64>>>> {
    carried
        .iter()
        .map(|s| s.as_ref().map(|s| s.samples.clone()))
        .collect()
}

impl RoundMeasurement {
    fn reading(&self, populations: Option<Vec<Vec<Vec<f64>>>>, runs: usize) -> RoundReading<'_> {
        RoundReading {
            moments: self.moments(),
            log_likelihood_std: self.log_likelihood_std,
            surrogate_error: self.surrogate_error,
            boundary_wanted: self.boundary_wanted,
            sampler_agreement: self.sampler_agreement.as_ref(),
            populations,
            runs,
        }
    }
}

/// What one round hands the next.
struct RoundCarry {
    /// Each replicate's population (`sampling = "sequential"`; `None`: anneal from the prior).
    populations: Vec<Option<BasisState>>,
    /// The fingerprint of the round the populations come from.
    from: Option<String>,
    /// Each data point's GP θ, the next fit's warm starts ([`GpStarts`]).
    warm_starts: Option<Vec<Vec<f64>>>,
}

/// Round `state.round`'s measurement: read back from the store where it was recorded for the
/// same inputs and nothing new is to be chosen from it (the round stops, or its runs are
/// recorded), else measured (the surrogate fitted, its posterior sampled) and recorded.
/// `carry` holds what the round before handed on (populations, warm starts) and receives this
/// round's.
fn measure_or_read_round(
    inputs: &RoundInputs<'_>,
    engine: &AdaptiveEngine,
    state: &EngineState,
    groups: &[GroupRuns],
    carry: &mut RoundCarry,
    runs_recorded: bool,
) -> Result<MeasuredRound> {
    let round = state.round;
    let label = format!("adaptive-round-{round}");
    let made: usize = groups.iter().map(GroupRuns::len).sum();
    let fingerprint = round_fingerprint(inputs, &state.sampling, groups, carry.from.as_deref())?;
    let key = format!("{label}/assessment");
    let population_key = format!("{label}/population");
    let warm_starts_key = format!("{label}/warm-starts");
    let runs = inputs.runs;
    let cached = runs
        .derived_result(&key, &fingerprint)?
        .and_then(|text| serde_json::from_str::<RoundMeasurement>(&text).ok());
    if let Some(m) = cached.as_ref().filter(|_| !inputs.recompute) {
        let recorded_populations = if inputs.keeps_populations() {
            runs.derived_result(&population_key, &fingerprint)?
                .and_then(|text| serde_json::from_str::<Vec<Option<BasisState>>>(&text).ok())
                .filter(|states| states.len() == inputs.settings.replicates)
        } else {
            None
        };
        let populations = recorded_populations.as_deref().and_then(populations_of);
        let stops = engine
            .judge(state, &m.reading(populations, made))
            .map_err(|e| {
                StudyError::failure(format!("adaptive round {round}: {e}")).with_source(e)
            })?
            .stop
            .is_some();
        if stops || runs_recorded {
            let fresh = vec![None; inputs.settings.replicates];
            carry
                .populations
                .clone_from_slice(&recorded_populations.unwrap_or(fresh));
            carry.warm_starts = match runs.derived_result(&warm_starts_key, &fingerprint)? {
                Some(text) => match serde_json::from_str(&text) {
                    Ok(warm_starts) => Some(warm_starts),
                    Err(e) => {
                        inputs.events.message(format!(
                            "adaptive round {round}: the recorded GP optima do not parse ({e}); the next round's GPs are fitted without warm starts"
                        ));
                        None
                    }
                },
                None => None,
            };
            return Ok(MeasuredRound {
                measurement: m.clone(),
                scoring: None,
                fingerprint,
            });
        }
    }
    let (m, scoring) = measure_round(inputs, round, &state.sampling, groups, carry)?;
    // Recorded before the assessment: a round read back from the store has its warm starts.
    if let Some(warm_starts) = &carry.warm_starts {
        let text = serde_json::to_string(warm_starts).map_err(|e| {
            StudyError::failure(format!(
                "adaptive round {round}: cannot record the GPs' hyper-parameters: {e}"
            ))
            .with_source(e)
        })?;
        runs.record_derived_result(&warm_starts_key, &fingerprint, &text)?;
    }
    if inputs.keeps_populations() {
        let text = serde_json::to_string(&carry.populations).map_err(|e| {
            StudyError::failure(format!(
                "adaptive round {round}: cannot record the population: {e}"
            ))
            .with_source(e)
        })?;
        runs.record_derived_result(&population_key, &fingerprint, &text)?;
    }
    if let Some(old) = cached.as_ref().filter(|old| **old != m) {
        inputs.events.message(format!(
            "adaptive round {round}: the recomputed assessment differs from the one recorded in the store (surrogate error {} vs {}, log evidence {} vs {}); the new one is recorded",
            m.surrogate_error, old.surrogate_error, m.log_evidence, old.log_evidence
        ));
    }
    let text = serde_json::to_string(&m).map_err(|e| {
        StudyError::failure(format!("adaptive round {round}: cannot record: {e}")).with_source(e)
    })?;
    runs.record_derived_result(&key, &fingerprint, &text)?;
    Ok(MeasuredRound {
        measurement: m,
        scoring: Some(scoring),
        fingerprint,
    })
}

impl AdaptiveRound {
    /// Count the round's new runs of the study's model, in all and per run group.
    fn count_new_runs(&mut self, requests: &[(usize, Vec<f64>)]) {
        for (g, _) in requests {
            self.new_runs_per_group[*g] += 1;
        }
        self.new_runs = requests.len();
    }

    /// The round's moments and sampling, for an engine that goes on after it.
    fn resumed(&self, settings: &AdaptiveSettings) -> (PosteriorMoments, RoundSampling) {
        (
            PosteriorMoments {
                mean: self.mean.clone(),
                std: self.std.clone(),
                mean_error: self.mean_error.clone(),
                std_error: self.std_error.clone(),
            },
            RoundSampling {
                samples: self.samples / settings.replicates.max(1),
                candidates: self.candidates,
                mixing_level: self.mixing_level,
            },
        )
    }

    /// The round as judged, before its runs are made.
    fn judged(
        round: usize,
        runs: usize,
        measured: &RoundMeasurement,
        judgement: &Judgement,
        sampling: &RoundSampling,
        settings: &AdaptiveSettings,
        groups: usize,
    ) -> Self {
        let m = measured;
        Self {
            round,
            runs,
            new_runs: 0,
            new_runs_per_group: vec![0; groups],
            samples: sampling.samples * settings.replicates,
            mean: m.mean.clone(),
            std: m.std.clone(),
            mean_error: m.mean_error.clone(),
            std_error: m.std_error.clone(),
            shift: judgement.assessment.shift,
            shift_noise: judgement.assessment.noise,
            distance: judgement.distance.as_ref().map(|d| d.distance),
            distance_noise: judgement.distance.as_ref().map(|d| d.noise),
            log_likelihood_std: m.log_likelihood_std,
            surrogate_error: m.surrogate_error,
            log_evidence_error: m.log_evidence_error,
            group_surrogate_error: m.group_surrogate_error.clone(),
            extrapolation_share: m.extrapolation_share,
            unsure_share: m.unsure_share,
            log_evidence: m.log_evidence,
            mixing_level: sampling.mixing_level,
            sampler_agreement: m.sampler_agreement.clone(),
            candidates: sampling.candidates,
            converged: judgement.converged,
            seconds: 0.0,
            carried_replicates: m.carried_replicates,
            surrogate_evaluations: m.surrogate_evaluations,
            surrogate_screenings: m.surrogate_screenings,
            new_low_fidelity_runs: None,
        }
    }
}

/// The round's line in the log: what it measured and what it does next.
fn round_message(
    round: usize,
    made: usize,
    m: &RoundMeasurement,
    j: &Judgement,
    requests: usize,
    candidates: usize,
) -> String {
    let shown = |v: Option<f64>| v.map_or("-".to_string(), |s| format!("{s:.3}"));
    format!(
        "adaptive round {round}: {made} runs so far; posterior shift {}, distance {} (sampler noise {}), surrogate error {:.3} posterior stds, surrogate log-likelihood std {:.3}, {:.0} % of the posterior extrapolated; {}",
        shown(j.assessment.shift),
        shown(j.distance.as_ref().map(|d| d.distance)),
        shown(j.noise()),
        j.assessment.surrogate_error,
        m.log_likelihood_std,
        100.0 * m.extrapolation_share,
        match (&j.stop, requests) {
            (Some(reason), _) => format!("stop: {reason}"),
            (None, 0) => format!("no candidate run is worth making among {candidates} candidates"),
            (None, n) => format!("{n} new runs"),
        }
    )
}

/// The engine's observer in the pipeline: the notes after a round's step into the pipeline's
/// log, and a Ctrl-C as [`Control::Stop`].
struct RoundLog<'a> {
    events: &'a Events,
}

impl Observer<RoundEvent<'_>> for RoundLog<'_> {
    fn observe(&mut self, event: &RoundEvent<'_>) -> Control {
        let (round, state) = (event.round, event.state);
        if event.judgement.sampler_disagrees && event.judgement.stop.is_none() {
            self.events.message(format!(
                "adaptive round {round}: the replicates that mixed harder differ by {:.3} posterior stds: not converged; the rounds from the next sample at mixing level {}",
                event.judgement.sampler_disagreement, state.sampling.mixing_level
            ));
        } else if event.new_runs == 0 && state.stop_reason.is_none() {
            self.events.message(format!(
                "adaptive round {round}: no candidate run is worth making, although the rule does not hold; the next round looks among {} candidates from {} samples per replicate",
                state.sampling.candidates, state.sampling.samples
            ));
        }
        if self.events.check_interrupt().is_err() {
            Control::Stop
        } else {
            Control::Continue
        }
    }
}

/// Run the requests of round `round` through the campaign and add them to `groups` and to the
/// rows of `adaptive/runs.csv`.
fn make_round_runs(
    inputs: &RoundInputs<'_>,
    round: usize,
    requests: Vec<(usize, Vec<f64>)>,
    groups: &mut [GroupRuns],
    rows: &mut Vec<Vec<f64>>,
) -> Result<()> {
    if requests.is_empty() {
        return Ok(());
    }
    // A two-fidelity round's expensive runs get a label of their own, so that a store shared
    // with a one-fidelity calibration of the same model (its runs reused) keeps that one's
    // rounds as they were.
    let label = if inputs.low_fidelity.is_some() {
        format!("two-fidelity-round-{round}")
    } else {
        format!("adaptive-round-{round}")
    };
    let outcomes = inputs.runs.run(Some(&label), &requests)?;
    for ((g, theta), outcome) in requests.iter().zip(&outcomes) {
        let mut row = vec![round as f64, *g as f64];
        row.extend(theta);
        row.push(if outcome.is_ok() { 0.0 } else { 1.0 });
        rows.push(row);
    }
    write_runs_table(inputs.study, inputs.dir, rows)?;
    let mut per_group: Vec<(Vec<Vec<f64>>, Vec<iuq_core::Outcome>)> =
        vec![(Vec::new(), Vec::new()); groups.len()];
    for ((g, theta), outcome) in requests.into_iter().zip(outcomes) {
        per_group[g].0.push(theta);
        per_group[g].1.push(outcome);
    }
    for (group, (points, outcomes)) in groups.iter_mut().zip(per_group) {
        group.extend(RunOrigin::Adaptive { round }, points, outcomes);
    }
    Ok(())
}

/// The runs an earlier pipeline chose in round `round`, if the stores have them: the design
/// `adaptive-round-<round>` of the study's store, or with a `[low_fidelity]` the allocation
/// recorded for the round (both fidelities' runs).
fn recorded_allocation(inputs: &RoundInputs<'_>, round: usize) -> Result<Option<Allocation>> {
    if inputs.low_fidelity.is_none() {
        let recorded = inputs
            .runs
            .recorded_requests(&format!("adaptive-round-{round}"))?;
        return Ok(recorded.map(|high| Allocation {
            high,
            low: Vec::new(),
        }));
    }
    let Some(text) = inputs
        .runs
        .derived_result(&allocation_key(round), ALLOCATION_FINGERPRINT)?
    else {
        return Ok(None);
    };
    serde_json::from_str(&text).map(Some).map_err(|e| {
        StudyError::failure(format!(
            "adaptive round {round}: the allocation recorded in the store cannot be read: {e}"
        ))
        .with_source(e)
    })
}

/// Run round `round`'s cheap runs (`[low_fidelity]`), their count in the round's record and
/// its log line.
fn run_cheap_round(
    inputs: &RoundInputs<'_>,
    round: usize,
    record: &mut AdaptiveRound,
    message: &mut String,
    requests: Vec<(usize, Vec<f64>)>,
) -> Result<()> {
    let Some(low) = inputs.low_fidelity else {
        return Ok(());
    };
    record.new_low_fidelity_runs = Some(requests.len());
    message.push_str(&format!(
        " ({} low-fidelity runs so far, {} new)",
        low.runs_made()?,
        requests.len()
    ));
    low.run_round(round, requests)
}

/// The fingerprint under which a round's allocation is recorded: the round's runs are replayed
/// as chosen, whatever the measurement computes now (as the design of a one-fidelity round is).
const ALLOCATION_FINGERPRINT: &str = "allocation";

/// The runs `wanted` of the study's model, split between the fidelities where there is a
/// `[low_fidelity]` (`low_fidelity::LowFidelity::allocate`) and that split recorded before any
/// of them runs (a rerun after kill -9 makes the same runs).
fn allocate(
    inputs: &RoundInputs<'_>,
    surrogate: &Surrogate,
    round: usize,
    wanted: Vec<(usize, Vec<f64>)>,
) -> Result<Allocation> {
    let emulator = &surrogate.emulator;
    let Some(low) = inputs.low_fidelity.filter(|_| emulator.is_two_fidelity()) else {
        return Ok(Allocation {
            high: wanted,
            low: Vec::new(),
        });
    };
    let ratio = low.cost_ratio(inputs.runs)?;
    let variance = |j: usize| total_variance(inputs.data, j, None).max(f64::MIN_POSITIVE);
    let split = |j: usize, theta: &[f64]| emulator.fidelity_variances(j, theta);
    let allocation = low.allocate(&split, inputs.runs, &variance, wanted, ratio)?;
    let text = serde_json::to_string(&allocation).map_err(|e| {
        StudyError::failure(format!("cannot record the allocation: {e}")).with_source(e)
    })?;
    inputs
        .runs
        .record_derived_result(&allocation_key(round), ALLOCATION_FINGERPRINT, &text)?;
    Ok(allocation)
}

/// The engine's settings from the study's `[surrogate] adaptive`.
fn engine_settings(settings: &AdaptiveSettings) -> EngineSettings {
    EngineSettings {
        criterion: ConvergenceCriterion {
            tolerance: settings.tolerance,
            log_likelihood_tolerance: settings.log_likelihood_tolerance,
            surrogate_error_multiple: settings.surrogate_error_multiple,
        },
        stopping_rule: settings.stopping_rule,
        max_runs: settings.max_runs,
        max_rounds: settings.max_rounds,
        samples: settings.samples,
        exploring_samples: settings.exploring_samples,
        max_samples: settings.max_samples,
        candidates: settings.candidates,
        more_samples: settings.more_samples,
        max_mixing_level: MAX_MIXING_LEVEL,
        makes_runs: settings.batch > 0,
    }
}

/// Run the adaptive engine on `groups` (holding the initial and test runs), adding its runs to
/// them. `inputs.dir` receives `round-<k>/` (each round's BASIS results), `rounds.json` (the
/// rounds' summaries) and `runs.csv` (every new run: round, run group from 0, θ, and 1 where it
/// failed).
pub(super) fn refine(
    inputs: &RoundInputs<'_>,
    groups: &mut [GroupRuns],
    earlier: Option<AdaptiveOutcome>,
) -> Result<AdaptiveOutcome> {
    let RoundInputs {
        study,
        data,
        settings,
        runs,
        dir,
        events,
        ..
    } = *inputs;
    let engine = AdaptiveEngine::new(engine_settings(settings))
        .bad_input(|| format!("{}: key `surrogate.adaptive`", study.path.display()))?;
    std::fs::create_dir_all(dir).map_err(|e| {
        StudyError::failure(format!("cannot create {}: {e}", dir.display())).with_source(e)
    })?;
    let choice = RunChoice::new(data, settings, runs, groups.len());
    // Going on after a failed check: from the round after the last, its moments the previous
    // ones (the shift then measures what the check's runs changed).
    let first_round = earlier.as_ref().map_or(1, |e| e.last_round() + 1);
    let AdaptiveOutcome {
        mut rounds,
        retrained_checks,
        run_rows: mut new_rows,
        mut parameters,
        populations: last_populations,
        ..
    } = earlier.unwrap_or_default();
    if !new_rows.is_empty() {
        write_runs_table(study, dir, &new_rows)?;
    }
    let mut state = engine.start(first_round, rounds.last().map(|r| r.resumed(settings)));
    state.previous_populations = last_populations;
    let mut observer = RoundLog { events };
    // Each replicate's population, carried from round to round (`sampling = "sequential"`),
    // and the fingerprint of the round it comes from.
    let sequential = settings.sampling == PosteriorSampling::Sequential;
    let mut carry = RoundCarry {
        populations: vec![None; settings.replicates],
        from: None,
        warm_starts: None,
    };
    while state.stop_reason.is_none() {
        events.check_interrupt()?;
        let round = state.round;
        let started = Instant::now();
        let made: usize = groups.iter().map(GroupRuns::len).sum();
        // A round an earlier pipeline already chose (the same study, a rerun after a stop) is
        // replayed from the store as it was chosen, bit for bit, even where recomputing the
        // choice would differ in the last bits (another processor, another library version).
        let recorded = recorded_allocation(inputs, round)?;
        let MeasuredRound {
            measurement: measured,
            scoring,
            fingerprint,
        } = measure_or_read_round(
            inputs,
            &engine,
            &state,
            groups,
            &mut carry,
            recorded.is_some(),
        )?;
        if sequential {
            carry.from = carry
                .populations
                .iter()
                .any(Option::is_some)
                .then(|| fingerprint.clone());
        }
        parameters = measured.parameters.clone();
        let populations = if inputs.keeps_populations() {
            populations_of(&carry.populations)
        } else {
            None
        };
        let reading = measured.reading(populations, made);
        let judgement = engine.judge(&state, &reading).map_err(|e| {
            StudyError::failure(format!("adaptive round {round}: {e}")).with_source(e)
        })?;
        let mut record = AdaptiveRound::judged(
            round,
            made,
            &measured,
            &judgement,
            &state.sampling,
            settings,
            groups.len(),
        );
        let Allocation {
            high: requests,
            low: low_requests,
        } = match (&judgement.stop, recorded, &scoring) {
            (Some(_), _, _) => Allocation::default(),
            (None, Some(recorded), _) => recorded,
            (None, None, scoring) => {
                let scoring = scoring.as_ref().ok_or_else(|| {
                    StudyError::failure(format!(
                        "adaptive round {round}: no surrogate to choose runs from"
                    ))
                })?;
                let remaining = settings.max_runs - made;
                let errors = &measured.group_surrogate_error;
                let wanted =
                    choose_runs(&choice, scoring, errors, judgement.boundary_due, remaining)?;
                allocate(inputs, &scoring.surrogate, round, wanted)?
            }
        };
        record.count_new_runs(&requests);
        let candidates = state.sampling.candidates;
        let mut message = round_message(
            round,
            made,
            &measured,
            &judgement,
            requests.len(),
            candidates,
        );
        let cheap_runs = low_requests.len();
        run_cheap_round(inputs, round, &mut record, &mut message, low_requests)?;
        events.message(message);
        make_round_runs(inputs, round, requests, groups, &mut new_rows)?;
        record.seconds = started.elapsed().as_secs_f64();
        let new_runs = record.new_runs + cheap_runs;
        rounds.push(record);
        write_rounds(dir, &rounds)?;
        engine.step(&mut state, reading, &judgement, new_runs);
        let event = RoundEvent {
            round,
            judgement: &judgement,
            new_runs,
            state: &state,
        };
        if observer.observe(&event) == Control::Stop {
            return Err(StudyError::Interrupted);
        }
    }
    Ok(AdaptiveOutcome::ended(
        inputs,
        state,
        rounds,
        parameters,
        retrained_checks,
        new_rows,
        carry,
    ))
}

impl AdaptiveOutcome {
    /// The outcome of a loop over `inputs` that ended in `state`, with its rounds (the earlier
    /// loop's included), parameters, retrained checks, rows of `runs.csv` and what the last
    /// round handed on: its GP optima and, where the final sample starts from them
    /// ([`FinalSample::Carried`], the populations kept in the store), its populations.
    fn ended(
        inputs: &RoundInputs<'_>,
        state: EngineState,
        rounds: Vec<AdaptiveRound>,
        parameters: Vec<String>,
        retrained_checks: Vec<RetrainedCheck>,
        run_rows: Vec<Vec<f64>>,
        carry: RoundCarry,
    ) -> Self {
        let settings = inputs.settings;
        let final_populations = (settings.final_sample == FinalSample::Carried
            && inputs.keeps_populations())
        .then(|| carry.populations.into_iter().collect::<Option<Vec<_>>>())
        .flatten();
        let warm_starts = carry.warm_starts;
        Self {
            rounds,
            converged: state.converged,
            stop_reason: state.stop_reason.unwrap_or_default(),
            parameters,
            tolerance: settings.tolerance,
            log_likelihood_tolerance: settings.log_likelihood_tolerance,
            surrogate_error_multiple: settings.surrogate_error_multiple,
            retrained_checks,
            mixing_level: state.sampling.mixing_level,
            run_rows,
            populations: state.previous_populations,
            warm_starts,
            final_populations,
        }
    }
}

/// What choosing a round's runs needs besides the round's scoring: the same every round.
#[derive(Clone, Copy)]
struct RunChoice<'a> {
    data: &'a DataLikelihood,
    settings: &'a AdaptiveSettings,
    runs: &'a ModelRuns,
    /// Run groups.
    groups: usize,
    /// The least density score worth a run (per group).
    min_score: f64,
    /// The least moment score worth a run (per group).
    min_moment_score: f64,
}

impl<'a> RunChoice<'a> {
    fn new(
        data: &'a DataLikelihood,
        settings: &'a AdaptiveSettings,
        runs: &'a ModelRuns,
        groups: usize,
    ) -> Self {
        let shared = groups.max(1) as f64;
        Self {
            data,
            settings,
            runs,
            groups,
            min_score: (settings.log_likelihood_tolerance / 2.0).powi(2) / shared,
            // A run must shrink the summed squared moment error by a hundredth of tolerance²,
            // shared among the run groups.
            min_moment_score: (settings.tolerance / 10.0).powi(2) / shared,
        }
    }
}

/// A round's new runs (run group, θ), in group order and, within a group, in the order they were
/// picked: per group up to its share of `batch` by ε_g² (`iuq_adaptive::allocation`), its
/// boundary runs first when `boundary_due`, then the greedy batch of the study's acquisition; at
/// most `batch` per group and `remaining` in all, the best scores first.
fn choose_runs(
    choice: &RunChoice<'_>,
    scoring: &RoundScoring,
    group_surrogate_error: &[f64],
    boundary_due: bool,
    remaining: usize,
) -> Result<Vec<(usize, Vec<f64>)>> {
    let RoundScoring {
        surrogate,
        candidates: c,
        likelihood_variance,
        boundary,
    } = scoring;
    let boundary: &[(usize, usize)] = if boundary_due { boundary } else { &[] };
    let RunChoice {
        data,
        settings,
        runs,
        groups,
        min_score,
        min_moment_score,
    } = *choice;
    let views = surrogate.emulator.output_views();
    // Each group's share of the round's runs follows its share of ε².
    let group_batch = if group_surrogate_error.len() == groups {
        group_batches(settings.batch, group_surrogate_error)
    } else {
        vec![settings.batch; groups]
    };
    // (score, group, order within the group's batch, candidate index)
    let mut picks: Vec<(f64, usize, usize, usize)> = Vec::new();
    for g in 0..groups {
        let outputs = runs.group_outputs(g);
        let terms: Vec<LikelihoodTerm<'_>> = outputs
            .map(|j| LikelihoodTerm {
                gp: &views[j],
                datum: data.observations.values[j],
                total_variance: likelihood_variance.iter().map(|v| v[j]).collect(),
            })
            .collect();
        let p_answer: Vec<f64> = surrogate
            .group_failure_probability(g, &c.theta)?
            .into_iter()
            .map(|p| 1.0 - p)
            .collect();
        let selection = match settings.acquisition {
            Acquisition::Density => select_batch(
                &terms,
                &c.theta,
                &likelihood_weights(&c.log_density, &p_answer),
                group_batch[g].min(remaining),
                min_score,
            )?,
            Acquisition::Moments => match surrogate.emulator.reduced_basis() {
                None => select_batch_for_moments(
                    &terms,
                    &c.theta,
                    &c.full,
                    &c.copies,
                    &p_answer,
                    group_batch[g].min(remaining),
                    min_moment_score,
                )?,
                // The first-order error through the components: δℓ = Σ_k a_k δc_k.
                Some(basis) => select_batch_for_moments_by_sensitivity(
                    &component_sensitivities(basis, &terms, runs.group_outputs(g), &c.theta)?,
                    &c.theta,
                    &c.full,
                    &c.copies,
                    &p_answer,
                    group_batch[g].min(remaining),
                    min_moment_score,
                )?,
            },
        };
        for (order, (&i, &score)) in selection.indices.iter().zip(&selection.scores).enumerate() {
            picks.push((score, g, order, i));
        }
    }
    // Within the budget, the boundary runs and then the best picks first (a group's
    // later picks already count its earlier ones).
    for (order, &(g, i)) in boundary.iter().enumerate() {
        if !picks.iter().any(|p| p.1 == g && p.3 == i) {
            picks.push((f64::INFINITY, g, usize::MAX - boundary.len() + order, i));
        }
    }
    picks.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    // At most `batch` per group: its boundary runs first, then its best acquisitions
    // (at most its share of the runs, as selected above).
    let mut per_group = vec![0usize; groups];
    picks.retain(|p| {
        per_group[p.1] += 1;
        per_group[p.1] <= settings.batch
    });
    picks.truncate(remaining);
    picks.sort_by(|a, b| a.1.cmp(&b.1).then(a.2.cmp(&b.2)));
    Ok(picks
        .into_iter()
        .map(|(_, g, _, i)| (g, c.theta[i].clone()))
        .collect())
}

/// The sensitivities of the log-likelihood to each component of a reduced basis at the
/// `candidates`: a_k = Σ_t a_t·a_tk over the outputs t of `terms` (output indices `outputs`),
/// a_t = (y_t − m_t)/s_t², so that δℓ = Σ_t a_t δm_t = Σ_k a_k δc_k.
fn component_sensitivities<'a>(
    basis: &'a iuq_gp::ReducedBasis,
    terms: &[LikelihoodTerm<'_>],
    outputs: std::ops::Range<usize>,
    candidates: &[Vec<f64>],
) -> Result<Vec<SensitivityTerm<'a>>> {
    let predictions = basis.predict(candidates)?;
    let m = candidates.len();
    let q = basis.components();
    let mut a = vec![vec![0.0; m]; q];
    for (term, j) in terms.iter().zip(outputs) {
        let p = &predictions[j];
        for i in 0..m {
            let s2 = term.total_variance[i];
            let at = if s2 > 0.0 && s2.is_finite() {
                (term.datum - p.mean[i]) / s2
            } else {
                0.0
            };
            for (k, ak) in a.iter_mut().enumerate() {
                ak[i] += at * basis.loading(j, k);
            }
        }
    }
    Ok(basis
        .component_gps()
        .iter()
        .zip(a)
        .map(|(gp, a)| SensitivityTerm {
            gp: gp as &dyn iuq_gp::OutputPredictor,
            a,
        })
        .collect())
}

/// `adaptive/runs.csv`: round, run group (from 0), θ, and 1 where the run failed.
fn write_runs_table(study: &Study, dir: &Path, rows: &[Vec<f64>]) -> Result<()> {
    let mut columns = vec!["round".to_string(), "group".to_string()];
    columns.extend(study.space.names());
    columns.push("failed".into());
    write_numeric_csv(&dir.join("runs.csv"), &columns, rows)
}

fn write_rounds(dir: &Path, rounds: &[AdaptiveRound]) -> Result<()> {
    let text = serde_json::to_string_pretty(rounds)
        .map_err(|e| StudyError::failure(format!("cannot write the rounds: {e}")).with_source(e))?;
    write_atomically(&dir.join("rounds.json"), text.as_bytes())
}

/// The largest share of `posterior_theta` that any GP fitted to the runs sees farther than
/// [`EXTRAPOLATION_THRESHOLD`] length scales from every run (a discrepancy shared across data
/// points has the abscissa as its last input, left out).
fn posterior_extrapolation(
    emulator: &super::emulator::Emulator,
    posterior_theta: &[Vec<f64>],
) -> Result<f64> {
    let d = posterior_theta.first().map_or(0, Vec::len);
    let mut extrapolation: f64 = 0.0;
    for gp in emulator.fitted_gps() {
        let runs: std::borrow::Cow<'_, [Vec<f64>]> = if gp.dimension() == d {
            std::borrow::Cow::Borrowed(gp.training_inputs())
        } else {
            gp.training_inputs()
                .iter()
                .map(|x| x[..d].to_vec())
                .collect()
        };
        let share = extrapolation_share(
            posterior_theta,
            &runs,
            &gp.length_scales_in_input_units()[..d],
            EXTRAPOLATION_THRESHOLD,
        )?;
        extrapolation = extrapolation.max(share);
    }
    Ok(extrapolation)
}

#[cfg(test)]
mod tests {
    use super::*;
    use iuq_basis::prediction_error::{ComputationalError, Observations};
    use std::path::PathBuf;

    fn data(computational_error: ComputationalError) -> DataLikelihood {
        DataLikelihood {
            file: PathBuf::from("data.csv"),
            x_column: "x".into(),
            y_column: "y".into(),
            x: vec![1.0, 2.0],
            observations: Observations {
                values: vec![0.5, 0.4],
                measurement_std: None,
            },
            modelling_error: None,
            measurement_error: true,
            computational_error,
            prediction: None,
        }
    }

    /// Two data points, two candidates: GP j predicts `mean[i]` with noise variance σ²_j.
    fn predictions() -> Vec<iuq_gp::Prediction> {
        vec![
            iuq_gp::Prediction {
                mean: vec![0.25, 0.5],
                variance: vec![1e-6, 1e-6],
                noise_variance: 0.01,
            },
            iuq_gp::Prediction {
                mean: vec![0.4, 0.8],
                variance: vec![1e-6, 1e-6],
                noise_variance: 0.0,
            },
        ]
    }

    #[test]
    fn the_scored_variance_holds_the_gp_noise_as_the_likelihood_does() {
        let s2 = vec![vec![1e-4, 2e-4], vec![3e-4, 4e-4]];
        // Relative (the paper's form): (σ·y/μ)², σ = 0.1 for data point 0 and 0 for point 1.
        let v = likelihood_variances(
            &data(ComputationalError::Relative),
            &predictions(),
            &[0.0, 0.0],
            &s2,
        );
        let expected = [
            [1e-4 + (0.1_f64 * 0.5 / 0.25).powi(2), 2e-4],
            [3e-4 + (0.1_f64 * 0.5 / 0.5).powi(2), 4e-4],
        ];
        for (row, want) in v.iter().zip(expected) {
            for (got, want) in row.iter().zip(want) {
                assert!((got - want).abs() < 1e-15, "{got} vs {want}");
            }
        }
        // Absolute: σ² whatever the mean; none: the data's variance alone.
        let v = likelihood_variances(
            &data(ComputationalError::Absolute),
            &predictions(),
            &[0.0, 0.0],
            &s2,
        );
        assert!((v[1][0] - (3e-4 + 0.01)).abs() < 1e-15);
        // A reduced basis's truncation error joins the noise as variance no run removes.
        let v = likelihood_variances(
            &data(ComputationalError::Absolute),
            &predictions(),
            &[0.0, 0.002],
            &s2,
        );
        assert!((v[1][0] - (3e-4 + 0.01)).abs() < 1e-15);
        assert!((v[1][1] - (4e-4 + 0.002)).abs() < 1e-15);
        let v = likelihood_variances(
            &data(ComputationalError::None),
            &predictions(),
            &[0.0, 0.0],
            &s2,
        );
        assert_eq!(v, s2);
    }

    /// The variance the surrogate posterior was sampled under counts the GP's latent variance
    /// too, and its noise where the bank reports a new run's std (the default).
    #[test]
    fn the_sampled_variance_holds_the_reported_std_as_the_surrogate_likelihood_did() {
        let s2 = vec![vec![1e-4, 2e-4], vec![3e-4, 4e-4]];
        let d = data(ComputationalError::Absolute);
        let with_noise = sampled_likelihood_variances(
            &d,
            &predictions(),
            iuq_gp::PredictiveStd::WithNoise,
            &[0.0, 0.0],
            &s2,
        );
        let latent = sampled_likelihood_variances(
            &d,
            &predictions(),
            iuq_gp::PredictiveStd::Latent,
            &[0.0, 0.0],
            &s2,
        );
        let expected_with_noise = [
            [1e-4 + 1e-6 + 0.01, 2e-4 + 1e-6],
            [3e-4 + 1e-6 + 0.01, 4e-4 + 1e-6],
        ];
        let expected_latent = [[1e-4 + 1e-6, 2e-4 + 1e-6], [3e-4 + 1e-6, 4e-4 + 1e-6]];
        for (v, expected) in [(with_noise, expected_with_noise), (latent, expected_latent)] {
            for (row, want) in v.iter().zip(expected) {
                for (got, want) in row.iter().zip(want) {
                    assert!((got - want).abs() < 1e-15, "{got} vs {want}");
                }
            }
        }
    }
}
