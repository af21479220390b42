//! How far BASIS's posterior lands from exact ones as the dimension grows, per mixing setting:
//! the published fixed chains (β = 0.2, burn 0 or 10), the default adaptive mixing and a stricter
//! one, on correlated Gaussians and on "banana" pairs (b | a ~ N(a²/2, 0.5²)) in 2, 6 and 10
//! dimensions, with closed-form moments. Prints the largest |Δmean|/std and |Δstd|/std over the
//! parameters and seeds, the evaluations per run, the stages and the longest burn-in
//! (docs/methods.md §5, "How the chains mix"). `MIXING_STAGES=1` prints every stage of seed 0.
//!
//! `cargo run --release -p iuq-basis --example mixing_accuracy -- [samples] [seeds]`
use iuq_basis::{Basis, BasisSettings, FnLikelihood, Mixing, Silent};
use iuq_core::{Parameter, ParameterSpace, Prior};

/// A log-likelihood of the parameter vector.
type LogLikelihoodFn = Box<dyn Fn(&[f64]) -> f64 + Sync + Send>;

struct Problem {
    name: String,
    d: usize,
    ll: LogLikelihoodFn,
    mean: Vec<f64>,
    std: Vec<f64>,
    half_width: f64,
}

fn gaussian(d: usize) -> Problem {
    // Correlated Gaussian: x_k = y_k + 0.5 y_{k-1} with independent y_k ~ N(mu_k, s_k²).
    let s: Vec<f64> = (0..d).map(|k| 0.5 + 0.25 * k as f64).collect();
    let mu: Vec<f64> = (0..d).map(|k| 1.0 - 0.3 * k as f64).collect();
    let (s2, mu2) = (s.clone(), mu.clone());
    let ll = move |x: &[f64]| {
        let mut acc = 0.0;
        let mut prev = 0.0;
        for k in 0..x.len() {
            let y = x[k] - 0.5 * prev;
            prev = y;
            acc += -0.5 * ((y - mu2[k]) / s2[k]).powi(2);
        }
        acc
    };
    let mut mean = vec![0.0; d];
    let mut std = vec![0.0; d];
    for k in 0..d {
        let (pm, pv) = if k > 0 {
            (mu[k - 1], s[k - 1] * s[k - 1])
        } else {
            (0.0, 0.0)
        };
        mean[k] = mu[k] + 0.5 * pm;
        std[k] = (s[k] * s[k] + 0.25 * pv).sqrt();
    }
    Problem {
        name: format!("gaussian-{d}"),
        d,
        ll: Box::new(ll),
        mean,
        std,
        half_width: 12.0,
    }
}

fn banana(d: usize) -> Problem {
    // pairs (a, b): a ~ N(0, 1), b | a ~ N(0.5 a², 0.5²)
    let ll = move |x: &[f64]| {
        let mut acc = 0.0;
        for p in 0..x.len() / 2 {
            let (a, b) = (x[2 * p], x[2 * p + 1]);
            acc += -0.5 * a * a - 0.5 * ((b - 0.5 * a * a) / 0.5).powi(2);
        }
        acc
    };
    let mut mean = vec![0.0; d];
    let mut std = vec![0.0; d];
    for p in 0..d / 2 {
        mean[2 * p] = 0.0;
        std[2 * p] = 1.0;
        mean[2 * p + 1] = 0.5;
        std[2 * p + 1] = (0.25 + 0.25 * 2.0f64).sqrt();
    }
    Problem {
        name: format!("banana-{d}"),
        d,
        ll: Box::new(ll),
        mean,
        std,
        half_width: 10.0,
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let samples: usize = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(4000);
    let seeds: u64 = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(3);
    let problems = vec![
        gaussian(2),
        gaussian(6),
        gaussian(10),
        banana(2),
        banana(6),
        banana(10),
    ];
    let settings = [
        ("fixed burn 0", Mixing::Fixed, 0usize),
        ("fixed burn 10", Mixing::Fixed, 10),
        (
            "adaptive 0.1/100",
            Mixing::Adaptive {
                correlation: 0.1,
                max_burn_in: 100,
            },
            0,
        ),
        (
            "adaptive 0.3/100",
            Mixing::Adaptive {
                correlation: 0.3,
                max_burn_in: 100,
            },
            0,
        ),
        (
            "adaptive 0.3/50",
            Mixing::Adaptive {
                correlation: 0.3,
                max_burn_in: 50,
            },
            0,
        ),
    ];
    println!("problem\tsetting\tmax|dmean|/std\tmax|dstd|/std\tevals\tstages\tmax_burn");
    for p in &problems {
        let space = ParameterSpace::new(
            (0..p.d)
                .map(|k| Parameter {
                    name: format!("x{k}"),
                    prior: Prior::Uniform(p.mean[k] - p.half_width, p.mean[k] + p.half_width),
                })
                .collect(),
        )
        .unwrap();
        let f = &p.ll;
        let likelihood = FnLikelihood::new(p.d, |x: &[f64]| f(x));
        for (name, mixing, burn) in settings {
            let (mut em, mut es, mut ev, mut st, mut mb) = (0.0f64, 0.0f64, 0usize, 0usize, 0usize);
            for seed in 0..seeds {
                let s = BasisSettings {
                    samples,
                    seed,
                    burn_in: burn,
                    mixing,
                    ..Default::default()
                }
                .check()
                .unwrap();
                let run = Basis::new(&space, &likelihood, s)
                    .unwrap()
                    .run(&mut Silent)
                    .unwrap();
                let st_ = &run.state;
                let n = st_.samples.len() as f64;
                for k in 0..p.d {
                    let m = st_.samples.iter().map(|x| x[k]).sum::<f64>() / n;
                    let v = st_.samples.iter().map(|x| (x[k] - m).powi(2)).sum::<f64>() / n;
                    em = em.max((m - p.mean[k]).abs() / p.std[k]);
                    es = es.max((v.sqrt() - p.std[k]).abs() / p.std[k]);
                }
                if std::env::var("MIXING_STAGES").is_ok() && seed == 0 {
                    for d in &st_.diagnostics {
                        eprintln!(
                            "  {} {} stage {} p {:.4} scale {:.3} acc {:.3} burn {} rho {:.3}",
                            p.name,
                            name,
                            d.stage,
                            d.exponent,
                            d.proposal_scale,
                            d.acceptance_rate,
                            d.burn_in,
                            d.start_correlation
                        );
                    }
                }
                ev += st_.evaluations;
                st += st_.stage;
                mb = mb.max(st_.diagnostics.iter().map(|d| d.burn_in).max().unwrap_or(0));
            }
            println!(
                "{}\t{}\t{:.3}\t{:.3}\t{}\t{:.1}\t{}",
                p.name,
                name,
                em,
                es,
                ev / seeds as usize,
                st as f64 / seeds as f64,
                mb
            );
        }
    }
}
