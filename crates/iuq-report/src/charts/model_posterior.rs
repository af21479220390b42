//! The model's own posterior: the histogram of its final importance log-weights, and the model
//! run at the MAPs of both posteriors beside the measurements (the published study's Fig. 8).

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::axis::{DataAxis, Padding, linear_tick_label};
use crate::charts::{LegendMark, draw_error_bars, header};
use crate::figure::{Chart, DrawResult};
use crate::input::{DataSeries, ModelPosteriorReport};
use crate::statistics::{extent, padded};
use crate::style::{
    AXIS_LABEL_SIZE, DATA_COLOUR, FONT, GRID_COLOUR, MODEL_COLOUR, SURROGATE_COLOUR, TICK_SIZE,
};

/// Bins of the log-weight histogram.
const BINS: usize = 30;

/// Room on each side of the data along x.
const X_PADDING: Padding = Padding {
    decades: 0.06,
    fraction: 0.05,
    half_spacings: 0.0,
};

/// Histogram of the final stage's log-weights.
pub(crate) struct LogWeightsChart<'a> {
    /// The model posterior.
    pub report: &'a ModelPosteriorReport,
}

impl Chart for LogWeightsChart<'_> {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        let r = self.report;
        // After a bridge the members descend from fewer ancestors.
        let ancestors = if r.ancestors > 0 && r.ancestors < r.samples {
            format!("; {} ancestors", r.ancestors)
        } else {
            String::new()
        };
        let entries = vec![(
            LegendMark::Filled(MODEL_COLOUR, 0.8),
            format!(
                "members ({} of {}; k̂ = {:.3}, threshold {:.3}; ESS {:.0}{ancestors})",
                r.log_weights.len(),
                r.samples,
                r.pareto_k,
                r.pareto_k_threshold,
                r.effective_sample_size
            ),
        )];
        let body = header(area, "Importance log-weights", &entries, 0)?;
        let (lo, hi) = extent(r.log_weights.iter().copied()).unwrap_or((-1.0, 0.0));
        let (lo, hi) = if hi > lo {
            (lo, hi)
        } else {
            (lo - 0.5, hi + 0.5)
        };
        let width = (hi - lo) / BINS as f64;
        let mut counts = [0usize; BINS];
        for w in &r.log_weights {
            let b = (((w - lo) / width) as usize).min(BINS - 1);
            counts[b] += 1;
        }
        let top = counts.iter().copied().max().unwrap_or(1).max(1) as f64 * 1.1;
        let (x_lo, x_hi) = padded(lo, hi, 0.04);
        let mut chart = ChartBuilder::on(&body)
            .margin_left(10)
            .margin_right(24)
            .margin_bottom(8)
            .x_label_area_size(58)
            .y_label_area_size(70)
            .build_cartesian_2d(x_lo..x_hi, 0.0..top)?;
        chart
            .configure_mesh()
            .x_desc(
                if r.both_batches || r.proposal_mismatch.as_ref().is_some_and(|t| t.corrected) {
                    "log-weight in the two batches' mixture"
                } else {
                    "Δβ·(ℓ model − ℓ surrogate)"
                },
            )
            .y_desc("members")
            .x_label_formatter(&|v| linear_tick_label(*v, x_lo, x_hi))
            .y_label_formatter(&|v| linear_tick_label(*v, 0.0, top))
            .label_style((FONT, TICK_SIZE))
            .axis_desc_style((FONT, AXIS_LABEL_SIZE))
            .bold_line_style(GRID_COLOUR)
            .light_line_style(TRANSPARENT)
            .draw()?;
        chart.draw_series(counts.iter().enumerate().map(|(b, &c)| {
            let left = lo + b as f64 * width;
            Rectangle::new(
                [(left, 0.0), (left + width, c as f64)],
                MODEL_COLOUR.mix(0.8).filled(),
            )
        }))?;
        Ok(())
    }
}

/// The model run at both MAPs, beside the measurements.
pub(crate) struct MapRunsChart<'a> {
    /// The model posterior.
    pub report: &'a ModelPosteriorReport,
    /// The measurements (for the axis labels).
    pub data: &'a DataSeries,
}

impl Chart for MapRunsChart<'_> {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        let r = self.report;
        let entries = vec![
            (
                LegendMark::DataPoint(DATA_COLOUR),
                "measurements (± std)".to_string(),
            ),
            (
                LegendMark::Cross(SURROGATE_COLOUR),
                format!(
                    "{} at the {} posterior's MAP",
                    r.model_source, r.surrogate_source
                ),
            ),
            (
                LegendMark::Dot(MODEL_COLOUR),
                format!("{} at its own posterior's MAP", r.model_source),
            ),
        ];
        let body = header(area, "The model at both MAPs", &entries, 0)?;
        let xs: Vec<f64> = r.map_runs.iter().map(|p| p.x).collect();
        let axis = DataAxis::new(&xs, X_PADDING);
        let values = r.map_runs.iter().flat_map(|p| {
            [p.datum.0 - p.datum.1, p.datum.0 + p.datum.1]
                .into_iter()
                .chain(p.at_surrogate_map)
                .chain(p.at_model_map)
        });
        let (y_lo, y_hi) = extent(values).unwrap_or((0.0, 1.0));
        let (y_lo, y_hi) = padded(y_lo, y_hi, 0.06);
        let mut chart = ChartBuilder::on(&body)
            .margin_left(10)
            .margin_right(24)
            .margin_bottom(8)
            .x_label_area_size(58)
            .y_label_area_size(82)
            .build_cartesian_2d(axis.clone(), y_lo..y_hi)?;
        chart
            .configure_mesh()
            .x_desc(self.data.x_label.as_str())
            .y_desc(self.data.y_label.as_str())
            .x_label_formatter(&|v| axis.label(*v))
            .y_label_formatter(&|v| linear_tick_label(*v, y_lo, y_hi))
            .label_style((FONT, TICK_SIZE))
            .axis_desc_style((FONT, AXIS_LABEL_SIZE))
            .bold_line_style(GRID_COLOUR)
            .light_line_style(TRANSPARENT)
            .draw()?;
        let bars: Vec<(f64, f64, f64)> = r
            .map_runs
            .iter()
            .map(|p| (axis.map(p.x), p.datum.0 - p.datum.1, p.datum.0 + p.datum.1))
            .collect();
        draw_error_bars(&mut chart, &bars, DATA_COLOUR.stroke_width(1), 4)?;
        chart.draw_series(
            r.map_runs
                .iter()
                .map(|p| Circle::new((axis.map(p.x), p.datum.0), 4, DATA_COLOUR.filled())),
        )?;
        chart.draw_series(r.map_runs.iter().filter_map(|p| {
            p.at_surrogate_map
                .map(|y| Cross::new((axis.map(p.x), y), 7, SURROGATE_COLOUR.stroke_width(2)))
        }))?;
        chart.draw_series(r.map_runs.iter().filter_map(|p| {
            p.at_model_map
                .map(|y| Circle::new((axis.map(p.x), y), 5, MODEL_COLOUR.filled()))
        }))?;
        Ok(())
    }
}
