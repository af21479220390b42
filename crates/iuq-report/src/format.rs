//! The one number format of the report: every number shown in an HTML table goes through
//! [`format_number`], so the page is consistent and a test can check it against `report.json`.

/// Significant digits shown for non-integer values.
const SIGNIFICANT_DIGITS: i32 = 4;

/// Formats a number for display: integers in full (up to 10¹⁵), other values with four
/// significant digits, in scientific notation below 10⁻³ and from 10⁵ on in magnitude.
///
/// One function for the whole report, so that a number reads the same in every table.
pub fn format_number(value: f64) -> String {
    if value.is_nan() {
        return "NaN".to_string();
    }
    if value.is_infinite() {
        return if value > 0.0 { "∞" } else { "−∞" }.to_string();
    }
    if value == 0.0 {
        return "0".to_string();
    }
    let magnitude = value.abs();
    if value.fract() == 0.0 && magnitude < 1e15 {
        return format!("{value:.0}");
    }
    if !(1e-3..1e5).contains(&magnitude) {
        return format!("{:.*e}", (SIGNIFICANT_DIGITS - 1) as usize, value);
    }
    let exponent = magnitude.log10().floor() as i32;
    let decimals = (SIGNIFICANT_DIGITS - 1 - exponent).max(0) as usize;
    format!("{value:.decimals$}")
}

/// Formats a tick label of a figure axis: like [`format_number`] but with trailing zeros
/// removed, because tick values are round numbers.
pub(crate) fn format_tick(value: f64) -> String {
    let text = format_number(value);
    if text.contains('.') && !text.contains('e') {
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        text
    }
}

/// The label of a tick on a logarithmic axis at log10 value `exponent`: 10^exponent with two
/// significant digits (a tick between decades reads 3.2, not 3.162).
pub(crate) fn format_log_tick(exponent: f64) -> String {
    let value = 10f64.powf(exponent);
    if !value.is_finite() || value <= 0.0 {
        return format_tick(value);
    }
    let scale = 10f64.powf(value.log10().floor() - 1.0);
    format_tick((value / scale).round() * scale)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_ticks_have_two_significant_digits() {
        assert_eq!(format_log_tick(0.5), "3.2");
        assert_eq!(format_log_tick(-0.5), "0.32");
        assert_eq!(format_log_tick(1.0), "10");
        assert_eq!(format_log_tick(-1.0), "0.1");
        assert_eq!(format_log_tick(0.0), "1");
    }

    #[test]
    fn four_significant_digits_in_the_middle_range() {
        assert_eq!(format_number(0.98765), "0.9877");
        assert_eq!(format_number(123.456), "123.5");
        assert_eq!(format_number(-1.5), "-1.500");
        assert_eq!(format_number(12345.6), "12346");
        assert_eq!(format_number(0.001234), "0.001234");
    }

    #[test]
    fn integers_in_full_and_extremes_in_scientific_notation() {
        assert_eq!(format_number(1200.0), "1200");
        assert_eq!(format_number(0.0), "0");
        assert_eq!(format_number(123456.7), "1.235e5");
        assert_eq!(format_number(0.000_123_45), "1.234e-4");
        assert_eq!(format_number(f64::NAN), "NaN");
    }

    #[test]
    fn ticks_drop_trailing_zeros() {
        assert_eq!(format_tick(0.5), "0.5");
        assert_eq!(format_tick(2.0), "2");
        assert_eq!(format_tick(0.25), "0.25");
    }
}
