//! The campaign store: one SQLite file holding the study text and hash, the designs, the runs
//! with their statuses, one attempt row per execution and the outputs.
//!
//! Only the coordinator writes it. Every change is one transaction, committed with
//! `synchronous = FULL` as soon as the results it records are ingested: a finished result is on
//! disk before the coordinator looks at the next one. On local disks the journal is a WAL
//! (readers such as `iuq status` never block the coordinator); on network file systems (NFS,
//! Lustre, GPFS, BeeGFS, CIFS, …), where WAL's shared memory does not work, the classic rollback
//! journal is used.
//!
//! Runs are keyed by the exact bits of their parameter vector, so identical vectors are run
//! once, whichever design asks for them.
//!
//! The SQLite connection is the store's own: every query of its tables is a method of
//! [`CampaignStore`] (the recorded designs' in [`recorded_designs`]), and nothing outside this
//! module reads or writes them except through those methods.

use std::path::{Path, PathBuf};

use rusqlite::{Connection, OptionalExtension, params};
use serde::Serialize;

use crate::error::{CampaignError, Result};
use crate::outcome::{OutcomeKind, RunResult, TaskReport, unix_now};
use crate::retry_policy::RetryPolicy;
use crate::study::CampaignStudy;

pub mod recorded_designs;

pub use recorded_designs::{CancelledDesign, DesignSummary};

/// Version of the schema below, kept in the `meta` table.
pub const SCHEMA_VERSION: i64 = 1;

const SCHEMA: &str = "
CREATE TABLE IF NOT EXISTS meta(key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS studies(
    id INTEGER PRIMARY KEY,
    name TEXT NOT NULL,
    hash TEXT NOT NULL UNIQUE,
    model_hash TEXT NOT NULL,
    text TEXT NOT NULL,
    created_at REAL NOT NULL);
CREATE TABLE IF NOT EXISTS designs(
    id INTEGER PRIMARY KEY,
    study_id INTEGER NOT NULL REFERENCES studies(id),
    label TEXT NOT NULL,
    size INTEGER NOT NULL,
    created_at REAL NOT NULL);
CREATE TABLE IF NOT EXISTS runs(
    id INTEGER PRIMARY KEY,
    parameter_key TEXT NOT NULL UNIQUE,
    parameters TEXT NOT NULL,
    status TEXT NOT NULL CHECK (status IN ('pending','queued','running','succeeded','failed','cancelled')),
    attempts INTEGER NOT NULL DEFAULT 0,
    outcome_kind TEXT,
    reason TEXT,
    created_at REAL NOT NULL,
    updated_at REAL NOT NULL);
CREATE INDEX IF NOT EXISTS runs_by_status ON runs(status);
CREATE TABLE IF NOT EXISTS design_points(
    design_id INTEGER NOT NULL REFERENCES designs(id),
    position INTEGER NOT NULL,
    run_id INTEGER NOT NULL REFERENCES runs(id),
    PRIMARY KEY (design_id, position));
CREATE TABLE IF NOT EXISTS attempts(
    id INTEGER PRIMARY KEY,
    run_id INTEGER NOT NULL REFERENCES runs(id),
    number INTEGER NOT NULL,
    executor TEXT NOT NULL,
    external_id TEXT,
    directory TEXT NOT NULL,
    host TEXT,
    submitted_at REAL NOT NULL,
    started_at REAL,
    finished_at REAL,
    exit_code INTEGER,
    signal INTEGER,
    outcome_kind TEXT,
    reason TEXT,
    stderr_tail TEXT,
    UNIQUE (run_id, number));
CREATE INDEX IF NOT EXISTS attempts_open ON attempts(run_id) WHERE outcome_kind IS NULL;
CREATE TABLE IF NOT EXISTS outputs(
    run_id INTEGER NOT NULL REFERENCES runs(id),
    attempt_id INTEGER NOT NULL REFERENCES attempts(id),
    position INTEGER NOT NULL,
    name TEXT NOT NULL,
    value REAL NOT NULL,
    std REAL,
    PRIMARY KEY (run_id, position));
CREATE TABLE IF NOT EXISTS derived_results(
    key TEXT NOT NULL,
    fingerprint TEXT NOT NULL,
    value TEXT NOT NULL,
    created_at REAL NOT NULL,
    PRIMARY KEY (key, fingerprint));
";

/// The status of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RunStatus {
    /// Waiting to be submitted.
    Pending,
    /// Submitted, not yet started.
    Queued,
    /// Started.
    Running,
    /// Finished with outputs.
    Succeeded,
    /// Finished without outputs, and not to be retried.
    Failed,
    /// Cancelled.
    Cancelled,
}

impl RunStatus {
    /// Every status, in life-cycle order.
    pub const ALL: [RunStatus; 6] = [
        Self::Pending,
        Self::Queued,
        Self::Running,
        Self::Succeeded,
        Self::Failed,
        Self::Cancelled,
    ];

    /// The name stored in the database.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Pending => "pending",
            Self::Queued => "queued",
            Self::Running => "running",
            Self::Succeeded => "succeeded",
            Self::Failed => "failed",
            Self::Cancelled => "cancelled",
        }
    }

    /// The status called `name`.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.as_str() == name)
    }

    /// True for succeeded, failed and cancelled.
    pub fn is_terminal(self) -> bool {
        matches!(self, Self::Succeeded | Self::Failed | Self::Cancelled)
    }
}

/// The journal mode chosen for the store's file system.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum JournalMode {
    /// Write-ahead log (local disks).
    Wal,
    /// Rollback journal (network file systems).
    Delete,
}

/// True when `path` lies on a network or cluster file system (by `statfs` magic number), where
/// SQLite's WAL mode is unsafe.
pub fn is_network_file_system(path: &Path) -> bool {
    use std::os::unix::ffi::OsStrExt;
    let Ok(c) = std::ffi::CString::new(path.as_os_str().as_bytes()) else {
        return false;
    };
    // SAFETY: statfs writes into the zeroed struct we own; the path is NUL-terminated.
    let magic = unsafe {
        let mut s: libc::statfs = std::mem::zeroed();
        if libc::statfs(c.as_ptr(), &mut s) != 0 {
            return false;
        }
        s.f_type as u64 & 0xffff_ffff
    };
    const NETWORK: [u64; 13] = [
        0x6969,      // NFS
        0x517B,      // SMB
        0xFF53_4D42, // CIFS
        0xFE53_4D42, // SMB2
        0x0BD0_0BD0, // Lustre
        0x4750_4653, // GPFS
        0x1983_0326, // BeeGFS
        0x00C3_6400, // Ceph
        0x0102_1997, // 9p
        0x5346_414F, // AFS
        0xAAD7_AAEA, // PanFS
        0x6573_5546, // FUSE (sshfs, …)
        0x0102_1994, // tmpfs is local; listed here only as a guard below
    ];
    magic != 0x0102_1994 && NETWORK.contains(&magic)
}

/// The key identifying a parameter vector exactly: the bits of each value (with -0 as 0).
pub fn parameter_key(point: &[f64]) -> String {
    point
        .iter()
        .map(|v| format!("{:016x}", if *v == 0.0 { 0u64 } else { v.to_bits() }))
        .collect::<Vec<_>>()
        .join(",")
}

/// Counts of runs per status.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct StatusCounts {
    /// Waiting to be submitted.
    pub pending: u64,
    /// Submitted, not started.
    pub queued: u64,
    /// Running.
    pub running: u64,
    /// Succeeded.
    pub succeeded: u64,
    /// Failed.
    pub failed: u64,
    /// Cancelled.
    pub cancelled: u64,
}

impl StatusCounts {
    /// All runs.
    pub fn total(&self) -> u64 {
        self.pending + self.queued + self.running + self.succeeded + self.failed + self.cancelled
    }

    /// Runs that reached a final status.
    pub fn finished(&self) -> u64 {
        self.succeeded + self.failed + self.cancelled
    }

    /// Count `n` more runs of the stored status `status` (an unknown name counts nowhere).
    pub(crate) fn add(&mut self, status: &str, n: u64) {
        match RunStatus::from_name(status) {
            Some(RunStatus::Pending) => self.pending += n,
            Some(RunStatus::Queued) => self.queued += n,
            Some(RunStatus::Running) => self.running += n,
            Some(RunStatus::Succeeded) => self.succeeded += n,
            Some(RunStatus::Failed) => self.failed += n,
            Some(RunStatus::Cancelled) => self.cancelled += n,
            None => {}
        }
    }
}

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

/// The campaign store.
pub struct CampaignStore {
    path: PathBuf,
    connection: Connection,
    journal: JournalMode,
    study_id: i64,
}

impl std::fmt::Debug for CampaignStore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CampaignStore")
            .field("path", &self.path)
            .field("journal", &self.journal)
            .finish()
    }
}

/// A run's parameters as the store holds them (a JSON array; `null` reads as NaN). Text that is
/// no such array is a corrupt store, an error of the row (column `column` of the query), never an
/// empty parameter vector that a model would then be run with.
fn decode_parameters(text: &str, column: usize) -> rusqlite::Result<Vec<f64>> {
    serde_json::from_str::<Vec<Option<f64>>>(text)
        .map(|v| v.into_iter().map(|x| x.unwrap_or(f64::NAN)).collect())
        .map_err(|e| {
            rusqlite::Error::FromSqlConversionFailure(
                column,
                rusqlite::types::Type::Text,
                format!("run parameters `{text}` are not a JSON array of numbers: {e}").into(),
            )
        })
}

fn encode_parameters(point: &[f64]) -> String {
    // Shortest round-trip form; parameters are finite (checked when designs are added).
    serde_json::to_string(point).unwrap_or_else(|_| "[]".into())
}

impl CampaignStore {
    fn err(&self, source: rusqlite::Error) -> CampaignError {
        CampaignError::Store {
            path: self.path.clone(),
            source,
        }
    }

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

    /// The database file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The journal mode in use.
    pub fn journal_mode(&self) -> JournalMode {
        self.journal
    }

    /// Open (creating if needed) the store of `study` at `path`, record the study text, and check
    /// that the study's model is the one the store's runs were made with.
    pub fn open(path: &Path, study: &CampaignStudy) -> Result<Self> {
        let mut store = Self::open_file(path, true)?;
        let model_hash = study.model_hash();
        let existing: Option<(String, String)> = store
            .connection
            .query_row(
                "SELECT model_hash, name FROM studies ORDER BY id LIMIT 1",
                [],
                |r| Ok((r.get(0)?, r.get(1)?)),
            )
            .optional()
            .map_err(|e| store.err(e))?;
        if let Some((hash, name)) = existing {
            if hash != model_hash && hash == study.legacy_model_hash() {
                store
                    .connection
                    .execute(
                        "UPDATE studies SET model_hash = ?1 WHERE model_hash = ?2",
                        params![model_hash, hash],
                    )
                    .map_err(|e| store.err(e))?;
            } else if hash != model_hash {
                return Err(CampaignError::study(
                    study.path.display().to_string(),
                    "model",
                    format!(
                        "the parameters or [model] differ from those of the campaign `{name}` stored in {}; results would not be comparable — use another `executor.directory` or remove the old campaign",
                        path.display()
                    ),
                ));
            }
        }
        let now = unix_now();
        store
            .connection
            .execute(
                "INSERT OR IGNORE INTO studies(name, hash, model_hash, text, created_at) VALUES (?1, ?2, ?3, ?4, ?5)",
                params![study.name, study.hash, model_hash, study.text, now],
            )
            .map_err(|e| store.err(e))?;
        store.study_id = store
            .connection
            .query_row(
                "SELECT id FROM studies WHERE hash = ?1",
                [&study.hash],
                |r| r.get(0),
            )
            .map_err(|e| store.err(e))?;
        Ok(store)
    }

    /// Open an existing store for reading and maintenance, without a study.
    pub fn open_existing(path: &Path) -> Result<Self> {
        if !path.exists() {
            return Err(CampaignError::BadInput(format!(
                "{}: no campaign store (has `iuq run` been started for this study?)",
                path.display()
            )));
        }
        Self::open_file(path, false)
    }

    fn open_file(path: &Path, create: bool) -> Result<Self> {
        if let Some(dir) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            if create {
                std::fs::create_dir_all(dir).map_err(|e| CampaignError::io(dir, e))?;
            }
        }
        let connection = Connection::open(path).map_err(|e| CampaignError::Store {
            path: path.to_path_buf(),
            source: e,
        })?;
        let dir = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let journal = if is_network_file_system(dir) {
            JournalMode::Delete
        } else {
            JournalMode::Wal
        };
        let mut store = Self {
            path: path.to_path_buf(),
            connection,
            journal,
            study_id: 0,
        };
        let mode = match journal {
            JournalMode::Wal => "WAL",
            JournalMode::Delete => "DELETE",
        };
        store
            .connection
            .busy_timeout(std::time::Duration::from_secs(30))
            .map_err(|e| store.err(e))?;
        let _: String = store
            .connection
            .query_row(&format!("PRAGMA journal_mode = {mode}"), [], |r| r.get(0))
            .map_err(|e| store.err(e))?;
        store
            .connection
            .execute_batch("PRAGMA synchronous = FULL; PRAGMA foreign_keys = ON;")
            .map_err(|e| store.err(e))?;
        if !create {
            // An existing store is only read (`iuq status`, `iuq export`): no schema writes.
            store.study_id = store
                .connection
                .query_row("SELECT COALESCE(MAX(id), 0) FROM studies", [], |r| r.get(0))
                .map_err(|e| store.err(e))?;
            return Ok(store);
        }
        let tx = store
            .connection
            .transaction()
            .map_err(|e| CampaignError::Store {
                path: path.to_path_buf(),
                source: e,
            })?;
        tx.execute_batch(SCHEMA)
            .and_then(|_| {
                tx.execute(
                    "INSERT OR IGNORE INTO meta(key, value) VALUES ('schema_version', ?1)",
                    [SCHEMA_VERSION.to_string()],
                )
            })
            .and_then(|_| tx.commit())
            .map_err(|e| CampaignError::Store {
                path: path.to_path_buf(),
                source: e,
            })?;
        Ok(store)
    }

    /// Record a design (a batch of points) and the runs it needs; identical vectors share one
    /// run. Returns the run id of each point, in order. A design already recorded under the same
    /// label with the same runs is not recorded again, so rerunning a study leaves its store as
    /// it was.
    pub fn add_design(&mut self, label: &str, points: &[Vec<f64>]) -> Result<Vec<i64>> {
        if let Some((i, _)) = points
            .iter()
            .enumerate()
            .find(|(_, p)| p.iter().any(|v| !v.is_finite()))
        {
            return Err(CampaignError::BadInput(format!(
                "design `{label}`: point {i} has a non-finite coordinate"
            )));
        }
        let now = unix_now();
        let study_id = self.study_id;
        let path = self.path.clone();
        let err = |e| CampaignError::Store {
            path: path.clone(),
            source: e,
        };
        if let Some(ids) = self.recorded_design(label, points).map_err(err)? {
            revive_cancelled(&self.connection, &ids).map_err(err)?;
            return Ok(ids);
        }
        let tx = self.connection.transaction().map_err(err)?;
        let mut ids = Vec::with_capacity(points.len());
        {
            tx.execute(
                "INSERT INTO designs(study_id, label, size, created_at) VALUES (?1, ?2, ?3, ?4)",
                params![study_id, label, points.len() as i64, now],
            )
            .map_err(err)?;
            let design_id = tx.last_insert_rowid();
            let mut insert = tx
                .prepare_cached(
                    "INSERT OR IGNORE INTO runs(parameter_key, parameters, status, created_at, updated_at) VALUES (?1, ?2, 'pending', ?3, ?3)",
                )
                .map_err(err)?;
            let mut find = tx
                .prepare_cached("SELECT id FROM runs WHERE parameter_key = ?1")
                .map_err(err)?;
            let mut link = tx
                .prepare_cached(
                    "INSERT INTO design_points(design_id, position, run_id) VALUES (?1, ?2, ?3)",
                )
                .map_err(err)?;
            for (position, point) in points.iter().enumerate() {
                let key = parameter_key(point);
                insert
                    .execute(params![key, encode_parameters(point), now])
                    .map_err(err)?;
                let id: i64 = find.query_row([&key], |r| r.get(0)).map_err(err)?;
                link.execute(params![design_id, position as i64, id])
                    .map_err(err)?;
                ids.push(id);
            }
        }
        revive_cancelled(&tx, &ids).map_err(err)?;
        tx.commit().map_err(err)?;
        Ok(ids)
    }

    /// The points of the latest design of this study recorded under `label`, in order, if there
    /// is one: what an earlier coordinator chose, read back bit for bit (so that a rerun can
    /// replay its choices even where recomputing them would differ in the last bits).
    pub fn design_points(&self, label: &str) -> Result<Option<Vec<Vec<f64>>>> {
        let design: Option<i64> = self
            .connection
            .query_row(
                "SELECT max(id) FROM designs WHERE study_id = ?1 AND label = ?2",
                params![self.study_id, label],
                |r| r.get(0),
            )
            .map_err(|e| self.err(e))?;
        let Some(design) = design else {
            return Ok(None);
        };
        let mut points = self
            .connection
            .prepare_cached(
                "SELECT r.parameters FROM design_points dp JOIN runs r ON r.id = dp.run_id WHERE dp.design_id = ?1 ORDER BY dp.position",
            )
            .map_err(|e| self.err(e))?;
        let rows = points
            .query_map([design], |r| r.get::<_, String>(0))
            .map_err(|e| self.err(e))?
            .map(|t| t.and_then(|text| decode_parameters(&text, 0)))
            .collect::<rusqlite::Result<Vec<_>>>()
            .map_err(|e| self.err(e))?;
        Ok(Some(rows))
    }

    /// The run ids of a design of this study recorded under `label` with exactly the runs of
    /// `points`, if there is one.
    fn recorded_design(
        &self,
        label: &str,
        points: &[Vec<f64>],
    ) -> rusqlite::Result<Option<Vec<i64>>> {
        let mut find = self
            .connection
            .prepare_cached("SELECT id FROM runs WHERE parameter_key = ?1")?;
        let mut ids = Vec::with_capacity(points.len());
        for point in points {
            match find
                .query_row([parameter_key(point)], |r| r.get::<_, i64>(0))
                .optional()?
            {
                Some(id) => ids.push(id),
                None => return Ok(None),
            }
        }
        let mut designs = self.connection.prepare_cached(
            "SELECT id FROM designs WHERE study_id = ?1 AND label = ?2 AND size = ?3 ORDER BY id",
        )?;
        let candidates: Vec<i64> = designs
            .query_map(params![self.study_id, label, points.len() as i64], |r| {
                r.get(0)
            })?
            .collect::<rusqlite::Result<_>>()?;
        let mut members = self.connection.prepare_cached(
            "SELECT run_id FROM design_points WHERE design_id = ?1 ORDER BY position",
        )?;
        for design in candidates {
            let runs: Vec<i64> = members
                .query_map([design], |r| r.get(0))?
                .collect::<rusqlite::Result<_>>()?;
            if runs == ids {
                return Ok(Some(ids));
            }
        }
        Ok(None)
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

    /// Put runs that are queued or running without an open attempt back to pending (a
    /// coordinator died between the two writes); returns how many.
    pub fn requeue_orphans(&mut self) -> Result<usize> {
        self.connection
            .execute(
                "UPDATE runs SET status = 'pending', updated_at = ?1 WHERE status IN ('queued', 'running')
                 AND NOT EXISTS (SELECT 1 FROM attempts a WHERE a.run_id = runs.id AND a.outcome_kind IS NULL)",
                [unix_now()],
            )
            .map_err(|e| self.err(e))
    }

    /// Put failed runs back to pending for `iuq retry`: those whose last attempt was lost
    /// (`lost`), and/or every other failed run (`failed`). Attempt limits start afresh. Returns
    /// how many runs were reset.
    pub fn reset_for_retry(&mut self, failed: bool, lost: bool) -> Result<usize> {
        let condition = match (failed, lost) {
            (true, true) => "status = 'failed'",
            (true, false) => "status = 'failed' AND COALESCE(outcome_kind, '') != 'lost'",
            (false, true) => "status = 'failed' AND outcome_kind = 'lost'",
            (false, false) => return Ok(0),
        };
        self.connection
            .execute(
                &format!("UPDATE runs SET status = 'pending', attempts = 0, updated_at = ?1 WHERE {condition}"),
                [unix_now()],
            )
            .map_err(|e| self.err(e))
    }

    /// Put the failed runs whose model never started back to pending with no attempts: every
    /// attempt could not start its command (`spawn_failed`) or was lost (e.g. held back by a
    /// stop before it started), at least one could not start. The failure is no result of the
    /// model (see [`crate::start_watch`]). Returns how many.
    pub fn restart_unstarted(&mut self) -> Result<usize> {
        self.connection
            .execute(
                "UPDATE runs SET status = 'pending', attempts = 0, updated_at = ?1 \
                 WHERE status = 'failed' \
                 AND EXISTS (SELECT 1 FROM attempts a WHERE a.run_id = runs.id \
                             AND a.outcome_kind = 'spawn_failed') \
                 AND NOT EXISTS (SELECT 1 FROM attempts a WHERE a.run_id = runs.id \
                                 AND a.outcome_kind NOT IN ('spawn_failed', 'lost'))",
                [unix_now()],
            )
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

    /// A result computed from the store's runs and recorded under `key` by
    /// [`CampaignStore::record_derived_result`], if one was recorded with exactly this
    /// `fingerprint` (a digest of everything the result was computed from): an expensive
    /// computation on the runs — an adaptive round's assessment — is then read back instead of
    /// repeated when a study is replayed.
    pub fn derived_result(&self, key: &str, fingerprint: &str) -> Result<Option<String>> {
        self.connection
            .query_row(
                "SELECT value FROM derived_results WHERE key = ?1 AND fingerprint = ?2",
                params![key, fingerprint],
                |r| r.get(0),
            )
            .optional()
            .map_err(|e| self.err(e))
    }

    /// Record `value`, computed from the runs, under `key` and the `fingerprint` of what it was
    /// computed from (replacing a value recorded with the same key and fingerprint).
    pub fn record_derived_result(
        &mut self,
        key: &str,
        fingerprint: &str,
        value: &str,
    ) -> Result<()> {
        let now = unix_now();
        self.connection
            .execute(
                "INSERT OR REPLACE INTO derived_results(key, fingerprint, value, created_at) VALUES (?1, ?2, ?3, ?4)",
                params![key, fingerprint, value, now],
            )
            .map(|_| ())
            .map_err(|e| self.err(e))
    }

    /// `PRAGMA integrity_check`: `ok` for a sound database.
    pub fn integrity_check(&self) -> Result<String> {
        self.connection
            .query_row("PRAGMA integrity_check", [], |r| r.get(0))
            .map_err(|e| self.err(e))
    }
}

/// Writes within one transaction of [`CampaignStore::write`].
pub struct StoreWriter<'a> {
    tx: &'a rusqlite::Transaction<'a>,
    path: &'a Path,
}

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

/// Make the cancelled runs among `run_ids` pending again: a design asked for them. Writes
/// nothing when the store has no cancelled run (a replay of a finished study stays a read).
pub(crate) fn revive_cancelled(connection: &Connection, run_ids: &[i64]) -> rusqlite::Result<()> {
    let any: i64 = connection.query_row(
        "SELECT COUNT(*) FROM runs WHERE status = 'cancelled'",
        [],
        |r| r.get(0),
    )?;
    if any == 0 {
        return Ok(());
    }
    let mut revive = connection.prepare_cached(
        "UPDATE runs SET status = 'pending', outcome_kind = NULL, reason = NULL, updated_at = ?1 \
         WHERE id = ?2 AND status = 'cancelled'",
    )?;
    let now = unix_now();
    for id in run_ids {
        revive.execute(params![now, id])?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const STUDY: &str = r#"
name = "s"
[parameters]
x = { uniform = [-1, 1] }
[model]
kind = "command"
command = ["true"]
outputs = ["f"]
output = { file = "r.json", format = "json" }
"#;

    fn fresh(name: &str) -> (PathBuf, CampaignStudy) {
        let dir = std::env::temp_dir().join(format!("iuq-store-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let study = CampaignStudy::parse(STUDY, &dir.join("study.toml")).unwrap();
        (dir, study)
    }

    #[test]
    fn a_derived_result_is_read_back_only_under_its_key_and_fingerprint_and_survives_reopening() {
        let (dir, study) = fresh("derived");
        let path = dir.join("c.sqlite");
        let mut store = CampaignStore::open(&path, &study).unwrap();
        assert_eq!(store.derived_result("round-1", "abc").unwrap(), None);
        store
            .record_derived_result("round-1", "abc", "{\"u\":1}")
            .unwrap();
        store
            .record_derived_result("round-1", "def", "{\"u\":2}")
            .unwrap();
        assert_eq!(
            store.derived_result("round-1", "abc").unwrap().as_deref(),
            Some("{\"u\":1}")
        );
        assert_eq!(store.derived_result("round-2", "abc").unwrap(), None);
        // The same key and fingerprint again replaces the value.
        store
            .record_derived_result("round-1", "abc", "{\"u\":3}")
            .unwrap();
        drop(store);
        let store = CampaignStore::open(&path, &study).unwrap();
        assert_eq!(
            store.derived_result("round-1", "abc").unwrap().as_deref(),
            Some("{\"u\":3}")
        );
        assert_eq!(
            store.derived_result("round-1", "def").unwrap().as_deref(),
            Some("{\"u\":2}")
        );
    }

    #[test]
    fn a_store_moved_with_its_study_and_its_program_keeps_its_runs() {
        let (dir, _) = fresh("moved");
        let text = STUDY.replace(r#"["true"]"#, r#"["./sim.sh", "{{x}}"]"#);
        let here = dir.join("here");
        let there = dir.join("elsewhere/deeper");
        let study = CampaignStudy::parse(&text, &here.join("study.toml")).unwrap();
        let moved = CampaignStudy::parse(&text, &there.join("study.toml")).unwrap();
        assert_ne!(study.legacy_model_hash(), moved.legacy_model_hash());
        assert_eq!(study.model_hash(), moved.model_hash());
        let path = dir.join("c.sqlite");
        drop(CampaignStore::open(&path, &study).unwrap());
        assert!(CampaignStore::open(&path, &moved).is_ok());
        // Another program is another model.
        let other = CampaignStudy::parse(
            &text.replace("./sim.sh", "./other.sh"),
            &there.join("study.toml"),
        )
        .unwrap();
        assert!(CampaignStore::open(&path, &other).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_store_hashed_with_the_program_s_absolute_path_is_rewritten_once_opened_where_it_was_made()
    {
        let (dir, _) = fresh("legacy");
        let text = STUDY.replace(r#"["true"]"#, r#"["./sim.sh"]"#);
        let here = dir.join("here");
        let study = CampaignStudy::parse(&text, &here.join("study.toml")).unwrap();
        let path = dir.join("c.sqlite");
        let store = CampaignStore::open(&path, &study).unwrap();
        store
            .connection
            .execute(
                "UPDATE studies SET model_hash = ?1",
                params![study.legacy_model_hash()],
            )
            .unwrap();
        drop(store);
        let elsewhere = CampaignStudy::parse(&text, &dir.join("b/study.toml")).unwrap();
        assert!(
            CampaignStore::open(&path, &elsewhere).is_err(),
            "an old hash holds the folder it was made in"
        );
        let store = CampaignStore::open(&path, &study).unwrap();
        let stored: String = store
            .connection
            .query_row("SELECT model_hash FROM studies", [], |r| r.get(0))
            .unwrap();
        assert_eq!(stored, study.model_hash());
        drop(store);
        assert!(CampaignStore::open(&path, &elsewhere).is_ok());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn identical_vectors_share_a_run_and_local_disks_use_wal() {
        let (dir, study) = fresh("dedup");
        let mut store = CampaignStore::open(&dir.join("c.sqlite"), &study).unwrap();
        assert_eq!(store.journal_mode(), JournalMode::Wal);
        let ids = store
            .add_design("a", &[vec![0.5], vec![0.0], vec![0.5], vec![-0.0]])
            .unwrap();
        assert_eq!(ids, vec![1, 2, 1, 2]);
        let ids = store.add_design("b", &[vec![0.25], vec![0.5]]).unwrap();
        assert_eq!(ids, vec![3, 1]);
        assert_eq!(store.counts(None).unwrap().pending, 3);
        assert!(store.add_design("c", &[vec![f64::NAN]]).is_err());
        // The same design again (a rerun of the study) adds nothing; another label or order does.
        let designs = |store: &CampaignStore| -> i64 {
            store
                .connection
                .query_row("SELECT COUNT(*) FROM designs", [], |r| r.get(0))
                .unwrap()
        };
        assert_eq!(designs(&store), 2);
        let again = store.add_design("b", &[vec![0.25], vec![0.5]]).unwrap();
        assert_eq!(again, vec![3, 1]);
        assert_eq!(designs(&store), 2);
        store.add_design("b", &[vec![0.5], vec![0.25]]).unwrap();
        store.add_design("d", &[vec![0.25], vec![0.5]]).unwrap();
        assert_eq!(designs(&store), 4);
        // A design's points read back in order, bit for bit; the latest of a label wins.
        assert_eq!(
            store.design_points("b").unwrap(),
            Some(vec![vec![0.5], vec![0.25]])
        );
        let a = store.design_points("a").unwrap().unwrap();
        assert_eq!(a.len(), 4);
        assert_eq!(
            a[3][0].to_bits(),
            0.0f64.to_bits(),
            "-0.0 and 0.0 are one run"
        );
        assert_eq!(store.design_points("nope").unwrap(), None);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn attempts_close_once_and_follow_the_retry_policy() {
        let (dir, study) = fresh("attempts");
        let mut store = CampaignStore::open(&dir.join("c.sqlite"), &study).unwrap();
        store.add_design("a", &[vec![0.1], vec![0.2]]).unwrap();
        let policy = RetryPolicy::default();
        let names = vec!["f".to_string()];
        let (a1, n1) = store
            .write(|w| w.begin_attempt(1, "local", Path::new("/tmp/r1")))
            .unwrap();
        assert_eq!(n1, 1);
        let lost = RunResult::failure(1, 1, OutcomeKind::Lost, "gone");
        let d = store
            .write(|w| w.finish_attempt(a1, &lost, None, &names, &policy))
            .unwrap();
        assert_eq!(d, Disposition::Retry);
        // A late duplicate report of the same attempt changes nothing.
        let d = store
            .write(|w| w.finish_attempt(a1, &lost, None, &names, &policy))
            .unwrap();
        assert_eq!(d, Disposition::Ignored);
        assert_eq!(store.pending_runs(10).unwrap().len(), 2);
        let (a2, n2) = store
            .write(|w| w.begin_attempt(1, "local", Path::new("/tmp/r1")))
            .unwrap();
        assert_eq!(n2, 2);
        let ok = RunResult {
            run_id: 1,
            attempt: 2,
            kind: OutcomeKind::Succeeded,
            reason: None,
            outputs: vec![4.0],
            std: Some(vec![0.5]),
        };
        let d = store
            .write(|w| w.finish_attempt(a2, &ok, None, &names, &policy))
            .unwrap();
        assert_eq!(d, Disposition::Succeeded);
        let (a3, _) = store
            .write(|w| w.begin_attempt(2, "local", Path::new("/tmp/r2")))
            .unwrap();
        let bad = RunResult::failure(2, 1, OutcomeKind::ExitStatus, "exited with status 1");
        let d = store
            .write(|w| w.finish_attempt(a3, &bad, None, &names, &policy))
            .unwrap();
        assert_eq!(d, Disposition::Failed);
        let outcomes = store.outcomes(&[1, 2]).unwrap();
        assert_eq!(outcomes[0], Some(Ok((vec![4.0], Some(vec![0.5])))));
        assert_eq!(outcomes[1], Some(Err("exited with status 1".into())));
        assert_eq!(store.failures().unwrap()[0].kind, "exit_status");
        assert_eq!(store.reset_for_retry(false, true).unwrap(), 0);
        assert_eq!(store.reset_for_retry(true, false).unwrap(), 1);
        assert_eq!(store.integrity_check().unwrap(), "ok");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_file_that_is_not_a_store_is_bad_input_and_left_as_it_was() {
        let (dir, study) = fresh("not-a-store");
        let path = dir.join("c.sqlite");
        let garbage =
            "not a database, just text that happens to sit where the store should be\n".repeat(20);
        std::fs::write(&path, &garbage).unwrap();
        for e in [
            CampaignStore::open(&path, &study).map(drop).unwrap_err(),
            CampaignStore::open_existing(&path).map(drop).unwrap_err(),
        ] {
            let message = e.to_string();
            assert!(e.is_bad_input(), "{message}");
            assert!(
                message.contains("c.sqlite") && message.contains("not an SQLite database"),
                "{message}"
            );
        }
        assert_eq!(std::fs::read_to_string(&path).unwrap(), garbage);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_store_refuses_a_study_with_another_model() {
        let (dir, study) = fresh("model");
        drop(CampaignStore::open(&dir.join("c.sqlite"), &study).unwrap());
        let other =
            CampaignStudy::parse(&STUDY.replace("[\"true\"]", "[\"false\"]"), &study.path).unwrap();
        let e = CampaignStore::open(&dir.join("c.sqlite"), &other).unwrap_err();
        assert!(
            e.is_bad_input() && e.to_string().contains("key `model`"),
            "{e}"
        );
        // Another text with the same model (a comment, a new design) is fine.
        let same = CampaignStudy::parse(&format!("# note\n{STUDY}"), &study.path).unwrap();
        assert!(CampaignStore::open(&dir.join("c.sqlite"), &same).is_ok());
        assert_eq!(parameter_key(&[1.0, -0.0]), parameter_key(&[1.0, 0.0]));
        assert!(!is_network_file_system(&dir));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
