//! Figure 6: the absolute error of each source's MAP curve against the measurements at every
//! stress, as grouped bars, with the measurement std marked for scale.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::axis::{CategoryAxis, category_label, linear_tick_label};
use crate::charts::{LegendMark, header};
use crate::derived::DerivedResults;
use crate::figure::{Chart, DrawResult};
use crate::format::format_tick;
use crate::input::DataSeries;
use crate::statistics::extent;
use crate::style::{AXIS_LABEL_SIZE, DATA_COLOUR, FONT, GRID_COLOUR, TICK_SIZE, source_colour};

/// Share of a category's width taken by its bars.
const GROUP_WIDTH: f64 = 0.7;

/// The MAP-error chart.
pub(crate) struct MapErrorChart<'a> {
    /// The measurements.
    pub data: &'a DataSeries,
    /// The MAP errors per source.
    pub derived: &'a DerivedResults,
}

impl Chart for MapErrorChart<'_> {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        let data = self.data;
        let n = data.x.len();
        // Categories in increasing stress.
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&a, &b| data.x[a].total_cmp(&data.x[b]));
        let labels: Vec<String> = order.iter().map(|&i| format_tick(data.x[i])).collect();

        let mut entries: Vec<(LegendMark, String)> = self
            .derived
            .predictions
            .iter()
            .enumerate()
            .map(|(s, p)| {
                (
                    LegendMark::Filled(source_colour(&p.source, s), 1.0),
                    p.source.clone(),
                )
            })
            .collect();
        entries.push((
            LegendMark::Line(DATA_COLOUR, 2),
            "measurement std".to_string(),
        ));
        let body = header(area, "Absolute error of the MAP prediction", &entries, 0)?;

        let values = self
            .derived
            .predictions
            .iter()
            .flat_map(|p| p.points.iter().map(|q| q.absolute_error))
            .chain(data.y_err.iter().copied());
        let (_, hi) = extent(values).unwrap_or((0.0, 1.0));
        let y_hi = if hi > 0.0 { hi * 1.12 } else { 1.0 };
        let mut chart = ChartBuilder::on(&body)
            .margin_left(10)
            .margin_right(24)
            .margin_bottom(8)
            .x_label_area_size(58)
            .y_label_area_size(88)
            .build_cartesian_2d(CategoryAxis { count: n }, 0.0..y_hi)?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_desc(data.x_label.as_str())
            .y_desc(format!("|MAP − data|, {}", data.y_label))
            .x_label_formatter(&|v| category_label(&labels, *v))
            .y_label_formatter(&|v| linear_tick_label(*v, 0.0, y_hi))
            .label_style((FONT, TICK_SIZE))
            .axis_desc_style((FONT, AXIS_LABEL_SIZE))
            .bold_line_style(GRID_COLOUR)
            .light_line_style(TRANSPARENT)
            .draw()?;
        let sources = self.derived.predictions.len().max(1);
        let width = GROUP_WIDTH / sources as f64;
        for (s, prediction) in self.derived.predictions.iter().enumerate() {
            let colour = source_colour(&prediction.source, s);
            chart.draw_series(order.iter().enumerate().filter_map(|(k, &i)| {
                let point = prediction.points.get(i)?;
                let left = k as f64 - GROUP_WIDTH / 2.0 + s as f64 * width;
                Some(Rectangle::new(
                    [
                        (left + 0.06 * width, 0.0),
                        (left + 0.94 * width, point.absolute_error),
                    ],
                    colour.filled(),
                ))
            }))?;
        }
        chart.draw_series(order.iter().enumerate().map(|(k, &i)| {
            let half = GROUP_WIDTH / 2.0 + 0.04;
            PathElement::new(
                vec![
                    (k as f64 - half, data.y_err[i]),
                    (k as f64 + half, data.y_err[i]),
                ],
                DATA_COLOUR.stroke_width(2),
            )
        }))?;
        Ok(())
    }
}
