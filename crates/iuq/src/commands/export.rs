//! `iuq export STUDY`: a tidy table of every run — parameters, outputs, status, reason — as CSV
//! or JSON.

use std::path::PathBuf;

use anyhow::Result;
use clap::{Args, ValueEnum};
use serde_json::json;

use iuq_campaign::export::{export_csv, export_json, export_rows};
use iuq_campaign::{CampaignStore, store_path};
use iuq_study::campaign_runs::campaign_error;
use iuq_study::campaign_study::load_study;
use iuq_study::table_io::write_atomically;

use crate::report_output::emit;

/// Export format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ExportFormat {
    /// Comma-separated values with a header line.
    Csv,
    /// A JSON array of objects.
    Json,
}

/// Arguments of `iuq export`.
#[derive(Debug, Args)]
pub struct ExportArgs {
    /// The study file.
    pub study: PathBuf,
    /// Output file (default: standard output).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Format (default: from the --out extension, else CSV; JSON with --json and no --out).
    #[arg(long, value_enum)]
    pub format: Option<ExportFormat>,
}

/// Run `iuq export`.
pub fn run(args: &ExportArgs, json: bool) -> Result<()> {
    let study = load_study(&args.study)?;
    let store = CampaignStore::open_existing(&store_path(&study)).map_err(campaign_error)?;
    let rows = export_rows(&store).map_err(campaign_error)?;
    let parameters = study.space.names();
    let outputs = study.model.outputs.clone();
    let format = args.format.unwrap_or_else(|| match &args.out {
        Some(p) if p.extension().is_some_and(|e| e == "json") => ExportFormat::Json,
        None if json => ExportFormat::Json,
        _ => ExportFormat::Csv,
    });
    let bytes = match format {
        ExportFormat::Csv => export_csv(&rows, &parameters, &outputs).map_err(campaign_error)?,
        ExportFormat::Json => {
            serde_json::to_vec_pretty(&export_json(&rows, &parameters, &outputs))?
        }
    };
    match &args.out {
        Some(path) => {
            write_atomically(path, &bytes)?;
            let value = json!({"rows": rows.len(), "out": path.display().to_string(), "format": format!("{format:?}").to_lowercase()});
            emit(json, &value, || {
                format!("wrote {} runs to {}", rows.len(), path.display())
            });
        }
        None if json => println!("{}", export_json(&rows, &parameters, &outputs)),
        None => {
            use std::io::Write;
            std::io::stdout().write_all(&bytes)?;
        }
    }
    Ok(())
}
