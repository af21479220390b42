//! BASIS posterior sampling (the CLI's `iuq basis`) of a Python log-likelihood, of a
//! log-density formula, or of the prediction-error likelihood of a Python model against data.

use pyo3::prelude::*;
use pyo3::types::PyDict;

use iuq_basis::{
    Basis, BasisRun, BasisSettings, ComputationalError, ErrorModel, LogDensityLikelihood,
    LogLikelihood, Observations, PosteriorSummary, PredictionErrorLikelihood, Silent, StopReason,
};
use iuq_core::{ParameterSpace, Prior};

use crate::arrays::{rows_to_array, vec_to_array};
use crate::callable::{OnError, PyLikelihood, PyModel};
use crate::errors::{bad_input, failure};
use crate::sensitivity::{PriorArgs, prior_space};

/// The likelihood of one `iuq.basis` call.
enum AnyLikelihood {
    Python(PyLikelihood),
    Formula(LogDensityLikelihood),
    Data(Box<PredictionErrorLikelihood<PyModel>>),
}

impl AnyLikelihood {
    fn as_likelihood(&self) -> &dyn LogLikelihood {
        match self {
            Self::Python(l) => l,
            Self::Formula(l) => l,
            Self::Data(l) => l.as_ref(),
        }
    }

    fn take_error(&self) -> Option<PyErr> {
        match self {
            Self::Python(l) => l.take_error(),
            Self::Formula(_) => None,
            Self::Data(l) => l.model().take_error(),
        }
    }
}

/// The data of the prediction-error form.
#[derive(FromPyObject)]
#[pyo3(from_item_all)]
pub struct DataArgs {
    model: Py<PyAny>,
    values: Vec<f64>,
    measurement_std: Option<Vec<f64>>,
    modelling_error: Option<(f64, f64)>,
    computational_error: String,
    measurement_error: bool,
}

/// The sampler's settings (a dict from `iuq.basis`, checked there).
#[derive(FromPyObject)]
#[pyo3(from_item_all)]
pub struct BasisArgs {
    samples: usize,
    burn: Option<usize>,
    max_chain: usize,
    seed: u64,
    cv_target: f64,
    proposal_scale: Option<f64>,
    max_stages: usize,
    on_error: String,
}

/// Sample the posterior with BASIS; the result (samples, evidence, summaries, stage
/// diagnostics as JSON) as a dict.
#[pyfunction]
#[pyo3(signature = (log_likelihood, formula, data, names, priors, settings))]
pub fn basis<'py>(
    py: Python<'py>,
    log_likelihood: Option<Py<PyAny>>,
    formula: Option<String>,
    data: Option<DataArgs>,
    names: Vec<String>,
    priors: Vec<PriorArgs>,
    settings: BasisArgs,
) -> PyResult<Bound<'py, PyDict>> {
    let BasisArgs {
        samples,
        burn,
        max_chain,
        seed,
        cv_target,
        proposal_scale,
        max_stages,
        on_error,
    } = settings;
    let on_error = OnError::parse(&on_error)?;
    let model_space = prior_space(&names, &priors)?;
    let (likelihood, space): (AnyLikelihood, ParameterSpace) = match (log_likelihood, formula, data)
    {
        (Some(f), None, None) => (
            AnyLikelihood::Python(PyLikelihood::new(f, names.len(), on_error)),
            model_space,
        ),
        (None, Some(source), None) => (
            AnyLikelihood::Formula(
                LogDensityLikelihood::new(&source, &model_space)
                    .map_err(|e| bad_input("log_likelihood", e))?,
            ),
            model_space,
        ),
        (None, None, Some(d)) => {
            let computational_error = ComputationalError::from_name(&d.computational_error)
                .ok_or_else(|| {
                    bad_input(
                        "computational_error",
                        format!(
                            "`{}` is not a known computational error",
                            d.computational_error
                        ),
                    )
                })?;
            let observations = Observations {
                values: d.values,
                measurement_std: d.measurement_std,
            };
            let errors = ErrorModel {
                measurement_error: d.measurement_error,
                computational_error,
                modelling_error: d.modelling_error.map(|(lo, hi)| Prior::Uniform(lo, hi)),
            };
            let m = observations.values.len();
            let outputs = (1..=m).map(|j| format!("y{j}")).collect();
            let model = PyModel::new(d.model, names.clone(), outputs, on_error);
            let likelihood = PredictionErrorLikelihood::new(model, observations, errors)
                .map_err(|e| bad_input("data", e))?;
            let space = likelihood
                .parameter_space(&model_space)
                .map_err(|e| bad_input("data", e))?;
            (AnyLikelihood::Data(Box::new(likelihood)), space)
        }
        _ => {
            return Err(bad_input(
                "log_likelihood",
                "give exactly one of a callable log_likelihood, a formula, or model and data",
            ));
        }
    };
    // A number of steps or a scale fixes the mixing, as a study's `[sampler]` does.
    let defaults = BasisSettings::default();
    let mixing = if burn.is_some() || proposal_scale.is_some() {
        iuq_basis::Mixing::Fixed
    } else {
        defaults.mixing
    };
    let settings = BasisSettings {
        samples,
        burn_in: burn.unwrap_or(defaults.burn_in),
        max_chain_length: max_chain,
        cv_target,
        proposal_scale: proposal_scale.unwrap_or(defaults.proposal_scale),
        mixing,
        max_stages,
        seed,
        ..defaults
    }
    .check()
    .map_err(|e| match e {
        iuq_basis::BasisError::InvalidSettings { setting, reason } => bad_input(setting, reason),
        other => bad_input("settings", other),
    })?;
    let result = py.allow_threads(|| {
        let sampler = Basis::new(&space, likelihood.as_likelihood(), settings)?;
        let run = sampler.run(&mut Silent)?;
        let summary = PosteriorSummary::from_state(&run.state)?;
        let stages = serde_json::to_string(&run.state.diagnostics)
            .map_err(|e| iuq_basis::BasisError::Observer(e.to_string()))?;
        Ok::<_, iuq_basis::BasisError>((run, summary, stages))
    });
    if let Some(error) = likelihood.take_error() {
        return Err(error);
    }
    let (run, summary, stages) = result.map_err(|e| failure("basis", e))?;
    run_dict(py, &run, &summary, stages)
}

/// A BASIS run and its summary as the dict the Python side reads (`stages` as JSON text).
pub fn run_dict<'py>(
    py: Python<'py>,
    run: &BasisRun,
    summary: &PosteriorSummary,
    stages: String,
) -> PyResult<Bound<'py, PyDict>> {
    let state = &run.state;
    let d = state.parameter_names.len();
    let out = PyDict::new(py);
    out.set_item("names", &state.parameter_names)?;
    out.set_item("samples", rows_to_array(py, &state.samples, d)?)?;
    out.set_item(
        "log_likelihood",
        vec_to_array(py, state.log_likelihood.clone()),
    )?;
    out.set_item("log_prior", vec_to_array(py, state.log_prior.clone()))?;
    out.set_item("log_evidence", state.log_evidence)?;
    out.set_item("n_stages", state.stages())?;
    out.set_item("stages_json", stages)?;
    out.set_item("evaluations", state.evaluations)?;
    out.set_item("stop_reason", run.stop_reason.name())?;
    out.set_item("stop_message", run.stop_reason.to_string())?;
    out.set_item("converged", run.stop_reason == StopReason::Converged)?;
    out.set_item("exponent", state.exponent)?;
    out.set_item("map", vec_to_array(py, summary.map.clone()))?;
    out.set_item("mean", vec_to_array(py, summary.mean.clone()))?;
    out.set_item("std", vec_to_array(py, summary.std.clone()))?;
    out.set_item("map_log_likelihood", summary.map_log_likelihood)?;
    out.set_item("map_log_prior", summary.map_log_prior)?;
    out.set_item(
        "probabilities",
        vec_to_array(py, summary.probabilities.clone()),
    )?;
    out.set_item(
        "quantiles",
        rows_to_array(py, &summary.quantiles, summary.probabilities.len())?,
    )?;
    out.set_item("failures", state.failures())?;
    out.set_item("failure_reasons", state.failure_reasons())?;
    out.set_item("out_of_support", state.out_of_support())?;
    Ok(out)
}
