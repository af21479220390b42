//! What the pipeline's stages keep and tell: the runs of each data point (`model-runs.csv`),
//! how a data point is named, the stages' times, a campaign moved aside and the model
//! posterior's BASIS checkpoint.

use std::path::{Path, PathBuf};
use std::time::Instant;

use iuq_basis::BasisState;

use super::events::Events;
use super::model_runs::ModelRuns;
use super::report_data::PointRuns;
use super::run_groups::GroupRuns;
use crate::error::{BadInput, Context, Result};
use crate::likelihood_section::DataLikelihood;
use crate::study::{ModelSection, Study};
use crate::table_io::write_numeric_csv;

/// Move `dir` aside to the first free `<dir>.previous-N`.
pub(super) fn move_aside(dir: &Path) -> Result<Option<PathBuf>> {
    if !dir.exists() {
        return Ok(None);
    }
    for k in 1.. {
        let target = PathBuf::from(format!("{}.previous-{k}", dir.display()));
        if !target.exists() {
            std::fs::rename(dir, &target)
                .with_context(|| format!("cannot move {} aside", dir.display()))?;
            return Ok(Some(target));
        }
    }
    Ok(None)
}

/// How a data point is named in messages: "at 1.36 Pa" for the cell model, "at t = 0.5"
/// otherwise.
pub(super) fn point_description(study: &Study, data: &DataLikelihood, j: usize) -> String {
    match (&study.model, &study.abscissa) {
        (ModelSection::RbcShear { .. }, _) => format!("at {} Pa", data.x[j]),
        (_, Some(name)) => format!("at {name} = {}", data.x[j]),
        (_, None) => format!("at {} = {} (output {})", data.x_column, data.x[j], j + 1),
    }
}

/// The runs of each data point, for the report and `model-runs.csv`.
pub(super) fn point_runs(
    groups: &[GroupRuns],
    runs: &ModelRuns,
    data: &DataLikelihood,
) -> Vec<PointRuns> {
    let mut points = Vec::with_capacity(data.x.len());
    for (g, group) in groups.iter().enumerate() {
        for (k, j) in runs.group_outputs(g).enumerate() {
            let training = group.training(k);
            let test = group.test(k);
            points.push(PointRuns {
                x: data.x[j],
                training_x: training.x,
                training_y: training.y,
                training_std: training.std,
                test_x: test.x,
                test_y: test.y,
                test_std: test.std,
                failures: group.failure_reasons(),
            });
        }
    }
    points
}

/// Add the time since `since` to the stage `label` (a stage repeated after a failed posterior
/// check counts every pass).
pub(super) fn add_seconds(stage_seconds: &mut Vec<(String, f64)>, label: &str, since: Instant) {
    let seconds = since.elapsed().as_secs_f64();
    match stage_seconds.iter_mut().find(|(l, _)| l == label) {
        Some((_, total)) => *total += seconds,
        None => stage_seconds.push((label.to_string(), seconds)),
    }
}

pub(super) fn resume_checkpoint(dir: &Path, events: &Events) -> Result<Option<BasisState>> {
    let path = dir.join("checkpoint.json");
    if !path.exists() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("cannot read {}", path.display()))?;
    let state = iuq_basis::checkpoint::from_json(&text)
        .bad_input(|| format!("{}: not a BASIS checkpoint", path.display()))?;
    events.message(format!(
        "resuming the model posterior from {}",
        path.display()
    ));
    Ok(Some(state))
}

pub(super) fn write_runs_csv(path: &Path, names: &[String], runs: &[PointRuns]) -> Result<()> {
    let mut columns = vec!["x".to_string(), "set".to_string()];
    columns.extend(names.iter().cloned());
    columns.push("y".into());
    columns.push("y_std".into());
    let mut rows = Vec::new();
    for r in runs {
        for (set, xs, ys, ss) in [
            (0.0, &r.training_x, &r.training_y, &r.training_std),
            (1.0, &r.test_x, &r.test_y, &r.test_std),
        ] {
            for ((x, y), s) in xs.iter().zip(ys).zip(ss) {
                let mut row = vec![r.x, set];
                row.extend(x.iter().copied());
                row.push(*y);
                row.push(*s);
                rows.push(row);
            }
        }
    }
    write_numeric_csv(path, &columns, &rows)
}
