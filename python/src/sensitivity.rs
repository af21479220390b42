//! Sobol' indices of a Python model or of formulas (the CLI's `iuq sobol`), over a box of
//! uniform priors.

use pyo3::prelude::*;
use pyo3::types::PyDict;

use iuq_core::{ExpressionModel, Model, Parameter, ParameterSpace, Prior};
use iuq_sensitivity::{IntervalMethod, SensitivityOptions, analyse};

use crate::arrays::check_bounds;
use crate::callable::{OnError, PyModel};
use crate::errors::{bad_input, failure};

/// A space of uniform priors U(lo, hi), one per name (what a study's `[parameters]` section with
/// `uniform = [lo, hi]` gives).
pub fn uniform_space(names: &[String], bounds: &[(f64, f64)]) -> PyResult<ParameterSpace> {
    check_bounds("bounds", bounds, names.len())?;
    ParameterSpace::new(
        names
            .iter()
            .zip(bounds)
            .map(|(name, (lo, hi))| Parameter {
                name: name.clone(),
                prior: Prior::Uniform(*lo, *hi),
            })
            .collect(),
    )
    .map_err(|e| bad_input("names", e))
}

/// The model of `iuq.sobol`: a Python callable or formulas.
pub enum AnyModel {
    /// A Python callable.
    Python(PyModel),
    /// Formulas of the inputs (a study's `kind = "expression"`).
    Expression(ExpressionModel),
}

impl AnyModel {
    /// `function` (a callable) or `expressions` (name, formula) pairs, exactly one of them.
    pub fn new(
        function: Option<Py<PyAny>>,
        expressions: Option<Vec<(String, String)>>,
        names: &[String],
        outputs: Vec<String>,
        on_error: OnError,
    ) -> PyResult<Self> {
        match (function, expressions) {
            (Some(f), None) => Ok(Self::Python(PyModel::new(
                f,
                names.to_vec(),
                outputs,
                on_error,
            ))),
            (None, Some(formulas)) => {
                for (name, formula) in &formulas {
                    iuq_core::Expression::parse(formula, names)
                        .map_err(|e| bad_input("model", format!("output `{name}`: {e}")))?;
                }
                ExpressionModel::new(names.to_vec(), &formulas)
                    .map(Self::Expression)
                    .map_err(|e| bad_input("model", e))
            }
            _ => Err(bad_input(
                "model",
                "give a callable or formulas (a string or a dict of strings)",
            )),
        }
    }

    /// The model as a library model.
    pub fn as_model(&self) -> &dyn Model {
        match self {
            Self::Python(m) => m,
            Self::Expression(m) => m,
        }
    }

    /// The exception of the Python model that stopped the computation, if any.
    pub fn take_error(&self) -> Option<PyErr> {
        match self {
            Self::Python(m) => m.take_error(),
            Self::Expression(_) => None,
        }
    }
}

/// Sobol' indices: the options and result of `iuq sobol`, as a dict of lists.
#[pyfunction]
#[pyo3(signature = (function, expressions, names, bounds, outputs, n, seed, resamples, replicates, confidence, on_error))]
#[allow(clippy::too_many_arguments)]
pub fn sobol_indices<'py>(
    py: Python<'py>,
    function: Option<Py<PyAny>>,
    expressions: Option<Vec<(String, String)>>,
    names: Vec<String>,
    bounds: Vec<(f64, f64)>,
    outputs: Vec<String>,
    n: usize,
    seed: u64,
    resamples: usize,
    replicates: Option<usize>,
    confidence: f64,
    on_error: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let space = uniform_space(&names, &bounds)?;
    let model = AnyModel::new(
        function,
        expressions,
        &names,
        outputs,
        OnError::parse(on_error)?,
    )?;
    if n < 2 {
        return Err(bad_input(
            "n",
            format!("at least 2 base points are needed, got {n}"),
        ));
    }
    if !(confidence > 0.0 && confidence < 1.0) {
        return Err(bad_input(
            "confidence",
            format!("{confidence} must lie strictly between 0 and 1"),
        ));
    }
    let interval = match replicates {
        Some(count) if count < 2 => {
            return Err(bad_input(
                "replicates",
                format!("at least 2 are needed, got {count}"),
            ));
        }
        Some(count) => IntervalMethod::Replicates { count },
        None if resamples < 2 => {
            return Err(bad_input(
                "resamples",
                format!("at least 2 are needed, got {resamples}"),
            ));
        }
        None => IntervalMethod::Bootstrap { resamples },
    };
    let options = SensitivityOptions {
        base_points: n,
        seed,
        interval,
        confidence_level: confidence,
        ..Default::default()
    };
    let result = py.allow_threads(|| analyse(model.as_model(), &space, &options));
    if let Some(error) = model.take_error() {
        return Err(error);
    }
    let report = result.map_err(|e| failure("sobol", e))?;
    let out = PyDict::new(py);
    out.set_item("inputs", &report.inputs)?;
    let per_output = PyDict::new(py);
    for o in &report.outputs {
        let d = PyDict::new(py);
        d.set_item("S1", &o.first_order)?;
        d.set_item("ST", &o.total)?;
        d.set_item("S1_conf", &o.first_order_conf)?;
        d.set_item("ST_conf", &o.total_conf)?;
        d.set_item("variance", o.variance)?;
        per_output.set_item(&o.output, d)?;
    }
    out.set_item("outputs", per_output)?;
    out.set_item(
        "output_names",
        report
            .outputs
            .iter()
            .map(|o| o.output.clone())
            .collect::<Vec<_>>(),
    )?;
    out.set_item("evaluations", report.evaluations)?;
    out.set_item("failed_evaluations", report.failed_evaluations)?;
    out.set_item("dropped_groups", report.dropped_groups)?;
    out.set_item("failure_handling", report.failure_handling())?;
    out.set_item("failure_reasons", report.failure_reasons.clone())?;
    out.set_item("base_points", n)?;
    out.set_item("confidence", confidence)?;
    Ok(out)
}
