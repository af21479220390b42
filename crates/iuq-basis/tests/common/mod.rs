//! Shared helpers of the integration tests: the BASIS reference problems (docs/methods.md §7)
//! and runners.

#![allow(dead_code)]

use iuq_basis::{Basis, BasisSettings, BasisState, FnLikelihood, LogLikelihood, Silent};
use iuq_core::{Parameter, ParameterSpace, Prior};

pub const LN_2PI: f64 = 1.837_877_066_409_345_5;

/// A uniform box U(−w, w)^d with parameters x0, x1, ….
pub fn uniform_box(d: usize, half_width: f64) -> ParameterSpace {
    ParameterSpace::new(
        (0..d)
            .map(|k| Parameter {
                name: format!("x{k}"),
                prior: Prior::Uniform(-half_width, half_width),
            })
            .collect(),
    )
    .unwrap()
}

/// A reference problem: name, prior space, log-likelihood, exact ln Z.
pub struct Problem {
    pub name: &'static str,
    pub space: ParameterSpace,
    pub log_likelihood: fn(&[f64]) -> f64,
    pub exact_log_evidence: f64,
}

pub fn gaussian_1d(x: &[f64]) -> f64 {
    -0.5 * ((x[0] + 2.0) / 3.0).powi(2) - 3f64.ln() - 0.5 * LN_2PI
}

pub fn half_norm_5d(x: &[f64]) -> f64 {
    -0.5 * x.iter().map(|v| v * v).sum::<f64>()
}

pub fn gaussian_2d(x: &[f64]) -> f64 {
    -0.5 * (x[0] * x[0] + x[1] * x[1]) - LN_2PI
}

pub fn rosenbrock(x: &[f64]) -> f64 {
    -(100.0 * (x[1] - x[0] * x[0]).powi(2) + (x[0] - 1.0).powi(2))
}

/// The four reference problems of docs/methods.md §7 with their exact log-evidence.
pub fn reference_problems() -> Vec<Problem> {
    vec![
        Problem {
            name: "ln N(x; -2, 3^2) on U(-15, 15)",
            space: uniform_box(1, 15.0),
            log_likelihood: gaussian_1d,
            exact_log_evidence: -3.401205,
        },
        Problem {
            name: "-|x|^2/2 on U(-5, 5)^5",
            space: uniform_box(5, 5.0),
            log_likelihood: half_norm_5d,
            exact_log_evidence: -6.918236,
        },
        Problem {
            name: "ln N2(x; 0, I) on U(-15, 15)^2",
            space: uniform_box(2, 15.0),
            log_likelihood: gaussian_2d,
            exact_log_evidence: -6.802395,
        },
        Problem {
            name: "Rosenbrock on U(-15, 15)^2",
            space: uniform_box(2, 15.0),
            log_likelihood: rosenbrock,
            exact_log_evidence: -7.960278,
        },
    ]
}

/// Run BASIS to the end.
pub fn run<L: LogLikelihood + ?Sized>(
    space: &ParameterSpace,
    likelihood: &L,
    settings: BasisSettings,
) -> BasisState {
    let run = Basis::new(space, likelihood, settings.check().unwrap())
        .unwrap()
        .run(&mut Silent)
        .unwrap();
    run.state
}

/// Run a reference problem.
pub fn run_problem(problem: &Problem, settings: BasisSettings) -> BasisState {
    let likelihood = FnLikelihood::new(problem.space.dimension(), problem.log_likelihood);
    run(&problem.space, &likelihood, settings)
}

/// Mean and sample standard deviation (ddof = 1).
pub fn mean_sd(values: &[f64]) -> (f64, f64) {
    let k = values.len() as f64;
    let mean = values.iter().sum::<f64>() / k;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (k - 1.0);
    (mean, var.sqrt())
}

/// The state with every wall-clock time zeroed: the only fields allowed to differ between two
/// runs of the same work.
pub fn without_wall_times(mut state: BasisState) -> BasisState {
    for d in &mut state.diagnostics {
        d.wall_seconds = 0.0;
    }
    state
}

/// Assert bitwise equality of two states (ignoring wall times), with a readable message.
pub fn assert_same_run(a: &BasisState, b: &BasisState) {
    let (a, b) = (without_wall_times(a.clone()), without_wall_times(b.clone()));
    assert_eq!(a.stage, b.stage, "stage");
    assert_eq!(a.log_evidence.to_bits(), b.log_evidence.to_bits(), "log Z");
    for (i, (x, y)) in a.samples.iter().zip(&b.samples).enumerate() {
        let xb: Vec<u64> = x.iter().map(|v| v.to_bits()).collect();
        let yb: Vec<u64> = y.iter().map(|v| v.to_bits()).collect();
        assert_eq!(xb, yb, "sample {i}");
    }
    assert_eq!(a, b);
}
