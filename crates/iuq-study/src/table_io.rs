//! Numeric CSV tables: reading with errors that name file, line and column, and atomic writing
//! (a temporary file renamed into place, so a crash never leaves a half-written result).
//! Every reading error is an input error naming the file.

use std::path::{Path, PathBuf};

use crate::error::{Context, Result, StudyError, input_error};

/// A table of named numeric columns, stored by rows.
#[derive(Debug, Clone, PartialEq)]
pub struct NumericTable {
    /// Column names from the header.
    pub columns: Vec<String>,
    /// Rows of values, one per data line.
    pub rows: Vec<Vec<f64>>,
}

impl NumericTable {
    /// Index of column `name`, or an input error naming the file and the columns it has.
    pub fn column_index(&self, name: &str, path: &Path) -> Result<usize> {
        self.columns.iter().position(|c| c == name).ok_or_else(|| {
            input_error(format!(
                "{}: no column `{name}` (columns: {})",
                path.display(),
                self.columns.join(", ")
            ))
        })
    }

    /// The values of the named columns, row by row.
    pub fn select(&self, names: &[String], path: &Path) -> Result<Vec<Vec<f64>>> {
        let idx = names
            .iter()
            .map(|n| self.column_index(n, path))
            .collect::<Result<Vec<_>>>()?;
        Ok(self
            .rows
            .iter()
            .map(|r| idx.iter().map(|&i| r[i]).collect())
            .collect())
    }
}

/// Read a CSV file with a header line and numeric cells. Lines starting with `#` are comments.
/// Empty cells and non-numbers are input errors naming the line and column; `nan` is accepted
/// only when `allow_nan` is set.
pub fn read_numeric_csv(path: &Path, allow_nan: bool) -> Result<NumericTable> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| input_error(format!("{}: cannot read: {e}", path.display())).with_source(e))?;
    let mut reader = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let columns: Vec<String> = reader
        .headers()
        .map_err(|e| input_error(format!("{}: bad header: {e}", path.display())).with_source(e))?
        .iter()
        .map(str::to_string)
        .collect();
    if columns.is_empty() || columns.iter().all(|c| c.is_empty()) {
        return Err(input_error(format!(
            "{}: the file has no header line",
            path.display()
        )));
    }
    let mut rows = Vec::new();
    for record in reader.records() {
        let record =
            record.map_err(|e| input_error(format!("{}: {e}", path.display())).with_source(e))?;
        let line = record.position().map_or(0, |p| p.line());
        if record.len() != columns.len() {
            return Err(input_error(format!(
                "{}: line {line} has {} cells but the header has {}",
                path.display(),
                record.len(),
                columns.len()
            )));
        }
        let row = record
            .iter()
            .zip(&columns)
            .map(|(cell, column)| {
                let v: f64 = cell.parse().map_err(|_| {
                    input_error(format!(
                        "{}: line {line}, column `{column}`: `{cell}` is not a number",
                        path.display()
                    ))
                })?;
                if !allow_nan && !v.is_finite() {
                    return Err(input_error(format!(
                        "{}: line {line}, column `{column}`: `{cell}` is not a finite number",
                        path.display()
                    )));
                }
                Ok(v)
            })
            .collect::<Result<Vec<f64>>>()?;
        rows.push(row);
    }
    Ok(NumericTable { columns, rows })
}

/// Write `contents` to `path` atomically: a temporary file in the same directory, renamed over
/// the target (iuq's one atomic writer, `iuq_atomic_file`). A missing directory is an
/// input error.
pub fn write_atomically(path: &Path, contents: &[u8]) -> Result<()> {
    let directory = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if !directory.is_dir() {
        return Err(input_error(format!(
            "{}: the directory {} does not exist",
            path.display(),
            directory.display()
        )));
    }
    if path.file_name().is_none() {
        return Err(input_error(format!("{}: not a file path", path.display())));
    }
    iuq_atomic_file::write_atomically(path, contents, iuq_atomic_file::Durability::Atomic).map_err(
        |source| {
            StudyError::failure(format!("cannot write {}: {source}", path.display()))
                .with_source(source)
        },
    )
}

/// Format a numeric table as CSV text (shortest round-trip representation of each value).
pub fn numeric_csv(columns: &[String], rows: &[Vec<f64>]) -> Result<Vec<u8>> {
    let mut writer = csv::Writer::from_writer(Vec::new());
    writer.write_record(columns)?;
    for row in rows {
        writer.write_record(row.iter().map(|v| format!("{v}")))?;
    }
    writer.into_inner().context("cannot format CSV")
}

/// Write a numeric table as CSV, atomically.
pub fn write_numeric_csv(path: &Path, columns: &[String], rows: &[Vec<f64>]) -> Result<()> {
    write_atomically(path, &numeric_csv(columns, rows)?)
}
