//! Whether the model command starts at all.
//!
//! A model command that cannot be started (a misspelt program, a missing executable, a command
//! word that does not resolve on the compute nodes) fails every run in moments: each run is
//! tried `retry.max_attempts` times and filed as failed, and a campaign of a thousand runs
//! burns through all of them in a few minutes, leaving failures that say nothing about the
//! model at those parameters (it never ran). `StartWatch` sees every finished attempt of a
//! coordinator session; once [`UNSTARTED_RUNS_LIMIT`] runs have failed for good without the
//! model having started even once in the session, the campaign stops with the reason, and the
//! runs that could not start are pending again ([`crate::store::CampaignStore::restart_unstarted`],
//! also applied when a later coordinator resumes), so that fixing the command and running again
//! runs them.

use crate::outcome::{OutcomeKind, RunResult};
use crate::store::Disposition;

/// Runs that failed for good because their command could not start, with no run started in
/// the session, after which the campaign stops.
pub const UNSTARTED_RUNS_LIMIT: usize = 3;

/// What one coordinator session has seen of its model command starting.
#[derive(Debug, Clone, Default)]
pub(crate) struct StartWatch {
    /// Whether an attempt got as far as running the model (any outcome but `spawn_failed`).
    started: bool,
    /// Runs that failed for good without starting: (run id, reason).
    unstarted: Vec<(i64, String)>,
}

impl StartWatch {
    /// Take note of one finished attempt and what the store made of it.
    pub(crate) fn observe(&mut self, result: &RunResult, disposition: Disposition) {
        match (result.kind, disposition) {
            (OutcomeKind::SpawnFailed, Disposition::Failed) => self.unstarted.push((
                result.run_id,
                result
                    .reason
                    .clone()
                    .unwrap_or_else(|| "no reason given".to_string()),
            )),
            // A lost, cancelled or infrastructure-failed attempt (an interrupt, a vanished node)
            // says nothing about the command.
            (
                OutcomeKind::SpawnFailed
                | OutcomeKind::Lost
                | OutcomeKind::Infrastructure
                | OutcomeKind::Cancelled,
                _,
            )
            | (_, Disposition::Ignored) => {}
            _ => self.started = true,
        }
    }

    /// The reason to stop, once [`UNSTARTED_RUNS_LIMIT`] runs could not start and none did.
    pub(crate) fn verdict(&self) -> Option<String> {
        if self.started || self.unstarted.len() < UNSTARTED_RUNS_LIMIT {
            return None;
        }
        let (run, reason) = &self.unstarted[0];
        Some(format!(
            "the model command cannot start: {} runs failed to start (run {run}: {reason}) and \
             none started; they and every other run that could not start are pending again. Fix \
             the study's `[model] command` (or `executor.worker`) and run again",
            self.unstarted.len()
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn result(run_id: i64, kind: OutcomeKind) -> RunResult {
        RunResult {
            run_id,
            attempt: 1,
            kind,
            reason: (kind != OutcomeKind::Succeeded).then(|| format!("{} happened", kind.as_str())),
            outputs: Vec::new(),
            std: None,
        }
    }

    #[test]
    fn stops_after_runs_that_never_started_and_not_once_one_did() {
        let mut watch = StartWatch::default();
        watch.observe(&result(1, OutcomeKind::SpawnFailed), Disposition::Retry);
        watch.observe(&result(1, OutcomeKind::SpawnFailed), Disposition::Failed);
        watch.observe(&result(2, OutcomeKind::Lost), Disposition::Failed);
        watch.observe(&result(3, OutcomeKind::SpawnFailed), Disposition::Failed);
        assert_eq!(
            watch.verdict(),
            None,
            "two runs that could not start are not yet enough"
        );
        watch.observe(&result(4, OutcomeKind::SpawnFailed), Disposition::Failed);
        let verdict = watch.verdict().unwrap();
        assert!(
            verdict.contains("3 runs failed to start (run 1: spawn_failed happened)"),
            "{verdict}"
        );

        let mut watch = StartWatch::default();
        watch.observe(&result(9, OutcomeKind::ExitStatus), Disposition::Failed);
        for run in 1..10 {
            watch.observe(&result(run, OutcomeKind::SpawnFailed), Disposition::Failed);
        }
        assert_eq!(
            watch.verdict(),
            None,
            "a model that ran once can start: a node's trouble"
        );
    }
}
