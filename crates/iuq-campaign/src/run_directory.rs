//! Run directories: where one task's command runs.
//!
//! A `command` run gets `runs/<run id>/` holding `params.json` (the parameters, the derived
//! values and `run_id`, one flat JSON object) and the study's templates with their placeholders
//! filled. A `batch-command` task gets `batches/<first run id>/` holding the input CSV
//! (`run_id`, parameters, derived values; one row per run). Both hold the worker's bookkeeping:
//! `iuq-status.json`, `iuq-result.json`, and `iuq-stdout.log`/`iuq-stderr.log` when the command
//! printed anything. A new attempt starts
//! from an empty directory.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use iuq_core::Expression;

use crate::study::{CommandKind, CommandSpec};
use crate::template::format_value;

/// The worker's result file in a task directory.
pub const RESULT_FILE: &str = "iuq-result.json";
/// The worker's status file in a task directory.
pub const STATUS_FILE: &str = "iuq-status.json";
/// The command's standard output (created when it prints something).
pub const STDOUT_FILE: &str = "iuq-stdout.log";
/// The command's standard error (created when it prints something).
pub const STDERR_FILE: &str = "iuq-stderr.log";

/// One run inside a task: its id, attempt number and parameter vector.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TaskRun {
    /// The run's id in the store.
    pub run_id: i64,
    /// The attempt number of this execution (1 for the first).
    pub attempt: u32,
    /// The parameter vector.
    pub parameters: Vec<f64>,
}

/// One unit of execution: one process in one directory, for one run (`command`) or a batch of
/// runs (`batch-command`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Task {
    /// The task directory (absolute).
    pub directory: PathBuf,
    /// The runs it executes.
    pub runs: Vec<TaskRun>,
}

/// The directory of run `run_id` (`command`) under the campaign directory.
pub fn run_directory(campaign_dir: &Path, run_id: i64) -> PathBuf {
    campaign_dir.join("runs").join(format!("{run_id:06}"))
}

/// The directory of the batch whose first run is `first_run_id` (`batch-command`).
pub fn batch_directory(campaign_dir: &Path, first_run_id: i64) -> PathBuf {
    campaign_dir
        .join("batches")
        .join(format!("{first_run_id:06}"))
}

/// The task directory of a group of runs for `spec`.
pub fn task_directory(campaign_dir: &Path, spec: &CommandSpec, first_run_id: i64) -> PathBuf {
    match spec.kind {
        CommandKind::Command => run_directory(campaign_dir, first_run_id),
        CommandKind::BatchCommand { .. } => batch_directory(campaign_dir, first_run_id),
    }
}

/// The named values of one run: parameters, derived values (in order), `run_id`.
pub fn run_values(spec: &CommandSpec, derived: &[Expression], run: &TaskRun) -> Vec<(String, f64)> {
    let mut values: Vec<f64> = run.parameters.clone();
    for e in derived {
        let v = e.evaluate(&values);
        values.push(v);
    }
    let mut named: Vec<(String, f64)> = spec
        .parameters
        .iter()
        .chain(spec.derived.iter().map(|(n, _)| n))
        .cloned()
        .zip(values)
        .collect();
    named.push(("run_id".into(), run.run_id as f64));
    named
}

fn io(path: &Path, e: std::io::Error) -> String {
    format!("{}: {e}", path.display())
}

/// True when `dir` has the shape of the directory of a task whose first run is `first_run_id`:
/// `…/runs/<id>` or `…/batches/<id>` ([`run_directory`], [`batch_directory`]). A worker empties
/// only such a directory, so a manifest edited by hand (or damaged) to name another directory
/// cannot make it delete that directory's contents.
pub fn is_task_directory_of(dir: &Path, first_run_id: i64) -> bool {
    let name_matches = dir
        .file_name()
        .is_some_and(|n| n.to_str() == Some(format!("{first_run_id:06}").as_str()));
    let parent_matches = dir
        .parent()
        .and_then(Path::file_name)
        .is_some_and(|p| p == "runs" || p == "batches");
    name_matches && parent_matches
}

/// Create the task directory afresh and write its inputs. The error is a reason (the task's
/// runs fail with it as an infrastructure failure); a directory that is not shaped like the
/// task's own ([`is_task_directory_of`]) is refused before anything in it is removed.
pub fn prepare(spec: &CommandSpec, derived: &[Expression], task: &Task) -> Result<(), String> {
    let dir = &task.directory;
    let first_run_id = task.runs.first().ok_or("a task without runs")?.run_id;
    if !is_task_directory_of(dir, first_run_id) {
        return Err(format!(
            "{}: not the directory of run {first_run_id} (`runs/{first_run_id:06}` or \
             `batches/{first_run_id:06}` of the campaign); refusing to empty it",
            dir.display()
        ));
    }
    match std::fs::remove_dir_all(dir) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(io(dir, e)),
    }
    if let Err(e) = std::fs::create_dir(dir) {
        if e.kind() != std::io::ErrorKind::NotFound {
            return Err(io(dir, e));
        }
        let parent = dir.parent().unwrap_or(dir);
        std::fs::create_dir_all(parent).map_err(|e| io(parent, e))?;
        std::fs::create_dir(dir).map_err(|e| io(dir, e))?;
    }
    match &spec.kind {
        CommandKind::Command => {
            let run = task.runs.first().ok_or("a task without runs")?;
            let values = run_values(spec, derived, run);
            let mut params = serde_json::Map::new();
            for (name, v) in &values {
                let json = if name == "run_id" {
                    serde_json::json!(run.run_id)
                } else {
                    serde_json::Number::from_f64(*v)
                        .map_or(serde_json::Value::Null, serde_json::Value::Number)
                };
                params.insert(name.clone(), json);
            }
            let path = dir.join("params.json");
            let text = serde_json::to_string_pretty(&params).map_err(|e| e.to_string())?;
            std::fs::write(&path, text).map_err(|e| io(&path, e))?;
            for t in &spec.templates {
                let path = dir.join(&t.target);
                if let Some(parent) = path.parent() {
                    std::fs::create_dir_all(parent).map_err(|e| io(parent, e))?;
                }
                let text = t.template.render(|name| {
                    values
                        .iter()
                        .find(|(n, _)| n == name)
                        .map(|(_, v)| format_value(*v))
                });
                std::fs::write(&path, text).map_err(|e| io(&path, e))?;
            }
        }
        CommandKind::BatchCommand { input, .. } => {
            let path = dir.join(input);
            let mut writer = csv::Writer::from_writer(Vec::new());
            let mut header = vec!["run_id".to_string()];
            header.extend(spec.parameters.iter().cloned());
            header.extend(spec.derived.iter().map(|(n, _)| n.clone()));
            writer.write_record(&header).map_err(|e| e.to_string())?;
            for run in &task.runs {
                let values = run_values(spec, derived, run);
                let mut record = vec![run.run_id.to_string()];
                record.extend(
                    values
                        .iter()
                        .filter(|(n, _)| n != "run_id")
                        .map(|(_, v)| format!("{v:?}")),
                );
                writer.write_record(&record).map_err(|e| e.to_string())?;
            }
            let bytes = writer.into_inner().map_err(|e| e.to_string())?;
            std::fs::write(&path, bytes).map_err(|e| io(&path, e))?;
            for t in &spec.templates {
                let path = dir.join(&t.target);
                if let Some(parent) = path.parent() {
                    std::fs::create_dir_all(parent).map_err(|e| io(parent, e))?;
                }
                std::fs::write(&path, t.template.render(|_| None)).map_err(|e| io(&path, e))?;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::study::CampaignStudy;

    const STUDY: &str = r#"name = "guard"
[parameters]
x = { uniform = [0, 1] }
[model]
kind = "command"
command = ["true"]
outputs = ["f"]
output = { file = "result.json", format = "json" }
"#;

    #[test]
    fn only_a_directory_shaped_like_the_tasks_own_is_emptied() {
        let campaign = std::env::temp_dir().join(format!("iuq-guard-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&campaign);
        assert!(is_task_directory_of(&run_directory(&campaign, 7), 7));
        assert!(is_task_directory_of(
            &batch_directory(&campaign, 1_234_567),
            1_234_567
        ));
        assert!(!is_task_directory_of(&run_directory(&campaign, 7), 8));
        assert!(!is_task_directory_of(
            &campaign.join("other").join("000007"),
            7
        ));
        assert!(!is_task_directory_of(Path::new("/"), 7));

        let study = CampaignStudy::parse(STUDY, &campaign.join("study.toml")).unwrap();
        let precious = campaign.join("precious");
        std::fs::create_dir_all(&precious).unwrap();
        std::fs::write(precious.join("thesis.tex"), "years of work").unwrap();
        let run = TaskRun {
            run_id: 7,
            attempt: 1,
            parameters: vec![0.5],
        };
        let task = Task {
            directory: precious.clone(),
            runs: vec![run.clone()],
        };
        let reason = prepare(&study.model, &[], &task).unwrap_err();
        assert!(
            reason.contains("refusing to empty") && reason.contains("runs/000007"),
            "{reason}"
        );
        assert!(precious.join("thesis.tex").exists());

        let own = run_directory(&campaign, 7);
        std::fs::create_dir_all(&own).unwrap();
        std::fs::write(own.join("stale.txt"), "from an earlier attempt").unwrap();
        let task = Task {
            directory: own.clone(),
            runs: vec![run],
        };
        prepare(&study.model, &[], &task).unwrap();
        assert!(!own.join("stale.txt").exists() && own.join("params.json").exists());
        let _ = std::fs::remove_dir_all(&campaign);
    }
}
