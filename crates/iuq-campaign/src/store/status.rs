//! The status of a run ([`RunStatus`], as the store names it) and counts of runs per status.

use serde::Serialize;

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
