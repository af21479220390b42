//! `iuq design lhs|sobol|saltelli`: space-filling designs written as CSV.

use std::path::PathBuf;

use anyhow::Result;
use clap::{Args, ValueEnum};
use serde_json::json;

use iuq_doe::{
    LhsMethod, SaltelliDesign, Scrambling, latin_hypercube, min_distance, scale_to_bounds,
    sobol_points,
};
use iuq_study::table_io::write_numeric_csv;

use crate::input_error::{BadInput, input_error};
use crate::report_output::{emit, short};

/// Which design to build.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum DesignKind {
    /// Latin hypercube.
    Lhs,
    /// Sobol' sequence (scrambled unless --unscrambled).
    Sobol,
    /// Saltelli design for Sobol' indices: N(d + 2) rows, grouped per base point as
    /// A_j, AB_1j … AB_dj, B_j.
    Saltelli,
}

/// Latin hypercube construction.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum LhsMethodName {
    /// Best of K random designs by minimum distance (pyDOE's maximin; K = --candidates).
    Maximin,
    /// Enhanced stochastic evolutionary optimisation of the φ_p criterion.
    Optimized,
    /// One random Latin hypercube.
    Random,
}

/// Arguments of `iuq design`.
#[derive(Debug, Args)]
pub struct DesignArgs {
    /// The design.
    pub kind: DesignKind,
    /// Number of points (base points N for saltelli).
    #[arg(long)]
    pub n: usize,
    /// Number of dimensions.
    #[arg(long)]
    pub dim: usize,
    /// Bounds per dimension, `lo:hi,lo:hi,...` (default: the unit cube).
    #[arg(long, allow_hyphen_values = true)]
    pub bounds: Option<String>,
    /// Latin hypercube method.
    #[arg(long, value_enum, default_value = "maximin")]
    pub method: LhsMethodName,
    /// Candidate designs of the maximin method.
    #[arg(long, default_value_t = iuq_doe::DEFAULT_MAXIMIN_CANDIDATES)]
    pub candidates: usize,
    /// Seed of the random design or scrambling.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Plain (unscrambled) Sobol' points, equal to scipy.stats.qmc.Sobol(scramble=False).
    #[arg(long)]
    pub unscrambled: bool,
    /// Output CSV file (columns x1..xD).
    #[arg(long)]
    pub out: PathBuf,
}

/// Parse `lo:hi,lo:hi,...` into `dim` pairs.
pub fn parse_bounds(text: &str, dim: usize) -> Result<Vec<(f64, f64)>> {
    let pairs: Vec<&str> = text.split(',').map(str::trim).collect();
    if pairs.len() != dim {
        return Err(input_error(format!(
            "--bounds: {} ranges given for --dim {dim}",
            pairs.len()
        )));
    }
    pairs
        .iter()
        .enumerate()
        .map(|(k, pair)| {
            let (lo, hi) = pair.split_once(':').ok_or_else(|| {
                input_error(format!("--bounds: range {} `{pair}` is not `lo:hi`", k + 1))
            })?;
            let lo: f64 = lo
                .trim()
                .parse()
                .bad_input(|| format!("--bounds: range {} lower `{lo}`", k + 1))?;
            let hi: f64 = hi
                .trim()
                .parse()
                .bad_input(|| format!("--bounds: range {} upper `{hi}`", k + 1))?;
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(input_error(format!(
                    "--bounds: range {} must have finite lo < hi, got {lo}:{hi}",
                    k + 1
                )));
            }
            Ok((lo, hi))
        })
        .collect()
}

/// Run `iuq design`.
pub fn run(args: &DesignArgs, json: bool) -> Result<()> {
    if args.n == 0 {
        return Err(input_error("--n: must be at least 1"));
    }
    if args.dim == 0 {
        return Err(input_error("--dim: must be at least 1"));
    }
    let bounds = args
        .bounds
        .as_deref()
        .map(|b| parse_bounds(b, args.dim))
        .transpose()?;
    let scrambling = if args.unscrambled {
        Scrambling::None
    } else {
        Scrambling::LinearMatrixWithShift {
            seed: args.seed,
            replicate: 0,
        }
    };
    let mut summary = json!({
        "design": format!("{:?}", args.kind).to_lowercase(),
        "dim": args.dim,
        "seed": args.seed,
        "out": args.out.display().to_string(),
    });
    let start = std::time::Instant::now();
    let unit = match args.kind {
        DesignKind::Lhs => {
            let method = match args.method {
                LhsMethodName::Maximin => {
                    if args.candidates == 0 {
                        return Err(input_error("--candidates: must be at least 1"));
                    }
                    LhsMethod::Maximin {
                        candidates: args.candidates,
                    }
                }
                LhsMethodName::Optimized => LhsMethod::optimized(),
                LhsMethodName::Random => LhsMethod::Random,
            };
            let points = latin_hypercube(args.n, args.dim, method, args.seed)
                .bad_input(|| "design".into())?;
            summary["method"] = json!(format!("{:?}", args.method).to_lowercase());
            summary["min_distance"] = json!(min_distance(&points));
            points
        }
        DesignKind::Sobol => {
            summary["scrambled"] = json!(!args.unscrambled);
            sobol_points(args.dim, args.n, scrambling).bad_input(|| "design".into())?
        }
        DesignKind::Saltelli => {
            summary["scrambled"] = json!(!args.unscrambled);
            summary["base_points"] = json!(args.n);
            SaltelliDesign::new(args.n, args.dim, scrambling)
                .bad_input(|| "design".into())?
                .rows()
        }
    };
    let rows = match &bounds {
        Some(b) => scale_to_bounds(&unit, b).bad_input(|| "--bounds".into())?,
        None => unit,
    };
    summary["rows"] = json!(rows.len());
    summary["seconds"] = json!(start.elapsed().as_secs_f64());
    let columns: Vec<String> = (1..=args.dim).map(|k| format!("x{k}")).collect();
    write_numeric_csv(&args.out, &columns, &rows)?;
    emit(json, &summary, || {
        let mut text = format!(
            "wrote {} rows of a {}-dimensional {} design to {}",
            rows.len(),
            args.dim,
            summary["design"].as_str().unwrap_or_default(),
            args.out.display()
        );
        if let Some(d) = summary["min_distance"].as_f64() {
            text.push_str(&format!(
                "\nminimum pairwise distance (unit cube): {}",
                short(d)
            ));
        }
        text
    });
    Ok(())
}
