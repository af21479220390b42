//! The batch `Model` trait: the one abstraction every stage of iuq meets at.
//!
//! A model maps a batch of parameter vectors to a batch of outcomes. Each outcome is either an
//! [`Evaluation`] (output vector and, optionally, the computational standard deviation of each
//! output) or an [`EvaluationFailure`] with a reason. Failures are data: samplers reject them,
//! sensitivity estimators report them, surrogates skip them.

use crate::error::Result;
pub use crate::evaluation_failure::EvaluationFailure;

/// A successful model evaluation at one parameter vector.
#[derive(Debug, Clone, PartialEq)]
pub struct Evaluation {
    /// One value per output of the model, in the order of [`Model::output_names`].
    pub outputs: Vec<f64>,
    /// The computational standard deviation of each output (e.g. the spread of a simulator's
    /// measuring window, or a surrogate's predictive std), when the model knows it.
    pub computational_std: Option<Vec<f64>>,
}

impl Evaluation {
    /// An evaluation without a computational uncertainty.
    pub fn new(outputs: Vec<f64>) -> Self {
        Self {
            outputs,
            computational_std: None,
        }
    }

    /// An evaluation with a computational standard deviation per output.
    pub fn with_std(outputs: Vec<f64>, computational_std: Vec<f64>) -> Self {
        Self {
            outputs,
            computational_std: Some(computational_std),
        }
    }

    /// True when every output (and std, if any) is finite.
    pub fn is_finite(&self) -> bool {
        self.outputs.iter().all(|v| v.is_finite())
            && self
                .computational_std
                .as_ref()
                .is_none_or(|s| s.iter().all(|v| v.is_finite()))
    }
}

/// The outcome of evaluating a model at one parameter vector.
pub type Outcome = std::result::Result<Evaluation, EvaluationFailure>;

/// A model evaluated on batches of parameter vectors.
///
/// Implementations evaluate a batch however suits them (in-process on all cores, through a
/// campaign of processes, over the network) and return exactly one [`Outcome`] per point, in
/// order. The `Err` of the outer `Result` is reserved for failures of the whole batch
/// (a lost database, an unreachable server), never for a failure at one point.
pub trait Model: Send + Sync {
    /// Names of the inputs, in the order the parameter vectors use.
    fn input_names(&self) -> &[String];

    /// Names of the outputs, in the order [`Evaluation::outputs`] uses.
    fn output_names(&self) -> &[String];

    /// Evaluate the model at every point of `points`.
    fn evaluate_batch(&self, points: &[Vec<f64>]) -> Result<Vec<Outcome>>;

    /// A cheap approximation of [`Model::evaluate_batch`]'s outcomes, where the model has one:
    /// the screen of delayed-acceptance moves (Christen & Fox 2005), which evaluate the model
    /// itself only at the proposals the screen lets through. A surrogate gives its means with
    /// only the noise part of its predictive std (no triangular solve per point, which is most of
    /// a prediction's cost); it must fail exactly where `evaluate_batch` fails, or the moves
    /// that the screen rejects there are lost. `None` (the default): no screen.
    fn screening_batch(&self, points: &[Vec<f64>]) -> Option<Result<Vec<Outcome>>> {
        let _ = points;
        None
    }

    /// The screen as an affine map of a few coefficients, where it is one
    /// ([`crate::affine_screen`]): a likelihood can then evaluate the screen as a quadratic form
    /// in the coefficients. `None` (the default): the screen, if any, gives its outputs only.
    fn affine_screening(&self) -> Option<&dyn crate::affine_screen::AffineScreening> {
        None
    }

    /// Number of inputs.
    fn input_dimension(&self) -> usize {
        self.input_names().len()
    }

    /// Number of outputs.
    fn output_dimension(&self) -> usize {
        self.output_names().len()
    }
}

/// Outcomes of a batch that are non-finite are turned into failures, so that NaN never leaves a model.
pub fn reject_non_finite(outcome: Outcome) -> Outcome {
    match outcome {
        Ok(e) if !e.is_finite() => Err(EvaluationFailure::new(
            "model returned a non-finite output".to_string(),
        )),
        other => other,
    }
}
