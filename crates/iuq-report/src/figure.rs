//! One figure, drawn twice from the same code: as an SVG document (kept in memory, later inlined
//! into the HTML page) and as a PNG file of the same pixel size.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{ReportError, Result};
use crate::style::ensure_font;

/// Error type of drawing on a plotters area of back-end `DB`.
pub(crate) type DrawResult<DB> =
    std::result::Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

/// A chart that can draw itself on any plotters back-end.
pub(crate) trait Chart {
    /// Draws the chart filling `area` (already cleared to white).
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> DrawResult<DB>;
}

/// What the report says about one figure: its files, size and caption.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FigureInfo {
    /// File stem, e.g. `data_fit`.
    pub name: String,
    /// Short title shown above the figure.
    pub title: String,
    /// The caption: what the figure shows and how to read it.
    pub caption: String,
    /// Path of the SVG file relative to the report directory.
    pub svg: String,
    /// Path of the PNG file relative to the report directory.
    pub png: String,
    /// Width in pixels (of both files).
    pub width: u32,
    /// Height in pixels (of both files).
    pub height: u32,
    /// Tables holding the figure's numbers (file stems in `tables/`).
    pub tables: Vec<String>,
}

/// A figure rendered as SVG, ready for its PNG to be drawn next to it.
pub(crate) struct RenderedFigure {
    /// The figure's description.
    pub info: FigureInfo,
    /// The SVG document.
    pub svg: String,
}

/// Draws `chart` as an SVG document of `width` × `height` pixels.
pub(crate) fn render_svg(
    name: &str,
    width: u32,
    height: u32,
    chart: &impl Chart,
) -> Result<String> {
    ensure_font()?;
    let mut svg = String::new();
    {
        let area = SVGBackend::with_string(&mut svg, (width, height)).into_drawing_area();
        area.fill(&WHITE)
            .map_err(|e| ReportError::drawing(name, e))?;
        chart
            .draw(&area)
            .map_err(|e| ReportError::drawing(name, e))?;
        area.present().map_err(|e| ReportError::drawing(name, e))?;
    }
    Ok(svg)
}

/// Draws `chart` as a PNG file at `path`, atomically: the image is written to a temporary file
/// beside `path` and renamed.
pub(crate) fn render_png(
    name: &str,
    width: u32,
    height: u32,
    chart: &impl Chart,
    path: &Path,
) -> Result<()> {
    ensure_font()?;
    // The bitmap back-end picks the encoder from the extension, so the temporary name keeps it.
    let temporary = iuq_atomic_file::temporary_path(path, Some("png"));
    let drawn = draw_png(name, width, height, chart, &temporary);
    if let Err(error) = drawn {
        let _ = std::fs::remove_file(&temporary);
        return Err(error);
    }
    iuq_atomic_file::replace(&temporary, path).map_err(|source| ReportError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Draws `chart` into the PNG file `path` (not atomically: [`render_png`] gives a temporary path).
fn draw_png(name: &str, width: u32, height: u32, chart: &impl Chart, path: &Path) -> Result<()> {
    let area = BitMapBackend::new(path, (width, height)).into_drawing_area();
    area.fill(&WHITE)
        .map_err(|e| ReportError::drawing(name, e))?;
    chart
        .draw(&area)
        .map_err(|e| ReportError::drawing(name, e))?;
    area.present().map_err(|e| ReportError::drawing(name, e))
}
