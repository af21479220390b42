//! The model posterior from a surrogate's (`iuq_basis::model_posterior`) on problems whose
//! model posterior is known exactly: Gaussian likelihoods on a wide uniform prior (the
//! truncation is below 1e-20), surrogates that are biased, too narrow, or that ignore where the
//! model fails.
//!
//! The surrogate population is an exact i.i.d. sample of the surrogate's posterior (drawn
//! directly, so that the test measures this method, not the sampler that produced it).
//!
//! Tolerances: each posterior mean and std is held to 4 of its own Monte Carlo standard errors
//! (the estimator's spread; 4σ keeps the family of 2–4 parameters × 2 statistics per test below
//! a 1e-3 chance of a false failure), and the MCSE itself must be small against the posterior
//! std, so that the test can fail.

use iuq_basis::{
    FnLikelihood, LogLikelihood, ModelPosterior, ModelPosteriorEvent, ModelPosteriorSettings,
    ModelPosteriorStop, SurrogatePopulation, Tempering, model_posterior, pareto_k_threshold,
    resume_model_posterior,
};
use iuq_core::random::stream;
use iuq_core::{Control, Parameter, ParameterSpace, Prior};
use rand_distr::{Distribution, StandardNormal};

fn space(d: usize) -> ParameterSpace {
    ParameterSpace::new(
        (0..d)
            .map(|k| Parameter {
                name: format!("x{k}"),
                prior: Prior::Uniform(-10.0, 10.0),
            })
            .collect(),
    )
    .unwrap()
}

/// ln N(x; mean, diag(std²)) up to a constant.
fn gaussian(mean: Vec<f64>, std: Vec<f64>) -> impl Fn(&[f64]) -> f64 + Send + Sync {
    move |x: &[f64]| {
        -0.5 * x
            .iter()
            .zip(&mean)
            .zip(&std)
            .map(|((x, m), s)| ((x - m) / s).powi(2))
            .sum::<f64>()
    }
}

/// `n` exact draws of N(mean, diag(std²)) with their log-likelihood under `surrogate`.
fn population(
    n: usize,
    mean: &[f64],
    std: &[f64],
    surrogate: &dyn LogLikelihood,
    space: &ParameterSpace,
) -> (Vec<Vec<f64>>, Vec<f64>, Vec<f64>) {
    seeded_population(7, n, mean, std, surrogate, space)
}

/// [`population`] drawn from the stream of `seed`.
fn seeded_population(
    seed: u64,
    n: usize,
    mean: &[f64],
    std: &[f64],
    surrogate: &dyn LogLikelihood,
    space: &ParameterSpace,
) -> (Vec<Vec<f64>>, Vec<f64>, Vec<f64>) {
    let mut rng = stream(seed, 1, 0);
    let samples: Vec<Vec<f64>> = (0..n)
        .map(|_| {
            mean.iter()
                .zip(std)
                .map(|(m, s)| {
                    let z: f64 = StandardNormal.sample(&mut rng);
                    m + s * z
                })
                .collect()
        })
        .collect();
    let ll = surrogate
        .log_likelihood_batch(&samples)
        .unwrap()
        .into_iter()
        .map(|v| v.unwrap())
        .collect();
    let lp = samples
        .iter()
        .map(|s| space.log_prior(s).unwrap())
        .collect();
    (samples, ll, lp)
}

/// [`gaussian`] as a model that counts its evaluations in `calls`.
fn counted_gaussian<'a>(
    mean: &[f64],
    std: &[f64],
    calls: &'a std::sync::atomic::AtomicUsize,
) -> FnLikelihood<impl Fn(&[f64]) -> f64 + Send + Sync + 'a> {
    let f = gaussian(mean.to_vec(), std.to_vec());
    FnLikelihood::new(mean.len(), move |x: &[f64]| {
        calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        f(x)
    })
}

fn run(
    d: usize,
    surrogate_mean: &[f64],
    surrogate_std: &[f64],
    model: &dyn LogLikelihood,
    settings: &ModelPosteriorSettings,
) -> ModelPosterior {
    seeded_run(7, d, surrogate_mean, surrogate_std, model, settings)
}

/// [`run`] on the population of `seed`.
fn seeded_run(
    seed: u64,
    d: usize,
    surrogate_mean: &[f64],
    surrogate_std: &[f64],
    model: &dyn LogLikelihood,
    settings: &ModelPosteriorSettings,
) -> ModelPosterior {
    let space = space(d);
    let surrogate = FnLikelihood::new(d, gaussian(surrogate_mean.to_vec(), surrogate_std.to_vec()));
    let (samples, ll, lp) = seeded_population(
        seed,
        4000,
        surrogate_mean,
        surrogate_std,
        &surrogate,
        &space,
    );
    // The surrogate's evidence: Π_k s_k·√(2π)/20 (the uniform prior's density 1/20 per axis).
    let log_evidence = surrogate_std
        .iter()
        .map(|s| (s * (2.0 * std::f64::consts::PI).sqrt() / 20.0).ln())
        .sum();
    let population = SurrogatePopulation {
        samples: &samples,
        log_likelihood: &ll,
        log_prior: &lp,
        log_evidence,
    };
    let mut stages = Vec::new();
    let mut corrections = Vec::new();
    let mut not_made = None;
    let result = model_posterior(
        &space,
        population,
        &surrogate,
        model,
        settings,
        &mut |event: &ModelPosteriorEvent<'_>| {
            match event {
                ModelPosteriorEvent::Stage(s) => stages.push((*s).clone()),
                ModelPosteriorEvent::Correction(c) => {
                    assert!(stages.is_empty(), "a correction comes before every stage");
                    corrections.push((*c).clone())
                }
                ModelPosteriorEvent::CorrectionNotMade(reason) => {
                    not_made = Some(reason.to_string())
                }
                ModelPosteriorEvent::Bridged(state) => {
                    assert_eq!(state.stages(), &stages[..], "a bridge follows its stage")
                }
            }
            Control::Continue
        },
    )
    .unwrap();
    assert_eq!(stages, result.stages, "every stage is reported as it ends");
    assert_eq!(
        corrections, result.corrections,
        "every correction is reported before its batch"
    );
    assert_eq!(
        not_made, result.correction_not_made,
        "a correction not made is reported"
    );
    result
}

fn assert_matches(result: &ModelPosterior, mean: &[f64], std: &[f64], what: &str) {
    for k in 0..mean.len() {
        let (m, s) = (result.mean[k], result.std[k]);
        let (em, es) = (result.mcse_mean[k], result.mcse_std[k]);
        println!(
            "{what}: x{k} mean {m:.4} ± {em:.4} (exact {:.4}), std {s:.4} ± {es:.4} (exact {:.4})",
            mean[k], std[k]
        );
        assert!(
            em < 0.15 * std[k] && es < 0.15 * std[k],
            "{what}: MCSE too large to test"
        );
        assert!((m - mean[k]).abs() <= 4.0 * em, "{what}: mean of x{k}");
        assert!((s - std[k]).abs() <= 4.0 * es, "{what}: std of x{k}");
    }
}

#[test]
fn a_biased_but_wider_surrogate_is_corrected_in_one_certified_stage() {
    let (mean, std) = (vec![1.0, -2.0, 0.5], vec![0.5, 1.0, 2.0]);
    let model = FnLikelihood::new(3, gaussian(mean.clone(), std.clone()));
    // The surrogate's posterior: shifted by a third of a std, 30 % wider.
    let s_mean: Vec<f64> = mean.iter().zip(&std).map(|(m, s)| m + s / 3.0).collect();
    let s_std: Vec<f64> = std.iter().map(|s| 1.3 * s).collect();
    let settings = ModelPosteriorSettings {
        samples: 400,
        ..Default::default()
    };
    let result = run(3, &s_mean, &s_std, &model, &settings);
    assert_eq!(result.stop, ModelPosteriorStop::Certified);
    assert_eq!(result.stages.len(), 1);
    assert_eq!(result.model_evaluations, 400);
    assert!(result.pareto_k < result.pareto_k_threshold);
    assert!(result.effective_sample_size > 100.0);
    assert_matches(&result, &mean, &std, "biased surrogate");
    // Both likelihoods are unnormalised Gaussians: Z_m/Z_s = Π s_k/(1.3 s_k) = 1.3⁻³. The
    // estimate ln mean exp(r) has sd ≈ CV/√S ≈ 0.5/20 = 0.025: 4 of those.
    let exact_ratio = -3.0 * 1.3f64.ln();
    println!(
        "ln Z ratio {} (exact {exact_ratio})",
        result.log_evidence_ratio
    );
    assert!((result.log_evidence_ratio - exact_ratio).abs() < 0.1);
    // Without the correction, the surrogate's own mean is 0.33 std off: the test can tell.
    assert!((s_mean[0] - mean[0]).abs() > 4.0 * result.mcse_mean[0]);
}

/// Where the surrogate is nearly the model's posterior (a tenth of a std off, 5 % wider), the
/// estimate is one certified step from the first batch, paired with the surrogate population
/// (`iuq_basis::paired_estimate`). Over 12 populations (4,000 exact draws each, 300 members) the
/// paired means' root-mean-square error, in exact stds, is below half the members' plain
/// weighted means' (equal weights would leave √(300/4000) = 0.27 of it; these weights vary a
/// little), every paired mean and std lies within 4 of its MCSE, and the MCSE is calibrated:
/// the mean errors' z-scores have a root-mean-square within [0.5, 1.6] (a χ² of 36 degrees of
/// freedom lies within [0.6, 1.4] of its mean's square root at 99.9 %).
#[test]
fn a_nearly_exact_surrogate_pairs_the_members_with_its_population() {
    let (mean, std) = (vec![1.0, -2.0, 0.5], vec![0.5, 1.0, 2.0]);
    let model = FnLikelihood::new(3, gaussian(mean.clone(), std.clone()));
    let s_mean: Vec<f64> = mean.iter().zip(&std).map(|(m, s)| m + s / 10.0).collect();
    let s_std: Vec<f64> = std.iter().map(|s| 1.05 * s).collect();
    let settings = ModelPosteriorSettings {
        samples: 300,
        ..Default::default()
    };
    let (mut paired_sq, mut plain_sq, mut z_sq, mut count) = (0.0, 0.0, 0.0, 0.0);
    for seed in 1..=12 {
        let result = seeded_run(seed, 3, &s_mean, &s_std, &model, &settings);
        assert_eq!(result.stop, ModelPosteriorStop::Certified);
        assert_eq!(result.stages.len(), 1);
        let errors = result.paired.as_ref().expect("a paired estimate");
        let w = result.weights();
        for k in 0..3 {
            let plain: f64 = result.samples.iter().zip(&w).map(|(t, w)| w * t[k]).sum();
            let total = errors.population[k].hypot(errors.difference[k]);
            assert!((total - result.mcse_mean[k]).abs() < 1e-12 * std[k]);
            paired_sq += ((result.mean[k] - mean[k]) / std[k]).powi(2);
            plain_sq += ((plain - mean[k]) / std[k]).powi(2);
            z_sq += ((result.mean[k] - mean[k]) / result.mcse_mean[k]).powi(2);
            count += 1.0;
        }
        assert_matches(&result, &mean, &std, &format!("paired, seed {seed}"));
    }
    let (paired, plain, z) = (
        (paired_sq / count).sqrt(),
        (plain_sq / count).sqrt(),
        (z_sq / count).sqrt(),
    );
    println!("RMSE paired {paired:.4} plain {plain:.4} (exact stds); z rms {z:.2}");
    assert!(paired < 0.5 * plain, "paired {paired} plain {plain}");
    assert!((0.5..=1.6).contains(&z), "z rms {z}");
}

#[test]
fn a_surrogate_that_misses_the_tails_is_flagged_and_bridged() {
    let (mean, std) = (vec![0.0, 3.0], vec![1.0, 0.5]);
    let calls = std::sync::atomic::AtomicUsize::new(0);
    let model = counted_gaussian(&mean, &std, &calls);
    // Half as wide as the model's posterior: the weights exp(1.5 z²) have no finite variance.
    let s_std: Vec<f64> = std.iter().map(|s| 0.5 * s).collect();
    let settings = ModelPosteriorSettings {
        samples: 400,
        ..Default::default()
    };
    // One step all the way would not hold: k̂ of the full step's weights.
    let space = space(2);
    let surrogate = FnLikelihood::new(2, gaussian(mean.clone(), s_std.clone()));
    let (samples, ll, _) = population(4000, &mean, &s_std, &surrogate, &space);
    let full: Vec<f64> = samples[..400]
        .iter()
        .zip(&ll)
        .map(|(x, l)| gaussian(mean.clone(), std.clone())(x) - l)
        .collect();
    let k_full = iuq_basis::pareto_smooth(&full).pareto_k;
    assert!(k_full > iuq_basis::pareto_k_threshold(400), "k̂ {k_full}");

    // By default the surrogate is corrected (one more batch of 400) and one stage then holds.
    let result = run(2, &mean, &s_std, &model, &settings);
    println!("corrected: {:#?} {:#?}", result.corrections, result.stages);
    assert_eq!(result.stop, ModelPosteriorStop::Certified);
    assert_eq!(result.corrections.len(), 1);
    assert!(result.corrections[0].pareto_k_before > result.pareto_k_threshold);
    assert_eq!(result.model_evaluations, 800);
    // Both batches, weighed as one sample of the mixture of the two posteriors, hold at once:
    // 800 members, no bridge.
    assert!(result.both_batches);
    assert_eq!(result.samples.len(), 800);
    assert_eq!(result.stages.len(), 1);
    assert_matches(&result, &mean, &std, "narrow surrogate, corrected");
    // The model's evidence: Z_m/Z_s = Π s_k/(0.5 s_k) = 4 (ln 4 = 1.386), within the
    // estimate's spread (CV/√S with CV ≲ 1: 0.05; 4 of those).
    println!("ln Z ratio {}", result.log_evidence_ratio);
    assert!((result.log_evidence_ratio - 4f64.ln()).abs() < 0.2);

    // Without corrections the tempering bridges: more stages, each moving every member.
    calls.store(0, std::sync::atomic::Ordering::Relaxed);
    let bridged = run(
        2,
        &mean,
        &s_std,
        &model,
        &ModelPosteriorSettings {
            corrections: 0,
            ..settings
        },
    );
    println!("bridged: {:#?}", bridged.stages);
    assert_eq!(bridged.stop, ModelPosteriorStop::Certified);
    assert!(bridged.corrections.is_empty());
    assert!(bridged.stages.len() > 1, "bridged");
    // The bridges' resampling leaves fewer distinct ancestors than members; the standard
    // errors are summed within their groups.
    assert!(
        bridged.ancestors > 1 && bridged.ancestors < bridged.samples.len(),
        "{}",
        bridged.ancestors
    );
    assert_eq!(
        result.ancestors,
        result.samples.len(),
        "no bridge: every member its own"
    );
    assert!(bridged.stages[0].pareto_k <= bridged.pareto_k_threshold);
    // Each step is the CV rule's (the target CV of its weights: `cv_target` 1 for the first,
    // `bridge_cv_target` 0.5 after a bridge, less where it reaches β = 1), halved until k̂
    // holds: here the first stage's rule step was too long for k̂ and was halved once.
    for (k, stage) in bridged.stages.iter().enumerate() {
        let halvings = (stage.cv_step / stage.step).log2();
        assert!(
            (halvings - halvings.round()).abs() < 1e-9 && halvings.round() >= 0.0,
            "stage {k}: step {} against the rule's {}",
            stage.step,
            stage.cv_step
        );
        let target = if k == 0 { 1.0 } else { 0.5 };
        if stage.step == stage.cv_step && stage.beta < 1.0 {
            assert!(
                (stage.cv - target).abs() < 1e-6,
                "stage {k}: CV {}",
                stage.cv
            );
        } else {
            assert!(stage.cv < target, "stage {k}: CV {}", stage.cv);
        }
        assert!(stage.pareto_k <= bridged.pareto_k_threshold, "stage {k}");
    }
    assert_eq!(bridged.stages[0].step, bridged.stages[0].cv_step / 2.0);
    for stage in &bridged.stages[1..] {
        let (screen, confirm) = (
            stage.screen_acceptance.unwrap(),
            stage.confirm_acceptance.unwrap(),
        );
        assert!(screen > 0.05 && confirm > 0.05, "{stage:?}");
    }
    // Every model evaluation is counted.
    assert_eq!(
        bridged.model_evaluations,
        calls.load(std::sync::atomic::Ordering::Relaxed)
    );
    assert_matches(&bridged, &mean, &std, "narrow surrogate, bridged");
}

/// The state between two stages, written as JSON after a bridge and read back, goes on to the
/// uninterrupted run's posterior bit for bit, without the bridges before it (only the first
/// batch is asked of the model again, as a rerun asks a campaign store); a state of another
/// run is refused.
#[test]
fn a_tempering_resumed_from_its_checkpoint_ends_where_the_uninterrupted_run_did() {
    let (mean, std) = (vec![0.0, 3.0], vec![1.0, 0.5]);
    let s_std: Vec<f64> = std.iter().map(|s| 0.5 * s).collect();
    let calls = std::sync::atomic::AtomicUsize::new(0);
    let model = counted_gaussian(&mean, &std, &calls);
    let settings = ModelPosteriorSettings {
        samples: 400,
        corrections: 0,
        ..Default::default()
    };
    let space = space(2);
    let surrogate = FnLikelihood::new(2, gaussian(mean.clone(), s_std.clone()));
    let (samples, ll, lp) = seeded_population(7, 4000, &mean, &s_std, &surrogate, &space);
    let population = || SurrogatePopulation {
        samples: &samples,
        log_likelihood: &ll,
        log_prior: &lp,
        log_evidence: 0.0,
    };
    let mut checkpoints: Vec<String> = Vec::new();
    let whole = model_posterior(
        &space,
        population(),
        &surrogate,
        &model,
        &settings,
        &mut |event: &ModelPosteriorEvent<'_>| {
            if let ModelPosteriorEvent::Bridged(state) = event {
                checkpoints.push(serde_json::to_string(state).unwrap());
            }
            Control::Continue
        },
    )
    .unwrap();
    assert!(whole.certified(), "{}", whole.stop);
    assert!(whole.stages.len() >= 3, "{:#?}", whole.stages);
    assert_eq!(checkpoints.len(), whole.stages.len() - 1, "one per bridge");

    let first: Tempering = serde_json::from_str(&checkpoints[0]).unwrap();
    assert_eq!(first.stages(), &whole.stages[..1]);
    assert!(first.beta() > 0.0 && first.beta() < 1.0);
    calls.store(0, std::sync::atomic::Ordering::Relaxed);
    let resumed = resume_model_posterior(
        &space,
        population(),
        &surrogate,
        &model,
        &settings,
        first.clone(),
        &mut |_: &ModelPosteriorEvent<'_>| Control::Continue,
    )
    .unwrap();
    assert_eq!(resumed, whole);
    assert_eq!(
        calls.load(std::sync::atomic::Ordering::Relaxed),
        400 + whole.model_evaluations - first.model_evaluations(),
        "the first batch again, then only the bridges after the checkpoint"
    );

    // Refused: another member count (before any model run), another population of the same
    // size, other settings, and a state whose parts do not fit together.
    let refused = |result: Result<ModelPosterior, iuq_basis::BasisError>, what: &str| {
        assert!(
            matches!(result, Err(iuq_basis::BasisError::CheckpointMismatch(_))),
            "{what}: {result:?}"
        );
    };
    calls.store(0, std::sync::atomic::Ordering::Relaxed);
    let resume = |population: SurrogatePopulation<'_>,
                  settings: &ModelPosteriorSettings,
                  checkpoint: Tempering| {
        resume_model_posterior(
            &space,
            population,
            &surrogate,
            &model,
            settings,
            checkpoint,
            &mut |_: &ModelPosteriorEvent<'_>| Control::Continue,
        )
    };
    let fewer = ModelPosteriorSettings {
        samples: 300,
        ..settings.clone()
    };
    refused(resume(population(), &fewer, first.clone()), "300 members");
    assert_eq!(calls.load(std::sync::atomic::Ordering::Relaxed), 0);
    let (samples8, ll8, lp8) = seeded_population(8, 4000, &mean, &s_std, &surrogate, &space);
    let another = SurrogatePopulation {
        samples: &samples8,
        log_likelihood: &ll8,
        log_prior: &lp8,
        log_evidence: 0.0,
    };
    refused(
        resume(another, &settings, first.clone()),
        "another population",
    );
    let reseeded = ModelPosteriorSettings {
        seed: settings.seed + 1,
        ..settings.clone()
    };
    refused(
        resume(population(), &reseeded, first.clone()),
        "another seed",
    );
    let mut corrupt: serde_json::Value = serde_json::from_str(&checkpoints[0]).unwrap();
    corrupt["ancestor"][0] = serde_json::json!(100_000);
    let corrupt: Tempering = serde_json::from_value(corrupt).unwrap();
    refused(
        resume(population(), &settings, corrupt),
        "an ancestor out of range",
    );
}

/// Stopped short of β = 1 (`max_stages = 1`, no correction) the result says so: not certified,
/// the β its one stage reached, and the final weights those of the rest of the way in one step
/// from the population's β (here 0), whose k̂ — the full step's, which does not hold — is the
/// one reported. The stage record keeps the step the stage took.
#[test]
fn a_model_posterior_stopped_short_is_not_certified_and_reports_the_remaining_step() {
    let (mean, std) = (vec![0.0, 3.0], vec![1.0, 0.5]);
    let model = FnLikelihood::new(2, gaussian(mean.clone(), std.clone()));
    let s_std: Vec<f64> = std.iter().map(|s| 0.5 * s).collect();
    let settings = ModelPosteriorSettings {
        samples: 400,
        corrections: 0,
        max_stages: 1,
        ..Default::default()
    };
    let result = run(2, &mean, &s_std, &model, &settings);
    println!("{:#?} k̂ {}", result.stages, result.pareto_k);
    assert!(!result.certified());
    assert_eq!(result.stages.len(), 1);
    let reached = result.stages[0].beta;
    assert!(reached > 0.0 && reached < 1.0, "β {reached}");
    assert_eq!(result.stop, ModelPosteriorStop::MaxStages { beta: reached });
    assert!(result.stop.to_string().starts_with("not certified"));
    // The stage itself held; the weights of the remaining step do not.
    assert!(result.stages[0].pareto_k <= result.pareto_k_threshold);
    assert!(
        result.pareto_k > result.pareto_k_threshold,
        "k̂ {} of the remaining step",
        result.pareto_k
    );
    assert_eq!(result.model_evaluations, 400);
}

/// A surrogate that misses a side lobe of the model's posterior: the model's likelihood is the
/// mixture 0.75·N((0, 0), I) + 0.25·N((3, 0), 0.5²·I), the surrogate's the main mode alone,
/// N((0, 0), I), whose posterior puts 2 % of its mass where the model's puts 25 %. The full
/// step's k̂ flags it; the method recovers the lobe, by the default correction and, without
/// one, by bridging, within 4 MCSE of the exact moments (x0: mean 0.75, std √2.5; x1: mean 0,
/// std √0.8125).
#[test]
fn a_surrogate_that_misses_a_side_lobe_is_flagged_and_the_lobe_recovered() {
    let lobe = |x: &[f64]| {
        let main = -0.5 * (x[0] * x[0] + x[1] * x[1]);
        let side = -0.5 * (((x[0] - 3.0) / 0.5).powi(2) + (x[1] / 0.5).powi(2));
        // 0.75·N(0, I) + 0.25·N((3, 0), 0.25·I): the lobe's density carries 1/0.25 for its stds.
        let (a, b) = (0.75f64.ln() + main, 0.25f64.ln() - 2.0 * 0.5f64.ln() + side);
        let top = a.max(b);
        top + ((a - top).exp() + (b - top).exp()).ln()
    };
    let model = FnLikelihood::new(2, lobe);
    let (mean, std) = (vec![0.75, 0.0], vec![2.5f64.sqrt(), 0.8125f64.sqrt()]);
    let (s_mean, s_std) = (vec![0.0, 0.0], vec![1.0, 1.0]);
    let settings = ModelPosteriorSettings {
        samples: 400,
        ..Default::default()
    };
    let space = space(2);
    let surrogate = FnLikelihood::new(2, gaussian(s_mean.clone(), s_std.clone()));
    let (samples, ll, _) = population(4000, &s_mean, &s_std, &surrogate, &space);
    let full: Vec<f64> = samples[..400]
        .iter()
        .zip(&ll)
        .map(|(x, l)| lobe(x) - l)
        .collect();
    let k_full = iuq_basis::pareto_smooth(&full).pareto_k;
    assert!(k_full > pareto_k_threshold(400), "k̂ {k_full}");

    let corrected = run(2, &s_mean, &s_std, &model, &settings);
    println!(
        "corrected: {:#?} {:#?}",
        corrected.corrections, corrected.stages
    );
    assert!(corrected.certified(), "{}", corrected.stop);
    assert_matches(&corrected, &mean, &std, "side lobe, corrected");

    let bridged = run(
        2,
        &s_mean,
        &s_std,
        &model,
        &ModelPosteriorSettings {
            corrections: 0,
            // The lobe's weight grows over more stages than the default 6 allow.
            max_stages: 20,
            ..settings
        },
    );
    println!("bridged: {:#?}", bridged.stages);
    assert!(bridged.certified(), "{}", bridged.stop);
    assert!(bridged.stages.len() > 1, "bridged");
    assert_matches(&bridged, &mean, &std, "side lobe, bridged");
    // The lobe's mass itself (x0 > 1.5: 0.75·P(z > 1.5) + 0.25·P(z > −3) = 0.2998), within 4
    // of its binomial standard error at the weights' effective sample size.
    let weights = bridged.weights();
    let in_lobe: f64 = bridged
        .samples
        .iter()
        .zip(&weights)
        .filter(|(x, _)| x[0] > 1.5)
        .map(|(_, w)| w)
        .sum();
    let exact = 0.75 * 0.0668072 + 0.25 * 0.9986501;
    let se = (exact * (1.0 - exact) / bridged.effective_sample_size).sqrt();
    println!("lobe mass {in_lobe:.4} (exact {exact:.4}, se {se:.4})");
    assert!((in_lobe - exact).abs() < 4.0 * se);
}

#[test]
fn where_the_model_fails_the_posterior_is_cut_and_the_failures_counted() {
    // The model fails for x0 > 0.5; its posterior is N(0, 1) cut there (x1 unaffected).
    let model = FnLikelihood::new(2, |x: &[f64]| {
        if x[0] > 0.5 {
            f64::NAN
        } else {
            -0.5 * (x[0] * x[0] + x[1] * x[1])
        }
    });
    let settings = ModelPosteriorSettings {
        samples: 600,
        ..Default::default()
    };
    let result = run(2, &[0.0, 0.0], &[1.0, 1.0], &model, &settings);
    assert!(result.failures > 100, "{}", result.failures);
    assert!(result.certified(), "{}", result.stop);
    // Truncated standard normal on (−∞, 0.5]: mean −φ(a)/Φ(a), var 1 − a·φ/Φ − (φ/Φ)².
    let a = 0.5f64;
    let phi = (-0.5 * a * a).exp() / (2.0 * std::f64::consts::PI).sqrt();
    let cdf = 0.691_462_461_274_013_1; // Φ(0.5)
    let lambda = phi / cdf;
    let exact_mean = -lambda;
    let exact_std = (1.0 - a * lambda - lambda * lambda).sqrt();
    assert_matches(
        &result,
        &[exact_mean, 0.0],
        &[exact_std, 1.0],
        "failing region",
    );
    assert!(
        result
            .samples
            .iter()
            .zip(result.weights())
            .all(|(x, w)| x[0] <= 0.5 || w == 0.0)
    );
}

#[test]
fn the_result_does_not_depend_on_the_thread_count_and_bad_settings_are_refused() {
    let (mean, std) = (vec![0.0, 3.0], vec![1.0, 0.5]);
    let model = FnLikelihood::new(2, gaussian(mean.clone(), std.clone()));
    let s_std: Vec<f64> = std.iter().map(|s| 0.6 * s).collect();
    let settings = ModelPosteriorSettings {
        samples: 100,
        ..Default::default()
    };
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| run(2, &mean, &s_std, &model, &settings));
    let three = rayon::ThreadPoolBuilder::new()
        .num_threads(3)
        .build()
        .unwrap()
        .install(|| run(2, &mean, &s_std, &model, &settings));
    assert_eq!(one, three);
    for bad in [
        ModelPosteriorSettings {
            samples: 5,
            ..Default::default()
        },
        ModelPosteriorSettings {
            moves: 0,
            ..Default::default()
        },
        ModelPosteriorSettings {
            min_step: 1.5,
            ..Default::default()
        },
    ] {
        assert!(bad.check().is_err());
    }
}

#[test]
fn a_gaussian_surrogate_of_a_curved_six_parameter_posterior_is_corrected() {
    // x1 | x0 ~ N(b·x0², 1), x0 ~ N(0, 1), x2..x5 ~ N(0, 1): E x1 = b, sd x1 = √(1 + 2b²).
    let b = 0.5f64;
    let model = FnLikelihood::new(6, move |x: &[f64]| {
        -0.5 * (x[0] * x[0] + (x[1] - b * x[0] * x[0]).powi(2))
            - 0.5 * x[2..].iter().map(|v| v * v).sum::<f64>()
    });
    let sd1 = (1.0 + 2.0 * b * b).sqrt();
    let mean = [0.0, b, 0.0, 0.0, 0.0, 0.0];
    let std = [1.0, sd1, 1.0, 1.0, 1.0, 1.0];
    // The surrogate: independent Gaussians with the right means, 25 % wider.
    let s_std: Vec<f64> = std.iter().map(|s| 1.25 * s).collect();
    let settings = ModelPosteriorSettings {
        samples: 800,
        ..Default::default()
    };
    let result = run(6, &mean, &s_std, &model, &settings);
    println!("{}", result.stop);
    assert!(result.certified());
    assert_matches(&result, &mean, &std, "curved, d = 6");
}

#[test]
fn a_correction_that_would_move_the_posterior_beyond_its_batch_is_refused_before_a_run() {
    // The model's posterior is 8 times as wide as the surrogate's in x1 (N(0, 8²) cut at the
    // prior's ±10): the quadratic fit of r = ℓ_m − ℓ_s is exact, and the posterior it corrects
    // to keeps only about 42 % of its mass inside the range of x1 over the 400 members it was
    // fitted on (±3.2 surrogate stds). That is the extrapolation that cost the TBHP red-cell study a batch
    // of 1,200 cell-model runs at the prior's corner: refused, without a model run, and the
    // bounded moment-matched correction is tried in its place.
    let calls = std::sync::atomic::AtomicUsize::new(0);
    let model = counted_gaussian(&[0.0, 0.0], &[1.0, 8.0], &calls);
    let settings = ModelPosteriorSettings {
        samples: 400,
        ..Default::default()
    };
    let result = run(2, &[0.0, 0.0], &[1.0, 1.0], &model, &settings);
    println!(
        "{:#?}\n{:?}\n{:#?}\n{}",
        result.corrections, result.correction_not_made, result.stages, result.stop
    );
    let refusals: Vec<&String> = result
        .corrections
        .iter()
        .flat_map(|c| c.refused.iter())
        .chain(result.correction_not_made.iter())
        .collect();
    assert!(
        refusals
            .iter()
            .any(|r| r.contains("least-squares fit") && r.contains("inside the range of x1")),
        "{refusals:?}"
    );
    assert!(result.corrections.iter().all(|c| c.moment_matched));
    // Every model evaluation is counted, and no batch was drawn from a refused correction.
    assert_eq!(
        result.model_evaluations,
        calls.load(std::sync::atomic::Ordering::Relaxed)
    );
    // The stages still reach the model's posterior: x1 ~ N(0, 8²) cut at ±10, whose std is
    // 8·√(1 − 2aφ(a)/(2Φ(a) − 1)) at a = 10/8 (φ(1.25) = 0.182649, Φ(1.25) = 0.894350).
    let a = 1.25f64;
    let sd1 = 8.0 * (1.0 - 2.0 * a * 0.182649 / (2.0 * 0.894350 - 1.0)).sqrt();
    assert!(result.certified(), "{}", result.stop);
    assert_matches(&result, &[0.0, 0.0], &[1.0, sd1], "wide model, refused fit");
    // Here both batches together do not hold (the model's x1 is 8 times wider than the
    // surrogate's): the stages went on from the corrected batch alone.
    if !result.corrections.is_empty() {
        assert!(!result.both_batches);
        assert!(result.stages.len() > 1, "{:?}", result.stages);
        assert_eq!(result.samples.len(), 400);
    }
}

/// SplitMix64: a deterministic hash of a point's bits, the "irregular part" of a chaotic model.
fn splitmix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A standard normal draw keyed by the exact bits of `x` and the output `k`: equal points give
/// equal draws, points a bit apart unrelated ones (as a chaotic simulator's window mean).
fn irregular_normal(x: &[f64], k: usize) -> f64 {
    let key = x.iter().fold(k as u64, |h, v| splitmix(h ^ v.to_bits()));
    let (a, b) = (splitmix(key), splitmix(key ^ 0x5555));
    let u1 = ((a >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
    let u2 = (b >> 11) as f64 / (1u64 << 53) as f64;
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// The chaotic model of the noisy tests: output k is θ_k + τ·z_k(θ), z_k a standard normal that
/// no two distinct points share; data y with measurement std σ. One run's likelihood
/// N(y; θ + τz, σ²) is a draw whose mean over z is N(y; θ, σ² + τ²): the model's posterior
/// averaged over its irregular part is N(y, σ² + τ²) per axis (the prior's truncation is below
/// 1e-20).
fn chaotic_model(
    y: &[f64],
    sigma: f64,
    tau: f64,
) -> FnLikelihood<impl Fn(&[f64]) -> f64 + Send + Sync> {
    let y = y.to_vec();
    FnLikelihood::new(y.len(), move |x: &[f64]| {
        -0.5 * (0..y.len())
            .map(|k| ((y[k] - x[k] - tau * irregular_normal(x, k)) / sigma).powi(2))
            .sum::<f64>()
    })
}

#[test]
fn a_noisy_models_posterior_is_its_average_over_the_noise() {
    let (y, sigma, tau): (Vec<f64>, f64, f64) = (vec![1.0, -2.0], 1.0, 0.5);
    let total: f64 = (sigma * sigma + tau * tau).sqrt();
    let model = chaotic_model(&y, sigma, tau);
    let std = vec![total; 2];
    let settings = ModelPosteriorSettings {
        samples: 400,
        pseudo_marginal: true,
        ..Default::default()
    };
    // A surrogate whose posterior is the averaged one: the weights are noise only, the test
    // finds no mismatch, and the one step is the estimate.
    let result = run(2, &y, &std, &model, &settings);
    let mismatch = result.proposal_mismatch.clone().unwrap();
    println!("matching surrogate: {mismatch:?}");
    assert!(!mismatch.significant());
    assert_eq!(result.stop, ModelPosteriorStop::Certified);
    assert!(result.corrections.is_empty());
    assert_eq!(result.model_evaluations, 400);
    assert_matches(&result, &y, &std, "noisy model, matching surrogate");

    // A surrogate a third of a std off and 30 % wider, as a GP with a noise term fitted to such
    // runs would be: the mismatch is found, the surrogate corrected by the weighted moments,
    // and both batches weighed as one sample of their mixture.
    let s_mean: Vec<f64> = y.iter().map(|m| m + total / 3.0).collect();
    let s_std: Vec<f64> = std.iter().map(|s| 1.3 * s).collect();
    let result = run(2, &s_mean, &s_std, &model, &settings);
    println!("{:?}\n{:?}", result.proposal_mismatch, result.stages);
    assert!(result.proposal_mismatch.as_ref().unwrap().significant());
    assert_eq!(result.stop, ModelPosteriorStop::Certified);
    assert_eq!(result.stages.len(), 1);
    assert_eq!(result.stages[0].beta, 1.0);
    assert_eq!(result.corrections.len(), 1);
    assert!(result.corrections[0].moment_matched);
    assert_eq!(result.model_evaluations, 800);
    assert_eq!(result.samples.len(), 800);
    assert_matches(&result, &y, &std, "noisy model, shifted surrogate");
    // The surrogate's own mean is off by more than the test's tolerance.
    assert!((s_mean[0] - y[0]).abs() > 4.0 * result.mcse_mean[0]);
    // The evidence: the averaged likelihood Π_k (σ/√(σ² + τ²))·N-shape integrates over the
    // uniform prior to (σ√(2π)/20)² (the surrogate's evidence is added by `run`'s population,
    // Π_k s_k√(2π)/20). The log of a mean of N weights with CV c has a standard error of about
    // c/√N; held to 4 of it.
    let log_z_exact = 2.0 * (sigma * (2.0 * std::f64::consts::PI).sqrt() / 20.0).ln();
    let log_z_surrogate: f64 = s_std
        .iter()
        .map(|s| (s * (2.0 * std::f64::consts::PI).sqrt() / 20.0).ln())
        .sum();
    let standard_error = result.stages[0].cv / (result.samples.len() as f64).sqrt();
    println!(
        "log-evidence {} (exact {log_z_exact}, standard error {standard_error})",
        log_z_surrogate + result.log_evidence_ratio
    );
    assert!(
        (log_z_surrogate + result.log_evidence_ratio - log_z_exact).abs() < 4.0 * standard_error
    );
    // The same with one thread and with three.
    let in_pool = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| run(2, &s_mean, &s_std, &model, &settings))
    };
    assert_eq!(in_pool(1), result);
    assert_eq!(in_pool(3), result);

    // A surrogate half as wide: the one step's tail is flagged by k̂ and the correction widens
    // the proposal…
    let narrow: Vec<f64> = std.iter().map(|s| 0.5 * s).collect();
    let result = run(2, &y, &narrow, &model, &settings);
    println!(
        "{:?}\n{:?}\n{:?}",
        result.proposal_mismatch, result.corrections, result.stages
    );
    assert_eq!(result.corrections.len(), 1);
    assert!(result.corrections[0].pareto_k_before > pareto_k_threshold(400));
    assert_eq!(result.stop, ModelPosteriorStop::Certified);
    assert_matches(&result, &y, &std, "noisy model, narrow surrogate");
    // …while without a correction the tail is reported, never bridged.
    let uncorrected = ModelPosteriorSettings {
        corrections: 0,
        ..settings.clone()
    };
    let result = run(2, &y, &narrow, &model, &uncorrected);
    assert_eq!(result.stop, ModelPosteriorStop::NoisyWeightsTail);
    assert!(!result.certified());
    assert!(result.proposal_mismatch.is_none());
    assert_eq!(result.stages.len(), 1);
    assert!(result.pareto_k > result.pareto_k_threshold);
    assert_eq!(result.model_evaluations, 400);
}

/// Mean over `seeds` seeds of each parameter's (estimate − exact)/MCSE for the mean and the std.
fn average_errors(
    surrogate_mean: &[f64],
    surrogate_std: &[f64],
    model: &dyn LogLikelihood,
    exact: (&[f64], &[f64]),
    settings: &ModelPosteriorSettings,
    seeds: u64,
) -> (Vec<f64>, Vec<f64>, usize) {
    let d = surrogate_mean.len();
    let (mut z_mean, mut z_std, mut certified) = (vec![0.0; d], vec![0.0; d], 0);
    for seed in 0..seeds {
        let settings = ModelPosteriorSettings {
            seed,
            ..settings.clone()
        };
        let r = run(d, surrogate_mean, surrogate_std, model, &settings);
        certified += usize::from(r.certified());
        for k in 0..d {
            z_mean[k] += (r.mean[k] - exact.0[k]) / r.mcse_mean[k] / seeds as f64;
            z_std[k] += (r.std[k] - exact.1[k]) / r.mcse_std[k] / seeds as f64;
        }
    }
    (z_mean, z_std, certified)
}

#[test]
fn over_seeds_the_corrected_noisy_estimate_is_unbiased_where_one_step_is_not() {
    // The chaotic model's averaged posterior N((1, −2), 1.118²·I); a surrogate posterior 0.8 std
    // off and 0.7 times as wide (the whole-curve problem's kind of GP). Over 20 seeds one
    // uncorrected step is certified 6 times and its estimates lie 1.3–2.3 MCSE off on average;
    // corrected, all are certified and within 1 MCSE. The average of 20 errors in MCSE units
    // has a std of about 1.5/√20 = 0.34 (the MCSE of noisy weights understates the spread
    // about 1.5 times, docs/methods.md §5b): the corrected averages are held to 4 of those
    // (1.35), the uncorrected ones shown beyond it so that the test can tell.
    let (y, sigma, tau): (Vec<f64>, f64, f64) = (vec![1.0, -2.0], 1.0, 0.5);
    let total: f64 = (sigma * sigma + tau * tau).sqrt();
    let model = chaotic_model(&y, sigma, tau);
    let std = vec![total; 2];
    let s_mean: Vec<f64> = y.iter().map(|m| m + 0.8 * total).collect();
    let s_std = vec![0.7 * total; 2];
    let settings = ModelPosteriorSettings {
        samples: 400,
        pseudo_marginal: true,
        ..Default::default()
    };
    let bound = 1.35;
    let (z_mean, z_std, certified) =
        average_errors(&s_mean, &s_std, &model, (&y, &std), &settings, 20);
    println!("corrected: mean {z_mean:.2?}, std {z_std:.2?}, certified {certified}/20");
    assert!(certified >= 18, "{certified}");
    for z in z_mean.iter().chain(&z_std) {
        assert!(z.abs() < bound, "{z_mean:?} {z_std:?}");
    }
    let one_step = ModelPosteriorSettings {
        corrections: 0,
        ..settings
    };
    let (z_mean, z_std, certified) =
        average_errors(&s_mean, &s_std, &model, (&y, &std), &one_step, 20);
    println!("one step: mean {z_mean:.2?}, std {z_std:.2?}, certified {certified}/20");
    assert!(z_mean.iter().chain(&z_std).any(|z| z.abs() > bound));
}

#[test]
fn a_narrow_shifted_surrogate_of_a_curved_eight_parameter_posterior_is_corrected() {
    // x1 | x0 ~ N(b·x0², 1), x0 ~ N(0, 1), x2..x7 ~ N(m_k, s_k): E x1 = b, sd x1 = √(1 + 2b²).
    // The surrogate is a product of Gaussians 40 % too narrow in x0..x3 (the weights exp(r)
    // have no finite variance: k = 1 − 0.6² = 0.64 in each) and a third of a std off in
    // x4..x7: the first batch does not reach the model's posterior in one step, the surrogate
    // is corrected, and the estimate comes either from both batches at once or from stages
    // after the corrected batch. Four seeds; each estimate within 4 MCSE of the exact
    // moments (8 parameters × 2 statistics × 4 seeds: a 4σ bound keeps a false failure below
    // 1 in 250), and at least one of them the two batches weighed together (the batch mixture
    // at eight parameters).
    //
    // The curvature is moderate (b = 0.3) on purpose: at b = 0.6 the banana's arm in x1 has an
    // exponential tail that neither Gaussian-tailed proposal reaches, and the stds come out
    // 10–17 % narrow with every k̂ below its threshold (docs/methods.md, "What k̂ cannot see").
    let b = 0.3f64;
    let m = [0.0, 0.0, 1.0, -2.0, 0.5, 3.0, -1.0, 2.0];
    let s = [1.0, 1.0, 0.5, 2.0, 1.0, 0.7, 1.5, 0.8];
    let calls = std::sync::atomic::AtomicUsize::new(0);
    let model = FnLikelihood::new(8, {
        let calls = &calls;
        move |x: &[f64]| {
            calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            -0.5 * (x[0] * x[0] + (x[1] - b * x[0] * x[0]).powi(2))
                - 0.5 * (2..8).map(|k| ((x[k] - m[k]) / s[k]).powi(2)).sum::<f64>()
        }
    });
    let mut mean = m.to_vec();
    mean[1] = b;
    let mut std = s.to_vec();
    std[1] = (1.0 + 2.0 * b * b).sqrt();
    let s_mean: Vec<f64> = (0..8)
        .map(|k| {
            if k >= 4 {
                mean[k] + std[k] / 3.0
            } else {
                mean[k]
            }
        })
        .collect();
    let s_std: Vec<f64> = (0..8)
        .map(|k| if k < 4 { 0.6 * std[k] } else { std[k] })
        .collect();
    let mut both = 0;
    for seed in 1..=4 {
        let settings = ModelPosteriorSettings {
            samples: 600,
            seed,
            ..Default::default()
        };
        calls.store(0, std::sync::atomic::Ordering::Relaxed);
        let result = run(8, &s_mean, &s_std, &model, &settings);
        println!(
            "seed {seed}: {:?}\n{:#?}\n{} (both batches: {})",
            result.corrections, result.stages, result.stop, result.both_batches
        );
        assert!(result.certified(), "{}", result.stop);
        assert_eq!(result.corrections.len(), 1);
        // The first batch's weights do not reach the model's posterior in one step: their CV is
        // above the step rule's target or their k̂ above its threshold.
        let before = &result.corrections[0];
        assert!(
            before.cv_before > settings.cv_target
                || before.pareto_k_before > pareto_k_threshold(600),
            "{before:?}"
        );
        assert_eq!(
            result.model_evaluations,
            calls.load(std::sync::atomic::Ordering::Relaxed)
        );
        if result.both_batches {
            both += 1;
            assert_eq!(result.samples.len(), 1200);
            assert_eq!(result.model_evaluations, 1200);
        }
        assert_matches(&result, &mean, &std, &format!("curved, d = 8, seed {seed}"));
    }
    assert!(both >= 1, "no seed weighed both batches");
}

#[test]
fn a_surrogate_too_narrow_in_all_ten_parameters_is_corrected_not_refused() {
    // The model's posterior N(μ, diag(s²)) in 10 parameters; the surrogate's is 0.6 times as
    // wide in every one (the weights have no finite variance). The quadratic fit of r is exact
    // here, and its posterior keeps about 92 % of itself inside the first batch's range of each
    // parameter, but only 0.92¹⁰ ≈ 43 % inside the batch's joint box: judged on the joint box
    // (as before 2026-11-28) the correct correction was refused, the stages bridged from the
    // first batch with 1,200–1,500 model evaluations, and the stds came out up to 16 % (4.4
    // MCSE) narrow. Judged parameter by parameter it is made, and both batches carry the
    // estimate. Three seeds; every mean and std within 4 MCSE (60 statistics: a false failure
    // below 1 in 250).
    let d = 10;
    let mean: Vec<f64> = (0..d).map(|k| k as f64 * 0.3 - 1.0).collect();
    let std: Vec<f64> = (0..d).map(|k| 0.3 + 0.1 * k as f64).collect();
    let model = FnLikelihood::new(d, gaussian(mean.clone(), std.clone()));
    let s_std: Vec<f64> = std.iter().map(|s| 0.6 * s).collect();
    for seed in 1..=3 {
        let settings = ModelPosteriorSettings {
            samples: 300,
            seed,
            ..Default::default()
        };
        let result = run(d, &mean, &s_std, &model, &settings);
        println!(
            "seed {seed}: {:?} {:?} {} (both batches: {})",
            result.corrections, result.correction_not_made, result.stop, result.both_batches
        );
        assert!(result.correction_not_made.is_none());
        assert_eq!(result.corrections.len(), 1);
        assert!(
            !result.corrections[0].moment_matched,
            "the quadratic fit is made"
        );
        assert!(result.corrections[0].refused.is_empty());
        assert!(result.certified(), "{}", result.stop);
        assert_matches(
            &result,
            &mean,
            &std,
            &format!("narrow, d = 10, seed {seed}"),
        );
    }
}

#[test]
fn a_surrogate_half_as_wide_in_one_parameter_is_corrected_even_where_k_hat_holds() {
    // The model's posterior N(0, I) in 6 parameters; the surrogate's is half as wide in x0 and
    // exact in the others. The weights exp(r) behave as exp(a·z²) with tail index
    // k = 1 − 0.5² = 0.75, a tail k̂ of 300 members underestimates: on seed 3 the first batch's
    // k̂ was 0.48 (threshold 0.60) with its CV under the step rule's target, and the one step
    // was certified with x0's std 30 % narrow (6.6 MCSE). The weighted std of x0 came out 1.47
    // times the batch's, which `iuq_basis::spread_ratio` flags: every seed is corrected (the
    // quadratic fit is exact here) and certified within 4 MCSE (6 × 2 statistics × 4 seeds: a
    // false failure below 1 in 300).
    let d = 6;
    let (mean, std) = (vec![0.0; d], vec![1.0; d]);
    let model = FnLikelihood::new(d, gaussian(mean.clone(), std.clone()));
    let mut s_std = std.clone();
    s_std[0] = 0.5;
    let mut held_by_k_hat = 0;
    for seed in 1..=4 {
        let settings = ModelPosteriorSettings {
            samples: 300,
            seed,
            ..Default::default()
        };
        let result = run(d, &mean, &s_std, &model, &settings);
        println!(
            "seed {seed}: {:?} {} (both batches: {})",
            result.corrections, result.stop, result.both_batches
        );
        assert_eq!(result.corrections.len(), 1, "seed {seed}");
        let before = &result.corrections[0];
        assert!(
            !before.moment_matched,
            "seed {seed}: the quadratic fit is made"
        );
        assert!(before.spread_ratio_before > 0.0);
        if before.pareto_k_before <= pareto_k_threshold(300)
            && before.cv_before <= settings.cv_target
        {
            held_by_k_hat += 1;
            assert!(
                before.spread_ratio_before > iuq_basis::spread_ratio::WIDER_THAN_PROPOSAL,
                "seed {seed}: {before:?}"
            );
        }
        assert!(result.certified(), "seed {seed}: {}", result.stop);
        assert_matches(&result, &mean, &std, &format!("half as wide, seed {seed}"));
    }
    assert!(
        held_by_k_hat >= 1,
        "no seed's first batch held by k̂ and the CV rule alone: the test no longer tests the spread"
    );
}

/// A log-density as a named type.
type BoxedDensity = Box<dyn Fn(&[f64]) -> f64 + Send + Sync>;

/// The lure problem in `d` parameters: a chaotic model (one run's likelihood N(y; θ + τz, σ²),
/// σ = 1, τ = 0.5) whose averaged posterior is N(y, T²·I), T = 1.118; the surrogate's posterior
/// is exact in every parameter but x1, where its core is half as wide as the model's and 0.1 %
/// of it is a flat tail from the mean to the prior's bound (a GP whose likelihood flattens away
/// from its runs, as the healthy red-cell study's in Λ). Its population: 4,000 exact draws.
struct Lure {
    y: Vec<f64>,
    total: f64,
    space: ParameterSpace,
    surrogate: FnLikelihood<BoxedDensity>,
    model: FnLikelihood<BoxedDensity>,
    samples: Vec<Vec<f64>>,
    log_likelihood: Vec<f64>,
    log_prior: Vec<f64>,
}

impl Lure {
    fn new(d: usize) -> Self {
        let y: Vec<f64> = [1.0, -2.0, 0.5, 3.0, -1.0, 2.0, 0.0, 1.5][..d].to_vec();
        let (sigma, tau) = (1.0f64, 0.5f64);
        let total = (sigma * sigma + tau * tau).sqrt();
        // As `chaotic_model`, boxed to be named.
        let model = FnLikelihood::new(d, {
            let y = y.clone();
            Box::new(move |x: &[f64]| {
                -0.5 * (0..y.len())
                    .map(|k| ((y[k] - x[k] - tau * irregular_normal(x, k)) / sigma).powi(2))
                    .sum::<f64>()
            }) as BoxedDensity
        });
        let (core, tail_share, bound) = (0.5 * total, 0.001, 10.0);
        let core_density = move |v: f64, m: f64| {
            (-0.5 * ((v - m) / core).powi(2)).exp() / (core * (2.0 * std::f64::consts::PI).sqrt())
        };
        let surrogate = FnLikelihood::new(d, {
            let y = y.clone();
            Box::new(move |x: &[f64]| {
                let tail = if x[1] >= y[1] {
                    1.0 / (bound - y[1])
                } else {
                    0.0
                };
                -0.5 * (0..x.len())
                    .filter(|&k| k != 1)
                    .map(|k| ((x[k] - y[k]) / total).powi(2))
                    .sum::<f64>()
                    + ((1.0 - tail_share) * core_density(x[1], y[1]) + tail_share * tail).ln()
            }) as BoxedDensity
        });
        let space = space(d);
        let mut rng = stream(7, 1, 0);
        let samples: Vec<Vec<f64>> = (0..4000)
            .map(|_| {
                let z0: f64 = StandardNormal.sample(&mut rng);
                let z1: f64 = StandardNormal.sample(&mut rng);
                let u: f64 = rand::Rng::random(&mut rng);
                let x1 = if u < tail_share {
                    y[1] + (bound - y[1]) * u / tail_share
                } else {
                    y[1] + core * z1
                };
                let mut x = vec![y[0] + total * z0, x1];
                for &m in &y[2..] {
                    let z: f64 = StandardNormal.sample(&mut rng);
                    x.push(m + total * z);
                }
                x
            })
            .collect();
        let log_likelihood = surrogate
            .log_likelihood_batch(&samples)
            .unwrap()
            .into_iter()
            .map(|v| v.unwrap())
            .collect();
        let log_prior = samples
            .iter()
            .map(|s| space.log_prior(s).unwrap())
            .collect();
        Self {
            y,
            total,
            space,
            surrogate,
            model,
            samples,
            log_likelihood,
            log_prior,
        }
    }

    fn population(&self) -> SurrogatePopulation<'_> {
        SurrogatePopulation {
            samples: &self.samples,
            log_likelihood: &self.log_likelihood,
            log_prior: &self.log_prior,
            log_evidence: 0.0,
        }
    }
}

#[test]
fn a_noisy_models_correction_lured_into_a_heavy_tail_is_refused_and_a_defensive_batch_run() {
    // The chaotic model's averaged posterior N((1, −2), 1.118²·I). The surrogate's posterior
    // is exact in x0; in x1 its core is half as wide as the model's, and 0.1 % of it is a flat
    // tail from the mean to the prior's bound (a GP whose likelihood flattens away from its
    // runs, as the healthy red-cell study's in Λ). The first batch's weights ask for a wider x1,
    // so that e^g grows outwards, and q·e^g — the flat tail multiplied by e^g up to the target's
    // 1-in-10,000 contour — lies beyond the batch: refused before a run. The one step alone,
    // from a core half as wide as the target, came out with an x1 std of 0.795 ± 0.045 against
    // 1.118, with k̂ 0.565 under its threshold 0.616 (the blind spot of k̂ for a proposal
    // narrower than the target, docs/methods.md, "What k̂ cannot see"). The defensive batch from
    // a normal at the weights' mean with twice their second moment about the batch's mean runs
    // instead, and both batches carry the estimate. Sixteen seeds: at least 14 certified, and
    // for those each mean and std within 4 of its spread, 1.5 MCSE (the MCSE of noisy weights
    // understates the spread about 1.5 times, docs/methods.md §5b; 64 statistics at most: a
    // false failure below 1 in 250), the average error of each statistic within 4 of its own
    // spread, 1.5/√n in MCSE units. Measured: 16 certified, x1's std 1.07 on average (−4 %,
    // −1.05 MCSE), the largest single error −4.2 MCSE; with the surrogate's posterior tempered
    // instead (`iuq_basis::defensive_tempering`), 13 certified.
    let lure = Lure::new(2);
    let (y, total) = (&lure.y, lure.total);
    let population = lure.population();
    let exact_std = [total, total];
    let seeds = 16;
    let (mut z, mut certified) = ([0.0f64; 4], 0);
    for seed in 1..=seeds {
        let settings = ModelPosteriorSettings {
            samples: 400,
            seed,
            pseudo_marginal: true,
            ..Default::default()
        };
        let result = model_posterior(
            &lure.space,
            population,
            &lure.surrogate,
            &lure.model,
            &settings,
            &mut |_: &ModelPosteriorEvent<'_>| Control::Continue,
        )
        .unwrap();
        println!(
            "seed {seed}: {:?} {:?} {:?} {}",
            result.corrections, result.correction_not_made, result.proposal_mismatch, result.stop
        );
        assert!(result.correction_not_made.is_none());
        assert_eq!(result.corrections.len(), 1);
        let correction = &result.corrections[0];
        assert!(correction.defensive_normal, "{correction:?}");
        assert_eq!(correction.tempering, None);
        assert!(!correction.moment_matched);
        assert_eq!(correction.refused.len(), 1, "{:?}", correction.refused);
        assert!(
            correction.refused[0].contains("moment-matched")
                && correction.refused[0].contains("inside the range of x1"),
            "{:?}",
            correction.refused
        );
        assert!(result.both_batches);
        assert_eq!(result.model_evaluations, 800);
        assert_eq!(result.samples.len(), 800);
        if !result.certified() {
            continue;
        }
        certified += 1;
        for k in 0..2 {
            let (m, sd) = (result.mean[k], result.std[k]);
            let (em, es) = (1.5 * result.mcse_mean[k], 1.5 * result.mcse_std[k]);
            println!("lured, seed {seed}: x{k} mean {m:.4} ± {em:.4}, std {sd:.4} ± {es:.4}");
            assert!(
                em < 0.15 * total && es < 0.15 * total,
                "MCSE too large to test"
            );
            assert!((m - y[k]).abs() <= 4.0 * em, "seed {seed}: mean of x{k}");
            assert!(
                (sd - exact_std[k]).abs() <= 4.0 * es,
                "seed {seed}: std of x{k}"
            );
        }
        for k in 0..2 {
            z[2 * k] += (result.mean[k] - y[k]) / result.mcse_mean[k];
            z[2 * k + 1] += (result.std[k] - total) / result.mcse_std[k];
        }
    }
    let z = z.map(|v| v / certified.max(1) as f64);
    println!(
        "average errors in MCSE units (mean, std of x0; of x1): {z:.2?}, certified {certified}/{seeds}"
    );
    assert!(certified >= 14, "{certified}");
    let bound = 4.0 * 1.5 / (certified as f64).sqrt();
    assert!(z.iter().all(|v| v.abs() < bound), "{z:?}");
}

#[test]
fn a_noisy_models_batch_narrower_than_the_target_is_corrected_where_k_hat_and_the_test_miss_it() {
    // The lure problem in 6 parameters (x2..x5 exact). On seeds 2, 3 and 6 (of 16), neither the
    // first batch's k̂ nor the permutation test saw x1's core half as wide as the target, and the
    // one step was certified with x1's std 27–35 % narrow (0.725, 0.821, 0.744 against 1.118).
    // Their weighted std of x1 was 1.24–1.32 times the batch's: the spread ratio now asks for
    // the correction, and a second batch follows (both batches weighed as one sample). Each seed corrected, and where certified,
    // x1's std within 4 × 1.5 MCSE (the documented understatement of noisy weights' MCSE).
    // Measured: 1.193 ± 0.143 (not certified), 1.195 ± 0.071 and 0.975 ± 0.062. (The second
    // batch's chaotic runs move with the last bit of the first batch's weights: a surrogate
    // written with its terms summed in another order gave 0.917, 1.345 and 0.956.)
    let lure = Lure::new(6);
    let population = lure.population();
    let mut certified = 0;
    for seed in [2, 3, 6] {
        let settings = ModelPosteriorSettings {
            samples: 400,
            seed,
            pseudo_marginal: true,
            ..Default::default()
        };
        let result = model_posterior(
            &lure.space,
            population,
            &lure.surrogate,
            &lure.model,
            &settings,
            &mut |_: &ModelPosteriorEvent<'_>| Control::Continue,
        )
        .unwrap();
        println!(
            "seed {seed}: {:?} {:?} {} x1 std {:.3} ± {:.3}",
            result.corrections,
            result.proposal_mismatch,
            result.stop,
            result.std[1],
            result.mcse_std[1]
        );
        assert_eq!(result.corrections.len(), 1, "seed {seed}");
        assert!(result.both_batches, "seed {seed}");
        assert_eq!(result.model_evaluations, 800);
        let before = &result.corrections[0];
        assert!(
            before.pareto_k_before <= pareto_k_threshold(400)
                && !result
                    .proposal_mismatch
                    .as_ref()
                    .is_some_and(|m| m.significant()),
            "seed {seed}: the spread ratio alone asked for the correction ({before:?})"
        );
        assert!(
            before.spread_ratio_before > iuq_basis::spread_ratio::WIDER_THAN_PROPOSAL,
            "seed {seed}: {before:?}"
        );
        if result.certified() {
            certified += 1;
            let es = 1.5 * result.mcse_std[1];
            assert!(
                (result.std[1] - lure.total).abs() <= 4.0 * es,
                "seed {seed}: std of x1"
            );
        }
    }
    assert!(certified >= 2, "{certified}");
}

/// A noisy model whose likelihood estimates carry a log-normal factor exp(σz − σ²/2), σ = 2
/// (unbiased, as a pseudo-marginal likelihood must be), on the exact surrogate: the weights are
/// the noise alone, heavy-tailed enough that most certified steps end with k̂ above ½, where the
/// delta method's standard error no longer holds. Over 60 seeds of S = 800 members, on the
/// certified runs with k̂ > ½ (37 runs, 74 means and 74 stds), the z-scores (estimate − exact)/MCSE
/// must have a root-mean-square of at most 1.2 for the means and 1.3 for the stds. For a
/// calibrated MCSE the rms of 74 z-scores has a spread of about 1/√(2·74) = 0.08, so 1.2 is
/// 2.5 of those above 1; the stds' z-scores lean negative by about 0.45 whatever the MCSE
/// (a std estimated low comes with a small delta-method error: studentisation's skew), which
/// alone makes their rms √(1 + 0.45²) ≈ 1.1, so their bound is 1.3. The delta method alone
/// gives 1.23 and 1.39 here (asserted above 1.3 for the stds, so the test can tell).
#[test]
fn heavy_tailed_weights_widen_the_standard_errors_to_the_errors_seen() {
    let (mean, std) = (vec![0.0, 3.0], vec![1.0, 0.5]);
    let sigma = 2.0;
    let noise = move |x: &[f64]| {
        use std::hash::{Hash, Hasher};
        let mut hasher = std::collections::hash_map::DefaultHasher::new();
        for v in x {
            v.to_bits().hash(&mut hasher);
        }
        let z: f64 = StandardNormal.sample(&mut stream(hasher.finish(), 9, 0));
        sigma * z - 0.5 * sigma * sigma
    };
    let g = gaussian(mean.clone(), std.clone());
    let model = FnLikelihood::new(2, move |x: &[f64]| g(x) + noise(x));
    // Squared z-scores: [delta-method mean, delta-method std, reported mean, reported std].
    let (mut squares, mut count) = ([0.0f64; 4], 0.0);
    for seed in 1..=60 {
        let settings = ModelPosteriorSettings {
            samples: 800,
            seed,
            pseudo_marginal: true,
            ..Default::default()
        };
        let result = seeded_run(seed, 2, &mean, &std, &model, &settings);
        if result.stop != ModelPosteriorStop::Certified || result.pareto_k <= 0.5 {
            assert!(result.heavy_tail_errors.is_none() || result.pareto_k > 0.5);
            continue;
        }
        let heavy = result
            .heavy_tail_errors
            .as_ref()
            .expect("subsampled errors");
        assert!(heavy.convergence_rate < 1.0, "{heavy:?}");
        assert!(result.paired.is_none());
        let w = result.weights();
        let own: Vec<usize> = (0..w.len()).collect();
        let delta =
            iuq_basis::ancestral_errors(&result.samples, &w, &own, &result.mean, &result.std);
        for k in 0..2 {
            assert!(result.mcse_mean[k] >= delta.mean[k] && result.mcse_std[k] >= delta.std[k]);
            let z = [
                (result.mean[k] - mean[k]) / delta.mean[k],
                (result.std[k] - std[k]) / delta.std[k],
                (result.mean[k] - mean[k]) / result.mcse_mean[k],
                (result.std[k] - std[k]) / result.mcse_std[k],
            ];
            for (s, z) in squares.iter_mut().zip(z) {
                *s += z * z;
            }
            count += 1.0;
        }
    }
    let rms = squares.map(|s| (s / count).sqrt());
    println!(
        "{count} z-scores with k̂ > ½; rms (delta method: mean, std; reported: mean, std) {rms:?}"
    );
    assert!(count >= 50.0, "{count}");
    assert!(
        rms[1] > 1.3,
        "the delta method's stds were expected off: {rms:?}"
    );
    assert!(rms[2] <= 1.2, "means: {rms:?}");
    assert!(rms[3] <= 1.3, "stds: {rms:?}");
}
