//! End-to-end tests of UM-Bridge in the CLI: `iuq serve umbridge` as a real process on
//! 127.0.0.1 (a free port), studies of `[model] kind = "umbridge"` run by `iuq sobol` and
//! `iuq basis` against it, the reference Python client against it (skipped with a message when
//! the Python package `umbridge` is missing), and the errors a user can make.

use crate::common;

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use crate::common::{Served, iuq, json_of};

use iuq_core::Model;
use iuq_umbridge::{ClientOptions, UmBridgeModel};
use serde_json::{Value, json};

fn scratch(name: &str) -> PathBuf {
    common::scratch("cli-umbridge", name)
}

fn write(path: &Path, text: &str) {
    std::fs::write(path, text).unwrap();
}

fn s(path: &Path) -> &str {
    path.to_str().unwrap()
}

fn names(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

fn linear_data(dir: &Path) {
    std::fs::create_dir_all(dir.join("data")).unwrap();
    let mut text = String::from("stress,el,el_err\n");
    for j in 0..6 {
        let x = j as f64;
        let y = 1.0 + 0.5 * x + 0.05 * (37.0 * x).sin();
        text.push_str(&format!("{x},{y},{}\n", 0.05 + 0.01 * x));
    }
    write(&dir.join("data/line.csv"), &text);
}

const PARAMETERS: &str = r#"
[parameters]
a = { uniform = [0, 3] }
b = { uniform = [-1, 2] }
"#;

const LIKELIHOOD: &str = r#"
[likelihood]
data = { file = "data/line.csv", x = "stress", y = "el", y_err = "el_err", x_range = [2, 4] }
# A modelling error sampled with the parameters: the served posterior model takes it as an input.
modelling_error = { uniform = [0.001, 0.1] }
[sampler]
samples = 300
seed = 3
"#;

#[test]
fn a_served_study_is_used_by_sobol_and_basis_exactly_like_the_model_in_process() {
    let dir = scratch("sobol-basis");
    linear_data(&dir);
    let local = dir.join("line.toml");
    write(
        &local,
        &format!(
            "name = \"line\"{PARAMETERS}[model]\nkind = \"expression\"\noutputs = {{ y2 = \"a + 2*b\", y3 = \"a + 3*b\", y4 = \"a + 4*b + 0*sqrt(a - 0.2)\" }}\n[sensitivity]\nn = 128\nseed = 2\n{LIKELIHOOD}"
        ),
    );
    let served = Served::start(&local, &["--parallel", "2"]);
    let a = &served.announcement;
    assert_eq!(a["protocol_version"], json!(1.0));
    assert_eq!(a["parallel"], json!(2));
    assert_eq!(a["models"][0]["name"], json!("line"));
    assert_eq!(a["models"][0]["inputs"], json!(["a", "b"]));
    assert_eq!(a["models"][0]["outputs"], json!(["y2", "y3", "y4"]));
    assert_eq!(a["models"][1]["name"], json!("line-posterior"));
    assert_eq!(a["models"][1]["inputs"], json!(["a", "b", "sigma_m"]));
    assert_eq!(a["models"][1]["outputs"], json!(["log_posterior"]));

    // The same study with the served model instead of the expression.
    let remote = dir.join("remote.toml");
    write(
        &remote,
        &format!(
            "name = \"line\"{PARAMETERS}[model]\nkind = \"umbridge\"\nurl = \"{}\"\nname = \"line\"\noutputs = [\"y2\", \"y3\", \"y4\"]\nconcurrency = 3\n[sensitivity]\nn = 128\nseed = 2\n{LIKELIHOOD}",
            served.url()
        ),
    );
    let sobol_local = json_of(&iuq(&["sobol", s(&local), "--json"]));
    let sobol_remote = json_of(&iuq(&["sobol", s(&remote), "--json"]));
    for key in [
        "outputs",
        "evaluations",
        "failed_evaluations",
        "dropped_groups",
    ] {
        assert!(sobol_local.get(key).is_some(), "{sobol_local}");
        assert_eq!(sobol_local[key], sobol_remote[key], "sobol `{key}`");
    }
    assert!(sobol_local["failed_evaluations"].as_u64().unwrap() > 0);

    let out_local = dir.join("basis-local");
    let out_remote = dir.join("basis-remote");
    let basis_local = json_of(&iuq(&[
        "basis",
        s(&local),
        "--out",
        s(&out_local),
        "--json",
    ]));
    let basis_remote = json_of(&iuq(&[
        "basis",
        s(&remote),
        "--out",
        s(&out_remote),
        "--json",
    ]));
    for key in [
        "log_evidence",
        "mean",
        "std",
        "map",
        "evaluations",
        "failures",
        "stages",
    ] {
        assert_eq!(basis_local[key], basis_remote[key], "basis `{key}`");
    }
    assert!(basis_local["failures"].as_u64().unwrap() > 0);
    assert_eq!(
        std::fs::read_to_string(out_local.join("samples.csv")).unwrap(),
        std::fs::read_to_string(out_remote.join("samples.csv")).unwrap()
    );

    // The posterior model: the log-posterior of a BASIS sample is ll + lp of samples.csv.
    let posterior = UmBridgeModel::connect(
        &served.url(),
        "line-posterior",
        names(&["a", "b", "sigma_m"]),
        ClientOptions::default(),
    )
    .unwrap();
    let samples = std::fs::read_to_string(out_local.join("samples.csv")).unwrap();
    let mut lines = samples.lines();
    assert_eq!(lines.next(), Some("a,b,sigma_m,ll,lp"));
    let rows: Vec<Vec<f64>> = lines
        .take(20)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    let points: Vec<Vec<f64>> = rows.iter().map(|r| r[..3].to_vec()).collect();
    let values = posterior.evaluate_batch(&points).unwrap();
    for (row, v) in rows.iter().zip(&values) {
        let expected = row[3] + row[4];
        let got = v.as_ref().unwrap().outputs[0];
        assert!(
            (got - expected).abs() <= 1e-9 * expected.abs().max(1.0),
            "{got} vs {expected}"
        );
    }
    // Outside the prior, the most negative double; a failed run (sqrt of a − 0.2 < 0), a 500.
    let out = posterior
        .evaluate_batch(&[vec![5.0, 0.0, 0.01], vec![0.1, 0.5, 0.01]])
        .unwrap();
    assert_eq!(out[0].as_ref().unwrap().outputs, vec![f64::MIN]);
    assert!(out[1].as_ref().unwrap_err().reason.contains("ModelError"));

    // A malformed request gets its error object and the CLI server keeps serving.
    let address = served.url().trim_start_matches("http://").to_string();
    let mut raw = TcpStream::connect(&address).unwrap();
    raw.write_all(b"POST /Evaluate HTTP/1.1\r\nContent-Length: 5\r\n\r\n{oops")
        .unwrap();
    raw.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let mut answer = vec![0u8; 512];
    let n = raw.read(&mut answer).unwrap();
    let answer = String::from_utf8_lossy(&answer[..n]);
    assert!(answer.starts_with("HTTP/1.1 400"), "{answer}");
    assert!(answer.contains("\"InvalidInput\""), "{answer}");
    assert!(posterior.evaluate(&[1.0, 0.5, 0.01]).unwrap().is_ok());
}

fn python_with_umbridge() -> Option<String> {
    let python = std::env::var("IUQ_PYTHON").unwrap_or_else(|_| "python3".into());
    let ok = Command::new(&python)
        .args(["-c", "import umbridge"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .map(|s| s.success())
        .unwrap_or(false);
    if !ok {
        eprintln!(
            "SKIPPED: `{python}` cannot import the Python package `umbridge` (install it with `{python} -m pip install umbridge`, or point IUQ_PYTHON at an interpreter that has it)"
        );
        return None;
    }
    Some(python)
}

#[test]
fn the_python_client_evaluates_a_served_study_and_sees_its_errors() {
    let Some(python) = python_with_umbridge() else {
        return;
    };
    let dir = scratch("python");
    let study = dir.join("gauss.toml");
    write(
        &study,
        r#"name = "gauss"
[parameters]
x = { uniform = [-4, 4] }
y = { uniform = [-2, 6] }
[model]
kind = "expression"
outputs = { f = "x^2 + y", g = "sqrt(x) * y" }
[likelihood]
log_density = "-0.5*(x^2 + y^2)"
"#,
    );
    let served = Served::start(&study, &[]);
    let check = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../iuq-umbridge/tests/python/umbridge_client_check.py");
    let run = |model: &str, bad: Option<&str>| -> Value {
        let mut command = Command::new(&python);
        command.arg(&check).args([served.url().as_str(), model]);
        if let Some(bad) = bad {
            command.arg(bad);
        }
        let o = command.output().expect("run python");
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice(&o.stdout).unwrap()
    };
    let r = run("gauss", Some("-1,2"));
    assert_eq!(r["models"], json!(["gauss", "gauss-posterior"]));
    assert_eq!(r["input_sizes"], json!([2]));
    assert_eq!(r["output_sizes"], json!([2]));
    assert_eq!(r["support"]["gradient"], json!(false));
    // f = 1.5² − 0.5, g = √1.5 · (−0.5) at (1.5, −0.5).
    assert_eq!(r["evaluate"], json!([[1.75, 1.5f64.sqrt() * -0.5]]));
    assert!(
        r["evaluate_with_std_error"]
            .as_str()
            .unwrap()
            .contains("InvalidOutput")
    );
    let errors = &r["errors"];
    assert!(
        errors["wrong_size"]
            .as_str()
            .unwrap()
            .contains("InvalidInput"),
        "{errors}"
    );
    assert!(
        errors["unknown_model"]
            .as_str()
            .unwrap()
            .contains("not supported"),
        "{errors}"
    );
    let failing = errors["failing_point"].as_str().unwrap();
    assert!(
        failing.contains("ModelError") && failing.contains("not finite"),
        "{failing}"
    );

    let r = run("gauss-posterior", None);
    assert_eq!(r["output_sizes"], json!([1]));
    let expected = -(8.0f64.ln() + 8.0f64.ln()) - 0.5 * (1.5 * 1.5 + 0.25);
    let got = r["evaluate"][0][0].as_f64().unwrap();
    assert!((got - expected).abs() < 1e-12, "{got} vs {expected}");
}

#[test]
fn a_gp_surrogate_is_served_with_its_std_and_the_exact_gradient_of_its_mean() {
    let dir = scratch("surrogate");
    let mut data = String::from("a,b,y\n");
    for i in 0..40 {
        let a = (i as f64 * 0.618034).fract() * 3.0;
        let b = (i as f64 * 0.754878).fract() * 3.0 - 1.0;
        data.push_str(&format!(
            "{a},{b},{}\n",
            (1.3 * a).sin() + b * b * 0.5 + 0.2 * a * b
        ));
    }
    write(&dir.join("train.csv"), &data);
    let gp = dir.join("gp.json");
    let o = iuq(&[
        "gp",
        "fit",
        "--data",
        s(&dir.join("train.csv")),
        "--inputs",
        "a,b",
        "--output",
        "y",
        "--restarts",
        "2",
        "--out",
        s(&gp),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let study = dir.join("surrogate.toml");
    write(&study, &format!("name = \"surrogate\"{PARAMETERS}"));
    let served = Served::start(&study, &["--surrogate", s(&gp)]);
    assert_eq!(served.announcement["models"][0]["gradient"], json!(true));
    assert_eq!(served.announcement["models"][0]["batch"], json!(64));
    assert_eq!(served.announcement["models"].as_array().unwrap().len(), 1);

    let client = UmBridgeModel::connect(
        &served.url(),
        "surrogate",
        names(&["a", "b"]),
        ClientOptions {
            config: json!({"computational_std": true}),
            std_output: true,
            ..Default::default()
        },
    )
    .unwrap();
    // Means and stds agree with `iuq gp predict`.
    let points: Vec<Vec<f64>> = (0..10)
        .map(|i| vec![0.25 + 0.27 * i as f64, -0.8 + 0.29 * i as f64])
        .collect();
    let mut csv = String::from("a,b\n");
    for p in &points {
        csv.push_str(&format!("{},{}\n", p[0], p[1]));
    }
    write(&dir.join("points.csv"), &csv);
    let o = iuq(&[
        "gp",
        "predict",
        "--model",
        s(&gp),
        "--points",
        s(&dir.join("points.csv")),
        "--out",
        s(&dir.join("pred.csv")),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let predicted = std::fs::read_to_string(dir.join("pred.csv")).unwrap();
    let mut lines = predicted.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let (mean_col, std_col) = (
        header.iter().position(|h| *h == "mean").unwrap(),
        // A GP bank reports the std of a new run (noise included) as its computational std.
        header.iter().position(|h| *h == "std_with_noise").unwrap(),
    );
    let out = client.evaluate_batch(&points).unwrap();
    for (line, o) in lines.zip(&out) {
        let cols: Vec<f64> = line.split(',').map(|v| v.parse().unwrap()).collect();
        let e = o.as_ref().unwrap();
        assert!((e.outputs[0] - cols[mean_col]).abs() < 1e-9, "{line}");
        let std = e.computational_std.as_ref().unwrap()[0];
        assert!(
            (std - cols[std_col]).abs() < 1e-6 * (1.0 + cols[std_col]),
            "{std} {line}"
        );
    }
    // Without the std, only the means are computed: the same numbers.
    let means_only = UmBridgeModel::connect(
        &served.url(),
        "surrogate",
        names(&["a", "b"]),
        Default::default(),
    )
    .unwrap();
    let plain = means_only.evaluate_batch(&points).unwrap();
    for (p, o) in plain.iter().zip(&out) {
        assert_eq!(p.as_ref().unwrap().outputs, o.as_ref().unwrap().outputs);
    }
    // The gradient of the mean against central differences of the served mean.
    for p in &points {
        let gradient = client.gradient(0, 0, p, &[1.0]).unwrap();
        let jv = client.apply_jacobian(0, 0, p, &[0.0, 1.0]).unwrap();
        assert_eq!(jv[0], gradient[1]);
        for k in 0..2 {
            // The GP's mean carries round-off of ~1e-9 (its noise variance sits at 1e-8): a
            // step of 1e-3 keeps both that and the truncation error near 1e-6.
            let h = 1e-3;
            let mut up = p.clone();
            let mut down = p.clone();
            up[k] += h;
            down[k] -= h;
            let f = |x: &[f64]| client.evaluate(x).unwrap().unwrap().outputs[0];
            let fd = (f(&up) - f(&down)) / (2.0 * h);
            assert!(
                (gradient[k] - fd).abs() < 1e-5 * (1.0 + fd.abs()),
                "∂/∂x{k} at {p:?}: {} vs {fd}",
                gradient[k]
            );
        }
    }
}

#[test]
fn mistakes_are_bad_input_and_an_unreachable_server_a_failure() {
    let dir = scratch("errors");
    let free_port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let study = |name: &str, model: &str| -> PathBuf {
        let path = dir.join(format!("{name}.toml"));
        write(
            &path,
            &format!("name = \"{name}\"{PARAMETERS}[model]\n{model}\n"),
        );
        path
    };
    // Missing keys, unknown keys: exit 2 naming the file and key.
    for (model, key) in [
        (
            "kind = \"umbridge\"\nurl = \"http://127.0.0.1:1\"",
            "model.name",
        ),
        ("kind = \"umbridge\"\nname = \"m\"", "model.url"),
        (
            "kind = \"umbridge\"\nurl = \"http://h\"\nname = \"m\"\nthreads = 3",
            "model.threads",
        ),
        (
            "kind = \"umbridge\"\nurl = \"https://h\"\nname = \"m\"",
            "model.url",
        ),
    ] {
        let path = study("bad", model);
        let o = iuq(&["sobol", s(&path), "--json"]);
        assert_eq!(o.status.code(), Some(2), "{model}");
        let v = json_of(&o);
        assert_eq!(v["error"]["kind"], json!("bad_input"));
        let message = v["error"]["message"].as_str().unwrap();
        assert!(
            message.contains("bad.toml") && message.contains(key),
            "{message}"
        );
    }
    // Nobody listening: a failure of the work (exit 1), after the configured retries.
    let path = study(
        "down",
        &format!(
            "kind = \"umbridge\"\nurl = \"http://127.0.0.1:{free_port}\"\nname = \"m\"\nretries = 1\nretry_delay = 0.05"
        ),
    );
    let o = iuq(&["sobol", s(&path), "--json"]);
    assert_eq!(o.status.code(), Some(1));
    let message = json_of(&o)["error"]["message"]
        .as_str()
        .unwrap()
        .to_string();
    assert!(message.contains("unreachable after 2 attempt"), "{message}");

    // A live server without the model, or with other sizes: exit 2.
    let expression = study("expr", "kind = \"expression\"\noutputs = { y = \"a*b\" }");
    let served = Served::start(&expression, &[]);
    let url = served.url();
    for (model, needle) in [
        (
            format!("kind = \"umbridge\"\nurl = \"{url}\"\nname = \"nonesuch\""),
            "has no model `nonesuch`",
        ),
        (
            format!(
                "kind = \"umbridge\"\nurl = \"{url}\"\nname = \"expr\"\noutputs = [\"p\", \"q\"]"
            ),
            "2 output names are given for 1 outputs",
        ),
    ] {
        let path = study("mismatch", &model);
        let o = iuq(&["sobol", s(&path), "--json"]);
        assert_eq!(
            o.status.code(),
            Some(2),
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
        let message = json_of(&o)["error"]["message"]
            .as_str()
            .unwrap()
            .to_string();
        assert!(
            message.contains(needle) && message.contains("mismatch.toml"),
            "{message}"
        );
    }
    // Serving: nothing to serve, a surrogate of other inputs, a port in use.
    let empty = dir.join("empty.toml");
    write(&empty, &format!("name = \"empty\"{PARAMETERS}"));
    let o = iuq(&["serve", "umbridge", s(&empty), "--port", "0", "--json"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        json_of(&o)["error"]["message"]
            .as_str()
            .unwrap()
            .contains("nothing to serve")
    );
    let gp = dir.join("gp.json");
    write(
        &dir.join("t.csv"),
        "u,v,y\n0,0,0\n1,0,1\n0,1,1\n1,1,2\n0.5,0.5,1\n",
    );
    let o = iuq(&[
        "gp",
        "fit",
        "--data",
        s(&dir.join("t.csv")),
        "--inputs",
        "u,v",
        "--output",
        "y",
        "--restarts",
        "0",
        "--out",
        s(&gp),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = iuq(&[
        "serve",
        "umbridge",
        s(&empty),
        "--port",
        "0",
        "--surrogate",
        s(&gp),
        "--json",
    ]);
    assert_eq!(o.status.code(), Some(2));
    let message = json_of(&o)["error"]["message"]
        .as_str()
        .unwrap()
        .to_string();
    assert!(message.contains("not the study's parameters"), "{message}");
    let port = served.url().rsplit(':').next().unwrap().to_string();
    let o = iuq(&[
        "serve",
        "umbridge",
        s(&expression),
        "--port",
        &port,
        "--json",
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        json_of(&o)["error"]["message"]
            .as_str()
            .unwrap()
            .contains("cannot listen")
    );
    let o = iuq(&[
        "serve",
        "umbridge",
        s(&expression),
        "--parallel",
        "0",
        "--json",
    ]);
    assert_eq!(o.status.code(), Some(2));
}
