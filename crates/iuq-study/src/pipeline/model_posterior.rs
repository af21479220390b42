//! The model's own posterior, beside the surrogate's (`iuq pipeline --model-posterior`).
//!
//! By default (`[model_posterior] method = "reweight"`) the surrogate posterior's population is
//! moved to the model's with the model's own outputs ([`iuq_basis::model_posterior()`]):
//! `samples` members run through the model in one campaign batch, importance stages certified by
//! Pareto-smoothed k̂, and delayed-acceptance bridges where one stage does not hold. Every model
//! evaluation is a campaign run recorded under `model-posterior-<k>` (its k-th batch): runs the
//! store already holds are reused, so a rerun after an interruption (even `kill -9`) requests
//! the same points in the same order and makes only the runs that were missing.
//! `method = "basis"` keeps plain BASIS on the model (`[model_sampler]`, by default chains of
//! one step without burn-in, as the published study).
//!
//! Results in `DIR/model-posterior/`: `summary.json` (everything below), `samples.csv` (the
//! population with its weights and both log-likelihoods) and `stages.csv`.

use std::path::Path;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use serde_json::{Value, json};

use iuq_basis::model_posterior::SurrogateCorrection;
use iuq_basis::{
    BasisError, BasisState, ErrorModel, LogLikelihood, ModelPosterior, ModelPosteriorEvent,
    ModelPosteriorSettings, ModelPosteriorStage, SurrogatePopulation, Tempering, model_posterior,
    resume_model_posterior, selected_members,
};
use iuq_core::{Control, Model, Outcome};
use iuq_study_file::StudySection;

use super::model_runs::ModelRuns;
use super::replicated_likelihood::{MAX_REPLICATES, ReplicatedLikelihood, bits};
use super::reproducibility_probe::{RELATIVE_NUDGE, ReproducibilityProbe, probe_reproducibility};
use super::surrogate::Surrogate;
use crate::error::{Context, Result, StudyError};
use crate::likelihood_section::{DataLikelihood, LikelihoodSection, parse_likelihood};
use crate::posterior::{SampledPosterior, build_posterior_with};
use crate::study::Study;
use crate::table_io::{write_atomically, write_numeric_csv};

/// Label prefix of the method's model runs in the campaign store.
pub const MODEL_POSTERIOR_DESIGN: &str = "model-posterior";

/// How `--model-posterior` samples the model's posterior (`[model_posterior] method`).
#[derive(Debug, Clone, PartialEq)]
pub enum ModelPosteriorMethod {
    /// From the surrogate's posterior by certified importance stages (the default; named as
    /// the study file names it, `method = "reweight"`).
    Reweight(ModelPosteriorOptions),
    /// Plain BASIS on the model with `[model_sampler]`.
    Basis,
}

/// `[model_posterior]` with `method = "reweight"`: the model posterior's settings and the
/// study's options around the method (the probe, a noisy model, replicates).
#[derive(Debug, Clone, PartialEq)]
pub struct ModelPosteriorOptions {
    /// The method's settings (`pseudo_marginal` is set from `noisy` or the probe).
    pub method: ModelPosteriorSettings,
    /// Members of the first batch rerun with nudged parameters to see whether the model's
    /// outputs repeat ([`super::reproducibility_probe`]; 0: no probe).
    pub probe: usize,
    /// Whether the model's likelihood is noisy, when the study says so (else the probe decides;
    /// without a probe, not noisy).
    pub noisy: Option<bool>,
    /// Runs per member at each irregular data point of a noisy likelihood, the member's own
    /// included ([`super::replicated_likelihood`]; 1: none repeated).
    pub replicates: usize,
    /// The Monte Carlo error of the means, in posterior stds, that the members are sized for
    /// (`target_mcse`; [`MemberSizing`]).
    pub target_mcse: f64,
    /// The most members a certified estimate may grow to for `target_mcse` (`max_samples`;
    /// `samples`: it does not grow).
    pub max_samples: usize,
}

/// The default `[model_posterior] target_mcse`: a Monte Carlo error of the means of 0.05
/// posterior stds (twice it is the adaptive engine's default tolerance).
pub const DEFAULT_TARGET_MCSE: f64 = 0.05;

/// The default `[model_posterior] max_samples`, as a multiple of `samples`.
pub const DEFAULT_MAX_SAMPLES_FACTOR: usize = 4;

/// Margin on the members the 1/√members law asks for: the Monte Carlo error itself is an
/// estimate from the members (its relative error about 1/√(2·ESS)), and an estimate short of
/// its target by a few per cent would cost another round of runs.
const SIZING_MARGIN: f64 = 1.2;

/// One estimate of the model posterior on the way to its target Monte Carlo error.
///
/// A certified estimate whose largest MCSE(μ_k)/σ_k (grouped by ancestry) exceeds
/// `target_mcse` is made again from n' = ⌈1.2·n·(MCSE/target)²⌉ members (the error falls as
/// 1/√n), at most `max_samples` and the surrogate population: the first n members are among the
/// n' (same seed), so their stored runs are reused and only the new members and the stages
/// after the first batch cost runs. A paired estimate's error has a part more members do not
/// reduce, the surrogate population's own (P): only the rest falls as 1/√n, so
/// n' = ⌈1.2·n·(MCSE² − P²)/(target² − P²)⌉, and none where P alone reaches the target. Where the
/// weights are heavy-tailed (k̂ > ½) the variance falls as n^(−rate) instead
/// ([`iuq_basis::heavy_tail_errors::pareto_convergence_rate`]), so the ratio is raised to 1/rate.
#[derive(Debug, Clone, PartialEq)]
pub struct MemberSizing {
    /// Members of the surrogate posterior in the first batch.
    pub samples: usize,
    /// The estimate's largest Monte Carlo error of a mean, in posterior stds.
    pub mcse: f64,
    /// Of that error, the part of the surrogate population's own error (a paired estimate,
    /// [`iuq_basis::paired_estimate`]; 0 otherwise), in posterior stds.
    pub population_mcse: f64,
    /// Whether the estimate was certified.
    pub certified: bool,
    /// Model runs it asked for (stored runs included).
    pub model_runs: usize,
    /// The exponent with which the error's variance falls in the members: 1, or below 1 where
    /// the weights are heavy-tailed.
    pub convergence_rate: f64,
}

impl MemberSizing {
    /// The members for `target` from an estimate of `self.mcse` at `self.samples`, capped at
    /// `cap`; `None` where the estimate is not certified, meets the target, or cannot grow.
    pub fn next_samples(&self, target: f64, cap: usize) -> Option<usize> {
        if !self.certified || !self.mcse.is_finite() || self.mcse <= target {
            return None;
        }
        let wanted = members_for_target(
            SIZING_MARGIN * self.samples as f64,
            (self.mcse, self.population_mcse),
            target,
            self.convergence_rate,
        )?
        .ceil();
        let next = if wanted >= cap as f64 {
            cap
        } else {
            wanted as usize
        };
        (next > self.samples).then_some(next)
    }
}

/// The members that bring a Monte Carlo error `mcse` at `members` down to `target`, all in
/// posterior stds, where `population_mcse` of it is the surrogate population's own (a paired
/// estimate's; 0 otherwise), which more members do not reduce, and the rest's variance falls as
/// members^(−`convergence_rate`): members·((MCSE² − P²)/(target² − P²))^(1/rate). `None` where P
/// alone reaches the target.
pub fn members_for_target(
    members: f64,
    (mcse, population_mcse): (f64, f64),
    target: f64,
    convergence_rate: f64,
) -> Option<f64> {
    let floor = population_mcse.powi(2);
    (target * target > floor).then(|| {
        let ratio = (mcse.powi(2) - floor) / (target * target - floor);
        members * ratio.powf(1.0 / convergence_rate)
    })
}

/// The former name of [`ModelPosteriorOptions`].
pub type ReweightSettings = ModelPosteriorOptions;

/// Members probed by default.
pub const DEFAULT_PROBE: usize = 4;

/// Read `[model_posterior]` (defaults when absent): `method` ("reweight" or "basis"), and for
/// "reweight" `samples` (300), `target_mcse` (0.05), `max_samples` (4 × `samples`), `seed` (1), `cv_target` (1), `bridge_cv_target` (0.5),
/// `max_stages` (6), `corrections` (1), `moves` (1), `subchain` (20), `scale` (0.4), `min_step`
/// (1e-4), `probe` (4, at most `samples`), `noisy` (true/false; absent: the probe decides) and
/// `replicates` (1, at most 64).
pub fn parse_model_posterior(study: &Study) -> Result<ModelPosteriorMethod> {
    let file = study.path.display().to_string();
    let mut s = StudySection::optional(study.model_posterior.as_ref(), "model_posterior", &file);
    let method = s.choice("method", &["reweight", "basis"])?;
    if method == Some("basis") {
        s.finish_with_hint("with method = \"basis\" the sampler's keys go in `[model_sampler]`")?;
        return Ok(ModelPosteriorMethod::Basis);
    }
    let d = ModelPosteriorSettings::default();
    let settings = ModelPosteriorSettings {
        samples: s
            .count("samples", iuq_basis::model_posterior::MIN_SAMPLES)?
            .unwrap_or(d.samples),
        seed: s.seed("seed")?.unwrap_or(d.seed),
        cv_target: s.positive("cv_target")?.unwrap_or(d.cv_target),
        bridge_cv_target: s
            .positive("bridge_cv_target")?
            .unwrap_or(d.bridge_cv_target),
        max_stages: s.count("max_stages", 1)?.unwrap_or(d.max_stages),
        corrections: s.count("corrections", 0)?.unwrap_or(d.corrections),
        moves: s.count("moves", 1)?.unwrap_or(d.moves),
        subchain: s.count("subchain", 1)?.unwrap_or(d.subchain),
        scale: s.positive("scale")?.unwrap_or(d.scale),
        min_step: s.positive("min_step")?.unwrap_or(d.min_step),
        probabilities: d.probabilities,
        pseudo_marginal: false,
    };
    let probe = s
        .count_in("probe", 0, settings.samples)?
        .unwrap_or(DEFAULT_PROBE.min(settings.samples));
    let noisy = s.boolean("noisy")?;
    let replicates = s.count_in("replicates", 1, MAX_REPLICATES)?.unwrap_or(1);
    let target_mcse = s.positive("target_mcse")?.unwrap_or(DEFAULT_TARGET_MCSE);
    let max_samples = s
        .count("max_samples", settings.samples)?
        .unwrap_or(DEFAULT_MAX_SAMPLES_FACTOR * settings.samples);
    s.finish()?;
    if let Err(iuq_basis::BasisError::InvalidSettings { setting, reason }) = settings.check() {
        return Err(s.error(setting, reason).into());
    }
    Ok(ModelPosteriorMethod::Reweight(ModelPosteriorOptions {
        method: settings,
        probe,
        noisy,
        replicates,
        target_mcse,
        max_samples,
    }))
}

/// Each datum's smallest error scale √(σ_d² + (σ_m,low·ŷ)²): its measurement std (when it
/// enters) and the modelling error's lower bound (its prior's lowest value, when estimated).
fn error_scales(data: &crate::likelihood_section::DataLikelihood) -> Vec<f64> {
    let sigma_low = data
        .modelling_error
        .as_ref()
        .map_or(0.0, |p| p.plotting_range().0.max(0.0));
    data.observations
        .values
        .iter()
        .enumerate()
        .map(|(j, y)| {
            let sd = match (&data.observations.measurement_std, data.measurement_error) {
                (Some(s), true) => s[j],
                _ => 0.0,
            };
            (sd * sd + (sigma_low * y).powi(2)).sqrt()
        })
        .collect()
}

/// The model at the data with every batch recorded as `model-posterior-<k>`.
struct LabelledModel {
    runs: ModelRuns,
    batches: Mutex<usize>,
}

impl Model for LabelledModel {
    fn input_names(&self) -> &[String] {
        self.runs.parameters()
    }

    fn output_names(&self) -> &[String] {
        self.runs.output_names()
    }

    fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
        let k = {
            let mut batches = self.batches.lock().map_err(|_| {
                iuq_core::CoreError::ModelUnavailable("the batch counter's lock is poisoned".into())
            })?;
            *batches += 1;
            *batches
        };
        self.runs
            .model_at_data()
            .evaluate_labelled(&format!("{MODEL_POSTERIOR_DESIGN}-{k}"), points)
    }
}

/// The model's posterior and what it cost.
pub struct ModelPosteriorOutcome {
    /// The weighted population and its diagnostics.
    pub posterior: ModelPosterior,
    /// The surrogate posterior's log-evidence plus the stages' ratio.
    pub log_evidence: f64,
    /// Model runs the method asked for (evaluations × run groups; stored runs included).
    pub model_runs: usize,
    /// Per data point, the model's output at the surrogate posterior's MAP and at the model
    /// posterior's MAP (`None`: a run failed).
    pub map_runs: Vec<(Option<f64>, Option<f64>)>,
    /// The surrogate posterior's MAP (model parameters).
    pub surrogate_map: Vec<f64>,
    /// The surrogate posterior's mean and std of every parameter the model posterior weighs
    /// (the posterior it starts from: [`ModelPosteriorOutcome::shift_from_surrogate`]).
    pub surrogate_moments: (Vec<f64>, Vec<f64>),
    /// The model's outputs (one per data point) at each member of the final population, read
    /// back from the member's stored run; `None` for a member without weight (a failed run, or
    /// a weight that underflows to 0) and where reading the run back failed. The report
    /// propagates the model's posterior with these (the surrogate only for a `None` it meets,
    /// said in the report's provenance).
    pub member_outputs: Vec<Option<Vec<f64>>>,
    /// Whether the model's outputs repeated under a nudge of the parameters (`None`: no probe).
    pub probe: Option<ReproducibilityProbe>,
    /// Whether the likelihood was taken as noisy (pseudo-marginal: one step, certified by k̂).
    pub pseudo_marginal: bool,
    /// Runs per member at each irregular data point (1: none repeated).
    pub replicates: usize,
    /// Replicate runs requested (beyond each member's own and the probe's; stored runs
    /// included).
    pub replicate_runs: usize,
    /// Of those, failed runs (their likelihood counts as 0 in the member's mean).
    pub replicate_failures: usize,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// The estimates made on the way to `target_mcse`, the last one this outcome
    /// ([`MemberSizing`]).
    pub member_sizing: Vec<MemberSizing>,
}

impl ModelPosteriorOutcome {
    /// How far the model's posterior moved from the surrogate's, per parameter, in the model
    /// posterior's stds: (μ_model − μ_surrogate)/σ_model, with its Monte Carlo error
    /// MCSE(μ_model)/σ_model (grouped by ancestry: [`iuq_basis::ancestral_variance`]; the
    /// surrogate's 10,000-sample mean adds little), or for a paired estimate the error of the
    /// members' difference alone (the population's own error is common to both means). A shift
    /// beyond 2 MCSEs is the surrogate's own error that the model's runs corrected; within
    /// them, the model posterior confirms the surrogate's.
    pub fn shift_from_surrogate(&self) -> Vec<(f64, f64)> {
        let p = &self.posterior;
        let (mean, _) = &self.surrogate_moments;
        (0..p.mean.len().min(mean.len()))
            .map(|k| {
                let sd = p.std[k];
                let error = p
                    .paired
                    .as_ref()
                    .and_then(|e| e.difference.get(k).copied())
                    .unwrap_or(p.mcse_mean[k]);
                if sd > 0.0 {
                    ((p.mean[k] - mean[k]) / sd, error / sd)
                } else {
                    (0.0, 0.0)
                }
            })
            .collect()
    }

    /// The largest Monte Carlo error of a mean in posterior stds, max_k MCSE(μ_k)/σ_k (0 where
    /// every σ_k is 0).
    pub fn largest_mcse(&self) -> f64 {
        self.largest_mcse_split().0
    }

    /// [`Self::largest_mcse`] with the part of it that is the surrogate population's own error
    /// (a paired estimate's; 0 otherwise), both in posterior stds.
    pub fn largest_mcse_split(&self) -> (f64, f64) {
        let p = &self.posterior;
        (0..p.mean.len())
            .filter(|&k| p.std[k] > 0.0)
            .map(|k| {
                let population = p
                    .paired
                    .as_ref()
                    .and_then(|e| e.population.get(k).copied())
                    .unwrap_or(0.0);
                (p.mcse_mean[k] / p.std[k], population / p.std[k])
            })
            .fold((0.0, 0.0), |a, b| if b.0 > a.0 { b } else { a })
    }

    /// The exponent with which the estimate's variance falls in its members: the Pareto-smoothed
    /// estimate's convergence rate where the weights are heavy-tailed
    /// ([`iuq_basis::ModelPosterior::heavy_tail_errors`]), otherwise 1.
    pub fn convergence_rate(&self) -> f64 {
        self.posterior
            .heavy_tail_errors
            .as_ref()
            .map_or(1.0, |h| h.convergence_rate)
    }

    /// The effective sample size the members' correlation leaves: min over parameters of
    /// σ_k²/MCSE(μ_k)², the number of independent draws whose mean would have the grouped
    /// error (Kish's ESS of the weights counts resampled copies of one ancestor as independent
    /// and overstates it after a bridge).
    pub fn effective_sample_size_by_ancestry(&self) -> f64 {
        let p = &self.posterior;
        p.std
            .iter()
            .zip(&p.mcse_mean)
            .filter(|(s, e)| **s > 0.0 && **e > 0.0)
            .map(|(s, e)| (s / e).powi(2))
            .fold(f64::INFINITY, f64::min)
            .min(p.effective_sample_size)
    }

    /// The summary `pipeline.json` and `iuq pipeline --json` carry.
    pub fn to_json(&self) -> Value {
        let p = &self.posterior;
        let by_name = |v: &[f64]| crate::posterior::by_name(&p.names, v);
        let finite = |v: f64| if v.is_finite() { json!(v) } else { Value::Null };
        let sizing: Vec<Value> = self
            .member_sizing
            .iter()
            .map(|m| {
                json!({
                    "samples": m.samples,
                    "mcse": finite(m.mcse),
                    "population_mcse": m.population_mcse,
                    "certified": m.certified,
                    "model_runs": m.model_runs,
                    "convergence_rate": m.convergence_rate,
                })
            })
            .collect();
        json!({
            "method": "reweight",
            "certified": p.certified(),
            "stop": p.stop.to_string(),
            "samples": p.samples.len(),
            "pareto_k": finite(p.pareto_k),
            "pareto_k_threshold": p.pareto_k_threshold,
            "effective_sample_size": p.effective_sample_size,
            "effective_sample_size_by_ancestry": finite(self.effective_sample_size_by_ancestry()),
            "shift_from_surrogate": by_name(&self.shift_from_surrogate().iter().map(|s| s.0).collect::<Vec<_>>()),
            "shift_from_surrogate_mcse": by_name(&self.shift_from_surrogate().iter().map(|s| s.1).collect::<Vec<_>>()),
            "map": by_name(&p.map),
            "mean": by_name(&p.mean),
            "std": by_name(&p.std),
            "mcse_mean": by_name(&p.mcse_mean),
            "mcse_std": by_name(&p.mcse_std),
            "ancestors": p.ancestors,
            "heavy_tail_errors": p.heavy_tail_errors.as_ref().map(|h| json!({
                "convergence_rate": h.convergence_rate,
                "batches": h.batches,
                "mcse_mean": by_name(&h.mean),
                "mcse_std": by_name(&h.std),
            })),
            "paired": p.paired.is_some(),
            "mcse_mean_population": p.paired.as_ref().map(|e| by_name(&e.population)),
            "log_evidence": finite(self.log_evidence),
            "log_evidence_ratio": finite(p.log_evidence_ratio),
            "model_evaluations": p.model_evaluations,
            "model_runs": self.model_runs,
            "map_runs": self.map_runs.iter().map(|(s, m)| json!({"at_surrogate_map": s, "at_model_map": m})).collect::<Vec<_>>(),
            "failures": p.failures,
            "corrections": p.corrections,
            "proposal_mismatch": p.proposal_mismatch,
            "correction_not_made": p.correction_not_made,
            "both_batches": p.both_batches,
            "pseudo_marginal": self.pseudo_marginal,
            "replicates": self.replicates,
            "replicate_runs": self.replicate_runs,
            "replicate_failures": self.replicate_failures,
            "probe": self.probe.as_ref().map(ReproducibilityProbe::to_json),
            "stages": p.stages.iter().map(stage_json).collect::<Vec<_>>(),
            "seconds": self.seconds,
            "member_sizing": sizing,
        })
    }
}

/// One stage of the model posterior as `--json` and `summary.json` carry it.
fn stage_json(s: &ModelPosteriorStage) -> Value {
    let finite = |v: f64| if v.is_finite() { json!(v) } else { Value::Null };
    json!({
        "stage": s.stage,
        "beta": s.beta,
        "step": s.step,
        "cv_step": s.cv_step,
        "cv": s.cv,
        "pareto_k": finite(s.pareto_k),
        "effective_sample_size": s.effective_sample_size,
        "model_evaluations": s.model_evaluations,
        "failures": s.failures,
        "screen_acceptance": s.screen_acceptance,
        "confirm_acceptance": s.confirm_acceptance,
        "spread_ratio": s.spread_ratio,
    })
}

/// The former name of [`model_posterior_from_surrogate`].
pub use self::model_posterior_from_surrogate as reweight_to_model;

/// The model's posterior from the surrogate's `gp_posterior` (`options`), through the campaign
/// of `model_runs`, its members sized for `options.target_mcse` ([`MemberSizing`]); writes
/// `out/model-posterior/`; `message` receives a line per stage and per resizing.
pub fn model_posterior_from_surrogate(
    study: &Study,
    gp_posterior: &SampledPosterior,
    surrogate: &Surrogate,
    model_runs: &ModelRuns,
    options: &ModelPosteriorOptions,
    out: &Path,
    message: &mut dyn FnMut(String),
) -> Result<ModelPosteriorOutcome> {
    let started = std::time::Instant::now();
    let population = gp_posterior.run.state.samples.len();
    let cap = options.max_samples.min(population);
    let first = &options.method;
    let mut options = options.clone();
    let mut sizing = Vec::new();
    let mut outcome = loop {
        let outcome = estimate(
            study,
            gp_posterior,
            surrogate,
            model_runs,
            (&options, first),
            &out.join("model-posterior"),
            message,
        )?;
        let (mcse, population_mcse) = outcome.largest_mcse_split();
        let this = MemberSizing {
            samples: options.method.samples.min(population),
            mcse,
            population_mcse,
            certified: outcome.posterior.certified(),
            model_runs: outcome.model_runs,
            convergence_rate: outcome.convergence_rate(),
        };
        let next = this.next_samples(options.target_mcse, cap);
        sizing.push(this);
        let Some(next) = next else { break outcome };
        message(format!(
            "the model's posterior: its means carry a Monte Carlo error of up to {:.3} posterior stds, more than `target_mcse` = {}; again from {next} members (the first {} are reused)",
            outcome.largest_mcse(),
            options.target_mcse,
            options.method.samples.min(population),
        ));
        options.method.samples = next;
    };
    outcome.member_sizing = sizing;
    outcome.seconds = started.elapsed().as_secs_f64();
    write_results(&outcome, &out.join("model-posterior"))?;
    Ok(outcome)
}

/// One estimate of the model's posterior from `options.method.samples` members, the probe at
/// the members of the first estimate (`first`: the same runs for every estimate); its tempering
/// checkpointed under `dir` ([`tempering_checkpoint`]).
fn estimate(
    study: &Study,
    gp_posterior: &SampledPosterior,
    surrogate: &Surrogate,
    model_runs: &ModelRuns,
    (options, first): (&ModelPosteriorOptions, &ModelPosteriorSettings),
    dir: &Path,
    message: &mut dyn FnMut(String),
) -> Result<ModelPosteriorOutcome> {
    let started = std::time::Instant::now();
    let d = model_runs.parameters().len();
    let state = &gp_posterior.run.state;
    let data = match parse_likelihood(study)? {
        LikelihoodSection::Data(data) => Some(data),
        LikelihoodSection::LogDensity(_) => None,
    };
    let probe = probe_first_members(
        study,
        state,
        model_runs,
        options.probe,
        first,
        data.as_ref(),
    )?;
    let pseudo_marginal = options
        .noisy
        .unwrap_or_else(|| probe.as_ref().is_some_and(ReproducibilityProbe::irregular));
    if let Some(probe) = &probe {
        message(probe_line(probe, pseudo_marginal));
    }
    if options.replicates > 1 && !pseudo_marginal {
        message(format!(
            "replicates = {} goes unused: the model's likelihood is not noisy (its outputs repeat, or `noisy = false`)",
            options.replicates
        ));
    }
    let settings = &ModelPosteriorSettings {
        pseudo_marginal,
        ..options.method.clone()
    };
    let surrogate_posterior = build_posterior_with(study, || Ok(surrogate.clone()))?;
    let model = LabelledModel {
        runs: model_runs.clone(),
        batches: Mutex::new(0),
    };
    let model_posterior_likelihood = build_posterior_with(study, || Ok(model))?;
    let replicated = match (pseudo_marginal && options.replicates > 1, data) {
        (true, Some(data)) => {
            let irregular = irregular_outputs(probe.as_ref(), model_runs.output_names().len());
            Some((data, irregular))
        }
        _ => None,
    };
    let replicated_likelihood = replicated.as_ref().map(|(data, irregular)| {
        replicated_likelihood(
            model_posterior_likelihood.likelihood.as_ref(),
            model_runs,
            data,
            irregular,
            Replication {
                replicates: options.replicates,
                ranges: study.space.ranges(),
                probe: probe.as_ref(),
            },
        )
    });
    if let Some(r) = &replicated_likelihood {
        let members = options.method.samples.min(state.samples.len());
        message(replicates_line(r, model_runs, members));
    }
    let model_likelihood: &dyn LogLikelihood = match &replicated_likelihood {
        Some(r) => r,
        None => model_posterior_likelihood.likelihood.as_ref(),
    };
    let population = SurrogatePopulation {
        samples: &state.samples,
        log_likelihood: &state.log_likelihood,
        log_prior: &state.log_prior,
        log_evidence: state.log_evidence,
    };
    let groups = model_runs.groups();
    let posterior = temper(
        MethodInputs {
            space: &surrogate_posterior.space,
            population,
            surrogate: surrogate_posterior.likelihood.as_ref(),
            model: model_likelihood,
            settings,
        },
        &tempering_checkpoint(dir, options.method.samples.min(state.samples.len())),
        (groups, replicated_likelihood.is_some()),
        message,
    )?;
    let replicate_runs = replicated_likelihood
        .as_ref()
        .map_or(0, |r| r.replicate_runs.load(Ordering::Relaxed));
    let replicate_failures = replicated_likelihood
        .as_ref()
        .map_or(0, |r| r.replicate_failures.load(Ordering::Relaxed));
    let surrogate_map = gp_posterior.summary.map[..d].to_vec();
    let map_runs = runs_at_maps(model_runs, &surrogate_map, &posterior.map[..d])?;
    let member_outputs = member_outputs(model_runs, &posterior, d)?;
    let k = posterior.mean.len();
    let outcome = ModelPosteriorOutcome {
        map_runs,
        surrogate_map,
        surrogate_moments: (
            gp_posterior.summary.mean.iter().take(k).copied().collect(),
            gp_posterior.summary.std.iter().take(k).copied().collect(),
        ),
        member_outputs,
        log_evidence: state.log_evidence + posterior.log_evidence_ratio,
        model_runs: (posterior.model_evaluations
            + probe.as_ref().map_or(0, |p| p.model_evaluations))
            * groups
            + replicate_runs,
        replicate_runs,
        replicate_failures,
        replicates: if replicated_likelihood.is_some() {
            options.replicates
        } else {
            1
        },
        probe,
        pseudo_marginal,
        seconds: started.elapsed().as_secs_f64(),
        member_sizing: Vec::new(),
        posterior,
    };
    Ok(outcome)
}

/// The reproducibility probe at the first `probe` members of the first batch of `settings`
/// (`None` without a probe), judged against the data's error scales.
fn probe_first_members(
    study: &Study,
    state: &BasisState,
    model_runs: &ModelRuns,
    probe: usize,
    settings: &ModelPosteriorSettings,
    data: Option<&DataLikelihood>,
) -> Result<Option<ReproducibilityProbe>> {
    if probe == 0 {
        return Ok(None);
    }
    let d = model_runs.parameters().len();
    let members: Vec<Vec<f64>> = selected_members(state.samples.len(), settings)
        .into_iter()
        .take(probe)
        .map(|i| state.samples[i][..d].to_vec())
        .collect();
    let scales = data.map(error_scales).unwrap_or_default();
    Ok(Some(probe_reproducibility(
        model_runs,
        &members,
        &study.space.ranges(),
        &scales,
    )?))
}

/// The progress line of the reproducibility probe: whether the model's outputs repeat under a
/// nudge, and what that means for the method (`pseudo_marginal`).
fn probe_line(probe: &ReproducibilityProbe, pseudo_marginal: bool) -> String {
    let irregular: Vec<&str> = probe
        .outputs
        .iter()
        .filter(|o| o.irregular)
        .map(|o| o.name.as_str())
        .collect();
    format!(
        "the model's outputs under a nudge of the parameters by {RELATIVE_NUDGE:e} of their ranges ({} members): {}",
        probe.pairs,
        match (probe.pairs, irregular.is_empty(), pseudo_marginal) {
            (0, _, _) => "inconclusive: every probed member had a failed run".to_string(),
            (_, true, _) => "they repeat".to_string(),
            (_, false, true) => format!(
                "irregular at {} (the likelihood is a noisy estimate: one importance step, certified by k̂)",
                irregular.join(", ")
            ),
            (_, false, false) => format!(
                "irregular at {} (`noisy = false`: the stages all the same)",
                irregular.join(", ")
            ),
        }
    )
}

/// The data points whose runs are replicated: those the probe found irregular, or all
/// `points` where it found none (or there was no probe).
fn irregular_outputs(probe: Option<&ReproducibilityProbe>, points: usize) -> Vec<usize> {
    let all: Vec<usize> = (0..points).collect();
    match probe {
        Some(p) if p.irregular() => (0..p.outputs.len())
            .filter(|&j| p.outputs[j].irregular)
            .collect(),
        _ => all,
    }
}

/// How a noisy likelihood's members are replicated.
struct Replication<'a> {
    /// Runs per member at each irregular data point, the member's own included.
    replicates: usize,
    /// The parameters' prior ranges (the nudges' scale).
    ranges: Vec<(f64, f64)>,
    /// The probe, whose nudged points are already run.
    probe: Option<&'a ReproducibilityProbe>,
}

/// The model's likelihood with the members' runs at the `irregular` data points replicated
/// (averaged as [`ReplicatedLikelihood`] does), on top of `base`.
fn replicated_likelihood<'a>(
    base: &'a dyn LogLikelihood,
    model_runs: &'a ModelRuns,
    data: &'a DataLikelihood,
    irregular: &[usize],
    replication: Replication<'_>,
) -> ReplicatedLikelihood<'a> {
    ReplicatedLikelihood {
        base,
        runs: model_runs,
        observations: &data.observations,
        errors: ErrorModel {
            measurement_error: data.measurement_error,
            computational_error: data.computational_error,
            modelling_error: data.modelling_error,
        },
        irregular: irregular.to_vec(),
        replicates: replication.replicates,
        ranges: replication.ranges,
        already_run: replication
            .probe
            .iter()
            .flat_map(|p| p.nudged_points().iter().map(|x| bits(x)))
            .collect(),
        replicate_runs: AtomicUsize::new(0),
        replicate_failures: AtomicUsize::new(0),
    }
}

/// The progress line announcing the replicates: how many runs a batch of `members` members
/// may add, and in which run groups.
fn replicates_line(r: &ReplicatedLikelihood<'_>, model_runs: &ModelRuns, members: usize) -> String {
    let groups = r.irregular_groups().len();
    let names: Vec<&str> = r
        .irregular
        .iter()
        .map(|&j| model_runs.output_names()[j].as_str())
        .collect();
    format!(
        "replicates = {m}: after each batch, every member whose own runs succeeded is run {} more times (its parameters moved by k·1e-9 of their ranges) in the {groups} run group(s) holding {}: up to {} runs per batch of {members} members (results already stored are reused)",
        r.replicates - 1,
        names.join(", "),
        members * (r.replicates - 1) * groups,
        m = r.replicates,
    )
}

/// The method's error as the study reports it: bad model input, a batch the model could not
/// evaluate, or another failure.
fn method_error(e: iuq_basis::BasisError) -> StudyError {
    let error = match &e {
        iuq_basis::BasisError::ModelInput(reason) => StudyError::bad_input(reason.clone()),
        iuq_basis::BasisError::ModelBatch(reason) => StudyError::failure(format!(
            "the model posterior: the model could not evaluate a batch: {reason}"
        )),
        other => StudyError::failure(format!("the model posterior: {other}")),
    };
    error.with_source(e)
}

/// The model at both MAPs, per data point (`None`: a run failed): the surrogate posterior's
/// (usually stored by the posterior check) and the model posterior's (stored by the stages).
fn runs_at_maps(
    model_runs: &ModelRuns,
    surrogate_map: &[f64],
    model_map: &[f64],
) -> Result<Vec<(Option<f64>, Option<f64>)>> {
    let maps = [surrogate_map.to_vec(), model_map.to_vec()];
    let at_maps = model_runs
        .model_at_data()
        .evaluate_labelled(&format!("{MODEL_POSTERIOR_DESIGN}-maps"), &maps)
        .map_err(|e| StudyError::from(e).context("the model at both MAPs"))?;
    let outputs: Vec<Option<Vec<f64>>> = at_maps
        .into_iter()
        .map(|o| o.ok().map(|e| e.outputs))
        .collect();
    let points = model_runs.output_names().len();
    Ok((0..points)
        .map(|j| {
            (
                outputs[0].as_ref().and_then(|v| v.get(j).copied()),
                outputs[1].as_ref().and_then(|v| v.get(j).copied()),
            )
        })
        .collect())
}

/// The model's outputs at every member of `posterior` with weight, from the members' runs,
/// which the stages made and stored, so that no run is made (each distinct member asked for
/// once; the request is recorded as the design `model-posterior-members`).
fn member_outputs(
    model_runs: &ModelRuns,
    posterior: &ModelPosterior,
    d: usize,
) -> Result<Vec<Option<Vec<f64>>>> {
    let weights = posterior.weights();
    let mut distinct: Vec<Vec<f64>> = Vec::new();
    let mut index_of: std::collections::HashMap<Vec<u64>, usize> = Default::default();
    let slots: Vec<Option<usize>> = posterior
        .samples
        .iter()
        .zip(&weights)
        .map(|(theta, &w)| {
            (w > 0.0).then(|| {
                let theta = &theta[..d];
                *index_of.entry(bits(theta)).or_insert_with(|| {
                    distinct.push(theta.to_vec());
                    distinct.len() - 1
                })
            })
        })
        .collect();
    let outcomes = model_runs
        .model_at_data()
        .evaluate_labelled(&format!("{MODEL_POSTERIOR_DESIGN}-members"), &distinct)
        .map_err(|e| {
            StudyError::from(e).context("the model's outputs at its posterior's members")
        })?;
    Ok(slots
        .into_iter()
        .map(|slot| slot.and_then(|k| outcomes[k].as_ref().ok().map(|e| e.outputs.clone())))
        .collect())
}

/// The progress line of a finished stage.
fn stage_line(stage: &ModelPosteriorStage, groups: usize) -> String {
    format!(
        "model posterior, stage {}: β = {:.4} (step {:.4}), k̂ = {:.3}, ESS {:.0}, {} model evaluations ({} runs){}",
        stage.stage,
        stage.beta,
        stage.step,
        stage.pareto_k,
        stage.effective_sample_size,
        stage.model_evaluations,
        stage.model_evaluations * groups,
        match (stage.screen_acceptance, stage.confirm_acceptance) {
            (Some(a), Some(b)) => format!("; bridge acceptance: surrogate {a:.2}, model {b:.2}"),
            _ => String::new(),
        }
    )
}

/// The progress line announcing a correction's batch, before its runs start.
fn correction_line(correction: &SurrogateCorrection, groups: usize, replicated: bool) -> String {
    let kind = if correction.defensive_normal {
        "a defensive batch from a normal at the first batch's weighted mean with twice its weighted second moment".to_string()
    } else if let Some(beta) = correction.tempering {
        format!(
            "a defensive batch from the surrogate's posterior tempered at β = {beta:.3} (π·L_s^β)"
        )
    } else if correction.moment_matched {
        "the surrogate is corrected by the moment-matched log-ratio of the first batch's weights"
            .to_string()
    } else if correction.quadratic {
        "the surrogate is corrected by a quadratic fit of the first batch's log-ratios".to_string()
    } else {
        "the surrogate is corrected by a linear fit of the first batch's log-ratios".to_string()
    };
    let refused = if correction.refused.is_empty() {
        String::new()
    } else {
        format!(" (refused first: {})", correction.refused.join("; "))
    };
    let at = if correction.defensive_normal {
        "that normal"
    } else if correction.tempering.is_some() {
        "the tempered surrogate's posterior"
    } else {
        "the corrected surrogate's posterior"
    };
    format!(
        "model posterior: the first batch's weights (k̂ = {:.3}, CV {:.2}, widest std ratio {:.2}) call for a correction: \
         {kind}{refused}; a batch of {} samples at {at} starts, {} runs{} (results already \
         stored are reused)",
        correction.pareto_k_before,
        correction.cv_before,
        correction.spread_ratio_before,
        correction.model_evaluations,
        correction.model_evaluations * groups,
        if replicated {
            " and their replicates"
        } else {
            ""
        },
    )
}

fn write_results(outcome: &ModelPosteriorOutcome, dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let p = &outcome.posterior;
    let mut summary = outcome.to_json();
    summary["quantiles"] = json!({
        "probabilities": p.probabilities,
        "values": p.names.iter().zip(&p.quantiles).map(|(n, q)| (n.clone(), json!(q))).collect::<serde_json::Map<String, Value>>(),
    });
    write_atomically(
        &dir.join("summary.json"),
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )?;
    let mut columns = p.names.clone();
    columns.extend(
        [
            "weight",
            "log_weight",
            "raw_log_weight",
            "ll_model",
            "ll_surrogate",
            "lp",
        ]
        .map(String::from),
    );
    let weights = p.weights();
    let rows: Vec<Vec<f64>> = (0..p.samples.len())
        .map(|i| {
            let mut row = p.samples[i].clone();
            row.extend([
                weights[i],
                p.log_weights[i],
                p.raw_log_weights[i],
                p.model_log_likelihood[i],
                p.surrogate_log_likelihood[i],
                p.log_prior[i],
            ]);
            row
        })
        .collect();
    write_numeric_csv(&dir.join("samples.csv"), &columns, &rows)?;
    let columns: Vec<String> = [
        "stage",
        "beta",
        "step",
        "cv_step",
        "cv",
        "pareto_k",
        "effective_sample_size",
        "model_evaluations",
        "failures",
        "screen_acceptance",
        "confirm_acceptance",
        "spread_ratio",
    ]
    .map(String::from)
    .to_vec();
    let rows: Vec<Vec<f64>> = p
        .stages
        .iter()
        .map(|s| {
            vec![
                s.stage as f64,
                s.beta,
                s.step,
                s.cv_step,
                s.cv,
                s.pareto_k,
                s.effective_sample_size,
                s.model_evaluations as f64,
                s.failures as f64,
                s.screen_acceptance.unwrap_or(f64::NAN),
                s.confirm_acceptance.unwrap_or(f64::NAN),
                s.spread_ratio,
            ]
        })
        .collect();
    write_numeric_csv(&dir.join("stages.csv"), &columns, &rows)
}

/// What [`model_posterior`] weighs: the parameters, the surrogate's population and the two
/// log-likelihoods, with the method's settings.
#[derive(Clone, Copy)]
struct MethodInputs<'a> {
    space: &'a iuq_core::ParameterSpace,
    population: SurrogatePopulation<'a>,
    surrogate: &'a dyn LogLikelihood,
    model: &'a dyn LogLikelihood,
    settings: &'a ModelPosteriorSettings,
}

/// The model posterior of `inputs`, going on from the state kept at `checkpoint` where one is
/// there and is this run's ([`resume_model_posterior`]), keeping the state there after every
/// bridge; a line per stage and correction in `message` (`groups` run groups, `replicated`:
/// the likelihood of replicated runs).
fn temper(
    inputs: MethodInputs<'_>,
    checkpoint: &Path,
    (groups, replicated): (usize, bool),
    message: &mut dyn FnMut(String),
) -> Result<ModelPosterior> {
    let MethodInputs {
        space,
        population,
        surrogate,
        model,
        settings,
    } = inputs;
    let resume = read_tempering(checkpoint, message);
    let resumed_from = resume.as_ref().map(|t| t.stages().len());
    let mut unwritten = None;
    let mut observer = |event: &ModelPosteriorEvent<'_>| {
        match event {
            ModelPosteriorEvent::Stage(stage) => message(stage_line(stage, groups)),
            ModelPosteriorEvent::Correction(correction) => {
                message(correction_line(correction, groups, replicated))
            }
            ModelPosteriorEvent::CorrectionNotMade(reason) => message(format!(
                "model posterior: no correction of the surrogate: {reason}"
            )),
            // A Ctrl-C stops the method through its model runs (the campaign's interrupt); the
            // state after each bridge is kept, so a rerun makes none of the bridges before it.
            ModelPosteriorEvent::Bridged(tempering) => {
                if let Err(e) = write_tempering(checkpoint, tempering) {
                    unwritten = Some(e.to_string());
                }
            }
        }
        Control::Continue
    };
    let mut refused = None;
    let posterior = match resume {
        Some(tempering) => match resume_model_posterior(
            space,
            population,
            surrogate,
            model,
            settings,
            tempering,
            &mut observer,
        ) {
            Err(BasisError::CheckpointMismatch(reason)) => {
                refused = Some(reason);
                model_posterior(space, population, surrogate, model, settings, &mut observer)
            }
            resumed => resumed,
        },
        None => model_posterior(space, population, surrogate, model, settings, &mut observer),
    }
    .map_err(method_error)?;
    report_checkpoint(checkpoint, resumed_from, refused, unwritten, message);
    Ok(posterior)
}

/// Where [`estimate`] keeps its tempering's state after each bridge ([`Tempering`], JSON):
/// one file per member count, so that a resized estimate never reads another's.
fn tempering_checkpoint(dir: &Path, members: usize) -> std::path::PathBuf {
    dir.join(format!("tempering-{members}.json"))
}

/// The checkpoint at `path`, if one is there and reads; one that does not read is reported and
/// left for the run to overwrite (the store still answers every run it recorded).
fn read_tempering(path: &Path, message: &mut dyn FnMut(String)) -> Option<Tempering> {
    let text = std::fs::read_to_string(path).ok()?;
    match serde_json::from_str(&text) {
        Ok(tempering) => Some(tempering),
        Err(e) => {
            message(format!(
                "model posterior: {}: not a tempering checkpoint ({e}); tempering from the start",
                path.display()
            ));
            None
        }
    }
}

/// `tempering` written to `path` atomically (its folder made where missing).
fn write_tempering(path: &Path, tempering: &Tempering) -> Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).context(format!("{}", dir.display()))?;
    }
    let text = serde_json::to_string(tempering)
        .map_err(|e| StudyError::failure(format!("{}: {e}", path.display())).with_source(e))?;
    write_atomically(path, text.as_bytes())
}

/// The checkpoint's part in a finished estimate, told in `message`: resumed from (after its
/// `resumed_from` stages), refused (another run's state), or not written; the file is removed,
/// its estimate being done.
fn report_checkpoint(
    path: &Path,
    resumed_from: Option<usize>,
    refused: Option<String>,
    unwritten: Option<String>,
    message: &mut dyn FnMut(String),
) {
    match (resumed_from, refused) {
        (Some(_), Some(reason)) => message(format!(
            "model posterior: {} is another run's tempering ({reason}); tempered from the start",
            path.display()
        )),
        (Some(stages), None) => message(format!(
            "model posterior: went on from the tempering checkpoint after {stages} stages ({})",
            path.display()
        )),
        (None, _) => {}
    }
    if let Some(e) = unwritten {
        message(format!(
            "model posterior: the tempering checkpoint could not be written: {e}"
        ));
    }
    let _ = std::fs::remove_file(path);
}

#[cfg(test)]
mod tests {
    use super::MemberSizing;

    fn sizing(samples: usize, mcse: f64, certified: bool) -> MemberSizing {
        MemberSizing {
            samples,
            mcse,
            population_mcse: 0.0,
            certified,
            model_runs: 0,
            convergence_rate: 1.0,
        }
    }

    #[test]
    fn members_grow_by_the_square_of_the_error_ratio_with_a_margin() {
        // 1.2 · 300 · (0.058/0.05)² = 484.4.
        assert_eq!(sizing(300, 0.058, true).next_samples(0.05, 1200), Some(485));
        // Capped at `max_samples` (or the population).
        assert_eq!(sizing(300, 0.2, true).next_samples(0.05, 1200), Some(1200));
    }

    #[test]
    fn members_do_not_grow_within_the_target_uncertified_or_at_the_cap() {
        assert_eq!(sizing(300, 0.05, true).next_samples(0.05, 1200), None);
        assert_eq!(sizing(300, 0.2, false).next_samples(0.05, 1200), None);
        assert_eq!(sizing(300, 0.2, true).next_samples(0.05, 300), None);
        assert_eq!(sizing(300, f64::NAN, true).next_samples(0.05, 1200), None);
    }

    #[test]
    fn a_paired_estimates_population_error_is_a_floor_more_members_do_not_lower() {
        // MCSE 0.06 of which 0.03 the population's: the members' part 0.052 must fall to
        // √(0.05² − 0.03²) = 0.04: 1.2 · 300 · (0.0036 − 0.0009)/(0.0025 − 0.0009) = 607.5.
        let paired = MemberSizing {
            population_mcse: 0.03,
            ..sizing(300, 0.06, true)
        };
        assert_eq!(paired.next_samples(0.05, 1200), Some(608));
        // The population alone at the target: no number of members reaches it.
        let floor = MemberSizing {
            population_mcse: 0.05,
            ..sizing(300, 0.06, true)
        };
        assert_eq!(floor.next_samples(0.05, 1200), None);
    }

    #[test]
    fn heavy_tailed_weights_ask_for_more_members_at_their_slower_rate() {
        // Variance falling as n^(−0.7): 1.2 · 300 · ((0.058/0.05)²)^(1/0.7) = 550.1 (485 at rate 1).
        let heavy = MemberSizing {
            convergence_rate: 0.7,
            ..sizing(300, 0.058, true)
        };
        assert_eq!(heavy.next_samples(0.05, 1200), Some(551));
    }
}
