//! `iuq bench …`: in-process timings of the numerical kernels on the user's data, for the
//! side-by-side benchmark script (scripts/bench/surrogate_toolkit.py), which runs the Python
//! references on the same files. File reading and writing are outside the timed region.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;
use clap::{Args, Subcommand};
use serde_json::json;

use iuq_core::GaussianKde;

use crate::input_error::{BadInput, input_error};
use crate::report_output::{emit, short};
use crate::table_io::{read_numeric_csv, write_numeric_csv};

/// The kernels that can be timed.
#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// 2-D Gaussian KDE of the first two columns of a CSV, evaluated on a G×G grid spanning
    /// the data's range.
    Kde(KdeBenchArgs),
    /// Prediction of a saved GP at the points of a CSV file: mean only, and mean with variance.
    GpPredict(GpPredictBenchArgs),
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
    let (file, gp) = crate::commands::gp::load_gp(&args.model)?;
    let table = read_numeric_csv(&args.points, false)?;
    let x = table.select(&file.inputs, &args.points)?;
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
    }
}
