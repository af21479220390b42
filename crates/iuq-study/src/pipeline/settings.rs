//! The settings of `iuq pipeline`, read from the study file's `[surrogate]` and `[sensitivity]`
//! sections (the sampler's come from `[sampler]` and `[model_sampler]`).
//!
//! ```toml
//! [surrogate]
//! design = { kind = "lhs", n = 24, seed = 11 }   # initial runs per run group: maximin LHS
//! test = { kind = "sobol", n = 8, seed = 12 }    # independent test runs per group (n = 0: none)
//! # refine where the posterior lies (see `pipeline::adaptive`); absent: one-shot design
//! adaptive = { batch = 2, max_runs = 300, tolerance = 0.1, log_likelihood_tolerance = 0.05,
//!              samples = 2000, exploring_samples = 500, replicates = 4, max_samples = 32000,
//!              max_rounds = 30,
//!              candidates = 1000, sampling = "sequential", stopping_rule = "distribution",
//!              more_samples = "when-resolving", final_sample = "carried" }
//! # run the model at the surrogate posterior's MAP and at 20 of its samples (absent: no check)
//! posterior_check = { samples = 20, seed = 5 }
//! # a whole-curve model emulated on its leading principal components (absent: so from 50 data
//! # rows on, without a second fidelity; `false`: a GP per point)
//! reduced_basis = { explained_variance = 0.9999, max_components = 30 }
//! [sensitivity]
//! n = 1024        # Saltelli base points on the surrogate
//! model_n = 8     # Saltelli base points run on the model itself (0: skip)
//! seed = 3
//! ```

use iuq_study_file::StudySection;

use super::emulator::ReducedBasisSettings;

use crate::error::{Result, input_error};
use crate::study::Study;

/// Settings of the surrogate and sensitivity stages.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct PipelineSettings {
    /// Initial training runs per run group (maximin Latin hypercube).
    pub training_runs: usize,
    /// Seed of the training designs (run group j uses `training_seed + j`).
    pub training_seed: u64,
    /// Random designs of which the maximin criterion keeps the best.
    pub maximin_candidates: usize,
    /// Test runs per run group (scrambled Sobol').
    pub test_runs: usize,
    /// Seed of the test design's scrambling.
    pub test_seed: u64,
    /// Saltelli base points on the surrogate.
    pub surrogate_sobol_n: usize,
    /// Saltelli base points on the model (0: none).
    pub model_sobol_n: usize,
    /// Seed of the Sobol' analyses.
    pub sobol_seed: u64,
    /// Confidence level of the Sobol' intervals.
    pub confidence: f64,
    /// Bootstrap resamples of the Sobol' intervals.
    pub resamples: usize,
    /// The adaptive refinement, when `[surrogate] adaptive` is given.
    pub adaptive: Option<AdaptiveSettings>,
    /// The model run at the posterior, when `[surrogate] posterior_check` is given.
    pub posterior_check: Option<PosteriorCheckSettings>,
    /// A reduced basis of the whole curve instead of a GP per data point: as
    /// `[surrogate] reduced_basis` says, or where it is absent as [`ReducedBasisChoice::resolve`]
    /// decides.
    pub reduced_basis: ReducedBasisChoice,
}

/// Data rows from which a whole-curve model is emulated on a reduced basis when
/// `[surrogate] reduced_basis` is absent: there a GP per row would make every evaluation of the
/// surrogate cost `rows` predictions, where the basis costs one per component (at most
/// `max_components`, 30 by default) and a product with the loadings. On a 200-point damped
/// oscillation (4 parameters, 9 components) a round's surrogate evaluations cost about a third
/// of the per-row GPs' (docs/adaptive-engine.md, "Long curves").
pub const AUTOMATIC_REDUCED_BASIS_ROWS: usize = 50;

/// What `[surrogate] reduced_basis` says.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ReducedBasisChoice {
    /// Absent: a reduced basis with the default settings for a whole-curve model of at least
    /// [`AUTOMATIC_REDUCED_BASIS_ROWS`] data rows (of two fidelities where `[low_fidelity]` is
    /// given), else a GP per row.
    Automatic,
    /// `false`: a GP per data row.
    Off,
    /// `true` or a table: a reduced basis with these settings.
    On(ReducedBasisSettings),
}

impl ReducedBasisChoice {
    /// The reduced basis to emulate with (`None`: a GP per data row), for a model that returns
    /// the whole curve (`whole_curve`) or runs once per row, and `rows` data rows.
    pub fn resolve(self, whole_curve: bool, rows: usize) -> Option<ReducedBasisSettings> {
        match self {
            ReducedBasisChoice::On(settings) => Some(settings),
            ReducedBasisChoice::Off => None,
            ReducedBasisChoice::Automatic => (whole_curve && rows >= AUTOMATIC_REDUCED_BASIS_ROWS)
                .then(ReducedBasisSettings::default),
        }
    }
}

/// Read `[surrogate] reduced_basis = { explained_variance, max_components }` (`true` for the
/// defaults, `false` for a GP per data row, absent for [`ReducedBasisChoice::Automatic`]).
fn parse_reduced_basis(
    surrogate: &mut StudySection<'_>,
    study: &Study,
) -> Result<ReducedBasisChoice> {
    let defaults = ReducedBasisSettings::default();
    let settings = match surrogate.value("reduced_basis") {
        None => return Ok(ReducedBasisChoice::Automatic),
        Some(toml::Value::Boolean(false)) => return Ok(ReducedBasisChoice::Off),
        Some(toml::Value::Boolean(true)) => defaults,
        Some(_) => {
            let Some(mut s) = surrogate.section(
                "reduced_basis",
                "{ explained_variance = 0.9999, max_components = 30 }",
            )?
            else {
                return Ok(ReducedBasisChoice::Automatic);
            };
            let explained_variance = s
                .positive("explained_variance")?
                .unwrap_or(defaults.explained_variance);
            if explained_variance > 1.0 {
                return Err(s
                    .error(
                        "explained_variance",
                        format!("must lie in (0, 1], got {explained_variance}"),
                    )
                    .into());
            }
            let max_components = s
                .count("max_components", 1)?
                .unwrap_or(defaults.max_components);
            s.finish()?;
            ReducedBasisSettings {
                explained_variance,
                max_components,
            }
        }
    };
    if study.abscissa.is_some()
        || matches!(study.model, crate::study::ModelSection::RbcShear { .. })
    {
        return Err(surrogate
            .error(
                "reduced_basis",
                "emulates a whole-curve model (one run per parameter vector returning every data point); this model runs once per data point",
            )
            .into());
    }
    Ok(ReducedBasisChoice::On(settings))
}

/// `[surrogate] posterior_check = { samples, seed, significance, retrain }`: the model itself
/// run at the MAP of the surrogate's posterior and at `samples` of its samples, in every run
/// group, and compared with the surrogate's prediction there — the surrogate checked where the
/// calibration uses it.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct PosteriorCheckSettings {
    /// Posterior samples run besides the MAP (`samples`, default 20).
    pub samples: usize,
    /// Seed of their choice among the posterior's samples (`seed`, default 0).
    pub seed: u64,
    /// The check's family-wise significance (`significance`, default 0.01): the chance that a
    /// surrogate whose predictive stds are right fails it
    /// ([`super::posterior_check::PosteriorCheck::verdict`]).
    pub significance: f64,
    /// With the adaptive engine: a check that fails joins the training runs and the rounds go
    /// on, then the check is made again at the new posterior (`retrain`, default true).
    pub retrain: bool,
    /// The smallest error that counts, in measurement stds of the datum (`resolution`,
    /// default 0.1): added in quadrature to each run's predictive std. At a typical residual
    /// (about one measurement std) an error of 0.1 std moves the datum's log-likelihood term by
    /// about 0.1 nats.
    pub resolution: f64,
}

/// Read `[surrogate] posterior_check`.
fn parse_posterior_check(mut s: StudySection<'_>) -> Result<PosteriorCheckSettings> {
    let samples = s.count_in("samples", 2, 100_000)?.unwrap_or(20);
    let seed = s.seed("seed")?.unwrap_or(0);
    let significance = s.positive("significance")?.unwrap_or(0.01);
    if significance >= 1.0 {
        return Err(s
            .error(
                "significance",
                format!("must lie in (0, 1), got {significance}"),
            )
            .into());
    }
    let retrain = s.boolean("retrain")?.unwrap_or(true);
    let resolution = match s.number("resolution")? {
        Some(r) if !(r >= 0.0 && r.is_finite()) => {
            return Err(s
                .error("resolution", format!("must be finite and ≥ 0, got {r}"))
                .into());
        }
        r => r.unwrap_or(0.1),
    };
    s.finish()?;
    Ok(PosteriorCheckSettings {
        samples,
        seed,
        significance,
        retrain,
        resolution,
    })
}

/// `[surrogate] adaptive = { ... }`: rounds of new runs placed where the posterior lies.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AdaptiveSettings {
    /// New runs per run group and round at most (`batch`, default [`DEFAULT_BATCH`]).
    pub batch: usize,
    /// Model runs of the pipeline in all (initial, test and adaptive) at most (`max_runs`,
    /// default [`DEFAULT_MAX_RUNS`]).
    pub max_runs: usize,
    /// The largest shift of a posterior mean or std between rounds, in posterior stds, that
    /// counts as converged (`tolerance`, default 0.1).
    pub tolerance: f64,
    /// The largest posterior-mean std of the log-likelihood due to the surrogate, in nats, that
    /// counts as converged (`log_likelihood_tolerance`, default 0.05).
    pub log_likelihood_tolerance: f64,
    /// How many times the surrogate's error ε counts against `tolerance`
    /// (`surrogate_error_multiple`, default
    /// [`iuq_adaptive::convergence::SURROGATE_ERROR_MULTIPLE`] = 2: every posterior mean and std
    /// within `tolerance` of the model's at about 95 %; the shipped red-cell studies name 1, the
    /// rule they were recorded under).
    pub surrogate_error_multiple: f64,
    /// BASIS population of each replicate of a round's posterior at first (`samples`,
    /// default 2000).
    pub samples: usize,
    /// BASIS population of each replicate while the posterior is still far from where it
    /// settles (`exploring_samples`, default `samples / 4`, at least 10; at most `samples`): the
    /// first round, and each round after one whose posterior moved, or whose surrogate error
    /// was, more than 10 tolerances (`iuq_adaptive::engine::FAR`). `exploring_samples = samples`
    /// samples every round fully (the engine before 2026-12, which the shipped studies name).
    pub exploring_samples: usize,
    /// Independent BASIS runs per round (`replicates`, default 4): their pooled population is the
    /// round's posterior, their spread the Monte Carlo error of its moments (1: error unknown,
    /// taken as zero).
    pub replicates: usize,
    /// The population a replicate may grow to (`max_samples`, default 16 × `samples`): while
    /// the sampler's noise on the shift exceeds the tolerance, each round doubles it.
    pub max_samples: usize,
    /// Rounds at most (`max_rounds`, default 30).
    pub max_rounds: usize,
    /// Distinct posterior samples scored as candidates for new runs (`candidates`, default 1000).
    pub candidates: usize,
    /// How candidates are scored (`acquisition`, default `"density"`).
    pub acquisition: Acquisition,
    /// When a round's replicates sample more (`more_samples`, default `"when-resolving"`).
    pub more_samples: MoreSamples,
    /// How a round samples its posterior (`sampling`, default `"sequential"`).
    pub sampling: PosteriorSampling,
    /// What the stopping rule compares between rounds (`stopping_rule`, default
    /// `"distribution"`: the moments and the distance between the posteriors).
    pub stopping_rule: StoppingRule,
    /// Where the final posterior sample starts (`final_sample`, default `"carried"`).
    pub final_sample: FinalSample,
}

/// Where the final posterior sample (`[sampler]`'s population of the last surrogate) starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum FinalSample {
    /// `"carried"`: from the last round's replicates pooled, reweighted to the final surrogate,
    /// resampled to `[sampler] samples` and moved (`iuq_basis::carried_population`), where the
    /// rounds' populations are kept in the store (`sampling = "sequential"` or `stopping_rule =
    /// "distribution"`) and the reweighting's ESS holds; else annealed from the prior. The last
    /// round sampled the same posterior, so this spares the annealing, most of the final
    /// sample's cost.
    Carried,
    /// `"from-prior"`: always annealed from the prior (the pipeline before 2026-12; the shipped
    /// HemoCell studies name it, so that their final posteriors replay as published).
    FromPrior,
}

/// How each round of the adaptive engine samples its surrogate posterior.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum PosteriorSampling {
    /// `"sequential"`: each replicate carries its population from the round before, reweighted
    /// to the new surrogate, resampled and moved (`iuq_basis::carried_population`); it anneals
    /// from the prior only in the first round and where the reweighting's ESS collapses.
    Sequential,
    /// `"from-prior"`: every round anneals each replicate from the prior (the engine before
    /// 2026-12; the shipped red-cell studies name it, so that their rounds replay as recorded).
    FromPrior,
}

/// When the next round's replicates sample twice as many (`more_samples`).
pub use iuq_adaptive::engine::MoreSamples;
/// What the stopping rule compares between rounds (`stopping_rule`).
pub use iuq_adaptive::engine::StoppingRule;

/// How the adaptive engine scores a candidate for a new run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Acquisition {
    /// `"moments"`: by how much a run there shrinks the first-order error of every posterior
    /// mean and std (`iuq_adaptive::moment_acquisition`), the quantity the stopping rule
    /// measures.
    Moments,
    /// `"density"`: the variance of the log-likelihood there times the squared relative
    /// posterior density (`iuq_adaptive::acquisition`, GPry's form).
    Density,
}

/// New runs per run group and round when `adaptive` gives no `batch` (as `iuq.calibrate`).
pub const DEFAULT_BATCH: usize = 2;

/// Model runs in all when `adaptive` gives no `max_runs` (as `iuq.calibrate`).
pub const DEFAULT_MAX_RUNS: usize = 300;

/// Initial runs of an adaptive study whose `design` gives no `n`: max(6, d + 2) for d
/// parameters (as `iuq.calibrate`); the engine places the rest where the posterior lies. A
/// one-shot design (no `adaptive`) takes 40.
pub fn default_adaptive_design_runs(dimension: usize) -> usize {
    6.max(dimension + 2)
}

/// The initial design per data point of an adaptive study whose model runs once per data point
/// and has a cheap model (`[low_fidelity]`): the data points' discrepancies are one GP in
/// (θ, abscissa) that pools their expensive runs (`iuq_gp::shared_discrepancy`), so each needs
/// only its share of 4·(d + 2) (twice the 2·(d + 2) the shared discrepancy asks for), at least
/// the 3 a GP needs and at most [`default_adaptive_design_runs`]: ⌈4(d + 2)/m⌉ clamped.
pub fn shared_discrepancy_design_runs(dimension: usize, data_points: usize) -> usize {
    (4 * (dimension + 2))
        .div_ceil(data_points.max(1))
        .clamp(3, default_adaptive_design_runs(dimension))
}

/// Read `[surrogate] adaptive`.
fn parse_adaptive(mut s: StudySection<'_>) -> Result<AdaptiveSettings> {
    let samples = s.count("samples", 10)?.unwrap_or(2000);
    let settings = AdaptiveSettings {
        batch: s.count("batch", 1)?.unwrap_or(DEFAULT_BATCH),
        max_runs: s.count("max_runs", 1)?.unwrap_or(DEFAULT_MAX_RUNS),
        tolerance: s.positive("tolerance")?.unwrap_or(0.1),
        log_likelihood_tolerance: s.positive("log_likelihood_tolerance")?.unwrap_or(0.05),
        surrogate_error_multiple: s
            .positive("surrogate_error_multiple")?
            .unwrap_or(iuq_adaptive::convergence::SURROGATE_ERROR_MULTIPLE),
        samples,
        exploring_samples: s
            .count_in("exploring_samples", 10, samples)?
            .unwrap_or((samples / 4).max(10)),
        replicates: s.count_in("replicates", 1, 64)?.unwrap_or(4),
        max_samples: s.count("max_samples", samples)?.unwrap_or(16 * samples),
        max_rounds: s.count("max_rounds", 1)?.unwrap_or(30),
        candidates: s.count_in("candidates", 1, 1_000_000)?.unwrap_or(1000),
        acquisition: match s.choice("acquisition", &["density", "moments"])? {
            Some("moments") => Acquisition::Moments,
            _ => Acquisition::Density,
        },
        more_samples: match s.choice("more_samples", &["when-noisy", "when-resolving"])? {
            Some("when-noisy") => MoreSamples::WhenNoisy,
            _ => MoreSamples::WhenResolving,
        },
        sampling: match s.choice("sampling", &["sequential", "from-prior"])? {
            Some("from-prior") => PosteriorSampling::FromPrior,
            _ => PosteriorSampling::Sequential,
        },
        stopping_rule: match s.choice("stopping_rule", &["distribution", "moments"])? {
            Some("moments") => StoppingRule::Moments,
            _ => StoppingRule::Distribution,
        },
        final_sample: match s.choice("final_sample", &["carried", "from-prior"])? {
            Some("from-prior") => FinalSample::FromPrior,
            _ => FinalSample::Carried,
        },
    };
    s.finish()?;
    Ok(settings)
}

/// Read one design table (`{ kind, n, seed }`) of `[surrogate]` (absent: `defaults`).
fn design(
    surrogate: &mut StudySection<'_>,
    key: &str,
    kind: &'static str,
    defaults: (usize, u64),
    min_runs: usize,
) -> Result<(usize, u64)> {
    let example = format!("{{ kind = \"{kind}\", n = 24, seed = 1 }}");
    let Some(mut s) = surrogate.section(key, &example)? else {
        return Ok(defaults);
    };
    s.choice("kind", &[kind])?;
    let n = s.count("n", min_runs)?.unwrap_or(defaults.0);
    let seed = s.seed("seed")?.unwrap_or(defaults.1);
    s.finish()?;
    Ok((n, seed))
}

/// Read and check the pipeline's settings of `study`.
pub fn parse_pipeline_settings(study: &Study) -> Result<PipelineSettings> {
    let file = study.path.display().to_string();
    let mut surrogate = StudySection::optional(study.surrogate.as_ref(), "surrogate", &file);
    let posterior_check = surrogate
        .section("posterior_check", "{ samples = 20, seed = 5 }")?
        .map(parse_posterior_check)
        .transpose()?;
    let adaptive = surrogate
        .section("adaptive", "{ batch = 4, max_runs = 200, tolerance = 0.1 }")?
        .map(parse_adaptive)
        .transpose()?;
    // A GP needs 3 successful runs.
    let d = study.space.dimension();
    let per_data_point = study.abscissa.is_some()
        || matches!(study.model, crate::study::ModelSection::RbcShear { .. });
    let default_runs = match &adaptive {
        Some(_) if study.low_fidelity.is_some() && per_data_point => {
            match crate::likelihood_section::parse_likelihood(study)? {
                crate::likelihood_section::LikelihoodSection::Data(data) => {
                    shared_discrepancy_design_runs(d, data.x.len())
                }
                _ => default_adaptive_design_runs(d),
            }
        }
        Some(_) => default_adaptive_design_runs(d),
        None => 40,
    };
    let (training_runs, training_seed) =
        design(&mut surrogate, "design", "lhs", (default_runs, 1), 3)?;
    // An adaptive study spends its runs where the posterior lies: no test runs unless asked for.
    let default_test = if adaptive.is_some() { 0 } else { 8 };
    let (test_runs, test_seed) = design(&mut surrogate, "test", "sobol", (default_test, 2), 0)?;
    if test_runs == 1 {
        return Err(surrogate
            .error(
                "test.n",
                "0 (no test runs) or at least 2 (a Q2 needs two), got 1",
            )
            .into());
    }
    let maximin_candidates = surrogate.count("maximin_candidates", 1)?.unwrap_or(100);
    let reduced_basis = parse_reduced_basis(&mut surrogate, study)?;
    surrogate.finish()?;
    let s = &study.sensitivity;
    let surrogate_sobol_n = s.n.unwrap_or(1024);
    if surrogate_sobol_n < 2 {
        return Err(input_error(format!(
            "{file}: key `sensitivity.n`: at least 2 base points are needed, got {surrogate_sobol_n}"
        )));
    }
    let model_sobol_n = s.model_n.unwrap_or(0);
    if model_sobol_n == 1 {
        return Err(input_error(format!(
            "{file}: key `sensitivity.model_n`: 0 (none) or at least 2 base points, got 1"
        )));
    }
    let confidence = s.confidence.unwrap_or(0.95);
    if !(confidence > 0.0 && confidence < 1.0) {
        return Err(input_error(format!(
            "{file}: key `sensitivity.confidence`: {confidence} must lie strictly between 0 and 1"
        )));
    }
    if s.replicates.is_some() {
        return Err(input_error(format!(
            "{file}: key `sensitivity.replicates`: the pipeline uses bootstrap intervals (set `resamples`)"
        )));
    }
    let resamples = s.resamples.unwrap_or(100);
    if resamples < 2 {
        return Err(input_error(format!(
            "{file}: key `sensitivity.resamples`: at least 2 are needed, got {resamples}"
        )));
    }
    Ok(PipelineSettings {
        training_runs,
        training_seed,
        maximin_candidates,
        test_runs,
        test_seed,
        surrogate_sobol_n,
        model_sobol_n,
        sobol_seed: s.seed.unwrap_or(0),
        confidence,
        resamples,
        adaptive,
        posterior_check,
        reduced_basis,
    })
}

/// The final surrogate posterior's population where `[sampler]` gives no `samples` (that of
/// `iuq.calibrate`'s default).
pub const PIPELINE_FINAL_SAMPLES: usize = 10_000;

#[cfg(test)]
mod tests {
    use super::shared_discrepancy_design_runs;

    #[test]
    fn a_shared_discrepancy_starts_each_data_point_from_its_share_of_the_pooled_runs() {
        // 2 parameters, 10 data points: ⌈16/10⌉ = 2, raised to a GP's 3 (30 in all).
        assert_eq!(shared_discrepancy_design_runs(2, 10), 3);
        // 4 parameters, 4 data points: ⌈24/4⌉ = 6 each.
        assert_eq!(shared_discrepancy_design_runs(4, 4), 6);
        // Never more than one fidelity's default, max(6, d + 2).
        assert_eq!(shared_discrepancy_design_runs(2, 2), 6);
        assert_eq!(shared_discrepancy_design_runs(8, 1), 10);
    }
}
