//! Space-filling designs, as `iuq design lhs|sobol|saltelli` builds them (same library calls,
//! same seeds, same scaling to bounds).

use numpy::PyArray2;
use pyo3::prelude::*;

use iuq_doe::{
    LhsMethod, SaltelliDesign, Scrambling, latin_hypercube, scale_to_bounds, sobol_points,
};

use crate::arrays::{check_bounds, rows_to_array};
use crate::errors::bad_input;

fn check_size(n: usize, dim: usize) -> PyResult<()> {
    if n == 0 {
        return Err(bad_input("n", "must be at least 1"));
    }
    if dim == 0 {
        return Err(bad_input("dim", "must be at least 1"));
    }
    Ok(())
}

fn scrambling(seed: u64, scramble: bool) -> Scrambling {
    if scramble {
        Scrambling::LinearMatrixWithShift { seed, replicate: 0 }
    } else {
        Scrambling::None
    }
}

fn finish<'py>(
    py: Python<'py>,
    unit: Vec<Vec<f64>>,
    dim: usize,
    bounds: Option<Vec<(f64, f64)>>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let rows = match bounds {
        Some(b) => {
            check_bounds("bounds", &b, dim)?;
            scale_to_bounds(&unit, &b).map_err(|e| bad_input("bounds", e))?
        }
        None => unit,
    };
    rows_to_array(py, &rows, dim)
}

/// Latin hypercube of `n` points in `dim` dimensions (`iuq design lhs`).
#[pyfunction]
#[pyo3(signature = (n, dim, seed = 0, method = "maximin", candidates = iuq_doe::DEFAULT_MAXIMIN_CANDIDATES, bounds = None))]
pub fn lhs<'py>(
    py: Python<'py>,
    n: usize,
    dim: usize,
    seed: u64,
    method: &str,
    candidates: usize,
    bounds: Option<Vec<(f64, f64)>>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    check_size(n, dim)?;
    let method = match method {
        "maximin" => {
            if candidates == 0 {
                return Err(bad_input("candidates", "must be at least 1"));
            }
            LhsMethod::Maximin { candidates }
        }
        "optimized" => LhsMethod::optimized(),
        "random" => LhsMethod::Random,
        other => {
            return Err(bad_input(
                "method",
                format!("`{other}` is not one of maximin, optimized, random"),
            ));
        }
    };
    let unit = py
        .allow_threads(|| latin_hypercube(n, dim, method, seed))
        .map_err(|e| bad_input("design", e))?;
    finish(py, unit, dim, bounds)
}

/// The first `n` points of a Sobol' sequence (`iuq design sobol`), scrambled unless
/// `scramble` is false.
#[pyfunction]
#[pyo3(signature = (n, dim, seed = 0, scramble = true, bounds = None))]
pub fn sobol<'py>(
    py: Python<'py>,
    n: usize,
    dim: usize,
    seed: u64,
    scramble: bool,
    bounds: Option<Vec<(f64, f64)>>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    check_size(n, dim)?;
    let unit = py
        .allow_threads(|| sobol_points(dim, n, scrambling(seed, scramble)))
        .map_err(|e| bad_input("design", e))?;
    finish(py, unit, dim, bounds)
}

/// The Saltelli design of `n` base points (`iuq design saltelli`): n(dim + 2) rows grouped per
/// base point as A_j, AB_1j … AB_dj, B_j.
#[pyfunction]
#[pyo3(signature = (n, dim, seed = 0, scramble = true, bounds = None))]
pub fn saltelli<'py>(
    py: Python<'py>,
    n: usize,
    dim: usize,
    seed: u64,
    scramble: bool,
    bounds: Option<Vec<(f64, f64)>>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    check_size(n, dim)?;
    let unit = py
        .allow_threads(|| SaltelliDesign::new(n, dim, scrambling(seed, scramble)).map(|d| d.rows()))
        .map_err(|e| bad_input("design", e))?;
    finish(py, unit, dim, bounds)
}
