//! Figure 3: Sobol' indices as grouped bars, one panel per output (stress): for every parameter
//! S1 (solid) and ST (light) of each source side by side, with confidence-interval whiskers,
//! on a range cut at [`DISPLAY_RANGE`].

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::axis::{CategoryAxis, category_label};
use crate::charts::{LegendMark, draw_error_bars, header, panel_grid};
use crate::figure::{Chart, DrawResult};
use crate::format::format_tick;
use crate::input::{SensitivityResult, StudyReport};
use crate::statistics::extent;
use crate::style::{AXIS_LABEL_SIZE, FONT, GRID_COLOUR, TICK_SIZE, source_colour};

/// Height of the title and legend strip.
const HEADER: u32 = 74;
/// Size of one panel.
const PANEL: (u32, u32) = (360, 310);
/// Share of a category's width taken by its bars.
const GROUP_WIDTH: f64 = 0.84;
/// Opacity of the ST bars' fill.
const TOTAL_OPACITY: f64 = 0.3;
/// The widest index range a panel shows. Indices lie in [0, 1]; estimates from a handful of
/// model runs can lie far outside with intervals wider still, and one such bar would flatten
/// every other. What lies beyond is cut at the edge and marked with an arrowhead; the table
/// gives the values.
pub(crate) const DISPLAY_RANGE: (f64, f64) = (-0.25, 1.25);
/// Size in pixels of the arrowhead that marks a cut bar or interval.
const CUT_MARK: i32 = 5;

/// Whether an estimate with the confidence interval `low..high` says anything: an interval
/// wider than the index's whole range [0, 1] does not, and its bar is not drawn (a question
/// mark stands in its place; the table gives the numbers).
pub(crate) fn informative(low: f64, high: f64) -> bool {
    low.is_finite() && high.is_finite() && high - low <= 1.0
}

/// The y range of a panel whose values span `lo..hi`: at least [0, 1] with a margin, at most
/// [`DISPLAY_RANGE`].
pub(crate) fn panel_range(lo: f64, hi: f64) -> (f64, f64) {
    (
        (lo.min(0.0) - 0.02).max(DISPLAY_RANGE.0),
        (hi.max(1.0) + 0.04).min(DISPLAY_RANGE.1),
    )
}

/// One panel: the results of all sources for one output.
struct Panel<'a> {
    title: String,
    results: Vec<&'a SensitivityResult>,
}

/// The sensitivity chart.
pub(crate) struct SensitivityChart<'a> {
    /// Parameter names in display order.
    parameters: Vec<String>,
    /// Source names in order of first appearance.
    sources: Vec<String>,
    panels: Vec<Panel<'a>>,
    columns: usize,
}

impl<'a> SensitivityChart<'a> {
    /// Groups the report's sensitivity results into one panel per output.
    pub(crate) fn new(report: &'a StudyReport) -> Self {
        let mut parameters: Vec<String> = Vec::new();
        let mut sources: Vec<String> = Vec::new();
        let mut panels: Vec<Panel<'a>> = Vec::new();
        // Parameters in the study's order first, then any others as they appear.
        for name in &report.parameters {
            if report
                .sensitivity
                .iter()
                .any(|r| r.indices.iter().any(|i| &i.parameter == name))
            {
                parameters.push(name.clone());
            }
        }
        for result in &report.sensitivity {
            for index in &result.indices {
                if !parameters.contains(&index.parameter) {
                    parameters.push(index.parameter.clone());
                }
            }
            if !sources.contains(&result.source) {
                sources.push(result.source.clone());
            }
            match panels.iter_mut().find(|p| {
                p.results
                    .first()
                    .is_some_and(|r| r.output_label == result.output_label)
            }) {
                Some(panel) => panel.results.push(result),
                None => panels.push(Panel {
                    title: result.output_label.clone(),
                    results: vec![result],
                }),
            }
        }
        panels.sort_by(|a, b| {
            let x = |p: &Panel| p.results.first().map_or(0.0, |r| r.x);
            x(a).total_cmp(&x(b))
        });
        let columns = panels.len().clamp(1, 3);
        Self {
            parameters,
            sources,
            panels,
            columns,
        }
    }

    /// Pixel size (width, height) of the figure.
    pub(crate) fn size(&self) -> (u32, u32) {
        let rows = self.panels.len().div_ceil(self.columns).max(1) as u32;
        (PANEL.0 * self.columns as u32, HEADER + PANEL.1 * rows)
    }

    fn draw_panel<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        panel: &Panel,
    ) -> DrawResult<DB> {
        let values = panel.results.iter().flat_map(|r| {
            r.indices.iter().flat_map(|i| {
                [
                    (i.first_order_low, i.first_order_high, i.first_order),
                    (i.total_low, i.total_high, i.total),
                ]
                .into_iter()
                .filter(|(low, high, _)| informative(*low, *high))
                .flat_map(|(low, high, value)| [low, high, value])
            })
        });
        let (lo, hi) = extent(values).unwrap_or((0.0, 1.0));
        let (y_lo, y_hi) = panel_range(lo, hi);
        let clip = |v: f64| v.clamp(y_lo, y_hi);
        let n = self.parameters.len();
        let mut chart = ChartBuilder::on(area)
            .caption(panel.title.as_str(), (FONT, AXIS_LABEL_SIZE))
            .margin(8)
            .x_label_area_size(40)
            .y_label_area_size(64)
            .build_cartesian_2d(CategoryAxis { count: n }, y_lo..y_hi)?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .y_desc("Sobol' index")
            .x_label_formatter(&|v| category_label(&self.parameters, *v))
            .y_label_formatter(&|v| format_tick(*v))
            .label_style((FONT, TICK_SIZE))
            .axis_desc_style((FONT, TICK_SIZE + 1))
            .bold_line_style(GRID_COLOUR)
            .light_line_style(TRANSPARENT)
            .draw()?;
        let bars_per_group = 2 * self.sources.len().max(1);
        let width = GROUP_WIDTH / bars_per_group as f64;
        let mut whiskers = Vec::new();
        let mut cut: Vec<(f64, f64, bool)> = Vec::new();
        let mut uninformative: Vec<f64> = Vec::new();
        for (p, parameter) in self.parameters.iter().enumerate() {
            for (s, source) in self.sources.iter().enumerate() {
                let colour = source_colour(source, s);
                let Some(index) = panel
                    .results
                    .iter()
                    .filter(|r| &r.source == source)
                    .flat_map(|r| r.indices.iter())
                    .find(|i| &i.parameter == parameter)
                else {
                    continue;
                };
                for (k, (value, low, high)) in [
                    (
                        index.first_order,
                        index.first_order_low,
                        index.first_order_high,
                    ),
                    (index.total, index.total_low, index.total_high),
                ]
                .into_iter()
                .enumerate()
                {
                    let slot = k * self.sources.len() + s;
                    let left = p as f64 - GROUP_WIDTH / 2.0 + slot as f64 * width;
                    if !informative(low, high) {
                        uninformative.push(left + width / 2.0);
                        continue;
                    }
                    let corners = [
                        (left + 0.08 * width, 0.0),
                        (left + 0.92 * width, clip(value)),
                    ];
                    if k == 0 {
                        chart.draw_series(std::iter::once(Rectangle::new(
                            corners,
                            colour.filled(),
                        )))?;
                    } else {
                        chart.draw_series(std::iter::once(Rectangle::new(
                            corners,
                            colour.mix(TOTAL_OPACITY).filled(),
                        )))?;
                        chart.draw_series(std::iter::once(Rectangle::new(
                            corners,
                            colour.stroke_width(1),
                        )))?;
                    }
                    let centre = left + width / 2.0;
                    whiskers.push((centre, clip(low), clip(high)));
                    cut.extend(
                        [low, high, value]
                            .into_iter()
                            .filter(|v| *v > y_hi)
                            .map(|_| (centre, y_hi, true)),
                    );
                    cut.extend(
                        [low, high, value]
                            .into_iter()
                            .filter(|v| *v < y_lo)
                            .map(|_| (centre, y_lo, false)),
                    );
                }
            }
        }
        chart.draw_series(std::iter::once(PathElement::new(
            vec![(-0.5, 0.0), (n as f64 - 0.5, 0.0)],
            BLACK.stroke_width(1),
        )))?;
        draw_error_bars(&mut chart, &whiskers, BLACK.stroke_width(1), 3)?;
        let mid = 0.5 * (y_lo.max(0.0) + y_hi.min(1.0));
        chart.draw_series(uninformative.iter().map(|&x| {
            Text::new(
                "?",
                (x, mid),
                (FONT, AXIS_LABEL_SIZE)
                    .into_font()
                    .color(&RGBColor(120, 120, 120)),
            )
        }))?;
        cut.dedup_by(|a, b| a.0 == b.0 && a.2 == b.2);
        chart.draw_series(cut.iter().map(|&(x, y, upward)| {
            let tip = if upward { -CUT_MARK } else { CUT_MARK };
            EmptyElement::at((x, y))
                + Polygon::new(
                    vec![(0, tip), (-CUT_MARK, 0), (CUT_MARK, 0)],
                    BLACK.filled(),
                )
        }))?;
        Ok(())
    }
}

impl Chart for SensitivityChart<'_> {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        let mut entries = Vec::new();
        for (s, source) in self.sources.iter().enumerate() {
            let colour = source_colour(source, s);
            entries.push((
                LegendMark::Filled(colour, 1.0),
                format!("S1 (first order), {source}"),
            ));
            entries.push((
                LegendMark::Outlined(colour, TOTAL_OPACITY),
                format!("ST (total), {source}"),
            ));
        }
        entries.push((
            LegendMark::Whisker(BLACK),
            "confidence interval".to_string(),
        ));
        let body = header(
            area,
            "Sobol' sensitivity indices per output",
            &entries,
            HEADER,
        )?;
        for (panel, region) in
            self.panels
                .iter()
                .zip(panel_grid(&body, self.panels.len(), self.columns))
        {
            self.draw_panel(&region, panel)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn panel_range_covers_the_unit_interval_and_cuts_wild_estimates() {
        assert_eq!(panel_range(0.1, 0.9), (-0.02, 1.04));
        let (lo, hi) = panel_range(-0.1, 1.1);
        assert!((lo + 0.12).abs() < 1e-12 && (hi - 1.14).abs() < 1e-12);
        assert_eq!(panel_range(-141.5, 148.4), DISPLAY_RANGE);
    }
}
