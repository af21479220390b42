//! The Saltelli design for Sobol' sensitivity indices (Saltelli 2002; Saltelli et al. 2010).
//!
//! Two independent `N × d` matrices `A` and `B` are taken from one `2d`-dimensional Sobol'
//! sequence (`A` = its first `d` columns, `B` = its last `d`), as SALib does; `AB_i` is `A` with
//! column `i` taken from `B`. The model is evaluated on the `N(d + 2)` rows of `A`, `B` and every
//! `AB_i`, from which first-order indices `S_i = mean(f_B·(f_ABi − f_A))/V` (Saltelli 2010) and
//! total indices `S_Ti = ½·mean((f_A − f_ABi)²)/V` (Jansen 1999) follow.
//!
//! Rows are grouped per base point `j`: `[A_j, AB_1j, …, AB_dj, B_j]` (SALib's order without
//! second-order indices). A group holds everything the estimators need from base point `j`, so
//! a failed model run can be handled by dropping its whole group of `d + 2` rows without biasing
//! the others.

use std::ops::Range;

use crate::direction_numbers::SOBOL_MAX_DIM;
use crate::error::{DoeError, Result};
use crate::size::check_size;
use crate::sobol::{Scrambling, SobolSequence};

/// A Saltelli design: base matrices `A`, `B` (`N × d`) and, implicitly, the `d` matrices `AB_i`.
///
/// `AB_i` is not stored (it would take `N·d²` values); [`ab`](Self::ab) and
/// [`rows`](Self::rows) build it on demand.
#[derive(Debug, Clone, PartialEq)]
pub struct SaltelliDesign {
    /// Number of base points `N`.
    n: usize,
    /// Number of inputs `d`.
    dim: usize,
    /// Matrix `A`, `N` rows of `d` values.
    a: Vec<Vec<f64>>,
    /// Matrix `B`, `N` rows of `d` values.
    b: Vec<Vec<f64>>,
}

/// Model outputs of a Saltelli design split by matrix: `f_a[j] = f(A_j)`, `f_b[j] = f(B_j)`,
/// `f_ab[i][j] = f(AB_ij)`.
///
/// Generic over the value type, so that per-point outcomes (values or failures) can be split as
/// well as plain numbers.
#[derive(Debug, Clone, PartialEq)]
pub struct SaltelliOutputs<T = f64> {
    /// Outputs on the rows of `A` (`N` values).
    pub f_a: Vec<T>,
    /// Outputs on the rows of `B` (`N` values).
    pub f_b: Vec<T>,
    /// Outputs on the rows of `AB_i`, one vector of `N` values per input `i`.
    pub f_ab: Vec<Vec<T>>,
}

impl SaltelliDesign {
    /// The Saltelli design of `n` base points in `dim` inputs from the first `n` points of a
    /// `2·dim`-dimensional Sobol' sequence with the given scrambling (use independent
    /// `replicate`s for repeated-scrambling confidence intervals).
    ///
    /// Errors for `n = 0`, `dim = 0`, `2·dim > SOBOL_MAX_DIM` or more than
    /// [`MAX_DESIGN_VALUES`](crate::MAX_DESIGN_VALUES) values in [`rows`](Self::rows). Use `n` a power of two for the
    /// balance properties of the sequence; without scrambling, the first base point is the
    /// origin (for `A`) and `B_0` as well.
    pub fn new(n: usize, dim: usize, scrambling: Scrambling) -> Result<Self> {
        if n == 0 {
            return Err(DoeError::InvalidSampleSize {
                n,
                reason: "a Saltelli design needs at least one base point".into(),
            });
        }
        if dim == 0 || dim > SOBOL_MAX_DIM / 2 {
            return Err(DoeError::InvalidDimension {
                dim,
                reason: format!(
                    "a Saltelli design draws from a 2d-dimensional Sobol' sequence: 1 <= d <= {}",
                    SOBOL_MAX_DIM / 2
                ),
            });
        }
        check_size(n.saturating_mul(dim + 2), dim, "Saltelli design")?;
        let base = SobolSequence::new(2 * dim, scrambling)?.points(n)?;
        let (a, b) = base
            .into_iter()
            .map(|mut row| {
                let second = row.split_off(dim);
                (row, second)
            })
            .unzip();
        Ok(Self { n, dim, a, b })
    }

    /// A Saltelli design from given base matrices (e.g. plain Monte Carlo samples), which must
    /// have the same, non-zero, number of rows, all of the same non-zero length, and finite
    /// values (and [`rows`](Self::rows) at most [`MAX_DESIGN_VALUES`](crate::MAX_DESIGN_VALUES)
    /// values).
    pub fn from_matrices(a: Vec<Vec<f64>>, b: Vec<Vec<f64>>) -> Result<Self> {
        let n = a.len();
        if n == 0 || b.len() != n {
            return Err(DoeError::InvalidSampleSize {
                n,
                reason: format!(
                    "A and B need the same, non-zero, number of rows (got {} and {})",
                    n,
                    b.len()
                ),
            });
        }
        let dim = a[0].len();
        check_size(n.saturating_mul(dim + 2), dim, "Saltelli design")?;
        for (row, values) in a.iter().chain(&b).enumerate() {
            if values.len() != dim {
                return Err(DoeError::DimensionMismatch {
                    row,
                    expected: dim,
                    actual: values.len(),
                });
            }
            if let Some((column, &value)) = values.iter().enumerate().find(|(_, v)| !v.is_finite())
            {
                return Err(DoeError::NonFinite { row, column, value });
            }
        }
        Ok(Self { n, dim, a, b })
    }

    /// Number of base points `N`.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Number of inputs `d`.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Rows per base point, `d + 2`.
    pub fn group_size(&self) -> usize {
        self.dim + 2
    }

    /// Total number of model runs, `N(d + 2)`.
    pub fn len(&self) -> usize {
        self.n * self.group_size()
    }

    /// Whether the design has no rows (never true for a constructed design).
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Matrix `A` (`N` rows of `d` values).
    pub fn a(&self) -> &[Vec<f64>] {
        &self.a
    }

    /// Matrix `B` (`N` rows of `d` values).
    pub fn b(&self) -> &[Vec<f64>] {
        &self.b
    }

    /// Row `j` of `AB_i`: `A_j` with coordinate `i` from `B_j` (`i < d`, `j < N`; `None`
    /// otherwise).
    pub fn ab_row(&self, i: usize, j: usize) -> Option<Vec<f64>> {
        if i >= self.dim {
            return None;
        }
        let mut row = self.a.get(j)?.clone();
        row[i] = self.b[j][i];
        Some(row)
    }

    /// Matrix `AB_i` (`N` rows; `None` for `i ≥ d`).
    pub fn ab(&self, i: usize) -> Option<Vec<Vec<f64>>> {
        (0..self.n).map(|j| self.ab_row(i, j)).collect()
    }

    /// The range of rows of base point `j` in [`rows`](Self::rows): `j(d+2)..(j+1)(d+2)`.
    pub fn group(&self, j: usize) -> Range<usize> {
        j * self.group_size()..(j + 1) * self.group_size()
    }

    /// All `N(d + 2)` rows to evaluate, grouped per base point `j`:
    /// `[A_j, AB_1j, …, AB_dj, B_j]`, for `j = 0, …, N − 1` (so row `j(d+2)` is `A_j`, row
    /// `j(d+2) + 1 + i` is `AB_ij` and row `j(d+2) + d + 1` is `B_j`).
    pub fn rows(&self) -> Vec<Vec<f64>> {
        let mut rows = Vec::with_capacity(self.len());
        for j in 0..self.n {
            rows.push(self.a[j].clone());
            for i in 0..self.dim {
                let mut row = self.a[j].clone();
                row[i] = self.b[j][i];
                rows.push(row);
            }
            rows.push(self.b[j].clone());
        }
        rows
    }

    /// Splits the outputs of the rows of [`rows`](Self::rows) (same order) into `f_A`, `f_B` and
    /// `f_AB[i]`. Errors unless `values.len() == N(d + 2)`.
    pub fn split_outputs<T: Clone>(&self, values: &[T]) -> Result<SaltelliOutputs<T>> {
        if values.len() != self.len() {
            return Err(DoeError::OutputLength {
                expected: self.len(),
                actual: values.len(),
            });
        }
        let g = self.group_size();
        let mut out = SaltelliOutputs {
            f_a: Vec::with_capacity(self.n),
            f_b: Vec::with_capacity(self.n),
            f_ab: vec![Vec::with_capacity(self.n); self.dim],
        };
        for group in values.chunks_exact(g) {
            out.f_a.push(group[0].clone());
            for (f_ab_i, v) in out.f_ab.iter_mut().zip(&group[1..=self.dim]) {
                f_ab_i.push(v.clone());
            }
            out.f_b.push(group[g - 1].clone());
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn invalid_sizes_are_errors() {
        assert!(SaltelliDesign::new(0, 2, Scrambling::None).is_err());
        assert!(SaltelliDesign::new(8, 0, Scrambling::None).is_err());
        assert!(SaltelliDesign::new(8, SOBOL_MAX_DIM / 2 + 1, Scrambling::None).is_err());
        assert!(SaltelliDesign::from_matrices(vec![], vec![]).is_err());
        assert!(SaltelliDesign::from_matrices(vec![vec![0.1]], vec![vec![0.1, 0.2]]).is_err());
        assert!(SaltelliDesign::from_matrices(vec![vec![f64::NAN]], vec![vec![0.1]]).is_err());
    }
}
