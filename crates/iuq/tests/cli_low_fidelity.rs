//! Two fidelities (`[low_fidelity]`): the expensive model y = A·e^(−k t) + 0.3·sin(k t) at ten
//! times, calibrated with the help of a cheap one, against the exact posterior (a 600 × 600 grid
//! over the uniform prior) and against the same study with the expensive model alone.
//!
//! Tolerances: the final posterior's members (10,000 by default) give its means a Monte Carlo
//! error of about 0.02 posterior stds; the engine stops when the surrogate's error could move a
//! mean or std by up to `tolerance` = 0.1 posterior stds. So a mean within 0.15 posterior stds and
//! a std within 10 % hold for an emulator that is right, and an emulator biased by its cheap model
//! (a cheap model that does not correlate, taken at its word) misses them by far: before the
//! guard on the explained share, the uncorrelated case below ended 3–4.5 stds off.

use crate::common;

use std::path::Path;

use crate::common::{iuq, pipeline, scratch, stderr_of};

const TIMES: usize = 10;

fn expensive(a: f64, k: f64, t: f64) -> f64 {
    a * (-k * t).exp() + 0.3 * (k * t).sin()
}

/// Data from A = 5, k = 0.3 with noise 0.05 (fixed deviates).
fn data() -> Vec<(f64, f64)> {
    let noise = [-0.7, 0.35, 1.1, -0.2, 0.6, -1.3, 0.05, 0.9, -0.45, 0.25];
    (0..TIMES)
        .map(|i| {
            let t = i as f64;
            (t, expensive(5.0, 0.3, t) + 0.05 * noise[i])
        })
        .collect()
}

fn write_study(dir: &Path, name: &str, low_fidelity: &str) -> std::path::PathBuf {
    write_study_with(
        dir,
        name,
        low_fidelity,
        "design = { kind = \"lhs\", n = 8, seed = 1 }\n",
    )
}

/// [`write_study`] with `design` for its `[surrogate] design` line (empty: the default).
fn write_study_with(
    dir: &Path,
    name: &str,
    low_fidelity: &str,
    design: &str,
) -> std::path::PathBuf {
    let mut csv = String::from("t,y,y_err\n");
    for (t, y) in data() {
        csv.push_str(&format!("{t},{y},0.05\n"));
    }
    std::fs::write(dir.join("data.csv"), csv).unwrap();
    let text = format!(
        r#"name = "{name}"
[parameters]
A = {{ uniform = [1, 10] }}
k = {{ uniform = [0.05, 1] }}
[likelihood]
data = {{ file = "data.csv", x = "t", y = "y", y_err = "y_err" }}
[model]
kind = "expression"
abscissa = "t"
outputs = {{ y = "A * exp(-k * t) + 0.3 * sin(k * t)" }}
[surrogate]
{design}adaptive = {{ batch = 2, max_runs = 200 }}
[sampler]
seed = 1
{low_fidelity}"#
    );
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

/// The exact posterior's means and stds of (A, k), on a grid.
fn exact_moments() -> ([f64; 2], [f64; 2]) {
    let data = data();
    let n = 600;
    let (mut w_sum, mut m, mut s) = (0.0, [0.0; 2], [0.0; 2]);
    let mut log_likelihoods = Vec::with_capacity(n * n);
    for i in 0..n {
        let a = 1.0 + 9.0 * (i as f64 + 0.5) / n as f64;
        for j in 0..n {
            let k = 0.05 + 0.95 * (j as f64 + 0.5) / n as f64;
            let ll: f64 = data
                .iter()
                .map(|(t, y)| -0.5 * ((y - expensive(a, k, *t)) / 0.05).powi(2))
                .sum();
            log_likelihoods.push((a, k, ll));
        }
    }
    let max = log_likelihoods
        .iter()
        .fold(f64::MIN, |acc, (_, _, l)| acc.max(*l));
    for (a, k, ll) in &log_likelihoods {
        let w = (ll - max).exp();
        w_sum += w;
        m[0] += w * a;
        m[1] += w * k;
        s[0] += w * a * a;
        s[1] += w * k * k;
    }
    let mean = [m[0] / w_sum, m[1] / w_sum];
    let std = [
        (s[0] / w_sum - mean[0] * mean[0]).sqrt(),
        (s[1] / w_sum - mean[1] * mean[1]).sqrt(),
    ];
    (mean, std)
}

/// The surrogate posterior's (A, k) means and stds and the study model's runs.
fn calibrate(dir: &Path, study: &Path) -> ([f64; 2], [f64; 2], usize) {
    let (summary, log) = pipeline(study, &dir.join("out"), &[]);
    let parameters = summary["posterior"][0]["parameters"].as_array().unwrap();
    let moment = |name: &str, key: &str| {
        parameters
            .iter()
            .find(|p| p["parameter"] == name)
            .unwrap_or_else(|| panic!("{log}"))[key]
            .as_f64()
            .unwrap()
    };
    assert_eq!(summary["converged"], true, "{log}");
    (
        [moment("A", "mean"), moment("k", "mean")],
        [moment("A", "std"), moment("k", "std")],
        summary["runs"].as_u64().unwrap() as usize,
    )
}

fn assert_exact(label: &str, mean: [f64; 2], std: [f64; 2]) {
    let (exact_mean, exact_std) = exact_moments();
    for p in 0..2 {
        let error = (mean[p] - exact_mean[p]).abs() / exact_std[p];
        let ratio = std[p] / exact_std[p];
        assert!(
            error < 0.15 && (ratio - 1.0).abs() < 0.1,
            "{label}: parameter {p}: mean {} against {} ({error:.3} stds), std ratio {ratio:.3}",
            mean[p],
            exact_mean[p]
        );
    }
}

/// A cheap model that carries the expensive one's trend (the same decay without the sine) at a
/// declared cost ratio of 100: the exact posterior with fewer expensive runs than the expensive
/// model alone needs (83 against 113 when written), and the cheap runs in a store of their own.
#[test]
fn a_correlated_cheap_model_reaches_the_exact_posterior_with_fewer_expensive_runs() {
    let dir = scratch("low-fidelity", "correlated");
    let cheap = "[low_fidelity]\nkind = \"expression\"\nabscissa = \"t\"\noutputs = { y = \"A * exp(-k * t)\" }\ncost_ratio = 100\n";
    let two = write_study(&dir, "two", cheap);
    let (mean, std, two_runs) = calibrate(&dir, &two);
    assert_exact("two fidelities", mean, std);
    let alone_dir = scratch("low-fidelity", "alone");
    let alone = write_study(&alone_dir, "alone", "");
    let (mean, std, alone_runs) = calibrate(&alone_dir, &alone);
    assert_exact("the expensive model alone", mean, std);
    assert!(
        two_runs < alone_runs,
        "two fidelities took {two_runs} expensive runs, the expensive model alone {alone_runs}"
    );
    // The report shows both fidelities per data point.
    let html = std::fs::read_to_string(dir.join("out/report.html")).unwrap();
    assert!(html.contains("Two fidelities per data point"));
    let table = std::fs::read_to_string(dir.join("out/tables/two_fidelity.csv")).unwrap();
    assert_eq!(table.lines().count(), 1 + TIMES, "{table}");
    let cheap_store = dir.join("two.campaign/low-fidelity/campaign.sqlite");
    assert!(cheap_store.is_file(), "{}", cheap_store.display());
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("out/two-fidelity.json")).unwrap()).unwrap();
    for output in summary["outputs"].as_array().unwrap() {
        assert_eq!(output["uses_low_fidelity"], true, "{output}");
        assert!(
            (output["rho"].as_f64().unwrap() - 1.0).abs() < 0.05,
            "{output}"
        );
    }
}

/// With the default design, the ten data points' discrepancies are one GP in (θ, t)
/// (`iuq_gp::shared_discrepancy`): 3 expensive runs per data point to start with (30 in all,
/// where the expensive model alone starts from 6 per point) and the exact posterior from fewer
/// expensive runs than the expensive model alone with its default design, ρ one for all points.
#[test]
fn the_data_points_share_one_discrepancy_and_start_from_fewer_expensive_runs() {
    let dir = scratch("low-fidelity", "shared");
    let cheap = "[low_fidelity]\nkind = \"expression\"\nabscissa = \"t\"\noutputs = { y = \"A * exp(-k * t) * (1 + 0.03 * t)\" }\ncost_ratio = 100\n";
    let two = write_study_with(&dir, "shared", cheap, "");
    let (mean, std, two_runs) = calibrate(&dir, &two);
    assert_exact("one shared discrepancy", mean, std);
    let log = std::fs::read_to_string(dir.join("out/pipeline.log")).unwrap_or_default();
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("out/two-fidelity.json")).unwrap()).unwrap();
    let outputs = summary["outputs"].as_array().unwrap();
    let rho = outputs[0]["rho"].as_f64().unwrap();
    for output in outputs {
        assert_eq!(output["shared_discrepancy"], true, "{output} {log}");
        assert_eq!(output["uses_low_fidelity"], true, "{output}");
        assert_eq!(output["rho"].as_f64().unwrap(), rho);
    }
    let alone_dir = scratch("low-fidelity", "shared-alone");
    let alone = write_study_with(&alone_dir, "alone", "", "");
    let (mean, std, alone_runs) = calibrate(&alone_dir, &alone);
    assert_exact("the expensive model alone, default design", mean, std);
    println!(
        "expensive runs: shared discrepancy {two_runs}, the expensive model alone {alone_runs}"
    );
    assert!(
        two_runs < alone_runs,
        "one shared discrepancy took {two_runs} expensive runs, the expensive model alone {alone_runs}"
    );
}

/// A cheap model unrelated to the expensive one (an oscillation): it is not used, and the
/// posterior is the exact one from no more expensive runs than the expensive model alone.
#[test]
fn an_uncorrelated_cheap_model_leaves_the_expensive_runs_in_charge() {
    let dir = scratch("low-fidelity", "uncorrelated");
    let cheap = "[low_fidelity]\nkind = \"expression\"\nabscissa = \"t\"\noutputs = { y = \"cos(13 * A * k + t)\" }\ncost_ratio = 100\n";
    let study = write_study(&dir, "unrelated", cheap);
    let (mean, std, runs) = calibrate(&dir, &study);
    assert_exact("an uncorrelated cheap model", mean, std);
    assert!(runs <= 113 + 2, "{runs} expensive runs");
}

/// The same unrelated cheap model with the default design, which with a cheap model starts each
/// data point from 3 expensive runs (the shared discrepancy's share) where the expensive model
/// alone starts from 6: the shared discrepancy is not used, and the exact posterior comes from
/// no more expensive runs than the expensive model alone's with its own default design (95) and
/// a round's batch (2).
#[test]
fn an_uncorrelated_cheap_model_with_the_default_design_costs_no_more_expensive_runs() {
    let dir = scratch("low-fidelity", "uncorrelated-default");
    let cheap = "[low_fidelity]\nkind = \"expression\"\nabscissa = \"t\"\noutputs = { y = \"cos(13 * A * k + t)\" }\ncost_ratio = 100\n";
    let study = write_study_with(&dir, "unrelated", cheap, "");
    let (mean, std, runs) = calibrate(&dir, &study);
    assert_exact("an uncorrelated cheap model, default design", mean, std);
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("out/two-fidelity.json")).unwrap()).unwrap();
    for output in summary["outputs"].as_array().unwrap() {
        assert_eq!(output["shared_discrepancy"], false, "{output}");
    }
    println!("expensive runs with an unrelated cheap model, default design: {runs}");
    assert!(runs <= 95 + 2, "{runs} expensive runs");
}

/// A bad `[low_fidelity]` key is refused before any run, with exit code 2 naming the file and
/// the whole key.
#[test]
fn bad_low_fidelity_keys_exit_2_naming_file_and_key() {
    let dir = scratch("low-fidelity", "bad-keys");
    for (section, key) in [
        (
            "[low_fidelity]\nkind = \"expression\"\nabscissa = \"t\"\noutputs = { y = \"A\" }\ncost_ratio = -1\n",
            "low_fidelity.cost_ratio",
        ),
        (
            "[low_fidelity]\nkind = \"expression\"\nabscissa = \"t\"\noutputs = { y = \"A\" }\ndesign = { n = 4, seeds = 2 }\n",
            "low_fidelity.design.seeds",
        ),
        (
            "[low_fidelity]\nkind = \"expresion\"\n",
            "low_fidelity.kind",
        ),
        (
            "[low_fidelity]\nkind = \"expression\"\nabscissa = \"t\"\noutputs = { y = \"A * q\" }\n",
            "low_fidelity",
        ),
    ] {
        let study = write_study(&dir, "bad", section);
        let out = dir.join("out");
        let output = iuq(&[
            "pipeline",
            study.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        let stderr = stderr_of(&output);
        assert_eq!(output.status.code(), Some(2), "{section}: {stderr}");
        assert!(
            stderr.contains("bad.toml") && stderr.contains(&format!("`{key}")),
            "{section}: {stderr}"
        );
        assert!(
            !dir.join("bad.campaign").exists(),
            "{section}: a run was made"
        );
    }
    // A reduced basis asked for where the expensive model returns the whole curve but the
    // cheap one runs once per data point.
    let study = write_curve_study(&dir, "bad", false);
    let text = std::fs::read_to_string(&study)
        .unwrap()
        .replace("[surrogate]\n", "[surrogate]\nreduced_basis = true\n")
        + "[low_fidelity]\nkind = \"expression\"\nabscissa = \"t\"\noutputs = { y = \"A * exp(-gamma * t) * cos(omega * t)\" }\n";
    std::fs::write(&study, text).unwrap();
    let out = dir.join("out");
    let output = iuq(&[
        "pipeline",
        study.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let stderr = stderr_of(&output);
    assert_eq!(output.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("bad.toml") && stderr.contains("`surrogate.reduced_basis`"),
        "{stderr}"
    );
    assert!(!dir.join("bad.campaign").exists(), "a run was made");
}

/// The cooling study per time with the program (`cooling_model.py`, each run 0.2 s, every
/// finished run logged) as the cheap fidelity and the same Newton curve with a small sine as the
/// expensive expression, its cheap runs favoured (cost ratio 1,000).
fn mixed_cooling_study(dir: &Path, log: &Path) -> std::path::PathBuf {
    let text = std::fs::read_to_string(dir.join("cooling-per-time.toml")).unwrap();
    let program = "kind = \"command\"\ncommand = [\"./cooling_model.py\"]\nabscissa = \"t\"\noutputs = [\"T\"]\noutput = { file = \"result.json\", format = \"json\" }";
    assert!(text.contains(program));
    let expensive = "kind = \"expression\"\nabscissa = \"t\"\noutputs = { T = \"20 + (T0 - 20) * exp(-k * t) + 0.4 * sin(3 * k)\" }";
    let cheap = format!(
        "\n[low_fidelity]\n{program}\nenv = {{ COOLING_SLEEP = \"0.2\", COOLING_RUN_LOG = \"{}\" }}\ndesign = {{ n = 2, seed = 2 }}\ncost_ratio = 1000\n\n[executor]\nkind = \"local\"\nmax_parallel = 2\n",
        log.display()
    );
    let path = dir.join("mixed.toml");
    // The test is of resumption, not of the posterior's precision: 4,000 samples a replicate
    // instead of the example's 10,000 (its time is mostly sampling).
    let text = text.replace("samples = 10000", "samples = 4000");
    assert!(text.contains("samples = 4000"));
    std::fs::write(&path, text.replace(program, expensive) + &cheap).unwrap();
    path
}

/// kill -9 while a round's cheap runs are under way (60 ms into the first one's 0.2 s: a run
/// that the campaign had not seen finish is lost and made again, by the local executor's
/// design), then rerun: every finished run is kept
/// (none run twice: the log of finished runs has no repeated line, and the killed pipeline's log
/// is a prefix of the whole) and the result is that of an uninterrupted pipeline (the same
/// runs, rounds and posterior moments, bit for bit).
#[test]
fn a_pipeline_killed_during_a_mixed_round_continues_without_losing_or_repeating_runs() {
    use std::process::{Command, Stdio};
    use std::time::{Duration, Instant};
    // The initial runs alone (`--runs-only`) in the pipeline that is not killed: how many cheap
    // runs (run directories) there are before the first round.
    let clean_dir = common::cooling_example("low-fidelity", "clean");
    let clean_log = clean_dir.join("finished.jsonl");
    let clean_study = mixed_cooling_study(&clean_dir, &clean_log);
    pipeline(&clean_study, &clean_dir.join("report"), &["--runs-only"]);
    let run_directories = |d: &Path| {
        std::fs::read_dir(d.join("mixed.campaign/low-fidelity/runs")).map_or(0, |r| r.count())
    };
    let initial = run_directories(&clean_dir);
    let dir = common::cooling_example("low-fidelity", "killed");
    let log = dir.join("finished.jsonl");
    let study = mixed_cooling_study(&dir, &log);
    let out = dir.join("report");
    let mut child = Command::new(env!("CARGO_BIN_EXE_iuq"))
        .args(["pipeline", study.to_str().unwrap(), "--out"])
        .arg(&out)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let started = Instant::now();
    while run_directories(&dir) <= initial {
        assert!(
            started.elapsed() < Duration::from_secs(300),
            "no round's cheap run"
        );
        assert!(
            child.try_wait().unwrap().is_none(),
            "finished before a round's cheap run"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    std::thread::sleep(Duration::from_millis(60));
    child.kill().unwrap();
    child.wait().unwrap();
    let before = std::fs::read_to_string(&log).unwrap();
    let (resumed, _) = pipeline(&study, &out, &[]);
    assert_eq!(resumed["converged"], true, "{resumed}");
    let text = std::fs::read_to_string(&log).unwrap();
    let all: Vec<&str> = text.lines().collect();
    let mut unique = all.clone();
    unique.sort_unstable();
    unique.dedup();
    assert_eq!(unique.len(), all.len(), "a finished cheap run was repeated");
    assert!(text.starts_with(&before));
    let (clean, _) = pipeline(&clean_study, &clean_dir.join("report"), &[]);
    assert_eq!(resumed["runs"], clean["runs"]);
    assert_eq!(resumed["rounds"], clean["rounds"]);
    assert_eq!(resumed["posterior"], clean["posterior"]);
    let cheap_runs = |d: &Path| {
        std::fs::read_to_string(d.join("finished.jsonl"))
            .unwrap()
            .lines()
            .count()
    };
    assert_eq!(cheap_runs(&dir), cheap_runs(&clean_dir));
    assert!(run_directories(&dir) > initial);
}

/// The damped oscillation A·e^(−γt)·cos(ωt) at 60 times, a whole curve per run.
const CURVE_TIMES: usize = 60;

fn curve_time(i: usize) -> f64 {
    0.1 + 0.1 * i as f64
}

fn oscillation(a: f64, gamma: f64, omega: f64, t: f64) -> f64 {
    a * (-gamma * t).exp() * (omega * t).cos()
}

/// Data from A = 1.5, γ = 0.3, ω = 2 with noise 0.05 (fixed deviates, uniform on ±0.05·√3).
fn curve_data() -> Vec<(f64, f64)> {
    (0..CURVE_TIMES)
        .map(|i| {
            let t = curve_time(i);
            let deviate = ((i * 37) % CURVE_TIMES) as f64 / CURVE_TIMES as f64 - 0.5;
            (
                t,
                oscillation(1.5, 0.3, 2.0, t) + 0.05 * 12f64.sqrt() * deviate,
            )
        })
        .collect()
}

/// The oscillation study: the expensive model, and the cheap one (ω 1 % off: its curves drift
/// out of phase, 3.4 posterior stds of bias in the benchmark) where `cheap` is set.
fn write_curve_study(dir: &Path, name: &str, cheap: bool) -> std::path::PathBuf {
    let mut csv = String::from("t,y,y_err\n");
    for (t, y) in curve_data() {
        csv.push_str(&format!("{t:?},{y:?},0.05\n"));
    }
    std::fs::write(dir.join("data.csv"), csv).unwrap();
    let outputs = |scale: &str| {
        (0..CURVE_TIMES)
            .map(|i| {
                let t = curve_time(i);
                format!("y{i} = \"A * exp(-gamma * {t:?}) * cos({scale}omega * {t:?})\"")
            })
            .collect::<Vec<_>>()
            .join(", ")
    };
    let low = if cheap {
        format!(
            "[low_fidelity]\nkind = \"expression\"\noutputs = {{ {} }}\ncost_ratio = 100\n",
            outputs("1.01 * ")
        )
    } else {
        String::new()
    };
    let text = format!(
        r#"name = "{name}"
[parameters]
A = {{ uniform = [0.5, 3.0] }}
gamma = {{ uniform = [0.05, 0.8] }}
omega = {{ uniform = [1.0, 3.0] }}
[likelihood]
data = {{ file = "data.csv", x = "t", y = "y", y_err = "y_err" }}
[model]
kind = "expression"
outputs = {{ {} }}
[surrogate]
adaptive = {{}}
[sampler]
seed = 1
{low}"#,
        outputs("")
    );
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

/// The exact posterior's means and stds of (A, γ, ω): a 90³ midpoint grid over a box of about
/// ±9 posterior stds around the truth (the posterior is about 10⁻⁶ of the prior's box, so a grid
/// over the whole box would miss it; nothing of it lies outside: the box's edges are 40 log
/// units below its peak).
fn curve_exact_moments() -> ([f64; 3], [f64; 3]) {
    let data = curve_data();
    let n = 90;
    let boxes = [(1.25, 1.75), (0.22, 0.38), (1.94, 2.06)];
    let at = |b: (f64, f64), i: usize| b.0 + (b.1 - b.0) * (i as f64 + 0.5) / n as f64;
    let mut cells = Vec::with_capacity(n * n * n);
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let theta = [at(boxes[0], i), at(boxes[1], j), at(boxes[2], k)];
                let ll: f64 = data
                    .iter()
                    .map(|(t, y)| {
                        -0.5 * ((y - oscillation(theta[0], theta[1], theta[2], *t)) / 0.05).powi(2)
                    })
                    .sum();
                cells.push((theta, ll));
            }
        }
    }
    let max = cells.iter().fold(f64::MIN, |m, c| m.max(c.1));
    let edge = cells
        .iter()
        .filter(|(t, _)| {
            (0..3).any(|p| (t[p] - boxes[p].0).abs() < 0.01 * (boxes[p].1 - boxes[p].0))
        })
        .fold(f64::MIN, |m, c| m.max(c.1));
    assert!(
        max - edge > 20.0,
        "the grid's box cuts the posterior ({})",
        max - edge
    );
    let (mut w_sum, mut m, mut s) = (0.0, [0.0; 3], [0.0; 3]);
    for (theta, ll) in &cells {
        let w = (ll - max).exp();
        w_sum += w;
        for p in 0..3 {
            m[p] += w * theta[p];
            s[p] += w * theta[p] * theta[p];
        }
    }
    let mean = m.map(|v| v / w_sum);
    let std = [0, 1, 2].map(|p| (s[p] / w_sum - mean[p] * mean[p]).sqrt());
    (mean, std)
}

/// A whole curve of 60 points with a cheap model of the same shapes, a frequency 1 % off, at a
/// cost ratio of 100: the emulator is a reduced basis of both fidelities' curves (automatic at
/// 60 points), each principal component a two-fidelity GP; it reaches the exact posterior (means
/// within 0.15 and stds within 10 % of the exact ones, as the file's header says) with fewer
/// expensive runs than the expensive model alone (11 against 19 when written; on the
/// benchmark's data, `scripts/bench/multi_fidelity.py`, 11 against 28).
#[test]
fn a_whole_curve_of_two_fidelities_is_emulated_on_a_reduced_basis_with_fewer_expensive_runs() {
    let (exact_mean, exact_std) = curve_exact_moments();
    let assert_exact = |label: &str, summary: &serde_json::Value| {
        let parameters = summary["posterior"][0]["parameters"].as_array().unwrap();
        for (p, name) in ["A", "gamma", "omega"].iter().enumerate() {
            let row = parameters.iter().find(|r| r["parameter"] == *name).unwrap();
            let error = (row["mean"].as_f64().unwrap() - exact_mean[p]).abs() / exact_std[p];
            let ratio = row["std"].as_f64().unwrap() / exact_std[p];
            assert!(
                error < 0.15 && (ratio - 1.0).abs() < 0.1,
                "{label}: {name}: mean {} against {} ({error:.3} stds), std ratio {ratio:.3}",
                row["mean"],
                exact_mean[p]
            );
        }
        assert_eq!(summary["converged"], true, "{label}");
        summary["runs"].as_u64().unwrap()
    };
    let dir = scratch("low-fidelity", "curve-two");
    let (two, log) = pipeline(&write_curve_study(&dir, "two", true), &dir.join("out"), &[]);
    let two_runs = assert_exact("two fidelities", &two);
    assert!(
        log.contains("two fidelities: the cheap model helps"),
        "{log}"
    );
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("out/two-fidelity.json")).unwrap()).unwrap();
    let components = summary["components"].as_array().unwrap();
    assert!(
        components.iter().any(|c| c["uses_low_fidelity"] == true),
        "{summary}"
    );
    assert!(dir.join("out/reduced-basis.json").is_file());
    // The report shows both fidelities per component, with the runs of each.
    let html = std::fs::read_to_string(dir.join("out/report.html")).unwrap();
    assert!(html.contains("Two fidelities per principal component"));
    let table =
        std::fs::read_to_string(dir.join("out/tables/two_fidelity_components.csv")).unwrap();
    assert_eq!(table.lines().count(), 1 + components.len(), "{table}");
    let expensive_runs = two["runs"].as_u64().unwrap().to_string();
    assert!(
        table
            .lines()
            .skip(1)
            .all(|row| row.split(',').nth(6) == Some(expensive_runs.as_str())),
        "every component's expensive runs are the study's {expensive_runs}: {table}"
    );
    let alone_dir = scratch("low-fidelity", "curve-alone");
    let (alone, _) = pipeline(
        &write_curve_study(&alone_dir, "alone", false),
        &alone_dir.join("out"),
        &[],
    );
    let alone_runs = assert_exact("the expensive model alone", &alone);
    assert!(
        two_runs < alone_runs,
        "two fidelities took {two_runs} expensive runs, the expensive model alone {alone_runs}"
    );
}
