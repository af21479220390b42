//! Axis ranges and tick positions that plotters does not choose well on its own: logarithmic
//! stress axes with 1–2–5 ticks, and category axes with one tick per category.

use std::ops::Range;

use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint, Ranged};

/// A logarithmic axis range around the positive values `xs`, padded by `pad_decades` on each
/// side (in decades), and its 1–2–5 tick positions inside the range.
pub(crate) fn log_axis(xs: &[f64], pad_decades: f64) -> (f64, f64, Vec<f64>) {
    let (lo, hi) = crate::statistics::extent(xs.iter().copied()).unwrap_or((1.0, 10.0));
    let (log_lo, log_hi) = (lo.log10() - pad_decades, hi.log10() + pad_decades);
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
    }
    (lo, hi, ticks)
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

/// Half the smallest spacing between neighbouring sorted values of `xs` in decades, a width
/// that keeps violins and markers at neighbouring stresses apart (0.1 for a single value).
pub(crate) fn half_min_log_spacing(xs: &[f64]) -> f64 {
    let mut logs: Vec<f64> = xs.iter().map(|x| x.log10()).collect();
    logs.sort_by(f64::total_cmp);
    logs.windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 0.0)
        .fold(None, |acc: Option<f64>, d| {
            Some(acc.map_or(d, |a| a.min(d)))
        })
        .map_or(0.1, |d| d / 2.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_ticks_follow_one_two_five() {
        let (lo, hi, ticks) = log_axis(&[0.64, 9.04], 0.1);
        assert!(lo < 0.64 && hi > 9.04);
        assert_eq!(ticks, vec![1.0, 2.0, 5.0, 10.0]);
    }

    #[test]
    fn category_labels_only_at_integers() {
        let labels = vec!["a".to_string(), "b".to_string()];
        assert_eq!(category_label(&labels, 1.0), "b");
        assert_eq!(category_label(&labels, 0.5), "");
        assert_eq!(category_label(&labels, 7.0), "");
    }
}
