//! Figure 4: the corner plot of the posterior — 1-D KDE marginals on the diagonal, 68 % and 95 %
//! highest-density contours of the 2-D KDE for every pair below it, all sources overlaid.

use iuq_core::GaussianKde;
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::axis::linear_tick_label;
use crate::charts::contour::{contour_lines, level_for_mass};
use crate::charts::{LegendMark, header};
use crate::figure::{Chart, DrawResult};
use crate::input::StudyReport;
use crate::statistics::{extent, padded};
use crate::style::{AXIS_LABEL_SIZE, FONT, TICK_SIZE, source_colour};

/// Points of a 1-D marginal curve.
const CURVE_POINTS: usize = 160;
/// Grid points per axis of a 2-D density.
const GRID_POINTS: usize = 56;
/// Probability masses of the drawn highest-density regions, innermost first.
pub(crate) const CONTOUR_MASSES: [f64; 2] = [0.68, 0.95];
/// Height of the title and legend strip.
const HEADER: u32 = 74;
/// Width of the left label area (ticks and parameter names).
const LEFT: u32 = 90;
/// Height of the bottom label area.
const BOTTOM: u32 = 64;
/// Blank strip right of the last column.
const RIGHT: u32 = 18;

/// A 1-D marginal: a density curve, or a single value when the samples are all equal.
enum Marginal {
    /// Density at `xs`.
    Curve { xs: Vec<f64>, density: Vec<f64> },
    /// All samples equal.
    Constant(f64),
}

/// The contour lines of one panel (row, column) below the diagonal, as (index into
/// [`CONTOUR_MASSES`], polyline) pairs.
type PairContours = ((usize, usize), Vec<(usize, Vec<(f64, f64)>)>);

/// The corner plot with its precomputed densities.
pub(crate) struct CornerChart<'a> {
    report: &'a StudyReport,
    /// Axis range of each parameter.
    ranges: Vec<(f64, f64)>,
    /// `marginals[s][p]`.
    marginals: Vec<Vec<Marginal>>,
    /// `contours[s]`: source `s`'s contour lines of each panel below the diagonal.
    contours: Vec<Vec<PairContours>>,
    /// Side of one panel in pixels.
    panel: u32,
}

impl<'a> CornerChart<'a> {
    /// Estimates all marginal and pairwise densities of every source.
    pub(crate) fn new(report: &'a StudyReport) -> Self {
        let d = report.parameters.len();
        let column = |samples: &[Vec<f64>], p: usize| -> Vec<f64> {
            samples
                .iter()
                .filter_map(|row| row.get(p).copied())
                .collect()
        };
        let ranges: Vec<(f64, f64)> = (0..d)
            .map(|p| {
                let values = report
                    .posteriors
                    .iter()
                    .flat_map(|post| column(&post.samples, p));
                let (lo, hi) = extent(values).unwrap_or((0.0, 1.0));
                padded(lo, hi, 0.06)
            })
            .collect();
        let grid = |p: usize, n: usize| -> Vec<f64> {
            let (lo, hi) = ranges[p];
            (0..n)
                .map(|k| lo + (hi - lo) * k as f64 / (n - 1) as f64)
                .collect()
        };
        let mut marginals = Vec::new();
        let mut contours = Vec::new();
        for posterior in &report.posteriors {
            let columns: Vec<Vec<f64>> = (0..d).map(|p| column(&posterior.samples, p)).collect();
            let constant: Vec<bool> = columns
                .iter()
                .map(|c| {
                    extent(c.iter().copied())
                        .is_none_or(|(lo, hi)| hi - lo <= f64::EPSILON * hi.abs().max(1.0))
                })
                .collect();
            marginals.push(
                (0..d)
                    .map(|p| {
                        let fallback =
                            Marginal::Constant(columns[p].first().copied().unwrap_or(0.0));
                        if constant[p] {
                            return fallback;
                        }
                        let points: Vec<Vec<f64>> = columns[p].iter().map(|&v| vec![v]).collect();
                        let xs = grid(p, CURVE_POINTS);
                        match GaussianKde::new(&points, None).and_then(|k| k.evaluate_1d(&xs)) {
                            Ok(density) => Marginal::Curve { xs, density },
                            Err(_) => fallback,
                        }
                    })
                    .collect(),
            );
            let mut pairs = Vec::new();
            for row in 1..d {
                for col in 0..row {
                    if constant[row] || constant[col] {
                        continue;
                    }
                    let points: Vec<Vec<f64>> = columns[col]
                        .iter()
                        .zip(&columns[row])
                        .map(|(&x, &y)| vec![x, y])
                        .collect();
                    let (xs, ys) = (grid(col, GRID_POINTS), grid(row, GRID_POINTS));
                    let Ok(z) =
                        GaussianKde::new(&points, None).and_then(|k| k.evaluate_grid_2d(&xs, &ys))
                    else {
                        continue;
                    };
                    let lines = CONTOUR_MASSES
                        .iter()
                        .enumerate()
                        .flat_map(|(m, &mass)| {
                            contour_lines(&xs, &ys, &z, level_for_mass(&z, mass))
                                .into_iter()
                                .map(move |line| (m, line))
                        })
                        .collect();
                    pairs.push(((row, col), lines));
                }
            }
            contours.push(pairs);
        }
        let panel = (920 / d.max(1) as u32).clamp(150, 300);
        Self {
            report,
            ranges,
            marginals,
            contours,
            panel,
        }
    }

    /// Pixel size (width, height) of the figure.
    pub(crate) fn size(&self) -> (u32, u32) {
        let d = self.report.parameters.len() as u32;
        (
            LEFT + d * self.panel + RIGHT,
            HEADER + d * self.panel + BOTTOM,
        )
    }

    /// Draws panel (row, col) of the lower triangle or diagonal.
    fn draw_panel<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        row: usize,
        col: usize,
    ) -> DrawResult<DB> {
        let d = self.report.parameters.len();
        let names = &self.report.parameters;
        let (x_lo, x_hi) = self.ranges[col];
        let diagonal = row == col;
        let (y_lo, y_hi) = if diagonal {
            let peak = self
                .marginals
                .iter()
                .filter_map(|m| match &m[col] {
                    Marginal::Curve { density, .. } => density.iter().copied().reduce(f64::max),
                    Marginal::Constant(_) => None,
                })
                .fold(0.0, f64::max);
            (0.0, if peak > 0.0 { peak * 1.08 } else { 1.0 })
        } else {
            self.ranges[row]
        };
        let mut chart = ChartBuilder::on(area)
            .margin(5)
            .x_label_area_size(if row == d - 1 { BOTTOM } else { 0 })
            .y_label_area_size(if col == 0 { LEFT } else { 0 })
            .build_cartesian_2d(x_lo..x_hi, y_lo..y_hi)?;
        let x_label = |v: &f64| linear_tick_label(*v, x_lo, x_hi);
        let y_label = |v: &f64| linear_tick_label(*v, y_lo, y_hi);
        let mut mesh = chart.configure_mesh();
        mesh.disable_mesh()
            .x_labels(4)
            .y_labels(if diagonal { 0 } else { 4 })
            .x_label_formatter(&x_label)
            .y_label_formatter(&y_label)
            .label_style((FONT, TICK_SIZE))
            .axis_desc_style((FONT, AXIS_LABEL_SIZE));
        if row == d - 1 {
            mesh.x_desc(names[col].as_str());
        }
        if col == 0 && !diagonal {
            mesh.y_desc(names[row].as_str());
        }
        mesh.draw()?;
        chart.plotting_area().draw(&Rectangle::new(
            [(x_lo, y_lo), (x_hi, y_hi)],
            BLACK.mix(0.6).stroke_width(1),
        ))?;

        for (s, posterior) in self.report.posteriors.iter().enumerate() {
            let colour = source_colour(&posterior.source, s);
            if diagonal {
                match &self.marginals[s][col] {
                    Marginal::Curve { xs, density } => {
                        chart.draw_series(LineSeries::new(
                            xs.iter().copied().zip(density.iter().copied()),
                            colour.stroke_width(2),
                        ))?;
                    }
                    Marginal::Constant(v) => {
                        chart.draw_series(std::iter::once(PathElement::new(
                            vec![(*v, y_lo), (*v, y_hi)],
                            colour.stroke_width(2),
                        )))?;
                    }
                }
                if let Some(summary) = posterior.summary.get(col) {
                    chart.draw_series(std::iter::once(PathElement::new(
                        vec![(summary.map, y_lo), (summary.map, y_hi)],
                        colour.mix(0.8).stroke_width(1),
                    )))?;
                }
            } else {
                if let Some((_, lines)) =
                    self.contours[s].iter().find(|(key, _)| *key == (row, col))
                {
                    for (mass, line) in lines {
                        let style = if *mass == 0 {
                            colour.stroke_width(2)
                        } else {
                            colour.mix(0.75).stroke_width(1)
                        };
                        chart
                            .draw_series(std::iter::once(PathElement::new(line.clone(), style)))?;
                    }
                }
                if let (Some(x), Some(y)) = (posterior.summary.get(col), posterior.summary.get(row))
                {
                    chart.draw_series(std::iter::once(Cross::new(
                        (x.map, y.map),
                        5,
                        colour.stroke_width(2),
                    )))?;
                }
            }
        }
        Ok(())
    }
}

impl Chart for CornerChart<'_> {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        let d = self.report.parameters.len();
        let mut entries: Vec<(LegendMark, String)> = self
            .report
            .posteriors
            .iter()
            .enumerate()
            .map(|(s, p)| {
                (
                    LegendMark::Line(source_colour(&p.source, s), 2),
                    p.source.clone(),
                )
            })
            .collect();
        let grey = RGBColor(90, 90, 90);
        entries.push((LegendMark::Line(grey, 2), "68 % region".to_string()));
        entries.push((LegendMark::Line(grey, 1), "95 % region".to_string()));
        entries.push((LegendMark::Cross(grey), "MAP".to_string()));
        let body = header(
            area,
            "Posterior: marginals and pairwise densities",
            &entries,
            HEADER,
        )?;
        let p = self.panel as i32;
        let x_breaks: Vec<i32> = (1..=d as i32).map(|k| LEFT as i32 + k * p).collect();
        let y_breaks: Vec<i32> = (1..d as i32).map(|k| k * p).collect();
        let panels = body.split_by_breakpoints(x_breaks, y_breaks);
        for row in 0..d {
            for col in 0..=row {
                if let Some(panel) = panels.get(row * (d + 1) + col) {
                    self.draw_panel(panel, row, col)?;
                }
            }
        }
        Ok(())
    }
}
