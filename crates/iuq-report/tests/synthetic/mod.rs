//! A small synthetic calibration study for the report's tests and the demo example: an RBC-like
//! elongation-index curve EL(τ) with two model parameters and a modelling error, posterior
//! samples from a seeded random generator, one or two sources.

use iuq_report::{
    CellPortrait, CellPortraits, CheckedPoint, ComparedParameter, ComparedTraces, Convergence,
    ConvergenceRound, DataSeries, ElongationTrace, FailureMapPanel, GpDiagnostic, MapRunsAtPoint,
    MismatchTest, ModelPosteriorReport, ModelPosteriorStageRow, ParameterSummary,
    PosteriorCheckReport, PosteriorResult, PropagatedOutput, RunStatistics, RunsAtPoint,
    SamplerStage, SensitivityIndex, SensitivityResult, StudyReport,
};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rand_xoshiro::Xoshiro256PlusPlus;

/// The toy model: EL(τ) = 0.68 τ / (τ + kLink/60) − 0.0004 (kBend − 200) / (1 + τ).
pub fn model(stress: f64, k_link: f64, k_bend: f64) -> f64 {
    0.68 * stress / (stress + k_link / 60.0) - 0.0004 * (k_bend - 200.0) / (1.0 + stress)
}

/// Mean, std, quantiles and MAP (the sample nearest the mean, standing in for the density's
/// mode) of one sample column.
fn summary(name: &str, column: &[f64], map: f64) -> ParameterSummary {
    let mut sorted = column.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len() as f64;
    let mean = sorted.iter().sum::<f64>() / n;
    let std = (sorted.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let q = |p: f64| sorted[((p * (n - 1.0)).round() as usize).min(sorted.len() - 1)];
    ParameterSummary {
        name: name.to_string(),
        map,
        mean,
        std,
        q05: q(0.05),
        q50: q(0.5),
        q95: q(0.95),
    }
}

/// One posterior source with `samples` samples around (kLink, kBend) = `centre`.
fn posterior(
    source: &str,
    centre: (f64, f64),
    stresses: &[f64],
    samples: usize,
    rng: &mut Xoshiro256PlusPlus,
) -> PosteriorResult {
    let standard = Normal::new(0.0, 1.0).expect("valid normal");
    let rows: Vec<Vec<f64>> = (0..samples)
        .map(|_| {
            let (a, b): (f64, f64) = (standard.sample(rng), standard.sample(rng));
            let k_link = centre.0 + 9.0 * a;
            let k_bend = centre.1 + 35.0 * (0.7 * a + 0.71 * b);
            let sigma_m = (0.012 + 0.003 * standard.sample(rng)).abs();
            vec![k_link, k_bend, sigma_m]
        })
        .collect();
    let parameters = ["kLink", "kBend", "sigma_m"];
    let column = |p: usize| rows.iter().map(|r| r[p]).collect::<Vec<_>>();
    let map_row = rows
        .iter()
        .min_by(|a, b| {
            let d = |r: &Vec<f64>| {
                ((r[0] - centre.0) / 9.0).powi(2) + ((r[1] - centre.1) / 35.0).powi(2)
            };
            d(a).total_cmp(&d(b))
        })
        .cloned()
        .expect("samples exist");
    let summary = parameters
        .iter()
        .enumerate()
        .map(|(p, name)| summary(name, &column(p), map_row[p]))
        .collect();
    let propagated = stresses
        .iter()
        .map(|&x| PropagatedOutput {
            x,
            samples: rows.iter().map(|r| model(x, r[0], r[1])).collect(),
            map_prediction: model(x, map_row[0], map_row[1]),
        })
        .collect();
    let stages = (0..6)
        .map(|k| SamplerStage {
            stage: k,
            annealing_exponent: if k == 5 {
                1.0
            } else {
                (k as f64 / 5.0).powi(3)
            },
            cv: if k == 0 {
                0.0
            } else {
                1.0 + 0.1 * rng.random::<f64>()
            },
            acceptance: if k == 0 {
                1.0
            } else {
                0.2 + 0.2 * rng.random::<f64>()
            },
            log_evidence: -40.0 + 50.0 * (1.0 - (-(k as f64)).exp()),
            evaluations: samples,
            seconds: 0.5 + rng.random::<f64>(),
        })
        .collect();
    PosteriorResult {
        source: source.to_string(),
        summary,
        log_evidence: 9.873,
        samples: rows,
        stages,
        propagated,
    }
}

/// A synthetic study at the given stresses, with `sources` posterior sources (1: the GP
/// surrogate, 2: also the cell model) of `samples` samples each.
pub fn synthetic_report(
    stresses: &[f64],
    sources: usize,
    samples: usize,
    seed: u64,
) -> StudyReport {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let truth = (120.0, 210.0);
    let y: Vec<f64> = stresses
        .iter()
        .map(|&x| model(x, truth.0, truth.1) + 0.004 * (rng.random::<f64>() - 0.5))
        .collect();
    let y_err: Vec<f64> = stresses
        .iter()
        .map(|_| 0.003 + 0.003 * rng.random::<f64>())
        .collect();
    let mut posteriors = vec![posterior(
        "GP surrogate",
        (118.0, 205.0),
        stresses,
        samples,
        &mut rng,
    )];
    if sources > 1 {
        posteriors.push(posterior(
            "cell model",
            (124.0, 190.0),
            stresses,
            samples,
            &mut rng,
        ));
    }
    let mut sensitivity = Vec::new();
    for &x in stresses {
        for source in ["model runs", "surrogate"] {
            let share = 0.55 + 0.35 * (x / (x + 2.0));
            let noise = |rng: &mut Xoshiro256PlusPlus| 0.03 * (rng.random::<f64>() - 0.5);
            let index = |parameter: &str, s1: f64, rng: &mut Xoshiro256PlusPlus| {
                let s1 = s1 + noise(rng);
                let st = s1 + 0.04 + noise(rng).abs();
                SensitivityIndex {
                    parameter: parameter.to_string(),
                    first_order: s1,
                    first_order_low: s1 - 0.05,
                    first_order_high: s1 + 0.05,
                    total: st,
                    total_low: st - 0.04,
                    total_high: st + 0.06,
                }
            };
            let indices = vec![
                index("kLink", share, &mut rng),
                index("kBend", 0.92 - share, &mut rng),
            ];
            sensitivity.push(SensitivityResult {
                output_label: format!("EL at {x} Pa"),
                x,
                source: source.to_string(),
                indices,
            });
        }
    }
    let gp_diagnostics = stresses
        .iter()
        .map(|&x| {
            let simulated: Vec<f64> = (0..30)
                .map(|_| {
                    model(
                        x,
                        40.0 + 250.0 * rng.random::<f64>(),
                        50.0 + 350.0 * rng.random::<f64>(),
                    )
                })
                .collect();
            let predicted_std: Vec<f64> = (0..30)
                .map(|_| 0.002 + 0.004 * rng.random::<f64>())
                .collect();
            let predicted = simulated
                .iter()
                .zip(&predicted_std)
                .map(|(s, sd)| s + sd * (rng.random::<f64>() - 0.5) * 2.0)
                .collect();
            GpDiagnostic {
                output_label: format!("EL at {x} Pa"),
                x,
                q2: 0.99 - 0.01 * rng.random::<f64>(),
                loo_q2: 0.985 - 0.01 * rng.random::<f64>(),
                simulated,
                predicted,
                predicted_std,
                hyperparameters: vec![
                    (
                        "signal variance".to_string(),
                        0.02 + 0.01 * rng.random::<f64>(),
                    ),
                    (
                        "length scale kLink".to_string(),
                        80.0 + 40.0 * rng.random::<f64>(),
                    ),
                    (
                        "length scale kBend".to_string(),
                        300.0 + 100.0 * rng.random::<f64>(),
                    ),
                    (
                        "noise variance".to_string(),
                        1e-6 * (1.0 + rng.random::<f64>()),
                    ),
                ],
            }
        })
        .collect();
    let posterior_check = PosteriorCheckReport {
        source: "GP surrogate".to_string(),
        samples: 20,
        diagnostic: Some("EL drift over the window".to_string()),
        test: "Test (family-wise significance 0.01): passed.".to_string(),
        points: stresses
            .iter()
            .zip(&y)
            .map(|(&x, &el)| {
                let model: Vec<f64> = (0..20)
                    .map(|_| el + 0.01 * (rng.random::<f64>() - 0.5))
                    .collect();
                let surrogate: Vec<f64> = model
                    .iter()
                    .map(|m| m + 0.004 * (rng.random::<f64>() - 0.5))
                    .collect();
                let diagnostic: Vec<f64> = (0..21)
                    .map(|_| 0.01 * x / 9.0 * rng.random::<f64>())
                    .collect();
                let mut abs: Vec<f64> = diagnostic.iter().map(|d| d.abs()).collect();
                abs.sort_by(f64::total_cmp);
                let rmse = (model
                    .iter()
                    .zip(&surrogate)
                    .map(|(m, s)| (m - s).powi(2))
                    .sum::<f64>()
                    / 20.0)
                    .sqrt();
                CheckedPoint {
                    x,
                    map_model: Some((el + 0.002, 0.003)),
                    map_surrogate: (el, 0.002),
                    surrogate_std: vec![0.002; 20],
                    model_std: vec![0.003; 20],
                    model,
                    surrogate,
                    diagnostic_median_abs: Some(abs[10]),
                    diagnostic_largest_abs: Some(abs[20]),
                    diagnostic,
                    failed: 0,
                    rmse,
                    within_two_std: 0.95,
                }
            })
            .collect(),
    };
    StudyReport {
        two_fidelity: Vec::new(),
        two_fidelity_components: Vec::new(),
        title: "RBC calibration — healthy cells (synthetic)".to_string(),
        study_name: "rbc-healthy-synthetic".to_string(),
        provenance: vec![
            ("iuq version".to_string(), "0.1.0".to_string()),
            (
                "command".to_string(),
                "iuq pipeline examples/rbc-healthy-hemocell.toml --out report".to_string(),
            ),
            ("seed".to_string(), seed.to_string()),
            ("date".to_string(), "2025-01-01T00:00:00Z".to_string()),
            (
                "study file hash".to_string(),
                "sha256:0123456789abcdef".to_string(),
            ),
        ],
        parameters: vec![
            "kLink".to_string(),
            "kBend".to_string(),
            "sigma_m".to_string(),
        ],
        data: DataSeries {
            x_label: "shear stress (Pa)".to_string(),
            y_label: "elongation index EL (–)".to_string(),
            x: stresses.to_vec(),
            y: y.clone(),
            y_err,
        },
        posteriors,
        sensitivity,
        gp_diagnostics,
        run_statistics: RunStatistics {
            runs: 120,
            succeeded: 114,
            failed: 6,
            failures_by_reason: vec![("timeout".to_string(), 4), ("diverged".to_string(), 2)],
            stage_seconds: vec![
                ("design".to_string(), 0.31),
                ("model runs".to_string(), 3600.5),
                ("GP fit".to_string(), 12.25),
                ("Sobol' indices".to_string(), 4.125),
                ("BASIS sampling".to_string(), 35.2),
            ],
        },
        convergence: None,
        failure_map: Vec::new(),
        runs_per_point: Vec::new(),
        posterior_check: Some(posterior_check),
        model_posterior: Some(ModelPosteriorReport {
            surrogate_source: "GP surrogate".to_string(),
            model_source: "cell model".to_string(),
            certified: true,
            stop: "certified: every stage's k̂ is below its threshold".to_string(),
            samples: 200,
            pareto_k: 0.31,
            pareto_k_threshold: 0.565,
            effective_sample_size: 151.5,
            ancestors: 200,
            model_runs: 1600,
            failures: 2,
            corrections: 1,
            probe_pairs: 4,
            irregular_outputs: vec!["y_3".into()],
            pseudo_marginal: true,
            proposal_mismatch: Some(MismatchTest {
                mean_shift: 0.42,
                spread_divergence: 0.061,
                p_value: 0.002,
                level: 0.01,
                widening: 1.2,
                corrected: true,
            }),
            correction_not_made: None,
            correction_moment_matched: false,
            correction_tempering: None,
            correction_defensive_normal: false,
            both_batches: true,
            paired: false,
            corrections_refused: Vec::new(),
            replicates: 4,
            parameters: ["kLink", "kBend", "sigma_m"]
                .iter()
                .enumerate()
                .map(|(k, name)| {
                    let s = (10.0 + k as f64, 12.0 + k as f64, 2.0);
                    let m = (11.0 + k as f64, 12.5 + k as f64, 2.5);
                    ComparedParameter {
                        name: name.to_string(),
                        surrogate: s,
                        model: m,
                        relative_difference: (
                            Some((m.0 - s.0) / s.0),
                            Some((m.1 - s.1) / s.1),
                            Some((m.2 - s.2) / s.2),
                        ),
                        mcse: (0.2, 0.15),
                    }
                })
                .collect(),
            log_weights: (0..198).map(|i| -0.5 * (i as f64 / 40.0).powi(2)).collect(),
            stages: vec![ModelPosteriorStageRow {
                stage: 1,
                beta: 1.0,
                cv: 0.4,
                pareto_k: 0.31,
                effective_sample_size: 151.5,
                model_evaluations: 200,
                acceptance: None,
                spread_ratio: 1.04,
            }],
            map_runs: stresses
                .iter()
                .zip(&y)
                .map(|(&x, &el)| {
                    MapRunsAtPoint::new(x, (el, 0.01), Some(el + 0.01), Some(el - 0.003))
                })
                .collect(),
        }),
        cell_portraits: Some(CellPortraits {
            source: "the cell model posterior's MAP".to_string(),
            portraits: stresses
                .iter()
                .map(|&x| {
                    let el = 0.1 + 0.05 * x;
                    let (a, b) = (4.0 * (1.0 + el), 4.0 * (1.0 - el));
                    let ring = |rx: f64, ry: f64| -> Vec<[f64; 2]> {
                        (0..40)
                            .map(|i| {
                                let t = i as f64 / 40.0 * std::f64::consts::TAU;
                                [rx * t.cos(), ry * t.sin()]
                            })
                            .collect()
                    };
                    CellPortrait {
                        x,
                        elongation_index: (el, 0.002),
                        trace: elongation_trace(el),
                        window: (7.5, 9.375),
                        outline: ring(a, b),
                        ellipse: [0.0, 0.0, a, b, 0.1],
                        side: ring(a, 1.2),
                    }
                })
                .collect(),
            compared: Some(ComparedTraces {
                source: "the GP surrogate posterior's MAP".to_string(),
                traces: stresses
                    .iter()
                    .map(|&x| {
                        let el = 0.11 + 0.05 * x;
                        ElongationTrace {
                            x,
                            elongation_index: (el, 0.002),
                            trace: elongation_trace(el),
                        }
                    })
                    .collect(),
            }),
        }),
    }
}

/// A toy run's elongation index against strain, rising to `el`.
fn elongation_trace(el: f64) -> Vec<(f64, f64)> {
    (0..60)
        .map(|i| {
            let strain = i as f64 * 0.16;
            (strain, el * (1.0 - (-strain).exp()))
        })
        .collect()
}

/// The toy model's probability of failure: likely where kLink is small and kBend large.
fn failure_probability(k_link: f64, k_bend: f64) -> f64 {
    1.0 / (1.0 + (-(k_bend / 40.0 - k_link / 20.0 - 2.0)).exp())
}

/// One failure-map panel over (kLink, kBend): `initial` runs spread over the prior ranges and
/// `adaptive` runs near the posterior, failing at random with the toy failure probability,
/// over that probability on a `grid` × `grid` grid (no grid when `grid` is 0).
fn failure_panel(
    label: &str,
    initial: usize,
    adaptive: usize,
    grid: usize,
    rng: &mut Xoshiro256PlusPlus,
) -> FailureMapPanel {
    let bounds = (40.0, 290.0, 50.0, 400.0);
    let mut points = Vec::new();
    let mut is_adaptive = Vec::new();
    for k in 0..initial + adaptive {
        let point = if k < initial {
            (
                bounds.0 + (bounds.1 - bounds.0) * rng.random::<f64>(),
                bounds.2 + (bounds.3 - bounds.2) * rng.random::<f64>(),
            )
        } else {
            (
                118.0 + 40.0 * (rng.random::<f64>() - 0.5),
                205.0 + 120.0 * (rng.random::<f64>() - 0.5),
            )
        };
        points.push(point);
        is_adaptive.push(k >= initial);
    }
    let failed = points
        .iter()
        .map(|&(x, y)| rng.random::<f64>() < failure_probability(x, y))
        .collect();
    let mut probability = Vec::with_capacity(grid * grid);
    for row in 0..grid {
        for column in 0..grid {
            let x = bounds.0 + (column as f64 + 0.5) / grid as f64 * (bounds.1 - bounds.0);
            let y = bounds.2 + (row as f64 + 0.5) / grid as f64 * (bounds.3 - bounds.2);
            probability.push(failure_probability(x, y));
        }
    }
    FailureMapPanel {
        label: label.to_string(),
        x_parameter: "kLink".to_string(),
        y_parameter: "kBend".to_string(),
        bounds,
        points,
        failed,
        adaptive: is_adaptive,
        failure_probability: probability,
        grid_size: (grid, grid),
    }
}

/// Adds an adaptive design's results to `report`: `rounds` rounds of 12 new runs after 40
/// initial ones, converging; `panels` failure-map panels (the second without a probability
/// grid); the runs per data point.
pub fn add_adaptive_results(report: &mut StudyReport, rounds: usize, panels: usize, seed: u64) {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let parameters = vec![
        "kLink".to_string(),
        "kBend".to_string(),
        "sigma_m".to_string(),
    ];
    let target = [118.0, 205.0, 0.012];
    let spread = [9.0, 35.0, 0.003];
    let rounds: Vec<ConvergenceRound> = (0..rounds)
        .map(|r| {
            let decay = 0.25f64.powi(r as i32);
            let noise = |rng: &mut Xoshiro256PlusPlus| 2.0 * rng.random::<f64>() - 1.0;
            ConvergenceRound {
                round: r + 1,
                runs: 40 + 12 * r,
                new_runs: if r + 1 == rounds { 0 } else { 12 },
                mean: (0..3)
                    .map(|p| target[p] + 1.5 * spread[p] * decay * noise(&mut rng))
                    .collect(),
                std: (0..3).map(|p| spread[p] * (1.0 + 1.2 * decay)).collect(),
                shift: (r > 0).then_some(1.2 * decay),
                shift_noise: (r > 0).then_some(0.05),
                surrogate_error: Some(0.5 * decay),
                log_likelihood_std: 2.4 * decay,
                extrapolation_share: 0.3 * decay,
                mixing_level: u32::from(r > 0),
                sampler_disagreement: Some(if r == 0 { 0.4 } else { 0.02 * decay }),
            }
        })
        .collect();
    report.convergence = Some(Convergence {
        criterion: "every posterior mean and std moves by less than 0.1 posterior stds between rounds beyond the sampler's noise, and the surrogate's error could move none by more than 0.1 posterior stds".to_string(),
        converged: true,
        stop_reason: "the convergence rule was met".to_string(),
        parameters,
        rounds,
        retrained_checks: vec!["After round 3 the model at the posterior (21 runs) failed the check's test at 6.19: its runs became training runs and the rounds went on.".to_string()],
    });
    report.failure_map = (0..panels)
        .map(|k| {
            let grid = if k == 1 { 0 } else { 40 };
            failure_panel(
                &format!("runs at {} Pa", report.data.x[k % report.data.x.len()]),
                40,
                24,
                grid,
                &mut rng,
            )
        })
        .collect();
    report.runs_per_point = report
        .data
        .x
        .iter()
        .map(|&x| RunsAtPoint {
            x,
            runs: 64,
            adaptive: 24,
            failed: 5,
        })
        .collect();
}
