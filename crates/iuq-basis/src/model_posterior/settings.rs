//! The method's settings ([`ModelPosteriorSettings`]), its constants, and the members it runs
//! through the model first ([`selected_members`]).

use serde::{Deserialize, Serialize};

use iuq_core::random::stream;

use crate::error::{BasisError, Result};
use crate::member_selection::nested_selection;

/// A stage's weights whose CV is at most this are certified whatever their k̂: so nearly equal
/// (ESS/S ≥ 0.99) that their tail cannot carry the estimate. k̂ is a shape, blind to the
/// weights' spread: for a small step the weights exp(Δβ·r) ≈ 1 + Δβ·r keep the tail shape of r
/// itself, and a few members with a large r would hold k̂ up however small the step.
pub const NEARLY_EQUAL_CV: f64 = 0.1;

/// A correction whose posterior keeps less than this share of its population inside the range
/// (minimum to maximum) of some parameter over the batch it was fitted on is not made: most of
/// its mass would lie where no run informed the fit, and a second batch there is spent on the
/// fit's extrapolation (the stages go on from the first batch instead, exactly, at the price of
/// bridges). Parameter by parameter, not the joint box: a correct correction widening a narrow
/// surrogate posterior in every one of d parameters keeps about p^d inside the box when it
/// keeps p inside each range (in 10-D, 0.92 each and 0.43 jointly: refused, the stages bridged
/// from the first batch for 1,200–1,500 model evaluations where the correction and both
/// batches need 600), whereas an extrapolating fit leaves some range altogether.
pub const MIN_CORRECTED_WITHIN_BATCH: f64 = 0.5;

/// The smallest population: k̂ needs a tail of 5 weights, ⌈min(0.2·S, 3√S)⌉ ≥ 5 from S = 21.
pub const MIN_SAMPLES: usize = 25;

/// First stream stage of the model-posterior sampler (stage k uses `STREAM_BASE + k`; the
/// selection of the surrogate members uses `STREAM_BASE`).
pub const STREAM_BASE: u64 = iuq_core::random::stages::MODEL_POSTERIOR_BASE;

/// Settings of [`model_posterior`](super::model_posterior()).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelPosteriorSettings {
    /// Members of the surrogate population run through the model (the model posterior's sample
    /// size S).
    pub samples: usize,
    /// Seed of every random draw.
    pub seed: u64,
    /// The CV target γ of the first stage's step (BASIS's rule; 1 as in BASIS).
    pub cv_target: f64,
    /// The CV target of the stages after a bridge, whose population comes from short MCMC
    /// chains of resampled members and shows its tails less well than an independent sample of
    /// the surrogate's posterior, so that k̂ alone is not enough there (0.5; with 1 the
    /// bridged stds of a test problem came out 7 % narrow on average over seeds).
    pub bridge_cv_target: f64,
    /// Largest number of stages (each after the first costs a bridge of model runs).
    pub max_stages: usize,
    /// Corrections of the surrogate, 0 or 1 (one costs `samples` model evaluations): where the
    /// first batch's weights do not hold in one stage, the surrogate's log-likelihood is
    /// corrected by a quadratic fit of r and the corrected surrogate's posterior sampled anew;
    /// for a noisy model ([`Self::pseudo_marginal`]), where a permutation test finds the
    /// surrogate off, the step's k̂ does not hold or its spread ratio exceeds
    /// [`crate::spread_ratio::WIDER_THAN_PROPOSAL`], by the moment-matched log-ratio of
    /// [`crate::moment_matching`] (or, where that is refused, a defensive batch from a normal
    /// fitted to the first batch's weights, [`crate::defensive_normal`], or from the
    /// surrogate's posterior tempered where no such normal can be drawn,
    /// [`crate::defensive_tempering`]), both batches then weighed as one mixture sample.
    pub corrections: usize,
    /// Delayed-acceptance moves per member after a bridging stage.
    pub moves: usize,
    /// Surrogate Metropolis steps in each move's subchain.
    pub subchain: usize,
    /// Proposal scale β of the surrogate steps (covariance β²·Cov_w(θ)).
    pub scale: f64,
    /// Smallest tempering step.
    pub min_step: f64,
    /// The probabilities of the reported quantiles.
    pub probabilities: Vec<f64>,
    /// The model's log-likelihood is a noisy estimate: a chaotic or stochastic model, whose
    /// output moves by more than its own reported spread under a negligible change of the
    /// parameters, so that a run's likelihood L̂ is one draw whose mean over the model's
    /// irregular part is the likelihood L (pseudo-marginal; Andrieu & Roberts 2009). Importance
    /// weights L̂/L_s stay unbiased, so the estimate is one full step certified by k̂ (or
    /// nearly equal weights), after a moment-matched correction (or a defensive batch from a
    /// normal fitted to the weights, or from the surrogate's posterior tempered where no such
    /// normal can be drawn) where the first batch shows the surrogate off
    /// ([`crate::pseudo_marginal`]); no quadratic fit and no bridge, whose
    /// fits and Metropolis ratios assume a reproducible r (a noisy r makes the chains stick
    /// where a lucky run landed).
    #[serde(default)]
    pub pseudo_marginal: bool,
}

impl Default for ModelPosteriorSettings {
    fn default() -> Self {
        Self {
            samples: 300,
            seed: 1,
            cv_target: 1.0,
            bridge_cv_target: 0.5,
            max_stages: 6,
            corrections: 1,
            moves: 1,
            subchain: 20,
            scale: 0.4,
            min_step: 1e-4,
            probabilities: vec![0.025, 0.05, 0.25, 0.5, 0.75, 0.95, 0.975],
            pseudo_marginal: false,
        }
    }
}

impl ModelPosteriorSettings {
    /// Refuse settings outside their ranges ([`BasisError::InvalidSettings`], named as the keys).
    pub fn check(&self) -> Result<()> {
        let bad = |setting: &'static str, reason: &str| {
            Err(BasisError::InvalidSettings {
                setting,
                reason: reason.to_string(),
            })
        };
        if self.samples < MIN_SAMPLES {
            return bad(
                "samples",
                &format!("must be at least {MIN_SAMPLES} (k̂ needs a tail of 5 weights)"),
            );
        }
        if !(self.cv_target.is_finite() && self.cv_target > 0.0) {
            return bad("cv_target", "must be a positive number");
        }
        if !(self.bridge_cv_target.is_finite() && self.bridge_cv_target > 0.0) {
            return bad("bridge_cv_target", "must be a positive number");
        }
        if self.max_stages == 0 {
            return bad("max_stages", "must be at least 1");
        }
        if self.corrections > 1 {
            return bad("corrections", "must be 0 or 1");
        }
        if self.moves == 0 {
            return bad("moves", "must be at least 1");
        }
        if self.subchain == 0 {
            return bad("subchain", "must be at least 1");
        }
        if !(self.scale.is_finite() && self.scale > 0.0) {
            return bad("scale", "must be a positive number");
        }
        if !(self.min_step.is_finite() && self.min_step > 0.0 && self.min_step < 1.0) {
            return bad("min_step", "must lie in (0, 1)");
        }
        if self.probabilities.iter().any(|p| !(0.0..=1.0).contains(p)) {
            return bad("probabilities", "must lie in [0, 1]");
        }
        Ok(())
    }
}

/// The indices (ascending) of the members of a surrogate population of `population_size` that
/// [`model_posterior`](super::model_posterior()) runs through the model first: `min(samples, population_size)` of them,
/// drawn without replacement by `seed`, nested in `samples` ([`crate::member_selection`]: a
/// larger `samples` keeps these members and adds others, so their model runs are reused). A
/// caller that probes the model at the same members (e.g. whether its output is reproducible)
/// gets the points the method will request anyway.
pub fn selected_members(population_size: usize, settings: &ModelPosteriorSettings) -> Vec<usize> {
    let s = settings.samples.min(population_size);
    nested_selection(
        &mut stream(settings.seed, STREAM_BASE, 0),
        population_size,
        s,
    )
}
