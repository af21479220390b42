//! Hyper-parameter fitting: maximise the log marginal likelihood over θ in a box of log
//! bounds with the bounded quasi-Newton method of [`crate::optimizer`], from several starts.
//!
//! Starts: one data-driven θ ([`FitOptions::n_restarts`] = 0 gives only this one) plus
//! `n_restarts` points of a random Latin hypercube in the log-bounds box, drawn from the keyed
//! stream `(seed, GP_MULTI_START, index)` before any run starts. The runs are independent and
//! execute in parallel (rayon), each with its own workspace and a sequential factorisation, so
//! the result does not depend on the number of threads. The GP is the run with the largest
//! LML on all training points; ties go to the earlier start.
//!
//! With more than 2·[`FitOptions::screening_points`] training points the starts are first
//! screened on a subset and only distinct candidates are refined on all points
//! ([`crate::screening`]).

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use iuq_core::random::{stages::GP_MULTI_START, stream};

use crate::bounds::Bounds;
use crate::diagnostics::{FitDiagnostics, FitWarning, RunReport, StartReport};
use crate::error::{GpError, Result};
use crate::gaussian_process::{Covariance, GaussianProcess, Prepared, bound_warnings, prepare};
use crate::kernel::{Hyperparameters, Kernel};
use crate::log_marginal_likelihood::{LmlWorkspace, validate_jitter};
use crate::multi_start::{data_driven_start, latin_hypercube};
use crate::optimizer::{Objective, OptimizerOptions, Termination, minimize_bounded_objective};
use crate::screening;

/// Options of [`fit`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct FitOptions {
    /// The kernel variant (default: ARD with c and σ² estimated).
    pub kernel: Kernel,
    /// Bounds of the hyper-parameters (default: [`Bounds::default`], for scaled data).
    pub bounds: Bounds,
    /// Latin-hypercube starts in addition to the data-driven start (default 10, as
    /// scikit-learn's `n_restarts_optimizer=10`: 11 runs).
    pub n_restarts: usize,
    /// Map the training inputs onto the unit cube (default true).
    pub scale_inputs: bool,
    /// Standardise the outputs, mean 0 and std 1 with ddof 0 (default true).
    pub standardize_outputs: bool,
    /// Added to the diagonal of K (scikit-learn's `alpha`; default 1e−10).
    pub jitter: f64,
    /// Seed of the keyed random stream of the multi-start design (default 0).
    pub seed: u64,
    /// Settings of the quasi-Newton optimiser.
    pub optimizer: OptimizerOptions,
    /// Screening subset size m: with n > 2m training points, every start is first optimised
    /// on m of them and only the distinct end points are refined on all n (default 128;
    /// 0 optimises every start on all points). See [`crate::screening`].
    pub screening_points: usize,
    /// A leave-one-out Q2 at or below this is reported as degenerate (default 0.5: the GP
    /// explains less than half of the held-out variance; pure noise gives 0–0.2, because the
    /// hyper-parameters are fitted to the same data).
    pub min_leave_one_out_q2: f64,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            kernel: Kernel::ard(),
            bounds: Bounds::default(),
            n_restarts: 10,
            scale_inputs: true,
            standardize_outputs: true,
            jitter: 1e-10,
            seed: 0,
            optimizer: OptimizerOptions::default(),
            screening_points: 128,
            min_leave_one_out_q2: 0.5,
        }
    }
}

impl FitOptions {
    /// Checks kernel, bounds, jitter, optimiser settings and threshold, and returns the options
    /// as the value [`fit`] takes.
    ///
    /// # Errors
    /// The first invalid setting, named.
    pub fn check(self) -> Result<CheckedFitOptions> {
        self.kernel.validate()?;
        self.bounds.validate()?;
        validate_jitter(self.jitter)?;
        self.optimizer.validate()?;
        if !self.min_leave_one_out_q2.is_finite() {
            return Err(GpError::InvalidParameter {
                what: "min_leave_one_out_q2",
                reason: "must be finite".into(),
            });
        }
        if self.n_restarts > MAX_RESTARTS {
            return Err(GpError::InvalidParameter {
                what: "n_restarts",
                reason: format!("at most {MAX_RESTARTS}, got {}", self.n_restarts),
            });
        }
        Ok(CheckedFitOptions(self))
    }
}

/// The most optimizer restarts a fit takes (each is a full L-BFGS-B run; scikit-learn's
/// default is 0, iuq's 10).
pub const MAX_RESTARTS: usize = 10_000;

/// Fit options that passed [`FitOptions::check`]; read them through `Deref`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CheckedFitOptions(FitOptions);

impl CheckedFitOptions {
    /// The options as plain data.
    pub fn options(&self) -> &FitOptions {
        &self.0
    }
}

impl std::ops::Deref for CheckedFitOptions {
    type Target = FitOptions;
    fn deref(&self) -> &FitOptions {
        &self.0
    }
}

impl GaussianProcess {
    /// Fits a GP to (`x`, `y`) by maximising the log marginal likelihood ([`crate::fit()`]).
    pub fn fit(x: &[Vec<f64>], y: &[f64], options: &CheckedFitOptions) -> Result<Self> {
        fit(x, y, options)
    }

    /// Fits like [`GaussianProcess::fit`], with an earlier fit's θ as a warm start
    /// ([`crate::fit_warm()`]).
    pub fn fit_warm(
        x: &[Vec<f64>],
        y: &[f64],
        options: &CheckedFitOptions,
        warm: &[f64],
    ) -> Result<Self> {
        fit_warm(x, y, options, warm)
    }

    /// Conditions a GP with the given hyper-parameters (scaled units; no optimisation) on
    /// (`x`, `y`), using the kernel, scalings, jitter and Q2 threshold of `options`.
    pub fn with_hyperparameters(
        x: &[Vec<f64>],
        y: &[f64],
        hyperparameters: Hyperparameters,
        options: &CheckedFitOptions,
    ) -> Result<Self> {
        let prepared = prepare(x, y, options.scale_inputs, options.standardize_outputs)?;
        hyperparameters.validate(&options.kernel, prepared.x.d)?;
        Self::assemble(
            x,
            y,
            prepared,
            Covariance {
                kernel: options.kernel,
                hyperparameters,
                jitter: options.jitter,
            },
            options.min_leave_one_out_q2,
            FitDiagnostics::default(),
        )
    }
}

/// Fits a GP to training inputs `x` (one row per point) and outputs `y` by maximising the log
/// marginal likelihood (see the module documentation).
///
/// # Errors
/// Invalid options, fewer than 2 points, ragged or non-finite data, or no start that can be
/// evaluated. Degenerate optima are not errors: they come back as warnings in
/// [`GaussianProcess::diagnostics`].
pub fn fit(x: &[Vec<f64>], y: &[f64], options: &CheckedFitOptions) -> Result<GaussianProcess> {
    fit_with_stream(x, y, options, 0, None)
}

/// [`fit`] with `warm`, the θ (log space, [`GaussianProcess::theta`]) of an earlier fit of the
/// same output — typically on most of the same runs — as one more start.
///
/// The warm start changes where an optimum is polished, not which optima are refined nor so
/// which wins: it is screened on the subset after the other starts, the candidates to refine
/// are chosen among the other starts' end points alone ([`crate::screening`]), and the
/// candidate whose optimum the warm start's subset run ended at (the same θ within 1 % or the
/// same subset LML within [`crate::screening::MERGE_LML`]) is refined on all points from the
/// warm θ instead of from its subset end point; a warm start that ended elsewhere is not
/// refined. From the warm θ the refinement takes a few LML evaluations instead of tens, as an
/// optimum moves little when a few runs join. Without screening (n ≤ 2·[`FitOptions::screening_points`]), or with a θ of
/// the wrong length, `warm` is ignored and the fit is [`fit`]'s.
///
/// # Errors
/// As [`fit`].
///
/// # Example
/// ```
/// use iuq_gp::{FitOptions, GaussianProcess};
/// let x: Vec<Vec<f64>> = (0..300).map(|i| vec![(i as f64 * 0.618_034) % 1.0]).collect();
/// let y: Vec<f64> = x.iter().map(|p| (6.0 * p[0]).sin()).collect();
/// let options = FitOptions { n_restarts: 3, ..FitOptions::default() }.check()?;
/// let cold = GaussianProcess::fit(&x[..280], &y[..280], &options)?;
/// let warm = GaussianProcess::fit_warm(&x, &y, &options, &cold.theta())?;
/// assert!(warm.log_marginal_likelihood().is_finite());
/// # Ok::<(), iuq_gp::GpError>(())
/// ```
pub fn fit_warm(
    x: &[Vec<f64>],
    y: &[f64],
    options: &CheckedFitOptions,
    warm: &[f64],
) -> Result<GaussianProcess> {
    fit_with_stream(x, y, options, 0, Some(warm))
}

/// [`fit`] with the multi-start design drawn from stream `(seed, GP_MULTI_START, index)`
/// (a bank fits output j with index j) and an optional warm start ([`fit_warm`]).
pub(crate) fn fit_with_stream(
    x: &[Vec<f64>],
    y: &[f64],
    options: &CheckedFitOptions,
    index: u64,
    warm: Option<&[f64]>,
) -> Result<GaussianProcess> {
    let prepared = prepare(x, y, options.scale_inputs, options.standardize_outputs)?;
    let kernel = options.kernel;
    let d = prepared.x.d;
    let (lower, upper) = options.bounds.log_box(&kernel, d);
    let mut starts = vec![clamp_to_box(
        &data_driven_start(&kernel, &prepared.x, &prepared.y),
        &lower,
        &upper,
    )];
    let mut rng = stream(options.seed, GP_MULTI_START, index);
    starts.extend(latin_hypercube(
        options.n_restarts,
        &lower,
        &upper,
        &mut rng,
    ));

    let screen = options.screening_points >= 2 && prepared.x.n > 2 * options.screening_points;
    let warm_start = warm.filter(|w| screen && w.len() == lower.len()).map(|w| {
        starts.push(clamp_to_box(w, &lower, &upper));
        starts.len() - 1
    });
    let mut reports = if screen {
        screened_runs(
            &prepared, &kernel, options, &starts, warm_start, &lower, &upper,
        )
    } else {
        Vec::new()
    };
    if reports
        .iter()
        .all(|r| r.log_marginal_likelihood().is_none())
    {
        // No screening, or no refinement succeeded: every start on all points.
        reports = starts
            .par_iter()
            .map(|start| StartReport {
                start: start.clone(),
                on_subset: None,
                on_all_points: Some(run(&prepared, &kernel, options, start, &lower, &upper, 1.0)),
                merged_into: None,
                outranked_by: None,
                refined_from: None,
            })
            .collect();
    }

    let best = reports
        .iter()
        .enumerate()
        .filter_map(|(i, r)| r.log_marginal_likelihood().map(|v| (i, v)))
        .fold(None, |best: Option<(usize, f64)>, (i, v)| match best {
            Some((_, bv)) if bv >= v => best,
            _ => Some((i, v)),
        });
    let Some((best_index, _)) = best else {
        let reason = reports
            .iter()
            .flat_map(|r| r.on_subset.iter().chain(&r.on_all_points))
            .find_map(|r| r.error.clone())
            .unwrap_or_else(|| "no start".into());
        return Err(GpError::FitFailed(format!(
            "none of {} starts could be evaluated: {reason}",
            reports.len()
        )));
    };
    let Some(best_run) = reports[best_index].on_all_points.clone() else {
        return Err(GpError::FitFailed("best start has no run".into()));
    };
    let h = kernel.hyperparameters(&best_run.theta, d)?;
    let mut warnings = bound_warnings(&kernel, &h, &options.bounds);
    let failed = reports.iter().filter(|r| r.failed()).count();
    if failed > 0 {
        warnings.push(FitWarning::FailedStarts {
            failed,
            total: reports.len(),
        });
    }
    if let (Some(termination), Some(pg)) = (best_run.termination, best_run.projected_gradient_norm)
    {
        let suspicious = match termination {
            Termination::MaxIterations | Termination::MaxEvaluations => true,
            // A line search that cannot improve is normal at the optimum; report it only
            // when the gradient is still far from zero.
            Termination::LineSearchFailed => pg > 1e-2,
            _ => false,
        };
        if suspicious {
            warnings.push(FitWarning::NotConverged {
                termination,
                projected_gradient_norm: pg,
            });
        }
    }
    let diagnostics = FitDiagnostics {
        warnings,
        leave_one_out_q2: None,
        optimized: true,
        best_start: Some(best_index),
        starts: reports,
    };
    GaussianProcess::assemble(
        x,
        y,
        prepared,
        Covariance {
            kernel,
            hyperparameters: h,
            jitter: options.jitter,
        },
        options.min_leave_one_out_q2,
        diagnostics,
    )
}

/// −LML as an [`Objective`]: the value needs the Cholesky factor (n³/3 flops), the gradient
/// additionally K⁻¹ (2n³/3), computed only where the line search accepts a step.
struct NegativeLml<'a> {
    prepared: &'a Prepared,
    kernel: &'a Kernel,
    jitter: f64,
    workspace: LmlWorkspace,
    /// Hyper-parameters of the last successful `value` call.
    current: Option<Hyperparameters>,
}

impl Objective for NegativeLml<'_> {
    fn value(&mut self, theta: &[f64]) -> Option<f64> {
        self.current = None;
        let h = self.kernel.hyperparameters(theta, self.prepared.x.d).ok()?;
        self.workspace
            .factorize(&self.prepared.x, &h, self.jitter)
            .ok()?;
        let lml = self.workspace.solve(&self.prepared.y);
        if !lml.is_finite() {
            return None;
        }
        self.current = Some(h);
        Some(-lml)
    }

    fn gradient(&mut self, gradient: &mut [f64]) -> bool {
        let Some(h) = &self.current else {
            return false;
        };
        self.workspace.invert();
        self.workspace
            .gradient(&self.prepared.x, self.kernel, h, gradient);
        for g in gradient.iter_mut() {
            *g = -*g;
        }
        gradient.iter().all(|g| g.is_finite())
    }
}

/// θ with each coordinate clamped into [lower, upper].
fn clamp_to_box(theta: &[f64], lower: &[f64], upper: &[f64]) -> Vec<f64> {
    theta
        .iter()
        .zip(lower.iter().zip(upper))
        .map(|(t, (lo, hi))| t.clamp(*lo, *hi))
        .collect()
}

/// Screens every start on a subset, merges coinciding end points and refines the rest on all
/// points ([`crate::screening`]); the candidate the warm start (`starts[warm]`) screened into
/// is refined from the warm θ itself ([`fit_warm`]).
fn screened_runs(
    prepared: &Prepared,
    kernel: &Kernel,
    options: &FitOptions,
    starts: &[Vec<f64>],
    warm: Option<usize>,
    lower: &[f64],
    upper: &[f64],
) -> Vec<StartReport> {
    let subset = screening::subset(prepared, options.screening_points);
    let coarse: Vec<RunReport> = starts
        .par_iter()
        .map(|start| run(&subset, kernel, options, start, lower, upper, 1.0))
        .collect();
    let ends: Vec<(Vec<f64>, Option<f64>)> = coarse
        .iter()
        .map(|r| (r.theta.clone(), r.log_marginal_likelihood))
        .collect();
    // The plan of the multi-start alone: the warm start only chooses where the candidate it
    // screened into is refined from, never which candidates are refined.
    let cold = warm.unwrap_or(starts.len());
    let mut plan = screening::refinement_plan(&ends[..cold]);
    let warm_candidate = warm.and_then(|w| screening::coinciding_candidate(&ends, &plan, w));
    if warm.is_some() {
        plan.push(match warm_candidate {
            Some(r) => screening::Plan::MergedInto(r),
            None => screening::Plan::Unmatched,
        });
    }
    let refine: Vec<usize> = (0..starts.len())
        .filter(|&i| plan[i] == screening::Plan::Refine)
        .collect();
    let refined_from = |i: usize| warm.filter(|_| warm_candidate == Some(i));
    let refined: Vec<RunReport> = refine
        .par_iter()
        .map(|&i| {
            let from = refined_from(i).map_or(&coarse[i].theta, |w| &starts[w]);
            run(
                prepared,
                kernel,
                options,
                from,
                lower,
                upper,
                screening::REFINEMENT_TOLERANCE_FACTOR,
            )
        })
        .collect();
    let mut refined = refine.into_iter().zip(refined).peekable();
    starts
        .iter()
        .zip(coarse)
        .enumerate()
        .map(|(i, (start, on_subset))| {
            let on_all_points = refined.next_if(|(j, _)| *j == i).map(|(_, r)| r);
            StartReport {
                start: start.clone(),
                on_subset: Some(on_subset),
                refined_from: on_all_points.as_ref().and_then(|_| refined_from(i)),
                on_all_points,
                merged_into: match plan[i] {
                    screening::Plan::MergedInto(j) => Some(j),
                    _ => None,
                },
                outranked_by: match plan[i] {
                    screening::Plan::Outranked(j) => Some(j),
                    _ => None,
                },
            }
        })
        .collect()
}

/// One optimiser run from `start` on `data`, minimising −LML (function tolerance scaled by
/// `tolerance_factor`).
fn run(
    data: &Prepared,
    kernel: &Kernel,
    options: &FitOptions,
    start: &[f64],
    lower: &[f64],
    upper: &[f64],
    tolerance_factor: f64,
) -> RunReport {
    let mut objective = NegativeLml {
        prepared: data,
        kernel,
        jitter: options.jitter,
        workspace: LmlWorkspace::new(data.x.n),
        current: None,
    };
    let optimizer = OptimizerOptions {
        function_tolerance: options.optimizer.function_tolerance * tolerance_factor,
        ..options.optimizer
    };
    match minimize_bounded_objective(&mut objective, start, lower, upper, &optimizer) {
        Ok(m) => RunReport {
            theta: m.x,
            log_marginal_likelihood: Some(-m.value),
            iterations: m.iterations,
            evaluations: m.evaluations,
            gradient_evaluations: m.gradient_evaluations,
            termination: Some(m.termination),
            projected_gradient_norm: Some(m.projected_gradient_norm),
            error: None,
        },
        Err(e) => RunReport {
            theta: start.to_vec(),
            log_marginal_likelihood: None,
            iterations: 0,
            evaluations: 1,
            gradient_evaluations: 0,
            termination: None,
            projected_gradient_norm: None,
            error: Some(e.to_string()),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::Variance;
    use crate::test_data::{quasi_random_data, spec_data};

    fn raw(standardize_outputs: bool) -> FitOptions {
        FitOptions {
            scale_inputs: false,
            standardize_outputs,
            ..Default::default()
        }
    }

    #[test]
    fn reaches_the_reference_optimum_unnormalised() {
        let (x, y) = spec_data();
        let gp = fit(&x, &y, &raw(false).check().unwrap()).unwrap();
        assert!(
            gp.log_marginal_likelihood() >= 137.66278 - 1e-4,
            "{} {:?}",
            gp.log_marginal_likelihood(),
            gp.diagnostics()
        );
        assert!(gp.diagnostics().optimized);
        assert!(
            !gp.diagnostics().is_degenerate(),
            "{:?}",
            gp.diagnostics().messages()
        );
    }

    #[test]
    fn reaches_the_reference_optimum_standardised_and_predicts_like_scikit_learn() {
        let (x, y) = spec_data();
        let gp = fit(&x, &y, &raw(true).check().unwrap()).unwrap();
        assert!(
            gp.log_marginal_likelihood() >= 121.03245 - 1e-4,
            "{}",
            gp.log_marginal_likelihood()
        );
        // Looser check of our own optimum against scikit-learn's predictions (docs/methods.md §7).
        let pts = vec![
            vec![0.1, 0.2, 0.3],
            vec![0.5, 0.5, 0.5],
            vec![0.9, 0.05, 0.7],
        ];
        let p = gp.predict(&pts).unwrap();
        let mean = [0.779165520919, 0.500913086381, -0.229857992164];
        let std = [0.00918415919, 0.008652872795, 0.010347819603];
        for (i, s) in p.std_with_noise().iter().enumerate() {
            assert!((p.mean[i] - mean[i]).abs() < 1e-4, "{i}: {}", p.mean[i]);
            assert!((s - std[i]).abs() < 1e-2 * std[i], "{i}: {s}");
        }
        // Scaling the inputs to the unit cube reaches the same optimum (the LML is invariant).
        let scaled = fit(&x, &y, &FitOptions::default().check().unwrap()).unwrap();
        assert!((scaled.log_marginal_likelihood() - gp.log_marginal_likelihood()).abs() < 1e-4);
        assert!(scaled.loo_q2().unwrap() > 0.99);
    }

    #[test]
    fn every_kernel_variant_fits() {
        let (x, y) = spec_data();
        for kernel in [
            Kernel::isotropic(),
            Kernel::study_original(),
            Kernel {
                noise_variance: Variance::Fixed(1e-4),
                ..Kernel::ard()
            },
        ] {
            let opts = FitOptions {
                kernel,
                n_restarts: 4,
                ..Default::default()
            };
            let gp = fit(&x, &y, &opts.check().unwrap()).unwrap();
            assert_eq!(gp.theta().len(), kernel.n_theta(3));
            assert!(gp.log_marginal_likelihood().is_finite());
            if let Variance::Fixed(c) = kernel.signal_variance {
                assert_eq!(gp.hyperparameters().signal_variance, c);
            }
            // The optimum is stationary or at a bound: no better point nearby.
            let (xs, ys) = (gp.x.clone(), {
                let s = gp.output_scaling();
                y.iter().map(|v| s.apply(*v)).collect::<Vec<_>>()
            });
            let mut ws = LmlWorkspace::new(xs.n);
            let theta = gp.theta();
            let (lo, hi) = opts.bounds.log_box(&kernel, 3);
            for p in 0..theta.len() {
                for step in [-1e-3, 1e-3] {
                    let mut t = theta.clone();
                    t[p] = (t[p] + step).clamp(lo[p], hi[p]);
                    let h = kernel.hyperparameters(&t, 3).unwrap();
                    let v = ws
                        .evaluate(&xs, &ys, &kernel, &h, opts.jitter, None)
                        .unwrap();
                    assert!(v <= gp.log_marginal_likelihood() + 1e-6, "{kernel:?} θ{p}");
                }
            }
        }
    }

    #[test]
    fn result_does_not_depend_on_the_thread_count() {
        let (x, y) = quasi_random_data(80);
        let opts = FitOptions {
            n_restarts: 5,
            seed: 11,
            ..Default::default()
        };
        let run = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| fit(&x, &y, &opts.check().unwrap()).unwrap())
        };
        let (a, b) = (run(1), run(3));
        assert_eq!(a.theta(), b.theta());
        assert_eq!(a.diagnostics(), b.diagnostics());
        // Another seed gives other starts.
        let c = fit(&x, &y, &FitOptions { seed: 12, ..opts }.check().unwrap()).unwrap();
        assert_ne!(
            a.diagnostics().starts[1].start,
            c.diagnostics().starts[1].start
        );
        assert_eq!(a.diagnostics().starts.len(), 6);
    }

    /// Pure noise: the likelihood prefers a GP that interpolates the noise with short length
    /// scales (K nearly diagonal), whose leave-one-out Q2 is near 0 (0–0.2 from the
    /// selection bias of fitting the hyper-parameters to the same data).
    #[test]
    fn pure_noise_is_reported_as_degenerate() {
        for (n, salt) in [(40usize, 1u64), (60, 1), (60, 2), (100, 2)] {
            let (x, _) = quasi_random_data(n);
            let y: Vec<f64> = (0..n as u64)
                .map(|i| {
                    let h = iuq_core::random::splitmix64(i ^ (salt << 20) ^ 0xabcdef);
                    (h >> 11) as f64 / (1u64 << 53) as f64 - 0.5
                })
                .collect();
            let gp = fit(&x, &y, &FitOptions::default().check().unwrap()).unwrap();
            let diag = gp.diagnostics();
            assert!(
                diag.is_degenerate(),
                "n={n}: {:?} {:?}",
                gp.hyperparameters(),
                diag.messages()
            );
            assert!(diag.leave_one_out_q2.unwrap() < 0.3);
            assert!(
                diag.warnings
                    .iter()
                    .any(|w| matches!(w, FitWarning::LowLeaveOneOutQ2 { .. }))
            );
        }
    }

    /// Screening on a subset reaches the optimum of optimising every start on all points,
    /// with far fewer full-data evaluations, independently of the thread count.
    #[test]
    fn screening_reaches_the_full_multi_start_optimum() {
        let (x, y) = quasi_random_data(300);
        let screened_options = FitOptions {
            n_restarts: 6,
            screening_points: 100,
            ..Default::default()
        };
        let run = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| fit(&x, &y, &screened_options.check().unwrap()).unwrap())
        };
        let screened = run(2);
        let full = fit(
            &x,
            &y,
            &FitOptions {
                screening_points: 0,
                ..screened_options
            }
            .check()
            .unwrap(),
        )
        .unwrap();
        let (s, f) = (screened.diagnostics(), full.diagnostics());
        assert!(
            screened.log_marginal_likelihood() >= full.log_marginal_likelihood() - 1e-6,
            "{} vs {}",
            screened.log_marginal_likelihood(),
            full.log_marginal_likelihood()
        );
        assert!(s.starts.iter().all(|r| r.on_subset.is_some()));
        assert!(
            f.starts
                .iter()
                .all(|r| r.on_subset.is_none() && r.on_all_points.is_some())
        );
        assert!(s.starts.iter().any(|r| r.merged_into.is_some()));
        assert!(s.total_evaluations() * 2 < f.total_evaluations());
        assert!(s.total_screening_evaluations() > 0);
        let best = s.best_start.unwrap();
        assert_eq!(
            s.starts[best].log_marginal_likelihood(),
            Some(screened.log_marginal_likelihood())
        );
        let single = run(1);
        assert_eq!(single.theta(), screened.theta());
        assert_eq!(single.diagnostics(), screened.diagnostics());
    }

    /// A warm start from the fit on fewer runs reaches the cold multi-start's optimum on all
    /// runs (the same LML to the refinement's tolerance, θ within 1 %) with fewer full-data
    /// LML evaluations; one of the wrong length, or without screening, changes nothing.
    #[test]
    fn a_warm_start_polishes_the_multi_start_optimum_for_less() {
        let (x, y) = quasi_random_data(300);
        let options = FitOptions {
            n_restarts: 6,
            screening_points: 100,
            ..Default::default()
        }
        .check()
        .unwrap();
        let earlier = fit(&x[..280], &y[..280], &options).unwrap();
        let cold = fit(&x, &y, &options).unwrap();
        let warm = fit_warm(&x, &y, &options, &earlier.theta()).unwrap();
        let (c, w) = (
            cold.log_marginal_likelihood(),
            warm.log_marginal_likelihood(),
        );
        assert!((w - c).abs() <= 1e-6 * c.abs(), "warm {w} vs cold {c}");
        for (a, b) in warm.theta().iter().zip(cold.theta()) {
            assert!(
                (a - b).abs() < 1e-2,
                "{:?} vs {:?}",
                warm.theta(),
                cold.theta()
            );
        }
        let (wd, cd) = (warm.diagnostics(), cold.diagnostics());
        assert_eq!(wd.starts.len(), cd.starts.len() + 1);
        assert!(
            wd.total_evaluations() < cd.total_evaluations(),
            "{} vs {}",
            wd.total_evaluations(),
            cd.total_evaluations()
        );
        let wrong_length = fit_warm(&x, &y, &options, &[0.0]).unwrap();
        assert_eq!(wrong_length.theta(), cold.theta());
        assert_eq!(wrong_length.diagnostics(), cold.diagnostics());
        let small = fit(&x[..150], &y[..150], &options).unwrap();
        let small_warm = fit_warm(&x[..150], &y[..150], &options, &earlier.theta()).unwrap();
        assert_eq!(small_warm.theta(), small.theta());
    }

    #[test]
    fn bad_inputs_are_errors() {
        let (x, y) = spec_data();
        let o = FitOptions::default();
        assert!(matches!(
            fit(&x[..1], &y[..1], &o.check().unwrap()),
            Err(GpError::TooFewPoints { .. })
        ));
        assert!(fit(&x, &y[..5], &o.check().unwrap()).is_err());
        assert!(fit(&[], &[], &o.check().unwrap()).is_err());
        let mut xb = x.clone();
        xb[4][1] = f64::INFINITY;
        assert!(matches!(
            fit(&xb, &y, &o.check().unwrap()),
            Err(GpError::NonFinite { .. })
        ));
        let mut xb = x.clone();
        xb[4].push(0.0);
        assert!(matches!(
            fit(&xb, &y, &o.check().unwrap()),
            Err(GpError::DimensionMismatch { .. })
        ));
        let bad = FitOptions {
            jitter: f64::NAN,
            ..o
        };
        assert!(
            bad.check().is_err(),
            "invalid options are refused by check()"
        );
        let bad = FitOptions {
            bounds: Bounds {
                length_scale: [-1.0, 1.0],
                ..Default::default()
            },
            ..o
        };
        assert!(
            bad.check().is_err(),
            "invalid options are refused by check()"
        );
        let bad = FitOptions {
            kernel: Kernel {
                signal_variance: Variance::Fixed(f64::INFINITY),
                ..Kernel::ard()
            },
            ..o
        };
        assert!(
            bad.check().is_err(),
            "invalid options are refused by check()"
        );
        assert!(
            GaussianProcess::with_hyperparameters(
                &x,
                &y,
                Hyperparameters {
                    signal_variance: 1.0,
                    length_scales: vec![1.0; 2],
                    noise_variance: 1e-3,
                },
                &o.check().unwrap()
            )
            .is_err()
        );
    }

    #[test]
    fn constant_output_and_input_are_reported() {
        let (x, _) = spec_data();
        let y = vec![2.5; x.len()];
        let gp = fit(
            &x,
            &y,
            &FitOptions {
                n_restarts: 1,
                ..Default::default()
            }
            .check()
            .unwrap(),
        )
        .unwrap();
        assert!(
            gp.diagnostics()
                .warnings
                .contains(&FitWarning::ConstantOutput)
        );
        assert!(gp.diagnostics().is_degenerate());
        assert_eq!(gp.predict_mean(&[vec![0.3, 0.3, 0.3]]).unwrap()[0], 2.5);
        let (x, y) = spec_data();
        let x: Vec<Vec<f64>> = x.iter().map(|p| vec![p[0], 1.0]).collect();
        let gp = fit(
            &x,
            &y,
            &FitOptions {
                n_restarts: 1,
                ..Default::default()
            }
            .check()
            .unwrap(),
        )
        .unwrap();
        assert!(
            gp.diagnostics()
                .warnings
                .contains(&FitWarning::ConstantInput { input: 1 })
        );
    }
}
