//! Figure 7: the Gaussian processes' predictions against the simulated outputs of the
//! independent test set, one panel per output, with ±2 std whiskers, the identity line and Q²
//! in the panel title.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::axis::linear_tick_label;
use crate::charts::{LegendMark, draw_error_bars, header, panel_grid};
use crate::figure::{Chart, DrawResult};
use crate::format::format_number;
use crate::input::GpDiagnostic;
use crate::statistics::{extent, padded};
use crate::style::{FONT, GRID_COLOUR, SURROGATE_COLOUR, TICK_SIZE};

/// Height of the title and legend strip.
const HEADER: u32 = 74;
/// Side of one (square) panel.
const PANEL: u32 = 270;

/// The GP-diagnostics chart.
pub(crate) struct GpDiagnosticsChart<'a> {
    /// One panel per output.
    pub diagnostics: &'a [GpDiagnostic],
}

impl GpDiagnosticsChart<'_> {
    /// Panels per row.
    fn columns(&self) -> usize {
        self.diagnostics.len().clamp(1, 4)
    }

    /// Pixel size (width, height) of the figure.
    pub(crate) fn size(&self) -> (u32, u32) {
        let columns = self.columns();
        let rows = self.diagnostics.len().div_ceil(columns).max(1) as u32;
        (PANEL * columns as u32, HEADER + PANEL * rows)
    }

    fn draw_panel<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        diagnostic: &GpDiagnostic,
    ) -> DrawResult<DB> {
        let n = diagnostic.simulated.len();
        let values = (0..n).flat_map(|i| {
            let (p, s) = (diagnostic.predicted[i], diagnostic.predicted_std[i]);
            [diagnostic.simulated[i], p - 2.0 * s, p + 2.0 * s]
        });
        let (lo, hi) = extent(values).unwrap_or((0.0, 1.0));
        let (lo, hi) = padded(lo, hi, 0.05);
        let title = format!(
            "{}: Q² = {}",
            diagnostic.output_label,
            format_number(diagnostic.q2)
        );
        let mut chart = ChartBuilder::on(area)
            .caption(title, (FONT, TICK_SIZE + 2))
            .margin(8)
            .x_label_area_size(46)
            .y_label_area_size(66)
            .build_cartesian_2d(lo..hi, lo..hi)?;
        chart
            .configure_mesh()
            .x_labels(5)
            .y_labels(5)
            .x_desc("simulated")
            .y_desc("GP prediction")
            .x_label_formatter(&|v| linear_tick_label(*v, lo, hi))
            .y_label_formatter(&|v| linear_tick_label(*v, lo, hi))
            .label_style((FONT, TICK_SIZE - 1))
            .axis_desc_style((FONT, TICK_SIZE))
            .bold_line_style(GRID_COLOUR)
            .light_line_style(TRANSPARENT)
            .draw()?;
        chart.draw_series(std::iter::once(PathElement::new(
            vec![(lo, lo), (hi, hi)],
            BLACK.mix(0.7).stroke_width(1),
        )))?;
        let whiskers: Vec<(f64, f64, f64)> = (0..n)
            .map(|i| {
                let (p, s) = (diagnostic.predicted[i], diagnostic.predicted_std[i]);
                (diagnostic.simulated[i], p - 2.0 * s, p + 2.0 * s)
            })
            .collect();
        draw_error_bars(
            &mut chart,
            &whiskers,
            SURROGATE_COLOUR.mix(0.55).stroke_width(1),
            0,
        )?;
        chart.draw_series((0..n).map(|i| {
            Circle::new(
                (diagnostic.simulated[i], diagnostic.predicted[i]),
                3,
                SURROGATE_COLOUR.filled(),
            )
        }))?;
        Ok(())
    }
}

impl Chart for GpDiagnosticsChart<'_> {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        let entries = [
            (
                LegendMark::DataPoint(SURROGATE_COLOUR),
                "GP mean ± 2 std".to_string(),
            ),
            (
                LegendMark::Line(BLACK, 1),
                "identity (perfect prediction)".to_string(),
            ),
        ];
        let body = header(area, "Surrogate quality on the test set", &entries, HEADER)?;
        let columns = self.columns();
        for (diagnostic, region) in
            self.diagnostics
                .iter()
                .zip(panel_grid(&body, self.diagnostics.len(), columns))
        {
            self.draw_panel(&region, diagnostic)?;
        }
        Ok(())
    }
}
