//! Times the Latin hypercube methods and prints their minimum distances.
//!
//! `cargo run --release -p iuq-doe --example lhs_timing -- [n] [dim] [seeds] [outer]`
//! (defaults 500 3 5, and the default number of ESE outer iterations).

use std::time::Instant;

use iuq_doe::{EseOptions, LhsMethod, latin_hypercube, min_distance};

fn main() -> Result<(), iuq_doe::DoeError> {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let n = args.first().copied().unwrap_or(500);
    let dim = args.get(1).copied().unwrap_or(3);
    let seeds = args.get(2).copied().unwrap_or(5) as u64;
    let mut ese = EseOptions::default();
    if let Some(&outer) = args.get(3) {
        ese.outer_iterations = outer;
    }
    let methods = [
        ("random", LhsMethod::Random),
        ("maximin (5)", LhsMethod::Maximin { candidates: 5 }),
        ("maximin (100)", LhsMethod::maximin()),
        ("optimized (ESE)", LhsMethod::Optimized(ese)),
    ];
    println!(
        "n = {n}, d = {dim}, ESE outer iterations {}",
        ese.outer_iterations
    );
    for (name, method) in methods {
        for seed in 0..seeds {
            let start = Instant::now();
            let x = latin_hypercube(n, dim, method, seed)?;
            let t = start.elapsed().as_secs_f64();
            println!(
                "{name:>16}  seed {seed}: min distance {:.4}  ({t:.3} s)",
                min_distance(&x)
            );
        }
    }
    Ok(())
}
