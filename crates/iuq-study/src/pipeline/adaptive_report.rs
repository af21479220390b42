//! The adaptive engine and the failure classifiers as the report shows them: the convergence of
//! the posterior round by round, the failure map of each run group with failures, and the runs
//! per data point.

use iuq_core::ParameterSpace;
use iuq_report::{Convergence, ConvergenceRound, FailureMapPanel, RunsAtPoint};

use super::adaptive::AdaptiveOutcome;
use super::model_runs::ModelRuns;
use super::run_groups::{GroupRuns, RunOrigin};
use super::surrogate::Surrogate;
use crate::error::Result;

/// Cells per side of a failure map's probability grid.
const GRID: usize = 40;

/// Panels at most in the failure map.
const MAX_PANELS: usize = 8;

/// The convergence section's data.
pub(super) fn convergence(outcome: &AdaptiveOutcome) -> Convergence {
    let surrogate_error = if outcome.surrogate_error_multiple == 1.0 {
        "the surrogate's typical error on a posterior mean or std".to_string()
    } else {
        format!(
            "{} times the surrogate's typical error on a posterior mean or std",
            outcome.surrogate_error_multiple
        )
    };
    Convergence {
        criterion: format!(
            "every posterior mean and std moves by less than {0} posterior stds between rounds beyond twice the sampler's Monte Carlo error, that noise is itself below {0} posterior stds, {surrogate_error} is below {0} posterior stds, and the replicates that mix harder agree with the others within {0} posterior stds beyond their noise",
            outcome.tolerance
        ),
        converged: outcome.converged,
        stop_reason: outcome.stop_reason.clone(),
        parameters: outcome.parameters.clone(),
        rounds: outcome
            .rounds
            .iter()
            .map(|r| ConvergenceRound {
                round: r.round,
                runs: r.runs,
                new_runs: r.new_runs,
                mean: r.mean.clone(),
                std: r.std.clone(),
                shift: r.shift,
                shift_noise: r.shift_noise,
                surrogate_error: Some(r.surrogate_error),
                log_likelihood_std: r.log_likelihood_std,
                extrapolation_share: r.extrapolation_share,
                mixing_level: r.mixing_level,
                sampler_disagreement: r.sampler_agreement.as_ref().map(|a| a.disagreement),
            })
            .collect(),
        retrained_checks: outcome
            .retrained_checks
            .iter()
            .map(|c| {
                format!(
                    "After round {} the model at the posterior ({} runs) failed the check's test at {} (largest |z| {:.2}, bound {:.2}): its runs became training runs and the rounds went on.",
                    c.after_round,
                    c.runs,
                    c.failed_at
                        .iter()
                        .map(|x| x.to_string())
                        .collect::<Vec<_>>()
                        .join(", "),
                    c.verdict.largest_z,
                    c.verdict.z_bound
                )
            })
            .collect(),
    }
}

/// Runs, adaptive runs and failures informing each data point.
pub(super) fn runs_per_point(
    groups: &[GroupRuns],
    runs: &ModelRuns,
    xs: &[f64],
) -> Vec<RunsAtPoint> {
    let mut rows = Vec::with_capacity(xs.len());
    for (g, group) in groups.iter().enumerate() {
        for j in runs.group_outputs(g) {
            rows.push(RunsAtPoint {
                x: xs[j],
                runs: group.len(),
                adaptive: group.adaptive_runs(),
                failed: group.failure_reasons().len(),
            });
        }
    }
    rows
}

/// One panel per run group with failures (at most [`MAX_PANELS`]): the runs in the plane of the
/// two parameters the group's classifier finds most relevant (shortest length scales relative
/// to the prior ranges), over the classifier's probability of failure with the other
/// parameters at `centre` (the posterior mean).
pub(super) fn failure_map(
    groups: &[GroupRuns],
    surrogate: &Surrogate,
    space: &ParameterSpace,
    centre: &[f64],
    group_label: &dyn Fn(usize) -> String,
) -> Result<Vec<FailureMapPanel>> {
    let d = space.dimension();
    if d < 2 {
        return Ok(Vec::new());
    }
    let names = space.names();
    let ranges = space.ranges();
    let mut panels = Vec::new();
    for (g, group) in groups.iter().enumerate() {
        let Some(classifier) = surrogate.classifiers.get(g).and_then(Option::as_ref) else {
            continue;
        };
        if panels.len() == MAX_PANELS {
            break;
        }
        let lengths = classifier.length_scales_in_input_units();
        let mut order: Vec<usize> = (0..d).collect();
        order.sort_by(|&a, &b| {
            let ra = lengths[a] / (ranges[a].1 - ranges[a].0);
            let rb = lengths[b] / (ranges[b].1 - ranges[b].0);
            ra.total_cmp(&rb).then(a.cmp(&b))
        });
        let (a, b) = if order[0] < order[1] {
            (order[0], order[1])
        } else {
            (order[1], order[0])
        };
        let (xa, xb) = ranges[a];
        let (ya, yb) = ranges[b];
        let mut grid_points = Vec::with_capacity(GRID * GRID);
        for row in 0..GRID {
            for column in 0..GRID {
                let mut p = centre[..d].to_vec();
                p[a] = xa + (column as f64 + 0.5) / GRID as f64 * (xb - xa);
                p[b] = ya + (row as f64 + 0.5) / GRID as f64 * (yb - ya);
                grid_points.push(p);
            }
        }
        let probability = classifier.failure_probability(&grid_points)?;
        let (_, failed) = group.failure_labels();
        panels.push(FailureMapPanel {
            label: group_label(g),
            x_parameter: names[a].clone(),
            y_parameter: names[b].clone(),
            bounds: (xa, xb, ya, yb),
            points: group.points.iter().map(|p| (p[a], p[b])).collect(),
            failed,
            adaptive: group
                .origins
                .iter()
                .map(|o| matches!(o, RunOrigin::Adaptive { .. } | RunOrigin::Check { .. }))
                .collect(),
            failure_probability: probability,
            grid_size: (GRID, GRID),
        });
    }
    Ok(panels)
}
