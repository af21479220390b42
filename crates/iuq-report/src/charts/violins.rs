//! Figure 5: the propagated output at each stress as violins (Gaussian KDE of the propagated
//! samples, mirrored; split left/right when there are two sources), with the measurements and
//! the MAP curves, on the control value's [`DataAxis`] (logarithmic or linear).

use iuq_core::GaussianKde;
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::axis::{DataAxis, Padding, linear_tick_label};
use crate::charts::{LegendMark, draw_error_bars, header};
use crate::error::{ReportError, Result};
use crate::figure::{Chart, DrawResult};
use crate::input::StudyReport;
use crate::statistics::{extent, padded};
use crate::style::{AXIS_LABEL_SIZE, DATA_COLOUR, FONT, GRID_COLOUR, TICK_SIZE, source_colour};

/// Points along a violin's outline.
const OUTLINE_POINTS: usize = 80;
/// Opacity of a violin's fill.
const FILL_OPACITY: f64 = 0.35;

/// Room on each side of the data along x: at least the widest violin's half-width.
const X_PADDING: Padding = Padding {
    decades: 0.12,
    fraction: 0.05,
    half_spacings: 1.0,
};
/// Widest violin's half-width, as a share of half the smallest spacing of the control values
/// in axis space, so that neighbouring violins never touch.
const VIOLIN_SHARE: f64 = 0.8;
/// Half-width of the tick marking a constant output, as a share of the same.
const CONSTANT_SHARE: f64 = 0.3;

/// The density outline of one source's propagated samples at one stress.
enum Violin {
    /// Output values `ys` and half-widths (in axis space) at them.
    Density { ys: Vec<f64>, half_widths: Vec<f64> },
    /// All samples equal: drawn as a horizontal tick.
    Constant(f64),
}

/// Which side of the stress a violin is drawn on.
#[derive(Clone, Copy)]
enum Side {
    Left,
    Right,
    Both,
}

/// The violin chart with its precomputed densities.
pub(crate) struct ViolinChart<'a> {
    report: &'a StudyReport,
    /// The x axis.
    axis: DataAxis,
    /// `violins[s][i]`: source `s` at data point `i`.
    violins: Vec<Vec<Violin>>,
    /// Extent of everything drawn along y.
    y_range: (f64, f64),
}

impl<'a> ViolinChart<'a> {
    /// Estimates the densities of every source's propagated output at every data point.
    pub(crate) fn new(report: &'a StudyReport) -> Result<Self> {
        let axis = DataAxis::new(&report.data.x, X_PADDING);
        let max_half_width = VIOLIN_SHARE * axis.half_min_spacing(&report.data.x);
        let mut violins = Vec::with_capacity(report.posteriors.len());
        for (s, posterior) in report.posteriors.iter().enumerate() {
            let mut row = Vec::with_capacity(posterior.propagated.len());
            for (i, output) in posterior.propagated.iter().enumerate() {
                row.push(violin(&output.samples, max_half_width).map_err(|e| {
                    ReportError::invalid(format!("posteriors[{s}].propagated[{i}].samples"), e)
                })?);
            }
            violins.push(row);
        }
        let data = &report.data;
        let values = (0..data.x.len())
            .flat_map(|i| [data.y[i] - data.y_err[i], data.y[i] + data.y_err[i]])
            .chain(violins.iter().flatten().flat_map(|v| match v {
                Violin::Density { ys, .. } => vec![ys[0], ys[ys.len() - 1]],
                Violin::Constant(y) => vec![*y],
            }))
            .chain(
                report
                    .posteriors
                    .iter()
                    .flat_map(|p| p.propagated.iter().map(|o| o.map_prediction)),
            );
        let (lo, hi) = extent(values).unwrap_or((0.0, 1.0));
        Ok(Self {
            report,
            axis,
            violins,
            y_range: padded(lo, hi, 0.04),
        })
    }
}

/// The violin of `samples`: KDE outline scaled to `max_half_width` (axis space) at its widest.
fn violin(samples: &[f64], max_half_width: f64) -> std::result::Result<Violin, String> {
    let (lo, hi) = extent(samples.iter().copied()).unwrap_or((0.0, 0.0));
    if samples.len() < 2 || hi - lo <= f64::EPSILON * hi.abs().max(1.0) {
        return Ok(Violin::Constant(samples.first().copied().unwrap_or(0.0)));
    }
    let points: Vec<Vec<f64>> = samples.iter().map(|&v| vec![v]).collect();
    let kde = GaussianKde::new(&points, None).map_err(|e| e.to_string())?;
    let bandwidth = kde.covariance()[0][0].sqrt();
    // Cut the outline two bandwidths beyond the extreme samples (seaborn's default cut).
    let (start, end) = (lo - 2.0 * bandwidth, hi + 2.0 * bandwidth);
    let ys: Vec<f64> = (0..OUTLINE_POINTS)
        .map(|k| start + (end - start) * k as f64 / (OUTLINE_POINTS - 1) as f64)
        .collect();
    let density = kde.evaluate_1d(&ys).map_err(|e| e.to_string())?;
    let peak = density.iter().copied().fold(0.0, f64::max);
    let half_widths = density
        .iter()
        .map(|d| {
            if peak > 0.0 {
                max_half_width * d / peak
            } else {
                0.0
            }
        })
        .collect();
    Ok(Violin::Density { ys, half_widths })
}

impl Chart for ViolinChart<'_> {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        let data = &self.report.data;
        let mut entries = vec![(
            LegendMark::DataPoint(DATA_COLOUR),
            "measurements (± std)".to_string(),
        )];
        let sources = self.report.posteriors.len();
        for (s, posterior) in self.report.posteriors.iter().enumerate() {
            let colour = source_colour(&posterior.source, s);
            let side = match (sources, s) {
                (2, 0) => " (left)",
                (2, 1) => " (right)",
                _ => "",
            };
            entries.push((
                LegendMark::Outlined(colour, FILL_OPACITY),
                format!("{}: density{side}", posterior.source),
            ));
            entries.push((
                LegendMark::Line(colour, 2),
                format!("{}: MAP", posterior.source),
            ));
        }
        let plot_area = header(area, "Propagated output per stress", &entries, 0)?;

        let axis = &self.axis;
        let (y_lo, y_hi) = self.y_range;
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

        for (s, (posterior, violins)) in
            self.report.posteriors.iter().zip(&self.violins).enumerate()
        {
            let colour = source_colour(&posterior.source, s);
            let side = match (sources, s) {
                (2, 0) => Side::Left,
                (2, 1) => Side::Right,
                _ => Side::Both,
            };
            for (i, violin) in violins.iter().enumerate() {
                let centre = axis.map(data.x[i]);
                match violin {
                    Violin::Density { ys, half_widths } => {
                        let outline = outline(centre, ys, half_widths, side);
                        chart.draw_series(std::iter::once(Polygon::new(
                            outline.clone(),
                            colour.mix(FILL_OPACITY).filled(),
                        )))?;
                        let mut closed = outline;
                        if let Some(first) = closed.first().copied() {
                            closed.push(first);
                        }
                        chart.draw_series(std::iter::once(PathElement::new(
                            closed,
                            colour.stroke_width(1),
                        )))?;
                    }
                    Violin::Constant(y) => {
                        let w = CONSTANT_SHARE * axis.half_min_spacing(&data.x);
                        let (a, b) = match side {
                            Side::Left => (centre - w, centre),
                            Side::Right => (centre, centre + w),
                            Side::Both => (centre - w, centre + w),
                        };
                        chart.draw_series(std::iter::once(PathElement::new(
                            vec![(a, *y), (b, *y)],
                            colour.stroke_width(2),
                        )))?;
                    }
                }
            }
            let mut map: Vec<(f64, f64)> = posterior
                .propagated
                .iter()
                .zip(&data.x)
                .map(|(o, &x)| (axis.map(x), o.map_prediction))
                .collect();
            map.sort_by(|a, b| a.0.total_cmp(&b.0));
            chart.draw_series(LineSeries::new(map, colour.stroke_width(2)))?;
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
        Ok(())
    }
}

/// The closed outline (x in axis space, output) of a violin centred at `centre` (axis space).
fn outline(centre: f64, ys: &[f64], half_widths: &[f64], side: Side) -> Vec<(f64, f64)> {
    let at = |offset: f64, y: f64| (centre + offset, y);
    let right = ys.iter().zip(half_widths).map(|(&y, &w)| at(w, y));
    let left = ys.iter().zip(half_widths).rev().map(|(&y, &w)| at(-w, y));
    let centre_up = ys.iter().map(|&y| at(0.0, y));
    let centre_down = ys.iter().rev().map(|&y| at(0.0, y));
    match side {
        Side::Both => right.chain(left).collect(),
        Side::Right => right.chain(centre_down).collect(),
        Side::Left => centre_up.chain(left).collect(),
    }
}
