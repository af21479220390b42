//! End-to-end test of `iuq pipeline` on a small configuration of the real cell model: two
//! stresses, a few training and test runs, Sobol' indices from model runs and from the
//! surrogate, BASIS on the GP bank and on the cell model through the campaign, and the report.
//!
//! The cell-model runs are real (`iuq rbc shear` processes of the campaign executor) but short:
//! `start_strain = 0.05` ends each run after about 170 lattice steps instead of the study's 7.5
//! strain units, so the numbers are not the study's, only the machinery is.

use std::collections::HashSet;
use std::path::Path;

use crate::common::{iuq, json_of, scratch};

const DATA: &str =
    "stress_pa,el_healthy,el_healthy_err\n0.64,0.151,0.005\n1.36,0.268,0.004\n2.91,0.389,0.004\n";

fn small_study(dir: &Path, extra: &str) -> std::path::PathBuf {
    std::fs::write(dir.join("data.csv"), DATA).unwrap();
    let text = format!(
        r#"name = "rbc-small"
[parameters]
kLink = {{ uniform = [10, 300] }}
kBend = {{ uniform = [50, 400] }}
viscosityRatio = {{ uniform = [1, 15] }}
[likelihood]
data = {{ file = "data.csv", x = "stress_pa", y = "el_healthy", y_err = "el_healthy_err", x_range = [1.0, 3.0] }}
modelling_error = {{ uniform = [0.001, 0.1] }}
[model]
kind = "rbc-shear"
start_strain = 0.05
[surrogate]
design = {{ kind = "lhs", n = 5, seed = 11 }}
test = {{ kind = "sobol", n = 3, seed = 12 }}
posterior_check = {{ samples = 2, seed = 1 }}
[sensitivity]
n = 256
model_n = 2
resamples = 20
[sampler]
samples = 300
burn = 2
seed = 1
[model_sampler]
samples = 8
seed = 2
[model_posterior]
method = "basis"
[executor]
kind = "local"
max_parallel = 2
{extra}"#
    );
    let path = dir.join("small.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn numbers(value: &serde_json::Value, into: &mut HashSet<u64>) {
    match value {
        serde_json::Value::Number(n) => {
            if let Some(f) = n.as_f64() {
                into.insert(f.to_bits());
            }
        }
        serde_json::Value::Array(a) => a.iter().for_each(|v| numbers(v, into)),
        serde_json::Value::Object(o) => o.values().for_each(|v| numbers(v, into)),
        _ => {}
    }
}

#[test]
fn the_pipeline_writes_every_artefact_and_the_html_shows_the_json_numbers() {
    let dir = scratch("pipeline", "small");
    let study = small_study(&dir, "");
    let out = dir.join("report");
    let output = iuq(&[
        "pipeline",
        study.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--model-posterior",
        "--json",
    ]);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let summary = json_of(&output);
    assert_eq!(summary["runs"], 16); // (5 training + 3 test) × 2 stresses

    for file in [
        "report.html",
        "report.json",
        "pipeline.json",
        "gp-bank.json",
        "model-runs.csv",
        "basis-gp/samples.csv",
        "basis-gp/summary.json",
        "basis-model/checkpoint.json",
        "basis-model/summary.json",
    ] {
        assert!(out.join(file).is_file(), "{file} is missing");
    }
    for figure in [
        "data_fit",
        "corner",
        "sensitivity",
        "violins",
        "map_error",
        "gp_diagnostics",
        "sampler_stages",
        "posterior_check",
    ] {
        let svg = std::fs::read_to_string(out.join(format!("figures/{figure}.svg"))).unwrap();
        assert!(svg.contains("<svg"), "{figure}.svg");
        let png = std::fs::read(out.join(format!("figures/{figure}.png"))).unwrap();
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "{figure}.png");
    }
    let tables: Vec<_> = std::fs::read_dir(out.join("tables"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(tables.iter().any(|t| t.ends_with(".csv")), "{tables:?}");
    assert!(tables.iter().any(|t| t.ends_with(".json")), "{tables:?}");

    // Every number of the HTML tables is a number of report.json, bit for bit.
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let mut known = HashSet::new();
    numbers(&report, &mut known);
    let mut shown = 0;
    for piece in html.split("data-value=\"").skip(1) {
        let text = &piece[..piece.find('"').unwrap()];
        let v: f64 = text.parse().unwrap_or_else(|_| panic!("data-value {text}"));
        assert!(
            known.contains(&v.to_bits()),
            "{v} is in the HTML but not in report.json"
        );
        shown += 1;
    }
    assert!(shown > 50, "only {shown} numbers in the HTML tables");
    assert!(
        !html.contains("src=\"http") && !html.contains("href=\"http"),
        "self-contained"
    );

    // The posterior table printed on stdout is the report's.
    let report = &report["report"];
    let posteriors = report["posteriors"].as_array().unwrap();
    assert_eq!(posteriors.len(), 2);
    for (printed, reported) in summary["posterior"]
        .as_array()
        .unwrap()
        .iter()
        .zip(posteriors)
    {
        assert_eq!(printed["source"], reported["source"]);
        for (row, s) in printed["parameters"]
            .as_array()
            .unwrap()
            .iter()
            .zip(reported["summary"].as_array().unwrap())
        {
            for key in ["map", "mean", "std"] {
                assert_eq!(row[key], s[key], "{key} of {}", s["name"]);
            }
        }
    }
    let parameters: Vec<&str> = report["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p.as_str().unwrap())
        .collect();
    assert_eq!(parameters, ["kLink", "kBend", "viscosityRatio", "sigma_m"]);
    // The cell model at the MAP and 2 posterior samples per stress, each run with its drift over
    // the measuring window, beside the surrogate.
    let check = &report["posterior_check"];
    assert_eq!(check["diagnostic"], "EL drift over the window");
    for p in check["points"].as_array().unwrap() {
        let ok = p["model"].as_array().unwrap().len() + usize::from(p["map_model"].is_array());
        assert_eq!(ok + p["failed"].as_u64().unwrap() as usize, 3, "{p}");
        assert_eq!(p["diagnostic"].as_array().unwrap().len(), ok, "{p}");
        assert!(p["rmse"].as_f64().is_some_and(|r| r >= 0.0), "{p}");
    }
    // Sobol' indices from both sources, for both stresses.
    let sources: HashSet<&str> = report["sensitivity"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["source"].as_str().unwrap())
        .collect();
    assert_eq!(sources, HashSet::from(["model runs", "surrogate"]));

    // A second pipeline reuses every stored run: no new process of the cell model.
    let again = iuq(&[
        "pipeline",
        study.to_str().unwrap(),
        "--out",
        dir.join("again").to_str().unwrap(),
        "--runs-only",
        "--json",
    ]);
    assert!(again.status.success());
    let campaign = dir.join("small.campaign/runs");
    let before = std::fs::read_dir(&campaign).unwrap().count();
    assert_eq!(json_of(&again)["failed"], 0);
    assert_eq!(std::fs::read_dir(&campaign).unwrap().count(), before);
}

#[test]
fn bad_pipeline_settings_are_input_errors() {
    let dir = scratch("pipeline", "bad");
    for (extra, key) in [
        (
            "[surrogate]\ndesign = { kind = \"sobol\", n = 5 }\n",
            "surrogate.design.kind",
        ),
        ("[surrogate]\ntest = { n = 1 }\n", "surrogate.test.n"),
        ("[surrogate]\nsize = 3\n", "surrogate.size"),
        ("[sensitivity]\nmodel_n = 1\n", "sensitivity.model_n"),
        (
            "[surrogate]\nposterior_check = { samples = 1 }\n",
            "surrogate.posterior_check.samples",
        ),
        (
            "[surrogate]\nposterior_check = { n = 3 }\n",
            "surrogate.posterior_check.n",
        ),
        (
            "[surrogate]\nposterior_check = { significance = 1.5 }\n",
            "surrogate.posterior_check.significance",
        ),
        (
            "[surrogate]\nposterior_check = { resolution = -0.1 }\n",
            "surrogate.posterior_check.resolution",
        ),
        (
            "[surrogate]\nposterior_check = { retrain = \"yes\" }\n",
            "surrogate.posterior_check.retrain",
        ),
        (
            "[surrogate]\nadaptive = { acquisition = \"random\" }\n",
            "surrogate.adaptive.acquisition",
        ),
        (
            "[model]\nkind = \"rbc-shear\"\nwindow_factor = 0.9\n",
            "model.window_factor",
        ),
        (
            "[model]\nkind = \"rbc-shear\"\nframes = 1\n",
            "model.frames",
        ),
        // Misspelt keys, wherever they are, are named with their whole key.
        ("[sensitivity]\nnn = 256\n", "sensitivity.nn"),
        ("[sampler]\nburn_in = 2\n", "sampler.burn_in"),
        (
            "[model]\nkind = \"rbc-shear\"\nprotocl = \"scaled\"\n",
            "model.protocl",
        ),
        (
            "[likelihood]\ndata = { file = \"data.csv\", x = \"stress_pa\", y = \"el_healthy\", x_rnage = [1, 3] }\n",
            "likelihood.data.x_rnage",
        ),
    ] {
        let sub = dir.join(key.replace('.', "-"));
        std::fs::create_dir_all(&sub).unwrap();
        let base = small_study(&sub, "");
        // Replace the section the case is about.
        let text = std::fs::read_to_string(&base).unwrap();
        let section = extra.lines().next().unwrap();
        let start = text.find(section).unwrap();
        let end = text[start + section.len()..]
            .find("\n[")
            .map_or(text.len(), |i| start + section.len() + i + 1);
        let text = format!("{}{}{}", &text[..start], extra, &text[end..]);
        std::fs::write(&base, text).unwrap();
        let output = iuq(&["pipeline", base.to_str().unwrap(), "--runs-only"]);
        assert_eq!(output.status.code(), Some(2), "{key}");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(
            stderr.contains(key) && stderr.contains("small.toml"),
            "{key}: {stderr}"
        );
    }
    // A study whose model is not the cell model.
    let path = dir.join("expr.toml");
    std::fs::write(
        &path,
        "name = \"e\"\n[parameters]\nx = { uniform = [0, 1] }\n[likelihood]\nlog_density = \"-x^2\"\n[model]\nkind = \"expression\"\noutputs = { f = \"x\" }\n",
    )
    .unwrap();
    let output = iuq(&["pipeline", path.to_str().unwrap()]);
    assert_eq!(output.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&output.stderr).contains("likelihood"));
}

/// The README's main job: the healthy-cell study on its shipped campaign store completes without
/// a single new run of the cell model — the adaptive rounds and the cell model at the posterior
/// replayed from the store — and its result says what the study is known for: kLink is
/// identified, kBend is not, and the surrogate agrees with the cell model where the posterior
/// lies.
/// Run the pipeline of the shipped study `name` (`examples/<name>.toml`) on a copy of its shipped
/// store, checking that it makes no model run; returns its `--json` summary and the copy's
/// directory (the report in `report/`).
/// The replay leaves the store byte for byte as shipped (the README's main command leaves the
/// checkout clean: a store whose every needed record is there is only read).
fn replay_shipped_study(name: &str, extra: &[&str]) -> (serde_json::Value, std::path::PathBuf) {
    let store = format!("examples/{name}.campaign/campaign.sqlite");
    let (summary, dir) = replay_study_with(
        &format!("shipped-{name}"),
        name,
        &store,
        &|text| text.to_string(),
        extra,
    );
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let low_fidelity = format!("examples/{name}.campaign/low-fidelity/campaign.sqlite");
    let stores =
        std::iter::once(store).chain(root.join(&low_fidelity).is_file().then_some(low_fidelity));
    for store in stores {
        let shipped = std::fs::read(root.join(&store)).unwrap();
        let replayed = std::fs::read(dir.join(&store)).unwrap();
        assert!(
            shipped == replayed,
            "the replay rewrote {store} (the shipped file must be in WAL mode and nothing written)"
        );
        for leftover in ["-wal", "-shm", "-journal"] {
            let file = dir.join(format!("{store}{leftover}"));
            assert!(
                std::fs::metadata(&file).map_or(true, |m| m.len() == 0),
                "{} holds data",
                file.display()
            );
        }
    }
    (summary, dir)
}

/// Replays the study `examples/<name>.toml`, its text passed through `edit`, from the store
/// `store` (a path in the repository) in the scratch directory `label`, and checks that no model
/// run was made: the pipeline's `--json` summary and the directory.
fn replay_study(
    label: &str,
    name: &str,
    store: &str,
    edit: &dyn Fn(&str) -> String,
) -> (serde_json::Value, std::path::PathBuf) {
    replay_study_with(label, name, store, edit, &[])
}

/// [`replay_study`] with the pipeline's further arguments `extra`.
fn replay_study_with(
    label: &str,
    name: &str,
    store: &str,
    edit: &dyn Fn(&str) -> String,
    extra: &[&str],
) -> (serde_json::Value, std::path::PathBuf) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let dir = scratch("pipeline", label);
    let study = format!("examples/{name}.toml");
    // A two-fidelity study's cheap model has a store of its own beside the study's.
    let low_fidelity = format!("examples/{name}.campaign/low-fidelity/campaign.sqlite");
    let low_fidelity = root
        .join(&low_fidelity)
        .is_file()
        .then(|| (low_fidelity.clone(), low_fidelity));
    for (source, target) in [
        (
            store.to_string(),
            format!("examples/{name}.campaign/campaign.sqlite"),
        ),
        (
            "data/ektacytometry_gutierrez2018.csv".into(),
            "data/ektacytometry_gutierrez2018.csv".into(),
        ),
    ]
    .into_iter()
    .chain(low_fidelity)
    {
        let target = dir.join(target);
        std::fs::create_dir_all(target.parent().unwrap()).unwrap();
        std::fs::copy(root.join(source), &target).unwrap();
    }
    // The files beside the study (a command model's script and templates, read when the study
    // is loaded).
    let folder = Path::new(&study).parent().unwrap();
    for entry in std::fs::read_dir(root.join(folder)).unwrap() {
        let entry = entry.unwrap();
        if entry.file_type().unwrap().is_file() {
            std::fs::copy(entry.path(), dir.join(folder).join(entry.file_name())).unwrap();
        }
    }
    let text = std::fs::read_to_string(root.join(&study)).unwrap();
    std::fs::write(dir.join(&study), edit(&text)).unwrap();
    let out = dir.join("report");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_iuq"))
        .args([
            "pipeline",
            dir.join(&study).to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--json",
        ])
        .args(extra)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // A run of the cell model takes half a minute: a pipeline that has to make runs is stopped
    // rather than left to recompute the study.
    let started = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if started.elapsed() > std::time::Duration::from_secs(600) {
            // SIGTERM, which the pipeline forwards to the model runs it started (SIGKILL would
            // leave them running).
            let _ = std::process::Command::new("kill")
                .args(["-TERM", &child.id().to_string()])
                .status();
            let _ = child.wait();
            panic!("the pipeline did not finish from the shipped runs within 10 minutes");
        }
        std::thread::sleep(std::time::Duration::from_millis(200));
    }
    let output = child.wait_with_output().unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let runs = dir.join(format!("examples/{name}.campaign/runs"));
    let made = std::fs::read_dir(&runs).map_or(0, |d| d.count());
    assert_eq!(
        made, 0,
        "the shipped store should hold every run of the study"
    );
    // Nor a run in the pipeline's own process (the cell's portraits at the MAP come from the
    // store).
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!stderr.contains("in pictures"), "{stderr}");
    (json_of(&output), dir)
}

/// The shipped healthy study's surrogate calibration as replayed (`summary`, in `dir`).
fn assert_healthy_study_completes(summary: &serde_json::Value, dir: &Path) {
    let out = dir.join("report");
    // The shipped rounds replayed from the store: converged at round 25 with 669 runs.
    assert_eq!(summary["runs"], 669, "{}", summary["adaptive"]);
    assert_eq!(summary["rounds"], 25);
    assert_eq!(summary["converged"], true);
    assert_eq!(summary["failed"], 0);
    let gp = &summary["posterior"][0];
    assert_eq!(gp["source"], "GP surrogate");
    let std_of = |name: &str| {
        gp["parameters"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["parameter"] == name)
            .unwrap_or_else(|| panic!("{name} in {gp}"))["std"]
            .as_f64()
            .unwrap()
    };
    // Prior standard deviations: kLink 290/√12 = 83.7, kBend 350/√12 = 101.
    assert!(std_of("kLink") < 0.1 * 83.7, "kLink is identified");
    assert!(std_of("kBend") > 0.3 * 101.0, "kBend is not");
    // The cell model at the MAP and 20 posterior samples per stress, beside the surrogate. Its
    // predictive std as the likelihood uses it (latent function and the GP's noise), with the
    // run's frame std, covers the runs: a calibrated Gaussian covers each of the 21 runs with
    // probability 0.95, and 16 or fewer covered has probability 0.003. Up to 6.19 Pa the
    // surrogate's error there is also about the measurement std or less (0.0006-0.005, 1.99 Pa
    // the largest). At 9.04 Pa soft cells with nearly equal parameters end the window 0.03 apart
    // (docs/cell-model-high-stress.md): the GP holds that scatter as its noise (std 0.034), so
    // its error against single runs is of that size (0.029) and still covered.
    // The check passes its test (so nothing is retrained on).
    assert!(
        summary["adaptive"]["retrained_checks"]
            .as_array()
            .unwrap()
            .is_empty()
    );
    let check = summary["posterior_check"].as_array().unwrap();
    assert_eq!(check.len(), 8, "one check per stress");
    for point in check {
        assert_eq!(point["failed"], 0, "{point}");
        assert_eq!(point["passed"], true, "{point}");
        assert!(
            point["within_two_std"].as_f64().unwrap() >= 17.0 / 21.0,
            "{point}"
        );
        let largest_error = if point["x"].as_f64().unwrap() <= 6.19 {
            0.006
        } else {
            0.05
        };
        assert!(point["rmse"].as_f64().unwrap() < largest_error, "{point}");
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let sources: HashSet<&str> = report["report"]["sensitivity"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["source"].as_str().unwrap())
        .collect();
    assert_eq!(sources, HashSet::from(["surrogate"]));
    assert!(out.join("report.html").is_file());

    // The campaign commands read a pipeline study's store too.
    let status = json_of(&iuq(&[
        "status",
        dir.join("examples/rbc-healthy-hemocell.toml")
            .to_str()
            .unwrap(),
        "--json",
    ]));
    assert_eq!(status["study"], "rbc-healthy-hemocell");
    // The store also holds the model posterior's runs (`[model_posterior]`, complete: 5,607
    // runs succeeded in all), and the runs of batches abandoned on the way, never made and set
    // aside with `iuq cancel` (PROVENANCE.md): nothing is pending or failed.
    let counts = &status["counts"];
    let count = |k: &str| counts[k].as_u64().unwrap();
    assert_eq!(count("succeeded"), 5607, "{status}");
    assert_eq!(count("cancelled"), 6258, "{status}");
    assert_eq!(
        count("succeeded") + count("cancelled"),
        status["total"].as_u64().unwrap(),
        "{status}"
    );
}

/// The shipped TBHP study's surrogate calibration as replayed (`summary`).
fn assert_tbhp_study_completes(summary: &serde_json::Value) {
    // The engine's rule held at round 8 with 140 runs; the cell model at that posterior failed
    // the check's test at 6.19 Pa (4 samples in the posterior's high-Λ part, where the GP had no
    // runs, 0.03-0.05 below a surrogate sure to 0.002-0.014: |z| 4.81 against a bound of 4.11);
    // its 126 runs became training runs, the rule held again at round 11 with 290 runs, and the
    // check at the new posterior passes (PROVENANCE.md).
    assert_eq!(summary["runs"], 290, "{}", summary["adaptive"]);
    assert_eq!(summary["rounds"], 11);
    assert_eq!(summary["converged"], true);
    assert_eq!(summary["failed"], 0);
    let retrained = summary["adaptive"]["retrained_checks"].as_array().unwrap();
    assert_eq!(retrained.len(), 1, "{retrained:?}");
    assert_eq!(retrained[0]["after_round"], 8);
    assert_eq!(retrained[0]["runs"], 126);
    assert_eq!(retrained[0]["failed_at"], serde_json::json!([6.19]));
    // The final check: the MAP and 20 samples at each of the 6 stresses, every stress passing
    // the test; the surrogate's error within about the measurement std of these data
    // (0.002-0.005) below 9.04 Pa, where the runs themselves scatter by 0.03.
    let check = summary["posterior_check"].as_array().unwrap();
    assert_eq!(check.len(), 6, "one check per stress");
    for point in check {
        assert_eq!(point["failed"], 0, "{point}");
        assert_eq!(point["passed"], true, "{point}");
        assert!(
            point["within_two_std"].as_f64().unwrap() >= 20.0 / 21.0,
            "{point}"
        );
        let limit = if point["x"].as_f64().unwrap() > 9.0 {
            0.02
        } else {
            0.007
        };
        assert!(point["rmse"].as_f64().unwrap() < limit, "{point}");
    }
}

#[test]
fn the_cell_models_own_posterior_shows_the_cell_at_its_map() {
    let dir = scratch("pipeline", "portraits");
    let study = small_study(&dir, "");
    let text = std::fs::read_to_string(&study).unwrap().replace(
        "method = \"basis\"",
        "samples = 25\nseed = 3\nmax_samples = 25",
    );
    std::fs::write(&study, text).unwrap();
    let out = dir.join("report");
    let run = || {
        let output = iuq(&[
            "pipeline",
            study.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--model-posterior",
            "--json",
        ]);
        assert!(
            output.status.success(),
            "{}",
            String::from_utf8_lossy(&output.stderr)
        );
        (
            json_of(&output),
            String::from_utf8_lossy(&output.stderr).into_owned(),
        )
    };
    let (summary, stderr) = run();
    let m = &summary["model_posterior"];
    assert_eq!(m["samples"], 25, "{m}");
    for whose in ["model", "surrogate"] {
        assert!(
            stderr.contains(&format!(
                "the cell at the {whose} posterior's MAP in pictures: 2 runs"
            )),
            "{stderr}"
        );
    }
    for figure in [
        "cell_shapes",
        "elongation_trace",
        "model_posterior_map_runs",
    ] {
        assert!(
            out.join(format!("figures/{figure}.png")).is_file(),
            "{figure}"
        );
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let portraits = report["report"]["cell_portraits"]["portraits"]
        .as_array()
        .unwrap();
    assert_eq!(portraits.len(), 2);
    let map_runs = report["report"]["model_posterior"]["map_runs"]
        .as_array()
        .unwrap();
    for (p, run) in portraits.iter().zip(map_runs) {
        assert_eq!(p["x"], run["x"]);
        // The portrait is the cell model run again at the model posterior's MAP, in this process:
        // the same elongation index as the campaign's run there, bit for bit.
        assert_eq!(p["elongation_index"][0], run["at_model_map"], "{p}");
        let trace = p["trace"].as_array().unwrap();
        assert!(trace.len() > 10, "{}", trace.len());
        assert!(p["outline"].as_array().unwrap().len() > 10);
        assert!(p["side"].as_array().unwrap().len() > 10);
    }
    // Beside them, the elongation through the runs at the surrogate posterior's MAP, the same
    // as the campaign's run there.
    let compared = &report["report"]["cell_portraits"]["compared"];
    assert_eq!(
        compared["source"], "the GP surrogate posterior's MAP",
        "{compared}"
    );
    let traces = compared["traces"].as_array().unwrap();
    assert_eq!(traces.len(), 2);
    for (t, run) in traces.iter().zip(map_runs) {
        assert_eq!(t["x"], run["x"]);
        assert_eq!(t["elongation_index"][0], run["at_surrogate_map"], "{t}");
        assert!(t["trace"].as_array().unwrap().len() > 10);
    }
    // A replay reads the portraits back from the campaign store: no cell-model run.
    let (again, stderr) = run();
    assert!(!stderr.contains("in pictures"), "{stderr}");
    assert_eq!(again["model_posterior"]["mean"], m["mean"]);
    let replayed: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(
        replayed["report"]["cell_portraits"],
        report["report"]["cell_portraits"]
    );
}

/// The healthy study made from an empty campaign with the engine of 2026-11-27 (its posterior
/// check left out), replayed from its store `data/rbc_healthy_fresh_engine.sqlite`: converged at
/// round 8 with 324 runs, the posterior of `data/rbc_healthy_fresh_engine.md`.
/// Every (parameter, mean, std, decimals) row of a data file's posterior table matches the
/// summary's posterior `gp`, rounded as the table is.
fn assert_posterior_table(gp: &serde_json::Value, rows: &[(&str, f64, f64, i32)]) {
    for &(name, mean, std, digits) in rows {
        let p = gp["parameters"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["parameter"] == name)
            .unwrap_or_else(|| panic!("{name} in {gp}"));
        let round = |x: f64| (x * 10f64.powi(digits)).round() / 10f64.powi(digits);
        assert_eq!(round(p["mean"].as_f64().unwrap()), mean, "{name}: {p}");
        assert_eq!(round(p["std"].as_f64().unwrap()), std, "{name}: {p}");
    }
}

/// The TBHP study made from an empty campaign with `acquisition = "moments"`
/// (data/rbc_tbhp_moments_engine.md): converged at round 8 with 140 runs, and the cell model at
/// that posterior (the MAP and 20 samples per stress, 126 runs) passed the check, where the
/// shipped history's density acquisition also met the rule at 140 runs but failed the check.
#[test]
fn the_tbhp_study_with_moments_acquisition_replays_to_its_140_runs_and_passes_its_check() {
    let (summary, _) = replay_study(
        "tbhp-moments",
        "rbc-tbhp-hemocell",
        "data/rbc_tbhp_moments_engine.sqlite",
        &|text| {
            text.replace(
                "max_rounds = 30 }",
                "max_rounds = 30, acquisition = \"moments\" }",
            )
        },
    );
    assert_eq!(summary["runs"], 140, "{}", summary["adaptive"]);
    assert_eq!(summary["rounds"], 8);
    assert_eq!(summary["converged"], true);
    assert_eq!(summary["failed"], 0);
    assert!(
        summary["adaptive"]["retrained_checks"]
            .as_array()
            .unwrap()
            .is_empty(),
        "the check passed: nothing retrained"
    );
    let check = summary["posterior_check"].as_array().unwrap();
    assert_eq!(check.len(), 6, "one check per stress");
    for point in check {
        assert_eq!(point["passed"], true, "{point}");
    }
    let gp = &summary["posterior"][0];
    assert_eq!(gp["source"], "GP surrogate");
    // The table of data/rbc_tbhp_moments_engine.md (mean / std, as rounded there).
    assert_posterior_table(
        gp,
        &[
            ("kLink", 120.5, 15.1, 1),
            ("kBend", 320.3, 62.4, 1),
            ("viscosityRatio", 2.75, 1.80, 2),
            ("sigma_m", 0.0470, 0.0203, 4),
        ],
    );
}

#[test]
fn the_healthy_study_made_from_scratch_replays_to_its_324_runs() {
    let (summary, _) = replay_study(
        "healthy-from-scratch",
        "rbc-healthy-hemocell",
        "data/rbc_healthy_fresh_engine.sqlite",
        &|text| {
            text.lines()
                .filter(|l| !l.starts_with("posterior_check"))
                .collect::<Vec<_>>()
                .join("\n")
        },
    );
    assert_eq!(summary["runs"], 324, "{}", summary["adaptive"]);
    assert_eq!(summary["rounds"], 8);
    assert_eq!(summary["converged"], true);
    assert_eq!(summary["failed"], 0);
    let gp = &summary["posterior"][0];
    assert_eq!(gp["source"], "GP surrogate");
    // The table of data/rbc_healthy_fresh_engine.md (mean / std, as rounded there).
    assert_posterior_table(
        gp,
        &[
            ("kLink", 38.77, 4.09, 2),
            ("kBend", 236.3, 76.5, 1),
            ("viscosityRatio", 5.72, 1.59, 2),
            ("sigma_m", 0.0323, 0.0193, 4),
        ],
    );
}

/// Table 2 of the case study (`docs/case-study.md`, which the README links) for `study`
/// (`"healthy cells"` or `"TBHP cells"`): for each row, the parameter's name in the study and the
/// six numbers as printed (GP MAP, mean, std, then the cell model's).
fn readme_table2(study: &str) -> Vec<(String, Vec<String>)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let readme = std::fs::read_to_string(root.join("docs/case-study.md")).unwrap();
    let header = format!("| {study} |");
    let mut lines = readme
        .lines()
        .skip_while(|l| !l.starts_with(&header))
        .skip(2);
    let mut rows = Vec::new();
    while let Some(line) = lines.next().filter(|l| l.starts_with('|')) {
        let cells: Vec<String> = line
            .trim_matches('|')
            .split('|')
            .map(|c| c.trim().to_string())
            .collect();
        let name = match cells[0].as_str() {
            "Λ" => "viscosityRatio",
            "σ_m" => "sigma_m",
            other => other,
        };
        rows.push((name.to_string(), cells[1..].to_vec()));
    }
    assert_eq!(rows.len(), 4, "the case study's table for {study}");
    rows
}

/// `value` as the README prints `printed`: rounded to as many decimals as it shows.
fn as_printed(value: f64, printed: &str) -> String {
    let decimals = printed.split_once('.').map_or(0, |(_, d)| d.len());
    format!("{value:.decimals$}")
}

/// The cell model's own posterior of the shipped study `name` replays from its store: certified,
/// no model run, and the numbers of the README's Table 2 (both columns) are this replay's.
fn assert_shipped_model_posterior(
    name: &str,
    table: &str,
) -> (serde_json::Value, std::path::PathBuf) {
    let (summary, dir) = replay_shipped_study(name, &["--model-posterior"]);
    let m = &summary["model_posterior"];
    assert_eq!(m["certified"], true, "{m}");
    assert!(m["samples"].as_u64().unwrap() >= 200, "{m}");
    assert!(
        m["pareto_k"].as_f64().unwrap() <= m["pareto_k_threshold"].as_f64().unwrap(),
        "{m}"
    );
    let gp = summary["posterior"][0]["parameters"].as_array().unwrap();
    for (parameter, printed) in readme_table2(table) {
        let g = gp.iter().find(|p| p["parameter"] == parameter).unwrap();
        let ours = [
            g["map"].as_f64().unwrap(),
            g["mean"].as_f64().unwrap(),
            g["std"].as_f64().unwrap(),
            m["map"][&parameter].as_f64().unwrap(),
            m["mean"][&parameter].as_f64().unwrap(),
            m["std"][&parameter].as_f64().unwrap(),
        ];
        for (value, shown) in ours.iter().zip(&printed) {
            assert_eq!(&as_printed(*value, shown), shown, "{table}, {parameter}");
        }
    }
    // Both MAP runs at every stress, the cell's shapes at the model's MAP and its elongation
    // through the runs at both MAPs, read back from the store (the portraits' runs were made by
    // the pipeline that completed the campaign).
    let out = dir.join("report");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let stresses = summary["posterior_check"].as_array().unwrap().len();
    let map_runs = report["report"]["model_posterior"]["map_runs"]
        .as_array()
        .unwrap();
    assert_eq!(map_runs.len(), stresses);
    let portraits = report["report"]["cell_portraits"]["portraits"]
        .as_array()
        .unwrap();
    assert_eq!(portraits.len(), stresses);
    let traces = report["report"]["cell_portraits"]["compared"]["traces"]
        .as_array()
        .unwrap();
    assert_eq!(traces.len(), stresses);
    for (t, run) in traces.iter().zip(map_runs) {
        assert_eq!(t["x"], run["x"]);
        assert!(t["trace"].as_array().unwrap().len() > 10);
    }
    for figure in [
        "cell_shapes",
        "elongation_trace",
        "model_posterior_map_runs",
        "model_posterior_weights",
    ] {
        assert!(
            out.join(format!("figures/{figure}.png")).is_file(),
            "{figure}"
        );
    }
    (summary, dir)
}

/// The `--json` summary's posterior entry of parameter `name` (its mean, std, quantiles).
fn posterior_parameter(summary: &serde_json::Value, name: &str) -> serde_json::Value {
    summary["posterior"][0]["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["parameter"] == name)
        .unwrap()
        .clone()
}

/// The HemoCell 2.7-only calibration (the reference of the two-fidelity study) replays from its
/// shipped store, from wherever the checkout lies, without a HemoCell run: 20 points (one failed:
/// HemoCell lost the softest cell at 9.04 Pa), converged after 7 rounds. As with HemoCell 2.1,
/// kLink is identified and kBend is not (its posterior std near the prior's, 350/√12 = 101).
#[test]
fn the_hemocell27_reference_calibration_replays_from_its_store() {
    let (summary, _) = replay_shipped_study("hemocell/hemocell27-healthy", &[]);
    assert_eq!(summary["runs"], 20, "{summary}");
    assert_eq!(summary["failed"], 1, "{summary}");
    assert_eq!(summary["rounds"], 7, "{summary}");
    assert_eq!(summary["converged"], true, "{summary}");
    let parameter = |name: &str| posterior_parameter(&summary, name);
    let k_link = parameter("kLink");
    assert_eq!(format!("{:.1}", k_link["mean"].as_f64().unwrap()), "90.7");
    assert_eq!(format!("{:.1}", k_link["std"].as_f64().unwrap()), "13.3");
    assert!(parameter("kBend")["std"].as_f64().unwrap() > 0.9 * 101.0);
}

/// The HemoCell 2.7 calibration with the native cell model as a cheap second fidelity replays
/// from its two shipped stores without a run of either model: 15 HemoCell points (one failed)
/// where HemoCell alone needed 20, 150 native runs, converged after 10 rounds, with kLink's
/// posterior within a tenth of a std of HemoCell alone's (90.7 ± 13.3).
#[test]
fn the_hemocell27_two_fidelity_calibration_replays_from_its_stores() {
    let (summary, _) = replay_shipped_study("hemocell/hemocell27-healthy-two-fidelity", &[]);
    assert_eq!(summary["runs"], 15, "{summary}");
    assert_eq!(summary["failed"], 1, "{summary}");
    assert_eq!(summary["rounds"], 10, "{summary}");
    assert_eq!(summary["converged"], true, "{summary}");
    let parameter = |name: &str| posterior_parameter(&summary, name);
    let k_link = parameter("kLink");
    assert_eq!(format!("{:.1}", k_link["mean"].as_f64().unwrap()), "90.4");
    assert_eq!(format!("{:.1}", k_link["std"].as_f64().unwrap()), "13.2");
    assert!((k_link["mean"].as_f64().unwrap() - 90.7).abs() < 0.1 * 13.3);
}

/// The shipped healthy study replayed from its store with `--model-posterior` (one replay
/// covers both: the surrogate's calibration is the model posterior's first stage): no run
/// made, the store unchanged, the surrogate's calibration as published and the cell model's
/// own posterior certified as published.
#[test]
fn the_shipped_healthy_study_replays_its_calibration_and_the_cell_models_certified_posterior() {
    let (summary, dir) = assert_shipped_model_posterior("rbc-healthy-hemocell", "healthy cells");
    assert_healthy_study_completes(&summary, &dir);
    let m = &summary["model_posterior"];
    // The figures of docs/case-study.md and PROVENANCE.md: a noisy likelihood at 9.04 Pa weighed in one
    // pseudo-marginal step over both batches (400 members: the surrogate posterior's and the
    // defensive normal's), 4,428 runs (400 evaluations at 8 stresses, the probe's 32 and 1,196
    // replicates); k̂ 0.401, ESS 142.
    assert_eq!(m["pseudo_marginal"], true, "{m}");
    assert_eq!(m["both_batches"], true, "{m}");
    assert_eq!(m["corrections"][0]["defensive_normal"], true, "{m}");
    assert_eq!(m["samples"], 400, "{m}");
    assert_eq!(m["model_evaluations"], 400, "{m}");
    assert_eq!(m["replicate_runs"], 1196, "{m}");
    assert_eq!(m["model_runs"], 4428, "{m}");
    assert_eq!(m["stages"].as_array().unwrap().len(), 1, "{m}");
    assert_eq!(format!("{:.3}", m["pareto_k"].as_f64().unwrap()), "0.401");
    assert_eq!(
        format!("{:.0}", m["effective_sample_size"].as_f64().unwrap()),
        "142"
    );
}

/// The shipped TBHP study replayed from its store with `--model-posterior`, as the healthy one.
#[test]
fn the_shipped_tbhp_study_replays_its_calibration_and_the_cell_models_certified_posterior() {
    let (summary, _) = assert_shipped_model_posterior("rbc-tbhp-hemocell", "TBHP cells");
    assert_tbhp_study_completes(&summary);
    let m = &summary["model_posterior"];
    // The figures of docs/case-study.md and PROVENANCE.md: 1,198 model evaluations and the probe's 4, at
    // 6 stresses; 5 stages; k̂ 0.556, ESS 186 and 66 ancestors.
    assert_eq!(m["model_runs"], 7212, "{m}");
    assert_eq!(m["model_evaluations"], 1198, "{m}");
    assert_eq!(m["stages"].as_array().unwrap().len(), 5, "{m}");
    assert_eq!(m["ancestors"], 66, "{m}");
    assert_eq!(format!("{:.3}", m["pareto_k"].as_f64().unwrap()), "0.556");
    assert_eq!(
        format!("{:.0}", m["effective_sample_size"].as_f64().unwrap()),
        "186"
    );
}
