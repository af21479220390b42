//! Putting runs back to pending outside a coordinator's transactions: orphans of a coordinator
//! that died, failed runs for `iuq retry`, runs whose model never started.

use super::CampaignStore;
use crate::error::Result;
use crate::outcome::unix_now;

impl CampaignStore {
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
}
