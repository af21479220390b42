//! A whole-curve model emulated on its principal components (`[surrogate] reduced_basis`): the
//! cooling program (`examples/cooling/cooling_model.py --curve`) at 120 measurement times, its
//! failure region (k > 0.5) included, calibrated by the adaptive engine to the exact posterior
//! (BASIS on the closed-form curve, N = 20,000).
//!
//! Tolerances: those of the per-output pipeline on the same model (`cli_adaptive.rs`: 0.18
//! posterior stds for a mean, 10 % for a std, three and five times its spread over 7 seeds); a
//! reduced basis that mis-emulated the curve (too few components, its truncation error left out
//! of the likelihood) would miss them by far: the curve's 120 points each carry 0.8 °C noise, so a
//! systematic error of a tenth of that moves the posterior by more than a posterior std.

use std::path::Path;

use crate::common::{cooling_example, iuq, json_of};

/// Standard normal deviates from a fixed linear congruential generator (Box–Muller), so that the
/// test's data need no file.
fn deviates(count: usize) -> Vec<f64> {
    let mut state: u64 = 2026;
    let mut uniform = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    (0..count)
        .map(|_| {
            let (u, v) = (uniform(), uniform());
            (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
        })
        .collect()
}

fn times() -> Vec<f64> {
    (1..=120).map(|i| 0.1 * i as f64).collect()
}

fn write_data(dir: &Path) {
    let mut csv = String::from("t_min,temperature_c,temperature_err_c\n");
    for (t, e) in times().iter().zip(deviates(120)) {
        let temperature = 20.0 + (88.0 - 20.0) * (-0.3 * t).exp() + 0.8 * e;
        csv.push_str(&format!("{t},{temperature:.6},0.8\n"));
    }
    std::fs::write(dir.join("long.csv"), csv).unwrap();
}

fn moments(v: &serde_json::Value) -> Vec<(String, f64, f64)> {
    v["posterior"][0]["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            (
                p["parameter"].as_str().unwrap().to_string(),
                p["mean"].as_f64().unwrap(),
                p["std"].as_f64().unwrap(),
            )
        })
        .collect()
}

#[test]
fn a_reduced_basis_study_of_a_long_curve_converges_to_the_exact_posterior() {
    let dir = cooling_example("reduced-basis", "long-curve");
    write_data(&dir);
    let exact_study = std::fs::read_to_string(dir.join("cooling-exact.toml"))
        .unwrap()
        .replace("cooling.csv", "long.csv");
    std::fs::write(dir.join("exact.toml"), exact_study).unwrap();
    let output = iuq(&[
        "basis",
        dir.join("exact.toml").to_str().unwrap(),
        "--out",
        dir.join("exact").to_str().unwrap(),
        "--json",
    ]);
    assert!(output.status.success(), "{output:?}");
    let exact = json_of(&output);

    let arguments: Vec<String> = times().iter().map(|t| format!("\"{t}\"")).collect();
    let study = format!(
        "name = \"long-curve\"\n\n[parameters]\nk = {{ uniform = [0.05, 0.8] }}\nT0 = {{ uniform = [60, 100] }}\n\n\
         [likelihood]\ndata = {{ file = \"long.csv\", x = \"t_min\", y = \"temperature_c\", y_err = \"temperature_err_c\" }}\n\
         modelling_error = false\n\n[model]\nkind = \"command\"\n\
         command = [\"./cooling_model.py\", \"--curve\", {}]\n\
         output = {{ file = \"result.json\", format = \"json\", array = \"/T\" }}\n\n\
         [surrogate]\ndesign = {{ kind = \"lhs\", n = 8, seed = 1 }}\n\
         adaptive = {{ batch = 3, max_runs = 60, tolerance = 0.1 }}\n\
         reduced_basis = {{ explained_variance = 0.99999 }}\n\n[sampler]\nsamples = 10000\nseed = 1\n",
        arguments.join(", ")
    );
    let path = dir.join("long-curve.toml");
    std::fs::write(&path, study).unwrap();
    let out = dir.join("report");
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
    let v = json_of(&output);
    assert_eq!(v["converged"], true, "{v}");
    for (name, mean, std) in moments(&v) {
        let (m, s) = (
            exact["mean"][&name].as_f64().unwrap(),
            exact["std"][&name].as_f64().unwrap(),
        );
        assert!(
            (mean - m).abs() < 0.18 * s,
            "{name}: {mean} vs exact {m} ± {s}"
        );
        assert!(
            (std / s - 1.0).abs() < 0.1,
            "{name}: std {std} vs exact {s}"
        );
    }
    // The basis: a handful of components for 120 outputs, and what they leave stated.
    let basis: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("reduced-basis.json")).unwrap())
            .unwrap();
    let components = basis["components"].as_u64().unwrap();
    assert!((1..=10).contains(&components), "{basis}");
    assert!(basis["explained_variance_total"].as_f64().unwrap() >= 0.99999);
    assert_eq!(basis["truncation_std"].as_array().unwrap().len(), 120);
    // No GP per point was written: the report and the Sobol' indices came from the basis.
    assert!(!out.join("gp-bank.json").exists());
    assert!(out.join("report.html").exists());
}

#[test]
fn a_reduced_basis_of_a_model_run_per_data_point_exits_2_naming_the_key() {
    let dir = cooling_example("reduced-basis", "per-point");
    let study = std::fs::read_to_string(dir.join("cooling-per-time.toml"))
        .unwrap()
        .replace("[surrogate]\n", "[surrogate]\nreduced_basis = true\n");
    let path = dir.join("per-point.toml");
    std::fs::write(&path, study).unwrap();
    let output = iuq(&["pipeline", path.to_str().unwrap(), "--json"]);
    assert_eq!(output.status.code(), Some(2));
    let message = json_of(&output)["error"]["message"]
        .as_str()
        .unwrap()
        .to_string();
    assert!(
        message.contains("per-point.toml") && message.contains("`surrogate.reduced_basis`"),
        "{message}"
    );
    let bad = std::fs::read_to_string(dir.join("cooling-curve.toml"))
        .unwrap()
        .replace(
            "[surrogate]\n",
            "[surrogate]\nreduced_basis = { explained_variance = 1.5 }\n",
        );
    std::fs::write(&path, bad).unwrap();
    let output = iuq(&["pipeline", path.to_str().unwrap(), "--json"]);
    assert_eq!(output.status.code(), Some(2));
    let message = json_of(&output)["error"]["message"]
        .as_str()
        .unwrap()
        .to_string();
    assert!(
        message.contains("surrogate.reduced_basis.explained_variance"),
        "{message}"
    );
}
