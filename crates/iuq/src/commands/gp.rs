//! `iuq gp fit|predict|validate`: Gaussian-process surrogates from CSV data.
//!
//! A fitted GP is saved as iuq's one GP file format, a GP bank of one output
//! (`{"format": "iuq-gp-bank", "version": 1, "input_names": [...], "output_names": ["y"], ...}`,
//! `iuq_gp::GpBank`), which records the input and output names, so that `predict` and
//! `validate` find their columns by name, and `iuq serve --surrogate` takes it as it takes the
//! pipeline's `gp-bank.json`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Result;
use clap::{Args, Subcommand};
use serde_json::json;

use iuq_core::Model;
use iuq_gp::{FitOptions, GaussianProcess, GpBank, Kernel};
use iuq_study::table_io::{read_numeric_csv, write_atomically, write_numeric_csv};

use crate::input_error::{BadInput, input_error};
use crate::report_output::{emit, short};

/// The verbs of `iuq gp`.
#[derive(Debug, Subcommand)]
pub enum GpCommand {
    /// Fit a GP to columns of a CSV file by maximising the log marginal likelihood.
    Fit(FitArgs),
    /// Predict mean and std at the points of a CSV file.
    Predict(PredictArgs),
    /// Predictivity Q2 of a fitted GP on a test set.
    Validate(ValidateArgs),
}

/// Kernel variants offered on the command line.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum KernelName {
    /// One length scale per input, signal and noise variance estimated.
    Ard,
    /// One length scale for all inputs.
    Isotropic,
    /// The study's original kernel: isotropic length scale, signal variance fixed at 1.
    StudyOriginal,
}

/// Arguments of `iuq gp fit`.
#[derive(Debug, Args)]
pub struct FitArgs {
    /// Training data (CSV with a header).
    #[arg(long)]
    pub data: PathBuf,
    /// Input columns, comma-separated.
    #[arg(long, value_delimiter = ',')]
    pub inputs: Vec<String>,
    /// Output column.
    #[arg(long)]
    pub output: String,
    /// Random starts of the optimiser in addition to the data-driven start.
    #[arg(long, default_value_t = 10)]
    pub restarts: usize,
    /// Seed of the multi-start design.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Kernel variant.
    #[arg(long, value_enum, default_value = "ard")]
    pub kernel: KernelName,
    /// Work on raw inputs instead of mapping them to the unit cube.
    #[arg(long)]
    pub raw_inputs: bool,
    /// Work on raw outputs instead of standardising them.
    #[arg(long)]
    pub raw_outputs: bool,
    /// Where to save the fitted GP (JSON).
    #[arg(long)]
    pub out: PathBuf,
}

/// Arguments of `iuq gp predict`.
#[derive(Debug, Args)]
pub struct PredictArgs {
    /// A GP saved by `iuq gp fit`.
    #[arg(long)]
    pub model: PathBuf,
    /// Points (CSV with the GP's input columns).
    #[arg(long)]
    pub points: PathBuf,
    /// Output CSV: the input columns, then `mean`, `std` (latent function) and `std_with_noise`.
    #[arg(long)]
    pub out: PathBuf,
}

/// Arguments of `iuq gp validate`.
#[derive(Debug, Args)]
pub struct ValidateArgs {
    /// A GP saved by `iuq gp fit`.
    #[arg(long)]
    pub model: PathBuf,
    /// Test data (CSV with the GP's input and output columns).
    #[arg(long)]
    pub data: PathBuf,
}

/// Read a GP file (a GP bank of one output); errors name the file.
pub fn load_gp(path: &Path) -> Result<GpBank> {
    Ok(iuq_study::gp_file::read_gp_file(path, "`iuq gp`")?)
}

fn fit(args: &FitArgs, json: bool) -> Result<()> {
    if args.inputs.is_empty() || args.inputs.iter().any(|s| s.trim().is_empty()) {
        return Err(input_error(
            "--inputs: give the input columns, e.g. --inputs a,b,c",
        ));
    }
    let table = read_numeric_csv(&args.data, false)?;
    let x = table.select(&args.inputs, &args.data)?;
    let y: Vec<f64> = table
        .select(std::slice::from_ref(&args.output), &args.data)?
        .into_iter()
        .map(|r| r[0])
        .collect();
    if x.len() < 2 {
        return Err(input_error(format!(
            "{}: at least two data rows are needed",
            args.data.display()
        )));
    }
    let options = FitOptions {
        kernel: match args.kernel {
            KernelName::Ard => Kernel::ard(),
            KernelName::Isotropic => Kernel::isotropic(),
            KernelName::StudyOriginal => Kernel::study_original(),
        },
        n_restarts: args.restarts,
        seed: args.seed,
        scale_inputs: !args.raw_inputs,
        standardize_outputs: !args.raw_outputs,
        ..FitOptions::default()
    };
    let options = options
        .check()
        .bad_input(|| "--kernel/--restarts".to_string())?;
    let start = Instant::now();
    let gp =
        GaussianProcess::fit(&x, &y, &options).bad_input(|| format!("{}", args.data.display()))?;
    let seconds = start.elapsed().as_secs_f64();
    let bank = GpBank::new(args.inputs.clone(), vec![args.output.clone()], vec![gp])
        .bad_input(|| format!("{}", args.data.display()))?;
    let gp = &bank.gps()[0];
    write_atomically(&args.out, bank.to_json_string()?.as_bytes())?;
    let h = gp.hyperparameters();
    let warnings = gp.diagnostics().messages();
    let value = json!({
        "log_marginal_likelihood": gp.log_marginal_likelihood(),
        "length_scales": h.length_scales,
        "length_scales_input_units": gp.length_scales_in_input_units(),
        "signal_variance": h.signal_variance,
        "noise_variance": h.noise_variance,
        "loo_q2": gp.loo_q2(),
        "seconds": seconds,
        "n_training": gp.n_training(),
        "restarts": args.restarts,
        "degenerate": gp.diagnostics().is_degenerate(),
        "warnings": warnings,
        "out": args.out.display().to_string(),
    });
    emit(json, &value, || {
        let mut text = format!(
            "fitted a GP of `{}` on {} points in {} s\nlog marginal likelihood (unit-cube inputs, standardised outputs): {}\nlength scales: {}\nsignal variance {}, noise variance {}\nleave-one-out Q2: {}\nsaved to {}",
            args.output,
            gp.n_training(),
            short(seconds),
            short(gp.log_marginal_likelihood()),
            h.length_scales
                .iter()
                .map(|v| short(*v))
                .collect::<Vec<_>>()
                .join(", "),
            short(h.signal_variance),
            short(h.noise_variance),
            gp.loo_q2().map_or("undefined".into(), short),
            args.out.display()
        );
        for w in &warnings {
            text.push_str(&format!("\nWARNING: {w}"));
        }
        text
    });
    Ok(())
}

fn predict(args: &PredictArgs, json: bool) -> Result<()> {
    let bank = load_gp(&args.model)?;
    let gp = &bank.gps()[0];
    let table = read_numeric_csv(&args.points, false)?;
    let x = table.select(bank.input_names(), &args.points)?;
    let start = Instant::now();
    let prediction = gp
        .predict(&x)
        .bad_input(|| format!("{}", args.points.display()))?;
    let seconds = start.elapsed().as_secs_f64();
    let mut columns = bank.input_names().to_vec();
    columns.extend([
        "mean".to_string(),
        "std".to_string(),
        "std_with_noise".to_string(),
    ]);
    let rows: Vec<Vec<f64>> = x
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let mut r = p.clone();
            let v = prediction.variance[i].max(0.0);
            r.extend([
                prediction.mean[i],
                v.sqrt(),
                (v + prediction.noise_variance).sqrt(),
            ]);
            r
        })
        .collect();
    write_numeric_csv(&args.out, &columns, &rows)?;
    let value =
        json!({"points": rows.len(), "seconds": seconds, "out": args.out.display().to_string()});
    emit(json, &value, || {
        format!(
            "predicted {} points in {} s; wrote {}",
            rows.len(),
            short(seconds),
            args.out.display()
        )
    });
    Ok(())
}

fn validate(args: &ValidateArgs, json: bool) -> Result<()> {
    let bank = load_gp(&args.model)?;
    let gp = &bank.gps()[0];
    let table = read_numeric_csv(&args.data, false)?;
    let x = table.select(bank.input_names(), &args.data)?;
    let y: Vec<f64> = table
        .select(&bank.output_names()[..1], &args.data)?
        .into_iter()
        .map(|r| r[0])
        .collect();
    let q2 = gp
        .q2(&x, &y)
        .bad_input(|| format!("{}", args.data.display()))?;
    let value = json!({"q2": q2, "points": y.len(), "loo_q2": gp.loo_q2()});
    emit(json, &value, || {
        format!("Q2 on {} test points: {}", y.len(), short(q2))
    });
    Ok(())
}

/// Run `iuq gp`.
pub fn run(command: &GpCommand, json: bool) -> Result<()> {
    match command {
        GpCommand::Fit(args) => fit(args, json),
        GpCommand::Predict(args) => predict(args, json),
        GpCommand::Validate(args) => validate(args, json),
    }
}
