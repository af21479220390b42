//! What the two scheduler executors ([`super::slurm`], [`super::hyperqueue`]) share about job
//! arrays: the manifest that tells each array index its task, and the book-keeping of a task
//! between submission and its worker's result.

use std::path::{Path, PathBuf};

use crate::atomic_file::write_atomically;
use crate::error::{CampaignError, Result};
use crate::executor::{ExecutorEvent, SubmittedTask};
use crate::outcome::unix_now;
use crate::worker::ArrayManifest;

/// A submitted task as its executor follows it.
#[derive(Debug, Clone)]
pub(crate) struct ArrayTask {
    /// The task and the attempts it carries.
    pub(crate) task: SubmittedTask,
    /// Whether its `Started` events were sent.
    pub(crate) started: bool,
    /// Consecutive polls in which the scheduler no longer listed it and no result had arrived.
    pub(crate) missing_polls: u32,
}

impl ArrayTask {
    /// A task just submitted (or reattached): not yet seen running.
    pub(crate) fn new(task: SubmittedTask) -> Self {
        Self {
            task,
            started: false,
            missing_polls: 0,
        }
    }

    /// Mark the task running and return the `Started` event of each of its attempts, once: later
    /// calls return nothing.
    pub(crate) fn start(&mut self, external_id: &str, host: Option<String>) -> Vec<ExecutorEvent> {
        if self.started {
            return Vec::new();
        }
        self.started = true;
        let started_at = unix_now();
        self.task
            .attempt_ids
            .iter()
            .map(|&attempt_id| ExecutorEvent::Started {
                attempt_id,
                external_id: Some(external_id.to_string()),
                host: host.clone(),
                started_at,
            })
            .collect()
    }
}

/// Write the manifest of the `number`-th array of this coordinator into `dir`, atomically, as
/// `array-<milliseconds>-<number>.json`, and return its stem (for the array's other files) and
/// path. `executor` names the executor in errors.
pub(crate) fn write_manifest(
    executor: &'static str,
    dir: &Path,
    number: usize,
    spec: &Path,
    tasks: &[SubmittedTask],
) -> Result<(String, PathBuf)> {
    let stem = format!("array-{}-{number}", (unix_now() * 1000.0) as u64);
    let path = dir.join(format!("{stem}.json"));
    let manifest = ArrayManifest {
        spec: spec.to_path_buf(),
        tasks: tasks.iter().map(|t| t.task.clone()).collect(),
    };
    let text = serde_json::to_vec(&manifest)
        .map_err(|e| CampaignError::executor(executor, e.to_string()))?;
    write_atomically(&path, &text, true)?;
    Ok((stem, path))
}
