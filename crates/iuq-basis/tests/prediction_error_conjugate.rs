//! The prediction-error likelihood with data against a closed-form conjugate case: a linear
//! model q(a, b) = a + b·x_j, known measurement errors σ_j, no modelling or computational error,
//! and a uniform prior wide enough that its truncation is negligible. The posterior is then
//! Gaussian with precision A = XᵀWX (W = diag 1/σ_j²), mean A⁻¹XᵀWy, and
//! Z = L(θ̂)·2π·det(A)^(−1/2)/V, V the prior volume.

mod common;

use common::*;
use iuq_basis::{
    BasisSettings, ComputationalError, CurveModel, ErrorModel, LogLikelihood, Observations,
    PosteriorSummary, PredictionErrorLikelihood, StopReason,
};
use iuq_core::{Parameter, ParameterSpace, Prior};

struct Conjugate {
    xs: Vec<f64>,
    ys: Vec<f64>,
    sigmas: Vec<f64>,
}

fn data() -> Conjugate {
    let xs: Vec<f64> = (0..11).map(|j| j as f64).collect();
    // y = 1 + 0.5 x + a fixed pseudo-random perturbation of the size of σ
    let ys = xs
        .iter()
        .enumerate()
        .map(|(j, x)| 1.0 + 0.5 * x + 0.3 * (37.0 * j as f64).sin())
        .collect();
    let sigmas = (0..11).map(|j| 0.2 + 0.02 * j as f64).collect();
    Conjugate { xs, ys, sigmas }
}

/// (posterior mean, posterior sd, ln Z) in closed form for the prior volume `volume`.
fn closed_form(c: &Conjugate, volume: f64) -> ([f64; 2], [f64; 2], f64) {
    let (mut a00, mut a01, mut a11, mut b0, mut b1) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for ((x, y), s) in c.xs.iter().zip(&c.ys).zip(&c.sigmas) {
        let w = 1.0 / (s * s);
        a00 += w;
        a01 += w * x;
        a11 += w * x * x;
        b0 += w * y;
        b1 += w * x * y;
    }
    let det = a00 * a11 - a01 * a01;
    let mean = [(a11 * b0 - a01 * b1) / det, (a00 * b1 - a01 * b0) / det];
    let sd = [(a11 / det).sqrt(), (a00 / det).sqrt()];
    let mut ln_l_max = 0.0;
    for ((x, y), s) in c.xs.iter().zip(&c.ys).zip(&c.sigmas) {
        let r = y - mean[0] - mean[1] * x;
        ln_l_max += -0.5 * (r * r / (s * s) + LN_2PI + (s * s).ln());
    }
    let ln_z = ln_l_max + LN_2PI - 0.5 * det.ln() - volume.ln();
    (mean, sd, ln_z)
}

fn model_space() -> ParameterSpace {
    ParameterSpace::new(vec![
        Parameter {
            name: "a".into(),
            prior: Prior::Uniform(-10.0, 10.0),
        },
        Parameter {
            name: "b".into(),
            prior: Prior::Uniform(-5.0, 5.0),
        },
    ])
    .unwrap()
}

#[test]
fn linear_model_with_known_errors_matches_the_closed_form() {
    let c = data();
    let model = CurveModel::new(vec!["a".into(), "b".into()], "a + b*x", c.xs.clone()).unwrap();
    let likelihood = PredictionErrorLikelihood::new(
        model,
        Observations {
            values: c.ys.clone(),
            measurement_std: Some(c.sigmas.clone()),
        },
        ErrorModel {
            measurement_error: true,
            computational_error: ComputationalError::None,
            modelling_error: None,
        },
    )
    .unwrap();
    let space = likelihood.parameter_space(&model_space()).unwrap();
    assert_eq!(space.names(), vec!["a", "b"]);
    assert_eq!(likelihood.parameter_count(), 2);
    let (mean, sd, ln_z) = closed_form(&c, 200.0);

    // Expected single-run spread of ln Z at N = 1000, n_burn = 10 (docs/methods.md §7): ≈ 0.1
    // (0.15 allowed); 3σ/√k on the mean of k runs.
    // Posterior mean: 3·sd/√(k·N/10) (N_eff ≥ N/10); posterior sd: relative error of a sd from
    // N_eff samples is 1/√(2 N_eff), 3 of them over k runs.
    let (seeds, n) = (6u64, 1000usize);
    let mut evidences = Vec::new();
    let mut means = [0.0; 2];
    let mut sds = [0.0; 2];
    for seed in 0..seeds {
        let state = run(
            &space,
            &likelihood,
            BasisSettings {
                samples: n,
                burn_in: 10,
                seed,
                ..Default::default()
            },
        );
        assert_eq!(state.stop_reason, Some(StopReason::Converged));
        assert_eq!(state.failures(), 0);
        evidences.push(state.log_evidence);
        let s = PosteriorSummary::from_state(&state).unwrap();
        for k in 0..2 {
            means[k] += s.mean[k] / seeds as f64;
            sds[k] += s.std[k] / seeds as f64;
        }
    }
    let (z_mean, z_sd) = mean_sd(&evidences);
    let k = seeds as f64;
    println!(
        "conjugate: ln Z {z_mean:.4} (exact {ln_z:.4}, sd {z_sd:.3}); mean {means:?} (exact {mean:?}); sd {sds:?} (exact {sd:?})"
    );
    assert!(
        (z_mean - ln_z).abs() < 3.0 * 0.15 / k.sqrt(),
        "ln Z {z_mean} vs {ln_z}"
    );
    let n_eff = n as f64 / 10.0;
    for j in 0..2 {
        assert!(
            (means[j] - mean[j]).abs() < 3.0 * sd[j] / (k * n_eff).sqrt(),
            "mean {j}: {} vs {}",
            means[j],
            mean[j]
        );
        assert!(
            (sds[j] / sd[j] - 1.0).abs() < 3.0 / (2.0 * k * n_eff).sqrt(),
            "sd {j}: {} vs {}",
            sds[j],
            sd[j]
        );
    }
}

#[test]
fn modelling_error_is_estimated_as_an_extra_parameter() {
    // Data generated with a 5 % relative scatter and no measurement error: σ_m must be found
    // near 0.05 (the likelihood is the prediction-error model with Σ_jj = σ_m² ŷ_j²).
    let xs: Vec<f64> = (0..40).map(|j| 1.0 + j as f64 * 0.25).collect();
    let ys: Vec<f64> = xs
        .iter()
        .enumerate()
        .map(|(j, x)| (2.0 + 0.5 * x) * (1.0 + 0.05 * 1.7 * (12.9898 * j as f64).sin()))
        .collect();
    let model = CurveModel::new(vec!["a".into(), "b".into()], "a + b*x", xs).unwrap();
    let likelihood = PredictionErrorLikelihood::new(
        model,
        Observations {
            values: ys,
            measurement_std: None,
        },
        ErrorModel::default(),
    )
    .unwrap();
    let space = likelihood.parameter_space(&model_space()).unwrap();
    assert_eq!(space.names(), vec!["a", "b", "sigma_m"]);
    let state = run(
        &space,
        &likelihood,
        BasisSettings {
            samples: 2000,
            burn_in: 5,
            seed: 4,
            ..Default::default()
        },
    );
    let s = PosteriorSummary::from_state(&state).unwrap();
    println!("sigma_m posterior mean {} sd {}", s.mean[2], s.std[2]);
    // the sample rms of 0.085·sin(12.9898 j) over 40 points is ≈ 0.06
    assert!(s.mean[2] > 0.04 && s.mean[2] < 0.08, "{:?}", s.mean);
    assert!(
        (s.mean[1] - 0.5).abs() < 0.1 && (s.mean[0] - 2.0).abs() < 0.4,
        "{:?}",
        s.mean
    );
    assert!(s.map[2] > 0.001 && s.map[2] < 0.1);
}
