//! The adaptive engine's check of its own sampler (`iuq_adaptive::sampler_agreement`) on a
//! six-parameter linear-Gaussian problem whose posterior is exact: a deliberately under-sampled
//! sampler (`burn = 0` at β = 0.2: in six dimensions its population is off by up to about one
//! posterior std, `crates/iuq-basis/examples/mixing_accuracy.rs`) must be caught and never called
//! converged, and the engine, sampling harder from then on, must end at the exact posterior.

use std::path::Path;

use crate::common::{iuq, json_of, scratch};

/// The design matrix of y(t) = a + b t + c t² + d sin t + e cos t + f exp(−t).
fn basis(t: f64) -> [f64; 6] {
    [1.0, t, t * t, t.sin(), t.cos(), (-t).exp()]
}

const TRUTH: [f64; 6] = [1.0, 0.5, -0.2, 0.8, -0.6, 1.5];
const NOISE_STD: f64 = 0.1;
/// Standard normal deviates (Python `random.Random(7).gauss(0, 1)`, 12 draws, 3 decimals).
const NOISE: [f64; 12] = [
    -0.372, 1.213, 0.245, -0.871, 0.532, -1.106, 0.118, 0.905, -0.467, -0.059, 1.672, -0.734,
];

fn times() -> Vec<f64> {
    (0..12).map(|i| 0.5 * i as f64).collect()
}

/// The exact posterior (uniform priors far wider than it): mean (XᵀX)⁻¹Xᵀy, covariance
/// σ²(XᵀX)⁻¹.
fn exact(y: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let t = times();
    let mut a = [[0.0; 13]; 6];
    for (i, &ti) in t.iter().enumerate() {
        let x = basis(ti);
        for r in 0..6 {
            for c in 0..6 {
                a[r][c] += x[r] * x[c];
            }
            a[r][6] += x[r] * y[i];
        }
    }
    for r in 0..6 {
        a[r][7 + r] = 1.0;
    }
    // Gauss–Jordan with partial pivoting on [XᵀX | Xᵀy | I].
    for col in 0..6 {
        let pivot = (col..6)
            .max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))
            .unwrap();
        a.swap(col, pivot);
        let p = a[col][col];
        for v in a[col].iter_mut() {
            *v /= p;
        }
        for r in 0..6 {
            if r != col {
                let f = a[r][col];
                let pivot_row = a[col];
                for (v, pv) in a[r].iter_mut().zip(pivot_row) {
                    *v -= f * pv;
                }
            }
        }
    }
    let mean = (0..6).map(|r| a[r][6]).collect();
    let std = (0..6).map(|r| NOISE_STD * a[r][7 + r].sqrt()).collect();
    (mean, std)
}

fn write_study(dir: &Path, sampler: &str) -> (std::path::PathBuf, Vec<f64>, Vec<f64>) {
    let t = times();
    let y: Vec<f64> = t
        .iter()
        .zip(NOISE)
        .map(|(&ti, e)| {
            basis(ti).iter().zip(TRUTH).map(|(x, p)| x * p).sum::<f64>() + NOISE_STD * e
        })
        .collect();
    let mut csv = String::from("t,y,y_err\n");
    for (ti, yi) in t.iter().zip(&y) {
        csv.push_str(&format!("{ti},{yi},{NOISE_STD}\n"));
    }
    std::fs::write(dir.join("data.csv"), csv).unwrap();
    let (mean, std) = exact(&y);
    // Uniform priors of ±8 exact posterior stds: the truncation moves no moment measurably.
    let priors: String = ["a", "b", "c", "d", "e", "f"]
        .iter()
        .zip(mean.iter().zip(&std))
        .map(|(name, (m, s))| {
            format!(
                "{name} = {{ uniform = [{}, {}] }}\n",
                m - 8.0 * s,
                m + 8.0 * s
            )
        })
        .collect();
    // The surrogate's variance enters as the paper has it (relative): these seeded cases were
    // set up with it. Under the absolute default the default sampler's first round reads a
    // disagreement of 0.105 posterior stds against the tolerance 0.1 — noise of two replicates
    // against two, a false alarm that only raises the mixing level.
    let study = format!(
        "name = \"linear-six\"\n\n[parameters]\n{priors}\n[likelihood]\n\
         data = {{ file = \"data.csv\", x = \"t\", y = \"y\", y_err = \"y_err\" }}\n\
         modelling_error = false\ncomputational_error = \"relative\"\n\n[model]\nkind = \"expression\"\nabscissa = \"t\"\n\
         outputs = {{ y = \"a + b*t + c*t^2 + d*sin(t) + e*cos(t) + f*exp(-t)\" }}\n\n\
         [surrogate]\ndesign = {{ kind = \"lhs\", n = 10, seed = 1 }}\n\
         adaptive = {{ batch = 2, max_runs = 600, tolerance = 0.1, samples = 1000, replicates = 4 }}\n\n\
         [sampler]\n{sampler}\n"
    );
    let path = dir.join("linear-six.toml");
    std::fs::write(&path, study).unwrap();
    (path, mean, std)
}

fn run(path: &Path, out: &Path) -> (serde_json::Value, serde_json::Value) {
    let output = iuq(&[
        "pipeline",
        path.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let rounds: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("adaptive/rounds.json")).unwrap())
            .unwrap();
    (json_of(&output), rounds)
}

#[test]
fn an_under_sampled_posterior_is_caught_never_called_converged_and_then_sampled_right() {
    let dir = scratch("sampler-check", "under-sampled");
    let (path, mean, std) = write_study(&dir, "samples = 4000\nburn = 0\nseed = 3");
    let (v, rounds) = run(&path, &dir.join("report"));
    let rounds = rounds.as_array().unwrap();
    // Round 1 samples as the study says (level 0), and its harder-mixing replicates disagree.
    let first = &rounds[0];
    assert_eq!(first["mixing_level"], 0, "{first}");
    let agreement = &first["sampler_agreement"];
    assert_eq!(agreement["disagrees"], true, "{first}");
    assert!(agreement["disagreement"].as_f64().unwrap() > 0.1, "{first}");
    // No round that samples at the study's own level is called converged, and after the first
    // round sampled with the full population (4 replicates of the study's `samples = 1000`, 4000
    // in all; round 1 explores with a quarter, whose check does not raise the level) every round
    // mixes harder.
    for r in rounds {
        if r["mixing_level"] == 0 {
            assert_eq!(r["converged"], false, "{r}");
        }
    }
    let full = rounds
        .iter()
        .position(|r| r["samples"].as_u64().unwrap() >= 4 * 1000)
        .expect("a round sampled in full");
    assert!(
        rounds[full + 1..]
            .iter()
            .all(|r| r["mixing_level"].as_u64().unwrap() >= 1),
        "{rounds:?}"
    );
    assert!(full + 1 < rounds.len(), "{rounds:?}");
    // Sampling harder, the engine converges with the check passing, and its final posterior is
    // the exact one: every mean within 0.1 posterior std and every std within 10 % (the
    // pipeline's spread on the cooling study is half of that, crates/iuq/tests/cli_adaptive.rs).
    assert_eq!(v["converged"], true, "{v}");
    let last = rounds.last().unwrap();
    assert_eq!(last["sampler_agreement"]["disagrees"], false, "{last}");
    let parameters = v["posterior"][0]["parameters"].as_array().unwrap();
    for (k, p) in parameters.iter().enumerate() {
        let (m, s) = (p["mean"].as_f64().unwrap(), p["std"].as_f64().unwrap());
        assert!(
            (m - mean[k]).abs() < 0.1 * std[k],
            "{p}: exact {} ± {}",
            mean[k],
            std[k]
        );
        assert!((s / std[k] - 1.0).abs() < 0.1, "{p}: exact std {}", std[k]);
    }
}

#[test]
fn the_default_sampler_passes_its_check_from_the_first_round() {
    let dir = scratch("sampler-check", "default");
    let (path, mean, std) = write_study(&dir, "samples = 4000\nseed = 3");
    let (v, rounds) = run(&path, &dir.join("report"));
    // Every round is checked; the last passes at the study's own mixing (a round whose check
    // fails on noise alone would only raise the level).
    let rounds = rounds.as_array().unwrap();
    assert!(rounds.iter().all(|r| r["sampler_agreement"].is_object()));
    let last = rounds.last().unwrap();
    assert_eq!(last["sampler_agreement"]["disagrees"], false, "{last}");
    assert_eq!(last["mixing_level"], 0, "{last}");
    assert_eq!(v["converged"], true, "{v}");
    let parameters = v["posterior"][0]["parameters"].as_array().unwrap();
    for (k, p) in parameters.iter().enumerate() {
        let (m, s) = (p["mean"].as_f64().unwrap(), p["std"].as_f64().unwrap());
        assert!(
            (m - mean[k]).abs() < 0.1 * std[k],
            "{p}: exact {} ± {}",
            mean[k],
            std[k]
        );
        assert!((s / std[k] - 1.0).abs() < 0.1, "{p}: exact std {}", std[k]);
    }
}
