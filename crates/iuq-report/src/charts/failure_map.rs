//! Where the model fails: one panel per run group in the plane of two parameters, the runs as
//! markers (hollow: initial and test designs, filled: adaptive, crosses: failed) over the
//! failure classifier's probability of failure, shaded red.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::axis::linear_tick_label;
use crate::charts::{LegendMark, header, panel_grid};
use crate::figure::{Chart, DrawResult};
use crate::input::FailureMapPanel;
use crate::statistics::{extent, padded};
use crate::style::{AXIS_LABEL_SIZE, DATA_COLOUR, FONT, SURROGATE_COLOUR, TICK_SIZE};

/// Panels drawn at most; further panels are left out.
pub(crate) const MAX_PANELS: usize = 8;
/// Height of the title and a one-line legend strip (figures of three or more columns).
const HEADER: u32 = 74;
/// Height of the title and a two-line legend strip (narrower figures).
const TALL_HEADER: u32 = 100;
/// Side of one (square) panel.
const PANEL: u32 = 300;
/// Colour of the failure probability ("tab:red").
const FAILURE_COLOUR: RGBColor = RGBColor(214, 39, 40);
/// Opacity of the shading at probability 1 (it grows linearly from 0).
const FAILURE_OPACITY: f64 = 0.6;
/// Steps of the shading: probabilities are rounded to multiples of 1 / LEVELS, so neighbouring
/// cells of equal shade merge into one rectangle (a far smaller SVG).
const LEVELS: f64 = 20.0;
/// Colour of the frame around each panel's plotting area.
const FRAME_COLOUR: RGBColor = RGBColor(160, 160, 160);
/// Radius of a run's marker in pixels.
const MARKER: i32 = 4;

/// The failure-map chart.
pub(crate) struct FailureMapChart<'a> {
    /// The panels (only the first [`MAX_PANELS`] are drawn).
    pub panels: &'a [FailureMapPanel],
}

impl FailureMapChart<'_> {
    /// Panels drawn.
    fn shown(&self) -> &[FailureMapPanel] {
        &self.panels[..self.panels.len().min(MAX_PANELS)]
    }

    /// Panels per row.
    fn columns(&self) -> usize {
        match self.shown().len() {
            0..=4 => self.shown().len().max(1),
            5 | 6 => 3,
            _ => 4,
        }
    }

    /// Height of the title and legend strip: the legend takes two lines below three columns.
    fn header_height(&self) -> u32 {
        if self.columns() >= 3 {
            HEADER
        } else {
            TALL_HEADER
        }
    }

    /// Pixel size (width, height) of the figure; a single panel is widened to two panels'
    /// width, room for the legend.
    pub(crate) fn size(&self) -> (u32, u32) {
        let columns = self.columns();
        let rows = self.shown().len().div_ceil(columns).max(1) as u32;
        (
            PANEL * columns.max(2) as u32,
            self.header_height() + PANEL * rows,
        )
    }

    fn draw_panel<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        panel: &FailureMapPanel,
    ) -> DrawResult<DB> {
        let (x_low, x_high, y_low, y_high) = panel.bounds;
        // The axes show the bounds, widened only when a run lies outside them.
        let axis = |low: f64, high: f64, values: &mut dyn Iterator<Item = f64>| match extent(values)
        {
            Some((lo, hi)) if lo < low || hi > high => padded(lo.min(low), hi.max(high), 0.03),
            _ => (low, high),
        };
        let (x_lo, x_hi) = axis(x_low, x_high, &mut panel.points.iter().map(|p| p.0));
        let (y_lo, y_hi) = axis(y_low, y_high, &mut panel.points.iter().map(|p| p.1));
        let mut chart = ChartBuilder::on(area)
            .caption(panel.label.as_str(), (FONT, TICK_SIZE + 2))
            .margin(8)
            .margin_right(14)
            .x_label_area_size(52)
            .y_label_area_size(64)
            .build_cartesian_2d(x_lo..x_hi, y_lo..y_hi)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_labels(5)
            .y_labels(5)
            .x_desc(panel.x_parameter.as_str())
            .y_desc(panel.y_parameter.as_str())
            .x_label_formatter(&|v| linear_tick_label(*v, x_lo, x_hi))
            .y_label_formatter(&|v| linear_tick_label(*v, y_lo, y_hi))
            .label_style((FONT, TICK_SIZE - 1))
            .axis_desc_style((FONT, AXIS_LABEL_SIZE - 2))
            .draw()?;

        let (columns, rows) = panel.grid_size;
        if !panel.failure_probability.is_empty() && columns > 0 && rows > 0 {
            let width = (x_high - x_low) / columns as f64;
            let height = (y_high - y_low) / rows as f64;
            let mut cells = Vec::new();
            for row in 0..rows {
                let level = |column: usize| {
                    (panel.failure_probability[row * columns + column] * LEVELS).round()
                };
                let mut start = 0;
                while start < columns {
                    let shade = level(start);
                    let mut end = start + 1;
                    while end < columns && level(end) == shade {
                        end += 1;
                    }
                    if shade > 0.0 {
                        cells.push(Rectangle::new(
                            [
                                (x_low + start as f64 * width, y_low + row as f64 * height),
                                (
                                    x_low + end as f64 * width,
                                    y_low + (row + 1) as f64 * height,
                                ),
                            ],
                            FAILURE_COLOUR
                                .mix(FAILURE_OPACITY * shade / LEVELS)
                                .filled(),
                        ));
                    }
                    start = end;
                }
            }
            chart.draw_series(cells)?;
        }
        chart.plotting_area().draw(&Rectangle::new(
            [(x_lo, y_hi), (x_hi, y_lo)],
            FRAME_COLOUR.stroke_width(1),
        ))?;

        let runs = || {
            panel
                .points
                .iter()
                .zip(panel.failed.iter().zip(&panel.adaptive))
        };
        chart.draw_series(
            runs()
                .filter(|(_, (failed, adaptive))| !**failed && !**adaptive)
                .map(|(&p, _)| Circle::new(p, MARKER, DATA_COLOUR.stroke_width(1))),
        )?;
        chart.draw_series(
            runs()
                .filter(|(_, (failed, adaptive))| !**failed && **adaptive)
                .map(|(&p, _)| Circle::new(p, MARKER, SURROGATE_COLOUR.filled())),
        )?;
        chart.draw_series(
            runs()
                .filter(|(_, (failed, _))| **failed)
                .map(|(&p, _)| Cross::new(p, MARKER, DATA_COLOUR.stroke_width(2))),
        )?;
        Ok(())
    }
}

impl Chart for FailureMapChart<'_> {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        let mut entries = vec![
            (
                LegendMark::Ring(DATA_COLOUR),
                "initial and test runs".to_string(),
            ),
            (
                LegendMark::Dot(SURROGATE_COLOUR),
                "adaptive runs".to_string(),
            ),
            (LegendMark::Cross(DATA_COLOUR), "failed runs".to_string()),
        ];
        if self
            .shown()
            .iter()
            .any(|p| !p.failure_probability.is_empty())
        {
            entries.push((
                LegendMark::Ramp(FAILURE_COLOUR, FAILURE_OPACITY),
                "probability of failure 0 → 1".to_string(),
            ));
        }
        let body = header(
            area,
            "Where the model fails",
            &entries,
            self.header_height(),
        )?;
        for (panel, region) in
            self.shown()
                .iter()
                .zip(panel_grid(&body, self.shown().len(), self.columns()))
        {
            self.draw_panel(&region, panel)?;
        }
        Ok(())
    }
}
