//! Writes of a coordinator, one transaction each ([`CampaignStore::write`]): attempts begun,
//! started and finished, outputs stored, the run's status set by the retry policy.

use std::path::Path;

use rusqlite::{OptionalExtension, params};

use super::CampaignStore;
use crate::error::{CampaignError, Result};
use crate::outcome::{OutcomeKind, RunResult, TaskReport, unix_now};
use crate::retry_policy::RetryPolicy;

impl CampaignStore {
    /// Apply one group of changes in one transaction, committed before returning.
    pub fn write<T>(&mut self, f: impl FnOnce(&StoreWriter<'_>) -> Result<T>) -> Result<T> {
        let path = self.path.clone();
        let tx = self
            .connection
            .transaction()
            .map_err(|e| CampaignError::Store {
                path: path.clone(),
                source: e,
            })?;
        let value = f(&StoreWriter {
            tx: &tx,
            path: &path,
        })?;
        tx.commit()
            .map_err(|e| CampaignError::Store { path, source: e })?;
        Ok(value)
    }
}

/// Writes within one transaction of [`CampaignStore::write`].
pub struct StoreWriter<'a> {
    tx: &'a rusqlite::Transaction<'a>,
    path: &'a Path,
}

/// What the store did with a finished attempt.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Disposition {
    /// The run succeeded.
    Succeeded,
    /// The run failed for good.
    Failed,
    /// The run is pending again (retry policy).
    Retry,
    /// The attempt was already closed (a late or duplicate report): nothing changed.
    Ignored,
}

impl StoreWriter<'_> {
    fn err(&self, source: rusqlite::Error) -> CampaignError {
        CampaignError::Store {
            path: self.path.to_path_buf(),
            source,
        }
    }

    /// Replace the stored outputs of `run_id` (decoded again from `attempt_id`'s directory).
    pub fn replace_outputs(
        &self,
        run_id: i64,
        attempt_id: i64,
        output_names: &[String],
        values: &[f64],
        std: Option<&[f64]>,
    ) -> Result<()> {
        let mut insert = self
            .tx
            .prepare_cached("INSERT OR REPLACE INTO outputs(run_id, attempt_id, position, name, value, std) VALUES (?1, ?2, ?3, ?4, ?5, ?6)")
            .map_err(|e| self.err(e))?;
        for (k, (name, value)) in output_names.iter().zip(values).enumerate() {
            let s = std.and_then(|s| s.get(k).copied());
            insert
                .execute(params![run_id, attempt_id, k as i64, name, value, s])
                .map_err(|e| self.err(e))?;
        }
        Ok(())
    }

    /// Record a new attempt at `run_id` (its number is the run's attempt count + 1) and mark the
    /// run queued. Returns `(attempt id, attempt number)`.
    pub fn begin_attempt(
        &self,
        run_id: i64,
        executor: &str,
        directory: &Path,
    ) -> Result<(i64, u32)> {
        let now = unix_now();
        self.tx
            .prepare_cached(
                "UPDATE runs SET status = 'queued', attempts = attempts + 1, updated_at = ?2 WHERE id = ?1",
            )
            .and_then(|mut s| s.execute(params![run_id, now]))
            .map_err(|e| self.err(e))?;
        // A reset run (`iuq retry`) starts counting again but keeps its old attempt rows.
        let previous: u32 = self
            .tx
            .prepare_cached("SELECT COALESCE(MAX(number), 0) FROM attempts WHERE run_id = ?1")
            .and_then(|mut s| s.query_row([run_id], |r| r.get(0)))
            .map_err(|e| self.err(e))?;
        let row_number = previous + 1;
        self.tx
            .prepare_cached("INSERT INTO attempts(run_id, number, executor, directory, submitted_at) VALUES (?1, ?2, ?3, ?4, ?5)")
            .and_then(|mut s| s.execute(params![run_id, row_number, executor, directory.display().to_string(), now]))
            .map_err(|e| self.err(e))?;
        Ok((self.tx.last_insert_rowid(), row_number))
    }

    /// Record the scheduler's id of an attempt.
    pub fn set_external_id(&self, attempt_id: i64, external_id: &str) -> Result<()> {
        self.tx
            .prepare_cached("UPDATE attempts SET external_id = ?2 WHERE id = ?1")
            .and_then(|mut s| s.execute(params![attempt_id, external_id]))
            .map_err(|e| self.err(e))?;
        Ok(())
    }

    /// Record that an attempt started (on `host`, as `external_id`) and mark its run running.
    pub fn mark_started(
        &self,
        attempt_id: i64,
        external_id: Option<&str>,
        host: Option<&str>,
        started_at: f64,
    ) -> Result<()> {
        let run_id: Option<i64> = self
            .tx
            .prepare_cached(
                "UPDATE attempts SET started_at = COALESCE(started_at, ?2), host = COALESCE(?3, host), external_id = COALESCE(?4, external_id)
                 WHERE id = ?1 AND outcome_kind IS NULL RETURNING run_id",
            )
            .and_then(|mut s| s.query_row(params![attempt_id, started_at, host, external_id], |r| r.get(0)).optional())
            .map_err(|e| self.err(e))?;
        if let Some(run_id) = run_id {
            self.tx
                .prepare_cached("UPDATE runs SET status = 'running', updated_at = ?2 WHERE id = ?1 AND status = 'queued'")
                .and_then(|mut s| s.execute(params![run_id, unix_now()]))
                .map_err(|e| self.err(e))?;
        }
        Ok(())
    }

    /// Close an attempt with its result (and the task report it came in, when there is one),
    /// store outputs on success, and set the run's status by `policy`.
    pub fn finish_attempt(
        &self,
        attempt_id: i64,
        result: &RunResult,
        report: Option<&TaskReport>,
        output_names: &[String],
        policy: &RetryPolicy,
    ) -> Result<Disposition> {
        let open: Option<(i64, u32)> = self
            .tx
            .prepare_cached("SELECT r.id, r.attempts FROM attempts a JOIN runs r ON r.id = a.run_id WHERE a.id = ?1 AND a.outcome_kind IS NULL")
            .and_then(|mut s| s.query_row([attempt_id], |r| Ok((r.get(0)?, r.get(1)?))).optional())
            .map_err(|e| self.err(e))?;
        let Some((run_id, attempts)) = open else {
            return Ok(Disposition::Ignored);
        };
        let mut kind = result.kind;
        let mut reason = result.reason.clone();
        if kind == OutcomeKind::Succeeded && result.outputs.len() != output_names.len() {
            kind = OutcomeKind::BadOutput;
            reason = Some(format!(
                "{} outputs for {} output names",
                result.outputs.len(),
                output_names.len()
            ));
        }
        self.tx
            .prepare_cached(
                "UPDATE attempts SET host = COALESCE(?2, host), started_at = COALESCE(?3, started_at), finished_at = ?4,
                 exit_code = ?5, signal = ?6, outcome_kind = ?7, reason = ?8, stderr_tail = ?9,
                 external_id = COALESCE(external_id, ?10) WHERE id = ?1",
            )
            .and_then(|mut s| {
                s.execute(params![
                    attempt_id,
                    report.map(|r| r.host.as_str()),
                    report.map(|r| r.started_at),
                    report.map_or_else(unix_now, |r| r.finished_at),
                    report.and_then(|r| r.exit_code),
                    report.and_then(|r| r.signal),
                    kind.as_str(),
                    reason,
                    report.map(|r| r.stderr_tail.as_str()).filter(|t| !t.is_empty()),
                    report.and_then(|r| r.pid).map(|p| format!("pid:{p}")),
                ])
            })
            .map_err(|e| self.err(e))?;
        let now = unix_now();
        let disposition = if kind == OutcomeKind::Succeeded {
            let mut insert = self
                .tx
                .prepare_cached("INSERT OR REPLACE INTO outputs(run_id, attempt_id, position, name, value, std) VALUES (?1, ?2, ?3, ?4, ?5, ?6)")
                .map_err(|e| self.err(e))?;
            for (k, (name, value)) in output_names.iter().zip(&result.outputs).enumerate() {
                let std = result.std.as_ref().and_then(|s| s.get(k).copied());
                insert
                    .execute(params![run_id, attempt_id, k as i64, name, value, std])
                    .map_err(|e| self.err(e))?;
            }
            Disposition::Succeeded
        } else if policy.should_retry(kind, attempts) {
            Disposition::Retry
        } else {
            Disposition::Failed
        };
        let status = match disposition {
            Disposition::Succeeded => "succeeded",
            Disposition::Retry => "pending",
            _ => "failed",
        };
        self.tx
            .prepare_cached("UPDATE runs SET status = ?2, outcome_kind = ?3, reason = ?4, updated_at = ?5 WHERE id = ?1")
            .and_then(|mut s| s.execute(params![run_id, status, kind.as_str(), reason, now]))
            .map_err(|e| self.err(e))?;
        Ok(disposition)
    }
}
