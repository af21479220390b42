//! `iuq bench …`: in-process timings of the numerical kernels on the user's data, for the
//! side-by-side benchmark script (scripts/bench/surrogate_toolkit.py), which runs the Python
//! references on the same files. File reading and writing are outside the timed region.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;
use clap::{Args, Subcommand};
use serde_json::json;

use iuq_basis::{
    Basis, BasisSettings, ComputationalError, PosteriorSummary, PredictionErrorLikelihood, Silent,
};
use iuq_core::{GaussianKde, Model};
use iuq_gp::GpBank;
use iuq_study::gp_bank_benchmark::{
    GpBankBenchmark, MEASUREMENT_STD, RBC_PRIOR, RBC_TRUTH, SHEAR_STRESSES,
};
use iuq_study::table_io::{read_numeric_csv, write_numeric_csv};

use crate::input_error::{BadInput, input_error};
use crate::report_output::{emit, short};

/// The kernels that can be timed.
#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// 2-D Gaussian KDE of the first two columns of a CSV, evaluated on a G×G grid spanning
    /// the data's range.
    Kde(KdeBenchArgs),
    /// Prediction of a saved GP at the points of a CSV file: mean only, and mean with variance.
    GpPredict(GpPredictBenchArgs),
    /// BASIS (N = 10 000, n_burn = 10) on a 4-parameter posterior whose model is a bank of 8
    /// GPs (500 training points each) with the GP's predictive std as computational error:
    /// the issue-3 benchmark (scripts/bench/basis_gp_bank.py runs the Python reference).
    BasisGpBank(BasisGpBankArgs),
}

/// Arguments of `iuq bench gp-predict`.
#[derive(Debug, Args)]
pub struct GpPredictBenchArgs {
    /// A GP saved by `iuq gp fit`.
    #[arg(long)]
    pub model: PathBuf,
    /// Points (CSV with the GP's input columns).
    #[arg(long)]
    pub points: PathBuf,
    /// Timed repetitions (the median is reported).
    #[arg(long, default_value_t = 5)]
    pub repeats: usize,
}

/// Arguments of `iuq bench kde`.
#[derive(Debug, Args)]
pub struct KdeBenchArgs {
    /// CSV whose first two columns are the data.
    #[arg(long)]
    pub points: PathBuf,
    /// Grid points per axis.
    #[arg(long, default_value_t = 100)]
    pub grid: usize,
    /// Timed repetitions (the median is reported).
    #[arg(long, default_value_t = 5)]
    pub repeats: usize,
    /// Where to write the grid densities (columns x, y, density), for comparison.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Median of timings in seconds.
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Evenly spaced values from `lo` to `hi`.
pub fn linspace(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    if n == 1 {
        return vec![lo];
    }
    (0..n)
        .map(|i| lo + (hi - lo) * i as f64 / (n - 1) as f64)
        .collect()
}

fn kde(args: &KdeBenchArgs, json: bool) -> Result<()> {
    if args.repeats == 0 || args.grid == 0 {
        return Err(input_error("--repeats and --grid must be at least 1"));
    }
    if args.grid > 1 << 14 {
        return Err(input_error(format!(
            "--grid: {} is more than {} points per side",
            args.grid,
            1 << 14
        )));
    }
    let table = read_numeric_csv(&args.points, false)?;
    if table.columns.len() < 2 {
        return Err(input_error(format!(
            "{}: need two columns",
            args.points.display()
        )));
    }
    let points: Vec<Vec<f64>> = table.rows.iter().map(|r| vec![r[0], r[1]]).collect();
    let range = |k: usize| {
        let lo = points.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min);
        let hi = points
            .iter()
            .map(|p| p[k])
            .fold(f64::NEG_INFINITY, f64::max);
        (lo, hi)
    };
    let ((x0, x1), (y0, y1)) = (range(0), range(1));
    let xs = linspace(x0, x1, args.grid);
    let ys = linspace(y0, y1, args.grid);
    let mut times = Vec::with_capacity(args.repeats);
    let mut grid = Vec::new();
    for _ in 0..args.repeats {
        let start = Instant::now();
        let kde =
            GaussianKde::new(&points, None).bad_input(|| args.points.display().to_string())?;
        grid = kde.evaluate_grid_2d(&xs, &ys)?;
        times.push(start.elapsed().as_secs_f64());
    }
    if let Some(out) = &args.out {
        let rows: Vec<Vec<f64>> = ys
            .iter()
            .enumerate()
            .flat_map(|(j, &y)| xs.iter().enumerate().map(move |(i, &x)| (i, j, x, y)))
            .map(|(i, j, x, y)| vec![x, y, grid[j][i]])
            .collect();
        write_numeric_csv(out, &["x".into(), "y".into(), "density".into()], &rows)?;
    }
    let seconds = median(times);
    let value = json!({
        "kernel": "kde2d",
        "points": points.len(),
        "grid": args.grid,
        "seconds_median": seconds,
        "repeats": args.repeats,
        "threads": rayon::current_num_threads(),
    });
    emit(json, &value, || {
        format!(
            "2-D KDE of {} points on a {}×{} grid: {} s (median of {})",
            points.len(),
            args.grid,
            args.grid,
            short(seconds),
            args.repeats
        )
    });
    Ok(())
}

fn gp_predict(args: &GpPredictBenchArgs, json: bool) -> Result<()> {
    if args.repeats == 0 {
        return Err(input_error("--repeats must be at least 1"));
    }
    let bank = crate::commands::gp::load_gp(&args.model)?;
    let gp = &bank.gps()[0];
    let table = read_numeric_csv(&args.points, false)?;
    let x = table.select(bank.input_names(), &args.points)?;
    let mut with_variance = Vec::with_capacity(args.repeats);
    let mut mean_only = Vec::with_capacity(args.repeats);
    for _ in 0..args.repeats {
        let start = Instant::now();
        let p = gp.predict(&x)?;
        with_variance.push(start.elapsed().as_secs_f64());
        std::hint::black_box(p);
        let start = Instant::now();
        let m = gp.predict_mean(&x)?;
        mean_only.push(start.elapsed().as_secs_f64());
        std::hint::black_box(m);
    }
    let (seconds, seconds_mean) = (median(with_variance), median(mean_only));
    let value = json!({
        "kernel": "gp-predict",
        "points": x.len(),
        "n_training": gp.n_training(),
        "seconds_median": seconds,
        "seconds_mean_median": seconds_mean,
        "repeats": args.repeats,
        "threads": rayon::current_num_threads(),
    });
    emit(json, &value, || {
        format!(
            "GP prediction of {} points ({} training points): mean {} s, mean and variance {} s (medians of {})",
            x.len(),
            gp.n_training(),
            short(seconds_mean),
            short(seconds),
            args.repeats
        )
    });
    Ok(())
}

/// Run `iuq bench`.
pub fn run(command: &BenchCommand, json: bool) -> Result<()> {
    match command {
        BenchCommand::Kde(args) => kde(args, json),
        BenchCommand::GpPredict(args) => gp_predict(args, json),
        BenchCommand::BasisGpBank(args) => basis_gp_bank(args, json),
    }
}

/// Arguments of `iuq bench basis-gp-bank`.
#[derive(Debug, Args)]
pub struct BasisGpBankArgs {
    /// Population size N.
    #[arg(long, default_value_t = 10_000)]
    pub samples: usize,
    /// Discarded MCMC steps per chain and stage (n_burn).
    #[arg(long, default_value_t = 10)]
    pub burn: usize,
    /// Seed of the sampler.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Seed of the training design, the GP fits and the synthetic data.
    #[arg(long, default_value_t = 0)]
    pub data_seed: u64,
    /// Training points per GP (a maximin Latin hypercube on the prior box).
    #[arg(long, default_value_t = 500)]
    pub training: usize,
    /// Worker threads (default: RAYON_NUM_THREADS, else one per core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Timed sampler runs with the same seed (the median is reported).
    #[arg(long, default_value_t = 1)]
    pub repeats: usize,
    /// Load this GP bank (a `bank.json` written by `--out`) instead of fitting one.
    #[arg(long)]
    pub bank: Option<PathBuf>,
    /// Directory to write `bank.json` (the GP bank) and `data.json` (data, prior, settings,
    /// reference predictions) for the Python reference.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// How the GP's predictive std enters Σ: relative (the paper's), absolute-times-data (the
    /// study's code), absolute or none.
    #[arg(long, default_value = "relative")]
    pub computational_error: String,
}

fn basis_gp_bank(args: &BasisGpBankArgs, json: bool) -> Result<()> {
    if args.repeats == 0 || args.training < 2 {
        return Err(input_error(
            "--repeats must be at least 1 and --training at least 2",
        ));
    }
    let computational_error =
        ComputationalError::from_name(&args.computational_error).ok_or_else(|| {
            input_error(format!(
                "--computational-error: unknown convention `{}` (relative, absolute-times-data, absolute, none)",
                args.computational_error
            ))
        })?;
    let settings = BasisSettings {
        samples: args.samples,
        burn_in: args.burn,
        seed: args.seed,
        mixing: iuq_basis::Mixing::Fixed,
        ..Default::default()
    }
    .check()
    .bad_input(|| "--samples/--burn".to_string())?;
    let mut pool = rayon::ThreadPoolBuilder::new();
    if let Some(t) = args.threads {
        pool = pool.num_threads(t);
    }
    let pool = pool.build()?;
    pool.install(|| basis_gp_bank_in_pool(args, settings, computational_error, json))
}

fn basis_gp_bank_in_pool(
    args: &BasisGpBankArgs,
    settings: iuq_basis::CheckedSettings,
    computational_error: ComputationalError,
    json: bool,
) -> Result<()> {
    // The surrogate: 8 GPs on a maximin LHS (fitted, or loaded), and the synthetic data.
    let loaded = match &args.bank {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| input_error(format!("--bank: cannot read {}: {e}", path.display())))?;
            Some(GpBank::from_json_str(&text).bad_input(|| format!("--bank {}", path.display()))?)
        }
        None => None,
    };
    let GpBankBenchmark {
        bank,
        fit_seconds,
        observations,
        errors,
        model_space,
    } = GpBankBenchmark::new(args.training, args.data_seed, computational_error, loaded)
        .bad_input(|| match &args.bank {
            Some(path) => format!("--bank {}", path.display()),
            None => "--training".to_string(),
        })?;
    let values = observations.values.clone();

    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir)
            .map_err(|e| input_error(format!("--out: cannot create {}: {e}", dir.display())))?;
        // Reference predictions for the Python side's equality check.
        let check = GpBankBenchmark::check_points();
        let predictions = bank.predict(&check)?;
        let data = json!({
            "parameters": RBC_PRIOR.iter().map(|p| json!({"name": p.0, "lower": p.1, "upper": p.2})).collect::<Vec<_>>(),
            "modelling_error": {"name": iuq_basis::MODELLING_ERROR_NAME, "lower": 0.001, "upper": 0.1},
            "shear_stresses": SHEAR_STRESSES,
            "truth": RBC_TRUTH,
            "observations": values,
            "measurement_std": vec![MEASUREMENT_STD; values.len()],
            "computational_error": computational_error.name(),
            "predictive_std": "with_noise",
            "settings": settings.settings(),
            "check": {
                "points": check,
                "mean": predictions.iter().map(|p| p.mean.clone()).collect::<Vec<_>>(),
                "std": predictions.iter().map(|p| p.std_with_noise()).collect::<Vec<_>>(),
            },
        });
        std::fs::write(dir.join("bank.json"), bank.to_json_string()?)?;
        std::fs::write(dir.join("data.json"), serde_json::to_string_pretty(&data)?)?;
    }

    let likelihood = PredictionErrorLikelihood::new(bank, observations, errors)?;
    let space = likelihood.parameter_space(&model_space)?;
    let basis = Basis::new(&space, &likelihood, settings)?;
    let mut times = Vec::with_capacity(args.repeats);
    let mut run = None;
    for _ in 0..args.repeats {
        let start = Instant::now();
        let r = basis.run(&mut Silent)?;
        times.push(start.elapsed().as_secs_f64());
        run = Some(r);
    }
    let Some(run) = run else {
        return Err(input_error("--repeats must be at least 1"));
    };
    let state = &run.state;
    let summary = PosteriorSummary::from_state(state)?;
    let seconds = median(times.clone());
    let outputs = likelihood.model().output_dimension();
    let predictions = state.evaluations * outputs;
    let by_name = |v: &[f64]| -> serde_json::Map<String, serde_json::Value> {
        summary
            .names
            .iter()
            .zip(v)
            .map(|(k, x)| (k.clone(), json!(x)))
            .collect()
    };
    let stages: Vec<serde_json::Value> = state
        .diagnostics
        .iter()
        .map(|d| {
            json!({
                "stage": d.stage,
                "exponent": d.exponent,
                "acceptance_rate": d.acceptance_rate,
                "evaluations": d.evaluations,
                "batches": d.batches,
                "log_evidence": d.log_evidence,
                "wall_seconds": d.wall_seconds,
            })
        })
        .collect();
    let value = json!({
        "kernel": "basis-gp-bank",
        "threads": rayon::current_num_threads(),
        "samples": settings.samples,
        "burn_in": settings.burn_in,
        "seed": settings.seed,
        "n_training": args.training,
        "outputs": outputs,
        "computational_error": computational_error.name(),
        "fit_seconds": fit_seconds,
        "seconds_median": seconds,
        "seconds": times,
        "repeats": args.repeats,
        "stages": state.stages(),
        "evaluations": state.evaluations,
        "predictions": predictions,
        "seconds_per_prediction": seconds / predictions as f64,
        "log_evidence": state.log_evidence,
        "stop_reason": run.stop_reason.name(),
        "failures": state.failures(),
        "mean": by_name(&summary.mean),
        "std": by_name(&summary.std),
        "map": by_name(&summary.map),
        "stage_diagnostics": stages,
    });
    emit(json, &value, || {
        format!(
            "BASIS on a GP bank ({outputs} GPs × {} points), N = {}, n_burn = {}: {} s (median of {}), {} stages, {} evaluations, {} predictions ({} s each), ln Z = {}{}",
            args.training,
            settings.samples,
            settings.burn_in,
            short(seconds),
            args.repeats,
            state.stages(),
            state.evaluations,
            predictions,
            short(seconds / predictions as f64),
            short(state.log_evidence),
            fit_seconds.map_or(String::new(), |f| format!("; GP fit {} s", short(f))),
        )
    });
    Ok(())
}
