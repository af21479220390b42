//! Output decoders: how the outputs of one run are read from the file its command wrote.
//!
//! | study file | outputs |
//! |---|---|
//! | `output = { file = "result.json", format = "json" }` | the top-level keys named as the outputs (`keys = { f = "/a/0/b" }` gives JSON pointers instead); a value is a number, or `{ "value": v, "std": s }` with a computational std |
//! | `output = { file = "result.json", format = "json", array = "/T" }` | one JSON array (at a pointer) holds the outputs in order, exactly as many as there are outputs; its elements as above |
//! | `output = { file = "out.csv", format = "csv" }` | the columns named as the outputs, in one row (`row = "last"` (default), `"first"` or a 0-based index) |
//! | `output = { file = "out.csv", format = "csv", column = "el" }` | the values of one column, row by row: output k is row k |
//! | `output = { file = "log.txt", format = "regex", patterns = { el = 'EL = (\S+)' } }` | per output, the first capture group of the last match |
//! | `output = { file = "log.txt", format = "regex", pattern = 'EL=(?P<el>\S+)' }` | one pattern, a named group per output, last match |
//!
//! A missing file, text that does not decode and a non-finite value are failures of the run with
//! a reason ([`OutcomeKind::MissingOutput`], [`OutcomeKind::BadOutput`],
//! [`OutcomeKind::NonFinite`]), never errors of the campaign.

use std::path::Path;

use regex::Regex;
use serde::{Deserialize, Serialize};

use crate::outcome::OutcomeKind;

/// Which row of a CSV file holds the outputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CsvRow {
    /// The first data row.
    First,
    /// The last data row.
    Last,
    /// The data row with this 0-based index.
    Index(usize),
}

/// How outputs are found in the output file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DecoderFormat {
    /// A JSON document: per output a JSON pointer (`/f` for a top-level key `f`).
    Json {
        /// One JSON pointer per output.
        pointers: Vec<String>,
    },
    /// A JSON document with one array (at a JSON pointer) holding every output, in order.
    JsonArray {
        /// The array's JSON pointer.
        pointer: String,
    },
    /// A CSV file with a header: per output a column, in one row.
    CsvColumns {
        /// The row.
        row: CsvRow,
    },
    /// A CSV file with a header: the outputs are the values of one column, row by row.
    CsvColumn {
        /// The column's name.
        column: String,
    },
    /// A text file: per output a regular expression whose first capture group (or the group
    /// named as the output) is the value; the last match counts.
    Regex {
        /// One pattern per output.
        patterns: Vec<String>,
    },
}

/// Where and how the outputs of a run are read.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DecoderSpec {
    /// The output file, relative to the run directory.
    pub file: String,
    /// How it is decoded.
    pub format: DecoderFormat,
}

/// The words every reason of an array whose length is not the number of outputs begins with, so
/// that a caller can tell a study that declares the wrong length (an input error) from a run that
/// failed.
pub const ARRAY_LENGTH_MISMATCH: &str = "array length mismatch";

/// A failure to decode: its kind and reason.
pub type DecodeFailure = (OutcomeKind, String);

/// A decoder ready to use (regular expressions compiled).
#[derive(Debug, Clone)]
pub struct OutputDecoder {
    spec: DecoderSpec,
    outputs: Vec<String>,
    regexes: Vec<Regex>,
}

/// The decoded outputs of one run, and their stds when the file gave one for any output (0 for
/// the outputs without one).
pub type Decoded = (Vec<f64>, Option<Vec<f64>>);

impl OutputDecoder {
    /// Compile `spec` for the named outputs; the error is the reason a pattern is unusable.
    pub fn new(spec: DecoderSpec, outputs: Vec<String>) -> Result<Self, String> {
        let regexes = match &spec.format {
            DecoderFormat::Regex { patterns } => {
                if patterns.len() != outputs.len() {
                    return Err(format!(
                        "{} patterns for {} outputs",
                        patterns.len(),
                        outputs.len()
                    ));
                }
                patterns
                    .iter()
                    .zip(&outputs)
                    .map(|(p, name)| {
                        let re = Regex::new(p).map_err(|e| format!("pattern of `{name}`: {e}"))?;
                        if re.captures_len() < 2 {
                            return Err(format!(
                                "pattern of `{name}` `{p}` has no capture group for the value"
                            ));
                        }
                        Ok(re)
                    })
                    .collect::<Result<Vec<_>, String>>()?
            }
            DecoderFormat::Json { pointers } if pointers.len() != outputs.len() => {
                return Err(format!(
                    "{} JSON keys for {} outputs",
                    pointers.len(),
                    outputs.len()
                ));
            }
            _ => Vec::new(),
        };
        Ok(Self {
            spec,
            outputs,
            regexes,
        })
    }

    /// The specification.
    pub fn spec(&self) -> &DecoderSpec {
        &self.spec
    }

    /// Decode the outputs of the run in `run_dir`.
    pub fn decode(&self, run_dir: &Path) -> Result<Decoded, DecodeFailure> {
        let path = run_dir.join(&self.spec.file);
        let text = match std::fs::read(&path) {
            Ok(bytes) => String::from_utf8_lossy(&bytes).into_owned(),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err((
                    OutcomeKind::MissingOutput,
                    format!("output file `{}` was not written", self.spec.file),
                ));
            }
            Err(e) => {
                return Err((
                    OutcomeKind::MissingOutput,
                    format!("output file `{}` cannot be read: {e}", self.spec.file),
                ));
            }
        };
        let (values, std) = self.decode_text(&text)?;
        check_finite(&self.outputs, &values, std.as_deref(), &self.spec.file)?;
        Ok((values, std))
    }

    fn bad(&self, reason: impl std::fmt::Display) -> DecodeFailure {
        (
            OutcomeKind::BadOutput,
            format!("output file `{}`: {reason}", self.spec.file),
        )
    }

    fn decode_text(&self, text: &str) -> Result<Decoded, DecodeFailure> {
        match &self.spec.format {
            DecoderFormat::Json { pointers } => {
                let doc: serde_json::Value = serde_json::from_str(text)
                    .map_err(|e| self.bad(format!("not valid JSON ({e})")))?;
                let mut values = Vec::with_capacity(pointers.len());
                let mut stds = Vec::with_capacity(pointers.len());
                for (pointer, name) in pointers.iter().zip(&self.outputs) {
                    let v = doc
                        .pointer(pointer)
                        .ok_or_else(|| self.bad(format!("no value at `{pointer}` for `{name}`")))?;
                    let (value, std) = json_number(v).ok_or_else(|| {
                        self.bad(format!(
                            "`{name}` is `{v}`, not a number or {{\"value\": …, \"std\": …}}"
                        ))
                    })?;
                    values.push(value);
                    stds.push(std);
                }
                // Stds when the run gave one for any output; an output without one (a diagnostic
                // such as a drift) has no computational uncertainty stated: 0.
                let std = stds
                    .iter()
                    .any(Option::is_some)
                    .then(|| stds.into_iter().map(|s| s.unwrap_or(0.0)).collect());
                Ok((values, std))
            }
            DecoderFormat::JsonArray { pointer } => {
                let doc: serde_json::Value = serde_json::from_str(text)
                    .map_err(|e| self.bad(format!("not valid JSON ({e})")))?;
                let items = doc
                    .pointer(pointer)
                    .ok_or_else(|| self.bad(format!("no value at `{pointer}`")))?
                    .as_array()
                    .ok_or_else(|| self.bad(format!("the value at `{pointer}` is not an array")))?;
                if items.len() != self.outputs.len() {
                    return Err(self.bad(format!(
                        "{ARRAY_LENGTH_MISMATCH}: the array at `{pointer}` has {} values for {} outputs",
                        items.len(),
                        self.outputs.len()
                    )));
                }
                let mut values = Vec::with_capacity(items.len());
                let mut stds = Vec::with_capacity(items.len());
                for (i, v) in items.iter().enumerate() {
                    let (value, std) = json_number(v).ok_or_else(|| {
                        self.bad(format!(
                            "`{pointer}/{i}` is `{v}`, not a number or {{\"value\": …, \"std\": …}}"
                        ))
                    })?;
                    values.push(value);
                    stds.push(std);
                }
                let std = stds
                    .iter()
                    .any(Option::is_some)
                    .then(|| stds.into_iter().map(|s| s.unwrap_or(0.0)).collect());
                Ok((values, std))
            }
            DecoderFormat::CsvColumns { row } => {
                let (header, rows) = self.read_csv(text)?;
                let chosen = match row {
                    CsvRow::First => rows.first(),
                    CsvRow::Last => rows.last(),
                    CsvRow::Index(i) => rows.get(*i),
                }
                .ok_or_else(|| self.bad(format!("no data row {row:?} ({} rows)", rows.len())))?;
                let values = self
                    .outputs
                    .iter()
                    .map(|name| {
                        let k = header.iter().position(|h| h == name).ok_or_else(|| {
                            self.bad(format!(
                                "no column `{name}` (columns: {})",
                                header.join(", ")
                            ))
                        })?;
                        parse_cell(chosen.get(k).map_or("", String::as_str)).ok_or_else(|| {
                            self.bad(format!(
                                "column `{name}`: `{}` is not a number",
                                chosen.get(k).map_or("", String::as_str)
                            ))
                        })
                    })
                    .collect::<Result<Vec<f64>, _>>()?;
                Ok((values, None))
            }
            DecoderFormat::CsvColumn { column } => {
                let (header, rows) = self.read_csv(text)?;
                let k = header.iter().position(|h| h == column).ok_or_else(|| {
                    self.bad(format!(
                        "no column `{column}` (columns: {})",
                        header.join(", ")
                    ))
                })?;
                if rows.len() != self.outputs.len() {
                    return Err(self.bad(format!(
                        "{ARRAY_LENGTH_MISMATCH}: column `{column}` has {} values for {} outputs",
                        rows.len(),
                        self.outputs.len()
                    )));
                }
                let values = rows
                    .iter()
                    .enumerate()
                    .map(|(i, r)| {
                        let cell = r.get(k).map_or("", String::as_str);
                        parse_cell(cell).ok_or_else(|| {
                            self.bad(format!(
                                "column `{column}`, row {i}: `{cell}` is not a number"
                            ))
                        })
                    })
                    .collect::<Result<Vec<f64>, _>>()?;
                Ok((values, None))
            }
            DecoderFormat::Regex { .. } => {
                let values = self
                    .regexes
                    .iter()
                    .zip(&self.outputs)
                    .map(|(re, name)| {
                        let caps = re.captures_iter(text).last().ok_or_else(|| {
                            self.bad(format!("no match of `{}` for `{name}`", re.as_str()))
                        })?;
                        let m = caps
                            .name(name)
                            .or_else(|| caps.get(1))
                            .map_or("", |m| m.as_str());
                        parse_cell(m).ok_or_else(|| {
                            self.bad(format!("`{name}`: matched `{m}`, not a number"))
                        })
                    })
                    .collect::<Result<Vec<f64>, _>>()?;
                Ok((values, None))
            }
        }
    }

    fn read_csv(&self, text: &str) -> Result<(Vec<String>, Vec<Vec<String>>), DecodeFailure> {
        read_csv_text(text).map_err(|e| self.bad(e))
    }
}

/// Parse CSV text with a header line (cells trimmed, `#` comment lines skipped).
pub fn read_csv_text(text: &str) -> Result<(Vec<String>, Vec<Vec<String>>), String> {
    let mut reader = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .trim(csv::Trim::All)
        .flexible(true)
        .from_reader(text.as_bytes());
    let header: Vec<String> = reader
        .headers()
        .map_err(|e| format!("not valid CSV ({e})"))?
        .iter()
        .map(str::to_string)
        .collect();
    if header.iter().all(String::is_empty) {
        return Err("empty: no header line".into());
    }
    let mut rows = Vec::new();
    for record in reader.records() {
        let record = record.map_err(|e| format!("not valid CSV ({e})"))?;
        rows.push(record.iter().map(str::to_string).collect());
    }
    Ok((header, rows))
}

/// A cell as a number: `nan`, `inf` are accepted here and rejected by the finiteness check, so
/// that the reason says "not finite".
pub fn parse_cell(cell: &str) -> Option<f64> {
    cell.trim().parse::<f64>().ok()
}

fn json_number(v: &serde_json::Value) -> Option<(f64, Option<f64>)> {
    match v {
        serde_json::Value::Number(n) => n.as_f64().map(|x| (x, None)),
        // NaN and infinities are not JSON numbers; simulators write them as strings.
        serde_json::Value::String(s) => parse_cell(s).map(|x| (x, None)),
        serde_json::Value::Object(o) => {
            let value = json_number(o.get("value")?)?.0;
            let std = match o.get("std") {
                Some(s) => Some(json_number(s)?.0),
                None => None,
            };
            Some((value, std))
        }
        _ => None,
    }
}

/// A non-finite output (or std) is a failure naming the output.
pub fn check_finite(
    names: &[String],
    values: &[f64],
    std: Option<&[f64]>,
    file: &str,
) -> Result<(), DecodeFailure> {
    for (name, v) in names.iter().zip(values) {
        if !v.is_finite() {
            return Err((
                OutcomeKind::NonFinite,
                format!("output `{name}` in `{file}` is not finite ({v})"),
            ));
        }
    }
    if let Some(std) = std {
        for (name, s) in names.iter().zip(std) {
            if !s.is_finite() || *s < 0.0 {
                return Err((
                    OutcomeKind::NonFinite,
                    format!(
                        "std of output `{name}` in `{file}` is not a finite non-negative number ({s})"
                    ),
                ));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(n: &[&str]) -> Vec<String> {
        n.iter().map(|s| s.to_string()).collect()
    }

    fn decoder(format: DecoderFormat, outputs: &[&str]) -> OutputDecoder {
        OutputDecoder::new(
            DecoderSpec {
                file: "out".into(),
                format,
            },
            names(outputs),
        )
        .unwrap()
    }

    #[test]
    fn json_values_pointers_and_stds() {
        let d = decoder(
            DecoderFormat::Json {
                pointers: vec!["/f".into(), "/nested/0/g".into()],
            },
            &["f", "g"],
        );
        let (v, s) = d
            .decode_text(r#"{"f": 1.5, "nested": [{"g": -2}]}"#)
            .unwrap();
        assert_eq!(v, vec![1.5, -2.0]);
        assert!(s.is_none());
        let (v, s) = d
            .decode_text(
                r#"{"f": {"value": 1, "std": 0.1}, "nested": [{"g": {"value": 2, "std": 0.2}}]}"#,
            )
            .unwrap();
        assert_eq!((v, s), (vec![1.0, 2.0], Some(vec![0.1, 0.2])));
        // A std for one output and none for a diagnostic beside it: the first std is kept.
        let (v, s) = d
            .decode_text(r#"{"f": {"value": 1, "std": 0.1}, "nested": [{"g": 0.5}]}"#)
            .unwrap();
        assert_eq!((v, s), (vec![1.0, 0.5], Some(vec![0.1, 0.0])));
        let e = d.decode_text("garbage").unwrap_err();
        assert_eq!(e.0, OutcomeKind::BadOutput);
        let e = d.decode_text(r#"{"f": 1}"#).unwrap_err();
        assert!(e.1.contains("/nested/0/g"), "{}", e.1);
    }

    #[test]
    fn csv_columns_rows_and_one_column() {
        let text = "t,el,area\n0,0.1,5\n1,0.2,6\n2,0.3,7\n";
        let d = decoder(
            DecoderFormat::CsvColumns { row: CsvRow::Last },
            &["el", "area"],
        );
        assert_eq!(d.decode_text(text).unwrap().0, vec![0.3, 7.0]);
        let d = decoder(
            DecoderFormat::CsvColumns {
                row: CsvRow::Index(1),
            },
            &["el"],
        );
        assert_eq!(d.decode_text(text).unwrap().0, vec![0.2]);
        let d = decoder(
            DecoderFormat::CsvColumn {
                column: "el".into(),
            },
            &["el0", "el1", "el2"],
        );
        assert_eq!(d.decode_text(text).unwrap().0, vec![0.1, 0.2, 0.3]);
        let d = decoder(DecoderFormat::CsvColumns { row: CsvRow::Last }, &["nope"]);
        assert!(
            d.decode_text(text)
                .unwrap_err()
                .1
                .contains("no column `nope`")
        );
    }

    #[test]
    fn regex_last_match_and_named_groups() {
        let text = "step 1 EL = 0.1\nstep 2 EL = 0.25\ndone area=3e2";
        let d = decoder(
            DecoderFormat::Regex {
                patterns: vec![r"EL = (\S+)".into(), r"area=(?P<area>\S+)".into()],
            },
            &["el", "area"],
        );
        assert_eq!(d.decode_text(text).unwrap().0, vec![0.25, 300.0]);
        assert!(
            OutputDecoder::new(
                DecoderSpec {
                    file: "x".into(),
                    format: DecoderFormat::Regex {
                        patterns: vec!["no group".into()]
                    }
                },
                names(&["a"])
            )
            .is_err()
        );
    }

    #[test]
    fn missing_and_non_finite_outputs_are_failures() {
        let dir = std::env::temp_dir().join(format!("iuq-decoder-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let d = OutputDecoder::new(
            DecoderSpec {
                file: "r.json".into(),
                format: DecoderFormat::Json {
                    pointers: vec!["/f".into()],
                },
            },
            names(&["f"]),
        )
        .unwrap();
        let _ = std::fs::remove_file(dir.join("r.json"));
        assert_eq!(d.decode(&dir).unwrap_err().0, OutcomeKind::MissingOutput);
        std::fs::write(dir.join("r.json"), r#"{"f": "NaN"}"#).unwrap();
        let e = d.decode(&dir).unwrap_err();
        assert_eq!(e.0, OutcomeKind::NonFinite);
        assert!(e.1.contains("`f`"));
        std::fs::write(dir.join("r.json"), r#"{"f": 2}"#).unwrap();
        assert_eq!(d.decode(&dir).unwrap().0, vec![2.0]);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
