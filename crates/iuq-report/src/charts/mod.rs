//! The report's charts, one kind per file, and the drawing helpers they share (legends drawn
//! in a strip of their own, error bars, panel grids).

pub(crate) mod cell_portraits;
pub(crate) mod contour;
pub(crate) mod convergence;
pub(crate) mod corner;
pub(crate) mod data_fit;
pub(crate) mod failure_map;
pub(crate) mod gp_diagnostics;
pub(crate) mod map_error;
pub(crate) mod model_posterior;
pub(crate) mod posterior_check;
pub(crate) mod sampler_stages;
pub(crate) mod sensitivity;
pub(crate) mod violins;

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::figure::DrawResult;
use crate::style::{FONT, LEGEND_SIZE, TITLE_SIZE};

/// How a legend entry is marked.
#[derive(Debug, Clone, Copy)]
pub(crate) enum LegendMark {
    /// A line of the colour and stroke width.
    Line(RGBColor, u32),
    /// A dashed line of the colour and stroke width.
    Dashed(RGBColor, u32),
    /// A filled square of the colour at the opacity.
    Filled(RGBColor, f64),
    /// A light square (colour at the opacity) with a border of the full colour.
    Outlined(RGBColor, f64),
    /// A filled circle with a vertical whisker, as data points are drawn.
    DataPoint(RGBColor),
    /// A vertical whisker with caps, as confidence intervals are drawn.
    Whisker(RGBColor),
    /// A line over a light band, as a curve with its credible band is drawn.
    LineOnBand(RGBColor, f64),
    /// A cross, as point estimates are marked.
    Cross(RGBColor),
    /// A filled circle, as single points are marked.
    Dot(RGBColor),
    /// A hollow circle.
    Ring(RGBColor),
    /// A ramp of the colour from transparent to the opacity, as a shaded scale is drawn.
    Ramp(RGBColor, f64),
}

impl LegendMark {
    /// Width of the mark's swatch in pixels: a ramp takes two swatches.
    fn width(self) -> i32 {
        match self {
            LegendMark::Ramp(..) => 2 * SWATCH,
            _ => SWATCH,
        }
    }
}

/// Height of one legend line in pixels.
const LEGEND_LINE: i32 = 24;
/// Vertical position of the first legend line's centre below the top of the header.
const LEGEND_TOP: i32 = 50;
/// Width of a legend swatch, the gap after it, and the space between entries.
const SWATCH: i32 = 22;
const GAP: i32 = 8;
const SPACING: i32 = 26;

/// Draws a figure's header — the title centred at the top, then the legend centred in as many
/// lines as it needs — and returns the area below it (at least `min_height` is taken).
pub(crate) fn header<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    entries: &[(LegendMark, String)],
    min_height: u32,
) -> std::result::Result<DrawingArea<DB, Shift>, DrawingAreaErrorKind<DB::ErrorType>> {
    let style =
        TextStyle::from((FONT, LEGEND_SIZE).into_font()).pos(Pos::new(HPos::Left, VPos::Center));
    let (width, _) = area.dim_in_pixel();
    let mut widths = Vec::with_capacity(entries.len());
    for (mark, text) in entries {
        let (w, _) = area.estimate_text_size(text, &style)?;
        widths.push(mark.width() + GAP + w as i32 + SPACING);
    }
    // Lay the entries out in lines no wider than the area.
    let mut lines: Vec<Vec<usize>> = Vec::new();
    let mut line_width = 0;
    for (i, w) in widths.iter().enumerate() {
        match lines.last_mut() {
            Some(line) if line_width + w <= width as i32 - 20 => line.push(i),
            _ => {
                lines.push(vec![i]);
                line_width = 0;
            }
        }
        line_width += w;
    }
    let height = (LEGEND_TOP + lines.len() as i32 * LEGEND_LINE - 4).max(min_height as i32);
    let (top, rest) = area.split_vertically(height);
    top.titled(title, (FONT, TITLE_SIZE))?;
    for (l, line) in lines.iter().enumerate() {
        let total: i32 = line.iter().map(|&i| widths[i]).sum::<i32>() - SPACING;
        let mut x = (width as i32 - total) / 2;
        let y = LEGEND_TOP + l as i32 * LEGEND_LINE;
        for &i in line {
            let (mark, text) = &entries[i];
            draw_mark(&top, *mark, (x, y), mark.width())?;
            top.draw(&Text::new(
                text.as_str(),
                (x + mark.width() + GAP, y),
                style.clone(),
            ))?;
            x += widths[i];
        }
    }
    Ok(rest)
}

/// Draws one legend mark `swatch` pixels wide, vertically centred on `(x, y)`.
fn draw_mark<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    mark: LegendMark,
    (x, y): (i32, i32),
    swatch: i32,
) -> DrawResult<DB> {
    match mark {
        LegendMark::Line(colour, width) => {
            area.draw(&PathElement::new(
                vec![(x, y), (x + swatch, y)],
                colour.stroke_width(width),
            ))?;
        }
        LegendMark::Dashed(colour, width) => {
            let dash = (swatch / 5).max(2);
            for start in [x, x + 2 * dash, x + swatch - dash] {
                area.draw(&PathElement::new(
                    vec![(start, y), (start + dash, y)],
                    colour.stroke_width(width),
                ))?;
            }
        }
        LegendMark::Filled(colour, opacity) => {
            area.draw(&Rectangle::new(
                [(x, y - 6), (x + swatch, y + 6)],
                colour.mix(opacity).filled(),
            ))?;
        }
        LegendMark::Outlined(colour, opacity) => {
            area.draw(&Rectangle::new(
                [(x, y - 6), (x + swatch, y + 6)],
                colour.mix(opacity).filled(),
            ))?;
            area.draw(&Rectangle::new(
                [(x, y - 6), (x + swatch, y + 6)],
                colour.stroke_width(1),
            ))?;
        }
        LegendMark::DataPoint(colour) => {
            let centre = x + swatch / 2;
            area.draw(&PathElement::new(
                vec![(centre, y - 7), (centre, y + 7)],
                colour.stroke_width(1),
            ))?;
            area.draw(&Circle::new((centre, y), 4, colour.filled()))?;
        }
        LegendMark::LineOnBand(colour, opacity) => {
            area.draw(&Rectangle::new(
                [(x, y - 7), (x + swatch, y + 7)],
                colour.mix(opacity).filled(),
            ))?;
            area.draw(&PathElement::new(
                vec![(x, y), (x + swatch, y)],
                colour.stroke_width(2),
            ))?;
        }
        LegendMark::Cross(colour) => {
            area.draw(&Cross::new((x + swatch / 2, y), 5, colour.stroke_width(2)))?;
        }
        LegendMark::Dot(colour) => {
            area.draw(&Circle::new((x + swatch / 2, y), 4, colour.filled()))?;
        }
        LegendMark::Ring(colour) => {
            area.draw(&Circle::new((x + swatch / 2, y), 4, colour.stroke_width(1)))?;
        }
        LegendMark::Ramp(colour, opacity) => {
            const STEPS: i32 = 11;
            let step = swatch / STEPS;
            for k in 0..STEPS {
                let left = x + k * step;
                area.draw(&Rectangle::new(
                    [(left, y - 6), (left + step, y + 6)],
                    colour.mix(opacity * k as f64 / (STEPS - 1) as f64).filled(),
                ))?;
            }
            area.draw(&Rectangle::new(
                [(x, y - 6), (x + STEPS * step, y + 6)],
                colour.mix(0.5).stroke_width(1),
            ))?;
        }
        LegendMark::Whisker(colour) => {
            let centre = x + swatch / 2;
            let style = colour.stroke_width(1);
            area.draw(&PathElement::new(
                vec![(centre, y - 7), (centre, y + 7)],
                style,
            ))?;
            for cap in [y - 7, y + 7] {
                area.draw(&PathElement::new(
                    vec![(centre - 3, cap), (centre + 3, cap)],
                    style,
                ))?;
            }
        }
    }
    Ok(())
}

/// Draws vertical error bars `(x, lo, hi)` on `chart`, with caps `cap` pixels to each side: the
/// bars are data-space lines, the caps pixel-space marks anchored at the ends.
pub(crate) fn draw_error_bars<DB, X, Y>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<X, Y>>,
    bars: &[(f64, f64, f64)],
    style: ShapeStyle,
    cap: i32,
) -> DrawResult<DB>
where
    DB: DrawingBackend,
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
{
    chart.draw_series(
        bars.iter()
            .map(|&(x, lo, hi)| PathElement::new(vec![(x, lo), (x, hi)], style)),
    )?;
    if cap > 0 {
        chart.draw_series(bars.iter().flat_map(|&(x, lo, hi)| {
            [lo, hi].map(|y| {
                EmptyElement::at((x, y)) + PathElement::new(vec![(-cap, 0), (cap, 0)], style)
            })
        }))?;
    }
    Ok(())
}

/// Splits `area` into a grid of `count` panels in `columns` columns (the last row may be
/// partly empty), returning the panels in reading order.
pub(crate) fn panel_grid<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    count: usize,
    columns: usize,
) -> Vec<DrawingArea<DB, Shift>> {
    let columns = columns.max(1);
    let rows = count.div_ceil(columns).max(1);
    let mut panels = area.split_evenly((rows, columns));
    panels.truncate(count);
    panels
}
