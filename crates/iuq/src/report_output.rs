//! What a command prints: exactly one JSON object with `--json`, readable text otherwise.

use serde_json::Value;

/// Print the result of a command: the JSON object when `json` is set, else the human text.
pub fn emit(json: bool, value: &Value, human: impl FnOnce() -> String) {
    if json {
        println!("{value}");
    } else {
        println!("{}", human());
    }
}

/// Format a number for people: 6 significant digits.
pub fn short(v: f64) -> String {
    if v == 0.0 || (v.abs() >= 1e-4 && v.abs() < 1e6) {
        let s = format!("{v:.6}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        if s.is_empty() || s == "-" {
            "0".into()
        } else {
            s.into()
        }
    } else {
        format!("{v:.5e}")
    }
}
