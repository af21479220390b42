//! Measures BASIS on the reference problems of docs/methods.md §7: mean, sd of ln Z over seeds,
//! stage counts and the Rosenbrock posterior mean. `cargo run --release -p iuq-basis --example
//! reference_problems -- [N] [burn] [seeds]`.

use iuq_basis::{Basis, BasisSettings, FnLikelihood, Silent};
use iuq_core::{Parameter, ParameterSpace, Prior};

const LN_2PI: f64 = 1.837_877_066_409_345_5;

fn space(d: usize, half_width: f64) -> ParameterSpace {
    ParameterSpace::new(
        (0..d)
            .map(|k| Parameter {
                name: format!("x{k}"),
                prior: Prior::Uniform(-half_width, half_width),
            })
            .collect(),
    )
    .expect("valid space")
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(1000);
    let burn: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(0);
    let seeds: u64 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(20);
    type Problem = (
        &'static str,
        ParameterSpace,
        Box<dyn Fn(&[f64]) -> f64 + Send + Sync>,
        f64,
    );
    let problems: Vec<Problem> = vec![
        (
            "gaussian-1d",
            space(1, 15.0),
            Box::new(|x: &[f64]| -0.5 * ((x[0] + 2.0) / 3.0).powi(2) - 3f64.ln() - 0.5 * LN_2PI),
            -3.401205,
        ),
        (
            "half-norm-5d",
            space(5, 5.0),
            Box::new(|x: &[f64]| -0.5 * x.iter().map(|v| v * v).sum::<f64>()),
            -6.918236,
        ),
        (
            "gaussian-2d",
            space(2, 15.0),
            Box::new(|x: &[f64]| -0.5 * (x[0] * x[0] + x[1] * x[1]) - LN_2PI),
            -6.802395,
        ),
        (
            "rosenbrock",
            space(2, 15.0),
            Box::new(|x: &[f64]| -(100.0 * (x[1] - x[0] * x[0]).powi(2) + (x[0] - 1.0).powi(2))),
            -7.960278,
        ),
    ];
    println!("N = {n}, burn = {burn}, seeds = {seeds}");
    for (name, space, f, exact) in &problems {
        let likelihood = FnLikelihood::new(space.dimension(), f);
        let start = std::time::Instant::now();
        let mut z = Vec::new();
        let mut stages = Vec::new();
        let mut means = vec![0.0; space.dimension()];
        let mut run_means: Vec<Vec<f64>> = Vec::new();
        for seed in 0..seeds {
            let settings = BasisSettings {
                samples: n,
                burn_in: burn,
                seed,
                ..Default::default()
            }
            .check()
            .expect("valid settings");
            let run = Basis::new(space, &likelihood, settings)
                .expect("sampler")
                .run(&mut Silent)
                .expect("run");
            z.push(run.state.log_evidence);
            stages.push(run.state.stage);
            let s = iuq_basis::PosteriorSummary::from_state(&run.state).expect("summary");
            run_means.push(s.mean.clone());
            for (m, v) in means.iter_mut().zip(&s.mean) {
                *m += v / seeds as f64;
            }
        }
        let k = z.len() as f64;
        let mean = z.iter().sum::<f64>() / k;
        let sd = (z.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (k - 1.0)).sqrt();
        println!(
            "{name:14} lnZ mean {mean:.4} (exact {exact:.4}, diff {:+.4}, sd {sd:.4}, se {:.4}) stages {:?} posterior mean {:?} [{:.2}s]",
            mean - exact,
            sd / k.sqrt(),
            stages,
            means
                .iter()
                .map(|m| (m * 1000.0).round() / 1000.0)
                .collect::<Vec<_>>(),
            start.elapsed().as_secs_f64()
        );
        let sds: Vec<f64> = (0..space.dimension())
            .map(|k| {
                let m = means[k];
                (run_means.iter().map(|r| (r[k] - m).powi(2)).sum::<f64>() / (seeds as f64 - 1.0))
                    .sqrt()
            })
            .collect();
        println!("{:14} sd of per-run posterior means {:?}", "", sds);
    }
}
