//! Conversions between numpy arrays and the row-major `Vec<Vec<f64>>` points of the libraries.

use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

use crate::errors::bad_input;

/// Rows of `columns` values each as an (n, columns) `float64` array.
pub fn rows_to_array<'py>(
    py: Python<'py>,
    rows: &[Vec<f64>],
    columns: usize,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let mut flat = Vec::with_capacity(rows.len() * columns);
    for (i, row) in rows.iter().enumerate() {
        if row.len() != columns {
            return Err(bad_input(
                "rows",
                format!("row {i} has {} values, expected {columns}", row.len()),
            ));
        }
        flat.extend_from_slice(row);
    }
    let array =
        Array2::from_shape_vec((rows.len(), columns), flat).map_err(|e| bad_input("rows", e))?;
    Ok(array.into_pyarray(py))
}

/// A vector as a 1-D `float64` array.
pub fn vec_to_array<'py>(py: Python<'py>, values: Vec<f64>) -> Bound<'py, PyArray1<f64>> {
    values.into_pyarray(py)
}

/// The rows of a 2-D array.
pub fn array_rows(x: &PyReadonlyArray2<'_, f64>) -> Vec<Vec<f64>> {
    x.as_array().outer_iter().map(|r| r.to_vec()).collect()
}

/// The values of a 1-D array.
pub fn array_values(y: &PyReadonlyArray1<'_, f64>) -> Vec<f64> {
    y.as_array().to_vec()
}

/// Check `(lo, hi)` pairs as the CLI's `--bounds` does: one per dimension, finite, lo < hi.
pub fn check_bounds(argument: &str, bounds: &[(f64, f64)], dim: usize) -> PyResult<()> {
    if bounds.len() != dim {
        return Err(bad_input(
            argument,
            format!("{} ranges given for {dim} dimensions", bounds.len()),
        ));
    }
    for (k, (lo, hi)) in bounds.iter().enumerate() {
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(bad_input(
                argument,
                format!("range {k} must have finite lo < hi, got ({lo}, {hi})"),
            ));
        }
    }
    Ok(())
}
