//! A model that fails on part of the domain (no NaN anywhere, failures counted and reported,
//! the evidence of the region where it succeeds), the minimum step and the stage limit.

mod common;

use common::*;
use iuq_basis::checkpoint::{from_json, to_json};
use iuq_basis::{
    Basis, BasisError, BasisSettings, BasisState, ComputationalError, ErrorModel, FnLikelihood,
    MinStepAction, Observations, PosteriorSummary, PredictionErrorLikelihood, Silent, StopReason,
};
use iuq_core::{Evaluation, EvaluationFailure, Model, Outcome, ParameterSpace};

/// q(x) = x, failing with "mesh broke" for x > `fail_above` and returning NaN for x < −14.
/// With datum ŷ = 0 and σ_d = 1 the log-likelihood is ln N(x; 0, 1) where the model succeeds.
struct Fragile {
    inputs: Vec<String>,
    outputs: Vec<String>,
    fail_above: f64,
}

impl Model for Fragile {
    fn input_names(&self) -> &[String] {
        &self.inputs
    }
    fn output_names(&self) -> &[String] {
        &self.outputs
    }
    fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
        Ok(points
            .iter()
            .map(|p| {
                if p[0] > self.fail_above {
                    Err(EvaluationFailure::new("mesh broke"))
                } else if p[0] < -14.0 {
                    Ok(Evaluation::new(vec![f64::NAN]))
                } else {
                    Ok(Evaluation::new(vec![p[0]]))
                }
            })
            .collect())
    }
}

fn fragile(fail_above: f64) -> (ParameterSpace, PredictionErrorLikelihood<Fragile>) {
    let model = Fragile {
        inputs: vec!["x0".into()],
        outputs: vec!["y".into()],
        fail_above,
    };
    let likelihood = PredictionErrorLikelihood::new(
        model,
        Observations {
            values: vec![0.0],
            measurement_std: Some(vec![1.0]),
        },
        ErrorModel {
            measurement_error: true,
            computational_error: ComputationalError::None,
            modelling_error: None,
        },
    )
    .unwrap();
    (uniform_box(1, 15.0), likelihood)
}

fn assert_no_nan(state: &BasisState) {
    assert!(state.samples.iter().flatten().all(|v| v.is_finite()));
    assert!(state.log_likelihood.iter().all(|v| !v.is_nan()));
    assert!(state.log_prior.iter().all(|v| v.is_finite()));
    assert!(state.log_evidence.is_finite());
    for d in &state.diagnostics {
        for v in [
            d.exponent,
            d.step,
            d.cv,
            d.ess_fraction,
            d.log_evidence_increment,
            d.log_evidence,
            d.max_log_likelihood,
            d.acceptance_rate,
            d.unique_fraction,
        ] {
            assert!(v.is_finite(), "stage {}: {d:?}", d.stage);
        }
    }
}

/// Φ(z) for the exact evidences (erfc by scipy: Φ(1) = 0.8413447460685429).
const PHI_1: f64 = 0.841_344_746_068_542_9;

#[test]
fn a_model_failing_on_part_of_the_domain_is_handled_and_reported() {
    // Fails for x > 1 (47 % of the prior) and gives NaN below −14: Z = Φ(1)/30.
    let (space, likelihood) = fragile(1.0);
    let exact = PHI_1.ln() - 30f64.ln();
    let seeds = 8u64;
    let mut evidences = Vec::new();
    for seed in 0..seeds {
        let state = run(
            &space,
            &likelihood,
            BasisSettings {
                samples: 1000,
                seed,
                ..Default::default()
            },
        );
        assert_eq!(state.stop_reason, Some(StopReason::Converged));
        assert_no_nan(&state);
        // stage 0 holds the failed prior draws, reported by reason
        let d0 = &state.diagnostics[0];
        assert!(d0.failures > 350 && d0.failures < 600, "{}", d0.failures);
        assert!(d0.failure_reasons["mesh broke"] > 350);
        assert!(
            d0.failure_reasons
                .contains_key("model returned a non-finite output")
        );
        assert_eq!(d0.failure_reasons.values().sum::<usize>(), d0.failures);
        // the final population never holds a failed point
        assert!(state.log_likelihood.iter().all(|v| v.is_finite()));
        assert!(state.samples.iter().all(|x| x[0] <= 1.0 && x[0] >= -14.0));
        assert!(
            state.failures() > d0.failures,
            "moves hit the failing region too"
        );
        assert!(state.failure_reasons()["mesh broke"] > 0);
        evidences.push(state.log_evidence);
        if seed == 0 {
            // −∞ members survive a checkpoint round trip as null
            let basis = Basis::new(
                &space,
                &likelihood,
                BasisSettings {
                    samples: 1000,
                    seed,
                    ..Default::default()
                }
                .check()
                .unwrap(),
            )
            .unwrap();
            let first = basis.initialise().unwrap();
            let text = to_json(&first).unwrap();
            assert!(text.contains("null"));
            let back = from_json(&text).unwrap();
            assert_same_run(&back, &first);
            let summary = PosteriorSummary::from_state(&state).unwrap();
            assert!(summary.mean[0].is_finite() && summary.map[0] <= 1.0);
        }
    }
    let (mean, sd) = mean_sd(&evidences);
    println!("failing model: mean ln Z {mean:.4} (exact {exact:.4}, sd {sd:.3})");
    assert!((mean - exact).abs() < 3.0 * 0.35 / (seeds as f64).sqrt());
}

#[test]
fn more_than_half_failed_takes_the_minimum_step_or_stops() {
    // Fails for x > −1 (53 % of the prior): CV(dp → 0) = √(0.53/0.47) > 1, so the solved step
    // is below any minimum. Clamping takes the minimum step; the run still converges and finds
    // Z = Φ(−1)/30.
    let (space, likelihood) = fragile(-1.0);
    let exact = (1.0 - PHI_1).ln() - 30f64.ln();
    let seeds = 6u64;
    let mut evidences = Vec::new();
    for seed in 0..seeds {
        let state = run(
            &space,
            &likelihood,
            BasisSettings {
                samples: 1000,
                seed,
                ..Default::default()
            },
        );
        assert_eq!(state.stop_reason, Some(StopReason::Converged));
        assert_no_nan(&state);
        assert!(state.diagnostics[0].failures > 450);
        assert!(state.diagnostics[1].step_clamped);
        assert_eq!(state.diagnostics[1].step, 1e-6);
        evidences.push(state.log_evidence);
    }
    let (mean, _) = mean_sd(&evidences);
    println!("clamped: mean ln Z {mean:.4} (exact {exact:.4})");
    assert!((mean - exact).abs() < 3.0 * 0.35 / (seeds as f64).sqrt());

    let stopped = run(
        &space,
        &likelihood,
        BasisSettings {
            samples: 1000,
            on_min_step: MinStepAction::Stop,
            ..Default::default()
        },
    );
    match &stopped.stop_reason {
        Some(StopReason::StepBelowMinimum {
            step,
            min_step,
            exponent,
        }) => {
            assert!(step < min_step);
            assert_eq!(*exponent, 0.0);
        }
        other => panic!("expected a stop below the minimum step, got {other:?}"),
    }
    assert_eq!(stopped.stage, 0);
}

#[test]
fn the_stage_limit_stops_with_a_reason() {
    let problem = &reference_problems()[3];
    let state = run_problem(
        problem,
        BasisSettings {
            samples: 500,
            max_stages: 3,
            ..Default::default()
        },
    );
    assert_eq!(state.stage, 3);
    match state.stop_reason {
        Some(StopReason::MaxStages {
            max_stages: 3,
            exponent,
        }) => assert!(exponent < 1.0 && exponent > 0.0),
        other => panic!("{other:?}"),
    }
    let reason = state.stop_reason.as_ref().unwrap();
    assert_eq!(reason.name(), "max_stages");
    assert!(reason.to_string().contains("maximum of 3 stages"));
}

#[test]
fn degenerate_inputs_are_errors_not_panics() {
    let space = uniform_box(2, 1.0);
    // wrong dimension
    let likelihood = FnLikelihood::new(3, |_: &[f64]| 0.0);
    assert!(matches!(
        Basis::new(
            &space,
            &likelihood,
            BasisSettings::default().check().unwrap()
        ),
        Err(BasisError::InvalidLikelihood(_))
    ));
    // every evaluation fails
    let likelihood = FnLikelihood::new(2, |_: &[f64]| f64::NAN);
    let basis = Basis::new(
        &space,
        &likelihood,
        BasisSettings::default().check().unwrap(),
    )
    .unwrap();
    match basis.run(&mut Silent) {
        Err(BasisError::NoFiniteLikelihood { stage: 0, failures }) => assert_eq!(failures, 1000),
        other => panic!("{other:?}"),
    }
    // invalid settings never reach the sampler
    assert!(matches!(
        BasisSettings {
            samples: 0,
            ..Default::default()
        }
        .check(),
        Err(BasisError::InvalidSettings {
            setting: "samples",
            ..
        })
    ));
    // a model that fails the whole batch stops the run with the stage named
    struct Down(Vec<String>, Vec<String>);
    impl Model for Down {
        fn input_names(&self) -> &[String] {
            &self.0
        }
        fn output_names(&self) -> &[String] {
            &self.1
        }
        fn evaluate_batch(&self, _: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
            Err(iuq_core::CoreError::ModelUnavailable(
                "server unreachable".into(),
            ))
        }
    }
    let likelihood = PredictionErrorLikelihood::new(
        Down(vec!["x0".into(), "x1".into()], vec!["y".into()]),
        Observations {
            values: vec![1.0],
            measurement_std: Some(vec![0.1]),
        },
        ErrorModel {
            modelling_error: None,
            ..Default::default()
        },
    )
    .unwrap();
    let basis = Basis::new(
        &space,
        &likelihood,
        BasisSettings::default().check().unwrap(),
    )
    .unwrap();
    match basis.run(&mut Silent) {
        Err(BasisError::Evaluation { stage: 0, reason }) => {
            assert!(reason.contains("server unreachable"))
        }
        other => panic!("{other:?}"),
    }
}
