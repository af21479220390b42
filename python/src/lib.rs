//! `iuq._native`: the Rust side of the `iuq` Python package.
//!
//! The functions here take and return contiguous `float64` numpy arrays and plain Python values;
//! the pure-Python modules of the package (`python/iuq/`) check and convert the user's arguments,
//! name them in errors, and wrap the results in documented objects. Every computation calls the
//! same library functions as the `iuq` command line, so a result for a given seed equals the
//! CLI's bit for bit. Rust work runs with the GIL released; a Python callable (a model or a
//! log-likelihood) is called with the GIL held, one 2-D array per batch (see the module `callable`).

#![warn(missing_docs)]
// No panic reachable from Python: every failure becomes a Python exception.
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

use pyo3::prelude::*;

mod arrays;
mod basis;
mod calibrate;
mod callable;
mod design;
mod errors;
mod gp;
mod progress;
mod sensitivity;
mod study;

/// The extension module `iuq._native`.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(design::lhs, m)?)?;
    m.add_function(wrap_pyfunction!(design::sobol, m)?)?;
    m.add_function(wrap_pyfunction!(design::saltelli, m)?)?;
    m.add_function(wrap_pyfunction!(sensitivity::sobol_indices, m)?)?;
    m.add_function(wrap_pyfunction!(basis::basis, m)?)?;
    m.add_class::<gp::NativeGaussianProcess>()?;
    m.add_class::<study::NativeStudy>()?;
    Ok(())
}
