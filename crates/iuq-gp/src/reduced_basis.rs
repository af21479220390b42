//! A reduced-basis emulator of a curve-valued model: GPs on the leading principal components of
//! the runs' outputs (Higdon, Gattiker, Williams & Rightley 2008, "Computer model calibration
//! using high-dimensional output", JASA 103(482); surmise's PCGP).
//!
//! With n runs of m outputs Y (n × m), each output centred by its mean over the runs μ_j and
//! divided by a scale s_j (the data's measurement std when the caller gives it, so that the basis
//! is judged in the units of the likelihood), Z = (Y − μ)/s = U S Vᵀ (thin SVD). The first q
//! right singular vectors v_k (q the fewest whose share of Σ S² reaches `explained_variance`, at
//! most `max_components` and n − 1) span the basis; run i's coefficients are c_ik = U_ik S_k, and
//! one GP per component is fitted to them (seed `seed + k`). At θ,
//!
//! y_j(θ) ≈ μ_j + s_j Σ_k V_jk c_k(θ),  Var = s_j² Σ_k V_jk² Var[c_k(θ)] + τ_j²,
//!
//! the components' GPs being independent, and τ_j² = s_j² · mean_i (Z_ij − Σ_k c_ik V_jk)², the
//! part of the runs' outputs the basis leaves out (the truncation error), carried into the
//! likelihood as a variance as Higdon et al. carry the discarded components. The decomposition
//! runs sequentially (faer, `Par::Seq`) and every sum in a fixed order, so the result does not
//! depend on the number of threads.
//!
//! When it pays: a curve of many points whose shapes over the prior span few dimensions (a
//! profile, a decay, a growth curve: q of 3–10 for hundreds of points), where m GPs would cost m
//! fits and m predictions per step. When the shapes do not (an oscillation whose frequency is a
//! parameter, or a few data points that each depend on θ their own way), q approaches m and
//! per-output GPs are as cheap and exact.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::matmul;
use faer::linalg::svd::{ComputeSvdVectors, svd, svd_scratch};
use faer::{Accum, Mat, MatMut, MatRef, Par};
use rayon::prelude::*;

use iuq_core::model::{Evaluation, EvaluationFailure, Model, Outcome};

use crate::bank::PredictiveStd;
use crate::component_gp::ComponentGp;
use crate::error::{GpError, Result};
use crate::fit::{CheckedFitOptions, FitOptions};
use crate::gaussian_process::GaussianProcess;
use crate::prediction::Prediction;

/// Points combined per parallel task by [`ReducedBasis`]'s `evaluate_batch`.
const COMBINE_BLOCK: usize = 64;

/// How the basis is chosen and its GPs fitted.
#[derive(Debug, Clone)]
pub struct ReducedBasisOptions {
    /// The share of the scaled outputs' variance over the runs the kept components must explain
    /// (default 0.9999).
    pub explained_variance: f64,
    /// The most components kept (default 30).
    pub max_components: usize,
    /// The scale s_j of each output (default: one scale for all, the std of every centred
    /// output value over the runs).
    pub output_scale: Option<Vec<f64>>,
    /// The options of each component's GP fit (its seed is `fit.seed + k`).
    pub fit: FitOptions,
}

impl Default for ReducedBasisOptions {
    fn default() -> Self {
        Self {
            explained_variance: 0.9999,
            max_components: 30,
            output_scale: None,
            fit: FitOptions::default(),
        }
    }
}

/// GPs on the leading principal components of a multi-output model's runs. Implements
/// [`Model`] as a [`crate::GpBank`] does: means, and the predictive stds (truncation error
/// included) as the computational std.
#[derive(Debug, Clone)]
pub struct ReducedBasis {
    input_names: Vec<String>,
    output_names: Vec<String>,
    centre: Vec<f64>,
    scale: Vec<f64>,
    /// V_jk, m rows of q.
    basis: Vec<Vec<f64>>,
    /// The share of Σ S² of each kept component.
    explained: Vec<f64>,
    /// τ_j² in output units.
    truncation_variance: Vec<f64>,
    gps: Vec<ComponentGp>,
    predictive_std: PredictiveStd,
}

impl ReducedBasis {
    /// Fit the basis and its GPs to runs `inputs` (n × d) with outputs `outputs` (n × m).
    ///
    /// # Errors
    /// Fewer than 3 runs, ragged or non-finite outputs, a non-positive scale, options out of
    /// range, a decomposition that fails, or a GP fit that fails.
    pub fn fit(
        input_names: Vec<String>,
        output_names: Vec<String>,
        inputs: &[Vec<f64>],
        outputs: &[Vec<f64>],
        options: &ReducedBasisOptions,
    ) -> Result<Self> {
        let n = outputs.len();
        let m = output_names.len();
        check_runs(inputs, outputs, m, options)?;
        let runs = ScaledRuns::of(outputs, m, options)?;
        let explained = runs
            .components
            .leading_shares(runs.limit, options.explained_variance);
        let q = explained.len();
        let basis = runs.basis(q);
        let (singular, order, u) = (
            &runs.components.singular,
            &runs.components.order,
            &runs.components.u,
        );
        let coefficients: Vec<Vec<f64>> = (0..q)
            .map(|c| {
                (0..n)
                    .map(|i| u[(i, order[c])] * singular[order[c]])
                    .collect()
            })
            .collect();
        let truncation_variance = runs.truncation_variance(0..n, &coefficients, &basis);
        let ScaledRuns { centre, scale, .. } = runs;
        let mut gps = Vec::with_capacity(q);
        for (c, y) in coefficients.iter().enumerate() {
            let fit: CheckedFitOptions = FitOptions {
                seed: options.fit.seed.wrapping_add(c as u64),
                ..options.fit
            }
            .check()?;
            gps.push(ComponentGp::Single(Box::new(GaussianProcess::fit(
                inputs, y, &fit,
            )?)));
        }
        Ok(Self {
            input_names,
            output_names,
            centre,
            scale,
            basis,
            explained,
            truncation_variance,
            gps,
            predictive_std: PredictiveStd::default(),
        })
    }

    /// Fit the basis on two fidelities' runs and emulate each component by a two-fidelity GP:
    /// the expensive runs (`high`: inputs n_H × d, outputs n_H × m) and the cheap model's
    /// (`low`, the same outputs), nested or not.
    ///
    /// The centre, scale and components are those of both sets of runs stacked (the cheap runs,
    /// many, show the shapes the curves take over the prior; the expensive ones add theirs);
    /// each run's coefficients are its scaled outputs' projections c_ik = Σ_j Z_ij V_jk, and
    /// component k is a [`crate::MultiFidelityGp`] of the expensive runs' c_·k on the cheap
    /// runs' (seed `seed + k`), which uses the cheap runs only where they help
    /// ([`crate::MultiFidelityGp::uses_low_fidelity`]). The truncation error τ_j² is the
    /// expensive runs' own: what the basis leaves out of the model being emulated.
    ///
    /// # Errors
    /// As [`ReducedBasis::fit`], for either set of runs, or a two-fidelity fit that fails.
    pub fn fit_two_fidelity(
        input_names: Vec<String>,
        output_names: Vec<String>,
        high: (&[Vec<f64>], &[Vec<f64>]),
        low: (&[Vec<f64>], &[Vec<f64>]),
        options: &ReducedBasisOptions,
    ) -> Result<Self> {
        let m = output_names.len();
        check_runs(high.0, high.1, m, options)?;
        check_runs(low.0, low.1, m, options)?;
        let stacked: Vec<Vec<f64>> = high.1.iter().chain(low.1).cloned().collect();
        let n = stacked.len();
        let runs = ScaledRuns::of(&stacked, m, options)?;
        let (z, components, limit) = (&runs.z, &runs.components, runs.limit);
        // The fewest components that explain `explained_variance` of both the stacked runs and
        // the expensive runs alone (a cheap model whose curves take other shapes must not leave
        // the expensive ones to the truncation error), at most `limit`.
        let n_high = high.1.len();
        let high_total: f64 = (0..n_high)
            .flat_map(|i| (0..m).map(move |j| (i, j)))
            .map(|(i, j)| z[(i, j)] * z[(i, j)])
            .sum();
        let mut q_high = if high_total > 0.0 { limit } else { 1 };
        let mut high_cumulative = 0.0;
        for (k, &c) in components.order[..limit].iter().enumerate() {
            if high_total <= 0.0 {
                break;
            }
            high_cumulative += (0..n_high)
                .map(|i| {
                    let c_ik: f64 = (0..m).map(|j| z[(i, j)] * components.v[(j, c)]).sum();
                    c_ik * c_ik
                })
                .sum::<f64>();
            if high_cumulative >= options.explained_variance * high_total {
                q_high = k + 1;
                break;
            }
        }
        let q = components
            .leading_shares(limit, options.explained_variance)
            .len()
            .max(q_high);
        let total = components.total();
        let explained: Vec<f64> = components.order[..q]
            .iter()
            .map(|&k| components.share(k, total))
            .collect();
        let basis = runs.basis(q);
        // c_ik of rows `rows` of Z, one vector per component.
        let project = |rows: std::ops::Range<usize>| -> Vec<Vec<f64>> {
            (0..q)
                .map(|k| {
                    rows.clone()
                        .map(|i| (0..m).map(|j| z[(i, j)] * basis[j][k]).sum())
                        .collect()
                })
                .collect()
        };
        let high_coefficients = project(0..n_high);
        let low_coefficients = project(n_high..n);
        let truncation_variance = runs.truncation_variance(0..n_high, &high_coefficients, &basis);
        let ScaledRuns { centre, scale, .. } = runs;
        let gps = (0..q)
            .into_par_iter()
            .map(|k| {
                let fit = FitOptions {
                    seed: options.fit.seed.wrapping_add(k as u64),
                    ..options.fit
                }
                .check()?;
                crate::MultiFidelityGp::fit(
                    low.0,
                    &low_coefficients[k],
                    high.0,
                    &high_coefficients[k],
                    &fit,
                )
                .map(|gp| ComponentGp::TwoFidelity(Box::new(gp)))
            })
            .collect::<Vec<_>>()
            .into_iter()
            // The first component's error, whichever thread failed first.
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            input_names,
            output_names,
            centre,
            scale,
            basis,
            explained,
            truncation_variance,
            gps,
            predictive_std: PredictiveStd::default(),
        })
    }

    /// Output j's latent variance at `points` split by fidelity: (what cheap runs there would
    /// remove, Σ_k a_jk²·ρ_k²σ²_L,k; what only expensive runs remove, Σ_k a_jk²·c_k σ²_δ,k),
    /// from each component's [`ComponentGp::fidelity_variances`] (a single-fidelity component's
    /// variance is all in the second).
    ///
    /// # Errors
    /// An output index out of range, or points of the wrong dimension or not finite.
    pub fn fidelity_variances(
        &self,
        j: usize,
        points: &[Vec<f64>],
    ) -> Result<(Vec<f64>, Vec<f64>)> {
        if j >= self.output_names.len() {
            return Err(GpError::InvalidParameter {
                what: "output index",
                reason: format!("{j} of {} outputs", self.output_names.len()),
            });
        }
        let (mut low, mut expensive) = (vec![0.0; points.len()], vec![0.0; points.len()]);
        for (k, gp) in self.gps.iter().enumerate() {
            let w = self.loading(j, k).powi(2);
            let (l, e) = gp.fidelity_variances(points)?;
            for i in 0..points.len() {
                low[i] += w * l[i];
                expensive[i] += w * e[i];
            }
        }
        Ok((low, expensive))
    }

    /// Whether some component is a two-fidelity GP ([`ReducedBasis::fit_two_fidelity`]).
    pub fn is_two_fidelity(&self) -> bool {
        self.gps.iter().any(|gp| gp.two_fidelity().is_some())
    }

    /// Report the latent std instead of the std with noise, or back.
    pub fn with_predictive_std(mut self, predictive_std: PredictiveStd) -> Self {
        self.predictive_std = predictive_std;
        self
    }

    /// The number of components kept, q.
    pub fn components(&self) -> usize {
        self.gps.len()
    }

    /// The share of the scaled outputs' variance each kept component explains.
    pub fn explained_variance(&self) -> &[f64] {
        &self.explained
    }

    /// τ_j², the truncation error's variance of each output (output units).
    pub fn truncation_variance(&self) -> &[f64] {
        &self.truncation_variance
    }

    /// The components' emulators, in order.
    pub fn component_gps(&self) -> &[ComponentGp] {
        &self.gps
    }

    /// s_j·V_jk: how much output j moves per unit of component k's coefficient.
    pub fn loading(&self, j: usize, k: usize) -> f64 {
        self.scale[j] * self.basis[j][k]
    }

    /// The input names.
    pub fn input_names(&self) -> &[String] {
        &self.input_names
    }

    /// The output names.
    pub fn output_names(&self) -> &[String] {
        &self.output_names
    }

    /// Per output, its prediction at `points`: the mean, the latent variance of the components'
    /// GPs and the noise variance they add. The truncation error is not in it (a run at θ does
    /// not lower it there): it is [`ReducedBasis::truncation_variance`], which the model's
    /// computational std adds.
    ///
    /// # Errors
    /// Points of the wrong dimension or not finite.
    pub fn predict(&self, points: &[Vec<f64>]) -> Result<Vec<Prediction>> {
        let components: Vec<Prediction> = self
            .gps
            .iter()
            .map(|gp| gp.predict(points))
            .collect::<Result<_>>()?;
        Ok(self.combine(&components, points.len()))
    }

    /// Output j's prediction at `points` alone (the components' predictions are made again for
    /// each output: callers that need every output use [`ReducedBasis::predict`]).
    ///
    /// # Errors
    /// An output index out of range, or points of the wrong dimension or not finite.
    pub fn predict_output(&self, j: usize, points: &[Vec<f64>]) -> Result<Prediction> {
        if j >= self.output_names.len() {
            return Err(GpError::InvalidParameter {
                what: "output index",
                reason: format!("{j} of {} outputs", self.output_names.len()),
            });
        }
        let components: Vec<Prediction> = self
            .gps
            .iter()
            .map(|gp| gp.predict(points))
            .collect::<Result<_>>()?;
        Ok(self.combine_output(j, &components, points.len()))
    }

    /// The outputs' predictions from the components' `predictions` at `count` points.
    fn combine(&self, components: &[Prediction], count: usize) -> Vec<Prediction> {
        (0..self.output_names.len())
            .map(|j| self.combine_output(j, components, count))
            .collect()
    }

    /// Output j's prediction from the components' `predictions` at `count` points.
    fn combine_output(&self, j: usize, components: &[Prediction], count: usize) -> Prediction {
        let (mut mean, mut variance) = (vec![self.centre[j]; count], vec![0.0; count]);
        let mut noise_variance = 0.0;
        for (k, p) in components.iter().enumerate() {
            let a = self.loading(j, k);
            for i in 0..count {
                mean[i] += a * p.mean[i];
                variance[i] += a * a * p.variance[i];
            }
            noise_variance += a * a * p.noise_variance;
        }
        Prediction {
            mean,
            variance,
            noise_variance,
        }
    }
}

/// Runs' outputs as a basis is drawn from them: centred by their means μ_j, divided by their
/// scales s_j (Z), Z's principal components, and the most components a basis may keep.
struct ScaledRuns {
    centre: Vec<f64>,
    scale: Vec<f64>,
    z: Mat<f64>,
    components: PrincipalComponents,
    /// At most `max_components`, n − 1 and the decomposition's rank, at least 1.
    limit: usize,
}

impl ScaledRuns {
    /// `outputs` (n × m, checked) with the scales `options.output_scale` or their own.
    fn of(outputs: &[Vec<f64>], m: usize, options: &ReducedBasisOptions) -> Result<Self> {
        let n = outputs.len();
        let centre: Vec<f64> = (0..m)
            .map(|j| outputs.iter().map(|r| r[j]).sum::<f64>() / n as f64)
            .collect();
        let scale = output_scale(options.output_scale.as_deref(), outputs, &centre)?;
        let z = Mat::<f64>::from_fn(n, m, |i, j| (outputs[i][j] - centre[j]) / scale[j]);
        let components = PrincipalComponents::of(&z)?;
        let limit = options
            .max_components
            .min(n - 1)
            .min(components.singular.len())
            .max(1);
        Ok(Self {
            centre,
            scale,
            z,
            components,
            limit,
        })
    }

    /// V_jk of the first `q` components (m rows of q).
    fn basis(&self, q: usize) -> Vec<Vec<f64>> {
        (0..self.z.ncols())
            .map(|j| {
                self.components.order[..q]
                    .iter()
                    .map(|&k| self.components.v[(j, k)])
                    .collect()
            })
            .collect()
    }

    /// τ_j² = s_j² · mean over `rows` of (Z_ij − Σ_k c_ik V_jk)², with `coefficients[k][i −
    /// rows.start]` the rows' coefficients on `basis`: what the basis leaves out of them.
    fn truncation_variance(
        &self,
        rows: std::ops::Range<usize>,
        coefficients: &[Vec<f64>],
        basis: &[Vec<f64>],
    ) -> Vec<f64> {
        let count = rows.len();
        (0..self.z.ncols())
            .map(|j| {
                let sum: f64 = rows
                    .clone()
                    .enumerate()
                    .map(|(r, i)| {
                        let fitted: f64 = coefficients
                            .iter()
                            .zip(&basis[j])
                            .map(|(c, v)| c[r] * v)
                            .sum();
                        (self.z[(i, j)] - fitted).powi(2)
                    })
                    .sum();
                self.scale[j] * self.scale[j] * sum / count as f64
            })
            .collect()
    }
}

/// Rejects fewer than 3 runs, inputs and outputs of different counts, options out of range
/// and outputs that are ragged (not `m` per run) or non-finite.
fn check_runs(
    inputs: &[Vec<f64>],
    outputs: &[Vec<f64>],
    m: usize,
    options: &ReducedBasisOptions,
) -> Result<()> {
    let n = outputs.len();
    if n < 3 {
        return Err(GpError::TooFewPoints {
            required: 3,
            actual: n,
        });
    }
    if inputs.len() != n {
        return Err(GpError::LengthMismatch {
            what: "runs' inputs vs. their outputs",
            expected: n,
            actual: inputs.len(),
        });
    }
    if !(options.explained_variance > 0.0 && options.explained_variance <= 1.0) {
        return Err(GpError::InvalidParameter {
            what: "explained_variance",
            reason: format!("must lie in (0, 1], got {}", options.explained_variance),
        });
    }
    if options.max_components == 0 {
        return Err(GpError::InvalidParameter {
            what: "max_components",
            reason: "must be at least 1".into(),
        });
    }
    for (i, row) in outputs.iter().enumerate() {
        if row.len() != m {
            return Err(GpError::DimensionMismatch {
                what: "run's outputs",
                index: i,
                expected: m,
                actual: row.len(),
            });
        }
        if let Some((j, v)) = row.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(GpError::NonFinite {
                what: "output",
                index: i * m + j,
                value: *v,
            });
        }
    }
    Ok(())
}

/// The scale s_j of each output: the caller's (checked finite and positive), or else one for
/// all, the std of every centred output value over the runs (1 where that is 0).
fn output_scale(given: Option<&[f64]>, outputs: &[Vec<f64>], centre: &[f64]) -> Result<Vec<f64>> {
    let (n, m) = (outputs.len(), centre.len());
    match given {
        Some(s) if s.len() != m => Err(GpError::LengthMismatch {
            what: "output scales vs. outputs",
            expected: m,
            actual: s.len(),
        }),
        Some(s) => {
            if let Some(v) = s.iter().find(|v| !(v.is_finite() && **v > 0.0)) {
                return Err(GpError::InvalidParameter {
                    what: "output scale",
                    reason: format!("must be finite and positive, got {v}"),
                });
            }
            Ok(s.to_vec())
        }
        None => {
            let sum: f64 = outputs
                .iter()
                .flat_map(|r| r.iter().zip(centre).map(|(y, c)| (y - c) * (y - c)))
                .sum();
            let s = (sum / (n * m) as f64).sqrt();
            Ok(vec![if s > 0.0 { s } else { 1.0 }; m])
        }
    }
}

/// The thin SVD Z = U S Vᵀ of the scaled runs, computed sequentially.
struct PrincipalComponents {
    /// S's diagonal, in faer's order.
    singular: Vec<f64>,
    /// Component indices by decreasing singular value (ties by index).
    order: Vec<usize>,
    u: Mat<f64>,
    v: Mat<f64>,
}

impl PrincipalComponents {
    fn of(z: &Mat<f64>) -> Result<Self> {
        let (n, m) = (z.nrows(), z.ncols());
        let size = n.min(m);
        let mut s = faer::diag::Diag::<f64>::zeros(size);
        let mut u = Mat::<f64>::zeros(n, size);
        let mut v = Mat::<f64>::zeros(m, size);
        let mut buffer = MemBuffer::new(svd_scratch::<f64>(
            n,
            m,
            ComputeSvdVectors::Thin,
            ComputeSvdVectors::Thin,
            Par::Seq,
            Default::default(),
        ));
        svd(
            z.as_ref(),
            s.as_mut(),
            Some(u.as_mut()),
            Some(v.as_mut()),
            Par::Seq,
            MemStack::new(&mut buffer),
            Default::default(),
        )
        .map_err(|e| GpError::FitFailed(format!("principal components: {e:?}")))?;
        let singular: Vec<f64> = (0..size).map(|k| s[k]).collect();
        // Components by decreasing singular value (faer's order, made sure of).
        let mut order: Vec<usize> = (0..size).collect();
        order.sort_by(|&a, &b| singular[b].total_cmp(&singular[a]).then(a.cmp(&b)));
        Ok(Self {
            singular,
            order,
            u,
            v,
        })
    }

    /// Σ S², the scaled runs' whole variance.
    fn total(&self) -> f64 {
        self.singular.iter().map(|v| v * v).sum()
    }

    /// Component k's share S_k² / Σ S² of it (0 where the runs do not vary).
    fn share(&self, k: usize, total: f64) -> f64 {
        if total > 0.0 {
            self.singular[k].powi(2) / total
        } else {
            0.0
        }
    }

    /// The share of Σ S² of each leading component kept: the fewest whose shares reach
    /// `explained_variance`, at most `limit`.
    fn leading_shares(&self, limit: usize, explained_variance: f64) -> Vec<f64> {
        let total = self.total();
        let mut q = 0;
        let mut cumulative = 0.0;
        let mut explained = Vec::new();
        while q < limit {
            let share = self.share(self.order[q], total);
            explained.push(share);
            cumulative += share;
            q += 1;
            if total <= 0.0 || cumulative >= explained_variance {
                break;
            }
        }
        explained
    }
}

impl Model for ReducedBasis {
    fn input_names(&self) -> &[String] {
        &self.input_names
    }

    fn output_names(&self) -> &[String] {
        &self.output_names
    }

    /// Per point: every output's mean, with its predictive std (components, truncation, and
    /// the components' noise unless latent) as the computational std. A point of the wrong
    /// dimension or with a non-finite coordinate is a per-point failure.
    fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
        self.outcomes(points, |probe| {
            self.gps.iter().map(|gp| gp.predict(probe)).collect()
        })
    }

    /// Per point: every output's mean, with the std of the truncation and the components'
    /// noise alone (the components' latent variances taken as zero): the screen of
    /// delayed-acceptance moves, O(n·d) per point and component instead of O(n²). Fails
    /// exactly where [`ReducedBasis::evaluate_batch`] does.
    fn screening_batch(&self, points: &[Vec<f64>]) -> Option<iuq_core::Result<Vec<Outcome>>> {
        Some(self.outcomes(points, |probe| {
            self.gps
                .iter()
                .map(|gp| {
                    let mean = gp.predict_mean(probe)?;
                    Ok(Prediction {
                        variance: vec![0.0; mean.len()],
                        mean,
                        noise_variance: gp.noise_variance(),
                    })
                })
                .collect::<Result<_>>()
        }))
    }

    fn affine_screening(&self) -> Option<&dyn iuq_core::affine_screen::AffineScreening> {
        Some(self)
    }
}

/// The screen of [`Model::screening_batch`] as an affine map: mean_j = μ_j + Σ_k a_jk c_k with
/// c_k the components' GP means, and the std of the truncation and the components' noise.
impl iuq_core::affine_screen::AffineScreening for ReducedBasis {
    fn affine_screen(&self) -> iuq_core::affine_screen::AffineScreen {
        let (m, q) = (self.output_names.len(), self.gps.len());
        let loadings: Vec<f64> = (0..q)
            .flat_map(|k| (0..m).map(move |j| self.loading(j, k)))
            .collect();
        let stds = (0..m)
            .map(|j| {
                let noise = self.gps.iter().enumerate().fold(0.0, |acc, (k, gp)| {
                    let a = loadings[k * m + j];
                    acc + a * a * gp.noise_variance()
                });
                (self.truncation_variance[j] + self.predictive_std.added_noise_variance(noise))
                    .sqrt()
            })
            .collect();
        iuq_core::affine_screen::AffineScreen {
            offset: self.centre.clone(),
            loadings,
            stds,
        }
    }

    fn screening_coefficients(
        &self,
        points: &[Vec<f64>],
    ) -> iuq_core::Result<Vec<iuq_core::affine_screen::CoefficientOutcome>> {
        let d = self.input_names.len();
        let valid: Vec<usize> = (0..points.len())
            .filter(|&i| points[i].len() == d && points[i].iter().all(|v| v.is_finite()))
            .collect();
        let probe: Vec<Vec<f64>> = valid.iter().map(|&i| points[i].clone()).collect();
        let means = self
            .gps
            .iter()
            .map(|gp| gp.predict_mean(&probe))
            .collect::<Result<Vec<_>>>()
            .map_err(|e| iuq_core::CoreError::ModelUnavailable(e.to_string()))?;
        let mut outcomes: Vec<iuq_core::affine_screen::CoefficientOutcome> = points
            .iter()
            .map(|p| {
                Err(EvaluationFailure::new(if p.len() != d {
                    format!("expected {d} inputs, got {}", p.len())
                } else {
                    "non-finite input".to_string()
                }))
            })
            .collect();
        for (slot, &i) in valid.iter().enumerate() {
            outcomes[i] = Ok(means.iter().map(|m| m[slot]).collect());
        }
        Ok(outcomes)
    }
}

impl ReducedBasis {
    /// One outcome per point from the components' predictions (`predict`) at the valid points,
    /// combined a block of points at a time by two matrix products (blocks in parallel, each
    /// product sequential, so that the result does not depend on the threads): mean_j = μ_j + Σ_k a_jk c_k, variance_j =
    /// Σ_k a_jk² Var c_k + τ_j² + Σ_k a_jk² σ_k² (the last where the noise counts), with
    /// a_jk = [`ReducedBasis::loading`]. A point of the wrong dimension or with a non-finite
    /// coordinate is a per-point failure.
    fn outcomes(
        &self,
        points: &[Vec<f64>],
        predict: impl FnOnce(&[Vec<f64>]) -> Result<Vec<Prediction>>,
    ) -> iuq_core::Result<Vec<Outcome>> {
        let d = self.input_names.len();
        let valid: Vec<usize> = (0..points.len())
            .filter(|&i| points[i].len() == d && points[i].iter().all(|v| v.is_finite()))
            .collect();
        let probe: Vec<Vec<f64>> = valid.iter().map(|&i| points[i].clone()).collect();
        let components =
            predict(&probe).map_err(|e| iuq_core::CoreError::ModelUnavailable(e.to_string()))?;
        let (m, q) = (self.output_names.len(), components.len());
        // a_jk column-major (m × q), and a_jk².
        let loadings: Vec<f64> = (0..q)
            .flat_map(|k| (0..m).map(move |j| self.loading(j, k)))
            .collect();
        let squared: Vec<f64> = loadings.iter().map(|a| a * a).collect();
        // Per output, the components' noise variance where it counts (θ does not change it).
        let noise_variance: Vec<f64> = (0..m)
            .map(|j| {
                let noise = components.iter().enumerate().fold(0.0, |acc, (k, p)| {
                    acc + squared[k * m + j] * p.noise_variance
                });
                self.predictive_std.added_noise_variance(noise)
            })
            .collect();
        let a = MatRef::from_column_major_slice(&loadings, m, q);
        let a2 = MatRef::from_column_major_slice(&squared, m, q);
        let combined: Vec<Evaluation> = (0..valid.len())
            .collect::<Vec<_>>()
            .par_chunks(COMBINE_BLOCK)
            .flat_map_iter(|slots| {
                let b = slots.len();
                // The block's coefficients and their variances, q × b column-major.
                let (mut c, mut v) = (vec![0.0; q * b], vec![0.0; q * b]);
                for (t, &slot) in slots.iter().enumerate() {
                    for (k, p) in components.iter().enumerate() {
                        c[t * q + k] = p.mean[slot];
                        v[t * q + k] = p.variance[slot];
                    }
                }
                let (mut mean, mut variance) = (vec![0.0; m * b], vec![0.0; m * b]);
                for (out, coefficients, weights) in [(&mut mean, &c, a), (&mut variance, &v, a2)] {
                    matmul::matmul(
                        MatMut::from_column_major_slice_mut(out, m, b),
                        Accum::Replace,
                        weights,
                        MatRef::from_column_major_slice(coefficients, q, b),
                        1.0,
                        Par::Seq,
                    );
                }
                (0..b)
                    .map(|t| {
                        let column = t * m..(t + 1) * m;
                        let means = mean[column.clone()]
                            .iter()
                            .zip(&self.centre)
                            .map(|(x, c)| c + x)
                            .collect();
                        let stds = variance[column]
                            .iter()
                            .zip(&self.truncation_variance)
                            .zip(&noise_variance)
                            .map(|((v, t), n)| (v + t + n).sqrt())
                            .collect();
                        Evaluation::with_std(means, stds)
                    })
                    .collect::<Vec<_>>()
            })
            .collect();
        let mut outcomes: Vec<Outcome> = points
            .iter()
            .map(|p| {
                Err(EvaluationFailure::new(if p.len() != d {
                    format!("expected {d} inputs, got {}", p.len())
                } else {
                    "non-finite input".to_string()
                }))
            })
            .collect();
        for (evaluation, &i) in combined.into_iter().zip(&valid) {
            outcomes[i] = Ok(evaluation);
        }
        Ok(outcomes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs of y(θ, x) = θ₀ exp(−θ₁ x) at 60 abscissae: a two-parameter family whose curves span
    /// few dimensions.
    fn runs(n: usize) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
        let xs: Vec<f64> = (0..60).map(|i| 0.1 * i as f64).collect();
        let inputs: Vec<Vec<f64>> = (0..n)
            .map(|i| {
                let u = (i as f64 + 0.5) / n as f64;
                let v = ((i * 7) % n) as f64 / n as f64;
                vec![1.0 + u, 0.2 + 0.6 * v]
            })
            .collect();
        let outputs = inputs
            .iter()
            .map(|t| xs.iter().map(|x| t[0] * (-t[1] * x).exp()).collect())
            .collect();
        (inputs, outputs)
    }

    fn names(prefix: &str, count: usize) -> Vec<String> {
        (0..count).map(|j| format!("{prefix}{j}")).collect()
    }

    /// A·e^(−γt)·cos(scale·ω·t) at 60 times for each θ = (A, γ, ω), and n space-filling θ of
    /// the box A ∈ [0.5, 3], γ ∈ [0.05, 0.8], ω ∈ [1, 3] (a lattice with coprime steps).
    fn oscillations(n: usize, scale: f64, offset: usize) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
        let inputs: Vec<Vec<f64>> = (0..n)
            .map(|i| {
                let u =
                    |step: usize| (((i + offset) * step) % n) as f64 / n as f64 + 0.5 / n as f64;
                vec![0.5 + 2.5 * u(1), 0.05 + 0.75 * u(7), 1.0 + 2.0 * u(11)]
            })
            .collect();
        let outputs = inputs
            .iter()
            .map(|t| {
                (0..60)
                    .map(|i| {
                        let x = 0.1 + 0.1 * i as f64;
                        t[0] * (-t[1] * x).exp() * (scale * t[2] * x).cos()
                    })
                    .collect()
            })
            .collect();
        (inputs, outputs)
    }

    /// Root mean square error of `rb` against the expensive curve at `test` points.
    fn rms_error(rb: &ReducedBasis, test: &(Vec<Vec<f64>>, Vec<Vec<f64>>)) -> f64 {
        let predictions = rb.predict(&test.0).unwrap();
        let mut sum = 0.0;
        for (j, p) in predictions.iter().enumerate() {
            for (i, mean) in p.mean.iter().enumerate() {
                sum += (mean - test.1[i][j]).powi(2);
            }
        }
        (sum / (60 * test.0.len()) as f64).sqrt()
    }

    /// With 16 expensive runs of a 3-parameter oscillation (too few for the expensive curves'
    /// shapes) and 150 runs of a cheap model whose frequency is 2 % off, the two-fidelity basis
    /// predicts the expensive curve several times better than the basis of the expensive runs
    /// alone; a cheap model of another family (a pure decay, no oscillation) leaves it no worse
    /// than about the single-fidelity basis (its components fall back to the expensive runs'
    /// GPs and the basis keeps what explains the expensive runs).
    #[test]
    fn a_cheap_model_of_the_same_shapes_makes_the_basis_better_and_an_unrelated_one_no_worse() {
        let high = oscillations(16, 1.0, 0);
        let low = oscillations(150, 1.02, 3);
        let test = oscillations(97, 1.0, 5);
        let options = ReducedBasisOptions::default();
        let single =
            ReducedBasis::fit(names("t", 3), names("y", 60), &high.0, &high.1, &options).unwrap();
        let two = ReducedBasis::fit_two_fidelity(
            names("t", 3),
            names("y", 60),
            (&high.0, &high.1),
            (&low.0, &low.1),
            &options,
        )
        .unwrap();
        assert!(two.is_two_fidelity() && !single.is_two_fidelity());
        let (e_single, e_two) = (rms_error(&single, &test), rms_error(&two, &test));
        println!("rms error: expensive runs alone {e_single:.4}, with the cheap runs {e_two:.4}");
        assert!(e_two < 0.5 * e_single, "{e_two} against {e_single}");
        // The variance a cheap run removes is part of the latent variance, and outputs sum their
        // components' parts.
        let at = vec![test.0[0].clone(), test.0[1].clone()];
        let latent = two.predict_output(7, &at).unwrap().variance;
        let (v_low, v_high) = two.fidelity_variances(7, &at).unwrap();
        for i in 0..2 {
            assert!(v_low[i] >= 0.0 && v_high[i] >= 0.0);
            assert!((v_low[i] + v_high[i] - latent[i]).abs() <= 1e-9 * latent[i].max(1e-300));
        }
        assert!(single.fidelity_variances(7, &at).unwrap().0 == vec![0.0, 0.0]);
        assert!(two.fidelity_variances(60, &at).is_err());

        let decay: (Vec<Vec<f64>>, Vec<Vec<f64>>) = {
            let (inputs, _) = oscillations(150, 1.0, 3);
            let outputs = inputs
                .iter()
                .map(|t| {
                    (0..60)
                        .map(|i| t[0] * (-t[1] * (0.1 + 0.1 * i as f64)).exp())
                        .collect()
                })
                .collect();
            (inputs, outputs)
        };
        let unrelated = ReducedBasis::fit_two_fidelity(
            names("t", 3),
            names("y", 60),
            (&high.0, &high.1),
            (&decay.0, &decay.1),
            &options,
        )
        .unwrap();
        let e_unrelated = rms_error(&unrelated, &test);
        println!("with an unrelated cheap model {e_unrelated:.4}");
        assert!(
            e_unrelated < 1.25 * e_single,
            "{e_unrelated} against {e_single}"
        );
    }

    /// The affine screen is the screen: μ + A·c(θ) gives `screening_batch`'s outputs and its
    /// stds are the screen's, at valid points (to rounding, 1e-12 of the curve's scale), and its
    /// coefficients fail where the screen does.
    #[test]
    fn the_affine_screen_reproduces_the_screen() {
        let (inputs, outputs) = runs(30);
        let rb = ReducedBasis::fit(
            names("t", 2),
            names("y", 60),
            &inputs,
            &outputs,
            &ReducedBasisOptions::default(),
        )
        .unwrap();
        let points = vec![
            vec![1.2, 0.3],
            vec![1.9, 0.75],
            vec![f64::NAN, 0.5],
            vec![1.5],
        ];
        let screened = rb.screening_batch(&points).unwrap().unwrap();
        let affine = rb.affine_screening().unwrap();
        let screen = affine.affine_screen();
        assert_eq!(screen.coefficients(), rb.components());
        let coefficients = affine.screening_coefficients(&points).unwrap();
        for (i, (outcome, c)) in screened.iter().zip(&coefficients).enumerate() {
            match (outcome, c) {
                (Ok(e), Ok(c)) => {
                    let q = screen.outputs_of(c);
                    let std = e.computational_std.as_ref().unwrap();
                    for j in 0..60 {
                        assert!((q[j] - e.outputs[j]).abs() < 1e-12, "point {i}, output {j}");
                        assert!(
                            (screen.stds[j] - std[j]).abs() < 1e-12,
                            "point {i}, std {j}"
                        );
                    }
                }
                (Err(a), Err(b)) => assert_eq!(a, b, "point {i}"),
                _ => panic!("point {i}: the screen and its coefficients disagree on failing"),
            }
        }
        assert!(coefficients[0].is_ok() && coefficients[2].is_err() && coefficients[3].is_err());
    }

    #[test]
    fn a_low_rank_family_needs_few_components_and_predicts_new_curves() {
        let (inputs, outputs) = runs(40);
        let rb = ReducedBasis::fit(
            names("t", 2),
            names("y", 60),
            &inputs,
            &outputs,
            &ReducedBasisOptions::default(),
        )
        .unwrap();
        assert!(rb.components() <= 6, "{} components", rb.components());
        let kept: f64 = rb.explained_variance().iter().sum();
        assert!(kept >= 0.9999, "{kept}");
        // The truncation error is what the basis leaves of the runs: at most 1e-4 of their
        // variance, on average over the outputs.
        let n = outputs.len() as f64;
        let centre: Vec<f64> = (0..60)
            .map(|j| outputs.iter().map(|r| r[j]).sum::<f64>() / n)
            .collect();
        let total: f64 = outputs
            .iter()
            .flat_map(|r| r.iter().zip(&centre).map(|(y, c)| (y - c).powi(2)))
            .sum::<f64>()
            / (n * 60.0);
        let mean_truncation = rb.truncation_variance().iter().sum::<f64>() / 60.0;
        assert!(
            mean_truncation <= 1e-4 * total * (1.0 + 1e-9),
            "{mean_truncation} vs {total}"
        );
        let theta = vec![vec![1.37, 0.55]];
        let predicted = rb.predict(&theta).unwrap();
        let xs: Vec<f64> = (0..60).map(|i| 0.1 * i as f64).collect();
        for (j, p) in predicted.iter().enumerate() {
            let exact = 1.37 * (-0.55 * xs[j]).exp();
            assert!(
                (p.mean[0] - exact).abs() < 5e-3,
                "output {j}: {} vs {exact}",
                p.mean[0]
            );
            assert!(p.variance[0] >= 0.0);
        }
        // As a model: the same means, stds with the truncation error and the noise.
        let outcome = rb.evaluate_batch(&theta).unwrap().remove(0).unwrap();
        assert_eq!(outcome.outputs[7], predicted[7].mean[0]);
        let std = outcome.computational_std.unwrap()[7];
        let expected =
            (predicted[7].variance[0] + rb.truncation_variance()[7] + predicted[7].noise_variance)
                .sqrt();
        assert!(
            (std - expected).abs() <= 1e-15 * expected.max(1.0),
            "{std} vs {expected}"
        );
        // One output alone is the same as all of them.
        let alone = rb.predict_output(7, &theta).unwrap();
        assert_eq!(alone, predicted[7]);
    }

    #[test]
    fn fewer_components_leave_their_share_as_truncation_error() {
        let (inputs, outputs) = runs(30);
        let options = ReducedBasisOptions {
            max_components: 1,
            ..Default::default()
        };
        let rb =
            ReducedBasis::fit(names("t", 2), names("y", 60), &inputs, &outputs, &options).unwrap();
        assert_eq!(rb.components(), 1);
        // The left-out share of the variance is the mean truncation variance over the outputs.
        let n = outputs.len() as f64;
        let m = 60.0;
        let centre: Vec<f64> = (0..60)
            .map(|j| outputs.iter().map(|r| r[j]).sum::<f64>() / n)
            .collect();
        let total: f64 = outputs
            .iter()
            .flat_map(|r| r.iter().zip(&centre).map(|(y, c)| (y - c).powi(2)))
            .sum::<f64>()
            / (n * m);
        let left = 1.0 - rb.explained_variance()[0];
        let mean_truncation = rb.truncation_variance().iter().sum::<f64>() / m;
        assert!(
            (mean_truncation - left * total).abs() < 1e-10 * total.max(1.0),
            "{mean_truncation} vs {}",
            left * total
        );
    }

    /// The screen of delayed acceptance: the same means, with the truncation and the noise
    /// in the std but not the components' latent variances.
    #[test]
    fn the_screen_has_the_means_and_the_truncation_and_noise_std() {
        let (inputs, outputs) = runs(30);
        let rb = ReducedBasis::fit(
            names("t", 2),
            names("y", 60),
            &inputs,
            &outputs,
            &ReducedBasisOptions::default(),
        )
        .unwrap();
        let points = vec![vec![1.3, 0.4], vec![0.2], vec![2.1, 0.9]];
        let full = rb.evaluate_batch(&points).unwrap();
        let screen = rb.screening_batch(&points).unwrap().unwrap();
        assert!(full[1].is_err() && screen[1].is_err());
        let predictions = rb.predict(&points[..1]).unwrap();
        for i in [0, 2] {
            let (f, s) = (full[i].as_ref().unwrap(), screen[i].as_ref().unwrap());
            for j in 0..60 {
                assert!((f.outputs[j] - s.outputs[j]).abs() <= 1e-12 * f.outputs[j].abs().max(1.0));
                let p = &predictions[j];
                let expected = (rb.truncation_variance()[j] + p.noise_variance).sqrt();
                let screened = s.computational_std.as_ref().unwrap()[j];
                assert!(
                    (screened - expected).abs() <= 1e-12 * expected,
                    "{screened} vs {expected}"
                );
                assert!(screened <= f.computational_std.as_ref().unwrap()[j]);
            }
        }
    }

    #[test]
    fn bad_input_is_an_error() {
        let (inputs, mut outputs) = runs(10);
        let fit = |i: &[Vec<f64>], o: &[Vec<f64>], opt: &ReducedBasisOptions| {
            ReducedBasis::fit(names("t", 2), names("y", 60), i, o, opt)
        };
        let d = ReducedBasisOptions::default();
        assert!(fit(&inputs[..2], &outputs[..2], &d).is_err());
        assert!(fit(&inputs[..5], &outputs, &d).is_err());
        let bad = ReducedBasisOptions {
            explained_variance: 0.0,
            ..Default::default()
        };
        assert!(fit(&inputs, &outputs, &bad).is_err());
        let bad = ReducedBasisOptions {
            output_scale: Some(vec![1.0; 59]),
            ..Default::default()
        };
        assert!(fit(&inputs, &outputs, &bad).is_err());
        outputs[3][4] = f64::NAN;
        assert!(fit(&inputs, &outputs, &d).is_err());
    }
}
