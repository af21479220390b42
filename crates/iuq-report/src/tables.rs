//! The report's tables: one model for all of them, written as CSV and JSON files and rendered
//! into the HTML page.
//!
//! A numeric cell keeps its exact value and a JSON pointer to where that value lives in
//! `report.json`, so the page can show a formatted number while carrying the exact one.

use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

use crate::error::{ReportError, Result};

/// One cell of a table.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Cell {
    /// Text (a name, a label).
    Text(String),
    /// A number and the JSON pointer of its value in `report.json`.
    Number {
        /// The exact value.
        value: f64,
        /// JSON pointer into `report.json`, e.g. `/report/posteriors/0/summary/1/mean`.
        pointer: String,
    },
    /// No value (e.g. a hyper-parameter one output's GP does not have).
    Empty,
}

impl Cell {
    /// A text cell.
    pub(crate) fn text(text: impl Into<String>) -> Self {
        Self::Text(text.into())
    }

    /// A numeric cell whose value sits at `pointer` in `report.json`.
    pub(crate) fn number(value: f64, pointer: impl Into<String>) -> Self {
        Self::Number {
            value,
            pointer: pointer.into(),
        }
    }

    /// A numeric cell, or "–" where there is no value (an undefined ratio).
    pub(crate) fn optional(value: Option<f64>, pointer: impl Into<String>) -> Self {
        match value {
            Some(value) => Self::number(value, pointer),
            None => Self::text("–"),
        }
    }

    /// A numeric cell for a count.
    pub(crate) fn count(value: usize, pointer: impl Into<String>) -> Self {
        Self::number(value as f64, pointer)
    }

    /// The cell as a JSON value (numbers as numbers, counts as integers).
    fn to_json(&self) -> Value {
        match self {
            Cell::Text(text) => Value::String(text.clone()),
            Cell::Number { value, .. } if value.fract() == 0.0 && value.abs() < 9e15 => {
                Value::from(*value as i64)
            }
            Cell::Number { value, .. } => Value::from(*value),
            Cell::Empty => Value::Null,
        }
    }

    /// The cell as CSV text (numbers in Rust's shortest round-trip form).
    fn to_csv(&self) -> String {
        match self {
            Cell::Text(text) => text.clone(),
            Cell::Number { value, .. } => value.to_string(),
            Cell::Empty => String::new(),
        }
    }
}

/// A column: its header and, optionally, the group it belongs to (a source, shown as a spanning
/// header row in HTML and as a prefix in CSV).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Column {
    /// Header text, e.g. "mean".
    pub header: String,
    /// Column group, e.g. "GP surrogate".
    pub group: Option<String>,
}

impl Column {
    /// A column without a group.
    pub(crate) fn plain(header: impl Into<String>) -> Self {
        Self {
            header: header.into(),
            group: None,
        }
    }

    /// A column in `group`.
    pub(crate) fn grouped(group: impl Into<String>, header: impl Into<String>) -> Self {
        Self {
            header: header.into(),
            group: Some(group.into()),
        }
    }

    /// The column's name in CSV and JSON: "group header" or "header".
    pub(crate) fn key(&self) -> String {
        match &self.group {
            Some(group) => format!("{group} {}", self.header),
            None => self.header.clone(),
        }
    }
}

/// A table of the report.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Table {
    /// File stem in `tables/`, e.g. `posterior_summary`.
    pub name: String,
    /// Title shown above the table.
    pub title: String,
    /// The columns.
    pub columns: Vec<Column>,
    /// The rows, each as long as `columns`.
    pub rows: Vec<Vec<Cell>>,
}

/// What the report says about one table: its name, title and files.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TableInfo {
    /// File stem, e.g. `posterior_summary`.
    pub name: String,
    /// Title shown above the table.
    pub title: String,
    /// Path of the CSV file relative to the report directory.
    pub csv: String,
    /// Path of the JSON file relative to the report directory.
    pub json: String,
}

impl Table {
    /// The table's description for `report.json`.
    pub(crate) fn info(&self) -> TableInfo {
        TableInfo {
            name: self.name.clone(),
            title: self.title.clone(),
            csv: format!("tables/{}.csv", self.name),
            json: format!("tables/{}.json", self.name),
        }
    }

    /// The table as CSV: one header row of column keys, then the rows.
    pub(crate) fn to_csv(&self) -> Result<Vec<u8>> {
        let csv_error = |source| ReportError::Csv {
            table: self.name.clone(),
            source,
        };
        let mut writer = csv::Writer::from_writer(Vec::new());
        writer
            .write_record(self.columns.iter().map(Column::key))
            .map_err(csv_error)?;
        for row in &self.rows {
            writer
                .write_record(row.iter().map(Cell::to_csv))
                .map_err(csv_error)?;
        }
        writer.into_inner().map_err(|e| ReportError::Io {
            path: format!("tables/{}.csv", self.name).into(),
            source: e.into_error(),
        })
    }

    /// The table as JSON: `{"name", "title", "columns", "rows"}` with each row an object keyed by
    /// the column keys.
    pub(crate) fn to_json(&self) -> Result<Vec<u8>> {
        let keys: Vec<String> = self.columns.iter().map(Column::key).collect();
        let rows: Vec<Value> = self
            .rows
            .iter()
            .map(|row| {
                let object: Map<String, Value> = keys
                    .iter()
                    .cloned()
                    .zip(row.iter().map(Cell::to_json))
                    .collect();
                Value::Object(object)
            })
            .collect();
        let document = serde_json::json!({
            "name": self.name,
            "title": self.title,
            "columns": keys,
            "rows": rows,
        });
        serde_json::to_vec_pretty(&document).map_err(|source| ReportError::Json {
            what: format!("table {}", self.name),
            source,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table() -> Table {
        Table {
            name: "t".into(),
            title: "T".into(),
            columns: vec![Column::plain("parameter"), Column::grouped("GP", "mean")],
            rows: vec![vec![Cell::text("kLink"), Cell::number(0.1, "/x")]],
        }
    }

    #[test]
    fn csv_has_grouped_headers_and_exact_numbers() {
        let csv = String::from_utf8(table().to_csv().unwrap()).unwrap();
        assert_eq!(csv, "parameter,GP mean\nkLink,0.1\n");
    }

    #[test]
    fn json_rows_are_keyed_by_column() {
        let json: Value = serde_json::from_slice(&table().to_json().unwrap()).unwrap();
        assert_eq!(json["rows"][0]["GP mean"], 0.1);
        assert_eq!(json["rows"][0]["parameter"], "kLink");
    }
}
