//! A campaign as a batch [`Model`]: the surrogate, the sensitivity analysis and BASIS evaluate an
//! expensive model without knowing it runs as a campaign.
//!
//! Each call of [`Model::evaluate_batch`] records the batch as a design of the store, runs what
//! is not yet known (a vector evaluated before, in this or an earlier session, is not run
//! again), and returns one outcome per point: the outputs, or the failure with its reason.

use std::sync::Mutex;
use std::time::Duration;

use iuq_core::{Control, CoreError, Evaluation, EvaluationFailure, Model, Observer, Outcome};

use crate::campaign::{Campaign, Progress};
use crate::{CampaignError, StatusCounts};

/// Observer of a campaign model's progress; [`Control::Stop`] stops the batch's campaign (the
/// batch then fails with the campaign's [`CampaignError::Interrupted`]).
pub type ProgressObserver = Box<dyn Observer<Progress> + Send>;

/// A campaign evaluated as a batch model.
pub struct CampaignModel {
    inputs: Vec<String>,
    outputs: Vec<String>,
    state: Mutex<(Campaign, usize, Option<ProgressObserver>)>,
    report_every: Duration,
}

impl std::fmt::Debug for CampaignModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CampaignModel")
            .field("inputs", &self.inputs)
            .field("outputs", &self.outputs)
            .finish()
    }
}

impl CampaignModel {
    /// Wrap an open campaign.
    pub fn new(campaign: Campaign) -> Self {
        let inputs = campaign.study().space.names();
        let outputs = campaign.study().model.outputs.clone();
        Self {
            inputs,
            outputs,
            state: Mutex::new((campaign, 0, None)),
            report_every: Duration::from_secs(2),
        }
    }

    /// Call `observer` with the progress of each batch, at most every `every`.
    pub fn with_progress(mut self, every: Duration, observer: ProgressObserver) -> Self {
        self.report_every = every;
        if let Ok(mut state) = self.state.lock() {
            state.2 = Some(observer);
        }
        self
    }

    /// The store's runs counted by status, and the reason of every failed run: the run
    /// statistics of a report, counted over runs (one per point and output group), not points.
    pub fn run_statistics(&self) -> crate::Result<(StatusCounts, Vec<String>)> {
        let guard = self
            .state
            .lock()
            .map_err(|_| CampaignError::BadInput("the campaign's lock is poisoned".into()))?;
        let store = guard.0.store();
        let counts = store.counts(None)?;
        let reasons = store.failures()?.into_iter().map(|f| f.reason).collect();
        Ok((counts, reasons))
    }

    /// The points of the design recorded in the store under `label`, if any (see
    /// [`crate::CampaignStore::design_points`]).
    pub fn recorded_design(&self, label: &str) -> crate::Result<Option<Vec<Vec<f64>>>> {
        let guard = self
            .state
            .lock()
            .map_err(|_| CampaignError::BadInput("the campaign's lock is poisoned".into()))?;
        guard.0.store().design_points(label)
    }

    /// The median wall time of the campaign's succeeded runs (see
    /// [`crate::CampaignStore::median_run_seconds`]).
    pub fn median_run_seconds(&self) -> crate::Result<Option<f64>> {
        let guard = self
            .state
            .lock()
            .map_err(|_| CampaignError::BadInput("the campaign's lock is poisoned".into()))?;
        guard.0.store().median_run_seconds()
    }

    /// The result derived from the runs recorded under `key` with `fingerprint`, if any (see
    /// [`crate::CampaignStore::derived_result`]).
    pub fn derived_result(&self, key: &str, fingerprint: &str) -> crate::Result<Option<String>> {
        let guard = self
            .state
            .lock()
            .map_err(|_| CampaignError::BadInput("the campaign's lock is poisoned".into()))?;
        guard.0.store().derived_result(key, fingerprint)
    }

    /// Record a result derived from the runs (see
    /// [`crate::CampaignStore::record_derived_result`]).
    pub fn record_derived_result(
        &self,
        key: &str,
        fingerprint: &str,
        value: &str,
    ) -> crate::Result<()> {
        let mut guard = self
            .state
            .lock()
            .map_err(|_| CampaignError::BadInput("the campaign's lock is poisoned".into()))?;
        guard
            .0
            .store_mut()
            .record_derived_result(key, fingerprint, value)
    }

    /// Give the campaign back.
    pub fn into_campaign(self) -> Option<Campaign> {
        self.state.into_inner().ok().map(|s| s.0)
    }
}

impl Model for CampaignModel {
    fn input_names(&self) -> &[String] {
        &self.inputs
    }

    fn output_names(&self) -> &[String] {
        &self.outputs
    }

    fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
        self.evaluate_labelled(None, points)
    }
}

impl CampaignModel {
    /// [`Model::evaluate_batch`] with the design recorded in the store under `label` (default:
    /// `batch-<number of this session's batch>`): a design that names its purpose
    /// (`initial-design`, `adaptive-round-3`) is found again by a rerun, which then adds
    /// nothing.
    pub fn evaluate_labelled(
        &self,
        label: Option<&str>,
        points: &[Vec<f64>],
    ) -> iuq_core::Result<Vec<Outcome>> {
        let unavailable = |e: crate::CampaignError| {
            if e.is_bad_input() {
                CoreError::ModelInput(e.to_string())
            } else {
                CoreError::ModelUnavailable(e.to_string())
            }
        };
        let mut guard = self
            .state
            .lock()
            .map_err(|_| CoreError::ModelUnavailable("the campaign's lock is poisoned".into()))?;
        let (campaign, batches, observer) = &mut *guard;
        *batches += 1;
        let label = label.map_or_else(|| format!("batch-{batches}"), str::to_string);
        let run_ids = campaign.add_points(&label, points).map_err(unavailable)?;
        let mut noop = |_: &Progress| Control::Continue;
        let observer: &mut dyn Observer<Progress> = match observer {
            Some(o) => o.as_mut(),
            None => &mut noop,
        };
        campaign
            .run_only(&run_ids, self.report_every, observer)
            .map_err(unavailable)?;
        let stored = campaign.store().outcomes(&run_ids).map_err(unavailable)?;
        Ok(stored
            .into_iter()
            .map(|s| match s {
                Some(Ok((outputs, std))) => Ok(Evaluation {
                    outputs,
                    computational_std: std,
                }),
                Some(Err(reason)) => Err(EvaluationFailure::new(reason)),
                None => Err(EvaluationFailure::new("the run did not finish")),
            })
            .collect())
    }
}
