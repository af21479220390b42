//! A bounded quasi-Newton minimiser: projected L-BFGS (in the spirit of L-BFGS-B) with a
//! projected Armijo backtracking / extrapolating line search.
//!
//! Minimises f(x) subject to l ≤ x ≤ u. Each iteration:
//! 1. the projected gradient p = P(x − ∇f) − x (P the projection onto the box) measures
//!    stationarity; ‖p‖∞ ≤ `gradient_tolerance` stops (scipy's `pgtol`);
//! 2. variables at a bound whose gradient pushes outwards are frozen; on the free variables the
//!    L-BFGS two-loop recursion (the last m pairs s = Δx, y = Δ∇f, initial scaling sᵀy/yᵀy)
//!    gives d = −H∇f; without pairs, or if d is not a descent direction, d = −∇f and the first
//!    trial step is 1/‖∇f‖₂ (as scipy's L-BFGS-B);
//! 3. along the projected path (gradients are computed only at accepted points) x(t) = P(x + t·d): accept the first t with
//!    f(x(t)) ≤ f(x) + c₁ ∇fᵀ(x(t) − x) (c₁ = 1e−4); an unusable value (a failed evaluation)
//!    or a rejected step shrinks t by safeguarded quadratic interpolation in [0.1 t, 0.5 t];
//!    an accepted step whose slope is still steep (∇f(x(t))ᵀd < 0.9 ∇fᵀd, no bound touched) is
//!    extended by 4× while the decrease condition holds;
//! 4. the pair (s, y) is stored when sᵀy > ε·yᵀy (keeps H positive definite);
//! 5. a relative decrease (f_k − f_{k+1})/max(|f_k|, |f_{k+1}|, 1) ≤ `function_tolerance`
//!    stops (scipy's `factr·eps`), and so does a line search whose trial steps predict a
//!    decrease −∇fᵀ(x(t) − x) below `function_tolerance`·max(|f|, 1) before any is accepted
//!    (no significant progress is possible along d; this also stops the search from chasing
//!    round-off in f).

use serde::{Deserialize, Serialize};

use crate::error::{GpError, Result};

/// Settings of [`minimize_bounded`]; the defaults are scipy's L-BFGS-B defaults (as used by
/// scikit-learn), with a smaller iteration cap.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OptimizerOptions {
    /// Number of (s, y) pairs kept, m.
    pub memory: usize,
    /// Maximum number of iterations.
    pub max_iterations: usize,
    /// Maximum number of objective evaluations.
    pub max_evaluations: usize,
    /// Stop when ‖P(x − ∇f) − x‖∞ ≤ this.
    pub gradient_tolerance: f64,
    /// Stop when the relative decrease of f in one iteration is ≤ this.
    pub function_tolerance: f64,
}

impl Default for OptimizerOptions {
    fn default() -> Self {
        Self {
            memory: 10,
            max_iterations: 1000,
            max_evaluations: 5000,
            gradient_tolerance: 1e-5,
            function_tolerance: 2.220_446_049_250_313e-9,
        }
    }
}

impl OptimizerOptions {
    /// Checks that the settings make sense.
    pub fn validate(&self) -> Result<()> {
        let bad = |reason: String| {
            Err(GpError::InvalidParameter {
                what: "optimizer options",
                reason,
            })
        };
        if self.memory == 0 || self.max_iterations == 0 || self.max_evaluations == 0 {
            return bad("memory, max_iterations and max_evaluations must be ≥ 1".into());
        }
        let valid = |t: f64| t >= 0.0 && t.is_finite();
        if !valid(self.gradient_tolerance) || !valid(self.function_tolerance) {
            return bad("tolerances must be finite and non-negative".into());
        }
        Ok(())
    }
}

/// Why the minimiser stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Termination {
    /// The projected gradient is below `gradient_tolerance`.
    GradientTolerance,
    /// The relative decrease of f fell below `function_tolerance`.
    FunctionTolerance,
    /// `max_iterations` reached.
    MaxIterations,
    /// `max_evaluations` reached.
    MaxEvaluations,
    /// No step along the search direction decreased f (usually: at the optimum to working
    /// precision).
    LineSearchFailed,
}

impl Termination {
    /// True for the two convergence criteria.
    pub fn converged(self) -> bool {
        matches!(self, Self::GradientTolerance | Self::FunctionTolerance)
    }
}

/// The result of [`minimize_bounded`].
#[derive(Debug, Clone, PartialEq)]
pub struct Minimum {
    /// The best point found.
    pub x: Vec<f64>,
    /// f at `x`.
    pub value: f64,
    /// ∇f at `x`.
    pub gradient: Vec<f64>,
    /// ‖P(x − ∇f) − x‖∞ at `x`.
    pub projected_gradient_norm: f64,
    /// Iterations done.
    pub iterations: usize,
    /// Objective values computed.
    pub evaluations: usize,
    /// Gradients computed (at the start and at accepted steps).
    pub gradient_evaluations: usize,
    /// Why it stopped.
    pub termination: Termination,
}

/// Line-search steps smaller than this relative to |x| (or 1) are not tried.
const MIN_RELATIVE_STEP: f64 = 1e-12;

fn project(x: &mut [f64], lower: &[f64], upper: &[f64]) {
    for ((v, &lo), &hi) in x.iter_mut().zip(lower).zip(upper) {
        *v = v.clamp(lo, hi);
    }
}

fn projected_gradient_norm(x: &[f64], g: &[f64], lower: &[f64], upper: &[f64]) -> f64 {
    x.iter()
        .zip(g)
        .zip(lower.iter().zip(upper))
        .map(|((&xi, &gi), (&lo, &hi))| ((xi - gi).clamp(lo, hi) - xi).abs())
        .fold(0.0, f64::max)
}

fn masked_dot(a: &[f64], b: &[f64], free: &[bool]) -> f64 {
    a.iter()
        .zip(b)
        .zip(free)
        .filter(|(_, f)| **f)
        .map(|((x, y), _)| x * y)
        .sum()
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// An objective for [`minimize_bounded_objective`], evaluated in two steps so that the
/// gradient (for a GP: the inverse of K, two thirds of the cost) is computed only at points
/// the line search accepts.
pub trait Objective {
    /// f(x), or `None` where f cannot be evaluated.
    fn value(&mut self, x: &[f64]) -> Option<f64>;
    /// ∇f at the point of the latest `value` call that returned a value; false if it cannot be
    /// computed.
    fn gradient(&mut self, gradient: &mut [f64]) -> bool;
}

/// Adapts a closure computing f and ∇f together to [`Objective`].
struct Joint<F> {
    f: F,
    gradient: Vec<f64>,
}

impl<F: FnMut(&[f64], &mut [f64]) -> Option<f64>> Objective for Joint<F> {
    fn value(&mut self, x: &[f64]) -> Option<f64> {
        (self.f)(x, &mut self.gradient)
    }
    fn gradient(&mut self, gradient: &mut [f64]) -> bool {
        gradient.copy_from_slice(&self.gradient);
        true
    }
}

/// Minimises `objective` over the box [`lower`, `upper`] from `x0` (projected into the box).
///
/// `objective(x, gradient)` returns f(x) and writes ∇f(x), or returns `None` where f cannot be
/// evaluated (the line search then shortens the step).
///
/// # Errors
/// Mismatched lengths, non-finite or crossed bounds, invalid options, or an objective that
/// cannot be evaluated at the (projected) start point.
pub fn minimize_bounded<F>(
    objective: F,
    x0: &[f64],
    lower: &[f64],
    upper: &[f64],
    options: &OptimizerOptions,
) -> Result<Minimum>
where
    F: FnMut(&[f64], &mut [f64]) -> Option<f64>,
{
    let mut joint = Joint {
        f: objective,
        gradient: vec![0.0; x0.len()],
    };
    minimize_bounded_objective(&mut joint, x0, lower, upper, options)
}

/// [`minimize_bounded`] for an [`Objective`] whose gradient is computed on demand: only at the
/// start and at accepted steps.
///
/// # Errors
/// As [`minimize_bounded`].
pub fn minimize_bounded_objective<O: Objective + ?Sized>(
    objective: &mut O,
    x0: &[f64],
    lower: &[f64],
    upper: &[f64],
    options: &OptimizerOptions,
) -> Result<Minimum> {
    options.validate()?;
    check_bounds(x0, lower, upper)?;
    let mut search = ProjectedLbfgs::start(objective, x0, lower, upper, options)?;
    let termination = loop {
        if let Some(termination) = search.stopping_criterion() {
            break termination;
        }
        search.iterations += 1;
        search.freeze_variables_pushed_out();
        let Some(first_step) = search.search_direction() else {
            break Termination::GradientTolerance;
        };
        let line_search = search.line_search(first_step);
        let Some(f_new) = line_search.accepted else {
            if !search.s_hist.is_empty() {
                // Retry once from steepest descent.
                search.forget_curvature();
                continue;
            }
            break if line_search.negligible {
                Termination::FunctionTolerance
            } else {
                Termination::LineSearchFailed
            };
        };
        if search.move_to_best_trial(f_new) {
            break Termination::FunctionTolerance;
        }
    };
    Ok(search.into_minimum(termination))
}

/// Rejects bounds of the wrong length, non-finite or crossed bounds and a non-finite start.
fn check_bounds(x0: &[f64], lower: &[f64], upper: &[f64]) -> Result<()> {
    let p = x0.len();
    if lower.len() != p || upper.len() != p {
        return Err(GpError::LengthMismatch {
            what: "bounds vs. start point",
            expected: p,
            actual: lower.len().min(upper.len()),
        });
    }
    if lower
        .iter()
        .zip(upper)
        .any(|(lo, hi)| !(lo.is_finite() && hi.is_finite() && lo <= hi))
        || x0.iter().any(|v| !v.is_finite())
    {
        return Err(GpError::InvalidParameter {
            what: "optimizer bounds",
            reason: "bounds and start must be finite with lower ≤ upper".into(),
        });
    }
    Ok(())
}

/// The outcome of one line search.
struct LineSearchOutcome {
    /// f at the accepted trial point (kept in `x_best`, `g_best`), if any was accepted.
    accepted: Option<f64>,
    /// The search stopped because a trial step predicted a negligible decrease.
    negligible: bool,
}

/// The state of the projected L-BFGS iteration: the current point, the curvature pairs and
/// the work vectors of the direction and the line search.
struct ProjectedLbfgs<'a, O: ?Sized> {
    objective: &'a mut O,
    lower: &'a [f64],
    upper: &'a [f64],
    options: &'a OptimizerOptions,
    /// The current point, f and ∇f there.
    x: Vec<f64>,
    f: f64,
    g: Vec<f64>,
    iterations: usize,
    evaluations: usize,
    gradient_evaluations: usize,
    /// The last m pairs s = Δx and y = Δ∇f, oldest first.
    s_hist: Vec<Vec<f64>>,
    y_hist: Vec<Vec<f64>>,
    /// Variables not held at a bound by an outward gradient.
    free: Vec<bool>,
    /// The search direction.
    d: Vec<f64>,
    /// The two-loop recursion's work vector and coefficients.
    q: Vec<f64>,
    coef: Vec<f64>,
    x_trial: Vec<f64>,
    g_trial: Vec<f64>,
    /// The best accepted trial point of the current line search, and ∇f there.
    x_best: Vec<f64>,
    g_best: Vec<f64>,
}

impl<'a, O: Objective + ?Sized> ProjectedLbfgs<'a, O> {
    /// Projects `x0` into the box and evaluates f and ∇f there.
    fn start(
        objective: &'a mut O,
        x0: &[f64],
        lower: &'a [f64],
        upper: &'a [f64],
        options: &'a OptimizerOptions,
    ) -> Result<Self> {
        let p = x0.len();
        let mut x = x0.to_vec();
        project(&mut x, lower, upper);
        let mut g = vec![0.0; p];
        let f = match objective.value(&x) {
            Some(v)
                if v.is_finite()
                    && objective.gradient(&mut g)
                    && g.iter().all(|v| v.is_finite()) =>
            {
                v
            }
            _ => {
                return Err(GpError::FitFailed(
                    "objective cannot be evaluated at the start point".into(),
                ));
            }
        };
        Ok(Self {
            objective,
            lower,
            upper,
            options,
            x,
            f,
            g,
            iterations: 0,
            evaluations: 1,
            gradient_evaluations: 1,
            s_hist: Vec::new(),
            y_hist: Vec::new(),
            free: vec![true; p],
            d: vec![0.0; p],
            q: vec![0.0; p],
            coef: vec![0.0; options.memory],
            x_trial: vec![0.0; p],
            g_trial: vec![0.0; p],
            x_best: vec![0.0; p],
            g_best: vec![0.0; p],
        })
    }

    /// The criterion checked before each iteration that stops the search, if one holds.
    fn stopping_criterion(&self) -> Option<Termination> {
        if projected_gradient_norm(&self.x, &self.g, self.lower, self.upper)
            <= self.options.gradient_tolerance
        {
            Some(Termination::GradientTolerance)
        } else if self.iterations >= self.options.max_iterations {
            Some(Termination::MaxIterations)
        } else if self.evaluations >= self.options.max_evaluations {
            Some(Termination::MaxEvaluations)
        } else {
            None
        }
    }

    /// Freezes the variables at a bound whose gradient pushes outwards.
    fn freeze_variables_pushed_out(&mut self) {
        let (x, g) = (&self.x, &self.g);
        for i in 0..x.len() {
            self.free[i] =
                !((x[i] <= self.lower[i] && g[i] > 0.0) || (x[i] >= self.upper[i] && g[i] < 0.0));
        }
    }

    fn forget_curvature(&mut self) {
        self.s_hist.clear();
        self.y_hist.clear();
    }

    /// Sets `d` to the quasi-Newton direction, or to steepest descent without curvature pairs
    /// or where the former is no descent direction; returns the first trial step, `None` when
    /// the free gradient is zero.
    fn search_direction(&mut self) -> Option<f64> {
        if !self.s_hist.is_empty() && self.quasi_newton_direction() {
            return Some(1.0);
        }
        let p = self.x.len();
        for i in 0..p {
            self.d[i] = if self.free[i] { -self.g[i] } else { 0.0 };
        }
        let norm = dot(&self.d, &self.d).sqrt();
        if norm == 0.0 {
            return None;
        }
        Some((1.0 / norm).min(1.0))
    }

    /// The two-loop recursion on the free variables: sets `d`, and returns whether it is a
    /// descent direction (if not, the curvature pairs are dropped).
    fn quasi_newton_direction(&mut self) -> bool {
        let p = self.x.len();
        let (s_hist, y_hist, free, q, coef) = (
            &self.s_hist,
            &self.y_hist,
            &self.free,
            &mut self.q,
            &mut self.coef,
        );
        for i in 0..p {
            q[i] = if free[i] { self.g[i] } else { 0.0 };
        }
        let m = s_hist.len();
        for k in (0..m).rev() {
            let rho = 1.0 / dot(&s_hist[k], &y_hist[k]);
            coef[k] = rho * masked_dot(&s_hist[k], q, free);
            for i in 0..p {
                if free[i] {
                    q[i] -= coef[k] * y_hist[k][i];
                }
            }
        }
        let (s_last, y_last) = (&s_hist[m - 1], &y_hist[m - 1]);
        let gamma = dot(s_last, y_last) / dot(y_last, y_last);
        for v in q.iter_mut() {
            *v *= gamma;
        }
        for k in 0..m {
            let rho = 1.0 / dot(&s_hist[k], &y_hist[k]);
            let beta = rho * masked_dot(&y_hist[k], q, free);
            for i in 0..p {
                if free[i] {
                    q[i] += s_hist[k][i] * (coef[k] - beta);
                }
            }
        }
        for i in 0..p {
            self.d[i] = if free[i] { -q[i] } else { 0.0 };
        }
        let slope = dot(&self.g, &self.d);
        if !(slope < 0.0 && slope.is_finite()) {
            self.forget_curvature();
            return false;
        }
        true
    }

    /// Projected backtracking / extrapolating line search along `d` from step `t`; the best
    /// accepted point is left in `x_best` and `g_best`.
    fn line_search(&mut self, mut t: f64) -> LineSearchOutcome {
        let p = self.x.len();
        let f = self.f;
        let slope = dot(&self.g, &self.d);
        let mut accepted: Option<f64> = None;
        let mut trials = 0;
        let mut extending = false;
        let mut negligible = false;
        loop {
            if self.evaluations >= self.options.max_evaluations || trials >= 40 {
                break;
            }
            trials += 1;
            let mut touched = false;
            for i in 0..p {
                let v = self.x[i] + t * self.d[i];
                self.x_trial[i] = v.clamp(self.lower[i], self.upper[i]);
                touched |= self.x_trial[i] != v;
            }
            let step: Vec<f64> = self
                .x_trial
                .iter()
                .zip(&self.x)
                .map(|(a, b)| a - b)
                .collect();
            // A step below round-off of x cannot decrease f measurably.
            if step
                .iter()
                .zip(&self.x)
                .all(|(s, xi)| s.abs() <= MIN_RELATIVE_STEP * xi.abs().max(1.0))
            {
                break;
            }
            let decrease = dot(&self.g, &step);
            // A step whose predicted decrease is below the function tolerance cannot make
            // progress that counts (and f is only accurate to round-off anyway).
            if -decrease <= self.options.function_tolerance * f.abs().max(1.0) {
                negligible = true;
                break;
            }
            self.evaluations += 1;
            let mut ft = self
                .objective
                .value(&self.x_trial)
                .filter(|v| v.is_finite());
            let mut ok = ft.is_some_and(|v| v <= f + 1e-4 * decrease);
            if ok {
                self.gradient_evaluations += 1;
                if !(self.objective.gradient(&mut self.g_trial)
                    && self.g_trial.iter().all(|g| g.is_finite()))
                {
                    ok = false;
                    ft = None;
                }
            }
            if ok {
                let v = ft.unwrap_or(f64::INFINITY);
                if accepted.is_none_or(|best| v < best) {
                    accepted = Some(v);
                    self.x_best.copy_from_slice(&self.x_trial);
                    self.g_best.copy_from_slice(&self.g_trial);
                } else {
                    break;
                }
                // Extend while the slope stays steep and no bound was touched.
                if !touched && dot(&self.g_trial, &self.d) < 0.9 * slope && t < 1e10 {
                    extending = true;
                    t *= 4.0;
                    continue;
                }
                break;
            }
            if extending {
                break;
            }
            t = shortened_step(t, ft, f, slope);
        }
        LineSearchOutcome {
            accepted,
            negligible,
        }
    }

    /// Moves to the line search's best point (value `f_new`), storing the pair (s, y) when
    /// it keeps H positive definite; returns whether the relative decrease is below
    /// `function_tolerance`.
    fn move_to_best_trial(&mut self, f_new: f64) -> bool {
        let s: Vec<f64> = self
            .x_best
            .iter()
            .zip(&self.x)
            .map(|(a, b)| a - b)
            .collect();
        let yv: Vec<f64> = self
            .g_best
            .iter()
            .zip(&self.g)
            .map(|(a, b)| a - b)
            .collect();
        let sy = dot(&s, &yv);
        let yy = dot(&yv, &yv);
        if sy > f64::EPSILON * yy && sy > 0.0 {
            if self.s_hist.len() == self.options.memory {
                self.s_hist.remove(0);
                self.y_hist.remove(0);
            }
            self.s_hist.push(s);
            self.y_hist.push(yv);
        }
        let f_old = self.f;
        self.f = f_new;
        self.x.copy_from_slice(&self.x_best);
        self.g.copy_from_slice(&self.g_best);
        let f = self.f;
        (f_old - f) <= self.options.function_tolerance * f_old.abs().max(f.abs()).max(1.0)
    }

    fn into_minimum(self, termination: Termination) -> Minimum {
        Minimum {
            projected_gradient_norm: projected_gradient_norm(
                &self.x, &self.g, self.lower, self.upper,
            ),
            x: self.x,
            value: self.f,
            gradient: self.g,
            iterations: self.iterations,
            evaluations: self.evaluations,
            gradient_evaluations: self.gradient_evaluations,
            termination,
        }
    }
}

/// The next trial step after a rejected step `t` with value `trial_value` (`None`: unusable):
/// safeguarded quadratic interpolation in [0.1 t, 0.5 t].
fn shortened_step(t: f64, trial_value: Option<f64>, f: f64, slope: f64) -> f64 {
    match trial_value {
        Some(v) => {
            let denom = 2.0 * (v - f - slope * t);
            let tq = if denom > 0.0 {
                -slope * t * t / denom
            } else {
                0.5 * t
            };
            tq.clamp(0.1 * t, 0.5 * t)
        }
        None => 0.1 * t,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rosenbrock(x: &[f64], g: &mut [f64]) -> Option<f64> {
        let (a, b) = (x[0], x[1]);
        g[0] = -2.0 * (1.0 - a) - 400.0 * a * (b - a * a);
        g[1] = 200.0 * (b - a * a);
        Some((1.0 - a).powi(2) + 100.0 * (b - a * a).powi(2))
    }

    #[test]
    fn unconstrained_rosenbrock() {
        let opts = OptimizerOptions {
            gradient_tolerance: 1e-8,
            function_tolerance: 0.0,
            ..Default::default()
        };
        let m =
            minimize_bounded(rosenbrock, &[-1.2, 1.0], &[-5.0, -5.0], &[5.0, 5.0], &opts).unwrap();
        assert!(
            (m.x[0] - 1.0).abs() < 1e-6 && (m.x[1] - 1.0).abs() < 1e-6,
            "{m:?}"
        );
        assert!(m.iterations < 100, "{m:?}");
    }

    #[test]
    fn active_bound_is_found() {
        // Minimum of the Rosenbrock function restricted to b ≤ 0.5 is on the bound.
        let tight = OptimizerOptions {
            function_tolerance: 1e-15,
            ..Default::default()
        };
        let m =
            minimize_bounded(rosenbrock, &[-1.2, 0.0], &[-5.0, -5.0], &[5.0, 0.5], &tight).unwrap();
        assert_eq!(m.x[1], 0.5);
        assert!(m.projected_gradient_norm < 1e-4, "{m:?}");
        // Quadratic with a corner solution.
        let quad = |x: &[f64], g: &mut [f64]| {
            g[0] = 2.0 * (x[0] - 3.0);
            g[1] = 2.0 * (x[1] + 3.0);
            Some((x[0] - 3.0).powi(2) + (x[1] + 3.0).powi(2))
        };
        let m = minimize_bounded(
            quad,
            &[0.0, 0.0],
            &[-1.0, -1.0],
            &[1.0, 1.0],
            &Default::default(),
        )
        .unwrap();
        assert_eq!(m.x, vec![1.0, -1.0]);
        assert_eq!(m.termination, Termination::GradientTolerance);
    }

    #[test]
    fn failed_evaluations_shorten_the_step() {
        // f undefined for x > 0.5; minimum of (x − 2)² on the defined part is at the edge.
        let f = |x: &[f64], g: &mut [f64]| {
            if x[0] > 0.5 {
                return None;
            }
            g[0] = 2.0 * (x[0] - 2.0);
            Some((x[0] - 2.0).powi(2))
        };
        let m = minimize_bounded(f, &[0.0], &[-10.0], &[10.0], &Default::default()).unwrap();
        assert!(m.x[0] <= 0.5 && m.x[0] > 0.4, "{m:?}");
    }

    #[test]
    fn bad_arguments_are_errors() {
        let f = |_: &[f64], _: &mut [f64]| Some(0.0);
        assert!(minimize_bounded(f, &[0.0], &[1.0], &[0.0], &Default::default()).is_err());
        assert!(minimize_bounded(f, &[0.0, 0.0], &[0.0], &[1.0], &Default::default()).is_err());
        assert!(minimize_bounded(f, &[f64::NAN], &[0.0], &[1.0], &Default::default()).is_err());
        let none = |_: &[f64], _: &mut [f64]| None;
        assert!(minimize_bounded(none, &[0.0], &[0.0], &[1.0], &Default::default()).is_err());
    }
}
