//! Reads of the runs, attempts and outputs: pending runs, counts per status, failures, open
//! attempts, stored outcomes, succeeded runs, the tidy export, what a run costs — and the rows
//! they return.

use std::path::PathBuf;

use rusqlite::OptionalExtension;
use serde::Serialize;

use super::CampaignStore;
use super::parameters::decode_parameters;
use super::status::{RunStatus, StatusCounts};
use crate::error::Result;

/// A run that failed, with its reason.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FailedRun {
    /// The run.
    pub run_id: i64,
    /// Its parameters.
    pub parameters: Vec<f64>,
    /// Attempts made.
    pub attempts: u32,
    /// Outcome kind of the last attempt.
    pub kind: String,
    /// The reason of the last attempt.
    pub reason: String,
}

/// An execution that was submitted and has no outcome yet.
#[derive(Debug, Clone, PartialEq)]
pub struct OpenAttempt {
    /// The attempt row.
    pub attempt_id: i64,
    /// The run.
    pub run_id: i64,
    /// Attempt number.
    pub number: u32,
    /// The executor that ran it.
    pub executor: String,
    /// The scheduler's id (`jobid_index`, `job.task`, or a local pid).
    pub external_id: Option<String>,
    /// The task directory.
    pub directory: PathBuf,
    /// The run's parameters.
    pub parameters: Vec<f64>,
}

/// A run waiting to be executed.
#[derive(Debug, Clone, PartialEq)]
pub struct PendingRun {
    /// The run.
    pub run_id: i64,
    /// Its parameters.
    pub parameters: Vec<f64>,
    /// Attempts made so far.
    pub attempts: u32,
}

/// One row of the tidy export.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ExportRow {
    /// The run.
    pub run_id: i64,
    /// Its status.
    pub status: String,
    /// Its parameters.
    pub parameters: Vec<f64>,
    /// Its outputs (empty unless succeeded).
    pub outputs: Vec<f64>,
    /// Output stds, when known.
    pub std: Option<Vec<f64>>,
    /// Attempts made.
    pub attempts: u32,
    /// Outcome kind of the last attempt.
    pub kind: Option<String>,
    /// Failure reason.
    pub reason: Option<String>,
}

/// The stored outcome of a run: outputs (with stds) or a failure reason; `None` while not final.
pub type StoredOutcome = Option<std::result::Result<(Vec<f64>, Option<Vec<f64>>), String>>;

/// A succeeded run as [`CampaignStore::succeeded_runs`] lists it.
#[derive(Debug, Clone, PartialEq)]
pub struct SucceededRun {
    /// The run.
    pub run_id: i64,
    /// The attempt whose outputs are stored.
    pub attempt_id: i64,
    /// That attempt's run directory, as recorded.
    pub directory: PathBuf,
    /// The stored outputs, in the study's output order: value and std (`None`: no std stored).
    pub outputs: Vec<(f64, Option<f64>)>,
}

impl CampaignStore {
    /// The median wall time, in seconds, of the succeeded attempts that record when they
    /// started and finished (`None` when none does): what a run of the model costs, for
    /// allocating runs between models of different costs.
    pub fn median_run_seconds(&self) -> Result<Option<f64>> {
        let mut statement = self
            .connection
            .prepare(
                "SELECT finished_at - started_at FROM attempts WHERE outcome_kind = 'succeeded' AND started_at IS NOT NULL AND finished_at IS NOT NULL",
            )
            .map_err(|e| self.err(e))?;
        let mut seconds: Vec<f64> = statement
            .query_map([], |r| r.get::<_, f64>(0))
            .map_err(|e| self.err(e))?
            .collect::<std::result::Result<_, _>>()
            .map_err(|e| self.err(e))?;
        seconds.retain(|s| s.is_finite() && *s >= 0.0);
        if seconds.is_empty() {
            return Ok(None);
        }
        seconds.sort_by(f64::total_cmp);
        let m = seconds.len();
        Ok(Some(if m % 2 == 1 {
            seconds[m / 2]
        } else {
            0.5 * (seconds[m / 2 - 1] + seconds[m / 2])
        }))
    }

    /// Runs that are pending, oldest first, at most `limit`.
    pub fn pending_runs(&self, limit: usize) -> Result<Vec<PendingRun>> {
        self.pending_runs_among(None, limit)
    }

    /// Runs that are pending and, when `among` is given, in it; oldest first, at most `limit`.
    pub fn pending_runs_among(
        &self,
        among: Option<&std::collections::HashSet<i64>>,
        limit: usize,
    ) -> Result<Vec<PendingRun>> {
        let Some(among) = among else {
            return self.all_pending_runs(limit);
        };
        Ok(self
            .all_pending_runs(usize::MAX)?
            .into_iter()
            .filter(|r| among.contains(&r.run_id))
            .take(limit)
            .collect())
    }

    fn all_pending_runs(&self, limit: usize) -> Result<Vec<PendingRun>> {
        let mut stmt = self
            .connection
            .prepare_cached("SELECT id, parameters, attempts FROM runs WHERE status = 'pending' ORDER BY id LIMIT ?1")
            .map_err(|e| self.err(e))?;
        let rows = stmt
            .query_map([limit.min(i64::MAX as usize) as i64], |r| {
                Ok(PendingRun {
                    run_id: r.get(0)?,
                    parameters: decode_parameters(&r.get::<_, String>(1)?, 1)?,
                    attempts: r.get(2)?,
                })
            })
            .and_then(|rows| rows.collect::<std::result::Result<Vec<_>, _>>())
            .map_err(|e| self.err(e))?;
        Ok(rows)
    }

    /// Counts of runs per status (all runs, or those of `run_ids`).
    pub fn counts(&self, run_ids: Option<&[i64]>) -> Result<StatusCounts> {
        let mut counts = StatusCounts::default();
        let mut add = |status: &str, n: u64| counts.add(status, n);
        match run_ids {
            None => {
                let mut stmt = self
                    .connection
                    .prepare_cached("SELECT status, COUNT(*) FROM runs GROUP BY status")
                    .map_err(|e| self.err(e))?;
                let rows = stmt
                    .query_map([], |r| Ok((r.get::<_, String>(0)?, r.get::<_, i64>(1)?)))
                    .and_then(|rows| rows.collect::<std::result::Result<Vec<_>, _>>())
                    .map_err(|e| self.err(e))?;
                for (s, n) in rows {
                    add(&s, n as u64);
                }
            }
            Some(ids) => {
                let mut stmt = self
                    .connection
                    .prepare_cached("SELECT status FROM runs WHERE id = ?1")
                    .map_err(|e| self.err(e))?;
                let mut seen = std::collections::HashSet::new();
                for id in ids {
                    if seen.insert(*id) {
                        let s: Option<String> = stmt
                            .query_row([id], |r| r.get(0))
                            .optional()
                            .map_err(|e| self.err(e))?;
                        if let Some(s) = s {
                            add(&s, 1);
                        }
                    }
                }
            }
        }
        Ok(counts)
    }

    /// Failed runs with the kind and reason of their last attempt.
    pub fn failures(&self) -> Result<Vec<FailedRun>> {
        let mut stmt = self
            .connection
            .prepare("SELECT id, parameters, attempts, COALESCE(outcome_kind, ''), COALESCE(reason, '') FROM runs WHERE status = 'failed' ORDER BY id")
            .map_err(|e| self.err(e))?;
        stmt.query_map([], |r| {
            Ok(FailedRun {
                run_id: r.get(0)?,
                parameters: decode_parameters(&r.get::<_, String>(1)?, 1)?,
                attempts: r.get(2)?,
                kind: r.get(3)?,
                reason: r.get(4)?,
            })
        })
        .and_then(|rows| rows.collect())
        .map_err(|e| self.err(e))
    }

    /// Number of attempts per outcome kind (open attempts under `"open"`).
    pub fn attempt_kinds(&self) -> Result<Vec<(String, u64)>> {
        let mut stmt = self
            .connection
            .prepare("SELECT COALESCE(outcome_kind, 'open'), COUNT(*) FROM attempts GROUP BY 1 ORDER BY 1")
            .map_err(|e| self.err(e))?;
        stmt.query_map([], |r| Ok((r.get(0)?, r.get::<_, i64>(1)? as u64)))
            .and_then(|rows| rows.collect())
            .map_err(|e| self.err(e))
    }

    /// Attempts without an outcome (submitted by this or an earlier coordinator).
    pub fn open_attempts(&self) -> Result<Vec<OpenAttempt>> {
        let mut stmt = self
            .connection
            .prepare(
                "SELECT a.id, a.run_id, a.number, a.executor, a.external_id, a.directory, r.parameters
                 FROM attempts a JOIN runs r ON r.id = a.run_id WHERE a.outcome_kind IS NULL ORDER BY a.id",
            )
            .map_err(|e| self.err(e))?;
        stmt.query_map([], |r| {
            Ok(OpenAttempt {
                attempt_id: r.get(0)?,
                run_id: r.get(1)?,
                number: r.get(2)?,
                executor: r.get(3)?,
                external_id: r.get(4)?,
                directory: PathBuf::from(r.get::<_, String>(5)?),
                parameters: decode_parameters(&r.get::<_, String>(6)?, 6)?,
            })
        })
        .and_then(|rows| rows.collect())
        .map_err(|e| self.err(e))
    }

    /// The stored outcome of each run of `run_ids`.
    pub fn outcomes(&self, run_ids: &[i64]) -> Result<Vec<StoredOutcome>> {
        let mut status_stmt = self
            .connection
            .prepare_cached("SELECT status, COALESCE(reason, '') FROM runs WHERE id = ?1")
            .map_err(|e| self.err(e))?;
        let mut output_stmt = self
            .connection
            .prepare_cached("SELECT value, std FROM outputs WHERE run_id = ?1 ORDER BY position")
            .map_err(|e| self.err(e))?;
        let mut out = Vec::with_capacity(run_ids.len());
        for id in run_ids {
            let (status, reason): (String, String) = status_stmt
                .query_row([id], |r| Ok((r.get(0)?, r.get(1)?)))
                .map_err(|e| self.err(e))?;
            out.push(match RunStatus::from_name(&status) {
                Some(RunStatus::Succeeded) => {
                    let rows: Vec<(f64, Option<f64>)> = output_stmt
                        .query_map([id], |r| Ok((r.get(0)?, r.get(1)?)))
                        .and_then(|rows| rows.collect())
                        .map_err(|e| self.err(e))?;
                    let values = rows.iter().map(|r| r.0).collect();
                    let std = rows.iter().map(|r| r.1).collect::<Option<Vec<f64>>>();
                    Some(Ok((values, std)))
                }
                Some(RunStatus::Failed) => Some(Err(reason)),
                Some(RunStatus::Cancelled) => Some(Err(format!(
                    "cancelled{}",
                    if reason.is_empty() {
                        String::new()
                    } else {
                        format!(": {reason}")
                    }
                ))),
                _ => None,
            });
        }
        Ok(out)
    }

    /// Every succeeded run with the directory of the attempt its outputs came from and the
    /// stored outputs (value, std), by run id.
    pub fn succeeded_runs(&self) -> Result<Vec<SucceededRun>> {
        let mut stmt = self
            .connection
            .prepare(
                "SELECT r.id, a.id, a.directory FROM runs r
                 JOIN attempts a ON a.run_id = r.id AND a.outcome_kind = 'succeeded'
                 WHERE r.status = 'succeeded'
                 AND a.number = (SELECT MAX(b.number) FROM attempts b WHERE b.run_id = r.id AND b.outcome_kind = 'succeeded')
                 ORDER BY r.id",
            )
            .map_err(|e| self.err(e))?;
        let heads: Vec<(i64, i64, String)> = stmt
            .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))
            .and_then(|rows| rows.collect())
            .map_err(|e| self.err(e))?;
        let mut output_stmt = self
            .connection
            .prepare_cached("SELECT value, std FROM outputs WHERE run_id = ?1 ORDER BY position")
            .map_err(|e| self.err(e))?;
        heads
            .into_iter()
            .map(|(run_id, attempt_id, directory)| {
                let outputs: Vec<(f64, Option<f64>)> = output_stmt
                    .query_map([run_id], |r| Ok((r.get(0)?, r.get(1)?)))
                    .and_then(|rows| rows.collect())
                    .map_err(|e| self.err(e))?;
                Ok(SucceededRun {
                    run_id,
                    attempt_id,
                    directory: PathBuf::from(directory),
                    outputs,
                })
            })
            .collect()
    }

    /// Every run with its status, parameters and outputs, by run id.
    pub fn export_rows(&self) -> Result<Vec<ExportRow>> {
        let mut stmt = self
            .connection
            .prepare("SELECT id, status, parameters, attempts, outcome_kind, reason FROM runs ORDER BY id")
            .map_err(|e| self.err(e))?;
        let mut rows: Vec<ExportRow> = stmt
            .query_map([], |r| {
                Ok(ExportRow {
                    run_id: r.get(0)?,
                    status: r.get(1)?,
                    parameters: decode_parameters(&r.get::<_, String>(2)?, 2)?,
                    outputs: Vec::new(),
                    std: None,
                    attempts: r.get(3)?,
                    kind: r.get(4)?,
                    reason: r.get(5)?,
                })
            })
            .and_then(|rows| rows.collect::<std::result::Result<Vec<_>, _>>())
            .map_err(|e| self.err(e))?;
        let mut out_stmt = self
            .connection
            .prepare("SELECT run_id, value, std FROM outputs ORDER BY run_id, position")
            .map_err(|e| self.err(e))?;
        let outputs: Vec<(i64, f64, Option<f64>)> = out_stmt
            .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))
            .and_then(|rows| rows.collect())
            .map_err(|e| self.err(e))?;
        let mut by_run: std::collections::HashMap<i64, Vec<(f64, Option<f64>)>> =
            std::collections::HashMap::new();
        for (id, v, s) in outputs {
            by_run.entry(id).or_default().push((v, s));
        }
        for row in &mut rows {
            if let Some(values) = by_run.remove(&row.run_id) {
                row.outputs = values.iter().map(|v| v.0).collect();
                row.std = values.iter().map(|v| v.1).collect();
            }
        }
        Ok(rows)
    }
}
