//! The designs recorded in a campaign store — each batch of points a coordinator asked for,
//! under its label — with how far each got, and setting a design aside: the store's methods
//! [`CampaignStore::design_summaries`] and [`CampaignStore::cancel_design`] and what they return.
//! (The `[design]` a study file asks for is [`crate::study_design`].)
//!
//! A pipeline that changes course (a posterior check stopped half-way, a batch found useless)
//! leaves the pending runs of the design it abandoned in the store. A pipeline never runs them
//! (it runs only the runs it asks for), but `iuq run` runs every pending run, and `iuq status`
//! counts them. [`CampaignStore::cancel_design`] sets such a design's pending runs to
//! `cancelled` (a final status: nothing runs them); a design that asks for one of them again
//! makes it pending again (the store's `revive_cancelled`, called whenever a design is
//! recorded), so that cancelling never costs a later request its result.

use rusqlite::{OptionalExtension, params};
use serde::Serialize;

use super::{CampaignStore, StatusCounts};
use crate::error::{CampaignError, Result};
use crate::outcome::unix_now;

/// A design of the store and the status of its runs.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DesignSummary {
    /// The design's id (the order in which designs were recorded).
    pub id: i64,
    /// Its label (`initial-design`, `adaptive-round-3`, `model-posterior-1`, …; several designs
    /// may share one).
    pub label: String,
    /// Points asked for.
    pub size: u64,
    /// When it was recorded (seconds since the Unix epoch).
    pub created_at: f64,
    /// Its runs per status (a run asked for by several designs counts in each).
    pub counts: StatusCounts,
    /// What its runs cost since it was recorded: the summed duration (start to finish, in
    /// seconds) of the attempts at its runs submitted at or after `created_at` (a run it reused
    /// from an earlier design cost it nothing; an attempt lost before it finished is not
    /// counted). The model time the design took, e.g. a model posterior's batch.
    pub run_seconds: f64,
    /// The first start and last finish of those attempts (seconds since the Unix epoch; `None`
    /// before one has finished): the wall-clock span in which the design's runs were made,
    /// stops of the campaign included.
    pub first_started_at: Option<f64>,
    /// See [`DesignSummary::first_started_at`].
    pub last_finished_at: Option<f64>,
}

/// What [`CampaignStore::cancel_design`] did.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CancelledDesign {
    /// The design.
    pub design: DesignSummary,
    /// Its runs set from pending to cancelled.
    pub cancelled: u64,
}

impl CampaignStore {
    /// Every design of the store, oldest first.
    pub fn design_summaries(&self) -> Result<Vec<DesignSummary>> {
        let err = |e| self.err(e);
        let connection = &self.connection;
        let mut designs = connection
            .prepare("SELECT id, label, size, created_at FROM designs ORDER BY id")
            .map_err(err)?;
        let rows: Vec<(i64, String, i64, f64)> = designs
            .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?)))
            .and_then(|rows| rows.collect())
            .map_err(err)?;
        let mut statuses = connection
            .prepare(
                "SELECT dp.design_id, r.status, COUNT(*) FROM design_points dp \
                 JOIN runs r ON r.id = dp.run_id GROUP BY dp.design_id, r.status",
            )
            .map_err(err)?;
        let per_status: Vec<(i64, String, i64)> = statuses
            .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))
            .and_then(|rows| rows.collect())
            .map_err(err)?;
        let mut times = connection
            .prepare(
                "SELECT dp.design_id, SUM(a.finished_at - a.started_at), MIN(a.started_at), \
                 MAX(a.finished_at) FROM designs d JOIN design_points dp ON dp.design_id = d.id \
                 JOIN attempts a ON a.run_id = dp.run_id WHERE a.submitted_at >= d.created_at \
                 AND a.started_at IS NOT NULL AND a.finished_at IS NOT NULL GROUP BY dp.design_id",
            )
            .map_err(err)?;
        let per_design_time: Vec<(i64, f64, f64, f64)> = times
            .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?)))
            .and_then(|rows| rows.collect())
            .map_err(err)?;
        Ok(rows
            .into_iter()
            .map(|(id, label, size, created_at)| {
                let mut counts = StatusCounts::default();
                for (_, status, n) in per_status.iter().filter(|(d, _, _)| *d == id) {
                    counts.add(status, *n as u64);
                }
                let time = per_design_time.iter().find(|(d, ..)| *d == id);
                DesignSummary {
                    id,
                    label,
                    size: size as u64,
                    created_at,
                    counts,
                    run_seconds: time.map_or(0.0, |t| t.1),
                    first_started_at: time.map(|t| t.2),
                    last_finished_at: time.map(|t| t.3),
                }
            })
            .collect())
    }

    /// Set the pending runs of design `design_id` to cancelled, with the reason saying so. Queued
    /// and running runs are left alone (only a coordinator may touch them, and one holding the
    /// campaign is the caller). An unknown id is bad input.
    pub fn cancel_design(&self, design_id: i64) -> Result<CancelledDesign> {
        let err = |e| self.err(e);
        let label: Option<String> = self
            .connection
            .query_row(
                "SELECT label FROM designs WHERE id = ?1",
                [design_id],
                |r| r.get(0),
            )
            .optional()
            .map_err(err)?;
        let Some(label) = label else {
            let known = self.design_summaries()?;
            return Err(CampaignError::BadInput(format!(
                "--design {design_id}: {} has no design {design_id} ({})",
                self.path().display(),
                match (known.first(), known.last()) {
                    (Some(first), Some(last)) => format!(
                        "its designs are {} to {}; `iuq status` lists them",
                        first.id, last.id
                    ),
                    _ => "it has none".to_string(),
                }
            )));
        };
        let cancelled = self
            .connection
            .execute(
                "UPDATE runs SET status = 'cancelled', outcome_kind = 'cancelled', reason = ?1, \
                 updated_at = ?2 WHERE status = 'pending' AND id IN \
                 (SELECT run_id FROM design_points WHERE design_id = ?3)",
                params![
                    format!("design {design_id} (`{label}`) set aside with `iuq cancel`"),
                    unix_now(),
                    design_id
                ],
            )
            .map_err(err)? as u64;
        let design = self
            .design_summaries()?
            .into_iter()
            .find(|d| d.id == design_id)
            .ok_or_else(|| {
                CampaignError::BadInput(format!(
                    "design {design_id} vanished while it was cancelled"
                ))
            })?;
        Ok(CancelledDesign { design, cancelled })
    }
}
