//! The pipeline's stages, in order, over one [`PipelineRun`]: the initial and test runs, the
//! adaptive rounds, the surrogate with BASIS on it and the model at its posterior (where that
//! check fails, its runs train the surrogate and the rounds go on), the surrogate's quality,
//! Sobol' indices, the model's own posterior, and the report.

use std::path::PathBuf;
use std::time::Instant;

use serde_json::Value;

use iuq_sensitivity::{SensitivityReport, analyse};

use super::adaptive::{self, AdaptiveOutcome};
use super::cell_model_campaign::campaign_directory;
use super::designs::{sobol_options, study_data, test_points, training_points};
use super::events::Events;
use super::low_fidelity::{LowFidelity, low_fidelity_study};
use super::model_runs::{ModelRuns, RunShape};
use super::posterior_check::{self, PosteriorCheck};
use super::records::{
    add_seconds, move_aside, point_description, point_runs, resume_checkpoint, write_runs_csv,
};
use super::report_data::{PipelineResults, PointRuns, write_pipeline_report};
use super::run_groups::{GroupRuns, RunOrigin};
use super::settings::PIPELINE_FINAL_SAMPLES;
use super::settings::{PipelineSettings, ReducedBasisChoice, parse_pipeline_settings};
use super::surrogate::{Emulation, GpStarts, Surrogate};
use super::{PipelineOptions, PipelineOutcome, cell_portraits, emulator, model_posterior};
use crate::error::{BadInput, Context, Result, input_error};
use crate::likelihood_section::DataLikelihood;
use crate::posterior::{SampledPosterior, build_posterior_with};
use crate::sampler_section::{SamplerOverrides, parse_model_sampler, parse_sampler};
use crate::study::Study;
use crate::table_io::write_atomically;

/// The stages' wall times, in the order they ran (a stage repeated after a failed posterior
/// check counts every pass).
type StageTimes = Vec<(String, f64)>;

/// One pipeline as its stages see it: the study, its data and settings, the campaign, where the
/// results go and where its events go.
struct PipelineRun<'a> {
    study: &'a Study,
    options: &'a PipelineOptions,
    events: &'a Events,
    data: DataLikelihood,
    settings: PipelineSettings,
    /// The final surrogate posterior's sampler.
    sampler_settings: iuq_basis::CheckedSettings,
    model_posterior_method: Option<model_posterior::ModelPosteriorMethod>,
    /// BASIS on the model itself (`--model-posterior` with `[model_sampler]`).
    model_sampler_settings: Option<iuq_basis::CheckedSettings>,
    out: PathBuf,
    model_runs: ModelRuns,
    /// The cheap model of `[low_fidelity]`, if any.
    low_fidelity: Option<LowFidelity>,
    emulation: Emulation,
}

/// The surrogate the pipeline ends with, its posterior, the check of the model at that
/// posterior, and what the adaptive engine did.
struct Calibration {
    surrogate: Surrogate,
    gp_posterior: SampledPosterior,
    posterior_check: Option<PosteriorCheck>,
    adaptive: Option<AdaptiveOutcome>,
}

/// The stages of [`super::run`], on the pipeline's thread.
pub(super) fn run_stages(
    study: &Study,
    options: &PipelineOptions,
    events: &Events,
) -> Result<PipelineOutcome> {
    let started = Instant::now();
    let mut times = StageTimes::new();
    let run = PipelineRun::open(study, options, events)?;
    let stage = Instant::now();
    let mut groups = run.initial_runs()?;
    times.push((
        "initial and test runs".into(),
        stage.elapsed().as_secs_f64(),
    ));
    if options.runs_only {
        return run.runs_only(&groups, times, started);
    }
    let stage = Instant::now();
    let adaptive = run.refine(&mut groups, None)?;
    if adaptive.is_some() {
        add_seconds(&mut times, "adaptive rounds", stage);
    }
    let calibration = run.calibrate(&mut groups, adaptive, &mut times)?;
    let point_runs = point_runs(&groups, &run.model_runs, &run.data);
    write_runs_csv(
        &run.out.join("model-runs.csv"),
        &study.space.names(),
        &point_runs,
    )?;
    let emulator = calibration.surrogate.emulator.clone();
    let gp_checks = run.surrogate_quality(&emulator, &point_runs)?;
    let (surrogate_sobol, model_sobol) = run.sensitivity(&emulator, &mut times)?;
    let reweighted = run.model_posterior(&calibration, &mut times)?;
    let (portraits, compared_portraits) = run.cell_portraits(reweighted.as_ref(), &mut times);
    let model_posterior = run.basis_on_model(&mut times)?;

    let stage = Instant::now();
    let results = PipelineResults {
        study,
        data: &run.data,
        settings: &run.settings,
        point_runs: &point_runs,
        gp_checks: &gp_checks,
        emulator: &emulator,
        surrogate_sobol: &surrogate_sobol,
        model_sobol: model_sobol.as_ref(),
        gp_posterior: &calibration.gp_posterior,
        model_posterior: model_posterior.as_ref(),
        reweighted: reweighted.as_ref(),
        portraits: portraits.as_deref(),
        compared_portraits: compared_portraits.as_deref(),
        campaign_runs: run
            .model_runs
            .campaign()
            .run_statistics()
            .context("reading the run statistics of the campaign store")?,
        adaptive: calibration.adaptive.as_ref(),
        posterior_check: calibration.posterior_check.as_ref(),
        groups: &groups,
        model_runs: &run.model_runs,
        surrogate: &calibration.surrogate,
        low_fidelity: run.low_fidelity.as_ref(),
    };
    times.push(("propagation and report".into(), 0.0));
    let summary = write_pipeline_report(&results, &run.out, &mut times, stage)?;
    Ok(PipelineOutcome {
        study: study.name.clone(),
        report: Some(run.out.join("report.html")),
        out: run.out.clone(),
        runs: groups.iter().map(GroupRuns::len).sum(),
        failed: groups.iter().map(|g| g.failure_reasons().len()).sum(),
        q2: gp_checks.iter().map(|c| c.0).collect(),
        posterior: summary,
        model_posterior: reweighted.as_ref().map(|r| r.to_json()),
        adaptive: calibration.adaptive,
        posterior_check: calibration.posterior_check,
        stage_seconds: times,
        seconds: started.elapsed().as_secs_f64(),
    })
}

impl<'a> PipelineRun<'a> {
    /// Read and check the study's settings, refuse bad options before any run, and open the
    /// campaign (moved aside first with `--fresh`).
    fn open(study: &'a Study, options: &'a PipelineOptions, events: &'a Events) -> Result<Self> {
        let data = study_data(study)?;
        let settings = parse_pipeline_settings(study)?;
        // The final posterior samples the surrogate, which costs no model run: by default as
        // many members as `iuq.calibrate` draws, enough for its moments to hold the adaptive
        // engine's tolerance (`AdaptiveOutcome::judge_final_sample`).
        let final_samples = study
            .sampler
            .as_ref()
            .is_none_or(|t| !t.contains_key("samples"))
            .then_some(PIPELINE_FINAL_SAMPLES);
        let sampler_settings = parse_sampler(
            study,
            &SamplerOverrides {
                samples: final_samples,
                ..Default::default()
            },
        )?;
        let model_posterior_method = options
            .model_posterior
            .then(|| model_posterior::parse_model_posterior(study))
            .transpose()?;
        if matches!(
            model_posterior_method,
            Some(model_posterior::ModelPosteriorMethod::Reweight(_))
        ) && sampler_settings.samples < iuq_basis::model_posterior::MIN_SAMPLES
        {
            // The members are drawn from the surrogate's population: refuse before any run.
            let file = study.path.display().to_string();
            return Err(iuq_study_file::StudySection::optional(
                study.sampler.as_ref(),
                "sampler",
                &file,
            )
            .error(
                "samples",
                format!(
                    "must be at least {} with --model-posterior: the model posterior's members are drawn from the surrogate's population",
                    iuq_basis::model_posterior::MIN_SAMPLES
                ),
            )
            .into());
        }
        // Checked before any run.
        let model_sampler_settings =
            if model_posterior_method == Some(model_posterior::ModelPosteriorMethod::Basis) {
                Some(parse_model_sampler(study, &SamplerOverrides::default())?)
            } else {
                None
            };
        let out = options.out.clone();
        std::fs::create_dir_all(&out).map_err(|e| {
            input_error(format!("--out: cannot create {}: {e}", out.display())).with_source(e)
        })?;
        if options.max_parallel == Some(0) {
            return Err(input_error("--max-parallel: must be at least 1"));
        }
        if options.fresh {
            let dir = campaign_directory(study);
            if let Some(moved) = move_aside(&dir)? {
                events.message(format!(
                    "--fresh: moved the earlier campaign to {}",
                    moved.display()
                ));
            }
        }
        // `[low_fidelity]`'s keys are checked before the study's campaign is opened.
        let low_fidelity_section = low_fidelity_study(
            study,
            settings.training_runs,
            settings.adaptive.as_ref().map_or(0, |a| a.max_runs),
            settings.training_seed,
        )?;
        // A reduced basis of two fidelities takes whole curves of both; checked before either
        // campaign is opened.
        let runs_whole_curve = |s: &Study| {
            s.abscissa.is_none() && !matches!(s.model, crate::study::ModelSection::RbcShear { .. })
        };
        let whole_curve = runs_whole_curve(study)
            && low_fidelity_section
                .as_ref()
                .is_none_or(|(low, _)| runs_whole_curve(low));
        if !whole_curve
            && low_fidelity_section.is_some()
            && matches!(settings.reduced_basis, ReducedBasisChoice::On(_))
        {
            return Err(input_error(format!(
                "{}: key `surrogate.reduced_basis`: a reduced basis of two fidelities needs both models to return the whole curve in one run (no `abscissa` in `[model]` or `[low_fidelity]`); remove it for a two-fidelity GP per data point",
                study.path.display()
            )));
        }
        let model_runs = ModelRuns::open(
            study,
            &data,
            options.max_parallel,
            options.callable.clone(),
            events,
            events.campaign_progress("model runs"),
        )?;
        let low_fidelity = match low_fidelity_section {
            Some((low_study, low_settings)) => Some(LowFidelity::open(
                &low_study,
                low_settings,
                &data,
                options.max_parallel,
                options.low_fidelity_callable.clone(),
                events,
            )?),
            None => None,
        };
        let emulation = Emulation::of(
            settings.reduced_basis.resolve(whole_curve, data.x.len()),
            &data,
        );
        Ok(Self {
            study,
            options,
            events,
            data,
            settings,
            sampler_settings,
            model_posterior_method,
            model_sampler_settings,
            out,
            model_runs,
            low_fidelity,
            emulation,
        })
    }

    fn describe(&self, j: usize) -> String {
        point_description(self.study, &self.data, j)
    }

    /// Stage 1: The initial and test runs of every run group through the campaign.
    fn initial_runs(&self) -> Result<Vec<GroupRuns>> {
        let (study, settings) = (self.study, &self.settings);
        let group_count = self.model_runs.groups();
        let test = test_points(&study.space, settings)?;
        let mut requests: Vec<(usize, Vec<f64>)> = Vec::new();
        let mut initial: Vec<Vec<Vec<f64>>> = Vec::with_capacity(group_count);
        for g in 0..group_count {
            let points = training_points(&study.space, settings, g)?;
            requests.extend(points.iter().chain(&test).map(|p| (g, p.clone())));
            initial.push(points);
        }
        self.events.message(format!(
            "{} model runs ({} initial + {} test {}; results already stored are reused)",
            requests.len(),
            settings.training_runs,
            settings.test_runs,
            match self.model_runs.shape() {
                RunShape::PerAbscissa { .. } => format!("at each of {} data points", group_count),
                RunShape::Curve =>
                    "parameter vectors, each run giving every data point".to_string(),
            }
        ));
        let outcomes = self.model_runs.run(None, &requests)?;
        let per_group = settings.training_runs + test.len();
        let mut groups: Vec<GroupRuns> = Vec::with_capacity(group_count);
        for (g, points) in initial.into_iter().enumerate() {
            let chunk = &outcomes[g * per_group..(g + 1) * per_group];
            let (train_out, test_out) = chunk.split_at(settings.training_runs);
            let mut group = GroupRuns::default();
            group.extend(RunOrigin::Initial, points, train_out.to_vec());
            group.extend(RunOrigin::Test, test.clone(), test_out.to_vec());
            groups.push(group);
        }
        if let Some(low) = &self.low_fidelity {
            low.initial_runs(
                study,
                &self.model_runs,
                &groups,
                settings.maximin_candidates,
            )?;
            self.events.message(format!(
                "{} low-fidelity runs (the initial points and a Latin hypercube of {})",
                low.runs_made()?,
                low.settings.design_runs
            ));
        }
        Ok(groups)
    }

    /// `--runs-only`: the runs' table, and no surrogate.
    fn runs_only(
        &self,
        groups: &[GroupRuns],
        times: StageTimes,
        started: Instant,
    ) -> Result<PipelineOutcome> {
        let point_runs = point_runs(groups, &self.model_runs, &self.data);
        write_runs_csv(
            &self.out.join("model-runs.csv"),
            &self.study.space.names(),
            &point_runs,
        )?;
        Ok(PipelineOutcome {
            study: self.study.name.clone(),
            out: self.out.clone(),
            report: None,
            runs: groups.iter().map(GroupRuns::len).sum(),
            failed: groups.iter().map(|g| g.failure_reasons().len()).sum(),
            q2: Vec::new(),
            posterior: Value::Null,
            model_posterior: None,
            adaptive: None,
            posterior_check: None,
            stage_seconds: times,
            seconds: started.elapsed().as_secs_f64(),
        })
    }

    /// Stage 2: The adaptive rounds (`None` without `[surrogate] adaptive`), going on from `earlier`
    /// after a failed posterior check.
    fn refine(
        &self,
        groups: &mut [GroupRuns],
        earlier: Option<AdaptiveOutcome>,
    ) -> Result<Option<AdaptiveOutcome>> {
        let Some(adaptive_settings) = self.settings.adaptive.as_ref() else {
            return Ok(None);
        };
        let adaptive_dir = self.out.join("adaptive");
        let describe = |j: usize| self.describe(j);
        let inputs = adaptive::RoundInputs {
            study: self.study,
            data: &self.data,
            settings: adaptive_settings,
            emulation: &self.emulation,
            training_seed: self.settings.training_seed,
            base_seed: parse_sampler(self.study, &SamplerOverrides::default())?.seed,
            runs: &self.model_runs,
            low_fidelity: self.low_fidelity.as_ref(),
            dir: &adaptive_dir,
            events: self.events,
            describe: &describe,
            recompute: self.options.recompute_rounds,
        };
        adaptive::refine(&inputs, groups, earlier).map(Some)
    }

    /// Stage 3: The surrogate (one GP per data point, failure classifiers), BASIS on it, and the
    /// model at its posterior: where that check fails its test after the engine stopped, its
    /// runs become training runs and the rounds go on.
    fn calibrate(
        &self,
        groups: &mut [GroupRuns],
        mut adaptive: Option<AdaptiveOutcome>,
        times: &mut StageTimes,
    ) -> Result<Calibration> {
        loop {
            let (surrogate, gp_posterior) =
                self.final_posterior(groups, adaptive.as_mut(), times)?;
            let Some(check) = &self.settings.posterior_check else {
                return Ok(Calibration {
                    surrogate,
                    gp_posterior,
                    posterior_check: None,
                    adaptive,
                });
            };
            let stage = Instant::now();
            let (checked, replayed) =
                self.check_posterior(check, &surrogate, &gp_posterior, adaptive.as_ref())?;
            add_seconds(times, "model at the posterior", stage);
            let made: usize = groups.iter().map(GroupRuns::len).sum();
            let retrain = match (&adaptive, &self.settings.adaptive) {
                (Some(outcome), Some(a)) => {
                    replayed
                        || (check.retrain
                            && !checked.verdict.passed
                            && outcome.converged
                            && made < a.max_runs
                            && outcome.last_round() < a.max_rounds)
                }
                _ => false,
            };
            let outcome = match adaptive.take() {
                Some(outcome) if retrain => outcome,
                other => {
                    return Ok(Calibration {
                        surrogate,
                        gp_posterior,
                        posterior_check: Some(checked),
                        adaptive: other,
                    });
                }
            };
            let outcome = self.retrain_on_check(outcome, &checked, groups)?;
            let stage = Instant::now();
            adaptive = self.refine(groups, Some(outcome))?;
            add_seconds(times, "adaptive rounds", stage);
        }
    }

    /// The surrogate of `groups` and its posterior sampled with `[sampler]` (at the rounds'
    /// last mixing level), held against the last round's (`AdaptiveOutcome::
    /// judge_final_sample`).
    fn final_posterior(
        &self,
        groups: &[GroupRuns],
        adaptive: Option<&mut AdaptiveOutcome>,
        times: &mut StageTimes,
    ) -> Result<(Surrogate, SampledPosterior)> {
        let stage = Instant::now();
        let surrogate = Surrogate::fit(
            groups,
            &self.model_runs,
            self.low_fidelity.as_ref(),
            &self.study.space,
            adaptive
                .as_ref()
                .map_or(GpStarts::cold(self.settings.training_seed), |outcome| {
                    outcome.final_gp_starts(self.settings.training_seed)
                }),
            &self.emulation,
            |j| self.describe(j),
        )?;
        add_seconds(times, "GP fits", stage);
        let stage = Instant::now();
        let posterior = build_posterior_with(self.study, || Ok(surrogate.clone()))?;
        // A sampler the adaptive engine found biased is not trusted with the final posterior
        // either: it is sampled at the rounds' last mixing level.
        let mixing = adaptive.as_ref().map_or(0, |a| a.mixing_level);
        let sampler = self.sampler_settings.with_stronger_mixing(mixing);
        let start = match adaptive.as_ref() {
            Some(outcome) => self.carried_final_start(outcome, &posterior, sampler)?,
            None => None,
        };
        let gp_posterior = self.events.sample(
            "GP bank",
            self.study,
            &posterior,
            sampler,
            &self.out.join("basis-gp"),
            start,
        )?;
        add_seconds(times, "BASIS on the GP bank", stage);
        // "Converged" holds only if the final sample carries the rounds' posterior.
        if let Some(outcome) = adaptive {
            let was = outcome.converged;
            outcome.judge_final_sample(
                &gp_posterior.summary.mean,
                &gp_posterior.summary.std,
                gp_posterior.run.state.samples.len(),
            );
            if was && !outcome.converged {
                self.events
                    .message(format!("adaptive: not converged: {}", outcome.stop_reason));
            }
        }
        Ok((surrogate, gp_posterior))
    }

    /// The final sample's start where it is carried from the last round (`final_sample =
    /// "carried"`): the round's replicates pooled, reweighted to the final surrogate and
    /// resampled to the sampler's population, which the sampler's final pass then moves; `None`
    /// (anneal from the prior) where the rounds' populations are not kept or the reweighting's
    /// ESS collapses, which is said.
    fn carried_final_start(
        &self,
        outcome: &AdaptiveOutcome,
        posterior: &crate::posterior::StudyPosterior,
        sampler: iuq_basis::CheckedSettings,
    ) -> Result<Option<iuq_basis::BasisState>> {
        let Some(population) = outcome.final_population()? else {
            return Ok(None);
        };
        let failure = |e: iuq_basis::BasisError| {
            crate::error::StudyError::failure(format!("the final posterior sample: {e}"))
                .with_source(e)
        };
        let basis = iuq_basis::Basis::new(&posterior.space, posterior.likelihood.as_ref(), sampler)
            .map_err(failure)?;
        Ok(
            match iuq_basis::carried_population::carry(&basis, &population).map_err(failure)? {
                iuq_basis::carried_population::Carried::Ready(state) => Some(*state),
                iuq_basis::carried_population::Carried::Collapsed { ess_fraction } => {
                    self.events.message(format!(
                        "final posterior: the last round's population keeps an ESS of {:.1} % under the final surrogate; annealing from the prior",
                        100.0 * ess_fraction
                    ));
                    None
                }
            },
        )
    }

    /// The model run at the posterior's MAP and samples, beside the surrogate; a check an
    /// earlier run of the study trained on (recorded under its round's label) is replayed from
    /// the store, points and all (`true`: replayed).
    fn check_posterior(
        &self,
        check: &super::settings::PosteriorCheckSettings,
        surrogate: &Surrogate,
        gp_posterior: &SampledPosterior,
        adaptive: Option<&AdaptiveOutcome>,
    ) -> Result<(PosteriorCheck, bool)> {
        let (study, data) = (self.study, &self.data);
        let recorded = match adaptive.filter(|o| o.converged) {
            Some(outcome) => {
                let label = posterior_check::retrained_check_label(outcome.last_round());
                self.model_runs.recorded_requests(&label)?.map(|requests| {
                    let points = requests
                        .into_iter()
                        .filter(|(g, _)| *g == 0)
                        .map(|(_, p)| p)
                        .collect();
                    posterior_check::CheckPoints::Recorded { points, label }
                })
            }
            None => None,
        };
        let replayed = recorded.is_some();
        self.events.message(format!(
            "the model at the posterior: the MAP and {} posterior samples{}, {} runs (results already stored are reused)",
            check.samples,
            if replayed {
                " (a check trained on, replayed from the store)"
            } else {
                ""
            },
            (check.samples + 1) * self.model_runs.groups()
        ));
        // Each datum's likelihood std without the surrogate, at the MAP (σ_m where sampled).
        let sigma_m = data.modelling_error.as_ref().and_then(|_| {
            gp_posterior
                .summary
                .map
                .get(study.space.dimension())
                .copied()
        });
        let likelihood_std: Vec<f64> = (0..data.x.len())
            .map(|j| adaptive::total_variance(data, j, sigma_m).sqrt())
            .collect();
        let checked = posterior_check::check_posterior(
            recorded.unwrap_or(posterior_check::CheckPoints::Posterior(gp_posterior)),
            surrogate,
            &self.model_runs,
            check,
            &likelihood_std,
        )?;
        write_atomically(
            &self.out.join("posterior-check.json"),
            serde_json::to_string_pretty(&checked)?.as_bytes(),
        )?;
        Ok((checked, replayed))
    }

    /// A failed check's runs become training runs of `groups`; the outcome goes on from the
    /// round after its last.
    fn retrain_on_check(
        &self,
        mut outcome: AdaptiveOutcome,
        checked: &PosteriorCheck,
        groups: &mut [GroupRuns],
    ) -> Result<AdaptiveOutcome> {
        let failed_at: Vec<String> = checked
            .verdict
            .failed_points
            .iter()
            .map(|&j| format!("{}", checked.points[j].x))
            .collect();
        self.events.message(format!(
            "the posterior check after round {} failed its test at {} (largest |z| {:.2}, bound {:.2}): its {} runs become training runs and the rounds go on",
            outcome.last_round(),
            failed_at.join(", "),
            checked.verdict.largest_z,
            checked.verdict.z_bound,
            (checked.samples.len() + 1) * self.model_runs.groups()
        ));
        write_atomically(
            &self.out.join(format!(
                "posterior-check-after-round-{}.json",
                outcome.last_round()
            )),
            serde_json::to_string_pretty(checked)?.as_bytes(),
        )?;
        outcome.retrain_on_check(checked, checked.verdict.clone(), &self.model_runs, groups)?;
        Ok(outcome)
    }

    /// The test runs' Q2 and the leave-one-out Q2 of each data point's GP (NaN where not
    /// defined), with the surrogate written beside the report (`gp-bank.json` or
    /// `reduced-basis.json`).
    fn surrogate_quality(
        &self,
        emulator: &emulator::Emulator,
        point_runs: &[PointRuns],
    ) -> Result<Vec<(f64, f64)>> {
        let mut gp_checks: Vec<(f64, f64)> = Vec::new();
        match emulator {
            emulator::Emulator::PerOutput(bank) => {
                for (gp, r) in bank.gps().iter().zip(point_runs) {
                    let q2 = if r.test_y.len() >= 2 {
                        gp.q2(&r.test_x, &r.test_y).unwrap_or(f64::NAN)
                    } else {
                        f64::NAN
                    };
                    gp_checks.push((q2, gp.loo_q2().unwrap_or(f64::NAN)));
                }
                write_atomically(
                    &self.out.join("gp-bank.json"),
                    bank.to_json_string()?.as_bytes(),
                )?;
            }
            emulator::Emulator::ReducedBasis(basis) => {
                // The test runs' Q2 per data point; a reduced basis has no leave-one-out Q2.
                for (j, r) in point_runs.iter().enumerate() {
                    let q2 = if r.test_y.len() >= 2 {
                        let predicted = &emulator.predict_means(&r.test_x)?[j];
                        iuq_gp::q2(&r.test_y, predicted).unwrap_or(f64::NAN)
                    } else {
                        f64::NAN
                    };
                    gp_checks.push((q2, f64::NAN));
                }
                let summary = serde_json::json!({
                    "components": basis.components(),
                    "explained_variance": basis.explained_variance(),
                    "explained_variance_total": basis.explained_variance().iter().sum::<f64>(),
                    "truncation_std": basis.truncation_variance().iter().map(|v| v.sqrt()).collect::<Vec<f64>>(),
                    "outputs": basis.output_names(),
                });
                write_atomically(
                    &self.out.join("reduced-basis.json"),
                    serde_json::to_string_pretty(&summary)?.as_bytes(),
                )?;
                if basis.is_two_fidelity() {
                    let summary = super::low_fidelity::two_fidelity_basis_summary(basis);
                    write_atomically(
                        &self.out.join("two-fidelity.json"),
                        serde_json::to_string_pretty(&summary)?.as_bytes(),
                    )?;
                    self.events
                        .message(super::low_fidelity::two_fidelity_basis_message(basis));
                }
                self.events.message(format!(
                    "reduced basis: {} principal components explain {:.6} of the runs' variance (in measurement stds); largest truncation std {:.3e}",
                    basis.components(),
                    basis.explained_variance().iter().sum::<f64>(),
                    basis
                        .truncation_variance()
                        .iter()
                        .fold(0.0f64, |a, v| a.max(v.sqrt()))
                ));
            }
            emulator::Emulator::TwoFidelity(bank) => {
                let means = |x: &[Vec<f64>]| emulator.predict_means(x);
                for (j, r) in point_runs.iter().enumerate() {
                    let q2 = if r.test_y.len() >= 2 {
                        iuq_gp::q2(&r.test_y, &means(&r.test_x)?[j]).unwrap_or(f64::NAN)
                    } else {
                        f64::NAN
                    };
                    gp_checks.push((q2, f64::NAN));
                }
                let summary = super::low_fidelity::two_fidelity_summary(bank);
                write_atomically(
                    &self.out.join("two-fidelity.json"),
                    serde_json::to_string_pretty(&summary)?.as_bytes(),
                )?;
                self.events
                    .message(super::low_fidelity::two_fidelity_message(bank));
            }
        }
        Ok(gp_checks)
    }

    /// Stage 4: Sobol' indices on the surrogate, and on model runs where `[sensitivity] model_n`
    /// asks for them.
    fn sensitivity(
        &self,
        emulator: &emulator::Emulator,
        times: &mut StageTimes,
    ) -> Result<(SensitivityReport, Option<SensitivityReport>)> {
        let (study, settings) = (self.study, &self.settings);
        let stage = Instant::now();
        let section = || format!("{}: section `[sensitivity]`", study.path.display());
        let surrogate_sobol = analyse(
            emulator,
            &study.space,
            &sobol_options(settings, settings.surrogate_sobol_n)
                .check()
                .bad_input(section)?,
        )
        .bad_input(section)?;
        times.push((
            "Sobol' on the surrogate".into(),
            stage.elapsed().as_secs_f64(),
        ));
        if settings.model_sobol_n < 2 {
            return Ok((surrogate_sobol, None));
        }
        let stage = Instant::now();
        self.events.message(format!(
            "Sobol' indices from model runs: N = {} base points, {} runs",
            settings.model_sobol_n,
            settings.model_sobol_n * (study.space.dimension() + 2) * self.model_runs.groups()
        ));
        let report = analyse(
            &self.model_runs.model_at_data(),
            &study.space,
            &sobol_options(settings, settings.model_sobol_n)
                .check()
                .bad_input(section)?,
        )
        .context("Sobol' indices from model runs")?;
        times.push(("Sobol' on model runs".into(), stage.elapsed().as_secs_f64()));
        Ok((surrogate_sobol, Some(report)))
    }

    /// Stage 5: The model's own posterior from the surrogate's (`--model-posterior` with
    /// `[model_posterior]`'s reweighting), with how far it moved from the surrogate's.
    fn model_posterior(
        &self,
        calibration: &Calibration,
        times: &mut StageTimes,
    ) -> Result<Option<model_posterior::ModelPosteriorOutcome>> {
        let Some(model_posterior::ModelPosteriorMethod::Reweight(settings)) =
            &self.model_posterior_method
        else {
            return Ok(None);
        };
        let events = self.events;
        let stage = Instant::now();
        let members = settings
            .method
            .samples
            .min(calibration.gp_posterior.run.state.samples.len());
        events.message(format!(
            "the model's posterior from the surrogate's: {members} samples, {} runs at first (results already stored are reused)",
            members * self.model_runs.groups()
        ));
        let outcome = model_posterior::model_posterior_from_surrogate(
            self.study,
            &calibration.gp_posterior,
            &calibration.surrogate,
            &self.model_runs,
            settings,
            &self.out,
            &mut |line| events.message(line),
        )?;
        let shifts = outcome.shift_from_surrogate();
        let (largest, k) = shifts
            .iter()
            .enumerate()
            .map(|(k, s)| (s.0.abs(), k))
            .fold((0.0, 0), |a, b| if b.0 > a.0 { b } else { a });
        events.message(format!(
            "the model's posterior: {} (k̂ {:.3}, threshold {:.3}; ESS {:.0}, {:.0} by ancestry from {} ancestors; {} model runs); it moved from the surrogate's by up to {largest:.3} posterior stds ({}, Monte Carlo error {:.3})",
            outcome.posterior.stop,
            outcome.posterior.pareto_k,
            outcome.posterior.pareto_k_threshold,
            outcome.posterior.effective_sample_size,
            outcome.effective_sample_size_by_ancestry(),
            outcome.posterior.ancestors,
            outcome.model_runs,
            outcome.posterior.names.get(k).map_or("-", String::as_str),
            shifts.get(k).map_or(0.0, |s| s.1),
        ));
        if let Some(heavy) = &outcome.posterior.heavy_tail_errors {
            events.message(format!(
                "the model's posterior: its weights are heavy-tailed (k̂ {:.3} above 0.5, where their variance is infinite): its standard errors are at least those of {} batches of the members, at the smoothed estimate's convergence rate {:.2} (the central limit theorem's is 1)",
                outcome.posterior.pareto_k, heavy.batches, heavy.convergence_rate
            ));
        } else if outcome.posterior.pareto_k > iuq_basis::heavy_tail_errors::CLT_PARETO_K {
            events.message(format!(
                "the model's posterior: its weights are heavy-tailed (k̂ {:.3} above 0.5, where their variance is infinite), but its members descend from {} ancestors, fewer than the {} that batches need: its standard errors are the delta method's and may understate the error (more members, `[model_posterior] samples`, give more ancestors)",
                outcome.posterior.pareto_k,
                outcome.posterior.ancestors,
                iuq_basis::heavy_tail_errors::MIN_GROUPS
            ));
        }
        // Members for the target Monte Carlo error where `max_samples` (or the surrogate's
        // population) stopped them short of it: the error's variance falls as
        // members^(−convergence rate).
        let (worst, floor) = outcome.largest_mcse_split();
        let target = settings.target_mcse;
        if worst > target && outcome.posterior.certified() {
            let members = outcome.member_sizing.last().map_or(0, |m| m.samples) as f64;
            events.message(
                match model_posterior::members_for_target(
                    members,
                    (worst, floor),
                    target,
                    outcome.convergence_rate(),
                ) {
                    None => format!(
                        "the model's posterior: its means carry a Monte Carlo error of up to {worst:.3} posterior stds, more than `target_mcse` = {target}, of which {floor:.3} is the surrogate posterior's own: more samples of it bring it there (`[sampler] samples`)"
                    ),
                    Some(needed) => format!(
                        "the model's posterior: its means carry a Monte Carlo error of up to {worst:.3} posterior stds, more than `target_mcse` = {target}; about {:.0} members would bring it there (`[model_posterior] max_samples`, at most the surrogate posterior's population, `[sampler] samples`)",
                        needed.ceil()
                    ),
                },
            );
        }
        times.push((
            "the model's posterior".into(),
            stage.elapsed().as_secs_f64(),
        ));
        Ok(Some(outcome))
    }

    /// The cell at both MAPs in pictures (the cell model only). Pictures only: a cell that
    /// cannot be portrayed (a run that fails where the campaign's did not) costs the figures,
    /// not the model posterior just made.
    fn cell_portraits(
        &self,
        reweighted: Option<&model_posterior::ModelPosteriorOutcome>,
        times: &mut StageTimes,
    ) -> (
        Option<Vec<iuq_rbc::ShearPortrait>>,
        Option<Vec<iuq_rbc::ShearPortrait>>,
    ) {
        let Some(outcome) = reweighted else {
            return (None, None);
        };
        let portray = |map: &[f64], whose: &str| {
            let d = self.model_runs.parameters().len();
            match cell_portraits::portraits_at(
                self.study,
                &self.model_runs,
                &map[..d],
                whose,
                &mut |line| self.events.message(line),
            ) {
                Ok(portraits) => portraits,
                Err(e) => {
                    self.events.message(format!(
                        "the cell at {whose} in pictures: {e} (the report goes without them)"
                    ));
                    None
                }
            }
        };
        let stage = Instant::now();
        let at_model_map = portray(&outcome.posterior.map, "the model posterior's MAP");
        let at_surrogate_map = at_model_map
            .as_ref()
            .and_then(|_| portray(&outcome.surrogate_map, "the surrogate posterior's MAP"));
        if at_model_map.is_some() {
            times.push(("the cell at the MAPs".into(), stage.elapsed().as_secs_f64()));
        }
        (at_model_map, at_surrogate_map)
    }

    /// BASIS on the model itself (`--model-posterior` with `[model_sampler]`), resuming its
    /// checkpoint.
    fn basis_on_model(&self, times: &mut StageTimes) -> Result<Option<SampledPosterior>> {
        let Some(settings) = self.model_sampler_settings else {
            return Ok(None);
        };
        let stage = Instant::now();
        let dir = self.out.join("basis-model");
        let checkpoint = resume_checkpoint(&dir, self.events)?;
        let model = self.model_runs.model_at_data();
        let posterior = build_posterior_with(self.study, || Ok(model))?;
        let sampled = self
            .events
            .sample("model", self.study, &posterior, settings, &dir, checkpoint)?;
        times.push(("BASIS on the model".into(), stage.elapsed().as_secs_f64()));
        Ok(Some(sampled))
    }
}
