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
//! - [`model`]: the input structures;
//! - [`write_report`]: validation and output;
//! - the charts (one module per kind) are private; colours are fixed per source (GP surrogate
//!   blue, cell model and model runs orange, measurements black).

#![warn(missing_docs)]

mod axis;
mod charts;
mod derived;
pub mod error;
mod figure;
mod files;
mod format;
mod html;
pub mod model;
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
pub use model::{
    CellPortrait, CellPortraits, CheckedPoint, ComparedParameter, ComparedTraces, Convergence,
    ConvergenceRound, DataSeries, ElongationTrace, FailureMapPanel, GpDiagnostic, MapRunsAtPoint,
    MismatchTest, ModelPosteriorReport, ModelPosteriorStageRow, ParameterSummary,
    PosteriorCheckReport, PosteriorResult, PropagatedOutput, RunStatistics, RunsAtPoint,
    SamplerStage, SensitivityIndex, SensitivityResult, StudyReport, TwoFidelityPoint,
};
pub use report::{REPORT_FORMAT, ReportDocument, ReportFiles, write_report};
pub use tables::TableInfo;
