//! Gaussian-process surrogates: `iuq gp fit|predict|validate` from Python.
//!
//! A fitted GP is saved as the CLI saves it: a GP bank of one output ([`GpBank`], whose
//! `to_json_string` both sides call), so a file saved here and one written by `iuq gp fit` on the
//! same data are identical, and either side loads the other's.

use std::path::{Path, PathBuf};

use numpy::{PyArray1, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

use iuq_core::Model;
use iuq_gp::{FitOptions, GaussianProcess, GpBank, Kernel};
use iuq_study::table_io::write_atomically;

use crate::arrays::{array_rows, array_values, vec_to_array};
use crate::errors::{bad_input, failure};

/// A fitted Gaussian process with the names of its input and output columns.
#[pyclass(name = "GaussianProcess", module = "iuq._native", frozen)]
pub struct NativeGaussianProcess {
    gp: GaussianProcess,
    inputs: Vec<String>,
    output: String,
}

/// Read a GP file: a GP bank of one output.
fn read_gp_file(path: &Path) -> PyResult<NativeGaussianProcess> {
    let bank = iuq_study::gp_file::read_gp_file(path, "GaussianProcess.load")
        .map_err(|e| bad_input("path", e.message().to_string()))?;
    match (bank.gps(), bank.output_names()) {
        ([gp], [output]) => Ok(NativeGaussianProcess {
            gp: gp.clone(),
            inputs: bank.input_names().to_vec(),
            output: output.clone(),
        }),
        _ => Err(bad_input("path", "a GP file of one output".to_string())),
    }
}

fn kernel_of(name: &str) -> PyResult<Kernel> {
    match name {
        "ard" => Ok(Kernel::ard()),
        "isotropic" => Ok(Kernel::isotropic()),
        "study-original" | "study_original" => Ok(Kernel::study_original()),
        other => Err(bad_input(
            "kernel",
            format!("`{other}` is not one of ard, isotropic, study-original"),
        )),
    }
}

/// The fit's settings (a dict from `iuq.GaussianProcess.fit`).
#[derive(FromPyObject)]
#[pyo3(from_item_all)]
pub struct FitArgs {
    restarts: usize,
    seed: u64,
    kernel: String,
    scale_inputs: bool,
    standardize_outputs: bool,
}

#[pymethods]
impl NativeGaussianProcess {
    /// Fit by maximising the log marginal likelihood (as `iuq gp fit`).
    #[staticmethod]
    #[pyo3(signature = (x, y, settings, inputs, output))]
    fn fit(
        py: Python<'_>,
        x: PyReadonlyArray2<'_, f64>,
        y: PyReadonlyArray1<'_, f64>,
        settings: FitArgs,
        inputs: Vec<String>,
        output: String,
    ) -> PyResult<Self> {
        let FitArgs {
            restarts,
            seed,
            kernel,
            scale_inputs,
            standardize_outputs,
        } = settings;
        let x = array_rows(&x);
        let y = array_values(&y);
        if x.len() != y.len() {
            return Err(bad_input(
                "y",
                format!("{} values for {} rows of X", y.len(), x.len()),
            ));
        }
        if x.len() < 2 {
            return Err(bad_input("X", "at least two data rows are needed"));
        }
        let dim = x.first().map_or(0, Vec::len);
        if inputs.len() != dim {
            return Err(bad_input(
                "input_names",
                format!("{} names for {dim} columns of X", inputs.len()),
            ));
        }
        let options = FitOptions {
            kernel: kernel_of(&kernel)?,
            n_restarts: restarts,
            seed,
            scale_inputs,
            standardize_outputs,
            ..FitOptions::default()
        };
        let gp = py
            .allow_threads(|| GaussianProcess::fit(&x, &y, &options.check()?))
            .map_err(|e| bad_input("X, y", e))?;
        Ok(Self { gp, inputs, output })
    }

    /// Read a GP file of `iuq gp fit` (or of `save`).
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        read_gp_file(&path)
    }

    /// Write the GP file (atomically), byte for byte as `iuq gp fit --out` writes it.
    fn save(&self, path: PathBuf) -> PyResult<()> {
        let bank = GpBank::new(
            self.inputs.clone(),
            vec![self.output.clone()],
            vec![self.gp.clone()],
        )
        .map_err(|e| failure("saving the GP", e))?;
        let text = bank
            .to_json_string()
            .map_err(|e| failure("serialising the GP", e))?;
        write_atomically(&path, text.as_bytes())
            .map_err(|e| bad_input("path", format!("{}: {e}", path.display())))
    }

    /// Mean, latent variance (clamped at 0, as the CLI) and noise variance at the rows of `x`.
    #[allow(clippy::type_complexity)]
    fn predict<'py>(
        &self,
        py: Python<'py>,
        x: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<(Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>, f64)> {
        let points = array_rows(&x);
        let prediction = py
            .allow_threads(|| self.gp.predict(&points))
            .map_err(|e| bad_input("X", e))?;
        let variance = prediction.variance.iter().map(|v| v.max(0.0)).collect();
        Ok((
            vec_to_array(py, prediction.mean),
            vec_to_array(py, variance),
            prediction.noise_variance,
        ))
    }

    /// Predictivity Q2 on a test set (as `iuq gp validate`).
    fn q2(
        &self,
        py: Python<'_>,
        x: PyReadonlyArray2<'_, f64>,
        y: PyReadonlyArray1<'_, f64>,
    ) -> PyResult<f64> {
        let points = array_rows(&x);
        let observed = array_values(&y);
        py.allow_threads(|| self.gp.q2(&points, &observed))
            .map_err(|e| bad_input("X, y", e))
    }

    /// The log marginal likelihood at the fitted hyper-parameters (on the GP's working scale:
    /// unit-cube inputs and standardised outputs unless switched off).
    #[getter]
    fn log_marginal_likelihood(&self) -> f64 {
        self.gp.log_marginal_likelihood()
    }

    /// Leave-one-out Q2 of the training data (None when undefined).
    #[getter]
    fn loo_q2(&self) -> Option<f64> {
        self.gp.loo_q2()
    }

    /// Length scales on the working scale.
    #[getter]
    fn length_scales(&self) -> Vec<f64> {
        self.gp.hyperparameters().length_scales.clone()
    }

    /// Length scales in the units of the inputs.
    #[getter]
    fn length_scales_input_units(&self) -> Vec<f64> {
        self.gp.length_scales_in_input_units()
    }

    /// Signal variance on the working scale.
    #[getter]
    fn signal_variance(&self) -> f64 {
        self.gp.hyperparameters().signal_variance
    }

    /// Noise variance on the working scale.
    #[getter]
    fn noise_variance(&self) -> f64 {
        self.gp.hyperparameters().noise_variance
    }

    /// Names of the input columns.
    #[getter]
    fn input_names(&self) -> Vec<String> {
        self.inputs.clone()
    }

    /// Name of the output column.
    #[getter]
    fn output_name(&self) -> String {
        self.output.clone()
    }

    /// Number of inputs.
    #[getter]
    fn dimension(&self) -> usize {
        self.gp.dimension()
    }

    /// Number of training points.
    #[getter]
    fn n_training(&self) -> usize {
        self.gp.n_training()
    }

    /// Warnings of the fit (degenerate optimum, poor leave-one-out Q2, …).
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.gp.diagnostics().messages()
    }
}
