//! Python callables as a [`Model`] or a [`LogLikelihood`] of the libraries.
//!
//! The libraries hand a whole batch of parameter vectors to a model (one Saltelli design, one
//! BASIS stage); the callable receives it as one (n, d) `float64` array, with the GIL taken for
//! the call only (the Rust work around it runs with the GIL released). Its result is checked:
//! shape (n,) or (n, m) — for a model also a pair `(values, std)` of such arrays, the second the
//! computational standard deviation of each output — and any other shape is a `ValueError`.
//! Non-finite values are failed points (a model) or rejections (a log-likelihood), as for every
//! model of iuq.
//!
//! When the callable raises, [`OnError::Raise`] stops the computation and the caller re-raises
//! the callable's own exception (kept in [`Callable::take_error`]); with [`OnError::Fail`] the
//! batch is evaluated again point by point and every point whose call raises becomes a failed
//! point whose reason is the exception's text (BASIS rejects it, the Sobol' estimator drops
//! its group). A `KeyboardInterrupt` and a result of the wrong shape always stop.

use std::sync::Mutex;

use numpy::PyUntypedArrayMethods;
use numpy::{PyArrayDyn, PyArrayMethods};
use pyo3::exceptions::{PyKeyboardInterrupt, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyTuple;

use iuq_basis::{BasisError, LogLikelihood, PointLogLikelihood};
use iuq_core::model::reject_non_finite;
use iuq_core::{CoreError, Evaluation, EvaluationFailure, Model, Outcome};

use crate::arrays::rows_to_array;
use crate::errors::bad_input;

/// What to do when the Python callable raises.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OnError {
    /// Stop and re-raise the exception.
    Raise,
    /// Evaluate the batch point by point; points whose call raises are failed points.
    Fail,
}

impl OnError {
    /// Parse the `on_error` argument.
    pub fn parse(text: &str) -> PyResult<Self> {
        match text {
            "raise" => Ok(Self::Raise),
            "fail" => Ok(Self::Fail),
            other => Err(bad_input(
                "on_error",
                format!("`{other}` is not one of raise, fail"),
            )),
        }
    }
}

/// Why a call gave no usable result.
enum CallError {
    /// The callable raised (a failed point when failures are allowed).
    Raised(PyErr),
    /// The result broke the contract (wrong shape, not numbers) or the user interrupted: stop.
    Fatal(PyErr),
}

/// Values of one call: (n, m) values and, optionally, (n, m) computational stds.
struct CallResult {
    values: Vec<Vec<f64>>,
    std: Option<Vec<Vec<f64>>>,
}

/// A Python callable with the bookkeeping of its errors.
pub struct Callable {
    function: Py<PyAny>,
    dimension: usize,
    /// Number of values per point; `None` for a log-likelihood (exactly one, shape (n,)).
    outputs: Option<usize>,
    on_error: OnError,
    error: Mutex<Option<PyErr>>,
    what: &'static str,
}

fn to_matrix(
    py: Python<'_>,
    value: &Bound<'_, PyAny>,
    n: usize,
    m: Option<usize>,
    what: &str,
) -> Result<Vec<Vec<f64>>, CallError> {
    let fatal =
        |reason: String| CallError::Fatal(PyValueError::new_err(format!("{what}: {reason}")));
    let numpy = py.import("numpy").map_err(CallError::Fatal)?;
    let array = numpy
        .call_method1("asarray", (value, "float64"))
        .map_err(|e| fatal(format!("the result is not an array of numbers ({e})")))?;
    let array = array
        .downcast::<PyArrayDyn<f64>>()
        .map_err(|e| fatal(format!("the result is not an array of numbers ({e})")))?;
    let shape = array.shape().to_vec();
    let columns = match (shape.as_slice(), m) {
        ([rows], None | Some(1)) if *rows == n => 1,
        ([rows, cols], Some(m)) if *rows == n && *cols == m => m,
        _ => {
            let expected = match m {
                None => format!("({n},)"),
                Some(1) => format!("({n},) or ({n}, 1)"),
                Some(m) => format!("({n}, {m})"),
            };
            return Err(fatal(format!(
                "returned an array of shape {shape:?} for {n} points; expected {expected}"
            )));
        }
    };
    let readonly = array.try_readonly().map_err(|e| fatal(e.to_string()))?;
    let view = readonly.as_array();
    let flat: Vec<f64> = view.iter().copied().collect();
    Ok(flat.chunks(columns).map(<[f64]>::to_vec).collect())
}

impl Callable {
    /// Wrap `function`, which takes (n, `dimension`) arrays and returns `outputs` values per row
    /// (`None`: one value, shape (n,)). `what` names it in errors (`model`, `log_likelihood`).
    pub fn new(
        function: Py<PyAny>,
        dimension: usize,
        outputs: Option<usize>,
        on_error: OnError,
        what: &'static str,
    ) -> Self {
        Self {
            function,
            dimension,
            outputs,
            on_error,
            error: Mutex::new(None),
            what,
        }
    }

    /// The exception that stopped the computation, if any (taken: a second call gives `None`).
    pub fn take_error(&self) -> Option<PyErr> {
        self.error.lock().ok().and_then(|mut e| e.take())
    }

    fn keep_error(&self, error: PyErr) {
        if let Ok(mut slot) = self.error.lock()
            && slot.is_none()
        {
            *slot = Some(error);
        }
    }

    fn has_error(&self) -> bool {
        self.error.lock().map(|e| e.is_some()).unwrap_or(true)
    }

    fn call(&self, py: Python<'_>, points: &[Vec<f64>]) -> Result<CallResult, CallError> {
        py.check_signals().map_err(CallError::Fatal)?;
        let x = rows_to_array(py, points, self.dimension).map_err(CallError::Fatal)?;
        let result = self.function.bind(py).call1((x,)).map_err(|e| {
            if e.is_instance_of::<PyKeyboardInterrupt>(py) {
                CallError::Fatal(e)
            } else {
                CallError::Raised(e)
            }
        })?;
        let n = points.len();
        let pair = match (self.outputs, result.downcast::<PyTuple>()) {
            (Some(_), Ok(t)) if t.len() == 2 => Some((
                t.get_item(0).map_err(CallError::Fatal)?,
                t.get_item(1).map_err(CallError::Fatal)?,
            )),
            _ => None,
        };
        match pair {
            Some((values, std)) => Ok(CallResult {
                values: to_matrix(py, &values, n, self.outputs, self.what)?,
                std: Some(to_matrix(py, &std, n, self.outputs, self.what)?),
            }),
            None => Ok(CallResult {
                values: to_matrix(py, &result, n, self.outputs, self.what)?,
                std: None,
            }),
        }
    }

    /// Evaluate a batch under the error policy: one entry per point (`Err` a failed point), or
    /// `Err(message)` when the computation must stop (the exception is kept).
    fn evaluate(&self, points: &[Vec<f64>]) -> Result<Vec<Result<CallRow, String>>, String> {
        if points.is_empty() {
            return Ok(Vec::new());
        }
        if self.has_error() {
            return Err(format!("the Python {} failed before", self.what));
        }
        Python::with_gil(|py| match self.call(py, points) {
            Ok(result) => Ok(rows_of(result).into_iter().map(Ok).collect()),
            Err(CallError::Raised(e)) if self.on_error == OnError::Fail => {
                let mut rows = Vec::with_capacity(points.len());
                for point in points {
                    match self.call(py, std::slice::from_ref(point)) {
                        Ok(result) => rows.extend(rows_of(result).into_iter().map(Ok)),
                        Err(CallError::Raised(e)) => rows.push(Err(e.to_string())),
                        Err(CallError::Fatal(e)) => {
                            let message = e.to_string();
                            self.keep_error(e);
                            return Err(message);
                        }
                    }
                }
                drop(e);
                Ok(rows)
            }
            Err(CallError::Raised(e) | CallError::Fatal(e)) => {
                let message = format!("the Python {} raised {e}", self.what);
                self.keep_error(e);
                Err(message)
            }
        })
    }
}

/// One point's values (and stds).
struct CallRow {
    values: Vec<f64>,
    std: Option<Vec<f64>>,
}

fn rows_of(result: CallResult) -> Vec<CallRow> {
    match result.std {
        Some(std) => result
            .values
            .into_iter()
            .zip(std)
            .map(|(values, s)| CallRow {
                values,
                std: Some(s),
            })
            .collect(),
        None => result
            .values
            .into_iter()
            .map(|values| CallRow { values, std: None })
            .collect(),
    }
}

/// A Python model: inputs and outputs named, evaluated in batches.
pub struct PyModel {
    callable: Callable,
    inputs: Vec<String>,
    outputs: Vec<String>,
}

impl PyModel {
    /// A model of `function` with these input and output names.
    pub fn new(
        function: Py<PyAny>,
        inputs: Vec<String>,
        outputs: Vec<String>,
        on_error: OnError,
    ) -> Self {
        let callable = Callable::new(
            function,
            inputs.len(),
            Some(outputs.len()),
            on_error,
            "model",
        );
        Self {
            callable,
            inputs,
            outputs,
        }
    }

    /// The exception that stopped the computation, if any.
    pub fn take_error(&self) -> Option<PyErr> {
        self.callable.take_error()
    }
}

impl Model for PyModel {
    fn input_names(&self) -> &[String] {
        &self.inputs
    }

    fn output_names(&self) -> &[String] {
        &self.outputs
    }

    fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
        let rows = self
            .callable
            .evaluate(points)
            .map_err(CoreError::ModelUnavailable)?;
        Ok(rows
            .into_iter()
            .map(|row| match row {
                Ok(CallRow { values, std: None }) => reject_non_finite(Ok(Evaluation::new(values))),
                Ok(CallRow {
                    values,
                    std: Some(s),
                }) => reject_non_finite(Ok(Evaluation::with_std(values, s))),
                Err(reason) => Err(EvaluationFailure::new(reason)),
            })
            .collect())
    }
}

/// A Python log-likelihood ln f(D | θ) of a batch of parameter vectors, shape (n,).
pub struct PyLikelihood {
    callable: Callable,
}

impl PyLikelihood {
    /// The log-likelihood `function` of `dimension` parameters.
    pub fn new(function: Py<PyAny>, dimension: usize, on_error: OnError) -> Self {
        Self {
            callable: Callable::new(function, dimension, None, on_error, "log_likelihood"),
        }
    }

    /// The exception that stopped the computation, if any.
    pub fn take_error(&self) -> Option<PyErr> {
        self.callable.take_error()
    }
}

impl LogLikelihood for PyLikelihood {
    fn parameter_count(&self) -> usize {
        self.callable.dimension
    }

    fn log_likelihood_batch(
        &self,
        points: &[Vec<f64>],
    ) -> iuq_basis::Result<Vec<PointLogLikelihood>> {
        let rows = self
            .callable
            .evaluate(points)
            .map_err(BasisError::ModelBatch)?;
        Ok(rows
            .into_iter()
            .map(|row| match row {
                Ok(CallRow { values, .. }) => Ok(values.first().copied().unwrap_or(f64::NAN)),
                Err(reason) => Err(EvaluationFailure::new(reason)),
            })
            .collect())
    }
}
