//! Axis ranges and tick positions that plotters does not choose well on its own: the control
//! value's axis (logarithmic or linear, chosen from the data, with 1–2–5 ticks), and category
//! axes with one tick per category.

use std::ops::Range;

use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint, Ranged};
use plotters::coord::types::RangedCoordf64;

use crate::format::format_tick;
use crate::statistics::{extent, padded};

/// Smallest ratio max/min of positive control values that gets a logarithmic axis: narrower
/// positive ranges (less than about 0.6 decades) read better on a linear one.
const MIN_LOG_RATIO: f64 = 4.0;
/// Most ticks on a linear axis; the 1–2–5 step is the smallest that keeps within it.
const MAX_LINEAR_TICKS: usize = 8;

/// Room left on each side of the data along a [`DataAxis`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct Padding {
    /// Room on a logarithmic axis, in decades.
    pub decades: f64,
    /// Room on a linear axis, as a fraction of the data's span (of its magnitude, or 1, when
    /// all values are equal).
    pub fraction: f64,
    /// Least room whatever the scale, in units of [`DataAxis::half_min_spacing`]: 1 leaves
    /// room for marks (violins) as wide as the spacing of the values allows.
    pub half_spacings: f64,
}

/// The x axis of the figures drawn against the data's control values: logarithmic when every
/// value is positive and they span a ratio of at least 4, linear otherwise (zero, negative
/// values, or a narrow range).
///
/// Charts draw on the axis itself, a plain linear coordinate in *axis space* — log10 x on a logarithmic axis, x
/// itself on a linear one — so both scales share one coordinate type: every x drawn goes
/// through [`DataAxis::map`], and tick labels through [`DataAxis::label`].
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct DataAxis {
    /// Whether axis space is log10 x (otherwise it is x).
    pub log: bool,
    /// Lower end of the axis, in axis space.
    pub lo: f64,
    /// Upper end of the axis, in axis space.
    pub hi: f64,
    /// Tick positions in axis space, increasing and within `lo..=hi`.
    pub ticks: Vec<f64>,
}

impl DataAxis {
    /// Whether control values `xs` get a logarithmic axis: all positive with max/min ≥ 4.
    pub(crate) fn wants_log(xs: &[f64]) -> bool {
        match extent(xs.iter().copied()) {
            Some((lo, hi)) => lo > 0.0 && hi / lo >= MIN_LOG_RATIO,
            None => false,
        }
    }

    /// The axis around the finite values `xs`, with `padding` on each side: 1–2–5 ticks per
    /// decade on a logarithmic axis (the values themselves when fewer than three fall in
    /// range), 1–2–5 steps with at most eight ticks on a linear one.
    pub(crate) fn new(xs: &[f64], padding: Padding) -> Self {
        let log = Self::wants_log(xs);
        let mapped = xs.iter().map(|&x| if log { x.log10() } else { x });
        let (data_lo, data_hi) = extent(mapped).unwrap_or((0.0, 1.0));
        let (lo, hi) = if log {
            (data_lo - padding.decades, data_hi + padding.decades)
        } else {
            padded(data_lo, data_hi, padding.fraction)
        };
        let room = padding.half_spacings.max(0.0) * half_min_spacing(log, xs);
        let (lo, hi) = (lo.min(data_lo - room), hi.max(data_hi + room));
        let ticks = if log {
            log_ticks(lo, hi, xs)
        } else {
            linear_ticks(lo, hi)
        };
        Self { log, lo, hi, ticks }
    }

    /// Control value `x` in axis space: log10 x on a logarithmic axis, x on a linear one.
    pub(crate) fn map(&self, x: f64) -> f64 {
        if self.log { x.log10() } else { x }
    }

    /// The tick label at axis-space position `v`: the control value there, through
    /// [`format_tick`].
    pub(crate) fn label(&self, v: f64) -> String {
        let x = if self.log { 10f64.powf(v) } else { v };
        format_tick(x)
    }

    /// Half the smallest spacing between distinct neighbouring values of `xs` in axis space, a
    /// width that keeps violins and markers at neighbouring control values apart. With a single
    /// distinct value: 0.1 decades on a logarithmic axis, a tenth of the value's magnitude (at
    /// least 0.1) on a linear one.
    pub(crate) fn half_min_spacing(&self, xs: &[f64]) -> f64 {
        half_min_spacing(self.log, xs)
    }
}

/// Plotted as a linear coordinate from `lo` to `hi` in axis space, with a key point at each
/// tick.
impl Ranged for DataAxis {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        RangedCoordf64::from(self.lo..self.hi).map(value, limit)
    }

    fn key_points<Hint: KeyPointHint>(&self, _hint: Hint) -> Vec<f64> {
        self.ticks.clone()
    }

    fn range(&self) -> Range<f64> {
        self.lo..self.hi
    }
}

/// [`DataAxis::half_min_spacing`] of `xs` on a logarithmic (`log`) or linear axis.
fn half_min_spacing(log: bool, xs: &[f64]) -> f64 {
    let mut mapped: Vec<f64> = xs
        .iter()
        .map(|&x| if log { x.log10() } else { x })
        .collect();
    mapped.sort_by(f64::total_cmp);
    let single = match mapped.first() {
        Some(x) if !log => 0.1 * x.abs().max(1.0),
        _ => 0.1,
    };
    mapped
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 0.0)
        .reduce(f64::min)
        .map_or(single, |d| d / 2.0)
}

/// Ticks of a logarithmic axis from `log_lo` to `log_hi` (in decades): log10 of the 1–2–5
/// values in range, or of the values `xs` when fewer than three fall in range.
fn log_ticks(log_lo: f64, log_hi: f64, xs: &[f64]) -> Vec<f64> {
    let (lo, hi) = (10f64.powf(log_lo), 10f64.powf(log_hi));
    let mut ticks = Vec::new();
    for exponent in (log_lo.floor() as i32)..=(log_hi.ceil() as i32) {
        let decade = 10f64.powi(exponent);
        for mantissa in [1.0, 2.0, 5.0] {
            let tick = mantissa * decade;
            if (lo..=hi).contains(&tick) {
                ticks.push(tick);
            }
        }
    }
    if ticks.len() < 3 {
        ticks = xs.to_vec();
        ticks.sort_by(f64::total_cmp);
        ticks.dedup();
    }
    ticks.into_iter().map(f64::log10).collect()
}

/// Ticks of a linear axis from `lo` to `hi`: the multiples of the smallest 1–2–5 step that
/// puts at most [`MAX_LINEAR_TICKS`] in range.
fn linear_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let span = hi - lo;
    if !(span > 0.0 && span.is_finite()) {
        return vec![lo];
    }
    let mut exponent = (span / MAX_LINEAR_TICKS as f64).log10().floor() as i32 - 1;
    loop {
        for mantissa in [1.0, 2.0, 5.0] {
            let step = mantissa * 10f64.powi(exponent);
            let first = (lo / step).ceil() as i64;
            let last = (hi / step).floor() as i64;
            if last - first < MAX_LINEAR_TICKS as i64 {
                // Multiples of the step, rounded so that 0.1 · 3 reads 0.3 and −0 reads 0.
                let decimals = (-exponent).max(0);
                let scale = 10f64.powi(decimals);
                return (first..=last)
                    .map(|k| ((k as f64 * step * scale).round() / scale) + 0.0)
                    .collect();
            }
        }
        exponent += 1;
    }
}

/// The label of tick `value` on a linear axis from `lo` to `hi`: [`format_tick`], with a value
/// within a billionth of the span from zero shown as 0 (plotters' own ticks step by sums that
/// leave residues such as −1.1e−16 where the axis crosses zero).
pub(crate) fn linear_tick_label(value: f64, lo: f64, hi: f64) -> String {
    if value.abs() <= 1e-9 * (hi - lo).abs() {
        "0".to_string()
    } else {
        format_tick(value)
    }
}

/// A category axis: positions 0, 1, …, n−1 (with half a category of room on each side) and one
/// tick per category; bars sit at fractional positions around their category.
#[derive(Debug, Clone, Copy)]
pub(crate) struct CategoryAxis {
    /// Number of categories.
    pub count: usize,
}

impl Ranged for CategoryAxis {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        let range = self.range();
        let fraction = (value - range.start) / (range.end - range.start);
        limit.0 + (fraction * (limit.1 - limit.0) as f64).round() as i32
    }

    fn key_points<Hint: KeyPointHint>(&self, _hint: Hint) -> Vec<f64> {
        (0..self.count).map(|i| i as f64).collect()
    }

    fn range(&self) -> Range<f64> {
        -0.5..self.count.max(1) as f64 - 0.5
    }
}

/// The label of category tick `value`: `labels[value]` when it is a category's position,
/// otherwise empty.
pub(crate) fn category_label(labels: &[String], value: f64) -> String {
    let index = value.round();
    if (value - index).abs() < 1e-9 && index >= 0.0 {
        labels.get(index as usize).cloned().unwrap_or_default()
    } else {
        String::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// No room beyond the data but what `decades` and `fraction` ask.
    const PAD: Padding = Padding {
        decades: 0.1,
        fraction: 0.05,
        half_spacings: 0.0,
    };

    /// The axis's ticks are increasing, inside its range, and cover it: no gap at either end
    /// wider than a step between ticks (plus the padding).
    fn assert_ticks_cover(axis: &DataAxis) {
        let ticks = &axis.ticks;
        assert!(ticks.len() >= 3, "too few ticks: {ticks:?}");
        assert!(ticks.windows(2).all(|w| w[0] < w[1]), "{ticks:?}");
        assert!(ticks.iter().all(|t| (axis.lo..=axis.hi).contains(t)));
        let widest = ticks.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max);
        assert!(ticks[0] - axis.lo <= widest && axis.hi - ticks[ticks.len() - 1] <= widest);
    }

    #[test]
    fn red_cell_stresses_get_a_log_axis_with_one_two_five_ticks() {
        let axis = DataAxis::new(&[0.64, 9.04], PAD);
        assert!(axis.log);
        assert!(axis.lo < 0.64f64.log10() && axis.hi > 9.04f64.log10());
        let labels: Vec<String> = axis.ticks.iter().map(|&t| axis.label(t)).collect();
        assert_eq!(labels, ["1", "2", "5", "10"]);
        assert_eq!(axis.map(100.0), 2.0);
        assert_ticks_cover(&axis);
    }

    #[test]
    fn zero_negative_or_narrow_values_get_a_linear_axis() {
        let times: Vec<f64> = (0..=20).map(|k| 0.5 * k as f64).collect();
        let axis = DataAxis::new(&times, PAD);
        assert!(!axis.log);
        assert!(axis.lo < 0.0 && axis.hi > 10.0);
        assert_eq!(axis.ticks, [0.0, 2.0, 4.0, 6.0, 8.0, 10.0]);
        assert_eq!(axis.map(2.5), 2.5);
        assert_eq!(axis.label(2.5), "2.5");
        assert_ticks_cover(&axis);

        let negative = DataAxis::new(&[-3.0, -1.0, 0.5, 2.0], PAD);
        assert!(!negative.log);
        assert_ticks_cover(&negative);

        assert!(!DataAxis::wants_log(&[1.0, 2.0]));
        let narrow = DataAxis::new(&[1.0, 1.5, 2.0], PAD);
        assert!(!narrow.log);
        assert_ticks_cover(&narrow);
        assert!(DataAxis::wants_log(&[1.0, 4.0]));
        assert!(!DataAxis::wants_log(&[]));
    }

    #[test]
    fn linear_ticks_are_round_and_few() {
        for (lo, hi) in [
            (0.0, 1.0),
            (-0.03, 0.07),
            (-1234.0, 5678.0),
            (0.1, 0.3),
            (-7.5, -7.25),
        ] {
            let ticks = linear_ticks(lo, hi);
            assert!((3..=MAX_LINEAR_TICKS).contains(&ticks.len()), "{ticks:?}");
            assert!(ticks.windows(2).all(|w| w[0] < w[1]));
            assert!(ticks.iter().all(|t| (lo..=hi).contains(t)));
            for t in &ticks {
                assert!(format_tick(*t).len() <= 8, "{t} reads {}", format_tick(*t));
            }
        }
        assert_eq!(linear_ticks(0.0, 1.0), [0.0, 0.2, 0.4, 0.6, 0.8, 1.0]);
        assert_eq!(linear_ticks(-0.05, 0.05)[2], 0.0);
    }

    #[test]
    fn half_spacings_are_measured_in_axis_space() {
        let log = DataAxis::new(&[1.0, 10.0, 100.0], PAD);
        assert!((log.half_min_spacing(&[1.0, 10.0, 100.0]) - 0.5).abs() < 1e-12);
        let linear = DataAxis::new(&[0.0, 1.0, 3.0], PAD);
        assert_eq!(linear.half_min_spacing(&[0.0, 1.0, 3.0]), 0.5);
        assert_eq!(linear.half_min_spacing(&[4.0]), 0.4);
        // Room for violins half a spacing wide beyond the outermost values.
        let roomy = DataAxis::new(
            &[0.0, 1.0, 3.0],
            Padding {
                half_spacings: 1.0,
                ..PAD
            },
        );
        assert!(roomy.lo <= -0.5 && roomy.hi >= 3.5);
        // A single value still gets a non-empty axis.
        let single = DataAxis::new(&[0.0], PAD);
        assert!(single.lo < 0.0 && single.hi > 0.0);
    }

    #[test]
    fn residues_at_zero_read_zero() {
        assert_eq!(linear_tick_label(-1.11e-16, -0.7, 0.2), "0");
        assert_eq!(linear_tick_label(-0.1, -0.7, 0.2), "-0.1");
        assert_eq!(linear_tick_label(1e-13, 0.0, 1e-12), "1.000e-13");
    }

    #[test]
    fn category_labels_only_at_integers() {
        let labels = vec!["a".to_string(), "b".to_string()];
        assert_eq!(category_label(&labels, 1.0), "b");
        assert_eq!(category_label(&labels, 0.5), "");
        assert_eq!(category_label(&labels, 7.0), "");
    }
}
