//! A noisy model's likelihood with its irregular outputs measured by replicate runs.
//!
//! Where the model's output at a data point does not repeat under a negligible change of the
//! parameters ([`super::reproducibility_probe`]), one run's likelihood of that datum, f_j(θ, ω),
//! is one draw of the likelihood averaged over the irregular part, E_ω f_j(θ, ω). The mean of m
//! draws — the run at θ and m − 1 runs at θ nudged by k·1e-9 of each parameter's range,
//! k = 1 … m − 1, whose irregular parts are unrelated — is still an unbiased draw, with 1/m of the
//! variance:
//!
//! ln L̂(θ) = Σ_{j regular} ln f_j(θ) + Σ_{g} ln (1/m) Σ_k Π_{j ∈ g irregular} f_j(θ_k),
//!
//! the mean over k taken per run group g (the data one run returns share its irregular part; a
//! group of one datum per run — the red-cell studies' stresses — averages datum by datum), and
//! separate runs' irregular parts being unrelated, exp of it is unbiased for the averaged
//! likelihood (pseudo-marginal, Andrieu & Roberts 2009). Only the run groups holding an irregular
//! datum are repeated (for the red-cell studies: one stress of eight). A failed replicate counts
//! as f = 0 (as a failed run does throughout; counted in `replicate_failures`). The replicate runs
//! are campaign runs under [`REPLICATES_DESIGN`], so a rerun reuses them; the k = 1 runs of the
//! probed members are the probe's own.

use std::collections::{BTreeSet, HashSet};
use std::sync::atomic::{AtomicUsize, Ordering};

use iuq_basis::{ErrorModel, LogLikelihood, Observations, PointLogLikelihood};

use super::model_runs::ModelRuns;
use super::reproducibility_probe::nudged_by;

/// Label of the replicate runs in the campaign store.
pub const REPLICATES_DESIGN: &str = "model-posterior-replicates";

/// The most replicates per member and irregular output.
pub const MAX_REPLICATES: usize = 64;

/// [`LogLikelihood`] of the model with its irregular data points averaged over replicates.
pub struct ReplicatedLikelihood<'a> {
    /// The model's ordinary likelihood (its runs at θ, every group).
    pub base: &'a dyn LogLikelihood,
    /// The model's runs, for the replicates.
    pub runs: &'a ModelRuns,
    /// The data.
    pub observations: &'a Observations,
    /// The error terms.
    pub errors: ErrorModel,
    /// The irregular data points (indices into the data).
    pub irregular: Vec<usize>,
    /// m: runs per member at each irregular data point, the one at θ included.
    pub replicates: usize,
    /// The model parameters' prior ranges (for the nudges).
    pub ranges: Vec<(f64, f64)>,
    /// Points already run by the reproducibility probe (their parameters' bits): the probed
    /// members' k = 1 replicates, not counted again.
    pub already_run: HashSet<Vec<u64>>,
    /// Replicate runs requested so far (k ≥ 1, beyond the probe's; stored runs included).
    pub replicate_runs: AtomicUsize,
    /// Of the replicate runs (k ≥ 1), those that failed (their likelihood counts as 0).
    pub replicate_failures: AtomicUsize,
}

/// The bits of a point, to compare points exactly.
pub fn bits(point: &[f64]) -> Vec<u64> {
    point.iter().map(|v| v.to_bits()).collect()
}

impl ReplicatedLikelihood<'_> {
    /// The run groups holding an irregular datum: the groups each member's replicates repeat.
    pub fn irregular_groups(&self) -> Vec<usize> {
        let irregular: BTreeSet<usize> = self.irregular.iter().copied().collect();
        (0..self.runs.groups())
            .filter(|&g| self.runs.group_outputs(g).any(|j| irregular.contains(&j)))
            .collect()
    }
}

/// ln (1/m) Σ exp(v_k), with −∞ terms (failed replicates) counted as zeros.
fn log_mean_exp(values: &[f64]) -> f64 {
    let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !max.is_finite() {
        return f64::NEG_INFINITY;
    }
    let sum: f64 = values.iter().map(|v| (v - max).exp()).sum();
    max + (sum / values.len() as f64).ln()
}

impl LogLikelihood for ReplicatedLikelihood<'_> {
    fn parameter_count(&self) -> usize {
        self.base.parameter_count()
    }

    fn log_likelihood_batch(
        &self,
        points: &[Vec<f64>],
    ) -> iuq_basis::Result<Vec<PointLogLikelihood>> {
        let mut values = self.base.log_likelihood_batch(points)?;
        if self.replicates <= 1 || self.irregular.is_empty() {
            return Ok(values);
        }
        let d = self.runs.parameters().len();
        let sigma_m = |p: &[f64]| p.get(d).copied().unwrap_or(0.0);
        let groups = self.irregular_groups();
        // Every replicate k = 0 … m − 1 of every member whose own runs succeeded, at every
        // irregular group, in one campaign batch (k = 0 is the member's own run, stored).
        let members: Vec<usize> = (0..points.len()).filter(|&i| values[i].is_ok()).collect();
        let mut requests = Vec::new();
        for &i in &members {
            let theta = vec![points[i][..d].to_vec()];
            for k in 0..self.replicates {
                let at = nudged_by(&theta, &self.ranges, k as f64).remove(0);
                for &g in &groups {
                    requests.push((g, at.clone()));
                }
            }
        }
        let new_runs = requests
            .iter()
            .enumerate()
            .filter(|(r, (_, at))| {
                let k = (r / groups.len()) % self.replicates;
                k > 0 && !self.already_run.contains(&bits(at))
            })
            .count();
        self.replicate_runs.fetch_add(new_runs, Ordering::Relaxed);
        let outcomes = self
            .runs
            .run(Some(REPLICATES_DESIGN), &requests)
            .map_err(|e| {
                if e.is_bad_input() {
                    iuq_basis::BasisError::ModelInput(e.message().to_string())
                } else {
                    iuq_basis::BasisError::ModelBatch(format!("replicate runs: {e}"))
                }
            })?;
        let failed = requests
            .iter()
            .zip(&outcomes)
            .enumerate()
            .filter(|(r, (_, o))| (r / groups.len()) % self.replicates > 0 && o.is_err())
            .count();
        self.replicate_failures.fetch_add(failed, Ordering::Relaxed);
        let per_member = self.replicates * groups.len();
        let y = &self.observations.values;
        let measurement = self.observations.measurement_std.as_deref();
        for (m, &i) in members.iter().enumerate() {
            let outcomes = &outcomes[m * per_member..(m + 1) * per_member];
            let s_m = sigma_m(&points[i]);
            let mut correction = 0.0;
            for (gi, &g) in groups.iter().enumerate() {
                let width = self.runs.group_outputs(g).len();
                // ln Π_{j irregular in g} f_j of replicate k: a run's data share its irregular
                // part, so the mean over k is taken of the group's product, not datum by datum.
                let terms: Vec<f64> = (0..self.replicates)
                    .map(|k| match &outcomes[k * groups.len() + gi] {
                        Ok(e) if e.outputs.len() == width => self
                            .runs
                            .group_outputs(g)
                            .enumerate()
                            .filter(|(_, j)| self.irregular.contains(j))
                            .map(|(offset, j)| {
                                let q = e.outputs[offset];
                                // As the model at the data reads a run's stds: all or none.
                                let s = match &e.computational_std {
                                    Some(s) if s.len() == width => s[offset],
                                    _ => 0.0,
                                };
                                if !q.is_finite() {
                                    return f64::NEG_INFINITY;
                                }
                                self.errors
                                    .datum_log_likelihood(
                                        j,
                                        y[j],
                                        measurement.map(|s| s[j]),
                                        q,
                                        s,
                                        s_m,
                                    )
                                    .unwrap_or(f64::NEG_INFINITY)
                            })
                            .sum(),
                        _ => f64::NEG_INFINITY,
                    })
                    .collect();
                // Replace the member's own term (k = 0) by the mean over the replicates.
                correction += log_mean_exp(&terms) - terms[0];
            }
            if let Ok(v) = &mut values[i] {
                *v += correction;
            }
        }
        Ok(values)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_log_mean_exp_averages_likelihoods_and_counts_failures_as_zeros() {
        let v = [(-1.0f64), (-2.0), f64::NEG_INFINITY];
        let expected = ((-1.0f64).exp() + (-2.0f64).exp()) / 3.0;
        assert!((log_mean_exp(&v) - expected.ln()).abs() < 1e-14);
        assert_eq!(log_mean_exp(&[f64::NEG_INFINITY; 2]), f64::NEG_INFINITY);
        assert!((log_mean_exp(&[-800.0, -800.0]) + 800.0).abs() < 1e-12);
    }
}
