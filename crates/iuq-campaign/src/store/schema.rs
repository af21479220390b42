//! The store's tables: the schema a new store is created with and its version, kept in `meta`.

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

/// Create the tables a store lacks and record the schema version, in the store's first
/// transaction.
pub(super) fn create(tx: &rusqlite::Transaction<'_>) -> rusqlite::Result<()> {
    tx.execute_batch(SCHEMA)?;
    tx.execute(
        "INSERT OR IGNORE INTO meta(key, value) VALUES ('schema_version', ?1)",
        [SCHEMA_VERSION.to_string()],
    )?;
    Ok(())
}
