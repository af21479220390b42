//! Durations a study may name (timeouts, grace periods, poll intervals): a number of seconds or
//! a text such as `"1h30m"`, at most [`MAX_DURATION_SECONDS`].

/// The longest duration a study may name, in seconds (about 31.7 years): every timeout, grace
/// period and poll interval becomes a `std::time::Duration` added to the clock, which longer
/// values would overflow.
pub const MAX_DURATION_SECONDS: f64 = 1e9;

/// Check that `seconds` is a duration a study may name: finite, ≥ 0 and at most
/// [`MAX_DURATION_SECONDS`].
pub fn check_duration(seconds: f64) -> std::result::Result<f64, String> {
    if seconds.is_finite() && (0.0..=MAX_DURATION_SECONDS).contains(&seconds) {
        Ok(seconds)
    } else {
        Err(format!(
            "{seconds} s is not a duration from 0 to {MAX_DURATION_SECONDS:e} s"
        ))
    }
}

/// Parse a duration: a number of seconds, or a text such as `"30m"`, `"1h30m"`, `"45s"`, `"500ms"`, `"2d"`
/// (at most [`MAX_DURATION_SECONDS`]).
pub fn parse_duration(text: &str) -> std::result::Result<f64, String> {
    let t = text.trim();
    if let Ok(v) = t.parse::<f64>() {
        return check_duration(v).map_err(|reason| format!("`{text}`: {reason}"));
    }
    let mut total = 0.0;
    let mut rest = t;
    if rest.is_empty() {
        return Err("empty duration".into());
    }
    while !rest.is_empty() {
        let number_end = rest
            .find(|c: char| !(c.is_ascii_digit() || c == '.'))
            .ok_or_else(|| format!("`{text}`: a unit (ms, s, m, h, d) must follow `{rest}`"))?;
        let number: f64 = rest[..number_end].parse().map_err(|_| {
            format!("`{text}` is not a duration such as \"30m\", \"1h30m\", \"45s\"")
        })?;
        let unit_str = &rest[number_end..];
        let unit_end = unit_str
            .find(|c: char| !c.is_ascii_alphabetic())
            .unwrap_or(unit_str.len());
        let factor = match &unit_str[..unit_end] {
            "ms" => 1e-3,
            "s" => 1.0,
            "m" | "min" => 60.0,
            "h" => 3600.0,
            "d" => 86400.0,
            other => return Err(format!("`{text}`: unknown unit `{other}` (ms, s, m, h, d)")),
        };
        total += number * factor;
        rest = unit_str[unit_end..].trim_start();
    }
    check_duration(total).map_err(|reason| format!("`{text}`: {reason}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations() {
        assert_eq!(parse_duration("30m").unwrap(), 1800.0);
        assert_eq!(parse_duration("1h30m").unwrap(), 5400.0);
        assert_eq!(parse_duration("500ms").unwrap(), 0.5);
        assert_eq!(parse_duration("12").unwrap(), 12.0);
        assert!(parse_duration("3 parsecs").is_err());
        assert!(parse_duration("").is_err());
    }
}
