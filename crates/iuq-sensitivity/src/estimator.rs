//! Point estimators of first-order and total Sobol' indices from a Saltelli design.
//!
//! With f_A, f_B the outputs on the base matrices A and B and f_ABi the outputs on A with
//! column i taken from B (docs/methods.md §3):
//! - first order (Saltelli et al. 2010): S_i = mean(f_B·(f_ABi − f_A)) / V;
//! - total (Jansen 1999): S_Ti = ½·mean((f_A − f_ABi)²) / V;
//! - V the population variance (ddof 0) of f over A and B together, as SALib computes it.

use crate::error::{Result, SensitivityError};

/// First-order and total indices of one output, and the variance they are normalised by.
#[derive(Debug, Clone, PartialEq)]
pub struct SobolEstimate {
    /// S_i, one per input.
    pub first_order: Vec<f64>,
    /// S_Ti, one per input.
    pub total: Vec<f64>,
    /// V, the output variance over A and B.
    pub variance: f64,
}

/// The model outputs of one Saltelli design, for one output, split by matrix.
#[derive(Debug, Clone, PartialEq)]
pub struct SaltelliValues {
    /// f(A_j), j = 1..N.
    pub f_a: Vec<f64>,
    /// f(B_j).
    pub f_b: Vec<f64>,
    /// f(AB_ij): `f_ab[i][j]` for input i.
    pub f_ab: Vec<Vec<f64>>,
}

impl SaltelliValues {
    /// Check shapes: N ≥ 2 base points, f_ab one row of length N per input, finite values.
    pub fn validate(&self) -> Result<()> {
        let n = self.f_a.len();
        if n < 2 {
            return Err(SensitivityError::InvalidInput(format!(
                "at least two base points are needed, got {n}"
            )));
        }
        if self.f_b.len() != n || self.f_ab.iter().any(|c| c.len() != n) {
            return Err(SensitivityError::InvalidInput(
                "f_A, f_B and every f_ABi must have the same length".into(),
            ));
        }
        if self.f_ab.is_empty() {
            return Err(SensitivityError::InvalidInput("no inputs".into()));
        }
        let all = self
            .f_a
            .iter()
            .chain(&self.f_b)
            .chain(self.f_ab.iter().flatten());
        if all.clone().any(|v| !v.is_finite()) {
            return Err(SensitivityError::InvalidInput(
                "outputs must be finite (failed runs are removed before estimation)".into(),
            ));
        }
        Ok(())
    }

    /// Number of base points N.
    pub fn base_points(&self) -> usize {
        self.f_a.len()
    }

    /// The values at the base points `rows` (with repetition, for bootstrap resamples).
    pub fn select(&self, rows: &[usize]) -> SaltelliValues {
        SaltelliValues {
            f_a: rows.iter().map(|&j| self.f_a[j]).collect(),
            f_b: rows.iter().map(|&j| self.f_b[j]).collect(),
            f_ab: self
                .f_ab
                .iter()
                .map(|c| rows.iter().map(|&j| c[j]).collect())
                .collect(),
        }
    }
}

/// Estimate S_i and S_Ti of every input; `output` names the output in errors.
pub fn estimate_indices(values: &SaltelliValues, output: &str) -> Result<SobolEstimate> {
    values.validate()?;
    let variance = pooled_variance(&values.f_a, &values.f_b);
    if variance <= 0.0 || !variance.is_finite() {
        return Err(SensitivityError::ZeroVariance(output.to_string()));
    }
    Ok(indices_with_variance(values, variance))
}

/// The estimators with a given V (bootstrap resamples whose V happens to vanish reuse it).
pub(crate) fn indices_with_variance(values: &SaltelliValues, variance: f64) -> SobolEstimate {
    let n = values.f_a.len() as f64;
    let mut first_order = Vec::with_capacity(values.f_ab.len());
    let mut total = Vec::with_capacity(values.f_ab.len());
    for f_abi in &values.f_ab {
        let mut s1 = 0.0;
        let mut st = 0.0;
        for ((&a, &b), &ab) in values.f_a.iter().zip(&values.f_b).zip(f_abi) {
            s1 += b * (ab - a);
            st += (a - ab) * (a - ab);
        }
        first_order.push(s1 / n / variance);
        total.push(0.5 * st / n / variance);
    }
    SobolEstimate {
        first_order,
        total,
        variance,
    }
}

/// Population variance of the concatenation of `a` and `b`.
pub(crate) fn pooled_variance(a: &[f64], b: &[f64]) -> f64 {
    let count = (a.len() + b.len()) as f64;
    let mean = a.iter().chain(b).sum::<f64>() / count;
    a.iter()
        .chain(b)
        .map(|v| (v - mean) * (v - mean))
        .sum::<f64>()
        / count
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn additive_linear_model_has_known_indices() {
        // f = x1 + 2 x2 on a tiny hand-made design: estimators follow the formulas exactly.
        let a = [[0.1, 0.2], [0.7, 0.4], [0.3, 0.9]];
        let b = [[0.5, 0.6], [0.2, 0.8], [0.9, 0.1]];
        let f = |x: [f64; 2]| x[0] + 2.0 * x[1];
        let f_a: Vec<f64> = a.iter().map(|&x| f(x)).collect();
        let f_b: Vec<f64> = b.iter().map(|&x| f(x)).collect();
        let f_ab: Vec<Vec<f64>> = (0..2)
            .map(|i| {
                (0..3)
                    .map(|j| {
                        let mut x = a[j];
                        x[i] = b[j][i];
                        f(x)
                    })
                    .collect()
            })
            .collect();
        let values = SaltelliValues {
            f_a: f_a.clone(),
            f_b: f_b.clone(),
            f_ab: f_ab.clone(),
        };
        let est = estimate_indices(&values, "f").unwrap();
        let v = pooled_variance(&f_a, &f_b);
        for i in 0..2 {
            let s1: f64 = (0..3).map(|j| f_b[j] * (f_ab[i][j] - f_a[j])).sum::<f64>() / 3.0 / v;
            let st: f64 = (0..3).map(|j| (f_a[j] - f_ab[i][j]).powi(2)).sum::<f64>() / 6.0 / v;
            assert!((est.first_order[i] - s1).abs() < 1e-15);
            assert!((est.total[i] - st).abs() < 1e-15);
        }
    }

    #[test]
    fn constant_output_and_bad_shapes_are_errors() {
        let constant = SaltelliValues {
            f_a: vec![1.0; 4],
            f_b: vec![1.0; 4],
            f_ab: vec![vec![1.0; 4]],
        };
        assert!(matches!(
            estimate_indices(&constant, "y"),
            Err(SensitivityError::ZeroVariance(_))
        ));
        let ragged = SaltelliValues {
            f_a: vec![1.0, 2.0],
            f_b: vec![1.0],
            f_ab: vec![vec![1.0, 2.0]],
        };
        assert!(estimate_indices(&ragged, "y").is_err());
        let nan = SaltelliValues {
            f_a: vec![1.0, f64::NAN],
            f_b: vec![1.0, 2.0],
            f_ab: vec![vec![1.0, 2.0]],
        };
        assert!(estimate_indices(&nan, "y").is_err());
    }
}
