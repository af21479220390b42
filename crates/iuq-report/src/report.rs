//! [`write_report`]: validates a study's results, draws the figures, writes the tables,
//! `report.json` and, last, `report.html`.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::derived::DerivedResults;
use crate::error::{ReportError, Result};
use crate::figure::FigureInfo;
use crate::files::{create_dir, write_atomic};
use crate::html::render_page;
use crate::input::StudyReport;
use crate::sections::build_sections;
use crate::tables::TableInfo;
use crate::validate::validate;

/// Identifies the layout of `report.json`, so readers can tell versions apart.
pub const REPORT_FORMAT: &str = "iuq-report/1";

/// The content of `report.json`: the study's results as given, what the report derived from
/// them, and the figures and tables it wrote. Every number in the HTML tables is in here.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReportDocument {
    /// Always [`REPORT_FORMAT`].
    pub format: String,
    /// The study's results, exactly as passed to [`write_report`].
    pub report: StudyReport,
    /// Quantities computed for the report (prediction bands, MAP errors, totals).
    pub derived: DerivedResults,
    /// The figures, in page order.
    pub figures: Vec<FigureInfo>,
    /// The tables, in page order (downloads included).
    pub tables: Vec<TableInfo>,
}

/// The files [`write_report`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct ReportFiles {
    /// The self-contained page, `DIR/report.html`.
    pub html: PathBuf,
    /// Everything as JSON, `DIR/report.json`.
    pub json: PathBuf,
    /// Every figure file, SVG and PNG, under `DIR/figures/`.
    pub figures: Vec<PathBuf>,
    /// Every table file, CSV and JSON, under `DIR/tables/`.
    pub tables: Vec<PathBuf>,
}

/// Writes the report of `report` into `dir`: `figures/*.svg` and `*.png`, `tables/*.csv` and
/// `*.json`, `report.json` and the self-contained `report.html`.
///
/// The input is validated before anything is written, and every file is written atomically
/// with `report.html` last, so an error never leaves a half-written page. Empty `posteriors`,
/// `sensitivity`, `gp_diagnostics` or `failure_map`, and a `convergence` of `None`, omit their
/// sections.
pub fn write_report(report: &StudyReport, dir: &Path) -> Result<ReportFiles> {
    validate(report)?;
    let derived = DerivedResults::compute(report);
    let figures_dir = dir.join("figures");
    let tables_dir = dir.join("tables");
    create_dir(&figures_dir)?;
    create_dir(&tables_dir)?;

    let sections = build_sections(report, &derived, &figures_dir)?;

    let mut files = ReportFiles {
        html: dir.join("report.html"),
        json: dir.join("report.json"),
        figures: Vec::new(),
        tables: Vec::new(),
    };
    let mut figures = Vec::new();
    let mut tables = Vec::new();
    for section in &sections {
        for figure in &section.figures {
            files.figures.push(dir.join(&figure.info.svg));
            files.figures.push(dir.join(&figure.info.png));
            figures.push(figure.info.clone());
        }
        for table in section.tables.iter().chain(&section.downloads) {
            let info = table.info();
            let (csv, json) = (dir.join(&info.csv), dir.join(&info.json));
            write_atomic(&csv, &table.to_csv()?)?;
            write_atomic(&json, &table.to_json()?)?;
            files.tables.push(csv);
            files.tables.push(json);
            tables.push(info);
        }
    }

    let document = ReportDocument {
        format: REPORT_FORMAT.to_string(),
        report: report.clone(),
        derived,
        figures,
        tables,
    };
    // Compact: the samples make this file large, and it is read by programs.
    let json = serde_json::to_vec(&document).map_err(|source| ReportError::Json {
        what: "report.json".to_string(),
        source,
    })?;
    write_atomic(&files.json, &json)?;
    write_atomic(&files.html, render_page(report, &sections).as_bytes())?;
    Ok(files)
}
