//! Figure 8: the BASIS sampler's per-stage diagnostics — annealing exponent, coefficient of
//! variation of the weights, acceptance rate and running log evidence — one line per source.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::axis::linear_tick_label;
use crate::charts::{LegendMark, header, panel_grid};
use crate::figure::{Chart, DrawResult};
use crate::format::format_tick;
use crate::input::{PosteriorResult, SamplerStage};
use crate::statistics::{extent, padded};
use crate::style::{FONT, GRID_COLOUR, TICK_SIZE, source_colour};

/// Height of the title and legend strip.
const HEADER: u32 = 74;
/// Pixel size of the figure.
pub(crate) const SIZE: (u32, u32) = (900, HEADER + 2 * 290);

/// A quantity plotted against the stage.
struct Quantity {
    title: &'static str,
    value: fn(&SamplerStage) -> f64,
    /// A fixed y range, or `None` for the data's extent.
    range: Option<(f64, f64)>,
}

/// The four quantities, in reading order.
const QUANTITIES: [Quantity; 4] = [
    Quantity {
        title: "annealing exponent",
        value: |s| s.annealing_exponent,
        range: Some((0.0, 1.05)),
    },
    Quantity {
        title: "CV of the plausibility weights",
        value: |s| s.cv,
        range: None,
    },
    Quantity {
        title: "acceptance rate",
        value: |s| s.acceptance,
        range: Some((0.0, 1.05)),
    },
    Quantity {
        title: "log evidence (running estimate)",
        value: |s| s.log_evidence,
        range: None,
    },
];

/// The sampler-stages chart.
pub(crate) struct SamplerStagesChart<'a> {
    /// The posteriors whose stages are drawn.
    pub posteriors: &'a [PosteriorResult],
}

impl SamplerStagesChart<'_> {
    fn draw_panel<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        quantity: &Quantity,
    ) -> DrawResult<DB> {
        let stages = self.posteriors.iter().flat_map(|p| p.stages.iter());
        let (first, last) = extent(stages.clone().map(|s| s.stage as f64)).unwrap_or((0.0, 1.0));
        let (x_lo, x_hi) = padded(first, last.max(first + 1.0), 0.04);
        let (y_lo, y_hi) = match quantity.range {
            Some(range) => range,
            None => {
                let (lo, hi) = extent(stages.map(|s| (quantity.value)(s))).unwrap_or((0.0, 1.0));
                padded(lo, hi, 0.08)
            }
        };
        let mut chart = ChartBuilder::on(area)
            .caption(quantity.title, (FONT, TICK_SIZE + 2))
            .margin(8)
            .x_label_area_size(46)
            .y_label_area_size(74)
            .build_cartesian_2d(x_lo..x_hi, y_lo..y_hi)?;
        chart
            .configure_mesh()
            .x_desc("stage")
            .x_labels(8)
            .y_labels(6)
            .x_label_formatter(&|v| {
                if v.fract() == 0.0 {
                    format_tick(*v)
                } else {
                    String::new()
                }
            })
            .y_label_formatter(&|v| linear_tick_label(*v, y_lo, y_hi))
            .label_style((FONT, TICK_SIZE))
            .axis_desc_style((FONT, TICK_SIZE))
            .bold_line_style(GRID_COLOUR)
            .light_line_style(TRANSPARENT)
            .draw()?;
        for (s, posterior) in self.posteriors.iter().enumerate() {
            let colour = source_colour(&posterior.source, s);
            let points: Vec<(f64, f64)> = posterior
                .stages
                .iter()
                .map(|stage| (stage.stage as f64, (quantity.value)(stage)))
                .collect();
            chart.draw_series(LineSeries::new(points.clone(), colour.stroke_width(2)))?;
            chart.draw_series(
                points
                    .into_iter()
                    .map(|p| Circle::new(p, 3, colour.filled())),
            )?;
        }
        Ok(())
    }
}

impl Chart for SamplerStagesChart<'_> {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        let entries: Vec<(LegendMark, String)> = self
            .posteriors
            .iter()
            .enumerate()
            // A posterior without sampler stages (the model's, reweighted from the surrogate's)
            // draws no line, so it gets no legend entry.
            .filter(|(_, p)| !p.stages.is_empty())
            .map(|(s, p)| {
                (
                    LegendMark::Line(source_colour(&p.source, s), 2),
                    p.source.clone(),
                )
            })
            .collect();
        let body = header(area, "Sampler diagnostics per stage", &entries, HEADER)?;
        for (quantity, region) in QUANTITIES
            .iter()
            .zip(panel_grid(&body, QUANTITIES.len(), 2))
        {
            self.draw_panel(&region, quantity)?;
        }
        Ok(())
    }
}
