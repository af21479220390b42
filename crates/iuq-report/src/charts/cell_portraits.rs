//! The cell at a MAP at every stress: its final shape (shear plane with the fitted ellipse, and
//! side view), and its elongation index against strain through the run with the measuring
//! window shaded.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::axis::linear_tick_label;
use crate::charts::{LegendMark, header, panel_grid};
use crate::figure::{Chart, DrawResult};
use crate::format::format_tick;
use crate::input::CellPortraits;
use crate::statistics::extent;
use crate::style::{
    AXIS_LABEL_SIZE, DATA_COLOUR, FONT, GRID_COLOUR, MODEL_COLOUR, SURROGATE_COLOUR, TICK_SIZE,
};

/// Shapes per row.
const COLUMNS: usize = 4;

/// Points of the drawn ellipse.
const ELLIPSE_POINTS: usize = 120;

/// The shapes chart.
pub(crate) struct CellShapesChart<'a> {
    /// The portraits.
    pub portraits: &'a CellPortraits,
}

impl CellShapesChart<'_> {
    /// Pixel size: one row of panels per `COLUMNS` stresses.
    pub(crate) fn size(&self) -> (u32, u32) {
        let rows = self.portraits.portraits.len().div_ceil(COLUMNS).max(1) as u32;
        (920, 110 + rows * 250)
    }
}

impl Chart for CellShapesChart<'_> {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        let entries = vec![
            (
                LegendMark::Dot(MODEL_COLOUR),
                "outline in the shear plane (flow →, gradient ↑)".to_string(),
            ),
            (
                LegendMark::Line(DATA_COLOUR, 2),
                "fitted ellipse".to_string(),
            ),
            (
                LegendMark::Dot(SURROGATE_COLOUR),
                "side view (flow →, vorticity ↑), below".to_string(),
            ),
        ];
        let body = header(
            area,
            &format!("The cell at {}", self.portraits.source),
            &entries,
            0,
        )?;
        let portraits = &self.portraits.portraits;
        // One scale for every panel: the largest extent of any outline.
        let reach = portraits
            .iter()
            .flat_map(|p| p.outline.iter().chain(&p.side))
            .flat_map(|q| [q[0].abs(), q[1].abs()])
            .fold(1.0f64, f64::max)
            * 1.1;
        for (p, panel) in portraits
            .iter()
            .zip(panel_grid(&body, portraits.len(), COLUMNS))
        {
            let title = format!("{} Pa: EL {:.3}", format_tick(p.x), p.elongation_index.0);
            let mut chart = ChartBuilder::on(&panel)
                .caption(title, (FONT, TICK_SIZE + 1))
                .margin(6)
                .x_label_area_size(28)
                .y_label_area_size(40)
                .build_cartesian_2d(-reach..reach, -2.0 * reach..reach)?;
            chart
                .configure_mesh()
                .x_labels(5)
                .y_labels(5)
                .x_label_formatter(&|v| linear_tick_label(*v, -reach, reach))
                .y_label_formatter(&|v| linear_tick_label(*v, -2.0 * reach, reach))
                .label_style((FONT, TICK_SIZE - 3))
                .axis_desc_style((FONT, AXIS_LABEL_SIZE - 4))
                .bold_line_style(GRID_COLOUR)
                .light_line_style(TRANSPARENT)
                .draw()?;
            chart.draw_series(
                p.outline
                    .iter()
                    .map(|q| Circle::new((q[0], q[1]), 2, MODEL_COLOUR.filled())),
            )?;
            let [cx, cy, a, b, angle] = p.ellipse;
            let (sin, cos) = angle.sin_cos();
            chart.draw_series(std::iter::once(PathElement::new(
                (0..=ELLIPSE_POINTS)
                    .map(|i| {
                        let t = i as f64 / ELLIPSE_POINTS as f64 * std::f64::consts::TAU;
                        let (u, v) = (a * t.cos(), b * t.sin());
                        (cx + u * cos - v * sin, cy + u * sin + v * cos)
                    })
                    .collect::<Vec<_>>(),
                DATA_COLOUR.stroke_width(2),
            )))?;
            // The side view sits below the shear-plane view, one reach lower.
            chart.draw_series(
                p.side.iter().map(|q| {
                    Circle::new((q[0], q[1] - 1.25 * reach), 2, SURROGATE_COLOUR.filled())
                }),
            )?;
        }
        Ok(())
    }
}

/// The elongation index against strain chart.
pub(crate) struct ElongationTraceChart<'a> {
    /// The portraits.
    pub portraits: &'a CellPortraits,
}

/// A colour per stress, from light to dark.
fn stress_colour(i: usize, n: usize) -> RGBColor {
    let t = if n > 1 {
        i as f64 / (n - 1) as f64
    } else {
        1.0
    };
    let mix = |lo: f64, hi: f64| (lo + t * (hi - lo)).round() as u8;
    RGBColor(mix(253.0, 127.0), mix(174.0, 39.0), mix(97.0, 4.0))
}

impl Chart for ElongationTraceChart<'_> {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        let portraits = &self.portraits.portraits;
        let compared = self.portraits.compared.as_ref();
        let n = portraits.len();
        let mut entries: Vec<(LegendMark, String)> = portraits
            .iter()
            .enumerate()
            .map(|(i, p)| {
                (
                    LegendMark::Line(stress_colour(i, n), 2),
                    format!("{} Pa", format_tick(p.x)),
                )
            })
            .collect();
        if let Some(compared) = compared {
            entries.push((
                LegendMark::Line(RGBColor(90, 90, 90), 2),
                self.portraits.source.clone(),
            ));
            entries.push((
                LegendMark::Dashed(RGBColor(90, 90, 90), 2),
                compared.source.clone(),
            ));
        }
        entries.push((
            LegendMark::Filled(GRID_COLOUR, 1.0),
            "measuring window".to_string(),
        ));
        let title = match compared {
            Some(_) => "Elongation index against strain at both MAPs".to_string(),
            None => format!("Elongation index against strain, {}", self.portraits.source),
        };
        let body = header(area, &title, &entries, 0)?;
        let x_hi = portraits
            .iter()
            .map(|p| p.window.1)
            .chain(compared.into_iter().flat_map(|c| {
                c.traces
                    .iter()
                    .filter_map(|t| t.trace.last().map(|point| point.0))
            }))
            .fold(1.0f64, f64::max)
            * 1.02;
        let (lo, hi) = extent(
            portraits
                .iter()
                .map(|p| &p.trace)
                .chain(
                    compared
                        .into_iter()
                        .flat_map(|c| c.traces.iter().map(|t| &t.trace)),
                )
                .flat_map(|trace| trace.iter().map(|t| t.1)),
        )
        .unwrap_or((0.0, 1.0));
        let y_lo = lo.min(0.0);
        let y_hi = hi * 1.08 + 1e-3;
        let mut chart = ChartBuilder::on(&body)
            .margin_left(10)
            .margin_right(24)
            .margin_bottom(8)
            .x_label_area_size(58)
            .y_label_area_size(82)
            .build_cartesian_2d(0.0..x_hi, y_lo..y_hi)?;
        chart
            .configure_mesh()
            .x_desc("strain γ̇t")
            .y_desc("elongation index EL")
            .x_label_formatter(&|v| linear_tick_label(*v, 0.0, x_hi))
            .y_label_formatter(&|v| linear_tick_label(*v, y_lo, y_hi))
            .label_style((FONT, TICK_SIZE))
            .axis_desc_style((FONT, AXIS_LABEL_SIZE))
            .bold_line_style(GRID_COLOUR)
            .light_line_style(TRANSPARENT)
            .draw()?;
        // The windows of all stresses (the same strains in the scaled protocol).
        for p in portraits {
            chart.draw_series(std::iter::once(Rectangle::new(
                [(p.window.0, y_lo), (p.window.1, y_hi)],
                GRID_COLOUR.mix(0.5).filled(),
            )))?;
        }
        for (i, p) in portraits.iter().enumerate() {
            chart.draw_series(LineSeries::new(
                p.trace.iter().copied(),
                stress_colour(i, n).stroke_width(2),
            ))?;
        }
        if let Some(compared) = compared {
            for (i, t) in compared.traces.iter().enumerate() {
                chart.draw_series(DashedLineSeries::new(
                    t.trace.iter().copied(),
                    7,
                    5,
                    stress_colour(i, n).stroke_width(2),
                ))?;
            }
        }
        Ok(())
    }
}
