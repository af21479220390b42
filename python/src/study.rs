//! Study files from Python: `iuq pipeline`, `iuq sobol`, `iuq basis`, `iuq status` and
//! `iuq export` as methods.
//!
//! Results are the JSON objects the CLI prints with `--json` (built the same way), handed to
//! Python as JSON text; the pure-Python `iuq.Study` turns them into objects.

use std::path::PathBuf;

use pyo3::prelude::*;
use pyo3::types::PyDict;
use serde_json::{Value, json};

use iuq_campaign::export::{export_csv, export_json, export_rows};
use iuq_campaign::{CampaignStore, store_path};
use iuq_sensitivity::{IntervalMethod, SensitivityOptions, analyse};
use iuq_study::campaign_runs::{CampaignStatus, campaign_error};
use iuq_study::campaign_study::load_study;
use iuq_study::pipeline::PipelineOptions;
use iuq_study::posterior::{SamplingJob, build_posterior, sample_posterior};
use iuq_study::sampler_section::{SamplerOverrides, parse_sampler};
use iuq_study::table_io::write_atomically;
use iuq_study::{Study, StudyError};

use crate::calibrate::forwarded_models;
use crate::callable::{OnError, PyModel};
use crate::errors::{bad_input, failure, study_error};
use crate::progress::ProgressObserver;

/// How long a Ctrl-C waits for the pipeline to reach its next check before the
/// `KeyboardInterrupt` is raised anyway (the pipeline then stops on its own, and the next call
/// waits for it): a GP fit or a sampler stage on hundreds of runs takes seconds, and a Ctrl-C
/// must interrupt within a second.
const INTERRUPT_GRACE: std::time::Duration = std::time::Duration::from_millis(400);

/// A study file, loaded and checked.
#[pyclass(name = "Study", module = "iuq._native", frozen)]
pub struct NativeStudy {
    study: Study,
}

fn to_json_text(value: &Value) -> PyResult<String> {
    serde_json::to_string(value).map_err(|e| failure("serialising the result", e))
}

/// How `Study.run` runs the pipeline (a dict from `iuq.Study.run`; the flags of `iuq pipeline`).
#[derive(FromPyObject)]
#[pyo3(from_item_all)]
pub struct RunArgs {
    max_parallel: Option<usize>,
    model_posterior: bool,
    fresh: bool,
    runs_only: bool,
    recompute_rounds: bool,
}

/// How `Study.calibrate` calls the Python model (a dict from `iuq.calibrate`): its `outputs`
/// per call, `on_error`, up to `max_parallel` runs per call, and whether to certify the model
/// posterior.
#[derive(FromPyObject)]
#[pyo3(from_item_all)]
pub struct CalibrateArgs {
    outputs: usize,
    on_error: String,
    max_parallel: usize,
    model_posterior: bool,
}

#[pymethods]
impl NativeStudy {
    /// Read and check a study file (as every CLI verb does).
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        Study::load(&path)
            .map(|study| Self { study })
            .map_err(study_error)
    }

    /// The study's name.
    #[getter]
    fn name(&self) -> String {
        self.study.name.clone()
    }

    /// The study file.
    #[getter]
    fn path(&self) -> PathBuf {
        self.study.path.clone()
    }

    /// The parameter names, in file order.
    #[getter]
    fn parameters(&self) -> Vec<String> {
        self.study.space.names()
    }

    /// The parameters' ranges (prior supports, or plotting ranges for unbounded priors).
    #[getter]
    fn ranges(&self) -> Vec<(f64, f64)> {
        self.study.space.ranges()
    }

    /// Run the pipeline (`iuq pipeline`); the outcome as the JSON text of `iuq pipeline --json`.
    #[pyo3(signature = (out, settings, progress))]
    fn run(
        &self,
        py: Python<'_>,
        out: PathBuf,
        settings: RunArgs,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<String> {
        let RunArgs {
            max_parallel,
            model_posterior,
            fresh,
            runs_only,
            recompute_rounds,
        } = settings;
        let options = PipelineOptions {
            out,
            max_parallel,
            model_posterior,
            fresh,
            runs_only,
            recompute_rounds,
            callable: None,
            low_fidelity_callable: None,
            interrupt_grace: Some(INTERRUPT_GRACE),
        };
        let mut observer = ProgressObserver::new(progress);
        let result =
            py.allow_threads(|| iuq_study::pipeline::run(&self.study, &options, &mut observer));
        if let Some(error) = observer.take_error() {
            return Err(error);
        }
        let outcome = result.map_err(study_error)?;
        let value = outcome.summary();
        to_json_text(&value)
    }

    /// Run the pipeline of a study whose model is of kind `callable`, the Python `model` (a
    /// callable (n, inputs) → (n, outputs), or a pair of such arrays, values and stds),
    /// evaluated on this thread in batches of up to `max_parallel` runs (see
    /// [`crate::calibrate`]); the outcome as `run` gives it. `low_fidelity`, a callable of the
    /// same signature, is the cheap model of a `[low_fidelity] kind = "callable"`.
    #[pyo3(signature = (out, model, settings, progress, low_fidelity=None))]
    fn calibrate(
        &self,
        py: Python<'_>,
        out: PathBuf,
        model: Py<PyAny>,
        settings: CalibrateArgs,
        progress: Option<Py<PyAny>>,
        low_fidelity: Option<Py<PyAny>>,
    ) -> PyResult<String> {
        let CalibrateArgs {
            outputs,
            on_error,
            max_parallel,
            model_posterior,
        } = settings;
        let on_error = OnError::parse(&on_error)?;
        let output_names: Vec<String> = (0..outputs).map(|j| format!("y[{j}]")).collect();
        let inputs = self.study.model_inputs();
        let mut models = vec![PyModel::new(
            model,
            inputs.clone(),
            output_names.clone(),
            on_error,
        )];
        let cheap = low_fidelity.is_some();
        if let Some(low) = low_fidelity {
            models.push(PyModel::new(low, inputs, output_names, on_error));
        }
        let (mut shared, mut observer) = forwarded_models(models, progress);
        let low_fidelity_callable = if cheap { shared.pop() } else { None };
        let shared = shared
            .pop()
            .ok_or_else(|| pyo3::exceptions::PyRuntimeError::new_err("no model to calibrate"))?;
        let options = PipelineOptions {
            out,
            max_parallel: Some(max_parallel),
            model_posterior,
            fresh: false,
            runs_only: false,
            recompute_rounds: false,
            callable: Some(shared),
            low_fidelity_callable,
            interrupt_grace: Some(INTERRUPT_GRACE),
        };
        let result =
            py.allow_threads(|| iuq_study::pipeline::run(&self.study, &options, &mut observer));
        if let Some(error) = observer.take_error() {
            return Err(error);
        }
        let outcome = result.map_err(study_error)?;
        to_json_text(&outcome.summary())
    }

    /// Sobol' indices of the study's model over its priors (`iuq sobol STUDY`): the options
    /// default to the study's `[sensitivity]` section, then to the CLI's defaults.
    #[pyo3(signature = (n, seed, replicates, resamples, confidence))]
    fn sobol<'py>(
        &self,
        py: Python<'py>,
        n: Option<usize>,
        seed: Option<u64>,
        replicates: Option<usize>,
        resamples: Option<usize>,
        confidence: Option<f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let section = &self.study.sensitivity;
        let n = n.or(section.n).unwrap_or(1024);
        if n < 2 {
            return Err(bad_input(
                "n",
                format!("at least 2 base points are needed, got {n}"),
            ));
        }
        let confidence = confidence.or(section.confidence).unwrap_or(0.95);
        if !(confidence > 0.0 && confidence < 1.0) {
            return Err(bad_input(
                "confidence",
                format!("{confidence} must lie strictly between 0 and 1"),
            ));
        }
        let interval = match replicates.or(section.replicates) {
            Some(count) if count < 2 => {
                return Err(bad_input(
                    "replicates",
                    format!("at least 2 are needed, got {count}"),
                ));
            }
            Some(count) => IntervalMethod::Replicates { count },
            None => {
                let resamples = resamples.or(section.resamples).unwrap_or(100);
                if resamples < 2 {
                    return Err(bad_input(
                        "resamples",
                        format!("at least 2 are needed, got {resamples}"),
                    ));
                }
                IntervalMethod::Bootstrap { resamples }
            }
        };
        let options = SensitivityOptions {
            base_points: n,
            seed: seed.or(self.study.sensitivity.seed).unwrap_or(0),
            interval,
            confidence_level: confidence,
            ..Default::default()
        };
        let study = &self.study;
        let report = py
            .allow_threads(|| {
                let model = study.model()?;
                let bad = |e: iuq_sensitivity::SensitivityError| {
                    StudyError::bad_input(format!("{}: {e}", study.path.display())).with_source(e)
                };
                analyse(&model, &study.space, &options.check().map_err(bad)?).map_err(bad)
            })
            .map_err(study_error)?;
        crate::sensitivity::report_dict(py, &report, n, confidence)
    }

    /// BASIS posterior of the study's `[likelihood]` (`iuq basis STUDY --out OUT`): the
    /// settings default to the study's `[sampler]`; every result file is written into `out`.
    #[pyo3(signature = (out, samples, burn, max_chain, seed))]
    fn basis<'py>(
        &self,
        py: Python<'py>,
        out: PathBuf,
        samples: Option<usize>,
        burn: Option<usize>,
        max_chain: Option<usize>,
        seed: Option<u64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let study = &self.study;
        let overrides = SamplerOverrides {
            samples,
            burn,
            max_chain,
            seed,
        };
        let (sampled, stages) = py
            .allow_threads(|| {
                let posterior = build_posterior(study)?;
                let settings = parse_sampler(study, &overrides)?;
                let job = SamplingJob {
                    study_name: &study.name,
                    study_file: &study.path,
                    out: &out,
                    checkpoint: None,
                    resume_dir: None,
                    stop_after: None,
                    marginals: true,
                };
                let sampled = sample_posterior(job, &posterior, settings, &mut iuq_basis::Silent)?;
                let stages = serde_json::to_string(&sampled.run.state.diagnostics)
                    .map_err(|e| StudyError::failure(e.to_string()).with_source(e))?;
                Ok::<_, StudyError>((sampled, stages))
            })
            .map_err(study_error)?;
        crate::basis::run_dict(py, &sampled.run, &sampled.summary, stages)
    }

    /// Where the study's campaign stands (`iuq status --json`), as JSON text.
    fn status(&self, py: Python<'_>) -> PyResult<String> {
        let path = self.study.path.clone();
        let value = py
            .allow_threads(|| -> Result<Value, StudyError> {
                Ok(CampaignStatus::read(&load_study(&path)?)?.to_json())
            })
            .map_err(study_error)?;
        to_json_text(&value)
    }

    /// Every run of the campaign (`iuq export`): as JSON text of the rows, or, with `out`, written
    /// to that file as CSV or JSON (`format`), returning the number of rows as JSON text.
    #[pyo3(signature = (out, format))]
    fn export(
        &self,
        py: Python<'_>,
        out: Option<PathBuf>,
        format: Option<String>,
    ) -> PyResult<String> {
        let format = match (format.as_deref(), &out) {
            (Some("csv"), _) => "csv",
            (Some("json"), _) => "json",
            (Some(other), _) => {
                return Err(bad_input(
                    "format",
                    format!("`{other}` is not one of csv, json"),
                ));
            }
            (None, Some(p)) if p.extension().is_some_and(|e| e == "json") => "json",
            (None, Some(_)) => "csv",
            (None, None) => "json",
        };
        let path = self.study.path.clone();
        py.allow_threads(|| -> Result<String, StudyError> {
            let study = load_study(&path)?;
            let store = CampaignStore::open_existing(&store_path(&study)).map_err(campaign_error)?;
            let rows = export_rows(&store).map_err(campaign_error)?;
            let parameters = study.space.names();
            let outputs = study.model.outputs.clone();
            let table = export_json(&rows, &parameters, &outputs);
            match &out {
                None => Ok(table.to_string()),
                Some(file) => {
                    let bytes = if format == "csv" {
                        export_csv(&rows, &parameters, &outputs).map_err(campaign_error)?
                    } else {
                        serde_json::to_vec_pretty(&table)
                            .map_err(|e| StudyError::failure(e.to_string()).with_source(e))?
                    };
                    write_atomically(file, &bytes)?;
                    Ok(json!({"rows": rows.len(), "out": file.display().to_string(), "format": format}).to_string())
                }
            }
        })
        .map_err(study_error)
    }
}
