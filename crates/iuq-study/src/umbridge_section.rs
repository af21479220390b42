//! The `[model]` section of kind `umbridge`: a model on a UM-Bridge 1.0 server (see the
//! `iuq-umbridge` crate), used like any other model by `iuq sobol` and `iuq basis`.
//!
//! ```toml
//! [model]
//! kind = "umbridge"
//! url = "http://localhost:4242"     # the server (plain HTTP)
//! name = "forward"                   # the model's name on the server
//! config = { level = 1 }             # optional: sent with every request (model-specific)
//! outputs = ["EI_0.3Pa", "EI_0.6Pa"] # optional: output names (default: name, or name_1…name_m)
//! computational_std = false          # optional: the server answers [outputs, stds]; an iuq
//!                                    # server does so with config = { computational_std = true }
//! concurrency = 4                    # optional: evaluations in flight at once
//! retries = 5                        # optional: retries after a lost connection or a 502/503/504
//! retry_delay = 1.0                  # optional: seconds before the first retry (then doubled)
//! timeout = 7200                     # optional: seconds to wait for one evaluation (default: none)
//! ```
//!
//! The study's parameters, in file order, are the model's input: the model's input sizes must
//! add up to their number (they are split over its input vectors in order). Output j is the
//! j-th value of the concatenated output vectors.

use std::time::Duration;

use iuq_umbridge::{ClientOptions, UmBridgeModel};

use crate::error::{Result, StudyError, input_error};

/// The keys the section accepts.
pub const UMBRIDGE_KEYS: [&str; 10] = [
    "kind",
    "url",
    "name",
    "config",
    "outputs",
    "computational_std",
    "concurrency",
    "retries",
    "retry_delay",
    "timeout",
];

/// A parsed `[model] kind = "umbridge"` section.
#[derive(Debug, Clone)]
pub struct UmBridgeSection {
    /// The server's URL.
    pub url: String,
    /// The model's name on the server.
    pub name: String,
    /// How the client talks to the server (config, output names, concurrency, retries…).
    pub options: ClientOptions,
}

fn positive_seconds(value: &toml::Value, file: &str, key: &str) -> Result<Duration> {
    let seconds = value
        .as_float()
        .or_else(|| value.as_integer().map(|i| i as f64))
        .filter(|s| s.is_finite() && *s >= 0.0 && *s < 1e9)
        .ok_or_else(|| {
            input_error(format!(
                "{file}: key `model.{key}`: expected a number of seconds ≥ 0"
            ))
        })?;
    Ok(Duration::from_secs_f64(seconds))
}

/// Parses the section (no network access: the server is contacted when the model is built).
pub fn parse_umbridge_section(table: &toml::Table, file: &str) -> Result<UmBridgeSection> {
    if let Some(key) = table.keys().find(|k| !UMBRIDGE_KEYS.contains(&k.as_str())) {
        return Err(input_error(format!(
            "{file}: key `model.{key}`: unknown key for kind = \"umbridge\" (expected one of {})",
            UMBRIDGE_KEYS[1..].join(", ")
        )));
    }
    let string = |key: &str| -> Result<String> {
        let value = table.get(key).ok_or_else(|| {
            input_error(format!(
                "{file}: key `model.{key}`: missing (kind = \"umbridge\" needs `url` and `name`)"
            ))
        })?;
        match value.as_str() {
            Some(s) if !s.trim().is_empty() => Ok(s.to_string()),
            _ => Err(input_error(format!(
                "{file}: key `model.{key}`: expected a non-empty string"
            ))),
        }
    };
    let url = string("url")?;
    let name = string("name")?;
    let mut options = ClientOptions::default();
    if let Some(config) = table.get("config") {
        options.config = serde_json::to_value(config).map_err(|e| {
            input_error(format!(
                "{file}: key `model.config`: not JSON-compatible: {e}"
            ))
        })?;
    }
    if let Some(outputs) = table.get("outputs") {
        let names = outputs
            .as_array()
            .and_then(|a| {
                a.iter()
                    .map(|v| v.as_str().map(str::to_string))
                    .collect::<Option<Vec<_>>>()
            })
            .filter(|names| !names.is_empty())
            .ok_or_else(|| {
                input_error(format!(
                    "{file}: key `model.outputs`: expected a non-empty array of output names"
                ))
            })?;
        options.output_names = Some(names);
    }
    if let Some(flag) = table.get("computational_std") {
        options.std_output = flag.as_bool().ok_or_else(|| {
            input_error(format!(
                "{file}: key `model.computational_std`: expected true or false"
            ))
        })?;
    }
    let count = |key: &str, min: i64| -> Result<Option<i64>> {
        match table.get(key) {
            None => Ok(None),
            Some(v) => match v.as_integer() {
                Some(n) if n >= min && n <= 1024 => Ok(Some(n)),
                _ => Err(input_error(format!(
                    "{file}: key `model.{key}`: expected an integer from {min} to 1024"
                ))),
            },
        }
    };
    if let Some(n) = count("concurrency", 1)? {
        options.concurrency = n as usize;
    }
    if let Some(n) = count("retries", 0)? {
        options.retries = n as u32;
    }
    if let Some(v) = table.get("retry_delay") {
        options.retry_delay = positive_seconds(v, file, "retry_delay")?;
    }
    if let Some(v) = table.get("timeout") {
        options.read_timeout = Some(positive_seconds(v, file, "timeout")?);
    }
    if !url.starts_with("http://") {
        return Err(input_error(format!(
            "{file}: key `model.url`: `{url}` is not an http:// URL (UM-Bridge servers speak plain HTTP)"
        )));
    }
    Ok(UmBridgeSection { url, name, options })
}

/// Connects to the section's model for the study's parameters. A server that cannot be used
/// as configured (unknown model, sizes that do not fit, another protocol version) is an input
/// error naming the file; an unreachable server is a failure of the work.
pub fn connect(
    section: &UmBridgeSection,
    input_names: Vec<String>,
    file: &str,
) -> Result<UmBridgeModel> {
    UmBridgeModel::connect(
        &section.url,
        &section.name,
        input_names,
        section.options.clone(),
    )
    .map_err(|e| {
        if e.is_bad_input() {
            input_error(format!(
                "{file}: section `[model]` (kind = \"umbridge\"): {e}"
            ))
        } else {
            StudyError::from(e).context(format!("{file}: section `[model]` (kind = \"umbridge\")"))
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<UmBridgeSection> {
        let table: toml::Table = toml::from_str(text).unwrap();
        parse_umbridge_section(&table, "s.toml")
    }

    #[test]
    fn keys_are_read_and_checked() {
        let s = parse(
            r#"kind = "umbridge"
url = "http://localhost:4242"
name = "forward"
config = { level = 2, tags = ["a"] }
outputs = ["a", "b"]
computational_std = true
concurrency = 8
retries = 0
retry_delay = 0.5
timeout = 60"#,
        )
        .unwrap();
        assert_eq!(s.name, "forward");
        assert_eq!(
            s.options.config,
            serde_json::json!({"level": 2, "tags": ["a"]})
        );
        assert_eq!(s.options.output_names, Some(vec!["a".into(), "b".into()]));
        assert!(s.options.std_output);
        assert_eq!((s.options.concurrency, s.options.retries), (8, 0));
        assert_eq!(s.options.retry_delay, Duration::from_millis(500));
        assert_eq!(s.options.read_timeout, Some(Duration::from_secs(60)));
        let d = parse("kind = \"umbridge\"\nurl = \"http://h:1\"\nname = \"m\"").unwrap();
        assert_eq!(d.options.read_timeout, None);
        for (text, key) in [
            ("kind = \"umbridge\"\nname = \"m\"", "model.url"),
            ("kind = \"umbridge\"\nurl = \"http://h\"", "model.name"),
            (
                "kind = \"umbridge\"\nurl = \"h:1\"\nname = \"m\"",
                "model.url",
            ),
            (
                "kind = \"umbridge\"\nurl = \"http://h\"\nname = \"m\"\nconcurrency = 0",
                "model.concurrency",
            ),
            (
                "kind = \"umbridge\"\nurl = \"http://h\"\nname = \"m\"\ntimeout = -1",
                "model.timeout",
            ),
            (
                "kind = \"umbridge\"\nurl = \"http://h\"\nname = \"m\"\nport = 1",
                "model.port",
            ),
            (
                "kind = \"umbridge\"\nurl = \"http://h\"\nname = \"m\"\noutputs = []",
                "model.outputs",
            ),
        ] {
            let e = parse(text).unwrap_err();
            assert!(e.is_bad_input());
            let m = e.to_string();
            assert!(m.contains("s.toml") && m.contains(key), "{m}");
        }
    }
}
