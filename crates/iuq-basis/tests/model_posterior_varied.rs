//! The model posterior from a surrogate's on nine problems with exact moments, 2 to 10
//! parameters, each surrogate posterior off in its own way: a correlation it ignores, shifted
//! and wider, narrower where the model fails over part of the prior, half as wide in one or two
//! parameters, narrower in all, far off, and nearly right. Four seeds each, 300 members a batch.
//!
//! The surrogate population is an exact i.i.d. sample of the surrogate's posterior (drawn
//! directly, so that the test measures this method, not the sampler that produced it).
//!
//! Tolerance: every estimate certified, and each posterior mean and std within 4.5 of its own
//! Monte Carlo standard errors: 496 statistics in all, and a 4.5σ bound keeps the family's chance
//! of a false failure near 3e-3 (the seeds are fixed, so a failure means the method changed).
//! Measured 2026-11-28: the errors' root-mean-square in MCSE units 1.01, the largest 4.2.
//!
//! The MCSE itself is checked by that root-mean-square: with standard errors that are right,
//! the errors in their units are about standard normal, and the mean of the 496 squares has a
//! std of √(2/n) for n independent ones; counting the statistics of one run (2d of them, one
//! population) as correlated leaves n ≥ 36 runs, a std of at most 0.24 on the mean square, so
//! the root-mean-square lies in [0.7, 1.4] (mean square 0.49–1.96, more than 2σ below and 4σ
//! above) unless the MCSE is off by a factor of about 1.4 — too large, and the bounds above
//! would pass where they should not; too small, and they would fail where the method is right.
//! Two problems are left out on purpose, documented in docs/methods.md §5b ("What the
//! certificate covers"): a target with tails heavier than a surrogate of the same width
//! (Student-t) and a curved arm a Gaussian surrogate does not reach (banana); neither the
//! spread ratio nor k̂ sees those at 300 members.

use iuq_basis::{FnLikelihood, LogLikelihood, ModelPosteriorSettings, SurrogatePopulation};
use iuq_core::random::stream;
use iuq_core::{Parameter, ParameterSpace, Prior};
use rand_distr::{Distribution, StandardNormal};

type LogDensity = Box<dyn Fn(&[f64]) -> f64 + Send + Sync>;

struct Problem {
    name: &'static str,
    model: LogDensity,
    surrogate_mean: Vec<f64>,
    surrogate_std: Vec<f64>,
    mean: Vec<f64>,
    std: Vec<f64>,
}

fn standard_normal(x: &[f64]) -> f64 {
    -0.5 * x.iter().map(|v| v * v).sum::<f64>()
}

fn problems() -> Vec<Problem> {
    // N(0, I) cut at x0 + x1 ≤ 1.5: along u = (x0 + x1)/√2 a standard normal cut at
    // c = 1.5/√2, mean −φ(c)/Φ(c), variance 1 − c·φ/Φ − (φ/Φ)²; x0 = (u + v)/√2 with v ~ N(0, 1).
    let c = 1.060_660_171_779_821_2;
    let lambda = 0.227_310_459_431_724_32 / 0.855_577_816_826_757_6;
    let cut_mean = -lambda / 2f64.sqrt();
    let cut_std = ((1.0 - c * lambda - lambda * lambda + 1.0) / 2.0).sqrt();
    let half = |d: usize, narrow: &[usize]| -> Vec<f64> {
        (0..d)
            .map(|k| if narrow.contains(&k) { 0.5 } else { 1.0 })
            .collect()
    };
    vec![
        Problem {
            name: "a correlation of 0.9 the surrogate ignores, 5 parameters",
            model: Box::new(|x: &[f64]| {
                let rho = 0.9;
                -0.5 * (x[0] * x[0] - 2.0 * rho * x[0] * x[1] + x[1] * x[1]) / (1.0 - rho * rho)
                    + standard_normal(&x[2..])
            }),
            surrogate_mean: vec![0.0; 5],
            surrogate_std: vec![1.0; 5],
            mean: vec![0.0; 5],
            std: vec![1.0; 5],
        },
        Problem {
            name: "shifted by half a std and 1.3 times as wide, 10 parameters",
            model: Box::new(standard_normal),
            surrogate_mean: vec![0.5; 10],
            surrogate_std: vec![1.3; 10],
            mean: vec![0.0; 10],
            std: vec![1.0; 10],
        },
        Problem {
            name: "failing where x0 + x1 > 1.5, surrogate 0.8 as wide and uncut, 5 parameters",
            model: Box::new(|x: &[f64]| {
                if x[0] + x[1] > 1.5 {
                    f64::NAN
                } else {
                    standard_normal(x)
                }
            }),
            surrogate_mean: vec![0.0; 5],
            surrogate_std: vec![0.8; 5],
            mean: vec![cut_mean, cut_mean, 0.0, 0.0, 0.0],
            std: vec![cut_std, cut_std, 1.0, 1.0, 1.0],
        },
        Problem {
            name: "two stds off in x0 and 0.7 as wide in x1, 2 parameters",
            model: Box::new(standard_normal),
            surrogate_mean: vec![2.0, 0.0],
            surrogate_std: vec![1.0, 0.7],
            mean: vec![0.0; 2],
            std: vec![1.0; 2],
        },
        Problem {
            name: "half as wide in x0, 6 parameters",
            model: Box::new(standard_normal),
            surrogate_mean: vec![0.0; 6],
            surrogate_std: half(6, &[0]),
            mean: vec![0.0; 6],
            std: vec![1.0; 6],
        },
        Problem {
            name: "0.7 as wide in all 4 parameters",
            model: Box::new(standard_normal),
            surrogate_mean: vec![0.0; 4],
            surrogate_std: vec![0.7; 4],
            mean: vec![0.0; 4],
            std: vec![1.0; 4],
        },
        Problem {
            name: "half as wide in x0 and x3, 10 parameters",
            model: Box::new(standard_normal),
            surrogate_mean: vec![0.0; 10],
            surrogate_std: half(10, &[0, 3]),
            mean: vec![0.0; 10],
            std: vec![1.0; 10],
        },
        Problem {
            name: "0.2 std off and 1.05 as wide, 10 parameters",
            model: Box::new(standard_normal),
            surrogate_mean: vec![0.2; 10],
            surrogate_std: vec![1.05; 10],
            mean: vec![0.0; 10],
            std: vec![1.0; 10],
        },
        Problem {
            name: "0.1 std off and 0.95 as wide, 10 parameters",
            model: Box::new(standard_normal),
            surrogate_mean: vec![0.1; 10],
            surrogate_std: vec![0.95; 10],
            mean: vec![0.0; 10],
            std: vec![1.0; 10],
        },
    ]
}

#[test]
fn the_model_posterior_is_certified_and_right_on_varied_problems() {
    let mut statistics = 0;
    let mut sum_of_squares = 0.0;
    for problem in problems() {
        let d = problem.mean.len();
        let space = ParameterSpace::new(
            (0..d)
                .map(|k| Parameter {
                    name: format!("x{k}"),
                    prior: Prior::Uniform(-10.0, 10.0),
                })
                .collect(),
        )
        .unwrap();
        let (sm, ss) = (
            problem.surrogate_mean.clone(),
            problem.surrogate_std.clone(),
        );
        let surrogate = FnLikelihood::new(d, move |x: &[f64]| {
            -0.5 * x
                .iter()
                .zip(&sm)
                .zip(&ss)
                .map(|((x, m), s)| ((x - m) / s).powi(2))
                .sum::<f64>()
        });
        let mut rng = stream(7, 1, 0);
        let samples: Vec<Vec<f64>> = (0..4000)
            .map(|_| {
                problem
                    .surrogate_mean
                    .iter()
                    .zip(&problem.surrogate_std)
                    .map(|(m, s)| {
                        let z: f64 = StandardNormal.sample(&mut rng);
                        m + s * z
                    })
                    .collect()
            })
            .collect();
        let log_likelihood: Vec<f64> = surrogate
            .log_likelihood_batch(&samples)
            .unwrap()
            .into_iter()
            .map(|v| v.unwrap())
            .collect();
        let log_prior: Vec<f64> = samples
            .iter()
            .map(|s| space.log_prior(s).unwrap())
            .collect();
        // The surrogate's evidence: Π_k s_k·√(2π)/20 (the uniform prior's density 1/20 per axis).
        let log_evidence = problem
            .surrogate_std
            .iter()
            .map(|s| (s * (2.0 * std::f64::consts::PI).sqrt() / 20.0).ln())
            .sum();
        let model_density = &problem.model;
        let model = FnLikelihood::new(d, |x: &[f64]| model_density(x));
        for seed in 1..=4 {
            let settings = ModelPosteriorSettings {
                samples: 300,
                seed,
                ..Default::default()
            };
            let population = SurrogatePopulation {
                samples: &samples,
                log_likelihood: &log_likelihood,
                log_prior: &log_prior,
                log_evidence,
            };
            let result = iuq_basis::model_posterior(
                &space,
                population,
                &surrogate,
                &model,
                &settings,
                &mut |_: &iuq_basis::ModelPosteriorEvent<'_>| iuq_core::Control::Continue,
            )
            .unwrap();
            let what = format!("{}, seed {seed}", problem.name);
            println!(
                "{what}: {} model evaluations, {} stages, {} corrections, both batches {}",
                result.model_evaluations,
                result.stages.len(),
                result.corrections.len(),
                result.both_batches
            );
            assert!(result.certified(), "{what}: {}", result.stop);
            for k in 0..d {
                let (m, s) = (result.mean[k], result.std[k]);
                let (em, es) = (result.mcse_mean[k], result.mcse_std[k]);
                println!(
                    "  x{k} mean {m:.4} ± {em:.4} (exact {:.4}), std {s:.4} ± {es:.4} (exact {:.4})",
                    problem.mean[k], problem.std[k]
                );
                assert!(
                    em < 0.15 * problem.std[k] && es < 0.15 * problem.std[k],
                    "{what}: MCSE too large to test"
                );
                assert!(
                    (m - problem.mean[k]).abs() <= 4.5 * em,
                    "{what}: mean of x{k}"
                );
                assert!(
                    (s - problem.std[k]).abs() <= 4.5 * es,
                    "{what}: std of x{k}"
                );
                statistics += 2;
                sum_of_squares += ((m - problem.mean[k]) / em).powi(2);
                sum_of_squares += ((s - problem.std[k]) / es).powi(2);
            }
        }
    }
    assert_eq!(statistics, 496);
    let rms = (sum_of_squares / statistics as f64).sqrt();
    println!("errors' root-mean-square in MCSE units: {rms:.3}");
    assert!(
        (0.7..=1.4).contains(&rms),
        "the Monte Carlo standard errors are off: RMS {rms}"
    );
}
