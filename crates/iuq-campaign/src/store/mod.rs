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
//! [`CampaignStore`], and nothing outside this module reads or writes them except through those
//! methods. The methods live with what they do:
//!
//! | file | what |
//! |---|---|
//! | `mod.rs` | the store and its connection: opening (journal mode, pragmas, tables), integrity |
//! | `schema.rs` | the tables and the schema version |
//! | `journal.rs` | the journal mode a file system allows ([`JournalMode`]) |
//! | `status.rs` | run statuses ([`RunStatus`]) and counts per status ([`StatusCounts`]) |
//! | `parameters.rs` | a parameter vector's exact key ([`parameter_key`]) and stored text |
//! | `design_points.rs` | recording a design's points as runs, reading them back |
//! | [`recorded_designs`] | the designs recorded, how far each got, setting one aside |
//! | `queries.rs` | reads of runs, attempts and outputs, and the rows they return |
//! | `writer.rs` | a coordinator's writes, one transaction each ([`StoreWriter`]) |
//! | `requeue.rs` | runs put back to pending (orphans, `iuq retry`, unstarted models) |
//! | `derived_results.rs` | results computed from the runs, recorded for replays |

mod derived_results;
mod design_points;
mod journal;
mod parameters;
mod queries;
pub mod recorded_designs;
mod requeue;
mod schema;
mod status;
mod writer;

#[cfg(test)]
mod tests;

use std::path::{Path, PathBuf};

use rusqlite::{Connection, OptionalExtension, params};

use crate::error::{CampaignError, Result};
use crate::outcome::unix_now;
use crate::study::CampaignStudy;

pub use journal::{JournalMode, is_network_file_system};
pub use parameters::parameter_key;
pub use queries::{ExportRow, FailedRun, OpenAttempt, PendingRun, StoredOutcome, SucceededRun};
pub use recorded_designs::{CancelledDesign, DesignSummary};
pub use schema::SCHEMA_VERSION;
pub use status::{RunStatus, StatusCounts};
pub use writer::{Disposition, StoreWriter};

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

impl CampaignStore {
    fn err(&self, source: rusqlite::Error) -> CampaignError {
        CampaignError::Store {
            path: self.path.clone(),
            source,
        }
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
        schema::create(&tx)
            .and_then(|()| tx.commit())
            .map_err(|e| CampaignError::Store {
                path: path.to_path_buf(),
                source: e,
            })?;
        Ok(store)
    }

    /// `PRAGMA integrity_check`: `ok` for a sound database.
    pub fn integrity_check(&self) -> Result<String> {
        self.connection
            .query_row("PRAGMA integrity_check", [], |r| r.get(0))
            .map_err(|e| self.err(e))
    }
}
