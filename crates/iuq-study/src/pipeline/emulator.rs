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
    GaussianProcess, GpBank, MultiFidelityBank, MultiFidelityGp, OutputPredictor, Prediction,
    PredictiveStd, ReducedBasis, ReducedBasisOutput,
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
    /// One two-fidelity GP per data point (`[low_fidelity]`): the expensive model's output as
    /// ρ·(the cheap model's GP) + a GP discrepancy.
    TwoFidelity(MultiFidelityBank),
}

/// One output's emulator as the adaptive engine uses it.
#[derive(Clone, Copy)]
pub enum OutputView<'a> {
    /// The output's own GP.
    Gp(&'a GaussianProcess),
    /// An output of a reduced basis.
    Basis(ReducedBasisOutput<'a>),
    /// The output's two-fidelity GP.
    TwoFidelity(&'a MultiFidelityGp),
}

impl OutputPredictor for OutputView<'_> {
    fn predict(&self, points: &[Vec<f64>]) -> iuq_gp::Result<Prediction> {
        match self {
            OutputView::Gp(gp) => OutputPredictor::predict(*gp, points),
            OutputView::Basis(b) => b.predict(points),
            OutputView::TwoFidelity(gp) => OutputPredictor::predict(*gp, points),
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
            OutputView::TwoFidelity(gp) => OutputPredictor::posterior_covariance(*gp, a, b),
        }
    }

    fn run_noise_variance(&self, prediction: &Prediction) -> f64 {
        match self {
            OutputView::Gp(gp) => gp.run_noise_variance(prediction),
            OutputView::Basis(v) => v.run_noise_variance(prediction),
            OutputView::TwoFidelity(gp) => gp.run_noise_variance(prediction),
        }
    }

    fn shared_components(&self) -> Option<iuq_gp::output_predictor::SharedComponents<'_>> {
        match self {
            OutputView::Basis(v) => v.shared_components(),
            OutputView::Gp(_) | OutputView::TwoFidelity(_) => None,
        }
    }
}

impl Emulator {
    /// The outputs' names.
    pub fn output_names(&self) -> &[String] {
        match self {
            Emulator::PerOutput(bank) => bank.output_names(),
            Emulator::ReducedBasis(rb) => rb.output_names(),
            Emulator::TwoFidelity(bank) => bank.output_names(),
        }
    }

    /// Every output's prediction at `points` (mean, latent variance, noise variance).
    pub fn predict(&self, points: &[Vec<f64>]) -> Result<Vec<Prediction>> {
        Ok(match self {
            Emulator::PerOutput(bank) => bank.predict(points)?,
            Emulator::ReducedBasis(rb) => rb.predict(points)?,
            Emulator::TwoFidelity(bank) => bank.predict(points)?,
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
            Emulator::TwoFidelity(bank) => {
                bank.predict(points)?.into_iter().map(|p| p.mean).collect()
            }
        })
    }

    /// Output j's variance that no run at a point removes: a reduced basis's truncation
    /// error (0 for a GP per output).
    pub fn unresolved_variance(&self, j: usize) -> f64 {
        match self {
            Emulator::PerOutput(_) | Emulator::TwoFidelity(_) => 0.0,
            Emulator::ReducedBasis(rb) => rb.truncation_variance()[j],
        }
    }

    /// Which predictive std the emulator reports as the model's computational std.
    pub fn predictive_std(&self) -> PredictiveStd {
        match self {
            Emulator::PerOutput(bank) => bank.predictive_std(),
            Emulator::ReducedBasis(_) => PredictiveStd::default(),
            Emulator::TwoFidelity(bank) => bank.predictive_std(),
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
            Emulator::TwoFidelity(bank) => bank.gps().iter().map(OutputView::TwoFidelity).collect(),
        }
    }

    /// The GPs fitted to the (high-fidelity) runs: one per output, or one per component; of a
    /// two-fidelity emulator, per output the GP in charge at the high-fidelity runs (δ's, or
    /// that of the high-fidelity runs alone).
    pub fn fitted_gps(&self) -> Vec<&GaussianProcess> {
        match self {
            Emulator::PerOutput(bank) => bank.gps().iter().collect(),
            Emulator::ReducedBasis(rb) => rb
                .component_gps()
                .iter()
                .map(iuq_gp::ComponentGp::in_charge)
                .collect(),
            Emulator::TwoFidelity(bank) => bank
                .gps()
                .iter()
                .map(|gp| {
                    if gp.uses_low_fidelity() {
                        gp.discrepancy()
                    } else {
                        gp.single_fidelity()
                    }
                })
                .collect(),
        }
    }

    /// Each data point's GP θ ([`GaussianProcess::theta`]) where each has a GP of its own
    /// fitted to the runs alone (`None` for a reduced basis or two fidelities): the next
    /// round's warm starts ([`super::surrogate::GpStarts`]).
    pub fn warm_starts(&self) -> Option<Vec<Vec<f64>>> {
        match self {
            Emulator::PerOutput(bank) => {
                Some(bank.gps().iter().map(GaussianProcess::theta).collect())
            }
            Emulator::ReducedBasis(_) | Emulator::TwoFidelity(_) => None,
        }
    }

    /// Every output's latent posterior covariance over `points`, where each output has an
    /// emulator of its own (`None` for a reduced basis, whose outputs share its components').
    pub fn output_covariances(&self, points: &[Vec<f64>]) -> Result<Option<Vec<Vec<Vec<f64>>>>> {
        use rayon::prelude::*;
        Ok(match self {
            Emulator::ReducedBasis(_) => None,
            Emulator::PerOutput(_) | Emulator::TwoFidelity(_) => Some(
                self.output_views()
                    .par_iter()
                    .map(|view| view.posterior_covariance(points, points))
                    .collect::<iuq_gp::Result<_>>()?,
            ),
        })
    }

    /// The two-fidelity bank, where the emulator is one.
    pub fn two_fidelity(&self) -> Option<&MultiFidelityBank> {
        match self {
            Emulator::TwoFidelity(bank) => Some(bank),
            _ => None,
        }
    }

    /// Whether the emulator uses a second fidelity's runs: a two-fidelity GP per data point, or
    /// a reduced basis of two fidelities.
    pub fn is_two_fidelity(&self) -> bool {
        match self {
            Emulator::TwoFidelity(_) => true,
            Emulator::ReducedBasis(rb) => rb.is_two_fidelity(),
            Emulator::PerOutput(_) => false,
        }
    }

    /// Output j's latent variance at `theta` split by fidelity: (what a cheap run there would
    /// remove, what only an expensive run removes); of a single-fidelity emulator (0, all).
    ///
    /// # Errors
    /// A point of the wrong dimension or not finite.
    pub fn fidelity_variances(&self, j: usize, theta: &[f64]) -> Result<(f64, f64)> {
        let at = vec![theta.to_vec()];
        let (low, expensive) = match self {
            Emulator::TwoFidelity(bank) => bank.gps()[j].fidelity_variances(&at)?,
            Emulator::ReducedBasis(rb) => rb.fidelity_variances(j, &at)?,
            Emulator::PerOutput(bank) => (vec![0.0], bank.gps()[j].predict(&at)?.variance),
        };
        Ok((low[0], expensive[0]))
    }

    /// The GP of each output, where each has its own.
    pub fn per_output_gps(&self) -> Option<&[GaussianProcess]> {
        match self {
            Emulator::PerOutput(bank) => Some(bank.gps()),
            Emulator::ReducedBasis(_) | Emulator::TwoFidelity(_) => None,
        }
    }

    /// The reduced basis, where the emulator is one.
    pub fn reduced_basis(&self) -> Option<&ReducedBasis> {
        match self {
            Emulator::PerOutput(_) | Emulator::TwoFidelity(_) => None,
            Emulator::ReducedBasis(rb) => Some(rb),
        }
    }
}

impl Model for Emulator {
    fn input_names(&self) -> &[String] {
        match self {
            Emulator::PerOutput(bank) => bank.input_names(),
            Emulator::ReducedBasis(rb) => rb.input_names(),
            Emulator::TwoFidelity(bank) => bank.input_names(),
        }
    }

    fn output_names(&self) -> &[String] {
        Emulator::output_names(self)
    }

    fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
        match self {
            Emulator::PerOutput(bank) => bank.evaluate_batch(points),
            Emulator::ReducedBasis(rb) => rb.evaluate_batch(points),
            Emulator::TwoFidelity(bank) => bank.evaluate_batch(points),
        }
    }

    fn screening_batch(&self, points: &[Vec<f64>]) -> Option<iuq_core::Result<Vec<Outcome>>> {
        match self {
            Emulator::PerOutput(bank) => bank.screening_batch(points),
            Emulator::ReducedBasis(rb) => rb.screening_batch(points),
            Emulator::TwoFidelity(_) => None,
        }
    }

    fn affine_screening(&self) -> Option<&dyn iuq_core::affine_screen::AffineScreening> {
        match self {
            Emulator::ReducedBasis(rb) => rb.affine_screening(),
            Emulator::PerOutput(_) | Emulator::TwoFidelity(_) => None,
        }
    }
}
