//! The adaptive engine's loop as a state and a step, in argmin's shape: an [`EngineState`]
//! (serialisable), [`AdaptiveEngine::judge`] and [`AdaptiveEngine::step`] once per round, and an
//! [`iuq_core::Observer`] of [`RoundEvent`]s returning [`iuq_core::Control`].
//!
//! A round, driven by the caller (who owns the model runs, the surrogate fits and the files):
//!
//! 1. measure the round: fit the surrogate on every run so far, sample its posterior with R
//!    replicate samplers as [`EngineState::sampling`] says, and measure the surrogate's error
//!    ε ([`crate::moment_error`]), u ([`crate::acquisition`]) and the check of the sampler
//!    ([`mod@crate::sampler_agreement`]) — a [`RoundReading`];
//! 2. [`AdaptiveEngine::judge`] the reading against the previous round: the shift of the moments
//!    and, with [`StoppingRule::Distribution`], the distance between the two posteriors
//!    ([`mod@crate::posterior_distance`]), each beyond the samplers' noise, and ε
//!    ([`crate::convergence`]); the judgement says whether to stop and why;
//! 3. where it does not stop, choose the round's runs ([`crate::batch`],
//!    [`crate::moment_acquisition`]) and make them;
//! 4. [`AdaptiveEngine::step`] the state: the reading becomes the previous round; the next
//!    round samples the smaller exploring population while the posterior is still far from
//!    where it settles (shift, distance or ε above [`FAR`] tolerances: early rounds, whose
//!    posterior moves by stds anyway, need no precise sample), else at least the full
//!    population, which doubles where the samplers' noise left the shift unresolved; the chains
//!    mix harder where the check of the sampler failed, the candidates widen where no run was
//!    worth making.
//!
//! The engine stops when the rule holds (converged), at `max_runs`, at `max_rounds`, when the
//! sampler check still fails at the strongest mixing, or when no candidate run is worth making
//! among the widest candidates — each with a reason a user can act on.
//!
//! ```
//! use iuq_adaptive::engine::{AdaptiveEngine, EngineSettings, Next, RoundReading};
//! use iuq_adaptive::{ConvergenceCriterion, PosteriorMoments};
//!
//! let engine = AdaptiveEngine::new(EngineSettings::new(ConvergenceCriterion::default(), 200, 30, 2000))?;
//! let mut state = engine.start(1, None);
//! // Two rounds whose posteriors agree within the samplers' noise, ε small: converged.
//! for _ in 0..2 {
//!     let reading = RoundReading {
//!         moments: PosteriorMoments {
//!             mean: vec![1.0],
//!             std: vec![0.5],
//!             mean_error: vec![0.005],
//!             std_error: vec![0.005],
//!         },
//!         log_likelihood_std: 0.01,
//!         surrogate_error: 0.02,
//!         boundary_wanted: false,
//!         sampler_agreement: None,
//!         populations: None,
//!         runs: 20,
//!     };
//!     let judgement = engine.judge(&state, &reading)?;
//!     let runs = if judgement.stop.is_some() { 0 } else { 2 };
//!     if let Next::Stop = engine.step(&mut state, reading, &judgement, runs) {
//!         break;
//!     }
//! }
//! assert!(state.converged, "{:?}", state.stop_reason);
//! # Ok::<(), iuq_adaptive::AdaptiveError>(())
//! ```

use serde::{Deserialize, Serialize};

use crate::convergence::{ConvergenceCriterion, PosteriorMoments, RoundAssessment};
use crate::error::Result;
use crate::posterior_distance::{PosteriorDistance, posterior_distance};
use crate::sampler_agreement::SamplerAgreement;

/// How far from settled a round's posterior is, in tolerances, for the next round to sample with
/// [`EngineSettings::exploring_samples`]: its shift or distance from the round before, or the
/// surrogate's error ε, above `FAR × tolerance` (1 posterior std at the default tolerance 0.1).
/// Such a round's posterior moves by more than the noise of a population a quarter the size
/// (twice the noise, so 0.2 std at most where the full population's is 0.1) could hide, so the
/// smaller population decides the same runs.
pub const FAR: f64 = 10.0;

/// The most burn-in steps per stage of a round sampled with
/// [`EngineSettings::exploring_samples`] (the chains' own `max_burn_in` where it is lower): such
/// a population only has to locate a posterior that will move by more than a posterior std, and
/// on an early surrogate's posterior (curved, often of several modes) the chains reach the
/// correlation target of the sampler's adaptive mixing in no number of steps, so every stage ran
/// its whole `max_burn_in` (50) at 7–35 % acceptance. Each level of stronger mixing doubles it,
/// so that the check's replicates still mix harder than the others.
pub const EXPLORING_MAX_BURN_IN: usize = 20;

/// How many times the candidates may widen (×[`CANDIDATE_WIDENING`] each) when no run is worth
/// making, before the engine gives up with the reason.
pub const CANDIDATE_WIDENING: usize = 4;

/// When the next round's replicates sample twice as many (up to `max_samples`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MoreSamples {
    /// `"when-noisy"`: whenever the samplers' noise on the shift reaches the tolerance.
    WhenNoisy,
    /// `"when-resolving"`: only once the surrogate's error is below the tolerance, so that the
    /// samplers' noise is what stands between the round and convergence. Early rounds, whose
    /// posterior moves by many stds anyway, keep their population (and their cost).
    WhenResolving,
}

/// What the stopping rule compares between successive rounds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StoppingRule {
    /// `"distribution"`: the moments' shift and the sliced distance between the two posteriors
    /// ([`mod@crate::posterior_distance`]), both beyond the samplers' noise. A round whose previous
    /// round's samples are unknown (read back from a store that did not record them) is judged
    /// on its moments, and says so ([`Judgement::distance`] is `None`).
    Distribution,
    /// `"moments"`: each parameter's posterior mean and std alone (the rule of the shipped
    /// red-cell studies).
    Moments,
}

/// How a round samples its posterior and chooses its candidates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct RoundSampling {
    /// Population of each replicate sampler.
    pub samples: usize,
    /// Distinct posterior samples scored as candidates for new runs.
    pub candidates: usize,
    /// How much harder than set the chains mix (the check's replicates one more).
    pub mixing_level: u32,
}

impl RoundSampling {
    /// The most burn-in steps a stage of a replicate mixing `harder` levels above the round's
    /// own may take: [`EXPLORING_MAX_BURN_IN`], doubled per level of mixing, where the round
    /// samples a smaller population than `full_samples` (an exploring round); `None` (the
    /// sampler's own) where it samples in full.
    pub fn burn_in_cap(&self, full_samples: usize, harder: u32) -> Option<usize> {
        (self.samples < full_samples).then(|| EXPLORING_MAX_BURN_IN << (self.mixing_level + harder))
    }
}

/// The settings that decide the loop.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EngineSettings {
    /// The tolerances.
    pub criterion: ConvergenceCriterion,
    /// What the rule compares.
    pub stopping_rule: StoppingRule,
    /// Model runs in all at most.
    pub max_runs: usize,
    /// Rounds at most.
    pub max_rounds: usize,
    /// Each replicate's population once the posterior has settled within [`FAR`] tolerances.
    pub samples: usize,
    /// Each replicate's population while the posterior is still far from where it settles
    /// (module docs): the first round, and every round after one whose shift, distance or
    /// surrogate error exceeded [`FAR`] tolerances; those rounds also leave the mixing as it is
    /// when the sampler check fails. Equal to `samples`: every round samples `samples` and a
    /// failing check always mixes harder (the engine before 2026-12).
    pub exploring_samples: usize,
    /// The population a replicate may grow to.
    pub max_samples: usize,
    /// Candidates scored at first.
    pub candidates: usize,
    /// When the population doubles.
    pub more_samples: MoreSamples,
    /// The strongest mixing level the sampler check may ask for.
    pub max_mixing_level: u32,
    /// Whether rounds make runs at all (boundary runs are due only then).
    pub makes_runs: bool,
}

impl EngineSettings {
    /// The defaults beside the given criterion and limits: the distribution rule, `samples`
    /// from the first round (no smaller exploring population), up to 16 × `samples`, 1000
    /// candidates, more samples when noisy, mixing up to level 3, runs made.
    pub fn new(
        criterion: ConvergenceCriterion,
        max_runs: usize,
        max_rounds: usize,
        samples: usize,
    ) -> Self {
        Self {
            criterion,
            stopping_rule: StoppingRule::Distribution,
            max_runs,
            max_rounds,
            samples,
            exploring_samples: samples,
            max_samples: 16 * samples,
            candidates: 1000,
            more_samples: MoreSamples::WhenNoisy,
            max_mixing_level: 3,
            makes_runs: true,
        }
    }
}

/// Where the loop stands between rounds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EngineState {
    /// The round to measure next, from 1.
    pub round: usize,
    /// How it samples.
    pub sampling: RoundSampling,
    /// The previous round's moments (`None` before the first).
    pub previous: Option<PosteriorMoments>,
    /// The previous round's samples per replicate, for the distance (`None` where unknown).
    #[serde(skip)]
    pub previous_populations: Option<Vec<Vec<Vec<f64>>>>,
    /// Whether the loop stopped converged.
    pub converged: bool,
    /// Why the loop stopped (`None` while it goes on).
    pub stop_reason: Option<String>,
}

/// What one round measured, as the engine judges it.
#[derive(Debug, Clone, PartialEq)]
pub struct RoundReading<'a> {
    /// The pooled posterior moments with their Monte Carlo errors.
    pub moments: PosteriorMoments,
    /// u, the posterior mean of the surrogate's std of the log-likelihood (nats).
    pub log_likelihood_std: f64,
    /// ε, the surrogate's largest error of a posterior mean or std, in posterior stds.
    pub surrogate_error: f64,
    /// Some failure region wants boundary runs.
    pub boundary_wanted: bool,
    /// The check of the sampler (`None`: one replicate).
    pub sampler_agreement: Option<&'a SamplerAgreement>,
    /// The round's samples per replicate (`None` where unknown).
    pub populations: Option<Vec<Vec<Vec<f64>>>>,
    /// Model runs made before this round's new runs.
    pub runs: usize,
}

/// The judgement of one round.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Judgement {
    /// The moments' shift, noise and ε against the tolerance.
    pub assessment: RoundAssessment,
    /// The distance to the previous round's posterior (`None`: the first round, the moments
    /// rule, or samples unknown).
    pub distance: Option<PosteriorDistance>,
    /// Every criterion held and the sampler check passed.
    pub converged: bool,
    /// Boundary runs are due (a failure region wants them and the surrogate is sure).
    pub boundary_due: bool,
    /// The sampler check failed.
    pub sampler_disagrees: bool,
    /// How far the replicates that mixed harder lie from the others, in posterior stds (0
    /// without the check).
    pub sampler_disagreement: f64,
    /// Why the loop stops at this round (`None`: it chooses runs).
    pub stop: Option<String>,
}

impl Judgement {
    /// The largest noise the round's shift is judged against: the moments' and the distance's.
    pub fn noise(&self) -> Option<f64> {
        let distance = self.distance.as_ref().map(|d| d.noise);
        match (self.assessment.noise, distance) {
            (Some(a), Some(b)) => Some(a.max(b)),
            (a, b) => a.or(b),
        }
    }
}

/// What the loop does after a round.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Next {
    /// Measure the next round.
    Continue,
    /// The loop has stopped ([`EngineState::stop_reason`] says why).
    Stop,
}

/// What the engine tells its observer after each round.
#[derive(Debug, Clone, PartialEq)]
pub struct RoundEvent<'a> {
    /// The round just finished.
    pub round: usize,
    /// Its judgement.
    pub judgement: &'a Judgement,
    /// The runs it chose.
    pub new_runs: usize,
    /// The state after the step.
    pub state: &'a EngineState,
}

/// The adaptive engine's decisions (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdaptiveEngine {
    settings: EngineSettings,
}

impl AdaptiveEngine {
    /// An engine with checked settings.
    ///
    /// # Errors
    /// A tolerance that is not positive and finite.
    pub fn new(settings: EngineSettings) -> Result<Self> {
        settings.criterion.check()?;
        Ok(Self { settings })
    }

    /// The settings.
    pub fn settings(&self) -> &EngineSettings {
        &self.settings
    }

    /// The state before round `round`: from scratch, or going on after an earlier loop with its
    /// last round's moments and sampling (a failed posterior check trained on). A round past
    /// `max_rounds` starts stopped.
    pub fn start(
        &self,
        round: usize,
        earlier: Option<(PosteriorMoments, RoundSampling)>,
    ) -> EngineState {
        let (previous, sampling) = match earlier {
            Some((moments, sampling)) => (Some(moments), sampling),
            None => (
                None,
                RoundSampling {
                    samples: self.settings.exploring_samples,
                    candidates: self.settings.candidates,
                    mixing_level: 0,
                },
            ),
        };
        let max_rounds = self.settings.max_rounds;
        EngineState {
            round,
            sampling,
            previous,
            previous_populations: None,
            converged: false,
            stop_reason: (round > max_rounds).then(|| format!("reached max_rounds = {max_rounds}")),
        }
    }

    /// Judge a round against the previous one (module docs, step 2).
    ///
    /// # Errors
    /// Moments or samples of different lengths.
    pub fn judge(&self, state: &EngineState, reading: &RoundReading<'_>) -> Result<Judgement> {
        let s = &self.settings;
        let tolerance = s.criterion.tolerance;
        let assessment = s.criterion.assess(
            state.previous.as_ref(),
            &reading.moments,
            reading.log_likelihood_std,
            reading.surrogate_error,
        )?;
        let distance = match (
            s.stopping_rule,
            &state.previous_populations,
            &reading.populations,
        ) {
            (StoppingRule::Distribution, Some(before), Some(now)) => {
                Some(posterior_distance(before, now)?)
            }
            _ => None,
        };
        let distance_holds = distance
            .as_ref()
            .is_none_or(|d| d.distance < tolerance && d.noise < tolerance);
        let sampler_disagrees = reading.sampler_agreement.is_some_and(|a| a.disagrees);
        let sampler_disagreement = reading.sampler_agreement.map_or(0.0, |a| a.disagreement);
        let boundary_due = reading.boundary_wanted
            && reading.log_likelihood_std < s.criterion.log_likelihood_tolerance
            && s.makes_runs;
        let converged = assessment.converged && distance_holds && !sampler_disagrees;
        let stop = if converged && !boundary_due {
            Some("converged".to_string())
        } else if reading.runs >= s.max_runs {
            Some(format!("reached max_runs = {}", s.max_runs))
        } else if sampler_disagrees
            && state.sampling.mixing_level >= s.max_mixing_level
            && state.sampling.samples >= s.samples
        {
            Some(format!(
                "the surrogate posterior still depends on how it is sampled at the strongest mixing (the replicates that mixed harder differ by {sampler_disagreement:.3} posterior stds): raise `samples` of `[surrogate] adaptive` or of `[sampler]`, or set `[sampler] correlation` lower"
            ))
        } else {
            None
        };
        Ok(Judgement {
            assessment,
            distance,
            converged,
            boundary_due,
            sampler_disagrees,
            sampler_disagreement,
            stop,
        })
    }

    /// Move the state past a judged round that chose `new_runs` runs (module docs, step 4).
    /// The round becomes the previous one; where the loop stops, [`EngineState::round`] stays
    /// at the round it stopped at.
    pub fn step(
        &self,
        state: &mut EngineState,
        reading: RoundReading<'_>,
        judgement: &Judgement,
        new_runs: usize,
    ) -> Next {
        let s = &self.settings;
        let tolerance = s.criterion.tolerance;
        let moments = reading.moments;
        let populations = reading.populations;
        let u = reading.log_likelihood_std;
        let record = |state: &mut EngineState| {
            state.previous = Some(moments);
            state.previous_populations = populations;
        };
        if let Some(reason) = &judgement.stop {
            state.converged = judgement.converged && reason == "converged";
            state.stop_reason = Some(reason.clone());
            record(state);
            return Next::Stop;
        }
        // Far from settled, the next round explores with the smaller population, and a sampler
        // check that fails there (a posterior of the early surrogates, often of several modes,
        // sampled by few chains) does not make the chains mix harder: its runs are chosen the
        // same either way, and the check decides once the posterior has settled. Without a
        // smaller exploring population, every round is sampled and checked as before exploring
        // rounds existed (the shipped studies' stores were recorded so).
        // Nor does a check of a round sampled with the exploring population: a smaller
        // population's own bias is not the sampler's at the population it is set to.
        let exploring = s.exploring_samples < s.samples;
        let far = exploring && Self::far_from_settled(judgement, tolerance);
        let checked_in_full = state.sampling.samples >= s.samples;
        if judgement.sampler_disagrees && checked_in_full && !far {
            state.sampling.mixing_level = (state.sampling.mixing_level + 1).min(s.max_mixing_level);
        }
        // With exploring rounds, a settled round whose samplers' noise still reaches the
        // tolerance samples again with twice the population while it can grow, even where no
        // candidate run is worth making (the noise, not the surrogate, keeps the rule from
        // holding).
        // With `WhenResolving`, only once the surrogate's error no longer keeps the round from
        // converging.
        let resolving = match s.more_samples {
            MoreSamples::WhenNoisy => true,
            MoreSamples::WhenResolving => s
                .criterion
                .surrogate_error_holds(judgement.assessment.surrogate_error),
        };
        let noisy = judgement.noise().is_some_and(|n| n >= tolerance);
        let can_resolve_noise =
            exploring && noisy && resolving && !far && state.sampling.samples < s.max_samples;
        state.sampling.samples = if far {
            s.exploring_samples
        } else {
            state.sampling.samples.max(s.samples)
        };
        let no_candidate = new_runs == 0;
        let widest = s.candidates * CANDIDATE_WIDENING * CANDIDATE_WIDENING;
        if no_candidate && !judgement.sampler_disagrees && !can_resolve_noise {
            if state.sampling.candidates >= widest {
                state.stop_reason = Some(self.no_candidate_reason(state, u, judgement));
                record(state);
                return Next::Stop;
            }
            // Nothing to run is no evidence of convergence (the rule did not hold): look among
            // more and rarer points of the posterior, from a larger population.
            state.sampling.candidates =
                (state.sampling.candidates * CANDIDATE_WIDENING).min(widest);
            state.sampling.samples = (2 * state.sampling.samples).min(s.max_samples);
        } else {
            // The shift cannot be told from the samplers' noise: sample more next round.
            if resolving && noisy {
                state.sampling.samples = (2 * state.sampling.samples).min(s.max_samples);
            }
        }
        record(state);
        state.round += 1;
        if state.round > s.max_rounds {
            state.stop_reason = Some(format!("reached max_rounds = {}", s.max_rounds));
            return Next::Stop;
        }
        Next::Continue
    }

    /// Whether the judged round's posterior is still far from where it settles: its shift,
    /// its distance or ε above [`FAR`] tolerances.
    fn far_from_settled(judgement: &Judgement, tolerance: f64) -> bool {
        let far = FAR * tolerance;
        judgement.assessment.surrogate_error > far
            || judgement.assessment.shift.is_some_and(|v| v > far)
            || judgement
                .distance
                .as_ref()
                .is_some_and(|d| d.distance > far)
    }

    fn no_candidate_reason(&self, state: &EngineState, u: f64, judgement: &Judgement) -> String {
        let shown = |v: Option<f64>| v.map_or("-".to_string(), |s| format!("{s:.3}"));
        format!(
            "no candidate run is worth making among {} candidates, although the rule does not hold (shift {}, distance {}, sampler noise {}, surrogate error {:.3} posterior stds, counted {} times, against the tolerance {}; the surrogate's log-likelihood std over the posterior is {u:.3} nats): the surrogate's remaining error lies where no run can reduce it by the minimum worth a run; lower `log_likelihood_tolerance` to let smaller gains count, or raise `tolerance` if this error is acceptable",
            state.sampling.candidates,
            shown(judgement.assessment.shift),
            shown(judgement.distance.as_ref().map(|d| d.distance)),
            shown(judgement.noise()),
            judgement.assessment.surrogate_error,
            self.settings.criterion.surrogate_error_multiple,
            self.settings.criterion.tolerance,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_an_exploring_round_caps_its_burn_in_doubled_per_level_of_mixing() {
        let exploring = RoundSampling {
            samples: 500,
            candidates: 1000,
            mixing_level: 1,
        };
        assert_eq!(
            exploring.burn_in_cap(2000, 0),
            Some(2 * EXPLORING_MAX_BURN_IN)
        );
        assert_eq!(
            exploring.burn_in_cap(2000, 1),
            Some(4 * EXPLORING_MAX_BURN_IN)
        );
        assert_eq!(exploring.burn_in_cap(500, 0), None);
    }

    fn moments(mean: f64, error: f64) -> PosteriorMoments {
        PosteriorMoments {
            mean: vec![mean, 0.0],
            std: vec![1.0, 1.0],
            mean_error: vec![error; 2],
            std_error: vec![error; 2],
        }
    }

    fn reading(mean: f64, error: f64, epsilon: f64, runs: usize) -> RoundReading<'static> {
        RoundReading {
            moments: moments(mean, error),
            log_likelihood_std: 0.01,
            surrogate_error: epsilon,
            boundary_wanted: false,
            sampler_agreement: None,
            populations: None,
            runs,
        }
    }

    fn engine(settings: impl FnOnce(&mut EngineSettings)) -> AdaptiveEngine {
        let mut s = EngineSettings::new(ConvergenceCriterion::default(), 100, 10, 500);
        settings(&mut s);
        AdaptiveEngine::new(s).unwrap()
    }

    /// Drive the engine through `readings`, `runs` new runs a round; returns the state.
    fn drive(
        engine: &AdaptiveEngine,
        readings: Vec<RoundReading<'static>>,
        runs: usize,
    ) -> EngineState {
        let mut state = engine.start(1, None);
        for r in readings {
            let j = engine.judge(&state, &r).unwrap();
            let chosen = if j.stop.is_some() { 0 } else { runs };
            if engine.step(&mut state, r, &j, chosen) == Next::Stop {
                break;
            }
        }
        state
    }

    #[test]
    fn a_posterior_that_stands_still_with_a_small_surrogate_error_converges() {
        let e = engine(|_| {});
        let s = drive(
            &e,
            vec![reading(0.0, 0.01, 0.04, 10), reading(0.02, 0.01, 0.04, 12)],
            2,
        );
        assert!(s.converged);
        assert_eq!(s.stop_reason.as_deref(), Some("converged"));
        assert_eq!(s.round, 2, "the stop leaves the round where it stopped");
    }

    #[test]
    fn a_noisy_shift_doubles_the_population_and_a_moving_one_does_not_converge() {
        let e = engine(|_| {});
        // Noise 2·√2·0.05 = 0.14 > 0.1: unresolved, the population doubles.
        let s = drive(
            &e,
            vec![reading(0.0, 0.05, 0.04, 10), reading(0.0, 0.05, 0.04, 12)],
            2,
        );
        assert!(!s.converged);
        // The first round has nothing to compare with (no noise on a shift): one doubling.
        assert_eq!(
            s.sampling.samples, 1000,
            "doubled after the noisy round: {s:?}"
        );
        let s = drive(
            &e,
            vec![reading(0.0, 0.01, 0.04, 10), reading(0.5, 0.01, 0.04, 12)],
            2,
        );
        assert!(!s.converged && s.stop_reason.is_none());
    }

    #[test]
    fn with_when_resolving_the_population_waits_for_the_surrogate() {
        let e = engine(|s| s.more_samples = MoreSamples::WhenResolving);
        let s = drive(
            &e,
            vec![reading(0.0, 0.05, 0.5, 10), reading(0.0, 0.05, 0.5, 12)],
            2,
        );
        assert_eq!(s.sampling.samples, 500);
        // ε = 0.07 is under the tolerance but counts twice: it still keeps the round from
        // converging, so the population still waits.
        let s = drive(
            &e,
            vec![reading(0.0, 0.05, 0.07, 10), reading(0.0, 0.05, 0.07, 12)],
            2,
        );
        assert_eq!(s.sampling.samples, 500);
        let s = drive(
            &e,
            vec![reading(0.0, 0.05, 0.04, 10), reading(0.0, 0.05, 0.04, 12)],
            2,
        );
        assert_eq!(s.sampling.samples, 1000);
    }

    #[test]
    fn rounds_far_from_settled_sample_the_exploring_population() {
        let e = engine(|s| s.exploring_samples = 125);
        assert_eq!(
            e.start(1, None).sampling.samples,
            125,
            "the first round explores"
        );
        // ε = 2 posterior stds (20 tolerances): still exploring.
        let s = drive(&e, vec![reading(0.0, 0.01, 2.0, 10)], 2);
        assert_eq!(s.sampling.samples, 125);
        // A shift of 3 stds with ε small: still exploring.
        let s = drive(
            &e,
            vec![reading(0.0, 0.01, 0.04, 10), reading(3.0, 0.01, 0.04, 12)],
            2,
        );
        assert_eq!(s.sampling.samples, 125);
        // A shift of 0.5 std (5 tolerances), ε small: the full population.
        let s = drive(
            &e,
            vec![reading(0.0, 0.01, 2.0, 10), reading(0.5, 0.01, 0.04, 12)],
            2,
        );
        assert_eq!(s.sampling.samples, 500);
        // Moving far again after settling: back to exploring.
        let s = drive(
            &e,
            vec![
                reading(0.0, 0.01, 0.04, 10),
                reading(0.3, 0.01, 0.04, 12),
                reading(5.0, 0.01, 0.04, 14),
            ],
            2,
        );
        assert_eq!(s.sampling.samples, 125);
    }

    #[test]
    fn the_limits_stop_with_their_reason() {
        let e = engine(|_| {});
        let s = drive(
            &e,
            vec![reading(0.0, 0.01, 0.5, 10), reading(1.0, 0.01, 0.5, 100)],
            2,
        );
        assert_eq!(s.stop_reason.as_deref(), Some("reached max_runs = 100"));
        let e = engine(|s| s.max_rounds = 2);
        let s = drive(
            &e,
            vec![reading(0.0, 0.01, 0.5, 10), reading(1.0, 0.01, 0.5, 12)],
            2,
        );
        assert_eq!(s.stop_reason.as_deref(), Some("reached max_rounds = 2"));
        assert!(!s.converged);
    }

    #[test]
    fn no_run_worth_making_widens_the_candidates_then_says_why() {
        let e = engine(|_| {});
        let readings = (0..4).map(|k| reading(k as f64, 0.01, 0.5, 10)).collect();
        let s = drive(&e, readings, 0);
        assert_eq!(s.sampling.candidates, 16_000);
        let reason = s.stop_reason.unwrap();
        assert!(
            reason.starts_with("no candidate run is worth making among 16000"),
            "{reason}"
        );
        assert!(!s.converged);
    }

    #[test]
    fn a_posterior_that_moved_as_a_distribution_is_not_converged_although_its_moments_stand() {
        // Two rounds with the same marginal moments, but the second one's correlation flipped:
        // x and y = ±x·0.9 + noise. The moments rule converges; the distance rule does not.
        let population = |sign: f64, seed: u64| -> Vec<Vec<Vec<f64>>> {
            use rand::SeedableRng;
            use rand_distr::{Distribution, StandardNormal};
            let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(seed);
            (0..4)
                .map(|_| {
                    (0..2000)
                        .map(|_| {
                            let (a, b): (f64, f64) = (
                                StandardNormal.sample(&mut rng),
                                StandardNormal.sample(&mut rng),
                            );
                            vec![a, sign * 0.9 * a + (1.0f64 - 0.81).sqrt() * b]
                        })
                        .collect()
                })
                .collect()
        };
        let with = |sign: f64, seed: u64| {
            let mut r = reading(0.0, 0.01, 0.04, 10);
            r.populations = Some(population(sign, seed));
            r
        };
        let rule = |rule: StoppingRule| {
            let e = engine(|s| s.stopping_rule = rule);
            drive(&e, vec![with(1.0, 1), with(-1.0, 2)], 2)
        };
        assert!(rule(StoppingRule::Moments).converged);
        let s = rule(StoppingRule::Distribution);
        assert!(!s.converged && s.stop_reason.is_none(), "{s:?}");
        // The same correlation sampled twice converges by either rule.
        let e = engine(|_| {});
        assert!(drive(&e, vec![with(1.0, 3), with(1.0, 4)], 2).converged);
    }

    #[test]
    fn a_failing_sampler_check_mixes_harder_and_stops_at_the_strongest_level() {
        let agreement = SamplerAgreement {
            disagreement: 0.3,
            noise: 0.01,
            disagrees: true,
        };
        let e = engine(|s| s.max_mixing_level = 1);
        let mut state = e.start(1, None);
        let mut stopped = None;
        for k in 0..4 {
            let mut r = reading(0.0, 0.01, 0.05, 10 + k);
            r.sampler_agreement = Some(&agreement);
            let j = e.judge(&state, &r).unwrap();
            assert!(!j.converged);
            if e.step(&mut state, r, &j, 2) == Next::Stop {
                stopped = state.stop_reason.clone();
                break;
            }
        }
        assert_eq!(state.sampling.mixing_level, 1);
        assert!(stopped.unwrap().contains("strongest mixing"));
        // Far from settled (ε = 2 posterior stds), with a smaller exploring population, the
        // same check leaves the mixing as it is; without one it mixes harder as before.
        for (exploring, level) in [(125, 0), (500, 1)] {
            let e = engine(|s| {
                s.max_mixing_level = 3;
                s.exploring_samples = exploring;
            });
            let mut state = e.start(1, None);
            let mut r = reading(0.0, 0.01, 2.0, 10);
            r.sampler_agreement = Some(&agreement);
            let j = e.judge(&state, &r).unwrap();
            assert_eq!(e.step(&mut state, r, &j, 2), Next::Continue);
            assert_eq!(state.sampling.mixing_level, level, "exploring {exploring}");
        }
        // Settled (ε small) but checked on the first round's exploring population: the next
        // round samples in full and the mixing stays.
        let e = engine(|s| s.exploring_samples = 125);
        let mut state = e.start(1, None);
        let mut r = reading(0.0, 0.01, 0.04, 10);
        r.sampler_agreement = Some(&agreement);
        let j = e.judge(&state, &r).unwrap();
        assert_eq!(e.step(&mut state, r, &j, 2), Next::Continue);
        assert_eq!(
            (state.sampling.mixing_level, state.sampling.samples),
            (0, 500)
        );
    }

    #[test]
    fn with_exploring_rounds_a_noisy_settled_round_samples_more_before_the_loop_stops() {
        // Settled (shift 0, ε 0.05) but every round's noise 2·√2·0.05 = 0.14 reaches the
        // tolerance 0.1, and no candidate run is worth making: the population doubles round by
        // round to `max_samples` among as many candidates, the mixing left as it is; only then
        // does the loop look among more candidates and stop for want of one.
        let e = engine(|s| s.exploring_samples = 125);
        let max_samples = e.settings.max_samples;
        let mut state = e.start(1, None);
        let mut trace = Vec::new();
        for _ in 0..30 {
            let r = reading(0.0, 0.05, 0.04, 10);
            let j = e.judge(&state, &r).unwrap();
            trace.push((state.sampling.samples, state.sampling.candidates));
            if e.step(&mut state, r, &j, 0) == Next::Stop {
                break;
            }
        }
        let reason = state.stop_reason.clone().unwrap_or_default();
        assert!(
            reason.starts_with("no candidate run"),
            "{reason}: {trace:?}"
        );
        assert_eq!(state.sampling.samples, max_samples, "{trace:?}");
        assert_eq!(state.sampling.mixing_level, 0, "{trace:?}");
        // (population, candidates) of each round: the first has no shift to be noisy about,
        // so it widens the candidates as before; then the population doubles among 4000
        // candidates up to `max_samples` (8000 here), and only then do they widen again.
        assert_eq!(
            trace,
            [
                (125, 1000),
                (1000, 4000),
                (2000, 4000),
                (4000, 4000),
                (8000, 4000),
                (8000, 16000)
            ],
        );
        // Without exploring rounds the loop widens its candidates at once, as before.
        let e = engine(|_| {});
        let mut state = e.start(1, None);
        let r = reading(0.0, 0.05, 0.04, 10);
        let j = e.judge(&state, &r).unwrap();
        e.step(&mut state, r, &j, 0);
        assert_eq!(state.sampling.candidates, 4 * e.settings.candidates);
    }
}
