//! Recording a design's points as runs (identical vectors share one run, a design recorded again
//! is not recorded twice, cancelled runs it asks for are pending again) and reading them back.

use rusqlite::{Connection, OptionalExtension, params};

use super::CampaignStore;
use super::parameters::{decode_parameters, encode_parameters, parameter_key};
use crate::error::{CampaignError, Result};
use crate::outcome::unix_now;

impl CampaignStore {
    /// Record a design (a batch of points) and the runs it needs; identical vectors share one
    /// run. Returns the run id of each point, in order. A design already recorded under the same
    /// label with the same runs is not recorded again, so rerunning a study leaves its store as
    /// it was.
    pub fn add_design(&mut self, label: &str, points: &[Vec<f64>]) -> Result<Vec<i64>> {
        if let Some((i, _)) = points
            .iter()
            .enumerate()
            .find(|(_, p)| p.iter().any(|v| !v.is_finite()))
        {
            return Err(CampaignError::BadInput(format!(
                "design `{label}`: point {i} has a non-finite coordinate"
            )));
        }
        let now = unix_now();
        let study_id = self.study_id;
        let path = self.path.clone();
        let err = |e| CampaignError::Store {
            path: path.clone(),
            source: e,
        };
        if let Some(ids) = self.recorded_design(label, points).map_err(err)? {
            revive_cancelled(&self.connection, &ids).map_err(err)?;
            return Ok(ids);
        }
        let tx = self.connection.transaction().map_err(err)?;
        let mut ids = Vec::with_capacity(points.len());
        {
            tx.execute(
                "INSERT INTO designs(study_id, label, size, created_at) VALUES (?1, ?2, ?3, ?4)",
                params![study_id, label, points.len() as i64, now],
            )
            .map_err(err)?;
            let design_id = tx.last_insert_rowid();
            let mut insert = tx
                .prepare_cached(
                    "INSERT OR IGNORE INTO runs(parameter_key, parameters, status, created_at, updated_at) VALUES (?1, ?2, 'pending', ?3, ?3)",
                )
                .map_err(err)?;
            let mut find = tx
                .prepare_cached("SELECT id FROM runs WHERE parameter_key = ?1")
                .map_err(err)?;
            let mut link = tx
                .prepare_cached(
                    "INSERT INTO design_points(design_id, position, run_id) VALUES (?1, ?2, ?3)",
                )
                .map_err(err)?;
            for (position, point) in points.iter().enumerate() {
                let key = parameter_key(point);
                insert
                    .execute(params![key, encode_parameters(point), now])
                    .map_err(err)?;
                let id: i64 = find.query_row([&key], |r| r.get(0)).map_err(err)?;
                link.execute(params![design_id, position as i64, id])
                    .map_err(err)?;
                ids.push(id);
            }
        }
        revive_cancelled(&tx, &ids).map_err(err)?;
        tx.commit().map_err(err)?;
        Ok(ids)
    }

    /// The points of the latest design of this study recorded under `label`, in order, if there
    /// is one: what an earlier coordinator chose, read back bit for bit (so that a rerun can
    /// replay its choices even where recomputing them would differ in the last bits).
    pub fn design_points(&self, label: &str) -> Result<Option<Vec<Vec<f64>>>> {
        let design: Option<i64> = self
            .connection
            .query_row(
                "SELECT max(id) FROM designs WHERE study_id = ?1 AND label = ?2",
                params![self.study_id, label],
                |r| r.get(0),
            )
            .map_err(|e| self.err(e))?;
        let Some(design) = design else {
            return Ok(None);
        };
        let mut points = self
            .connection
            .prepare_cached(
                "SELECT r.parameters FROM design_points dp JOIN runs r ON r.id = dp.run_id WHERE dp.design_id = ?1 ORDER BY dp.position",
            )
            .map_err(|e| self.err(e))?;
        let rows = points
            .query_map([design], |r| r.get::<_, String>(0))
            .map_err(|e| self.err(e))?
            .map(|t| t.and_then(|text| decode_parameters(&text, 0)))
            .collect::<rusqlite::Result<Vec<_>>>()
            .map_err(|e| self.err(e))?;
        Ok(Some(rows))
    }

    /// The run ids of a design of this study recorded under `label` with exactly the runs of
    /// `points`, if there is one.
    fn recorded_design(
        &self,
        label: &str,
        points: &[Vec<f64>],
    ) -> rusqlite::Result<Option<Vec<i64>>> {
        let mut find = self
            .connection
            .prepare_cached("SELECT id FROM runs WHERE parameter_key = ?1")?;
        let mut ids = Vec::with_capacity(points.len());
        for point in points {
            match find
                .query_row([parameter_key(point)], |r| r.get::<_, i64>(0))
                .optional()?
            {
                Some(id) => ids.push(id),
                None => return Ok(None),
            }
        }
        let mut designs = self.connection.prepare_cached(
            "SELECT id FROM designs WHERE study_id = ?1 AND label = ?2 AND size = ?3 ORDER BY id",
        )?;
        let candidates: Vec<i64> = designs
            .query_map(params![self.study_id, label, points.len() as i64], |r| {
                r.get(0)
            })?
            .collect::<rusqlite::Result<_>>()?;
        let mut members = self.connection.prepare_cached(
            "SELECT run_id FROM design_points WHERE design_id = ?1 ORDER BY position",
        )?;
        for design in candidates {
            let runs: Vec<i64> = members
                .query_map([design], |r| r.get(0))?
                .collect::<rusqlite::Result<_>>()?;
            if runs == ids {
                return Ok(Some(ids));
            }
        }
        Ok(None)
    }
}

/// Make the cancelled runs among `run_ids` pending again: a design asked for them. Writes
/// nothing when the store has no cancelled run (a replay of a finished study stays a read).
fn revive_cancelled(connection: &Connection, run_ids: &[i64]) -> rusqlite::Result<()> {
    let any: i64 = connection.query_row(
        "SELECT COUNT(*) FROM runs WHERE status = 'cancelled'",
        [],
        |r| r.get(0),
    )?;
    if any == 0 {
        return Ok(());
    }
    let mut revive = connection.prepare_cached(
        "UPDATE runs SET status = 'pending', outcome_kind = NULL, reason = NULL, updated_at = ?1 \
         WHERE id = ?2 AND status = 'cancelled'",
    )?;
    let now = unix_now();
    for id in run_ids {
        revive.execute(params![now, id])?;
    }
    Ok(())
}
