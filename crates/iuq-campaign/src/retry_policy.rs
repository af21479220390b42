//! Which failed attempts are tried again, and how often.
//!
//! Infrastructure failures (a lost execution, a node failure, a command that could not be
//! started) are retried by default; deterministic failures of the model (non-zero exit, signal,
//! timeout, bad or missing output) are not, because the same parameters fail the same way.
//! Both are configurable in the study file:
//!
//! ```toml
//! [executor]
//! retry = { max_attempts = 3, on = ["lost", "infrastructure", "spawn_failed", "timeout"] }
//! ```

use serde::{Deserialize, Serialize};

use crate::outcome::OutcomeKind;

/// The retry policy of a campaign.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RetryPolicy {
    /// Executions of one run at most, the first included (≥ 1).
    pub max_attempts: u32,
    /// Outcome kinds after which a run is tried again (while attempts remain).
    pub retry_on: Vec<OutcomeKind>,
}

impl Default for RetryPolicy {
    fn default() -> Self {
        Self {
            max_attempts: 3,
            retry_on: vec![
                OutcomeKind::Lost,
                OutcomeKind::Infrastructure,
                OutcomeKind::SpawnFailed,
            ],
        }
    }
}

impl RetryPolicy {
    /// True when a run whose attempt number `attempt` ended in `kind` is to be run again.
    pub fn should_retry(&self, kind: OutcomeKind, attempt: u32) -> bool {
        kind != OutcomeKind::Succeeded
            && attempt < self.max_attempts
            && self.retry_on.contains(&kind)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn infrastructure_failures_are_retried_model_failures_are_not() {
        let p = RetryPolicy::default();
        assert!(p.should_retry(OutcomeKind::Lost, 1));
        assert!(p.should_retry(OutcomeKind::Infrastructure, 2));
        assert!(!p.should_retry(OutcomeKind::Lost, 3));
        assert!(!p.should_retry(OutcomeKind::ExitStatus, 1));
        assert!(!p.should_retry(OutcomeKind::Timeout, 1));
        assert!(!p.should_retry(OutcomeKind::Succeeded, 1));
        let p = RetryPolicy {
            max_attempts: 2,
            retry_on: vec![OutcomeKind::Timeout],
        };
        assert!(p.should_retry(OutcomeKind::Timeout, 1));
        assert!(!p.should_retry(OutcomeKind::Lost, 1));
    }
}
