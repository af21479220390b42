//! The posterior check: at every data point, the model's output minus the surrogate's mean at
//! the MAP and at the posterior samples that were run, beside twice the surrogate's median
//! predictive std (a band) and twice each run's own predictive std (a line at the run): within
//! it, the surrogate claims, the run lies.

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::axis::{CategoryAxis, category_label, linear_tick_label};
use crate::charts::{LegendMark, header};
use crate::figure::{Chart, DrawResult};
use crate::format::format_tick;
use crate::input::{CheckedPoint, PosteriorCheckReport};
use crate::statistics::{extent, padded, quantile_sorted};
use crate::style::{AXIS_LABEL_SIZE, DATA_COLOUR, FONT, GRID_COLOUR, TICK_SIZE};

/// Pixel size of the chart.
pub(crate) const SIZE: (u32, u32) = (920, 520);

/// Colour of the posterior samples' residuals.
const SAMPLE_COLOUR: RGBColor = RGBColor(70, 110, 180);
/// Colour of the MAP's residual.
const MAP_COLOUR: RGBColor = RGBColor(200, 60, 40);
/// Half width of a category's band and scatter.
const HALF_WIDTH: f64 = 0.3;

/// The posterior-check chart.
pub(crate) struct PosteriorCheckChart<'a> {
    /// The check.
    pub check: &'a PosteriorCheckReport,
    /// Label of the data's control variable.
    pub x_label: &'a str,
}

/// Colour of each run's own ± 2σ line.
const RUN_BAND_COLOUR: RGBColor = RGBColor(150, 150, 150);

/// Twice each sample run's predictive std, √(surrogate std² + run std²): the half width within
/// which the surrogate claims that run lies.
fn run_half_widths(p: &CheckedPoint) -> Vec<f64> {
    p.surrogate_std
        .iter()
        .zip(p.model_std.iter().chain(std::iter::repeat(&0.0)))
        .map(|(s, m)| 2.0 * (s * s + m * m).sqrt())
        .collect()
}

/// The median of the finite `values` (NaN when there are none).
fn median(values: &[f64]) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    quantile_sorted(&v, 0.5)
}

impl Chart for PosteriorCheckChart<'_> {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        let points = &self.check.points;
        let mut order: Vec<usize> = (0..points.len()).collect();
        order.sort_by(|&a, &b| points[a].x.total_cmp(&points[b].x));
        let labels: Vec<String> = order.iter().map(|&i| format_tick(points[i].x)).collect();
        let entries = vec![
            (
                LegendMark::Dot(SAMPLE_COLOUR),
                "posterior samples".to_string(),
            ),
            (LegendMark::Dot(MAP_COLOUR), "MAP".to_string()),
            (
                LegendMark::Filled(RGBColor(200, 200, 200), 1.0),
                "± 2 × surrogate std (median)".to_string(),
            ),
            (
                LegendMark::Whisker(RUN_BAND_COLOUR),
                "± 2 × the run's predictive std".to_string(),
            ),
        ];
        let body = header(area, "Model − surrogate at the posterior", &entries, 0)?;
        let bands: Vec<f64> = order
            .iter()
            .map(|&i| 2.0 * median(&points[i].surrogate_std))
            .collect();
        let values = order.iter().enumerate().flat_map(|(c, &i)| {
            let p = &points[i];
            p.model
                .iter()
                .zip(&p.surrogate)
                .map(|(m, s)| m - s)
                .chain(run_half_widths(p).into_iter().flat_map(|w| [w, -w]))
                .chain(p.map_model.map(|(m, _)| m - p.map_surrogate.0))
                .chain([bands[c], -bands[c], 0.0])
                .collect::<Vec<_>>()
        });
        let (lo, hi) = extent(values.filter(|v| v.is_finite())).unwrap_or((-1.0, 1.0));
        let (lo, hi) = padded(lo, hi, 0.08);
        let n = order.len();
        let mut chart = ChartBuilder::on(&body)
            .margin_left(10)
            .margin_right(24)
            .margin_bottom(8)
            .x_label_area_size(58)
            .y_label_area_size(82)
            .build_cartesian_2d(CategoryAxis { count: n }, lo..hi)?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_desc(self.x_label)
            .y_desc("model − surrogate mean")
            .x_label_formatter(&|v| category_label(&labels, *v))
            .y_label_formatter(&|v| linear_tick_label(*v, lo, hi))
            .label_style((FONT, TICK_SIZE))
            .axis_desc_style((FONT, AXIS_LABEL_SIZE))
            .bold_line_style(GRID_COLOUR)
            .light_line_style(TRANSPARENT)
            .draw()?;
        for (c, band) in bands.iter().enumerate() {
            if band.is_finite() {
                let c = c as f64;
                chart.draw_series(std::iter::once(Rectangle::new(
                    [(c - HALF_WIDTH, -band), (c + HALF_WIDTH, *band)],
                    RGBColor(200, 200, 200).mix(0.6).filled(),
                )))?;
            }
        }
        chart.draw_series(std::iter::once(PathElement::new(
            vec![(-0.5, 0.0), (n as f64 - 0.5, 0.0)],
            DATA_COLOUR.stroke_width(1),
        )))?;
        for (c, &i) in order.iter().enumerate() {
            let p = &points[i];
            let k = p.model.len().max(1) as f64;
            // Spread over the category so that equal residuals stay visible.
            let at = |j: usize| c as f64 - HALF_WIDTH + 2.0 * HALF_WIDTH * (j as f64 + 0.5) / k;
            chart.draw_series(
                run_half_widths(p)
                    .into_iter()
                    .enumerate()
                    .filter(|(_, w)| w.is_finite())
                    .map(|(j, w)| {
                        PathElement::new(
                            vec![(at(j), -w), (at(j), w)],
                            RUN_BAND_COLOUR.stroke_width(1),
                        )
                    }),
            )?;
            chart.draw_series(p.model.iter().zip(&p.surrogate).enumerate().map(
                |(j, (m, s))| Circle::new((at(j), m - s), 3, SAMPLE_COLOUR.mix(0.8).filled()),
            ))?;
            if let Some((m, _)) = p.map_model {
                chart.draw_series(std::iter::once(Circle::new(
                    (c as f64, m - p.map_surrogate.0),
                    5,
                    MAP_COLOUR.filled(),
                )))?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::median;

    #[test]
    fn median_of_odd_and_even_counts() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(&[]).is_nan());
    }
}
