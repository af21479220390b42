//! The surrogate of a study's model: one GP per data point, trained on the successful training
//! runs that inform it (or a reduced basis of the whole curve, [`super::emulator`]), and — where
//! runs have failed — one failure classifier per run group (`iuq_gp::FailureClassifier`),
//! trained on every run of the group.
//!
//! As a [`Model`] of θ ([`Surrogate`]), it returns the emulator's means with its predictive stds
//! as the computational std, and *fails* where a classifier says the model is more likely than not
//! to give no answer (p_fail > ½): the posterior then has no mass there, BASIS counts the
//! proposals as failures, and the adaptive engine places no run there.

use iuq_core::{EvaluationFailure, Model, Outcome, ParameterSpace};
use iuq_gp::{
    CheckedFitOptions, ClassifierOptions, FailureClassifier, FitOptions, GaussianProcess, GpBank,
    MultiFidelityBank, MultiFidelityGp, PointRuns, ReducedBasis, ReducedBasisOptions,
    fit_shared_discrepancy_with,
};

use rayon::prelude::*;

use super::emulator::{Emulator, ReducedBasisSettings};
use super::low_fidelity::LowFidelity;
use super::model_runs::ModelRuns;
use super::run_groups::{Curves, GroupRuns, OutputRuns};
use crate::error::{Context, Result, StudyError};

/// The probability of failure above which the surrogate gives no answer.
pub const FAILURE_THRESHOLD: f64 = 0.5;

/// How the surrogate emulates the outputs.
#[derive(Debug, Clone, PartialEq)]
pub enum Emulation {
    /// One GP per data point.
    PerOutput,
    /// A reduced basis of the whole curve, each data row's output divided by `scale` (the data's
    /// measurement stds, when the data has them) before the principal components are taken.
    ReducedBasis {
        /// The basis's settings.
        settings: ReducedBasisSettings,
        /// Per data row, its scale.
        scale: Option<Vec<f64>>,
    },
}

impl Emulation {
    /// The emulation of `[surrogate] reduced_basis` (absent: a GP per point) for `data`: the
    /// basis is taken in units of each data row's measurement std where the data gives them.
    pub fn of(
        reduced_basis: Option<ReducedBasisSettings>,
        data: &crate::likelihood_section::DataLikelihood,
    ) -> Self {
        match reduced_basis {
            None => Emulation::PerOutput,
            Some(settings) => Emulation::ReducedBasis {
                settings,
                scale: data
                    .observations
                    .measurement_std
                    .clone()
                    .filter(|s| s.iter().all(|v| v.is_finite() && *v > 0.0)),
            },
        }
    }
}

/// The emulator of every data point and failure classifiers of the run groups.
#[derive(Debug, Clone)]
pub struct Surrogate {
    /// The emulator of the outputs.
    pub emulator: Emulator,
    /// Per run group, its failure classifier (`None`: no run of the group failed).
    pub classifiers: Vec<Option<FailureClassifier>>,
}

/// Bounds of the classifier's unit cube: each prior's support where finite, else the runs'
/// extent.
fn classifier_bounds(space: &ParameterSpace, points: &[Vec<f64>]) -> Vec<(f64, f64)> {
    space
        .parameters()
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let (lo, hi) = p.prior.support();
            if lo.is_finite() && hi.is_finite() && lo < hi {
                return (lo, hi);
            }
            let (a, b) = points
                .iter()
                .fold((f64::MAX, f64::MIN), |(a, b), x| (a.min(x[k]), b.max(x[k])));
            if a < b { (a, b) } else { (a - 1.0, a + 1.0) }
        })
        .collect()
}

/// How a surrogate's GP fits start: the seed of their multi-start designs, and optionally each
/// data point's θ from an earlier fit (`iuq_gp::fit_warm`; the adaptive engine passes the round
/// before's, so that a round on a few more runs polishes the same optimum instead of refining
/// its multi-start from the subset's).
#[derive(Debug, Clone, Copy)]
pub struct GpStarts<'a> {
    /// GP j's multi-start design is drawn with seed `seed + j`.
    pub seed: u64,
    /// θ per data point of an earlier fit of one GP per data point (ignored by other emulators).
    pub warm: Option<&'a [Vec<f64>]>,
}

impl GpStarts<'_> {
    /// Cold starts from `seed`.
    pub fn cold(seed: u64) -> Self {
        GpStarts { seed, warm: None }
    }
}

/// The runs a reduced basis is fitted to: the study model's run groups and, with a second
/// fidelity, the cheap model's.
struct BasisRuns<'a> {
    groups: &'a [GroupRuns],
    runs: &'a ModelRuns,
    low: Option<&'a LowFidelity>,
}

impl Surrogate {
    /// Fit the emulator (GP j with seed `starts.seed + j`, warm-started from `starts.warm[j]`
    /// where given; component k of a reduced basis with seed `starts.seed + k`) and the
    /// classifiers of `groups`.
    ///
    /// # Errors
    /// A data point with fewer than 3 successful training runs, or a fit that fails.
    ///
    /// With a cheap model (`low`), every data point's emulator is a two-fidelity GP on its runs
    /// and the study model's (`iuq_gp::MultiFidelityGp`), or with a reduced basis every
    /// principal component's (`iuq_gp::ReducedBasis::fit_two_fidelity`).
    pub fn fit(
        groups: &[GroupRuns],
        runs: &ModelRuns,
        low: Option<&LowFidelity>,
        space: &ParameterSpace,
        starts: GpStarts<'_>,
        emulation: &Emulation,
        describe: impl Fn(usize) -> String,
    ) -> Result<Self> {
        let seed = starts.seed;
        if let Emulation::ReducedBasis { settings, scale } = emulation {
            let basis = BasisRuns { groups, runs, low };
            return Self::fit_reduced_basis(basis, space, seed, settings, scale, describe);
        }
        // Every data point's training runs, checked in order; then the fits, in parallel (each
        // is deterministic, so the surrogate does not depend on the number of threads).
        let mut tasks = Vec::with_capacity(runs.output_names().len());
        // Data points whose discrepancies may be shared pool their expensive runs: each needs
        // only the 2 runs a GP takes.
        let shared = low.is_some() && runs.groups() > 1 && runs.group_abscissa(0).is_some();
        let min_runs = if shared { 2 } else { 3 };
        for (g, group) in groups.iter().enumerate() {
            for (k, j) in runs.group_outputs(g).enumerate() {
                let training = group.training(k);
                if training.y.len() < min_runs {
                    return Err(StudyError::failure(format!(
                        "{}: only {} training runs succeeded; a GP needs at least {min_runs} (failures: {}); a larger initial design (`[surrogate] design.n`, `initial_runs` of iuq.calibrate) or narrower priors give it more",
                        describe(j),
                        training.y.len(),
                        group
                            .failure_reasons()
                            .first()
                            .map_or("none", String::as_str)
                    )));
                }
                let options = FitOptions {
                    seed: seed.wrapping_add(j as u64),
                    ..Default::default()
                }
                .check()?;
                let cheap = low.map(|low| low.training(j)).transpose()?;
                tasks.push((j, training, cheap, options));
            }
        }
        // A model run once per data point: the data points' discrepancies may be one GP in
        // (θ, abscissa), used where it predicts the expensive runs better than each point's
        // own (`iuq_gp::shared_discrepancy`).
        if shared {
            let two_fidelity = Self::fit_shared_discrepancy(&tasks, runs, seed)?;
            return Self::two_fidelity_surrogate(groups, runs, space, two_fidelity);
        }
        let fits: Vec<_> = tasks
            .par_iter()
            .map(|(j, training, cheap, options)| match cheap {
                Some(cheap) => {
                    MultiFidelityGp::fit(&cheap.x, &cheap.y, &training.x, &training.y, options)
                        .map(|gp| FittedOutput::TwoFidelity(Box::new(gp)))
                }
                None => match starts.warm.and_then(|warm| warm.get(*j)) {
                    Some(warm) => {
                        GaussianProcess::fit_warm(&training.x, &training.y, options, warm)
                    }
                    None => GaussianProcess::fit(&training.x, &training.y, options),
                }
                .map(|gp| FittedOutput::Single(Box::new(gp))),
            })
            .collect();
        let mut two_fidelity = Vec::new();
        let mut gps = Vec::with_capacity(fits.len());
        for ((j, _, cheap, _), fit) in tasks.iter().zip(fits) {
            let kind = if cheap.is_some() {
                "two-fidelity GP fit"
            } else {
                "GP fit"
            };
            match fit.with_context(|| format!("{kind} {}", describe(*j)))? {
                FittedOutput::Single(gp) => gps.push(*gp),
                FittedOutput::TwoFidelity(gp) => two_fidelity.push(*gp),
            }
        }
        if low.is_some() {
            return Self::two_fidelity_surrogate(groups, runs, space, two_fidelity);
        }
        let classifiers = failure_classifiers(groups, space)?;
        let bank = GpBank::new(
            runs.parameters().to_vec(),
            runs.output_names().to_vec(),
            gps,
        )?;
        Ok(Self {
            emulator: Emulator::PerOutput(bank),
            classifiers,
        })
    }

    /// Every data point's two-fidelity GP where the model runs once per data point: on one
    /// discrepancy in (θ, abscissa) where that wins, else each point's own
    /// (`iuq_gp::fit_shared_discrepancy_with`; δ's seed follows the points').
    fn fit_shared_discrepancy(
        tasks: &[(usize, OutputRuns, Option<OutputRuns>, CheckedFitOptions)],
        runs: &ModelRuns,
        seed: u64,
    ) -> Result<Vec<MultiFidelityGp>> {
        let mut points = Vec::with_capacity(tasks.len());
        for (j, training, cheap, _) in tasks {
            let Some(cheap) = cheap else {
                return Err(StudyError::failure(format!(
                    "data point {}: no cheap runs for its two-fidelity GP",
                    j + 1
                )));
            };
            points.push(PointRuns {
                abscissa: runs.abscissa_of_output(*j),
                low_x: &cheap.x,
                low_y: &cheap.y,
                high_x: &training.x,
                high_y: &training.y,
            });
        }
        let shared = FitOptions {
            seed: seed.wrapping_add(tasks.len() as u64),
            ..Default::default()
        }
        .check()?;
        fit_shared_discrepancy_with(&points, &shared, &|k| Ok(tasks[k].3))
            .context("two-fidelity GP fit of the data points")
    }

    /// The surrogate of a two-fidelity GP per data point, with the groups' failure
    /// classifiers.
    fn two_fidelity_surrogate(
        groups: &[GroupRuns],
        runs: &ModelRuns,
        space: &ParameterSpace,
        two_fidelity: Vec<MultiFidelityGp>,
    ) -> Result<Self> {
        let bank = MultiFidelityBank::new(
            runs.parameters().to_vec(),
            runs.output_names().to_vec(),
            two_fidelity,
        )?;
        Ok(Self {
            emulator: Emulator::TwoFidelity(bank),
            classifiers: failure_classifiers(groups, space)?,
        })
    }

    /// The reduced basis of a whole-curve model's one run group, and its classifier.
    fn fit_reduced_basis(
        BasisRuns { groups, runs, low }: BasisRuns<'_>,
        space: &ParameterSpace,
        seed: u64,
        settings: &ReducedBasisSettings,
        scale: &Option<Vec<f64>>,
        describe: impl Fn(usize) -> String,
    ) -> Result<Self> {
        let [group] = groups else {
            return Err(StudyError::failure(format!(
                "a reduced basis emulates a whole-curve model (one run group), not {} run groups",
                groups.len()
            )));
        };
        let Curves { inputs, outputs } = group.training_curves();
        if inputs.len() < 3 {
            return Err(StudyError::failure(format!(
                "{}: only {} training runs succeeded; a reduced basis needs at least 3 (failures: {})",
                describe(0),
                inputs.len(),
                group
                    .failure_reasons()
                    .first()
                    .map_or("none", String::as_str)
            )));
        }
        let options = ReducedBasisOptions {
            explained_variance: settings.explained_variance,
            max_components: settings.max_components,
            output_scale: scale.clone(),
            fit: FitOptions {
                seed,
                ..Default::default()
            },
        };
        let basis = match low {
            None => ReducedBasis::fit(
                runs.parameters().to_vec(),
                runs.output_names().to_vec(),
                &inputs,
                &outputs,
                &options,
            ),
            Some(low) => {
                let cheap = low.training_curves()?;
                ReducedBasis::fit_two_fidelity(
                    runs.parameters().to_vec(),
                    runs.output_names().to_vec(),
                    (&inputs, &outputs),
                    (&cheap.inputs, &cheap.outputs),
                    &options,
                )
            }
        }
        .with_context(|| "the reduced basis of the curve".to_string())?;
        let (points, failed) = group.failure_labels();
        let bounds = classifier_bounds(space, &points);
        let classifier = FailureClassifier::fit(
            &points,
            &failed,
            &bounds,
            &ClassifierOptions::default().check()?,
        )
        .with_context(|| "failure classifier of run group 1".to_string())?;
        Ok(Self {
            emulator: Emulator::ReducedBasis(basis),
            classifiers: vec![classifier],
        })
    }

    /// The probability that a run of group `g` fails at each point.
    pub fn group_failure_probability(&self, g: usize, points: &[Vec<f64>]) -> Result<Vec<f64>> {
        match self.classifiers.get(g).and_then(Option::as_ref) {
            Some(c) => Ok(c.failure_probability(points)?),
            None => Ok(vec![0.0; points.len()]),
        }
    }
}

impl Model for Surrogate {
    fn input_names(&self) -> &[String] {
        self.emulator.input_names()
    }

    fn output_names(&self) -> &[String] {
        self.emulator.output_names()
    }

    fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
        let outcomes = self.emulator.evaluate_batch(points)?;
        self.classify(points, outcomes)
    }

    /// The emulator's screen with the same failure classifiers, so that it fails exactly where
    /// [`Surrogate::evaluate_batch`] does.
    fn screening_batch(&self, points: &[Vec<f64>]) -> Option<iuq_core::Result<Vec<Outcome>>> {
        let outcomes = self.emulator.screening_batch(points)?;
        Some(outcomes.and_then(|o| self.classify(points, o)))
    }

    /// The emulator's affine screen (a reduced basis), where no failure classifier could
    /// make the screen fail where its coefficients do not.
    fn affine_screening(&self) -> Option<&dyn iuq_core::affine_screen::AffineScreening> {
        if self.classifiers.iter().any(Option::is_some) {
            return None;
        }
        self.emulator.affine_screening()
    }
}

impl Surrogate {
    /// `outcomes` with a failure wherever a run group's classifier predicts no answer.
    fn classify(
        &self,
        points: &[Vec<f64>],
        mut outcomes: Vec<Outcome>,
    ) -> iuq_core::Result<Vec<Outcome>> {
        for (g, classifier) in self.classifiers.iter().enumerate() {
            let Some(c) = classifier else { continue };
            let valid: Vec<usize> = (0..points.len()).filter(|&i| outcomes[i].is_ok()).collect();
            let probe: Vec<Vec<f64>> = valid.iter().map(|&i| points[i].clone()).collect();
            let p = c
                .failure_probability(&probe)
                .map_err(|e| iuq_core::CoreError::ModelUnavailable(e.to_string()))?;
            for (&i, p_fail) in valid.iter().zip(p) {
                if p_fail > FAILURE_THRESHOLD {
                    outcomes[i] = Err(EvaluationFailure::new(format!(
                        "the failure classifier of run group {} predicts no answer here (p_fail = {p_fail:.2})",
                        g + 1
                    )));
                }
            }
        }
        Ok(outcomes)
    }
}

/// One data point's fitted emulator.
enum FittedOutput {
    Single(Box<GaussianProcess>),
    TwoFidelity(Box<MultiFidelityGp>),
}

/// Each run group's failure classifier (GP classification of where its runs failed; `None`
/// where none failed).
fn failure_classifiers(
    groups: &[GroupRuns],
    space: &ParameterSpace,
) -> Result<Vec<Option<FailureClassifier>>> {
    let mut classifiers = Vec::with_capacity(groups.len());
    for (g, group) in groups.iter().enumerate() {
        let (points, failed) = group.failure_labels();
        let bounds = classifier_bounds(space, &points);
        let classifier = FailureClassifier::fit(
            &points,
            &failed,
            &bounds,
            &ClassifierOptions::default().check()?,
        )
        .with_context(|| format!("failure classifier of run group {}", g + 1))?;
        classifiers.push(classifier);
    }
    Ok(classifiers)
}
