//! `iuq pipeline STUDY`: the calibration study end to end.
//!
//! 1. the training design (a maximin Latin hypercube per stress) and an independent test design
//!    (scrambled Sobol' points) run through the campaign executor — every result the campaign
//!    store already holds is reused;
//! 2. one GP per stress, validated by Q2 on the test runs (and leave-one-out Q2);
//! 3. Sobol' indices per stress from the surrogate and, with `[sensitivity] model_n`, from model
//!    runs;
//! 4. BASIS on the GP bank and, with `--model-posterior`, directly on the cell model through the
//!    campaign (`[model_sampler]`, chains of one step, no burn-in, resumable);
//! 5. posterior summaries and the propagation of the posterior to the outputs;
//! 6. the report: `DIR/report.html` with every figure as SVG and PNG and every table as CSV/JSON.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use clap::Args;
use serde_json::{Value, json};

use iuq_core::{Model, Outcome, ParameterSpace};
use iuq_doe::{LhsMethod, Scrambling, latin_hypercube, sobol_points};
use iuq_gp::{FitOptions, GaussianProcess, GpBank};
use iuq_sensitivity::{IntervalMethod, SensitivityOptions, SensitivityReport, analyse};

use crate::commands::basis::{SampledPosterior, build_posterior_with, sample_posterior};
use crate::input_error::{BadInput, input_error};
use crate::likelihood_section::{LikelihoodSection, parse_likelihood};
use crate::pipeline::cell_model_campaign::{CellModelAtStresses, open_cell_campaign, output_name};
use crate::pipeline::report_data::{PipelineOutcome, StressRuns, write_pipeline_report};
use crate::pipeline::settings::{PipelineSettings, parse_pipeline_settings};
use crate::report_output::emit;
use crate::sampler_section::{SamplerOverrides, parse_sampler};
use crate::study::Study;
use crate::table_io::{write_atomically, write_numeric_csv};

/// Arguments of `iuq pipeline`.
#[derive(Debug, Args)]
pub struct PipelineArgs {
    /// The study file (TOML) with a `[model]` of kind "rbc-shear" and a `[likelihood]` with data.
    pub study: PathBuf,
    /// Output directory of the report and every stage's results (default: `<study stem>-report`
    /// in the current directory).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Model runs at once (overrides `executor.max_parallel`; default: the number of cores).
    #[arg(long)]
    pub max_parallel: Option<usize>,
    /// Also sample the posterior directly on the cell model through the campaign, with
    /// `[model_sampler]` (expensive: samples × stages × stresses runs).
    #[arg(long)]
    pub model_posterior: bool,
    /// Recompute every model run: move the campaign directory aside (to `<dir>.previous-N`)
    /// instead of reusing the results it holds.
    #[arg(long)]
    pub fresh: bool,
    /// Stop after the training and test runs (e.g. to make the campaign in a batch job).
    #[arg(long)]
    pub runs_only: bool,
}

/// The stresses of the study's data and the data themselves.
fn study_data(study: &Study) -> Result<crate::likelihood_section::DataLikelihood> {
    let file = study.path.display();
    match parse_likelihood(study)? {
        LikelihoodSection::Data(data) if data.prediction.is_none() => Ok(data),
        _ => Err(input_error(format!(
            "{file}: section `[likelihood]`: the pipeline calibrates the model on data: give `data = {{ file, x, y, ... }}` without `prediction`"
        ))),
    }
}

/// The training points at stress index j: a maximin Latin hypercube mapped through the priors.
fn training_points(
    space: &ParameterSpace,
    settings: &PipelineSettings,
    j: usize,
) -> Result<Vec<Vec<f64>>> {
    let unit = latin_hypercube(
        settings.training_runs,
        space.dimension(),
        LhsMethod::Maximin {
            candidates: settings.maximin_candidates,
        },
        settings.training_seed.wrapping_add(j as u64),
    )?;
    unit.iter()
        .map(|u| space.from_unit_cube(u).map_err(anyhow::Error::from))
        .collect()
}

/// The test points (the same at every stress): scrambled Sobol' points through the priors.
fn test_points(space: &ParameterSpace, settings: &PipelineSettings) -> Result<Vec<Vec<f64>>> {
    let unit = sobol_points(
        space.dimension(),
        settings.test_runs,
        Scrambling::LinearMatrixWithShift {
            seed: settings.test_seed,
            replicate: 0,
        },
    )?;
    unit.iter()
        .map(|u| space.from_unit_cube(u).map_err(anyhow::Error::from))
        .collect()
}

/// Move `dir` aside to the first free `<dir>.previous-N`.
fn move_aside(dir: &Path) -> Result<Option<PathBuf>> {
    if !dir.exists() {
        return Ok(None);
    }
    for k in 1.. {
        let target = PathBuf::from(format!("{}.previous-{k}", dir.display()));
        if !target.exists() {
            std::fs::rename(dir, &target)
                .with_context(|| format!("cannot move {} aside", dir.display()))?;
            return Ok(Some(target));
        }
    }
    Ok(None)
}

fn progress_observer(label: &'static str) -> iuq_campaign::campaign_model::ProgressObserver {
    Box::new(move |p: &iuq_campaign::Progress| {
        eprintln!(
            "pipeline: {label}: {}",
            crate::commands::run::progress_line("runs", p)
        );
    })
}

fn split_runs(
    outcomes: &[Outcome],
    points: &[Vec<f64>],
) -> (Vec<Vec<f64>>, Vec<f64>, Vec<f64>, Vec<String>) {
    let mut x = Vec::new();
    let mut y = Vec::new();
    let mut std = Vec::new();
    let mut failures = Vec::new();
    for (o, p) in outcomes.iter().zip(points) {
        match o {
            Ok(e) => {
                x.push(p.clone());
                y.push(e.outputs[0]);
                std.push(e.computational_std.as_ref().map_or(0.0, |s| s[0]));
            }
            Err(f) => failures.push(f.reason.clone()),
        }
    }
    (x, y, std, failures)
}

/// Sobol' options of the pipeline with `n` base points.
fn sobol_options(settings: &PipelineSettings, n: usize) -> SensitivityOptions {
    SensitivityOptions {
        base_points: n,
        seed: settings.sobol_seed,
        interval: IntervalMethod::Bootstrap {
            resamples: settings.resamples,
        },
        confidence_level: settings.confidence,
        ..Default::default()
    }
}

/// Run `iuq pipeline`.
pub fn run(args: &PipelineArgs, json_output: bool) -> Result<()> {
    let started = Instant::now();
    let study = Study::load(&args.study)?;
    let data = study_data(&study)?;
    let settings = parse_pipeline_settings(&study)?;
    let sampler_settings = parse_sampler(&study, &SamplerOverrides::default())?;
    let model_sampler_settings = if args.model_posterior {
        let mut model_study = study.clone();
        model_study.sampler = study.model_sampler.clone();
        Some(parse_sampler(
            &model_study,
            &SamplerOverrides {
                burn: Some(0),
                max_chain: Some(1),
                ..Default::default()
            },
        )?)
    } else {
        None
    };
    let stem = study
        .path
        .file_stem()
        .map_or_else(|| "study".into(), |s| s.to_string_lossy().into_owned());
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("{stem}-report")));
    std::fs::create_dir_all(&out)
        .map_err(|e| input_error(format!("--out: cannot create {}: {e}", out.display())))?;
    if args.max_parallel == Some(0) {
        return Err(input_error("--max-parallel: must be at least 1"));
    }
    let stresses = data.x.clone();
    let names = study.space.names();
    let mut stage_seconds: Vec<(String, f64)> = Vec::new();

    // 1. Training and test runs through the campaign.
    let stage = Instant::now();
    if args.fresh {
        let dir = crate::pipeline::cell_model_campaign::campaign_directory(&study);
        if let Some(moved) = move_aside(&dir)? {
            eprintln!(
                "pipeline: --fresh: moved the earlier campaign to {}",
                moved.display()
            );
        }
    }
    let campaign = std::sync::Arc::new(
        open_cell_campaign(&study, &stresses, args.max_parallel)?
            .with_progress(Duration::from_secs(10), progress_observer("model runs")),
    );
    let test = test_points(&study.space, &settings)?;
    let mut runs: Vec<Vec<f64>> = Vec::new();
    let mut training: Vec<Vec<Vec<f64>>> = Vec::new();
    for j in 0..stresses.len() {
        training.push(training_points(&study.space, &settings, j)?);
    }
    for (j, s) in stresses.iter().enumerate() {
        for p in training[j].iter().chain(&test) {
            let mut x = p.clone();
            x.push(*s);
            runs.push(x);
        }
    }
    eprintln!(
        "pipeline: {} model runs ({} training + {} test at each of {} stresses; results already stored are reused)",
        runs.len(),
        settings.training_runs,
        settings.test_runs,
        stresses.len()
    );
    let outcomes = campaign.evaluate_batch(&runs)?;
    let per_stress = settings.training_runs + settings.test_runs;
    let mut stress_runs = Vec::new();
    for (j, s) in stresses.iter().enumerate() {
        let chunk = &outcomes[j * per_stress..(j + 1) * per_stress];
        let (train_out, test_out) = chunk.split_at(settings.training_runs);
        let (x, y, y_std, train_fail) = split_runs(train_out, &training[j]);
        let (xt, yt, yt_std, test_fail) = split_runs(test_out, &test);
        stress_runs.push(StressRuns {
            stress: *s,
            training_x: x,
            training_y: y,
            training_std: y_std,
            test_x: xt,
            test_y: yt,
            test_std: yt_std,
            failures: train_fail.into_iter().chain(test_fail).collect(),
        });
    }
    write_runs_csv(&out.join("model-runs.csv"), &names, &stress_runs)?;
    stage_seconds.push((
        "training and test runs".into(),
        stage.elapsed().as_secs_f64(),
    ));
    if args.runs_only {
        let failed: usize = stress_runs.iter().map(|r| r.failures.len()).sum();
        let value = json!({
            "study": study.name,
            "runs": runs.len(),
            "failed": failed,
            "out": out.display().to_string(),
            "seconds": started.elapsed().as_secs_f64(),
        });
        emit(json_output, &value, || {
            format!(
                "{} model runs of `{}` done ({failed} failed); results in {}",
                runs.len(),
                study.name,
                out.display()
            )
        });
        return Ok(());
    }

    // 2. One GP per stress.
    let stage = Instant::now();
    let mut gps: Vec<GaussianProcess> = Vec::new();
    let mut gp_checks: Vec<(f64, f64)> = Vec::new();
    for (j, r) in stress_runs.iter().enumerate() {
        if r.training_y.len() < 3 {
            anyhow::bail!(
                "at {} Pa only {} training runs succeeded; a GP needs at least 3 (failures: {})",
                r.stress,
                r.training_y.len(),
                r.failures.first().map_or("none", String::as_str)
            );
        }
        let options = FitOptions {
            seed: settings.training_seed.wrapping_add(j as u64),
            ..Default::default()
        };
        let gp = GaussianProcess::fit(&r.training_x, &r.training_y, &options)
            .with_context(|| format!("GP fit at {} Pa", r.stress))?;
        let q2 = if r.test_y.len() >= 2 {
            gp.q2(&r.test_x, &r.test_y).unwrap_or(f64::NAN)
        } else {
            f64::NAN
        };
        let loo = gp.loo_q2().unwrap_or(f64::NAN);
        gp_checks.push((q2, loo));
        gps.push(gp);
    }
    let outputs: Vec<String> = stresses.iter().map(|s| output_name(*s)).collect();
    let bank = GpBank::new(names.clone(), outputs.clone(), gps)?;
    write_atomically(&out.join("gp-bank.json"), bank.to_json_string()?.as_bytes())?;
    stage_seconds.push(("GP fits".into(), stage.elapsed().as_secs_f64()));

    // 3. Sobol' indices.
    let stage = Instant::now();
    let surrogate_sobol = analyse(
        &bank,
        &study.space,
        &sobol_options(&settings, settings.surrogate_sobol_n),
    )
    .bad_input(|| format!("{}: section `[sensitivity]`", study.path.display()))?;
    stage_seconds.push((
        "Sobol' on the surrogate".into(),
        stage.elapsed().as_secs_f64(),
    ));
    let model_sobol: Option<SensitivityReport> = if settings.model_sobol_n >= 2 {
        let stage = Instant::now();
        let cell = CellModelAtStresses::new(campaign.clone(), names.clone(), stresses.clone());
        eprintln!(
            "pipeline: Sobol' indices from model runs: N = {} base points, {} runs",
            settings.model_sobol_n,
            settings.model_sobol_n * (names.len() + 2) * stresses.len()
        );
        let report = analyse(
            &cell,
            &study.space,
            &sobol_options(&settings, settings.model_sobol_n),
        )
        .context("Sobol' indices from model runs")?;
        stage_seconds.push(("Sobol' on model runs".into(), stage.elapsed().as_secs_f64()));
        Some(report)
    } else {
        None
    };

    // 4. BASIS on the GP bank (and on the model).
    let stage = Instant::now();
    let posterior = build_posterior_with(&study, || Ok(bank.clone()))?;
    let gp_posterior = sample_posterior(
        &study.name,
        &study.path,
        &posterior,
        sampler_settings,
        &out.join("basis-gp"),
        None,
        None,
        None,
    )?;
    stage_seconds.push(("BASIS on the GP bank".into(), stage.elapsed().as_secs_f64()));
    let model_posterior: Option<SampledPosterior> = match model_sampler_settings {
        Some(settings) => {
            let stage = Instant::now();
            let dir = out.join("basis-model");
            let checkpoint = resume_checkpoint(&dir)?;
            let cell = CellModelAtStresses::new(campaign.clone(), names.clone(), stresses.clone());
            let posterior = build_posterior_with(&study, || Ok(cell))?;
            let sampled = sample_posterior(
                &study.name,
                &study.path,
                &posterior,
                settings,
                &dir,
                checkpoint,
                Some(&dir),
                None,
            )?;
            stage_seconds.push((
                "BASIS on the cell model".into(),
                stage.elapsed().as_secs_f64(),
            ));
            Some(sampled)
        }
        None => None,
    };

    // 5. Propagation and the report.
    let stage = Instant::now();
    let outcome = PipelineOutcome {
        study: &study,
        data: &data,
        settings: &settings,
        stress_runs: &stress_runs,
        gp_checks: &gp_checks,
        bank: &bank,
        surrogate_sobol: &surrogate_sobol,
        model_sobol: model_sobol.as_ref(),
        gp_posterior: &gp_posterior,
        model_posterior: model_posterior.as_ref(),
        campaign_runs: campaign
            .run_statistics()
            .context("reading the run statistics of the campaign store")?,
    };
    stage_seconds.push(("propagation and report".into(), 0.0));
    let summary = write_pipeline_report(&outcome, &out, &mut stage_seconds, stage)?;
    let total = started.elapsed().as_secs_f64();
    let value = json!({
        "study": study.name,
        "out": out.display().to_string(),
        "report": out.join("report.html").display().to_string(),
        "runs": runs.len(),
        "q2": gp_checks.iter().map(|c| c.0).collect::<Vec<_>>(),
        "posterior": summary,
        "stage_seconds": stage_seconds.iter().map(|(k, v)| json!({"stage": k, "seconds": v})).collect::<Vec<_>>(),
        "seconds": total,
    });
    emit(json_output, &value, || {
        format!(
            "study `{}`: report in {} ({total:.1} s)",
            study.name,
            out.join("report.html").display()
        )
    });
    Ok(())
}

fn resume_checkpoint(dir: &Path) -> Result<Option<iuq_basis::BasisState>> {
    let path = dir.join("checkpoint.json");
    if !path.exists() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("cannot read {}", path.display()))?;
    let state = iuq_basis::checkpoint::from_json(&text)
        .bad_input(|| format!("{}: not a BASIS checkpoint", path.display()))?;
    eprintln!(
        "pipeline: resuming the model posterior from {}",
        path.display()
    );
    Ok(Some(state))
}

fn write_runs_csv(path: &Path, names: &[String], runs: &[StressRuns]) -> Result<()> {
    let mut columns = vec!["stress".to_string(), "set".to_string()];
    columns.extend(names.iter().cloned());
    columns.push("el".into());
    columns.push("el_std".into());
    let mut rows = Vec::new();
    for r in runs {
        for (set, xs, ys, ss) in [
            (0.0, &r.training_x, &r.training_y, &r.training_std),
            (1.0, &r.test_x, &r.test_y, &r.test_std),
        ] {
            for ((x, y), s) in xs.iter().zip(ys).zip(ss) {
                let mut row = vec![r.stress, set];
                row.extend(x.iter().copied());
                row.push(*y);
                row.push(*s);
                rows.push(row);
            }
        }
    }
    write_numeric_csv(path, &columns, &rows)
}

/// JSON of a Sobol' report, by output and parameter.
pub fn sobol_json(report: &SensitivityReport) -> Value {
    let outputs: Vec<Value> = report
        .outputs
        .iter()
        .map(|o| {
            json!({
                "output": o.output,
                "S1": o.first_order, "S1_conf": o.first_order_conf,
                "ST": o.total, "ST_conf": o.total_conf,
                "variance": o.variance,
            })
        })
        .collect();
    json!({
        "inputs": report.inputs,
        "outputs": outputs,
        "evaluations": report.evaluations,
        "failed_evaluations": report.failed_evaluations,
        "failure_handling": report.failure_handling(),
    })
}
