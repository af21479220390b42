//! Log-likelihoods evaluated on batches of parameter vectors.
//!
//! The sampler sends every batch (the prior draws of stage 0, the proposals of one MCMC step)
//! through [`LogLikelihood::log_likelihood_batch`] in one call, so a likelihood backed by an
//! expensive model runs one campaign batch per step and a cheap one (an expression, a GP bank)
//! evaluates the batch on all cores. Points outside the prior support are never sent.
//!
//! Three likelihoods are provided: the prediction-error model of a [`iuq_core::Model`] against
//! data ([`crate::PredictionErrorLikelihood`]), a direct log-density expression of the
//! parameters ([`LogDensityLikelihood`], study key `[likelihood] log_density = "..."`) and a Rust
//! closure ([`FnLikelihood`]).

use rayon::prelude::*;

use iuq_core::{EvaluationFailure, Expression, ParameterSpace};

use crate::error::{BasisError, Result};

/// The log-likelihood at one point, or why there is none (the model failed, a variance was
/// zero). The sampler treats a failure, and any non-finite value, as ln f = −∞: a rejection,
/// counted with its reason.
pub type PointLogLikelihood = std::result::Result<f64, EvaluationFailure>;

/// A log-likelihood ln f(D | θ) of the sampled parameters θ, evaluated on batches.
pub trait LogLikelihood: Send + Sync {
    /// Number of parameters θ has (the sampler checks it against its parameter space).
    fn parameter_count(&self) -> usize;

    /// ln f(D | θ) at every point, in order, one entry per point.
    ///
    /// The outer `Err` is for a failure of the whole batch (the model's infrastructure); a
    /// failure at one point is an `Err` entry of the vector.
    fn log_likelihood_batch(&self, points: &[Vec<f64>]) -> Result<Vec<PointLogLikelihood>>;

    /// A cheap approximation of ln f at every point, where the likelihood has one (the screen
    /// of delayed acceptance, [`crate::BasisSettings::delayed_acceptance`]): finite exactly
    /// where [`LogLikelihood::log_likelihood_batch`] is. The closer it follows ln f, the more
    /// of the moves it lets through are accepted; the sampled law does not depend on it.
    /// `None` (the default): no screen, every move is evaluated.
    fn screening_log_likelihood_batch(
        &self,
        points: &[Vec<f64>],
    ) -> Option<Result<Vec<PointLogLikelihood>>> {
        let _ = points;
        None
    }
}

impl<L: LogLikelihood + ?Sized> LogLikelihood for &L {
    fn parameter_count(&self) -> usize {
        (**self).parameter_count()
    }
    fn log_likelihood_batch(&self, points: &[Vec<f64>]) -> Result<Vec<PointLogLikelihood>> {
        (**self).log_likelihood_batch(points)
    }
    fn screening_log_likelihood_batch(
        &self,
        points: &[Vec<f64>],
    ) -> Option<Result<Vec<PointLogLikelihood>>> {
        (**self).screening_log_likelihood_batch(points)
    }
}

impl<L: LogLikelihood + ?Sized> LogLikelihood for Box<L> {
    fn parameter_count(&self) -> usize {
        (**self).parameter_count()
    }
    fn log_likelihood_batch(&self, points: &[Vec<f64>]) -> Result<Vec<PointLogLikelihood>> {
        (**self).log_likelihood_batch(points)
    }
    fn screening_log_likelihood_batch(
        &self,
        points: &[Vec<f64>],
    ) -> Option<Result<Vec<PointLogLikelihood>>> {
        (**self).screening_log_likelihood_batch(points)
    }
}

/// A log-likelihood given as a Rust closure of the parameter vector, evaluated in parallel over
/// each batch (the reference problems of the tests, quick experiments).
pub struct FnLikelihood<F> {
    parameter_count: usize,
    function: F,
}

impl<F: Fn(&[f64]) -> f64 + Send + Sync> FnLikelihood<F> {
    /// A likelihood of `parameter_count` parameters computing ln f with `function`.
    pub fn new(parameter_count: usize, function: F) -> Self {
        Self {
            parameter_count,
            function,
        }
    }
}

impl<F: Fn(&[f64]) -> f64 + Send + Sync> LogLikelihood for FnLikelihood<F> {
    fn parameter_count(&self) -> usize {
        self.parameter_count
    }

    fn log_likelihood_batch(&self, points: &[Vec<f64>]) -> Result<Vec<PointLogLikelihood>> {
        Ok(points
            .par_iter()
            .with_min_len(64)
            .map(|x| Ok((self.function)(x)))
            .collect())
    }
}

impl<F> std::fmt::Debug for FnLikelihood<F> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FnLikelihood")
            .field("parameter_count", &self.parameter_count)
            .finish_non_exhaustive()
    }
}

/// A log-likelihood written directly as an analytic expression of the parameters (study key
/// `[likelihood] log_density = "-(100*(y - x^2)^2 + (x - 1)^2)"`), with no model and no data.
///
/// The expression's variables are the parameter names of the space, in order. A non-finite
/// value (e.g. `ln` of a negative number) is a failure at that point.
#[derive(Debug, Clone)]
pub struct LogDensityLikelihood {
    expression: Expression,
    parameter_count: usize,
}

impl LogDensityLikelihood {
    /// Parse `source` over the parameter names of `space`.
    pub fn new(source: &str, space: &ParameterSpace) -> Result<Self> {
        let expression = Expression::parse(source, &space.names())?;
        Ok(Self {
            expression,
            parameter_count: space.dimension(),
        })
    }

    /// The expression as written.
    pub fn source(&self) -> &str {
        self.expression.source()
    }
}

impl LogLikelihood for LogDensityLikelihood {
    fn parameter_count(&self) -> usize {
        self.parameter_count
    }

    fn log_likelihood_batch(&self, points: &[Vec<f64>]) -> Result<Vec<PointLogLikelihood>> {
        if let Some(p) = points.iter().find(|p| p.len() != self.parameter_count) {
            return Err(BasisError::InvalidLikelihood(format!(
                "log_density expects {} parameters, got a point with {}",
                self.parameter_count,
                p.len()
            )));
        }
        Ok(points
            .par_iter()
            .with_min_len(256)
            .map(|x| {
                let v = self.expression.evaluate(x);
                if v.is_nan() || v == f64::INFINITY {
                    Err(EvaluationFailure::new(format!(
                        "log_density `{}` is {v}",
                        self.expression.source()
                    )))
                } else {
                    Ok(v)
                }
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use iuq_core::{Parameter, Prior};

    fn space(names: &[&str]) -> ParameterSpace {
        ParameterSpace::new(
            names
                .iter()
                .map(|n| Parameter {
                    name: n.to_string(),
                    prior: Prior::Uniform(-15.0, 15.0),
                })
                .collect(),
        )
        .unwrap()
    }

    #[test]
    fn log_density_expression_evaluates_and_reports_non_finite_values() {
        let s = space(&["x", "y"]);
        let l = LogDensityLikelihood::new("-(100*(y - x^2)^2 + (x - 1)^2)", &s).unwrap();
        let v = l
            .log_likelihood_batch(&[vec![1.0, 1.0], vec![0.0, 1.0]])
            .unwrap();
        assert_eq!(v[0], Ok(0.0));
        assert_eq!(v[1], Ok(-101.0));
        let l = LogDensityLikelihood::new("ln(x)", &s).unwrap();
        let v = l.log_likelihood_batch(&[vec![-1.0, 0.0]]).unwrap();
        assert!(v[0].is_err());
        assert!(LogDensityLikelihood::new("z + 1", &s).is_err());
        assert!(l.log_likelihood_batch(&[vec![1.0]]).is_err());
    }
}
