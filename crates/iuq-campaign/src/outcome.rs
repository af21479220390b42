//! What one execution of a run ended in: the outcome kinds recorded per attempt, and the
//! per-run result a worker writes.

use serde::{Deserialize, Serialize};

/// How one attempt at a run ended. Stored as the snake-case name in the `attempts` table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OutcomeKind {
    /// Exit status 0 and every output decoded to a finite number.
    Succeeded,
    /// The command exited with a non-zero status.
    ExitStatus,
    /// The command was killed by a signal it did not get from the timeout.
    Signal,
    /// The command ran past its timeout and was stopped (SIGTERM, then SIGKILL).
    Timeout,
    /// The output file was not written.
    MissingOutput,
    /// The output file could not be decoded (not JSON, no such column, no regex match, …).
    BadOutput,
    /// An output decoded to NaN or an infinity.
    NonFinite,
    /// The command could not be started (not found, not executable).
    SpawnFailed,
    /// The execution vanished: its coordinator or scheduler job died without a result.
    Lost,
    /// The scheduler or node failed (node failure, preemption, worker crash, …).
    Infrastructure,
    /// The run was cancelled.
    Cancelled,
}

impl OutcomeKind {
    /// Every kind, in a stable order.
    pub const ALL: [OutcomeKind; 11] = [
        Self::Succeeded,
        Self::ExitStatus,
        Self::Signal,
        Self::Timeout,
        Self::MissingOutput,
        Self::BadOutput,
        Self::NonFinite,
        Self::SpawnFailed,
        Self::Lost,
        Self::Infrastructure,
        Self::Cancelled,
    ];

    /// The snake-case name (as stored and printed).
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Succeeded => "succeeded",
            Self::ExitStatus => "exit_status",
            Self::Signal => "signal",
            Self::Timeout => "timeout",
            Self::MissingOutput => "missing_output",
            Self::BadOutput => "bad_output",
            Self::NonFinite => "non_finite",
            Self::SpawnFailed => "spawn_failed",
            Self::Lost => "lost",
            Self::Infrastructure => "infrastructure",
            Self::Cancelled => "cancelled",
        }
    }

    /// The kind called `name`.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.as_str() == name)
    }

    /// True for failures of the model itself (deterministic: the same parameters fail again),
    /// false for success, infrastructure failures and cancellation.
    pub fn is_model_failure(self) -> bool {
        matches!(
            self,
            Self::ExitStatus
                | Self::Signal
                | Self::Timeout
                | Self::MissingOutput
                | Self::BadOutput
                | Self::NonFinite
        )
    }
}

impl std::fmt::Display for OutcomeKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The result of one run within one attempt, as written by the worker into `result.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunResult {
    /// The run.
    pub run_id: i64,
    /// Its attempt number (1 for the first execution).
    pub attempt: u32,
    /// How it ended.
    pub kind: OutcomeKind,
    /// Why it failed (absent on success).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// The decoded outputs, in the study's output order (empty on failure).
    #[serde(default)]
    pub outputs: Vec<f64>,
    /// The computational standard deviation of each output, when the decoder found one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub std: Option<Vec<f64>>,
}

impl RunResult {
    /// A failure of `run_id`/`attempt` of `kind` with `reason`.
    pub fn failure(
        run_id: i64,
        attempt: u32,
        kind: OutcomeKind,
        reason: impl Into<String>,
    ) -> Self {
        Self {
            run_id,
            attempt,
            kind,
            reason: Some(reason.into()),
            outputs: Vec::new(),
            std: None,
        }
    }
}

/// What a worker reports about one task (one process; a `batch-command` task covers many runs):
/// the content of `result.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TaskReport {
    /// One result per run of the task.
    pub runs: Vec<RunResult>,
    /// Exit status of the command, when it exited.
    #[serde(default)]
    pub exit_code: Option<i32>,
    /// The signal that ended the command, when one did.
    #[serde(default)]
    pub signal: Option<i32>,
    /// The host the command ran on.
    pub host: String,
    /// Process id of the command (its process group id).
    #[serde(default)]
    pub pid: Option<u32>,
    /// Start time, seconds since the Unix epoch.
    pub started_at: f64,
    /// End time, seconds since the Unix epoch.
    pub finished_at: f64,
    /// The last bytes of the command's standard error.
    #[serde(default)]
    pub stderr_tail: String,
}

/// Seconds since the Unix epoch, now.
pub fn unix_now() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// The host name of this machine (`/proc/sys/kernel/hostname`, then `$HOSTNAME`, else `localhost`).
pub fn host_name() -> String {
    // Read once per process: an in-process model's runs ask for it at every task.
    static HOST: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    HOST.get_or_init(|| {
        std::fs::read_to_string("/proc/sys/kernel/hostname")
            .ok()
            .map(|s| s.trim().to_string())
            .filter(|s| !s.is_empty())
            .or_else(|| std::env::var("HOSTNAME").ok())
            .unwrap_or_else(|| "localhost".into())
    })
    .clone()
}
