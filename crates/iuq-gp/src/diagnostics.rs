//! What the fit reports besides the GP: the multi-start runs and warnings about degenerate or
//! doubtful optima, for the caller to show (nothing is dropped silently).

use serde::{Deserialize, Serialize};

use crate::optimizer::Termination;

/// A warning about a fitted GP.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum FitWarning {
    /// A length scale sits at its lower bound: the GP treats the data as (nearly) uncorrelated
    /// in this input — usually a degenerate optimum. `input` is `None` for an isotropic kernel.
    LengthScaleAtLowerBound {
        /// The input (ARD), or none (isotropic).
        input: Option<usize>,
        /// The fitted length scale (scaled units).
        value: f64,
    },
    /// A length scale sits at its upper bound: the input has (almost) no effect, or only a
    /// trend the bound cuts off.
    LengthScaleAtUpperBound {
        /// The input (ARD), or none (isotropic).
        input: Option<usize>,
        /// The fitted length scale (scaled units).
        value: f64,
    },
    /// The signal variance sits at one of its bounds.
    SignalVarianceAtBound {
        /// The fitted signal variance (scaled units).
        value: f64,
    },
    /// The noise variance sits at its upper bound: the GP explains the data as noise.
    NoiseAtUpperBound {
        /// The fitted noise variance (scaled units).
        value: f64,
    },
    /// The leave-one-out Q2 is at or below the threshold: the GP predicts held-out points no
    /// better than their mean.
    LowLeaveOneOutQ2 {
        /// The leave-one-out Q2.
        q2: f64,
        /// The threshold it was compared with.
        threshold: f64,
    },
    /// The best optimiser run stopped without meeting a convergence criterion.
    NotConverged {
        /// Why it stopped.
        termination: Termination,
        /// Its projected-gradient norm.
        projected_gradient_norm: f64,
    },
    /// Some multi-start runs could not be evaluated (non-positive-definite K at their start).
    FailedStarts {
        /// Runs that failed.
        failed: usize,
        /// Runs in all.
        total: usize,
    },
    /// An input is constant over the training points (it cannot be learnt).
    ConstantInput {
        /// The input.
        input: usize,
    },
    /// The output is constant over the training points.
    ConstantOutput,
}

impl FitWarning {
    /// True for warnings that make the GP useless as a surrogate (length scale at the lower
    /// bound, noise at the upper bound, low leave-one-out Q2, constant output).
    pub fn is_degenerate(&self) -> bool {
        matches!(
            self,
            Self::LengthScaleAtLowerBound { .. }
                | Self::NoiseAtUpperBound { .. }
                | Self::LowLeaveOneOutQ2 { .. }
                | Self::ConstantOutput
        )
    }
}

impl std::fmt::Display for FitWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let which = |input: &Option<usize>| match input {
            Some(k) => format!("length scale of input {k}"),
            None => "isotropic length scale".to_string(),
        };
        match self {
            Self::LengthScaleAtLowerBound { input, value } => write!(
                f,
                "{} = {value:.3e} at its lower bound: degenerate fit (points nearly uncorrelated)",
                which(input)
            ),
            Self::LengthScaleAtUpperBound { input, value } => write!(
                f,
                "{} = {value:.3e} at its upper bound: the input has almost no effect",
                which(input)
            ),
            Self::SignalVarianceAtBound { value } => {
                write!(f, "signal variance = {value:.3e} at a bound")
            }
            Self::NoiseAtUpperBound { value } => write!(
                f,
                "noise variance = {value:.3e} at its upper bound: the data are explained as noise"
            ),
            Self::LowLeaveOneOutQ2 { q2, threshold } => write!(
                f,
                "leave-one-out Q2 = {q2:.4} ≤ {threshold}: the GP does not predict held-out points"
            ),
            Self::NotConverged {
                termination,
                projected_gradient_norm,
            } => write!(
                f,
                "optimiser stopped without converging ({termination:?}, projected gradient {projected_gradient_norm:.3e})"
            ),
            Self::FailedStarts { failed, total } => {
                write!(
                    f,
                    "{failed} of {total} optimiser starts could not be evaluated"
                )
            }
            Self::ConstantInput { input } => write!(f, "input {input} is constant"),
            Self::ConstantOutput => write!(f, "the output is constant"),
        }
    }
}

/// One optimiser run (on the screening subset or on all training points).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunReport {
    /// The θ it ended at (its start if it failed).
    pub theta: Vec<f64>,
    /// The LML it reached; `None` if the run failed.
    pub log_marginal_likelihood: Option<f64>,
    /// Optimiser iterations.
    pub iterations: usize,
    /// LML values computed (one Cholesky factorisation each).
    pub evaluations: usize,
    /// LML gradients computed (one inverse of K each).
    pub gradient_evaluations: usize,
    /// Why it stopped; `None` if it failed.
    pub termination: Option<Termination>,
    /// ‖P(θ + ∇LML) − θ‖∞ where it stopped; `None` if it failed.
    pub projected_gradient_norm: Option<f64>,
    /// Why it failed, if it did.
    pub error: Option<String>,
}

/// What became of one start of the multi-start maximisation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StartReport {
    /// The start θ (log space).
    pub start: Vec<f64>,
    /// The run from `start` on the screening subset, when screening was used
    /// ([`crate::FitOptions::screening_points`]).
    pub on_subset: Option<RunReport>,
    /// The run on all training points: from `start` (no screening) or from the screening end
    /// point; `None` when the start was merged into another one or its screening failed.
    pub on_all_points: Option<RunReport>,
    /// The start whose screening end point this one's coincided with (no own refinement).
    pub merged_into: Option<usize>,
    /// The start with the best screening end point, when this one's subset LML lay more than
    /// the refinement window below it (no own refinement; [`crate::screening`]).
    #[serde(default)]
    pub outranked_by: Option<usize>,
    /// The start whose θ the refinement on all points began at, where not this start's own
    /// screening end point: the warm start ([`crate::fit_warm`]).
    #[serde(default)]
    pub refined_from: Option<usize>,
}

impl StartReport {
    /// The LML on all training points, if this start was refined successfully.
    pub fn log_marginal_likelihood(&self) -> Option<f64> {
        self.on_all_points
            .as_ref()
            .and_then(|r| r.log_marginal_likelihood)
    }

    /// True if a run of this start could not be evaluated.
    pub fn failed(&self) -> bool {
        self.on_subset
            .iter()
            .chain(&self.on_all_points)
            .any(|r| r.error.is_some())
    }
}

/// Diagnostics of a fitted GP.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct FitDiagnostics {
    /// Warnings for the caller to report.
    pub warnings: Vec<FitWarning>,
    /// The leave-one-out Q2 (closed form); `None` for a constant output.
    pub leave_one_out_q2: Option<f64>,
    /// Whether the hyper-parameters were optimised (false: given by the caller).
    pub optimized: bool,
    /// The index (in `starts`) of the run that gave the GP; start 0 is the data-driven one.
    pub best_start: Option<usize>,
    /// Every multi-start run, in start order.
    pub starts: Vec<StartReport>,
}

impl FitDiagnostics {
    /// True when any warning marks the fit as degenerate ([`FitWarning::is_degenerate`]).
    pub fn is_degenerate(&self) -> bool {
        self.warnings.iter().any(FitWarning::is_degenerate)
    }

    /// The warnings as human-readable lines.
    pub fn messages(&self) -> Vec<String> {
        self.warnings.iter().map(ToString::to_string).collect()
    }

    /// Total LML values computed on all training points (the expensive ones).
    pub fn total_evaluations(&self) -> usize {
        self.starts
            .iter()
            .filter_map(|s| s.on_all_points.as_ref())
            .map(|r| r.evaluations)
            .sum()
    }

    /// Total LML gradients computed on all training points.
    pub fn total_gradient_evaluations(&self) -> usize {
        self.starts
            .iter()
            .filter_map(|s| s.on_all_points.as_ref())
            .map(|r| r.gradient_evaluations)
            .sum()
    }

    /// Total LML values computed on the screening subset.
    pub fn total_screening_evaluations(&self) -> usize {
        self.starts
            .iter()
            .filter_map(|s| s.on_subset.as_ref())
            .map(|r| r.evaluations)
            .sum()
    }
}
