//! The emulator of a study's model outputs: one GP per data point (the default), or, for a
//! whole-curve model, a reduced basis (`[surrogate] reduced_basis = { … }`: GPs on the leading
//! principal components of the runs' curves, `iuq_gp::ReducedBasis`).
//!
//! Per-output GPs suit short outputs and outputs that each depend on θ their own way (a few data
//! points, the red-cell studies' one run per stress); a reduced basis suits long curves whose
//! shapes over the prior span few dimensions, where it fits and evaluates q GPs instead of one
//! per point. Its truncation error (what the kept components leave of the runs' curves) enters
//! the likelihood as computational variance, like the GPs' own.

use iuq_core::{Model, Outcome};
use iuq_gp::{
    GaussianProcess, GpBank, OutputPredictor, Prediction, PredictiveStd, ReducedBasis,
    ReducedBasisOutput,
};

use crate::error::Result;

/// `[surrogate] reduced_basis = { explained_variance, max_components }`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ReducedBasisSettings {
    /// The share of the runs' variance (in measurement stds of each data row) the components
    /// must explain (`explained_variance`, default 0.9999).
    pub explained_variance: f64,
    /// The most components (`max_components`, default 30).
    pub max_components: usize,
}

impl Default for ReducedBasisSettings {
    fn default() -> Self {
        Self {
            explained_variance: 0.9999,
            max_components: 30,
        }
    }
}

/// A fitted emulator of every data point's model output.
#[derive(Debug, Clone)]
pub enum Emulator {
    /// One GP per data point.
    PerOutput(GpBank),
    /// GPs on principal components of the whole curve.
    ReducedBasis(ReducedBasis),
}

/// One output's emulator as the adaptive engine uses it.
#[derive(Clone, Copy)]
pub enum OutputView<'a> {
    /// The output's own GP.
    Gp(&'a GaussianProcess),
    /// An output of a reduced basis.
    Basis(ReducedBasisOutput<'a>),
}

impl OutputPredictor for OutputView<'_> {
    fn predict(&self, points: &[Vec<f64>]) -> iuq_gp::Result<Prediction> {
        match self {
            OutputView::Gp(gp) => OutputPredictor::predict(*gp, points),
            OutputView::Basis(b) => b.predict(points),
        }
    }

    fn posterior_covariance(
        &self,
        a: &[Vec<f64>],
        b: &[Vec<f64>],
    ) -> iuq_gp::Result<Vec<Vec<f64>>> {
        match self {
            OutputView::Gp(gp) => OutputPredictor::posterior_covariance(*gp, a, b),
            OutputView::Basis(v) => v.posterior_covariance(a, b),
        }
    }

    fn run_noise_variance(&self, prediction: &Prediction) -> f64 {
        match self {
            OutputView::Gp(gp) => gp.run_noise_variance(prediction),
            OutputView::Basis(v) => v.run_noise_variance(prediction),
        }
    }
}

impl Emulator {
    /// The outputs' names.
    pub fn output_names(&self) -> &[String] {
        match self {
            Emulator::PerOutput(bank) => bank.output_names(),
            Emulator::ReducedBasis(rb) => rb.output_names(),
        }
    }

    /// Every output's prediction at `points` (mean, latent variance, noise variance).
    pub fn predict(&self, points: &[Vec<f64>]) -> Result<Vec<Prediction>> {
        Ok(match self {
            Emulator::PerOutput(bank) => bank.predict(points)?,
            Emulator::ReducedBasis(rb) => rb.predict(points)?,
        })
    }

    /// Every output's mean at `points` (one row per output).
    pub fn predict_means(&self, points: &[Vec<f64>]) -> Result<Vec<Vec<f64>>> {
        Ok(match self {
            Emulator::PerOutput(bank) => bank
                .gps()
                .iter()
                .map(|gp| gp.predict_mean(points))
                .collect::<iuq_gp::Result<_>>()?,
            Emulator::ReducedBasis(rb) => rb.predict(points)?.into_iter().map(|p| p.mean).collect(),
        })
    }

    /// Output j's variance that no run at a point removes: a reduced basis's truncation
    /// error (0 for a GP per output).
    pub fn unresolved_variance(&self, j: usize) -> f64 {
        match self {
            Emulator::PerOutput(_) => 0.0,
            Emulator::ReducedBasis(rb) => rb.truncation_variance()[j],
        }
    }

    /// Which predictive std the emulator reports as the model's computational std.
    pub fn predictive_std(&self) -> PredictiveStd {
        match self {
            Emulator::PerOutput(bank) => bank.predictive_std(),
            Emulator::ReducedBasis(_) => PredictiveStd::default(),
        }
    }

    /// The variance whose square root the emulator reports as output j's computational std at
    /// each point of `prediction`.
    pub fn reported_variance(&self, j: usize, prediction: &Prediction) -> Vec<f64> {
        let extra = self.unresolved_variance(j);
        self.predictive_std()
            .variance(prediction)
            .into_iter()
            .map(|v| v + extra)
            .collect()
    }

    /// Every output's emulator, as the adaptive engine scores candidates with them.
    pub fn output_views(&self) -> Vec<OutputView<'_>> {
        match self {
            Emulator::PerOutput(bank) => bank.gps().iter().map(OutputView::Gp).collect(),
            Emulator::ReducedBasis(rb) => (0..rb.output_names().len())
                .map(|output| OutputView::Basis(ReducedBasisOutput { basis: rb, output }))
                .collect(),
        }
    }

    /// The GPs fitted to runs: one per output, or one per component.
    pub fn fitted_gps(&self) -> &[GaussianProcess] {
        match self {
            Emulator::PerOutput(bank) => bank.gps(),
            Emulator::ReducedBasis(rb) => rb.component_gps(),
        }
    }

    /// The GP of each output, where each has its own.
    pub fn per_output_gps(&self) -> Option<&[GaussianProcess]> {
        match self {
            Emulator::PerOutput(bank) => Some(bank.gps()),
            Emulator::ReducedBasis(_) => None,
        }
    }

    /// The reduced basis, where the emulator is one.
    pub fn reduced_basis(&self) -> Option<&ReducedBasis> {
        match self {
            Emulator::PerOutput(_) => None,
            Emulator::ReducedBasis(rb) => Some(rb),
        }
    }
}

impl Model for Emulator {
    fn input_names(&self) -> &[String] {
        match self {
            Emulator::PerOutput(bank) => bank.input_names(),
            Emulator::ReducedBasis(rb) => rb.input_names(),
        }
    }

    fn output_names(&self) -> &[String] {
        Emulator::output_names(self)
    }

    fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
        match self {
            Emulator::PerOutput(bank) => bank.evaluate_batch(points),
            Emulator::ReducedBasis(rb) => rb.evaluate_batch(points),
        }
    }

    fn screening_batch(&self, points: &[Vec<f64>]) -> Option<iuq_core::Result<Vec<Outcome>>> {
        match self {
            Emulator::PerOutput(bank) => bank.screening_batch(points),
            Emulator::ReducedBasis(rb) => rb.screening_batch(points),
        }
    }
}
