//! Gaussian-process classification of run failure: the probability that the model gives no
//! answer at a parameter vector, learnt from the runs that succeeded and those that failed.
//!
//! A latent function f ~ GP(m, K) with the logistic link p(fail | f) = σ(f) = 1/(1 + e^(−f)),
//! a constant prior mean m = logit of the observed failure share (so that far from every run
//! the classifier leans to the share rather than to ½), and the squared-exponential kernel
//! k(x, x') = c·exp(−½ Σ_k (x̃_k − x̃'_k)²/l_k²) on inputs mapped onto the unit cube by fixed
//! bounds (the prior box, so that length scales keep their meaning as runs are added).
//!
//! The posterior over f is approximated by Laplace's method: Newton iterations to the mode f̂
//! with B = I + W^½ K W^½, W = diag(π(1 − π)) (Rasmussen & Williams 2006, algorithm 3.1); the
//! prediction at x* has mean m + k*ᵀ(t − π̂) and variance k** − vᵀv, v = L⁻¹W^½k*
//! (algorithm 3.2), and the class probability is the probit approximation of the averaged
//! logistic, σ(μ*/√(1 + πV*/8)) (MacKay 1992). The hyper-parameters (c, l_k) maximise the
//! approximate log marginal likelihood −½ aᵀ(f̂ − m) + Σ ln σ(y_i f̂_i) − Σ ln L_ii over a grid of
//! isotropic length scales and signal variances, refined per input (ARD) by a coordinate search.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt;
use faer::linalg::triangular_solve;
use faer::{MatMut, MatRef, Par};
use serde::{Deserialize, Serialize};

use crate::error::{GpError, Result};

/// Options of [`FailureClassifier::fit`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ClassifierOptions {
    /// Isotropic length scales tried first (unit-cube units).
    pub length_scales: Vec<f64>,
    /// Signal variances c tried with each length scale.
    pub signal_variances: Vec<f64>,
    /// Factors by which each input's length scale is scaled in the ARD refinement.
    pub refinement_factors: Vec<f64>,
    /// Passes of the ARD refinement over the inputs.
    pub refinement_passes: usize,
    /// Newton iterations at most per fit of the mode.
    pub max_newton_iterations: usize,
}

impl Default for ClassifierOptions {
    fn default() -> Self {
        Self {
            length_scales: vec![0.01, 0.02, 0.03, 0.05, 0.08, 0.12, 0.2, 0.3, 0.5, 0.8, 1.2],
            signal_variances: vec![1.0, 4.0, 16.0],
            refinement_factors: vec![0.5, 2.0, 4.0],
            refinement_passes: 2,
            max_newton_iterations: 50,
        }
    }
}

impl ClassifierOptions {
    /// Checks that every grid value is positive and finite and that the grids are not empty,
    /// and returns the options as the value [`FailureClassifier::fit`] takes.
    ///
    /// # Errors
    /// The first invalid option, named.
    pub fn check(self) -> Result<CheckedClassifierOptions> {
        let positive = |what: &'static str, values: &[f64]| -> Result<()> {
            if values.is_empty() || values.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
                return Err(GpError::InvalidParameter {
                    what,
                    reason: format!("expected positive finite values, got {values:?}"),
                });
            }
            Ok(())
        };
        positive("classifier length scales", &self.length_scales)?;
        positive("classifier signal variances", &self.signal_variances)?;
        if self
            .refinement_factors
            .iter()
            .any(|v| !(v.is_finite() && *v > 0.0))
        {
            return Err(GpError::InvalidParameter {
                what: "classifier refinement factors",
                reason: format!(
                    "expected positive finite values, got {:?}",
                    self.refinement_factors
                ),
            });
        }
        if self.max_newton_iterations == 0 {
            return Err(GpError::InvalidParameter {
                what: "classifier Newton iterations",
                reason: "at least 1".into(),
            });
        }
        Ok(CheckedClassifierOptions(self))
    }
}

/// Options that passed [`ClassifierOptions::check`]; read them through `Deref`.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckedClassifierOptions(ClassifierOptions);

impl CheckedClassifierOptions {
    /// The options as plain data.
    pub fn options(&self) -> &ClassifierOptions {
        &self.0
    }
}

impl std::ops::Deref for CheckedClassifierOptions {
    type Target = ClassifierOptions;
    fn deref(&self) -> &ClassifierOptions {
        &self.0
    }
}

/// The Laplace approximation at one set of hyper-parameters.
struct LaplaceMode {
    /// t − π̂ (t = 1 for a failure): the gradient of the log likelihood at the mode.
    residual: Vec<f64>,
    /// W^½ at the mode.
    w_sqrt: Vec<f64>,
    /// Lower Cholesky factor of B, column-major n×n.
    factor: Vec<f64>,
    /// The approximate log marginal likelihood.
    log_marginal_likelihood: f64,
}

/// A fitted classifier of run failure over the parameter space.
#[derive(Debug, Clone)]
pub struct FailureClassifier {
    lower: Vec<f64>,
    range: Vec<f64>,
    points: Vec<Vec<f64>>,
    prior_mean: f64,
    signal_variance: f64,
    length_scales: Vec<f64>,
    residual: Vec<f64>,
    w_sqrt: Vec<f64>,
    factor: Vec<f64>,
    log_marginal_likelihood: f64,
    failures: usize,
}

fn logistic(f: f64) -> f64 {
    if f >= 0.0 {
        1.0 / (1.0 + (-f).exp())
    } else {
        let e = f.exp();
        e / (1.0 + e)
    }
}

/// ln σ(f), stable for large |f|.
fn log_logistic(f: f64) -> f64 {
    if f >= 0.0 {
        -(-f).exp().ln_1p()
    } else {
        f - f.exp().ln_1p()
    }
}

fn kernel(a: &[f64], b: &[f64], c: f64, length_scales: &[f64]) -> f64 {
    let s: f64 = a
        .iter()
        .zip(b)
        .zip(length_scales)
        .map(|((x, y), l)| {
            let t = (x - y) / l;
            t * t
        })
        .sum();
    c * (-0.5 * s).exp()
}

fn laplace_mode(
    points: &[Vec<f64>],
    targets: &[f64],
    prior_mean: f64,
    c: f64,
    length_scales: &[f64],
    max_iterations: usize,
) -> Result<LaplaceMode> {
    let n = points.len();
    let mut k = vec![0.0; n * n];
    for j in 0..n {
        for i in j..n {
            let v = kernel(&points[i], &points[j], c, length_scales);
            k[j * n + i] = v;
            k[i * n + j] = v;
        }
    }
    let req = llt::factor::cholesky_in_place_scratch::<f64>(n, Par::Seq, Default::default());
    let mut stack = MemBuffer::new(req);
    let mut latent = vec![prior_mean; n];
    let mut factor = vec![0.0; n * n];
    let mut w_sqrt = vec![0.0; n];
    let mut a = vec![0.0; n];
    let mut previous = f64::NEG_INFINITY;
    for _ in 0..max_iterations {
        let pi = factor_b(&k, &latent, &mut w_sqrt, &mut factor, &mut stack)?;
        // b = W(f − m) + (t − π); a = b − W^½ B⁻¹ W^½ K b.
        let b: Vec<f64> = (0..n)
            .map(|i| w_sqrt[i] * w_sqrt[i] * (latent[i] - prior_mean) + (targets[i] - pi[i]))
            .collect();
        let mut rhs: Vec<f64> = (0..n)
            .map(|i| w_sqrt[i] * (0..n).map(|j| k[j * n + i] * b[j]).sum::<f64>())
            .collect();
        solve_b(&factor, n, &mut rhs);
        for i in 0..n {
            a[i] = b[i] - w_sqrt[i] * rhs[i];
        }
        for i in 0..n {
            latent[i] = prior_mean + (0..n).map(|j| k[j * n + i] * a[j]).sum::<f64>();
        }
        let objective = laplace_objective(&a, &latent, prior_mean, targets);
        let converged = (objective - previous).abs() < 1e-10 * (1.0 + objective.abs());
        previous = objective;
        if converged {
            break;
        }
    }
    // The quantities at the final mode.
    let pi = factor_b(&k, &latent, &mut w_sqrt, &mut factor, &mut stack)?;
    let log_det_half: f64 = (0..n).map(|i| factor[i * n + i].ln()).sum();
    let log_marginal_likelihood =
        laplace_objective(&a, &latent, prior_mean, targets) - log_det_half;
    Ok(LaplaceMode {
        residual: targets.iter().zip(&pi).map(|(t, p)| t - p).collect(),
        w_sqrt,
        factor,
        log_marginal_likelihood,
    })
}

/// At the latent values f: W^½ from π = σ(f), and B = I + W^½ K W^½
/// factorised into `factor` (lower Cholesky, column-major); returns π.
fn factor_b(
    k: &[f64],
    latent: &[f64],
    w_sqrt: &mut [f64],
    factor: &mut [f64],
    stack: &mut MemBuffer,
) -> Result<Vec<f64>> {
    let n = latent.len();
    let pi: Vec<f64> = latent.iter().map(|f| logistic(*f)).collect();
    for i in 0..n {
        w_sqrt[i] = (pi[i] * (1.0 - pi[i])).sqrt();
    }
    for j in 0..n {
        for i in j..n {
            let mut v = w_sqrt[i] * k[j * n + i] * w_sqrt[j];
            if i == j {
                v += 1.0;
            }
            factor[j * n + i] = v;
        }
    }
    llt::factor::cholesky_in_place(
        MatMut::from_column_major_slice_mut(factor, n, n),
        Default::default(),
        Par::Seq,
        MemStack::new(stack),
        Default::default(),
    )
    .map_err(|_| GpError::NotPositiveDefinite { pivot: 0 })?;
    Ok(pi)
}

/// Ψ(f) = −½ aᵀ(f − m) + Σ ln σ(y_i f_i), the Laplace objective at the latent values f
/// (a = K⁻¹(f − m), y_i = ±1 from the targets).
fn laplace_objective(a: &[f64], latent: &[f64], prior_mean: f64, targets: &[f64]) -> f64 {
    let centred: Vec<f64> = latent.iter().map(|f| f - prior_mean).collect();
    -0.5 * dot(a, &centred)
        + latent
            .iter()
            .zip(targets)
            .map(|(f, t)| log_logistic(if *t > 0.5 { *f } else { -*f }))
            .sum::<f64>()
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// rhs ← B⁻¹ rhs with B = LLᵀ (L lower, column-major n×n).
fn solve_b(factor: &[f64], n: usize, rhs: &mut [f64]) {
    let l = MatRef::from_column_major_slice(factor, n, n);
    let mut r = MatMut::from_column_major_slice_mut(rhs, n, 1);
    triangular_solve::solve_lower_triangular_in_place(l, r.as_mut(), Par::Seq);
    triangular_solve::solve_upper_triangular_in_place(l.transpose(), r.as_mut(), Par::Seq);
}

impl FailureClassifier {
    /// Fit the classifier to runs at `points` (original units) of which `failed[i]` tells
    /// whether run i failed, with inputs mapped onto the unit cube by `bounds` (lower, upper).
    ///
    /// Returns `Ok(None)` when no run failed: the model answered everywhere it was asked, and
    /// the failure probability is taken as 0.
    ///
    /// # Errors
    /// No points, ragged or non-finite points, lengths that differ, empty or reversed bounds,
    /// invalid options, or every run failed (nothing to learn a success region from).
    pub fn fit(
        points: &[Vec<f64>],
        failed: &[bool],
        bounds: &[(f64, f64)],
        options: &CheckedClassifierOptions,
    ) -> Result<Option<Self>> {
        let d = bounds.len();
        if d == 0 {
            return Err(GpError::ZeroDimension);
        }
        if points.is_empty() {
            return Err(GpError::TooFewPoints {
                required: 1,
                actual: 0,
            });
        }
        if failed.len() != points.len() {
            return Err(GpError::LengthMismatch {
                what: "failure labels vs. points",
                expected: points.len(),
                actual: failed.len(),
            });
        }
        crate::data::validate_points(points, "classifier point", Some(d))?;
        if let Some((k, (lo, hi))) = bounds
            .iter()
            .enumerate()
            .find(|(_, (lo, hi))| !(lo.is_finite() && hi.is_finite() && lo < hi))
        {
            return Err(GpError::InvalidParameter {
                what: "classifier bounds",
                reason: format!("input {k}: [{lo}, {hi}] must be finite with lower < upper"),
            });
        }
        let failures = failed.iter().filter(|f| **f).count();
        if failures == 0 {
            return Ok(None);
        }
        if failures == points.len() {
            return Err(GpError::InvalidParameter {
                what: "failure labels",
                reason: format!("all {failures} runs failed: no region where the model answers"),
            });
        }
        let lower: Vec<f64> = bounds.iter().map(|b| b.0).collect();
        let range: Vec<f64> = bounds.iter().map(|b| b.1 - b.0).collect();
        let scaled: Vec<Vec<f64>> = points
            .iter()
            .map(|p| (0..d).map(|k| (p[k] - lower[k]) / range[k]).collect())
            .collect();
        let targets: Vec<f64> = failed.iter().map(|f| if *f { 1.0 } else { 0.0 }).collect();
        let n = points.len() as f64;
        // The failure share with one pseudo-run of each kind, so that it is never 0 or 1.
        let share = (failures as f64 + 0.5) / (n + 1.0);
        let prior_mean = (share / (1.0 - share)).ln();
        let evaluate = |c: f64, l: &[f64]| {
            laplace_mode(
                &scaled,
                &targets,
                prior_mean,
                c,
                l,
                options.max_newton_iterations,
            )
        };
        let mut best: Option<(f64, Vec<f64>, LaplaceMode)> = None;
        for &l in &options.length_scales {
            for &c in &options.signal_variances {
                let ls = vec![l; d];
                let mode = evaluate(c, &ls)?;
                if best
                    .as_ref()
                    .is_none_or(|b| mode.log_marginal_likelihood > b.2.log_marginal_likelihood)
                {
                    best = Some((c, ls, mode));
                }
            }
        }
        let Some((c, mut ls, mut mode)) = best else {
            return Err(GpError::InvalidParameter {
                what: "classifier grids",
                reason: "empty".into(),
            });
        };
        for _ in 0..options.refinement_passes {
            for k in 0..d {
                for &factor in &options.refinement_factors {
                    let mut trial = ls.clone();
                    trial[k] *= factor;
                    let trial_mode = evaluate(c, &trial)?;
                    if trial_mode.log_marginal_likelihood > mode.log_marginal_likelihood + 1e-9 {
                        ls = trial;
                        mode = trial_mode;
                    }
                }
            }
        }
        Ok(Some(Self {
            lower,
            range,
            points: scaled,
            prior_mean,
            signal_variance: c,
            length_scales: ls,
            residual: mode.residual,
            w_sqrt: mode.w_sqrt,
            factor: mode.factor,
            log_marginal_likelihood: mode.log_marginal_likelihood,
            failures,
        }))
    }

    /// The probability that a run at each of `points` (original units) fails.
    ///
    /// # Errors
    /// A point of the wrong dimension or with a non-finite coordinate.
    pub fn failure_probability(&self, points: &[Vec<f64>]) -> Result<Vec<f64>> {
        let d = self.lower.len();
        crate::data::validate_points(points, "classifier point", Some(d))?;
        let n = self.points.len();
        let mut v = vec![0.0; n];
        Ok(points
            .iter()
            .map(|p| {
                let x: Vec<f64> = (0..d)
                    .map(|k| (p[k] - self.lower[k]) / self.range[k])
                    .collect();
                let mut mean = self.prior_mean;
                for (i, vi) in v.iter_mut().enumerate() {
                    let kx = kernel(
                        &self.points[i],
                        &x,
                        self.signal_variance,
                        &self.length_scales,
                    );
                    mean += kx * self.residual[i];
                    *vi = self.w_sqrt[i] * kx;
                }
                let l = MatRef::from_column_major_slice(&self.factor, n, n);
                let mut column = MatMut::from_column_major_slice_mut(&mut v, n, 1);
                triangular_solve::solve_lower_triangular_in_place(l, column.as_mut(), Par::Seq);
                let variance = (self.signal_variance - dot(&v, &v)).max(0.0);
                let kappa = 1.0 / (1.0 + std::f64::consts::PI * variance / 8.0).sqrt();
                logistic(kappa * mean)
            })
            .collect())
    }

    /// The fitted length scales in original input units (unit-cube length scale × range).
    pub fn length_scales_in_input_units(&self) -> Vec<f64> {
        self.length_scales
            .iter()
            .zip(&self.range)
            .map(|(l, r)| l * r)
            .collect()
    }

    /// The fitted signal variance c of the latent function.
    pub fn signal_variance(&self) -> f64 {
        self.signal_variance
    }

    /// The approximate log marginal likelihood at the fitted hyper-parameters.
    pub fn log_marginal_likelihood(&self) -> f64 {
        self.log_marginal_likelihood
    }

    /// Failed runs among the training runs.
    pub fn failures(&self) -> usize {
        self.failures
    }

    /// Training runs.
    pub fn runs(&self) -> usize {
        self.points.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs on a 12×12 grid of [0, 1]² fail where x0 + x1 > 1.2.
    fn grid() -> (Vec<Vec<f64>>, Vec<bool>) {
        let mut points = Vec::new();
        let mut failed = Vec::new();
        for i in 0..12 {
            for j in 0..12 {
                let p = vec![i as f64 / 11.0, j as f64 / 11.0];
                failed.push(p[0] + p[1] > 1.2);
                points.push(p);
            }
        }
        (points, failed)
    }

    #[test]
    fn no_failure_gives_no_classifier() {
        let (points, _) = grid();
        let failed = vec![false; points.len()];
        let c = FailureClassifier::fit(
            &points,
            &failed,
            &[(0.0, 1.0), (0.0, 1.0)],
            &ClassifierOptions::default().check().unwrap(),
        )
        .unwrap();
        assert!(c.is_none());
    }

    #[test]
    fn the_classifier_separates_a_failure_region() {
        let (points, failed) = grid();
        let c = FailureClassifier::fit(
            &points,
            &failed,
            &[(0.0, 1.0), (0.0, 1.0)],
            &ClassifierOptions::default().check().unwrap(),
        )
        .unwrap()
        .unwrap();
        let probe = vec![
            vec![0.1, 0.1],
            vec![0.3, 0.5],
            vec![0.9, 0.95],
            vec![0.75, 0.8],
        ];
        let p = c.failure_probability(&probe).unwrap();
        assert!(p[0] < 0.1 && p[1] < 0.1, "{p:?}");
        assert!(p[2] > 0.9 && p[3] > 0.7, "{p:?}");
        // Training accuracy: every run more than 0.1 from the boundary is classified right.
        let all = c.failure_probability(&points).unwrap();
        for ((q, f), x) in all.iter().zip(&failed).zip(&points) {
            if (x[0] + x[1] - 1.2).abs() > 0.1 {
                assert_eq!(*q > 0.5, *f, "{x:?}: {q}");
            }
        }
        // Invariant to the units of the inputs: the same runs in other units give the same
        // probabilities.
        let scaled: Vec<Vec<f64>> = points
            .iter()
            .map(|p| vec![10.0 + 5.0 * p[0], -3.0 * p[1]])
            .collect();
        let c2 = FailureClassifier::fit(
            &scaled,
            &failed,
            &[(10.0, 15.0), (-3.0, 0.0)],
            &ClassifierOptions::default().check().unwrap(),
        )
        .unwrap()
        .unwrap();
        let probe2: Vec<Vec<f64>> = probe
            .iter()
            .map(|p| vec![10.0 + 5.0 * p[0], -3.0 * p[1]])
            .collect();
        let p2 = c2.failure_probability(&probe2).unwrap();
        for (a, b) in p.iter().zip(&p2) {
            assert!((a - b).abs() < 1e-9, "{a} vs {b}");
        }
    }

    #[test]
    fn far_from_every_run_the_probability_is_the_failure_share() {
        // Runs in one corner only; 1 of 4 failed.
        let points = vec![
            vec![0.0, 0.0],
            vec![0.05, 0.0],
            vec![0.0, 0.05],
            vec![0.05, 0.05],
        ];
        let failed = vec![false, false, false, true];
        let options = ClassifierOptions {
            length_scales: vec![0.05],
            signal_variances: vec![1.0],
            refinement_factors: vec![],
            ..ClassifierOptions::default()
        };
        let c = FailureClassifier::fit(
            &points,
            &failed,
            &[(0.0, 1.0), (0.0, 1.0)],
            &options.check().unwrap(),
        )
        .unwrap()
        .unwrap();
        let p = c.failure_probability(&[vec![1.0, 1.0]]).unwrap()[0];
        // The prior there: f ~ N(logit(share), c), averaged through the probit approximation.
        let share: f64 = 1.5 / 5.0;
        let kappa = 1.0 / (1.0 + std::f64::consts::PI / 8.0).sqrt();
        let expected = logistic(kappa * (share / (1.0 - share)).ln());
        assert!((p - expected).abs() < 1e-6, "{p} vs {expected}");
        assert!(p > share && p < 0.5);
    }

    #[test]
    fn bad_input_is_an_error() {
        let (points, failed) = grid();
        let b = [(0.0, 1.0), (0.0, 1.0)];
        let o = ClassifierOptions::default().check().unwrap();
        assert!(FailureClassifier::fit(&points, &failed[..3], &b, &o).is_err());
        assert!(FailureClassifier::fit(&points, &failed, &[(1.0, 0.0), (0.0, 1.0)], &o).is_err());
        assert!(FailureClassifier::fit(&points, &vec![true; points.len()], &b, &o).is_err());
        let bad = ClassifierOptions {
            length_scales: vec![-1.0],
            ..ClassifierOptions::default()
        };
        assert!(
            bad.check().is_err(),
            "invalid options are refused by check()"
        );
        let c = FailureClassifier::fit(&points, &failed, &b, &o)
            .unwrap()
            .unwrap();
        assert!(c.failure_probability(&[vec![0.5]]).is_err());
        assert!(c.failure_probability(&[vec![0.5, f64::NAN]]).is_err());
    }
}
