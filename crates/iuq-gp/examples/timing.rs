//! Timing of a fit (n = 500, d = 3, 10 restarts) and of a 100 000-point prediction with
//! variance; compare with `scikit-learn` on the same data (see the crate's report).
//!
//! `cargo run -p iuq-gp --release --example timing [n] [m] [restarts] [screening_points]`

use std::time::Instant;

use iuq_gp::{FitOptions, GaussianProcess};

const PHI: f64 = 1.220_744_084_605_759_6;
const PLASTIC: [f64; 3] = [
    0.754_877_666_246_692_7,
    0.569_840_290_998_053_2,
    0.430_159_709_001_946_85,
];

fn truth(p: &[f64]) -> f64 {
    (2.0 * std::f64::consts::PI * p[0]).sin() + p[1] * p[1] + 0.5 * p[2]
}

fn main() {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let n = args.first().copied().unwrap_or(500);
    let m = args.get(1).copied().unwrap_or(100_000);
    let restarts = args.get(2).copied().unwrap_or(10);
    let screening_points = args
        .get(3)
        .copied()
        .unwrap_or(FitOptions::default().screening_points);
    let a = [1.0 / PHI, 1.0 / (PHI * PHI), 1.0 / (PHI * PHI * PHI)];
    let x: Vec<Vec<f64>> = (1..=n)
        .map(|i| {
            a.iter()
                .map(|ak| (0.5 + i as f64 * ak).rem_euclid(1.0))
                .collect()
        })
        .collect();
    let y: Vec<f64> = x
        .iter()
        .enumerate()
        .map(|(i, p)| truth(p) + 0.01 * (37.0 * (i + 1) as f64).sin())
        .collect();
    let points: Vec<Vec<f64>> = (1..=m)
        .map(|j| {
            PLASTIC
                .iter()
                .map(|b| (0.5 + j as f64 * b).rem_euclid(1.0))
                .collect()
        })
        .collect();
    let options = FitOptions {
        n_restarts: restarts,
        screening_points,
        ..Default::default()
    };
    println!("threads: {}", rayon::current_num_threads());
    for rep in 0..2 {
        let t = Instant::now();
        let gp = GaussianProcess::fit(&x, &y, &options.check().unwrap()).expect("fit");
        let fit_s = t.elapsed().as_secs_f64();
        let d = gp.diagnostics();
        println!(
            "fit #{rep}: {fit_s:.3} s, LML {:.7}, {} starts; on all points: {} LML values + {} gradients; on the screening subset: {} values; best start {:?}",
            gp.log_marginal_likelihood(),
            d.starts.len(),
            d.total_evaluations(),
            d.total_gradient_evaluations(),
            d.total_screening_evaluations(),
            d.best_start,
        );
        if rep == 0 {
            for (i, s) in d.starts.iter().enumerate() {
                let fmt = |r: &Option<iuq_gp::RunReport>| {
                    r.as_ref()
                        .map(|r| {
                            format!(
                                "LML {:?} ({} values, {:?})",
                                r.log_marginal_likelihood, r.evaluations, r.termination
                            )
                        })
                        .unwrap_or_else(|| "-".into())
                };
                println!(
                    "  start {i}: subset {}; all points {}; merged into {:?}; outranked by {:?}",
                    fmt(&s.on_subset),
                    fmt(&s.on_all_points),
                    s.merged_into,
                    s.outranked_by
                );
            }
            println!(
                "  hyper-parameters {:?}, length scales in input units {:?}, LOO Q2 {:?}, warnings {:?}",
                gp.hyperparameters(),
                gp.length_scales_in_input_units(),
                gp.loo_q2(),
                d.messages()
            );
        }
        let t = Instant::now();
        let p = gp.predict(&points).expect("predict");
        let pred_s = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let mean_only = gp.predict_mean(&points).expect("predict");
        let mean_s = t.elapsed().as_secs_f64();
        let truth_values: Vec<f64> = points.iter().map(|p| truth(p)).collect();
        let q2 = iuq_gp::q2(&truth_values, &p.mean).expect("q2");
        println!(
            "predict {m} points with variance: {pred_s:.3} s; mean only {mean_s:.3} s; Q2 {q2:.7}; first {:?} std {:?}",
            &p.mean[..3],
            &p.std_with_noise()[..3]
        );
        assert_eq!(mean_only, p.mean);
    }
}
