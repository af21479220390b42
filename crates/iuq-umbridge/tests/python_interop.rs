//! Interoperability with the reference implementation, the Python package `umbridge`
//! (`pip install umbridge`): its client against our server, our client against its
//! `serve_models` server. Each test prints SKIPPED and passes when the package is missing
//! (the interpreter is `IUQ_PYTHON`, else `python3`).

mod common;

use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::{names, python_with_umbridge, quadratic_models, serve};
use iuq_core::Model;
use iuq_umbridge::{ClientOptions, ServerOptions, UmBridgeError, UmBridgeModel};
use serde_json::{Value, json};

fn script(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests")
        .join("python")
        .join(name)
}

#[test]
fn the_python_client_uses_our_server_and_sees_protocol_errors() {
    let Some(python) = python_with_umbridge() else {
        return;
    };
    let server = serve(quadratic_models(), ServerOptions::default());
    let output = Command::new(&python)
        .arg(script("umbridge_client_check.py"))
        .args([server.url().as_str(), "quadratic", "-1,2"])
        .output()
        .expect("run python");
    assert!(
        output.status.success(),
        "python client failed:\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let r: Value = serde_json::from_slice(&output.stdout).expect("one JSON object");
    assert_eq!(r["models"], json!(["quadratic", "plain"]));
    assert_eq!(r["input_sizes"], json!([2]));
    assert_eq!(r["output_sizes"], json!([2]));
    assert_eq!(r["output_sizes_with_std"], json!([2, 2]));
    assert_eq!(
        r["support"],
        json!({"evaluate": true, "gradient": true, "apply_jacobian": true, "apply_hessian": false})
    );
    // f = x² + y, g = x·y at (1.5, −0.5); J = [[3, 1], [−0.5, 1.5]].
    assert_eq!(r["evaluate"], json!([[1.75, -0.75]]));
    assert_eq!(
        r["evaluate_with_std"],
        json!([[1.75, -0.75], [0.1 * 1.75, 0.1 * 0.75]])
    );
    assert_eq!(r["gradient"], json!([2.5, 2.5]));
    assert_eq!(r["apply_jacobian"], json!([3.0, -0.5]));
    let errors = &r["errors"];
    let message = |key: &str| errors[key].as_str().unwrap_or_default().to_string();
    assert!(message("wrong_size").contains("InvalidInput"), "{errors}");
    assert!(
        message("wrong_size").contains("Expected 2 but got 3"),
        "{errors}"
    );
    assert!(
        message("unknown_model").contains("not supported by server"),
        "{errors}"
    );
    assert!(message("failing_point").contains("ModelError"), "{errors}");
    assert!(message("failing_point").contains("mesh broke"), "{errors}");
    assert!(message("hessian").contains("not supported"), "{errors}");

    // A model without a Jacobian: no gradient, and the client can ask for it anyway.
    let output = Command::new(&python)
        .arg(script("umbridge_client_check.py"))
        .args([server.url().as_str(), "plain"])
        .output()
        .expect("run python");
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let r: Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(r["support"]["gradient"], json!(false));
    assert!(r.get("gradient").is_none());
    assert_eq!(r["evaluate"], json!([[1.75, -0.75]]));
}

/// The Python package's server, stopped when dropped.
struct PythonServer(Child);

impl Drop for PythonServer {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn start_python_server(python: &str) -> (PythonServer, String) {
    let port = common::free_port();
    let child = Command::new(python)
        .arg(script("umbridge_model_server.py"))
        .arg(port.to_string())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start the Python server");
    let server = PythonServer(child);
    let url = format!("http://127.0.0.1:{port}");
    // Wait until it answers /Info.
    let deadline = Instant::now() + Duration::from_secs(30);
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(Instant::now() < deadline, "the Python server did not start");
        std::thread::sleep(Duration::from_millis(100));
    }
    (server, url)
}

#[test]
fn our_client_uses_the_python_server() {
    let Some(python) = python_with_umbridge() else {
        return;
    };
    let (_server, url) = start_python_server(&python);
    let options = ClientOptions {
        retries: 20,
        retry_delay: Duration::from_millis(100),
        ..Default::default()
    };
    // Input sizes [2, 1]: the three parameters are split over two input vectors; the output
    // vectors [2, 1] are concatenated.
    let model = UmBridgeModel::connect(&url, "forward", names(&["a", "b", "c"]), options.clone())
        .expect("connect to the Python server");
    assert_eq!(model.input_sizes(), &[2, 1]);
    assert_eq!(model.output_sizes(), &[2, 1]);
    assert_eq!(
        model.output_names(),
        &names(&["forward_1", "forward_2", "forward_3"])[..]
    );
    assert!(model.support().gradient);
    let points: Vec<Vec<f64>> = (0..40)
        .map(|i| vec![i as f64 * 0.25 - 1.0, 0.5 + i as f64, 0.1 * i as f64])
        .collect();
    let out = model.evaluate_batch(&points).unwrap();
    for (p, o) in points.iter().zip(&out) {
        if p[0] < 0.0 {
            let reason = &o.as_ref().unwrap_err().reason;
            assert!(reason.contains("HTTP 500"), "{reason}");
        } else {
            let e = o.as_ref().unwrap();
            assert_eq!(e.outputs, vec![p[0] + p[1], p[0] * p[1], p[2].sin()]);
        }
    }
    assert_eq!(out.iter().filter(|o| o.is_err()).count(), 4);
    // config reaches the model.
    let scaled = UmBridgeModel::connect(
        &url,
        "forward",
        names(&["a", "b", "c"]),
        ClientOptions {
            config: json!({"scale": 2.0}),
            ..options.clone()
        },
    )
    .unwrap();
    let e = scaled.evaluate(&[1.0, 2.0, 0.0]).unwrap().unwrap();
    assert_eq!(e.outputs, vec![6.0, 4.0, 0.0]);
    // Gradient of out0 w.r.t. input vector 0 with sens [1, 1]: [1 + b, 1 + a].
    assert_eq!(
        model.gradient(0, 0, &[1.0, 2.0, 0.5], &[1.0, 1.0]).unwrap(),
        vec![3.0, 2.0]
    );
    // A model answering [value, std].
    let with_std = UmBridgeModel::connect(
        &url,
        "with-std",
        names(&["x"]),
        ClientOptions {
            std_output: true,
            ..options.clone()
        },
    )
    .unwrap();
    let e = with_std.evaluate(&[1.25]).unwrap().unwrap();
    assert_eq!(
        (e.outputs, e.computational_std),
        (vec![2.5], Some(vec![0.1]))
    );
    // Errors of the Python server reach the caller clearly.
    let e = UmBridgeModel::connect(&url, "nonesuch", names(&["x"]), options.clone()).unwrap_err();
    assert!(matches!(e, UmBridgeError::ModelNotFound { .. }), "{e}");
    let e = UmBridgeModel::connect(&url, "forward", names(&["a", "b"]), options).unwrap_err();
    assert!(matches!(e, UmBridgeError::SizeMismatch { .. }), "{e}");
}
