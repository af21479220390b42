//! Library errors as Python exceptions: bad input is a `ValueError` (the message names the
//! argument and the reason), failed work a `RuntimeError`.

use pyo3::PyErr;
use pyo3::exceptions::{PyRuntimeError, PyValueError};

/// A `ValueError` whose message is `argument: reason`.
pub fn bad_input(argument: &str, reason: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(format!("{argument}: {reason}"))
}

/// A `RuntimeError` for work that failed: `what: reason`.
pub fn failure(what: &str, reason: impl std::fmt::Display) -> PyErr {
    PyRuntimeError::new_err(format!("{what}: {reason}"))
}

/// A study-layer error: bad input is a `ValueError`, anything else a `RuntimeError`.
pub fn study_error(error: iuq_study::StudyError) -> PyErr {
    if error.is_bad_input() {
        PyValueError::new_err(error.message().to_string())
    } else {
        PyRuntimeError::new_err(error.message().to_string())
    }
}
