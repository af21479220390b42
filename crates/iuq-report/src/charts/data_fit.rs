//! Figure 1: the measurements with their error bars, and for each posterior source the MAP
//! curve and the central 95 % band of the propagated output.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::axis::{DataAxis, Padding, linear_tick_label};
use crate::charts::{LegendMark, draw_error_bars, header};
use crate::derived::DerivedResults;
use crate::figure::{Chart, DrawResult};
use crate::input::DataSeries;
use crate::statistics::{extent, padded};
use crate::style::{AXIS_LABEL_SIZE, DATA_COLOUR, FONT, GRID_COLOUR, TICK_SIZE, source_colour};

/// Opacity of a prediction band.
const BAND_OPACITY: f64 = 0.22;

/// Room on each side of the data along x.
const X_PADDING: Padding = Padding {
    decades: 0.06,
    fraction: 0.05,
    half_spacings: 0.0,
};

/// The data-versus-model chart.
pub(crate) struct DataFitChart<'a> {
    /// The measurements.
    pub data: &'a DataSeries,
    /// Bands and MAP predictions per source.
    pub derived: &'a DerivedResults,
    /// The model itself run at the MAP: (x, output, computational std), drawn as open diamonds
    /// with whiskers (empty: not run).
    pub map_runs: Vec<(f64, f64, f64)>,
}

/// Colour of the model's runs at the MAP.
const MAP_RUN_COLOUR: RGBColor = RGBColor(200, 60, 40);

impl Chart for DataFitChart<'_> {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        let data = self.data;
        let mut entries = vec![(
            LegendMark::DataPoint(DATA_COLOUR),
            "measurements (± std)".to_string(),
        )];
        for (s, prediction) in self.derived.predictions.iter().enumerate() {
            let colour = source_colour(&prediction.source, s);
            entries.push((
                LegendMark::LineOnBand(colour, BAND_OPACITY * 1.5),
                format!("{}: MAP and 95 % band", prediction.source),
            ));
        }
        if !self.map_runs.is_empty() {
            entries.push((
                LegendMark::Cross(MAP_RUN_COLOUR),
                "model run at the MAP (± computational std)".to_string(),
            ));
        }
        let plot_area = header(area, "Measurements and calibrated model", &entries, 0)?;

        let axis = DataAxis::new(&data.x, X_PADDING);
        let values = (0..data.x.len())
            .flat_map(|i| [data.y[i] - data.y_err[i], data.y[i] + data.y_err[i]])
            .chain(self.derived.predictions.iter().flat_map(|p| {
                p.points
                    .iter()
                    .flat_map(|q| [q.q025, q.q975, q.map_prediction])
            }))
            .chain(self.map_runs.iter().flat_map(|r| [r.1 - r.2, r.1 + r.2]));
        let (y_lo, y_hi) = extent(values).unwrap_or((0.0, 1.0));
        let (y_lo, y_hi) = padded(y_lo, y_hi, 0.06);
        let mut chart = ChartBuilder::on(&plot_area)
            .margin_left(10)
            .margin_right(24)
            .margin_bottom(8)
            .x_label_area_size(58)
            .y_label_area_size(82)
            .build_cartesian_2d(axis.clone(), y_lo..y_hi)?;
        chart
            .configure_mesh()
            .x_desc(data.x_label.as_str())
            .y_desc(data.y_label.as_str())
            .x_label_formatter(&|v| axis.label(*v))
            .y_label_formatter(&|v| linear_tick_label(*v, y_lo, y_hi))
            .label_style((FONT, TICK_SIZE))
            .axis_desc_style((FONT, AXIS_LABEL_SIZE))
            .bold_line_style(GRID_COLOUR)
            .light_line_style(TRANSPARENT)
            .draw()?;

        // All bands first, so that no band hides another source's MAP curve.
        for (s, prediction) in self.derived.predictions.iter().enumerate() {
            let colour = source_colour(&prediction.source, s);
            let mut sorted: Vec<_> = prediction.points.iter().collect();
            sorted.sort_by(|a, b| a.x.total_cmp(&b.x));
            let band: Vec<(f64, f64)> = sorted
                .iter()
                .map(|p| (axis.map(p.x), p.q975))
                .chain(sorted.iter().rev().map(|p| (axis.map(p.x), p.q025)))
                .collect();
            chart.draw_series(std::iter::once(Polygon::new(
                band,
                colour.mix(BAND_OPACITY).filled(),
            )))?;
        }
        for (s, prediction) in self.derived.predictions.iter().enumerate() {
            let colour = source_colour(&prediction.source, s);
            let mut sorted: Vec<_> = prediction.points.iter().collect();
            sorted.sort_by(|a, b| a.x.total_cmp(&b.x));
            chart.draw_series(LineSeries::new(
                sorted.iter().map(|p| (axis.map(p.x), p.map_prediction)),
                colour.stroke_width(2),
            ))?;
        }
        let bars: Vec<(f64, f64, f64)> = (0..data.x.len())
            .map(|i| {
                (
                    axis.map(data.x[i]),
                    data.y[i] - data.y_err[i],
                    data.y[i] + data.y_err[i],
                )
            })
            .collect();
        draw_error_bars(&mut chart, &bars, DATA_COLOUR.stroke_width(1), 4)?;
        chart.draw_series(
            (0..data.x.len())
                .map(|i| Circle::new((axis.map(data.x[i]), data.y[i]), 4, DATA_COLOUR.filled())),
        )?;
        let run_bars: Vec<(f64, f64, f64)> = self
            .map_runs
            .iter()
            .map(|&(x, y, s)| (axis.map(x), y - s, y + s))
            .collect();
        draw_error_bars(&mut chart, &run_bars, MAP_RUN_COLOUR.stroke_width(2), 5)?;
        chart.draw_series(
            self.map_runs
                .iter()
                .map(|&(x, y, _)| Cross::new((axis.map(x), y), 6, MAP_RUN_COLOUR.stroke_width(2))),
        )?;
        Ok(())
    }
}
