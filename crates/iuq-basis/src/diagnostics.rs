//! Per-stage diagnostics of a BASIS run (BASIS step 8, docs/methods.md §5): what each stage did
//! and how well.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::proposal::CovarianceFactor;

/// At most this many distinct failure reasons are kept per stage; further ones are counted
/// under [`OTHER_REASONS`].
pub const MAX_FAILURE_REASONS: usize = 32;
/// The key under which failures beyond [`MAX_FAILURE_REASONS`] distinct reasons are counted.
pub const OTHER_REASONS: &str = "(other reasons)";

/// What one stage did. Stage 0 is the prior stage (no step, no moves); stage k ≥ 1 anneals from
/// p_{k−1} to p_k = p_{k−1} + dp, resamples and moves; the final pass has dp = 0 at p = 1.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageDiagnostics {
    /// Stage index k.
    pub stage: usize,
    /// The exponent p_k after the stage.
    pub exponent: f64,
    /// The step dp = p_k − p_{k−1} (0 for stage 0 and the final pass).
    pub step: f64,
    /// CV of the incremental weights of the step (population std, ddof = 0).
    pub cv: f64,
    /// Effective sample size of the weights divided by N, 1/(N Σ w̄²) = 1/(1 + CV²).
    pub ess_fraction: f64,
    /// Whether the solved step was below the minimum and replaced by it.
    pub step_clamped: bool,
    /// Bisection iterations used to solve for the step.
    pub bisection_iterations: usize,
    /// The increment ln E[f^dp] of the log-evidence at this stage.
    pub log_evidence_increment: f64,
    /// The log-evidence accumulated up to and including this stage.
    pub log_evidence: f64,
    /// The largest log-likelihood of the population after the stage.
    pub max_log_likelihood: f64,
    /// How the proposal covariance was factorised (`None` at stage 0).
    pub covariance: Option<CovarianceFactor>,
    /// Number of chains (members with a positive copy count, split by l_max).
    pub chains: usize,
    /// MCMC proposals made (burn-in included).
    pub proposals: usize,
    /// Proposals accepted.
    pub accepted: usize,
    /// The proposal scale β of the stage's moves (0 at stage 0; read as 0 from a checkpoint
    /// written before it was recorded).
    #[serde(default)]
    pub proposal_scale: f64,
    /// Discarded MCMC steps each chain took before its first sample.
    #[serde(default)]
    pub burn_in: usize,
    /// The largest correlation, over the parameters, between the chains' starting points and
    /// their states at the end of the stage: near 0 when the moves took the resampled copies
    /// apart, near 1 when they barely moved (0 at stage 0).
    #[serde(default)]
    pub start_correlation: f64,
    /// accepted / proposals (0 when there were no proposals).
    pub acceptance_rate: f64,
    /// Proposals outside the prior support, rejected without evaluation.
    pub out_of_support: usize,
    /// Evaluations that failed or gave a non-finite log-likelihood (rejections at stages ≥ 1,
    /// zero-weight members at stage 0).
    pub failures: usize,
    /// Failures by reason.
    pub failure_reasons: BTreeMap<String, usize>,
    /// Points sent to the likelihood (model evaluations) in this stage.
    pub evaluations: usize,
    /// Batches sent to the likelihood in this stage (1 + one per MCMC step at most).
    pub batches: usize,
    /// Points sent to the likelihood's screen in this stage (delayed acceptance; 0 without).
    #[serde(default)]
    pub screenings: usize,
    /// Proposals the screen rejected, so that the likelihood never saw them (a subset of
    /// `screenings`; screen failures are counted in `failures` too).
    #[serde(default)]
    pub screened_out: usize,
    /// Distinct members of the population after the stage, divided by N.
    pub unique_fraction: f64,
    /// Wall-clock seconds the stage took (the only field that differs between identical runs).
    pub wall_seconds: f64,
}

/// Add one failure with `reason` to `reasons`, keeping at most [`MAX_FAILURE_REASONS`] keys.
pub fn count_failure(reasons: &mut BTreeMap<String, usize>, reason: &str) {
    if let Some(c) = reasons.get_mut(reason) {
        *c += 1;
    } else if reasons.len() < MAX_FAILURE_REASONS {
        reasons.insert(reason.to_string(), 1);
    } else {
        *reasons.entry(OTHER_REASONS.to_string()).or_insert(0) += 1;
    }
}

/// Sum failure reasons over stages (same cap).
pub fn merge_failure_reasons<'a>(
    maps: impl IntoIterator<Item = &'a BTreeMap<String, usize>>,
) -> BTreeMap<String, usize> {
    let mut total = BTreeMap::new();
    for map in maps {
        for (reason, count) in map {
            if let Some(c) = total.get_mut(reason) {
                *c += count;
            } else if total.len() < MAX_FAILURE_REASONS {
                total.insert(reason.clone(), *count);
            } else {
                *total.entry(OTHER_REASONS.to_string()).or_insert(0) += count;
            }
        }
    }
    total
}
