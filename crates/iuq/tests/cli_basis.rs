//! End-to-end tests of `iuq basis`: real processes, real files.

use crate::common::{iuq, json_of, scratch};

use std::path::Path;
use std::process::Command;

fn write(path: &Path, text: &str) {
    std::fs::write(path, text).unwrap();
}

fn s(path: &Path) -> &str {
    path.to_str().unwrap()
}

const GAUSSIAN_2D: &str = r#"
name = "gauss2"
[parameters]
x = { uniform = [-15, 15] }
y = { uniform = [-15, 15] }
[likelihood]
log_density = "-0.5*(x^2 + y^2) - ln(2*pi)"
[sampler]
samples = 1000
seed = 4
"#;

#[test]
fn log_density_study_writes_samples_stages_summary_and_checkpoint() {
    let dir = scratch("cli-basis", "log-density");
    let study = dir.join("study.toml");
    write(&study, GAUSSIAN_2D);
    let out = dir.join("out");
    let o = iuq(&["basis", s(&study), "--out", s(&out), "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json_of(&o);
    // exact ln Z = −ln 900 = −6.802395; single-run sd at N = 1000 is at most 0.35
    let log_z = v["log_evidence"].as_f64().unwrap();
    assert!((log_z + 6.802395).abs() < 4.0 * 0.35, "{log_z}");
    assert_eq!(v["stop_reason"], "converged");
    assert_eq!(v["converged"], true);
    assert!(v["stages"].as_u64().unwrap() >= 3);
    assert!(v["evaluations"].as_u64().unwrap() >= 1000);
    for key in ["map", "mean", "std"] {
        let m = v[key].as_object().unwrap();
        assert_eq!(m.keys().collect::<Vec<_>>(), vec!["x", "y"], "{key}");
    }
    assert!(v["mean"]["x"].as_f64().unwrap().abs() < 0.3);
    assert!((v["std"]["y"].as_f64().unwrap() - 1.0).abs() < 0.2);
    // progress lines on stderr (not a terminal here)
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("basis: stage 0:") && stderr.contains("ln Z so far"));

    let samples = std::fs::read_to_string(out.join("samples.csv")).unwrap();
    let mut lines = samples.lines();
    assert_eq!(lines.next(), Some("x,y,ll,lp"));
    assert_eq!(lines.count(), 1000);
    let stages = std::fs::read_to_string(out.join("stages.csv")).unwrap();
    assert!(stages.starts_with("stage,exponent,step,cv,ess_fraction"));
    assert_eq!(
        stages.lines().count(),
        v["stages"].as_u64().unwrap() as usize + 2
    );
    let stages_json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("stages.json")).unwrap()).unwrap();
    assert!(stages_json[1]["failure_reasons"].is_object());
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["log_evidence"], v["log_evidence"]);
    assert!(summary["quantiles"]["x"]["0.5"].is_number());
    assert_eq!(summary["settings"]["seed"], 4);
    let checkpoint: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("checkpoint.json")).unwrap())
            .unwrap();
    assert_eq!(checkpoint["format"], "iuq-basis-checkpoint");
    assert_eq!(checkpoint["version"], 1);
    assert_eq!(checkpoint["stop_reason"]["kind"], "converged");
    let marginals: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("marginals.json")).unwrap())
            .unwrap();
    assert_eq!(
        marginals["one_dimensional"][0]["grid"]
            .as_array()
            .unwrap()
            .len(),
        200
    );
    assert_eq!(marginals["two_dimensional"].as_array().unwrap().len(), 1);
}

fn linear_data(dir: &Path) {
    std::fs::create_dir_all(dir.join("data")).unwrap();
    let mut text = String::from("# a straight line with known errors\nstress,el,el_err\n");
    for j in 0..12 {
        let x = j as f64;
        let y = 1.0 + 0.5 * x + 0.05 * (37.0 * x).sin();
        text.push_str(&format!("{x},{y},{}\n", 0.05 + 0.01 * x));
    }
    write(&dir.join("data/line.csv"), &text);
}

#[test]
fn data_study_with_a_prediction_formula_estimates_sigma_m() {
    let dir = scratch("cli-basis", "prediction");
    linear_data(&dir);
    let study = dir.join("study.toml");
    write(
        &study,
        r#"
name = "line"
[parameters]
a = { uniform = [-5, 5] }
b = { uniform = [-2, 2] }
[likelihood]
data = { file = "data/line.csv", x = "stress", y = "el", y_err = "el_err", x_range = [1, 10] }
prediction = "a + b*x"
modelling_error = { uniform = [0.001, 0.1] }
computational_error = "relative"
[sampler]
samples = 1000
burn = 2
seed = 2
"#,
    );
    let out = dir.join("out");
    // run from another directory: the data path is relative to the study file
    let o = Command::new(env!("CARGO_BIN_EXE_iuq"))
        .args(["basis", s(&study), "--out", s(&out), "--json"])
        .current_dir(std::env::temp_dir())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json_of(&o);
    for key in ["map", "mean", "std"] {
        let names: Vec<&String> = v[key].as_object().unwrap().keys().collect();
        assert_eq!(names, vec!["a", "b", "sigma_m"], "{key}");
    }
    assert!((v["mean"]["b"].as_f64().unwrap() - 0.5).abs() < 0.1);
    let sigma_m = v["mean"]["sigma_m"].as_f64().unwrap();
    assert!(sigma_m > 0.001 && sigma_m < 0.1);
    let header = std::fs::read_to_string(out.join("samples.csv")).unwrap();
    assert!(header.starts_with("a,b,sigma_m,ll,lp\n"));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(
        summary["likelihood"]["points"], 10,
        "x_range keeps x = 1..10"
    );
}

#[test]
fn data_study_with_an_expression_model_compares_outputs_by_order_and_counts_failures() {
    let dir = scratch("cli-basis", "expression-model");
    linear_data(&dir);
    let study = dir.join("study.toml");
    // three data points (x = 2, 3, 4); output j ↔ data point j. The sqrt fails for a < 0.5:
    // those points are rejected and counted.
    let text = r#"
name = "by-order"
[parameters]
a = { uniform = [0, 5] }
b = { uniform = [-2, 2] }
[model]
kind = "expression"
outputs = { y2 = "a + 2*b + 0*sqrt(a - 0.5)", y3 = "a + 3*b", y4 = "a + 4*b" }
[likelihood]
data = { file = "data/line.csv", x = "stress", y = "el", y_err = "el_err", x_range = [2, 4] }
modelling_error = false
"#;
    write(&study, text);
    let out = dir.join("out");
    let o = iuq(&[
        "basis",
        s(&study),
        "--out",
        s(&out),
        "--samples",
        "800",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json_of(&o);
    assert_eq!(
        v["mean"].as_object().unwrap().keys().collect::<Vec<_>>(),
        vec!["a", "b"]
    );
    assert!(v["failures"].as_u64().unwrap() > 0);
    let reasons = v["failure_reasons"].as_object().unwrap();
    assert!(
        reasons.keys().any(|r| r.contains("not finite")),
        "{reasons:?}"
    );
    assert!(v["map"]["a"].as_f64().unwrap() >= 0.5);
    let samples = std::fs::read_to_string(out.join("samples.csv")).unwrap();
    assert!(!samples.contains("NaN") && !samples.contains("inf"));

    // a model whose output count differs from the data is bad input naming `model.outputs`
    write(
        &study,
        &text.replace("x_range = [2, 4]", "x_range = [2, 5]"),
    );
    let o = iuq(&["basis", s(&study), "--out", s(&out), "--json"]);
    assert_eq!(o.status.code(), Some(2));
    let message = json_of(&o)["error"]["message"]
        .as_str()
        .unwrap()
        .to_string();
    assert!(
        message.contains("study.toml") && message.contains("model.outputs"),
        "{message}"
    );
}

#[test]
fn stopping_and_resuming_gives_the_uninterrupted_result() {
    let dir = scratch("cli-basis", "resume");
    let study = dir.join("study.toml");
    write(
        &study,
        &GAUSSIAN_2D.replace(
            "log_density = \"-0.5*(x^2 + y^2) - ln(2*pi)\"",
            "log_density = \"-(100*(y - x^2)^2 + (x - 1)^2)\"",
        ),
    );
    let full = dir.join("full");
    let o = iuq(&[
        "basis",
        s(&study),
        "--out",
        s(&full),
        "--samples",
        "600",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v_full = json_of(&o);
    let part = dir.join("part");
    for stop_after in ["0", "3"] {
        let o = iuq(&[
            "basis",
            s(&study),
            "--out",
            s(&part),
            "--samples",
            "600",
            "--stop-after",
            stop_after,
            "--json",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v = json_of(&o);
        assert_eq!(v["stop_reason"], "interrupted");
        assert_eq!(v["stages"].as_u64().unwrap().to_string(), stop_after);
        let o = iuq(&[
            "basis",
            s(&study),
            "--resume",
            s(&part),
            "--samples",
            "600",
            "--json",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v = json_of(&o);
        assert_eq!(v["stop_reason"], "converged");
        for key in [
            "log_evidence",
            "stages",
            "evaluations",
            "map",
            "mean",
            "std",
        ] {
            assert_eq!(v[key], v_full[key], "{key}");
        }
        assert_eq!(
            std::fs::read(part.join("samples.csv")).unwrap(),
            std::fs::read(full.join("samples.csv")).unwrap()
        );
    }
    // resuming with other settings is bad input
    let o = iuq(&[
        "basis",
        s(&study),
        "--resume",
        s(&part),
        "--samples",
        "600",
        "--seed",
        "9",
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--resume"));
    let o = iuq(&["basis", s(&study), "--resume", s(&dir.join("nowhere"))]);
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn bad_study_files_are_rejected_with_exit_code_2_naming_file_and_key() {
    let dir = scratch("cli-basis", "bad");
    linear_data(&dir);
    let data_study = r#"
name = "line"
[parameters]
a = { uniform = [-5, 5] }
b = { uniform = [-2, 2] }
[model]
kind = "expression"
outputs = { f = "a" }
[likelihood]
data = { file = "data/line.csv", x = "stress", y = "el", y_err = "el_err" }
prediction = "a + b*x"
[sampler]
samples = 500
"#;
    let cases: Vec<(String, &str)> = vec![
        (
            GAUSSIAN_2D.replace("log_density", "log_densty"),
            "likelihood.log_densty",
        ),
        (
            GAUSSIAN_2D.replace("- ln(2*pi)\"", "- ln(2*pi) + z\""),
            "likelihood.log_density",
        ),
        (
            GAUSSIAN_2D.replace("[likelihood]\n", "[likelihood]\nmodelling_error = false\n"),
            "likelihood.modelling_error",
        ),
        (
            GAUSSIAN_2D.replace(
                "[likelihood]\nlog_density = \"-0.5*(x^2 + y^2) - ln(2*pi)\"\n",
                "",
            ),
            "[likelihood]",
        ),
        (
            GAUSSIAN_2D.replace("samples = 1000", "samples = 1"),
            "sampler.samples",
        ),
        (
            GAUSSIAN_2D.replace("samples = 1000", "samples = -5"),
            "sampler.samples",
        ),
        (
            GAUSSIAN_2D.replace("seed = 4", "seed = 4\nresampling = \"stratified\""),
            "sampler.resampling",
        ),
        (
            GAUSSIAN_2D.replace("seed = 4", "seed = 4\ncv_target = 0"),
            "sampler.cv_target",
        ),
        (GAUSSIAN_2D.replace("seed = 4", "sead = 4"), "sampler.sead"),
        (
            GAUSSIAN_2D.replace("seed = 4", "seed = 4\nburn = \"soon\""),
            "sampler.burn",
        ),
        (
            GAUSSIAN_2D.replace("seed = 4", "seed = 4\nburn = 10\ncorrelation = 0.2"),
            "sampler.correlation",
        ),
        (
            GAUSSIAN_2D.replace("seed = 4", "seed = 4\ncorrelation = 1.5"),
            "sampler.correlation",
        ),
        (
            GAUSSIAN_2D.replace("seed = 4", "seed = 4\nproposal_scale = 0.3\nmax_burn = 20"),
            "sampler.max_burn",
        ),
        (
            GAUSSIAN_2D.replace("seed = 4", "seed = 4\nmax_burn = 0"),
            "sampler.max_burn",
        ),
        // Step counts no run could afford, which would overflow their sums: errors, not panics.
        (
            GAUSSIAN_2D.replace("seed = 4", "seed = 4\nburn = 9223372036854775807"),
            "sampler.burn",
        ),
        (
            GAUSSIAN_2D.replace("seed = 4", "seed = 4\nmax_stages = 2000000"),
            "sampler.max_stages",
        ),
        (
            data_study.replace("data/line.csv", "data/missing.csv"),
            "likelihood.data.file",
        ),
        (
            data_study.replace("y = \"el\"", "y = \"elongation\""),
            "likelihood.data.y",
        ),
        (
            data_study.replace(
                "y_err = \"el_err\"",
                "y_err = \"el_err\", x_range = [20, 30]",
            ),
            "likelihood.data",
        ),
        (
            data_study.replace("y_err = \"el_err\"", "y_err = \"el_err\", columns = 3"),
            "likelihood.data.columns",
        ),
        (
            data_study.replace("prediction = \"a + b*x\"", "prediction = \"a + b*t\""),
            "likelihood.prediction",
        ),
        (
            data_study.replace(
                "prediction = \"a + b*x\"",
                "prediction = \"a + b*x\"\nmodelling_error = { uniform = [0.1, 0.01] }",
            ),
            "likelihood.modelling_error",
        ),
        (
            data_study.replace(
                "prediction = \"a + b*x\"",
                "prediction = \"a + b*x\"\ncomputational_error = \"sometimes\"",
            ),
            "likelihood.computational_error",
        ),
        (
            data_study.replace(
                "prediction = \"a + b*x\"",
                "prediction = \"a + b*x\"\nlog_density = \"a\"",
            ),
            "likelihood.log_density",
        ),
    ];
    let study = dir.join("study.toml");
    for (text, key) in cases {
        write(&study, &text);
        let o = iuq(&["basis", s(&study), "--out", s(&dir.join("out")), "--json"]);
        assert_eq!(
            o.status.code(),
            Some(2),
            "{key}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let v = json_of(&o);
        assert_eq!(v["error"]["kind"], "bad_input");
        let message = v["error"]["message"].as_str().unwrap();
        assert!(
            message.contains("study.toml") && message.contains(key),
            "{key}: {message}"
        );
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
    // a bad flag names the flag
    write(&study, GAUSSIAN_2D);
    let o = iuq(&["basis", s(&study), "--samples", "1", "--json"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        json_of(&o)["error"]["message"]
            .as_str()
            .unwrap()
            .contains("--samples")
    );
    let o = iuq(&[
        "basis",
        s(&study),
        "--burn",
        "18446744073709551615",
        "--json",
    ]);
    assert_eq!(
        o.status.code(),
        Some(2),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        json_of(&o)["error"]["message"]
            .as_str()
            .unwrap()
            .contains("--burn")
    );
}
