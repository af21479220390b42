//! Two-stage multi-start for larger training sets: screen every start on a subset of the
//! training points, refine only the distinct candidates on all of them.
//!
//! One LML evaluation costs O(n³); a start far from the optimum needs 30–90 of them. On a
//! subset of m ≪ n points an evaluation costs (m/n)³ as much, and the subset's optima lie close
//! to the full data's (the hyper-parameters describe the same function). So, when n > 2m:
//! 1. every start is optimised on m training points taken at evenly spaced indices
//!    ⌊i·n/m⌋ (the design's own density, whatever its order);
//! 2. the end points are ranked by their subset LML; an end point within 0.01 (max-norm in
//!    log space, i.e. 1 %) of a better one is merged into it — both would refine to the same
//!    optimum;
//! 3. each remaining end point is refined by an optimisation on all n points (with a 100×
//!    tighter function tolerance, as there are few such runs).
//!
//! On the 500-point, 11-start benchmark of the crate's `timing` example this cuts the full-data
//! LML evaluations from ≈ 590 to ≈ 110 (two distinct candidates refined) at an equal or better
//! optimum.

use crate::data::ColumnMajor;
use crate::gaussian_process::Prepared;

/// Max-norm distance in log space below which two screening end points are merged.
pub(crate) const MERGE_DISTANCE: f64 = 0.01;

/// Factor applied to the function tolerance of the refinement runs.
pub(crate) const REFINEMENT_TOLERANCE_FACTOR: f64 = 1e-2;

/// The training points at indices ⌊i·n/m⌋, i = 0..m.
pub(crate) fn subset(prepared: &Prepared, m: usize) -> Prepared {
    let n = prepared.x.n;
    let d = prepared.x.d;
    let indices: Vec<usize> = (0..m).map(|i| i * n / m).collect();
    let mut values = Vec::with_capacity(m * d);
    for k in 0..d {
        let column = prepared.x.column(k);
        values.extend(indices.iter().map(|&i| column[i]));
    }
    Prepared {
        input_scaling: prepared.input_scaling.clone(),
        output_scaling: prepared.output_scaling,
        x: ColumnMajor { n: m, d, values },
        y: indices.iter().map(|&i| prepared.y[i]).collect(),
        warnings: Vec::new(),
    }
}

/// For each screening end point (θ, LML; `None` for a failed run): `None` if it is to be
/// refined, or `Some(j)` if it lies within [`MERGE_DISTANCE`] of the better end point j.
/// Candidates are taken in order of decreasing LML (ties: lower index first).
pub(crate) fn merge_duplicates(ends: &[(Vec<f64>, Option<f64>)]) -> Vec<Option<usize>> {
    let mut order: Vec<usize> = (0..ends.len()).filter(|&i| ends[i].1.is_some()).collect();
    order.sort_by(|&a, &b| {
        let (la, lb) = (
            ends[a].1.unwrap_or(f64::NEG_INFINITY),
            ends[b].1.unwrap_or(f64::NEG_INFINITY),
        );
        lb.total_cmp(&la).then(a.cmp(&b))
    });
    let mut merged = vec![None; ends.len()];
    let mut kept: Vec<usize> = Vec::new();
    for i in order {
        let close = kept.iter().copied().find(|&r| {
            ends[i]
                .0
                .iter()
                .zip(&ends[r].0)
                .all(|(a, b)| (a - b).abs() <= MERGE_DISTANCE)
        });
        match close {
            Some(r) => merged[i] = Some(r),
            None => kept.push(i),
        }
    }
    merged
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gaussian_process::prepare;
    use crate::test_data::quasi_random_data;

    #[test]
    fn subset_takes_evenly_spaced_points() {
        let (x, y) = quasi_random_data(10);
        let p = prepare(&x, &y, false, false).unwrap();
        let s = subset(&p, 4);
        assert_eq!(s.x.n, 4);
        for (j, i) in [0usize, 2, 5, 7].into_iter().enumerate() {
            assert_eq!(s.y[j], y[i]);
            assert_eq!(s.x.values[4 + j], x[i][1]);
        }
    }

    #[test]
    fn merging_keeps_the_best_of_each_cluster() {
        let ends = vec![
            (vec![0.0, 1.0], Some(5.0)),
            (vec![0.005, 1.002], Some(6.0)),
            (vec![2.0, 1.0], Some(1.0)),
            (vec![0.0, 1.0], None),
            (vec![0.003, 0.999], Some(6.0)),
        ];
        assert_eq!(
            merge_duplicates(&ends),
            vec![Some(1), None, None, None, Some(1)]
        );
    }
}
