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

use iuq_study_file::StudySection;

use crate::error::{Result, StudyError, input_error};

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

/// A number of seconds, at least 0 and below 10⁹.
fn seconds(s: &mut StudySection<'_>, key: &str) -> Result<Option<Duration>> {
    match s.number(key)? {
        None => Ok(None),
        Some(v) if (0.0..1e9).contains(&v) => Ok(Some(Duration::from_secs_f64(v))),
        Some(v) => Err(s
            .error(key, format!("expected a number of seconds ≥ 0, found {v}"))
            .into()),
    }
}

/// Parses the section (no network access: the server is contacted when the model is built).
pub fn parse_umbridge_section(table: &toml::Table, file: &str) -> Result<UmBridgeSection> {
    let mut s = StudySection::new(table, "model", file);
    s.allow(&["kind"]);
    let mut required = |key: &str| -> Result<String> {
        match s.string(key)? {
            Some(v) if !v.trim().is_empty() => Ok(v),
            Some(_) => Err(s.error(key, "expected a non-empty string").into()),
            None => Err(s
                .error(key, "missing (kind = \"umbridge\" needs `url` and `name`)")
                .into()),
        }
    };
    let url = required("url")?;
    let name = required("name")?;
    let mut options = ClientOptions::default();
    if let Some(config) = s.value("config") {
        options.config = serde_json::to_value(config)
            .map_err(|e| s.error("config", format!("not JSON-compatible: {e}")))?;
    }
    if let Some(names) = s.strings("outputs")? {
        if names.is_empty() {
            return Err(s
                .error("outputs", "expected a non-empty array of output names")
                .into());
        }
        options.output_names = Some(names);
    }
    if let Some(flag) = s.boolean("computational_std")? {
        options.std_output = flag;
    }
    let mut at_most_1024 = |key: &str, min: usize| -> Result<Option<usize>> {
        match s.count(key, min)? {
            Some(n) if n > 1024 => Err(s
                .error(
                    key,
                    format!("expected an integer from {min} to 1024, found {n}"),
                )
                .into()),
            other => Ok(other),
        }
    };
    if let Some(n) = at_most_1024("concurrency", 1)? {
        options.concurrency = n;
    }
    if let Some(n) = at_most_1024("retries", 0)? {
        options.retries = n as u32;
    }
    if let Some(delay) = seconds(&mut s, "retry_delay")? {
        options.retry_delay = delay;
    }
    if let Some(timeout) = seconds(&mut s, "timeout")? {
        options.read_timeout = Some(timeout);
    }
    s.finish()?;
    if !url.starts_with("http://") {
        return Err(s
            .error(
                "url",
                format!("`{url}` is not an http:// URL (UM-Bridge servers speak plain HTTP)"),
            )
            .into());
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
            .with_source(e)
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
