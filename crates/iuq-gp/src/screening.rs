//! Two-stage multi-start for larger training sets: screen every start on a subset of the
//! training points, refine only the distinct candidates on all of them.
//!
//! One LML evaluation costs O(n³); a start far from the optimum needs 30–90 of them. On a
//! subset of m ≪ n points an evaluation costs (m/n)³ as much, and the subset's optima lie close
//! to the full data's (the hyper-parameters describe the same function). So, when n > 2m:
//! 1. every start is optimised on m training points taken at evenly spaced indices
//!    ⌊i·n/m⌋ (the design's own density, whatever its order);
//! 2. the end points are ranked by their subset LML; an end point is merged into a better one
//!    when both are the same optimum: within 0.01 of it (max-norm in log space, i.e. 1 %), or
//!    with an LML within [`MERGE_LML`] of it (the optimiser's ends along a flat ridge of the
//!    LML, which lie apart in θ but refine to the same surrogate);
//! 3. a remaining end point whose subset LML lies more than [`REFINEMENT_WINDOW`] nats below
//!    the best one's is not refined: the full data, a superset of the subset, widen an LML gap
//!    about n/m-fold rather than close it;
//! 4. each remaining end point is refined by an optimisation on all n points (with a 100×
//!    tighter function tolerance, as there are few such runs).
//!
//! On the 500-run, 20-output benchmark of `scripts/bench/round_cost.py` (twoexp, 11 starts per
//! output) steps 2–3 leave one refinement per output where the 1 % rule alone left 2–5, with the
//! same optimum (the refined LMLs of those candidates agreed to 10⁻³ nats, or the lower basins'
//! lay hundreds of nats below).

use crate::data::ColumnMajor;
use crate::gaussian_process::Prepared;

/// Max-norm distance in log space below which two screening end points are merged.
pub(crate) const MERGE_DISTANCE: f64 = 0.01;

/// Subset LMLs closer than this (nats) are one optimum: the optimiser's function tolerance on
/// a flat ridge leaves its end points 10⁻⁵–10⁻³ nats apart, while distinct local optima of the
/// benchmarks lie more than a nat apart.
pub const MERGE_LML: f64 = 0.01;

/// End points whose subset LML lies more than this many nats below the best one's are not
/// refined (a likelihood ratio of e² ≈ 7.4 on the subset alone).
pub const REFINEMENT_WINDOW: f64 = 2.0;

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

/// The end points that have an LML, as (index, LML) in order of decreasing LML (ties: lower
/// index first).
fn by_decreasing_lml(ends: &[(Vec<f64>, Option<f64>)]) -> Vec<(usize, f64)> {
    let mut order: Vec<(usize, f64)> = ends
        .iter()
        .enumerate()
        .filter_map(|(i, (_, lml))| lml.map(|v| (i, v)))
        .collect();
    order.sort_by(|&(a, la), &(b, lb)| lb.total_cmp(&la).then(a.cmp(&b)));
    order
}

/// What becomes of one screening end point.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Plan {
    /// Refined on all training points.
    Refine,
    /// The same optimum as the better end point j (no own refinement).
    MergedInto(usize),
    /// More than [`REFINEMENT_WINDOW`] nats below the best end point j on the subset.
    Outranked(usize),
    /// Its screening run failed.
    Failed,
    /// A warm start ([`crate::fit_warm`]) whose end point coincides with no candidate's.
    Unmatched,
}

/// Whether two end points are one optimum: θ within [`MERGE_DISTANCE`] (max-norm) or LML
/// within [`MERGE_LML`].
fn coincide(a: &(Vec<f64>, Option<f64>), b: &(Vec<f64>, Option<f64>)) -> bool {
    let (Some(la), Some(lb)) = (a.1, b.1) else {
        return false;
    };
    (la - lb).abs() <= MERGE_LML
        || a.0
            .iter()
            .zip(&b.0)
            .all(|(x, y)| (x - y).abs() <= MERGE_DISTANCE)
}

/// The candidate to refine (`Plan::Refine`) whose cluster the end point `ends[w]` coincides
/// with, taking the cluster members in order of decreasing LML; `plan` covers the end points
/// before `w`.
pub(crate) fn coinciding_candidate(
    ends: &[(Vec<f64>, Option<f64>)],
    plan: &[Plan],
    w: usize,
) -> Option<usize> {
    by_decreasing_lml(&ends[..plan.len()])
        .into_iter()
        .find_map(|(i, _)| {
            let candidate = match plan[i] {
                Plan::Refine => i,
                Plan::MergedInto(r) => r,
                _ => return None,
            };
            coincide(&ends[w], &ends[i]).then_some(candidate)
        })
}

/// For each screening end point (θ, LML; `None` for a failed run) its [`Plan`]. Candidates are
/// taken in order of decreasing LML (ties: lower index first); each is merged into the first
/// kept one it coincides with (θ within [`MERGE_DISTANCE`], or LML within [`MERGE_LML`]).
pub(crate) fn refinement_plan(ends: &[(Vec<f64>, Option<f64>)]) -> Vec<Plan> {
    let order = by_decreasing_lml(ends);
    let mut plan = vec![Plan::Failed; ends.len()];
    let Some(&(best, best_lml)) = order.first() else {
        return plan;
    };
    let mut kept: Vec<(usize, f64)> = Vec::new();
    for (i, lml) in order {
        let same = kept
            .iter()
            .copied()
            .find(|&(r, _)| coincide(&ends[i], &ends[r]));
        plan[i] = match same {
            Some((r, _)) => Plan::MergedInto(r),
            None if best_lml - lml > REFINEMENT_WINDOW => Plan::Outranked(best),
            None => {
                kept.push((i, lml));
                Plan::Refine
            }
        };
    }
    plan
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
            (vec![2.0, 1.0], Some(5.5)),
            (vec![0.0, 1.0], None),
            (vec![0.003, 0.999], Some(6.0)),
        ];
        assert_eq!(
            refinement_plan(&ends),
            vec![
                Plan::MergedInto(1),
                Plan::Refine,
                Plan::Refine,
                Plan::Failed,
                Plan::MergedInto(1)
            ]
        );
    }

    /// Ends along a flat ridge (apart in θ, equal LML to the optimiser's precision) are one
    /// candidate; an end point beyond the window below the best is not refined, one inside it
    /// is.
    #[test]
    fn ridges_merge_and_far_worse_optima_are_not_refined() {
        let ends = vec![
            (vec![0.0, 1.0], Some(806.2954)),
            (vec![0.4, 1.3], Some(806.2951)),
            (vec![-3.0, 0.2], Some(-184.3)),
            (vec![1.5, -1.0], Some(805.0)),
            (vec![2.5, -2.0], Some(806.2954 - REFINEMENT_WINDOW - 1e-6)),
        ];
        assert_eq!(
            refinement_plan(&ends),
            vec![
                Plan::Refine,
                Plan::MergedInto(0),
                Plan::Outranked(0),
                Plan::Refine,
                Plan::Outranked(0)
            ]
        );
        assert_eq!(refinement_plan(&[(vec![0.0], None)]), vec![Plan::Failed]);
    }

    /// A warm start's end point goes to the candidate of the cluster it coincides with (by θ
    /// or by LML), and to none where it ended in an optimum of its own.
    #[test]
    fn a_warm_end_point_joins_the_candidate_it_coincides_with() {
        let mut ends = vec![
            (vec![0.0, 1.0], Some(806.2954)),
            (vec![0.4, 1.3], Some(806.2951)),
            (vec![1.5, -1.0], Some(805.0)),
        ];
        let plan = refinement_plan(&ends);
        assert_eq!(plan, vec![Plan::Refine, Plan::MergedInto(0), Plan::Refine]);
        ends.push((vec![0.405, 1.295], Some(806.10)));
        assert_eq!(coinciding_candidate(&ends, &plan, 3), Some(0));
        ends[3] = (vec![1.504, -1.002], Some(804.9));
        assert_eq!(coinciding_candidate(&ends, &plan, 3), Some(2));
        ends[3] = (vec![3.0, 3.0], Some(900.0));
        assert_eq!(coinciding_candidate(&ends, &plan, 3), None);
        ends[3] = (vec![0.0, 1.0], None);
        assert_eq!(coinciding_candidate(&ends, &plan, 3), None);
    }
}
