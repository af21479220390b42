//! The calibration study's report: figures as SVG and PNG, tables as CSV and JSON, everything
//! in `report.json`, and one self-contained `report.html` (inline CSS and SVG, no scripts, no
//! external resources).
//!
//! `iuq pipeline` fills a [`StudyReport`] and calls [`write_report`]. The page shows, in order:
//! the measurements against the calibrated model, the posterior summary, Sobol' indices, the
//! corner plot, the propagated output as violins, the MAP error, the surrogate's quality, the
//! sampler's stages, the convergence of the adaptive design, where the model fails, and the run
//! statistics. Every number in an HTML table is formatted by
//! [`format_number`] and carries its exact value and its JSON pointer into `report.json`.
//!
//! - [`input`]: the input structures;
//! - [`write_report`]: validation and output;
//! - the charts (one module per kind) are private; colours are fixed per source (GP surrogate
//!   blue, cell model and model runs orange, measurements black).
//!
//! # Example
//!
//! A report of measurements alone (every optional section left empty): the page, its JSON
//! and the data-fit figure are written, and a bad input (a negative measurement std) is refused
//! before anything is written.
//!
//! ```
//! use iuq_report::{DataSeries, RunStatistics, StudyReport, write_report};
//!
//! let mut report = StudyReport {
//!     title: "Cooling of a cup".into(),
//!     study_name: "cooling".into(),
//!     provenance: vec![("iuq".into(), "0.1.0".into())],
//!     parameters: vec!["k".into()],
//!     data: DataSeries {
//!         x_label: "time (min)".into(),
//!         y_label: "temperature (°C)".into(),
//!         x: vec![0.0, 5.0, 10.0],
//!         y: vec![90.0, 61.0, 45.0],
//!         y_err: vec![0.5, 0.5, 0.5],
//!     },
//!     posteriors: vec![],
//!     sensitivity: vec![],
//!     gp_diagnostics: vec![],
//!     run_statistics: RunStatistics::default(),
//!     convergence: None,
//!     failure_map: vec![],
//!     runs_per_point: vec![],
//!     posterior_check: None,
//!     model_posterior: None,
//!     cell_portraits: None,
//!     two_fidelity: vec![],
//!     two_fidelity_components: vec![],
//! };
//! let dir = std::env::temp_dir().join(format!("iuq-report-doc-{}", std::process::id()));
//! let files = write_report(&report, &dir)?;
//! assert!(std::fs::read_to_string(&files.html)?.contains("Cooling of a cup"));
//! assert!(files.figures.iter().any(|f| f.ends_with("data_fit.svg")));
//!
//! report.data.y_err[1] = -0.5;
//! let elsewhere = dir.join("bad");
//! assert!(write_report(&report, &elsewhere).is_err());
//! assert!(!elsewhere.join("report.html").exists());
//! # std::fs::remove_dir_all(&dir)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]
// No panic reachable from user input: a library reports every failure in its error type.
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

mod axis;
mod charts;
mod derived;
pub mod error;
mod figure;
mod files;
mod format;
mod html;
pub mod input;
mod report;
mod report_tables;
mod sections;
mod statistics;
mod style;
mod tables;
mod validate;

pub use derived::{DerivedResults, PredictionPoint, SourcePredictions};
pub use error::{ReportError, Result};
pub use figure::FigureInfo;
pub use format::format_number;
pub use input::{
    CellPortrait, CellPortraits, CheckedPoint, ComparedParameter, ComparedTraces, Convergence,
    ConvergenceRound, DataSeries, ElongationTrace, FailureMapPanel, GpDiagnostic, MapRunsAtPoint,
    MismatchTest, ModelPosteriorReport, ModelPosteriorStageRow, ParameterSummary,
    PosteriorCheckReport, PosteriorResult, PropagatedOutput, RunStatistics, RunsAtPoint,
    SamplerStage, SensitivityIndex, SensitivityResult, StudyReport, TwoFidelityComponent,
    TwoFidelityPoint,
};
pub use report::{REPORT_FORMAT, ReportDocument, ReportFiles, write_report};
pub use tables::TableInfo;
