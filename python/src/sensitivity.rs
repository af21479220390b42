//! Sobol' indices of a Python model or of formulas (the CLI's `iuq sobol`) over the priors of
//! the inputs.

use pyo3::prelude::*;
use pyo3::types::PyDict;

use iuq_core::{ExpressionModel, Model, Parameter, ParameterSpace, Prior};
use iuq_sensitivity::{IntervalMethod, SensitivityOptions, SensitivityReport, analyse};

use crate::callable::{OnError, PyModel};
use crate::errors::{bad_input, failure};

/// One prior as the Python side passes it: its kind, as in a study file (`uniform`, `normal`,
/// `log_normal`, `truncated_normal`), and its parameters in the study file's order.
pub type PriorArgs = (String, Vec<f64>);

/// The parameter space of named priors (what a study's `[parameters]` section gives); bad priors
/// are `ValueError`s of the argument `bounds` naming the parameter.
pub fn prior_space(names: &[String], priors: &[PriorArgs]) -> PyResult<ParameterSpace> {
    if names.len() != priors.len() {
        return Err(bad_input(
            "bounds",
            format!("{} names for {} priors", names.len(), priors.len()),
        ));
    }
    let mut parameters = Vec::with_capacity(names.len());
    for (name, (kind, p)) in names.iter().zip(priors) {
        let prior = match (kind.as_str(), p.as_slice()) {
            ("uniform", [lo, hi]) => Prior::Uniform(*lo, *hi),
            ("normal", [m, s]) => Prior::Normal(*m, *s),
            ("log_normal", [m, s]) => Prior::LogNormal(*m, *s),
            ("truncated_normal", [m, s, lo, hi]) => Prior::TruncatedNormal(*m, *s, *lo, *hi),
            _ => {
                return Err(bad_input(
                    "bounds",
                    format!(
                        "parameter `{name}`: `{kind}` with {} values is not a prior (uniform = [lo, hi], normal = [mean, std], log_normal = [mu, sigma], truncated_normal = [mean, std, lo, hi])",
                        p.len()
                    ),
                ));
            }
        };
        parameters.push(Parameter {
            name: name.clone(),
            prior,
        });
    }
    ParameterSpace::new(parameters).map_err(|e| bad_input("bounds", e))
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

/// The estimator's settings (a dict from `iuq.sobol_indices`): `n` base points, `seed`, the
/// confidence intervals' `resamples` (bootstrap) or `replicates`, their `confidence`, and
/// `on_error`.
#[derive(FromPyObject)]
#[pyo3(from_item_all)]
pub struct SobolArgs {
    n: usize,
    seed: u64,
    resamples: usize,
    replicates: Option<usize>,
    confidence: f64,
    on_error: String,
}

/// Sobol' indices: the options and result of `iuq sobol`, as a dict of lists.
#[pyfunction]
#[pyo3(signature = (function, expressions, names, priors, outputs, settings))]
pub fn sobol_indices<'py>(
    py: Python<'py>,
    function: Option<Py<PyAny>>,
    expressions: Option<Vec<(String, String)>>,
    names: Vec<String>,
    priors: Vec<PriorArgs>,
    outputs: Vec<String>,
    settings: SobolArgs,
) -> PyResult<Bound<'py, PyDict>> {
    let SobolArgs {
        n,
        seed,
        resamples,
        replicates,
        confidence,
        on_error,
    } = settings;
    let space = prior_space(&names, &priors)?;
    let model = AnyModel::new(
        function,
        expressions,
        &names,
        outputs,
        OnError::parse(&on_error)?,
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
    let result = py.allow_threads(|| analyse(model.as_model(), &space, &options.check()?));
    if let Some(error) = model.take_error() {
        return Err(error);
    }
    let report = result.map_err(|e| failure("sobol", e))?;
    report_dict(py, &report, n, confidence)
}

/// A Sobol' report as the dict the Python side reads (lists per output).
pub fn report_dict<'py>(
    py: Python<'py>,
    report: &SensitivityReport,
    n: usize,
    confidence: f64,
) -> PyResult<Bound<'py, PyDict>> {
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
