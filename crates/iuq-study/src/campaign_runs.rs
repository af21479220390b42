//! Campaigns of model runs as the study layer uses them: campaign errors as study errors,
//! opening (and resuming) a campaign with this executable as the remote worker, and the log line
//! of a campaign's progress.

use iuq_campaign::store::{DesignSummary, FailedRun, JournalMode};
use iuq_campaign::{
    Campaign, CampaignError, CampaignOptions, CampaignStore, CampaignStudy, Progress,
    ResumeSummary, StatusCounts, store_path,
};
use serde_json::{Map, Value, json};

use crate::error::{Result, StudyError, input_error};

/// A campaign error as a study error: bad input (a study file, a flag) or a failure of the
/// work, with the campaign error's message.
pub fn campaign_error(error: CampaignError) -> StudyError {
    StudyError::from(error)
}

/// Open the campaign of `study` (resuming it), with the iuq executable as the remote worker
/// (`<exe> worker`, see `iuq_campaign::worker::iuq_executable`) unless the study's executor
/// names one; `max_parallel` overrides `executor.max_parallel` (0 is an input error).
pub fn open_campaign(
    study: CampaignStudy,
    max_parallel: Option<usize>,
) -> Result<(Campaign, ResumeSummary)> {
    open_campaign_with(
        study,
        CampaignOptions {
            max_parallel,
            ..Default::default()
        },
    )
}

/// [`open_campaign`] with every option of the campaign (an in-process model, a poll interval);
/// an `options.worker_command` of `None` gets the default worker.
pub fn open_campaign_with(
    study: CampaignStudy,
    mut options: CampaignOptions,
) -> Result<(Campaign, ResumeSummary)> {
    if options.max_parallel == Some(0) {
        return Err(input_error("--max-parallel: must be at least 1"));
    }
    if options.worker_command.is_none() {
        options.worker_command = study.executor.worker.clone().or_else(|| {
            iuq_campaign::worker::iuq_executable()
                .map(|exe| vec![exe.display().to_string(), "worker".to_string()])
        });
    }
    Campaign::open(study, &options).map_err(campaign_error)
}

/// A duration for people: `42s`, `3m05s`, `2h10m`.
pub fn human_duration(s: f64) -> String {
    let s = s.max(0.0).round() as u64;
    match s {
        0..=59 => format!("{s}s"),
        60..=3599 => format!("{}m{:02}s", s / 60, s % 60),
        _ => format!("{}h{:02}m", s / 3600, (s % 3600) / 60),
    }
}

/// One log line about the progress of campaign `name`.
pub fn progress_line(name: &str, p: &Progress) -> String {
    let c = &p.counts;
    format!(
        "campaign {name}: {}/{} finished ({} succeeded, {} failed), {} running, {} queued, {} pending, elapsed {}, ETA {}",
        c.finished(),
        c.total(),
        c.succeeded,
        c.failed + c.cancelled,
        c.running,
        c.queued,
        c.pending,
        human_duration(p.elapsed_seconds),
        p.eta_seconds
            .map_or_else(|| "unknown".into(), human_duration)
    )
}

/// Where a campaign stands: runs per status, attempts per outcome, and the failures with their
/// reasons — what `iuq status` prints and the Python package's `Study.status` returns.
#[derive(Debug, Clone)]
pub struct CampaignStatus {
    /// The study's name.
    pub study: String,
    /// The store file.
    pub store: std::path::PathBuf,
    /// The store's journal mode.
    pub journal_mode: JournalMode,
    /// Runs per status.
    pub counts: StatusCounts,
    /// Attempts per outcome kind (`open` for those without one yet).
    pub attempts: Vec<(String, u64)>,
    /// The failed runs, by run id.
    pub failures: Vec<FailedRun>,
    /// The names of the runs' parameters, in order.
    pub parameter_names: Vec<String>,
    /// The designs recorded in the store (every batch a coordinator asked for), oldest first.
    pub designs: Vec<DesignSummary>,
}

impl CampaignStatus {
    /// Read the status of `study`'s campaign from its store (which must exist).
    pub fn read(study: &CampaignStudy) -> Result<Self> {
        let path = store_path(study);
        let store = CampaignStore::open_existing(&path).map_err(campaign_error)?;
        Ok(Self {
            study: study.name.clone(),
            journal_mode: store.journal_mode(),
            counts: store.counts(None).map_err(campaign_error)?,
            attempts: store.attempt_kinds().map_err(campaign_error)?,
            failures: store.failures().map_err(campaign_error)?,
            designs: store.design_summaries().map_err(campaign_error)?,
            parameter_names: study.space.names(),
            store: path,
        })
    }

    /// The status as the JSON object of `iuq status --json`.
    pub fn to_json(&self) -> Value {
        let failures: Vec<Value> = self
            .failures
            .iter()
            .map(|f| {
                let parameters: Map<String, Value> = self
                    .parameter_names
                    .iter()
                    .cloned()
                    .zip(f.parameters.iter().map(|v| json!(v)))
                    .collect();
                json!({"run_id": f.run_id, "parameters": parameters, "attempts": f.attempts, "kind": f.kind, "reason": f.reason})
            })
            .collect();
        let attempts: Map<String, Value> = self
            .attempts
            .iter()
            .map(|(k, n)| (k.clone(), json!(n)))
            .collect();
        json!({
            "study": self.study,
            "store": self.store.display().to_string(),
            "journal_mode": self.journal_mode,
            "counts": self.counts,
            "total": self.counts.total(),
            "attempts": attempts,
            "failures": failures,
            "designs": self.designs,
        })
    }
}
