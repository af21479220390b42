//! The adaptive design's convergence: one panel per parameter with the posterior mean and its
//! ± 1 std band against the number of model runs, and a last panel with the surrogate's
//! log-likelihood std and its error on the posterior moments per round. The spacing of the rounds along the x axis shows the runs each
//! round added.

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use crate::axis::linear_tick_label;
use crate::charts::{LegendMark, draw_error_bars, header, panel_grid};
use crate::figure::{Chart, DrawResult};
use crate::format::{format_log_tick, format_tick};
use crate::input::{Convergence, ConvergenceRound};
use crate::statistics::{extent, padded};
use crate::style::{DATA_COLOUR, FONT, GRID_COLOUR, MODEL_COLOUR, SURROGATE_COLOUR, TICK_SIZE};

/// Height of the title and legend strip.
const HEADER: u32 = 74;
/// Width of the figure (the panels share it).
const WIDTH: u32 = 900;
/// Height of one panel.
const PANEL_HEIGHT: u32 = 270;
/// Opacity of the ± 1 std band.
const BAND_OPACITY: f64 = 0.22;
/// Title of the last panel.
const LIKELIHOOD_TITLE: &str = "surrogate uncertainty (log scale)";

/// One panel's chart: model runs against a value.
type Panel<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// The convergence chart.
pub(crate) struct ConvergenceChart<'a> {
    /// The adaptive engine's rounds (at least one).
    pub convergence: &'a Convergence,
}

impl ConvergenceChart<'_> {
    /// Panels: one per parameter and the surrogate's.
    fn panels(&self) -> usize {
        self.convergence.parameters.len() + 1
    }

    /// Panels per row: up to three, four panels as two by two.
    fn columns(&self) -> usize {
        match self.panels() {
            4 => 2,
            n => n.clamp(1, 3),
        }
    }

    /// Pixel size (width, height) of the figure.
    pub(crate) fn size(&self) -> (u32, u32) {
        let rows = self.panels().div_ceil(self.columns()) as u32;
        (WIDTH, HEADER + PANEL_HEIGHT * rows)
    }

    /// The x range shared by all panels: the runs of the rounds.
    fn runs_range(&self) -> (f64, f64) {
        let runs = self.convergence.rounds.iter().map(|r| r.runs as f64);
        let (lo, hi) = extent(runs).unwrap_or((0.0, 1.0));
        padded(lo, hi, 0.05)
    }

    /// A panel's chart with its mesh: `y` range, caption, and the runs on the x axis.
    /// With `log_y` the panel's y values are log10 of the quantity and its labels show the
    /// quantity (10^y).
    fn draw_mesh<'a, DB: DrawingBackend>(
        &self,
        area: &'a DrawingArea<DB, Shift>,
        caption: &str,
        (y_lo, y_hi): (f64, f64),
        log_y: bool,
    ) -> std::result::Result<Panel<'a, DB>, DrawingAreaErrorKind<DB::ErrorType>> {
        let (x_lo, x_hi) = self.runs_range();
        let mut chart = ChartBuilder::on(area)
            .caption(caption, (FONT, TICK_SIZE + 2))
            .margin(8)
            .x_label_area_size(46)
            .y_label_area_size(66)
            .build_cartesian_2d(x_lo..x_hi, y_lo..y_hi)?;
        chart
            .configure_mesh()
            .x_desc("model runs")
            .x_labels(5)
            .y_labels(5)
            .x_label_formatter(&|v| {
                if v.fract() == 0.0 {
                    format_tick(*v)
                } else {
                    String::new()
                }
            })
            .y_label_formatter(&|v| {
                if log_y {
                    format_log_tick(*v)
                } else {
                    linear_tick_label(*v, y_lo, y_hi)
                }
            })
            .label_style((FONT, TICK_SIZE - 1))
            .axis_desc_style((FONT, TICK_SIZE))
            .bold_line_style(GRID_COLOUR)
            .light_line_style(TRANSPARENT)
            .draw()?;
        Ok(chart)
    }

    /// Parameter `p`'s posterior mean with its ± 1 std band per round.
    fn draw_parameter<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        p: usize,
    ) -> DrawResult<DB> {
        let rounds = &self.convergence.rounds;
        let band = |r: &ConvergenceRound| (r.mean[p] - r.std[p], r.mean[p] + r.std[p]);
        let values = rounds.iter().flat_map(|r| {
            let (lo, hi) = band(r);
            [lo, hi]
        });
        let (lo, hi) = extent(values).unwrap_or((0.0, 1.0));
        let name = &self.convergence.parameters[p];
        let mut chart = self.draw_mesh(area, name, padded(lo, hi, 0.08), false)?;
        let x = |r: &ConvergenceRound| r.runs as f64;
        if rounds.len() > 1 {
            let mut outline: Vec<(f64, f64)> = rounds.iter().map(|r| (x(r), band(r).1)).collect();
            outline.extend(rounds.iter().rev().map(|r| (x(r), band(r).0)));
            chart.draw_series(std::iter::once(Polygon::new(
                outline,
                SURROGATE_COLOUR.mix(BAND_OPACITY).filled(),
            )))?;
        } else {
            // A single round has no band to shade: its ± 1 std as a whisker.
            let whiskers: Vec<(f64, f64, f64)> = rounds
                .iter()
                .map(|r| (x(r), band(r).0, band(r).1))
                .collect();
            draw_error_bars(&mut chart, &whiskers, SURROGATE_COLOUR.stroke_width(1), 5)?;
        }
        let means: Vec<(f64, f64)> = rounds.iter().map(|r| (x(r), r.mean[p])).collect();
        chart.draw_series(LineSeries::new(
            means.clone(),
            SURROGATE_COLOUR.stroke_width(2),
        ))?;
        chart.draw_series(
            means
                .into_iter()
                .map(|m| Circle::new(m, 3, SURROGATE_COLOUR.filled())),
        )?;
        Ok(())
    }

    /// The surrogate's log-likelihood std (nats) and its error on the posterior moments
    /// (posterior stds) per round, on a logarithmic axis (they fall by orders of magnitude as
    /// the surrogate learns the posterior region).
    fn draw_likelihood<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        let rounds = &self.convergence.rounds;
        let log = |u: f64| u.max(1e-6).log10();
        let (lo, hi) = extent(
            rounds
                .iter()
                .map(|r| log(r.log_likelihood_std))
                .chain(rounds.iter().filter_map(|r| r.surrogate_error.map(log))),
        )
        .unwrap_or((-1.0, 0.0));
        let (lo, hi) = if hi - lo < 1.0 {
            (lo - 0.5, hi + 0.5)
        } else {
            padded(lo, hi, 0.08)
        };
        let mut chart = self.draw_mesh(area, LIKELIHOOD_TITLE, (lo, hi), true)?;
        let points: Vec<(f64, f64)> = rounds
            .iter()
            .map(|r| (r.runs as f64, log(r.log_likelihood_std)))
            .collect();
        chart.draw_series(LineSeries::new(points.clone(), DATA_COLOUR.stroke_width(2)))?;
        chart.draw_series(
            points
                .into_iter()
                .map(|p| Circle::new(p, 3, DATA_COLOUR.filled())),
        )?;
        let errors: Vec<(f64, f64)> = rounds
            .iter()
            .filter_map(|r| r.surrogate_error.map(|e| (r.runs as f64, log(e))))
            .collect();
        chart.draw_series(LineSeries::new(
            errors.clone(),
            MODEL_COLOUR.stroke_width(2),
        ))?;
        chart.draw_series(
            errors
                .into_iter()
                .map(|p| Circle::new(p, 3, MODEL_COLOUR.filled())),
        )?;
        Ok(())
    }
}

impl Chart for ConvergenceChart<'_> {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        let entries = [
            (
                LegendMark::LineOnBand(SURROGATE_COLOUR, BAND_OPACITY),
                "posterior mean ± 1 std".to_string(),
            ),
            (
                LegendMark::Line(DATA_COLOUR, 2),
                "surrogate log-likelihood std (nats)".to_string(),
            ),
            (
                LegendMark::Line(MODEL_COLOUR, 2),
                "surrogate error of the moments (posterior stds)".to_string(),
            ),
        ];
        let body = header(area, "Convergence of the adaptive design", &entries, HEADER)?;
        let regions = panel_grid(&body, self.panels(), self.columns());
        let d = self.convergence.parameters.len();
        for (p, region) in regions.iter().take(d).enumerate() {
            self.draw_parameter(region, p)?;
        }
        if let Some(region) = regions.get(d) {
            self.draw_likelihood(region)?;
        }
        Ok(())
    }
}
