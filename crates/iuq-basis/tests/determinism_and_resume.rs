//! Results independent of the rayon thread count, and resumption from a checkpoint after any
//! stage bit-identical to an uninterrupted run.

mod common;

use common::*;
use iuq_basis::checkpoint::{from_json, to_json};
use iuq_basis::{
    Basis, BasisError, BasisSettings, BasisState, ComputationalError, Control, CurveModel,
    ErrorModel, FnLikelihood, LogLikelihood, Observations, PredictionErrorLikelihood, Resampling,
    Silent, StopReason,
};
use iuq_core::{Parameter, ParameterSpace, Prior};

fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

/// A data-driven problem whose model (a curve formula) is evaluated in parallel by rayon.
fn curve_problem() -> (ParameterSpace, PredictionErrorLikelihood<CurveModel>) {
    let xs: Vec<f64> = (0..8).map(|j| 0.5 + j as f64).collect();
    let ys: Vec<f64> = xs.iter().map(|x| 2.0 * (-0.3 * x).exp() + 0.1).collect();
    let model = CurveModel::new(vec!["a".into(), "k".into()], "a*exp(-k*x) + 0.1", xs).unwrap();
    let likelihood = PredictionErrorLikelihood::new(
        model,
        Observations {
            values: ys,
            measurement_std: Some(vec![0.02; 8]),
        },
        ErrorModel {
            computational_error: ComputationalError::Relative,
            ..Default::default()
        },
    )
    .unwrap();
    let model_space = ParameterSpace::new(vec![
        Parameter {
            name: "a".into(),
            prior: Prior::Uniform(0.0, 5.0),
        },
        Parameter {
            name: "k".into(),
            prior: Prior::Uniform(0.0, 2.0),
        },
    ])
    .unwrap();
    let space = likelihood.parameter_space(&model_space).unwrap();
    (space, likelihood)
}

#[test]
fn one_and_two_threads_give_identical_runs() {
    let (space, likelihood) = curve_problem();
    for settings in [
        BasisSettings {
            samples: 1500,
            burn_in: 2,
            seed: 11,
            ..Default::default()
        },
        BasisSettings {
            samples: 1000,
            max_chain_length: 3,
            resampling: Resampling::Systematic,
            seed: 12,
            ..Default::default()
        },
    ] {
        let one = in_pool(1, || run(&space, &likelihood, settings));
        let two = in_pool(2, || run(&space, &likelihood, settings));
        assert_eq!(one.stop_reason, Some(StopReason::Converged));
        assert_same_run(&one, &two);
    }
    // and with a closure likelihood
    let problem = &reference_problems()[3];
    let settings = BasisSettings {
        samples: 2000,
        seed: 5,
        ..Default::default()
    };
    let one = in_pool(1, || run_problem(problem, settings));
    let two = in_pool(2, || run_problem(problem, settings));
    assert_same_run(&one, &two);
}

#[test]
fn resuming_after_every_stage_is_bit_identical() {
    let (space, likelihood) = curve_problem();
    let settings = BasisSettings {
        samples: 400,
        burn_in: 1,
        max_chain_length: 2,
        seed: 21,
        ..Default::default()
    }
    .check()
    .unwrap();
    let basis = Basis::new(&space, &likelihood, settings).unwrap();
    let mut states: Vec<BasisState> = Vec::new();
    let full = basis
        .run(&mut |s: &BasisState| {
            states.push(s.clone());
            Control::Continue
        })
        .unwrap();
    assert_eq!(full.stop_reason, StopReason::Converged);
    assert_eq!(states.len(), full.state.stage + 1);
    assert!(full.state.stage >= 4, "{} stages", full.state.stage);
    for (stop_at, expected) in states.iter().enumerate().take(full.state.stage) {
        let mut seen = 0;
        let interrupted = basis
            .run(&mut |s: &BasisState| {
                seen += 1;
                if s.stage == stop_at {
                    Control::Stop
                } else {
                    Control::Continue
                }
            })
            .unwrap();
        assert_eq!(seen, stop_at + 1);
        assert_eq!(
            interrupted.stop_reason,
            StopReason::Interrupted { stage: stop_at }
        );
        // the checkpoint round-trips bit for bit
        let text = to_json(&interrupted.state).unwrap();
        let restored = from_json(&text).unwrap();
        assert_same_run(&restored, &interrupted.state);
        assert_same_run(&restored, expected);
        // and the resumed run ends exactly where the uninterrupted one did
        let resumed = basis.resume(restored, &mut Silent).unwrap();
        assert_eq!(resumed.stop_reason, StopReason::Converged);
        assert_same_run(&resumed.state, &full.state);
    }
    // a finished state resumes to itself
    let again = basis.resume(full.state.clone(), &mut Silent).unwrap();
    assert_same_run(&again.state, &full.state);
    assert!(matches!(
        basis.advance(full.state.clone()),
        Err(BasisError::AlreadyFinished(_))
    ));
}

#[test]
fn a_checkpoint_of_other_settings_or_parameters_is_refused() {
    let (space, likelihood) = curve_problem();
    let settings = BasisSettings {
        samples: 200,
        seed: 1,
        ..Default::default()
    };
    let basis = Basis::new(&space, &likelihood, settings.check().unwrap()).unwrap();
    let state = basis.initialise().unwrap();
    let other = BasisSettings {
        seed: 2,
        ..settings
    }
    .check()
    .unwrap();
    let basis_other = Basis::new(&space, &likelihood, other).unwrap();
    assert!(matches!(
        basis_other.resume(state.clone(), &mut Silent),
        Err(BasisError::CheckpointMismatch(_))
    ));
    let mut renamed = state.clone();
    renamed.parameter_names[0] = "z".into();
    assert!(matches!(
        basis.resume(renamed, &mut Silent),
        Err(BasisError::CheckpointMismatch(_))
    ));
    // malformed checkpoints
    let text = to_json(&state).unwrap();
    assert!(matches!(
        from_json(&text.replace("iuq-basis-checkpoint", "something-else")),
        Err(BasisError::Checkpoint(_))
    ));
    assert!(matches!(
        from_json(&text.replace("\"version\":1", "\"version\":99")),
        Err(BasisError::Checkpoint(_))
    ));
    assert!(from_json("{").is_err());
    assert!(from_json("[]").is_err());
    let mut short = state.clone();
    short.samples.pop();
    assert!(from_json(&to_json(&short).unwrap()).is_err());
    // the documented fields are present
    let value: serde_json::Value = serde_json::from_str(&text).unwrap();
    for key in [
        "format",
        "version",
        "parameter_names",
        "settings",
        "stage",
        "exponent",
        "log_evidence",
        "samples",
        "log_likelihood",
        "log_prior",
        "evaluations",
        "diagnostics",
        "stop_reason",
    ] {
        assert!(value.get(key).is_some(), "{key}");
    }
    assert_eq!(value["settings"]["seed"], 1);
}

#[test]
fn one_batch_per_stage_and_per_mcmc_step_and_never_outside_the_support() {
    use std::sync::atomic::{AtomicUsize, Ordering};
    struct Counting<L> {
        inner: L,
        batches: AtomicUsize,
        points: AtomicUsize,
        outside: AtomicUsize,
        space: ParameterSpace,
    }
    impl<L: LogLikelihood> LogLikelihood for Counting<L> {
        fn parameter_count(&self) -> usize {
            self.inner.parameter_count()
        }
        fn log_likelihood_batch(
            &self,
            points: &[Vec<f64>],
        ) -> iuq_basis::Result<Vec<iuq_basis::PointLogLikelihood>> {
            self.batches.fetch_add(1, Ordering::Relaxed);
            self.points.fetch_add(points.len(), Ordering::Relaxed);
            let outside = points.iter().filter(|p| !self.space.in_support(p)).count();
            self.outside.fetch_add(outside, Ordering::Relaxed);
            self.inner.log_likelihood_batch(points)
        }
    }
    // A Gaussian close to the edge of its prior: many proposals fall outside.
    let space = uniform_box(2, 1.0);
    let counting = Counting {
        inner: FnLikelihood::new(2, |x: &[f64]| {
            -0.5 * ((x[0] - 0.9) / 0.2).powi(2) - 0.5 * ((x[1] + 0.9) / 0.2).powi(2)
        }),
        batches: AtomicUsize::new(0),
        points: AtomicUsize::new(0),
        outside: AtomicUsize::new(0),
        space: space.clone(),
    };
    let settings = BasisSettings {
        samples: 1000,
        burn_in: 3,
        max_chain_length: 2,
        seed: 3,
        ..Default::default()
    };
    let state = run(&space, &counting, settings);
    assert_eq!(counting.outside.load(Ordering::Relaxed), 0);
    assert!(state.out_of_support() > 0);
    let batches: usize = state.diagnostics.iter().map(|d| d.batches).sum();
    assert_eq!(batches, counting.batches.load(Ordering::Relaxed));
    assert_eq!(state.evaluations, counting.points.load(Ordering::Relaxed));
    assert_eq!(state.diagnostics[0].batches, 1);
    for d in &state.diagnostics[1..] {
        // n_burn (at least the 3 asked for) + the longest chain (≤ l_max) steps, one batch each
        assert!(d.burn_in >= 3, "burn-in {}", d.burn_in);
        assert!(d.batches <= d.burn_in + 2, "{} batches", d.batches);
        assert_eq!(d.proposals, d.evaluations + d.out_of_support);
    }
}
