//! A model made of one formula of the parameters and the data's abscissa `x`, evaluated at each
//! data point: output j is f(θ, x_j). It is how a data-driven likelihood gets an analytic model
//! without writing one output per datum (study key `[likelihood] prediction = "a + b*x"`).

use rayon::prelude::*;

use iuq_core::{CoreError, Evaluation, EvaluationFailure, Expression, Model, Outcome};

use crate::error::{BasisError, Result};

/// The name of the abscissa variable in a curve formula.
pub const ABSCISSA_NAME: &str = "x";

/// The model θ ↦ (f(θ, x_1), …, f(θ, x_n)) of one formula over the parameters and `x`.
#[derive(Debug, Clone)]
pub struct CurveModel {
    input_names: Vec<String>,
    output_names: Vec<String>,
    abscissae: Vec<f64>,
    expression: Expression,
}

impl CurveModel {
    /// Parse `formula` over `input_names` and `x`, to be evaluated at each of `abscissae`.
    /// Outputs are named `f(x=<value>)`. No parameter may be called `x`.
    pub fn new(input_names: Vec<String>, formula: &str, abscissae: Vec<f64>) -> Result<Self> {
        if input_names.iter().any(|n| n == ABSCISSA_NAME) {
            return Err(BasisError::InvalidLikelihood(format!(
                "a parameter is called `{ABSCISSA_NAME}`, the name of the data's abscissa in the prediction formula"
            )));
        }
        if abscissae.is_empty() {
            return Err(BasisError::InvalidData(
                "a curve model needs at least one abscissa".into(),
            ));
        }
        if let Some(x) = abscissae.iter().find(|x| !x.is_finite()) {
            return Err(BasisError::InvalidData(format!(
                "abscissa {x} is not finite"
            )));
        }
        let mut variables = input_names.clone();
        variables.push(ABSCISSA_NAME.into());
        let expression = Expression::parse(formula, &variables)?;
        let output_names = abscissae.iter().map(|x| format!("f(x={x})")).collect();
        Ok(Self {
            input_names,
            output_names,
            abscissae,
            expression,
        })
    }

    /// The abscissae x_j.
    pub fn abscissae(&self) -> &[f64] {
        &self.abscissae
    }

    fn evaluate_point(&self, theta: &[f64]) -> Outcome {
        let mut values = theta.to_vec();
        values.push(0.0);
        let k = values.len() - 1;
        let mut outputs = Vec::with_capacity(self.abscissae.len());
        for &x in &self.abscissae {
            values[k] = x;
            let v = self.expression.evaluate(&values);
            if !v.is_finite() {
                return Err(EvaluationFailure::new(format!(
                    "prediction `{}` is {v} at x = {x}",
                    self.expression.source()
                )));
            }
            outputs.push(v);
        }
        Ok(Evaluation::new(outputs))
    }
}

impl Model for CurveModel {
    fn input_names(&self) -> &[String] {
        &self.input_names
    }

    fn output_names(&self) -> &[String] {
        &self.output_names
    }

    fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
        if let Some(p) = points.iter().find(|p| p.len() != self.input_names.len()) {
            return Err(CoreError::DimensionMismatch {
                expected: self.input_names.len(),
                actual: p.len(),
            });
        }
        Ok(points
            .par_iter()
            .with_min_len(64)
            .map(|p| self.evaluate_point(p))
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn evaluates_the_formula_at_each_abscissa() {
        let m =
            CurveModel::new(vec!["a".into(), "b".into()], "a + b*x", vec![0.0, 1.0, 2.0]).unwrap();
        let out = m.evaluate_batch(&[vec![1.0, 2.0]]).unwrap();
        assert_eq!(out[0].as_ref().unwrap().outputs, vec![1.0, 3.0, 5.0]);
        assert_eq!(m.output_dimension(), 3);
        let m = CurveModel::new(vec!["a".into()], "ln(a - x)", vec![0.0, 2.0]).unwrap();
        assert!(m.evaluate_batch(&[vec![1.0]]).unwrap()[0].is_err());
        assert!(CurveModel::new(vec!["x".into()], "x", vec![1.0]).is_err());
        assert!(CurveModel::new(vec!["a".into()], "a + z", vec![1.0]).is_err());
        assert!(m.evaluate_batch(&[vec![1.0, 2.0]]).is_err());
    }
}
