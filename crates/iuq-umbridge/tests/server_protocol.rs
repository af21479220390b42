//! The server over raw sockets: every endpoint, every kind of bad request answered with the
//! protocol's status and error type, and the server still serving afterwards.

mod common;

use std::io::Write;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use common::{Connection, Slow, post, quadratic_models, serve};
use iuq_umbridge::{ServedModel, ServerOptions};
use serde_json::json;

fn options() -> ServerOptions {
    ServerOptions {
        parallel: 2,
        max_body_bytes: 1 << 20,
        ..Default::default()
    }
}

const GOOD: &str = r#"{"name": "quadratic", "input": [[3.0, 0.5]], "config": {}}"#;

/// A good evaluation still works.
fn still_serving(address: std::net::SocketAddr) {
    let a = post(address, "/Evaluate", GOOD);
    assert_eq!(a.status, 200, "{}", a.body);
    assert_eq!(a.json(), json!({"output": [[9.5, 1.5]]}));
}

#[test]
fn metadata_endpoints_follow_the_protocol() {
    let server = serve(quadratic_models(), options());
    let address = server.local_addr();
    let mut c = Connection::open(address);
    let info = c.get("/Info");
    assert_eq!(info.status, 200);
    assert_eq!(info.header("content-type"), Some("application/json"));
    let v = info.json();
    assert!(v["protocolVersion"].is_number(), "{v}");
    assert_eq!(v["protocolVersion"].as_f64(), Some(1.0));
    assert_eq!(v["models"], json!(["quadratic", "plain"]));
    // The same kept-alive connection answers the next requests.
    assert_eq!(
        c.post("/ModelInfo", r#"{"name": "quadratic"}"#).json(),
        json!({"support": {"Evaluate": true, "Gradient": true, "ApplyJacobian": true, "ApplyHessian": false}})
    );
    assert_eq!(
        c.post("/ModelInfo", r#"{"name": "plain"}"#).json()["support"]["Gradient"],
        json!(false)
    );
    assert_eq!(
        c.post("/InputSizes", r#"{"name": "quadratic", "config": {}}"#)
            .json(),
        json!({"inputSizes": [2]})
    );
    assert_eq!(
        c.post("/OutputSizes", r#"{"name": "quadratic"}"#).json(),
        json!({"outputSizes": [2]})
    );
    assert_eq!(
        c.post(
            "/OutputSizes",
            r#"{"name": "quadratic", "config": {"computational_std": true}}"#
        )
        .json(),
        json!({"outputSizes": [2, 2]})
    );
    let e = c.post(
        "/Evaluate",
        r#"{"name": "quadratic", "input": [[3.0, 0.5]], "config": {"computational_std": true}}"#,
    );
    assert_eq!(
        e.json(),
        json!({"output": [[9.5, 1.5], [0.9500000000000001, 0.15000000000000002]]})
    );
    server.shutdown();
}

#[test]
fn derivatives_are_served_for_models_with_a_jacobian() {
    let server = serve(quadratic_models(), options());
    let address = server.local_addr();
    // J = [[2x, 1], [y, x]] at (3, 0.5) = [[6, 1], [0.5, 3]].
    let g = post(
        address,
        "/Gradient",
        r#"{"name": "quadratic", "outWrt": 0, "inWrt": 0, "input": [[3.0, 0.5]], "sens": [1.0, 2.0]}"#,
    );
    assert_eq!(g.status, 200, "{}", g.body);
    assert_eq!(g.json(), json!({"output": [7.0, 7.0]}));
    let j = post(
        address,
        "/ApplyJacobian",
        r#"{"name": "quadratic", "outWrt": 0, "inWrt": 0, "input": [[3.0, 0.5]], "vec": [1.0, -1.0], "config": {}}"#,
    );
    assert_eq!(j.json(), json!({"output": [5.0, -2.5]}));
    let cases = [
        (
            "/Gradient",
            r#"{"name": "plain", "outWrt": 0, "inWrt": 0, "input": [[3.0, 0.5]], "sens": [1.0, 2.0]}"#,
            400,
            "UnsupportedFeature",
        ),
        (
            "/Gradient",
            r#"{"name": "quadratic", "outWrt": 0, "inWrt": 1, "input": [[3.0, 0.5]], "sens": [1.0, 2.0]}"#,
            400,
            "InvalidInput",
        ),
        (
            "/Gradient",
            r#"{"name": "quadratic", "outWrt": 2, "inWrt": 0, "input": [[3.0, 0.5]], "sens": [1.0, 2.0]}"#,
            400,
            "InvalidInput",
        ),
        (
            "/Gradient",
            r#"{"name": "quadratic", "outWrt": 0, "inWrt": 0, "input": [[3.0, 0.5]], "sens": [1.0]}"#,
            400,
            "InvalidInput",
        ),
        (
            "/Gradient",
            r#"{"name": "quadratic", "outWrt": 0, "inWrt": 0, "input": [[-3.0, 0.5]], "sens": [1.0, 2.0]}"#,
            500,
            "ModelError",
        ),
        (
            "/ApplyJacobian",
            r#"{"name": "quadratic", "outWrt": 0, "inWrt": 0, "input": [[3.0, 0.5]]}"#,
            400,
            "InvalidInput",
        ),
        (
            "/ApplyHessian",
            r#"{"name": "quadratic", "outWrt": 0, "inWrt1": 0, "inWrt2": 0, "input": [[3.0, 0.5]], "sens": [1.0, 0.0], "vec": [1.0, 0.0]}"#,
            400,
            "UnsupportedFeature",
        ),
    ];
    for (path, body, status, error_type) in cases {
        let a = post(address, path, body);
        assert_eq!(
            (a.status, a.error_type().as_str()),
            (status, error_type),
            "{path} {body}: {}",
            a.body
        );
        still_serving(address);
    }
}

#[test]
fn malformed_requests_get_the_right_status_and_type_and_the_server_keeps_serving() {
    let server = serve(quadratic_models(), options());
    let address = server.local_addr();
    let cases: Vec<(&str, String, u16, &str)> = vec![
        ("/Evaluate", "{\"name\": \"quadratic\", \"input\": [[1, 2]".into(), 400, "InvalidInput"),
        ("/Evaluate", "not json at all".into(), 400, "InvalidInput"),
        ("/Evaluate", "[1, 2, 3]".into(), 400, "InvalidInput"),
        ("/Evaluate", "".into(), 400, "InvalidInput"),
        ("/Evaluate", r#"{"input": [[1.0, 2.0]]}"#.into(), 400, "InvalidInput"),
        ("/Evaluate", r#"{"name": 7, "input": [[1.0, 2.0]]}"#.into(), 400, "InvalidInput"),
        ("/Evaluate", r#"{"name": "quadratic"}"#.into(), 400, "InvalidInput"),
        ("/Evaluate", r#"{"name": "quadratic", "input": [[1.0, 2.0, 3.0]]}"#.into(), 400, "InvalidInput"),
        ("/Evaluate", r#"{"name": "quadratic", "input": [[1.0]]}"#.into(), 400, "InvalidInput"),
        ("/Evaluate", r#"{"name": "quadratic", "input": [[1.0, 2.0], [3.0]]}"#.into(), 400, "InvalidInput"),
        ("/Evaluate", r#"{"name": "quadratic", "input": [1.0, 2.0]}"#.into(), 400, "InvalidInput"),
        ("/Evaluate", r#"{"name": "quadratic", "input": [[1.0, "2"]]}"#.into(), 400, "InvalidInput"),
        ("/Evaluate", r#"{"name": "quadratic", "input": [[1e400, 2.0]]}"#.into(), 400, "InvalidInput"),
        ("/Evaluate", r#"{"name": "quadratic", "input": [[1.0, 2.0]], "config": 5}"#.into(), 400, "InvalidInput"),
        ("/Evaluate", r#"{"name": "quadratic", "input": [[1.0, 2.0]], "config": {"computational_std": "yes"}}"#.into(), 400, "InvalidInput"),
        ("/Evaluate", format!("{}{}", "[".repeat(100_000), "]".repeat(100_000)), 400, "InvalidInput"),
        ("/Evaluate", r#"{"name": "nonesuch", "input": [[1.0, 2.0]]}"#.into(), 400, "ModelNotFound"),
        ("/ModelInfo", r#"{"name": "nonesuch"}"#.into(), 400, "ModelNotFound"),
        ("/InputSizes", r#"{"name": "nonesuch"}"#.into(), 400, "ModelNotFound"),
        ("/OutputSizes", r#"{"name": "nonesuch", "config": {}}"#.into(), 400, "ModelNotFound"),
        ("/Gradient", r#"{"name": "nonesuch"}"#.into(), 400, "ModelNotFound"),
        ("/EvaluateShMem", r#"{"name": "quadratic"}"#.into(), 404, "UnsupportedFeature"),
    ];
    let mut kept = Connection::open(address);
    for (path, body, status, error_type) in &cases {
        let a = post(address, path, body);
        assert_eq!(
            (a.status, a.error_type().as_str()),
            (*status, *error_type),
            "{path} {}: {}",
            &body[..body.len().min(80)],
            a.body
        );
        // A bad request does not close a kept-alive connection either.
        let b = kept.post(path, body);
        assert_eq!(b.status, *status);
        assert_eq!(kept.post("/Evaluate", GOOD).status, 200);
        still_serving(address);
    }
    // Wrong method, garbage instead of HTTP.
    let a = Connection::open(address).get("/Evaluate");
    assert_eq!((a.status, a.error_type().as_str()), (405, "InvalidInput"));
    let a = Connection::open(address).send_raw(b"HELLO THERE\r\n\r\n");
    assert_eq!((a.status, a.error_type().as_str()), (400, "InvalidInput"));
    still_serving(address);
}

#[test]
fn oversized_bodies_are_refused_with_413_without_being_read() {
    let server = serve(quadratic_models(), options());
    let address = server.local_addr();
    // A forged length far beyond memory: refused at once, from the header alone.
    let started = Instant::now();
    let a = Connection::open(address)
        .send_raw(b"POST /Evaluate HTTP/1.1\r\nHost: t\r\nContent-Length: 99999999999999\r\n\r\n{");
    assert_eq!((a.status, a.error_type().as_str()), (413, "InvalidInput"));
    assert_eq!(a.header("connection"), Some("close"));
    assert!(started.elapsed() < Duration::from_secs(2));
    still_serving(address);
    // A real 3 MB body over the 1 MiB limit, sent in full by the client.
    let big = format!(
        "{{\"name\": \"quadratic\", \"input\": [[1.0, 2.0]], \"pad\": \"{}\"}}",
        "x".repeat(3 << 20)
    );
    let mut c = Connection::open(address);
    let head = format!(
        "POST /Evaluate HTTP/1.1\r\nHost: t\r\nContent-Length: {}\r\n\r\n",
        big.len()
    );
    c.writer.write_all(head.as_bytes()).unwrap();
    let _ = c.writer.write_all(big.as_bytes()); // may be cut short by the server's close
    let a = common::read_answer(&mut c.reader);
    assert_eq!((a.status, a.error_type().as_str()), (413, "InvalidInput"));
    still_serving(address);
    // Chunked, passing the limit in the middle.
    let mut c = Connection::open(address);
    c.writer
        .write_all(b"POST /Evaluate HTTP/1.1\r\nHost: t\r\nTransfer-Encoding: chunked\r\n\r\n")
        .unwrap();
    let chunk = format!("{:x}\r\n{}\r\n", 256 << 10, "y".repeat(256 << 10));
    for _ in 0..8 {
        if c.writer.write_all(chunk.as_bytes()).is_err() {
            break;
        }
    }
    let a = common::read_answer(&mut c.reader);
    assert_eq!((a.status, a.error_type().as_str()), (413, "InvalidInput"));
    still_serving(address);
    // A head over the limit.
    let long = format!(
        "GET /Info HTTP/1.1\r\nX-Long: {}\r\n\r\n",
        "z".repeat(100 << 10)
    );
    let a = Connection::open(address).send_raw(long.as_bytes());
    assert_eq!((a.status, a.error_type().as_str()), (431, "InvalidInput"));
    still_serving(address);
    // Exactly at the limit is accepted (and then parsed).
    let server = serve(
        quadratic_models(),
        ServerOptions {
            max_body_bytes: GOOD.len(),
            ..options()
        },
    );
    assert_eq!(post(server.local_addr(), "/Evaluate", GOOD).status, 200);
}

#[test]
fn model_failures_are_500_error_objects() {
    let server = serve(quadratic_models(), options());
    let address = server.local_addr();
    let cases = [
        (
            r#"{"name": "quadratic", "input": [[-1.0, 2.0]]}"#,
            "ModelError",
            "mesh broke: x < 0",
        ),
        (
            r#"{"name": "quadratic", "input": [[2e6, 2.0]]}"#,
            "ModelError",
            "panicked: x is far too large",
        ),
        (
            r#"{"name": "quadratic", "input": [[12345.0, 2.0]]}"#,
            "InvalidOutput",
            "non-finite",
        ),
    ];
    for (body, error_type, reason) in cases {
        let a = post(address, "/Evaluate", body);
        assert_eq!(
            (a.status, a.error_type().as_str()),
            (500, error_type),
            "{}",
            a.body
        );
        let message = a.json()["error"]["message"].as_str().unwrap().to_string();
        assert!(message.contains(reason), "{message}");
        still_serving(address);
    }
    // The std is asked for but the model reports none.
    let expression = iuq_core::ExpressionModel::new(
        common::names(&["x"]),
        &[("y".to_string(), "2*x".to_string())],
    )
    .unwrap();
    let server = serve(vec![ServedModel::new("e", Arc::new(expression))], options());
    let a = post(
        server.local_addr(),
        "/Evaluate",
        r#"{"name": "e", "input": [[1.5]], "config": {"computational_std": true}}"#,
    );
    assert_eq!((a.status, a.error_type().as_str()), (500, "InvalidOutput"));
    let a = post(
        server.local_addr(),
        "/Evaluate",
        r#"{"name": "e", "input": [[1.5]]}"#,
    );
    assert_eq!(a.json(), json!({"output": [[3.0]]}));
}

#[test]
fn evaluations_run_in_parallel_up_to_the_limit_while_metadata_is_answered() {
    let slow = Arc::new(Slow::new(1000));
    let server = serve(
        vec![ServedModel::new("slow", slow.clone())],
        ServerOptions {
            parallel: 3,
            ..Default::default()
        },
    );
    let address = server.local_addr();
    let started = Instant::now();
    let info_latency = std::thread::scope(|s| {
        let requests: Vec<_> = (0..6)
            .map(|i| {
                s.spawn(move || {
                    let a = post(
                        address,
                        "/Evaluate",
                        &format!(r#"{{"name": "slow", "input": [[{i}.0]]}}"#),
                    );
                    assert_eq!(a.status, 200);
                    assert_eq!(a.json()["output"][0][0].as_f64(), Some(i as f64 + 1.0));
                })
            })
            .collect();
        std::thread::sleep(Duration::from_millis(200));
        let t = Instant::now();
        assert_eq!(Connection::open(address).get("/Info").status, 200);
        let latency = t.elapsed();
        for r in requests {
            r.join().unwrap();
        }
        latency
    });
    let elapsed = started.elapsed();
    // At most three points at once, one per call.
    assert_eq!(slow.most.load(Ordering::SeqCst), 3);
    assert_eq!(slow.calls.load(Ordering::SeqCst), 6);
    // Two rounds of three parallel 1 s evaluations; /Info is not queued behind them.
    assert!(elapsed >= Duration::from_millis(1990), "{elapsed:?}");
    assert!(elapsed < Duration::from_millis(3500), "{elapsed:?}");
    assert!(
        info_latency < Duration::from_millis(500),
        "{info_latency:?}"
    );
}

#[test]
fn too_many_connections_are_answered_with_503() {
    let server = serve(
        quadratic_models(),
        ServerOptions {
            max_connections: 2,
            ..options()
        },
    );
    let address = server.local_addr();
    let mut first = Connection::open(address);
    let mut second = Connection::open(address);
    assert_eq!(first.get("/Info").status, 200);
    assert_eq!(second.get("/Info").status, 200);
    let a = common::read_answer(&mut Connection::open(address).reader);
    assert_eq!((a.status, a.error_type().as_str()), (503, "ServerBusy"));
    drop(first);
    // Once a connection closes, new ones are served again.
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(Connection::open(address).get("/Info").status, 200);
    assert_eq!(second.get("/Info").status, 200);
}

#[test]
fn concurrent_requests_share_batches_up_to_the_model_limit() {
    let slow = Arc::new(Slow::new(500));
    let server = serve(
        vec![ServedModel::new("slow", slow.clone()).with_batch_limit(8)],
        ServerOptions {
            parallel: 1,
            ..Default::default()
        },
    );
    let address = server.local_addr();
    let started = Instant::now();
    std::thread::scope(|s| {
        for i in 0..8 {
            s.spawn(move || {
                let a = post(
                    address,
                    "/Evaluate",
                    &format!(r#"{{"name": "slow", "input": [[{i}.0]]}}"#),
                );
                assert_eq!(a.json()["output"][0][0].as_f64(), Some(i as f64 + 1.0));
            });
        }
    });
    // One call for the first request, one for the seven that waited: two rounds of 0.5 s
    // instead of eight (a slow machine may split the second round).
    assert!(
        slow.calls.load(Ordering::SeqCst) <= 4,
        "{}",
        slow.calls.load(Ordering::SeqCst)
    );
    assert!(
        started.elapsed() < Duration::from_millis(2500),
        "{:?}",
        started.elapsed()
    );
}

/// The values of `Quadratic` without a std, counting its calls.
struct ValuesOnly(Arc<common::Quadratic>, std::sync::atomic::AtomicUsize);

impl iuq_core::Model for ValuesOnly {
    fn input_names(&self) -> &[String] {
        self.0.input_names()
    }
    fn output_names(&self) -> &[String] {
        self.0.output_names()
    }
    fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<iuq_core::Outcome>> {
        self.1.fetch_add(points.len(), Ordering::SeqCst);
        Ok(points
            .iter()
            .map(|p| Ok(iuq_core::Evaluation::new(common::Quadratic::value(p))))
            .collect())
    }
}

#[test]
fn requests_without_the_std_are_answered_by_the_cheaper_twin_and_panics_stay_per_point() {
    let q = Arc::new(common::Quadratic::new());
    let twin = Arc::new(ValuesOnly(q.clone(), Default::default()));
    let server = serve(
        vec![
            ServedModel::new("quadratic", q.clone())
                .with_values_only(twin.clone())
                .with_batch_limit(16),
        ],
        ServerOptions {
            parallel: 1,
            ..options()
        },
    );
    let address = server.local_addr();
    assert_eq!(
        post(address, "/Evaluate", GOOD).json(),
        json!({"output": [[9.5, 1.5]]})
    );
    assert_eq!(twin.1.load(Ordering::SeqCst), 1);
    let with_std = post(
        address,
        "/Evaluate",
        r#"{"name": "quadratic", "input": [[3.0, 0.5]], "config": {"computational_std": true}}"#,
    );
    assert_eq!(with_std.json()["output"][0], json!([9.5, 1.5]));
    assert_eq!(twin.1.load(Ordering::SeqCst), 1);
    // Concurrent requests batched together, one of which panics in the full model: only that
    // one fails.
    std::thread::scope(|s| {
        for i in 0..12 {
            s.spawn(move || {
                let x = if i == 5 { 2e6 } else { i as f64 };
                let a = post(
                    address,
                    "/Evaluate",
                    &format!(
                        r#"{{"name": "quadratic", "input": [[{x:?}, 1.0]], "config": {{"computational_std": true}}}}"#
                    ),
                );
                if i == 5 {
                    assert_eq!((a.status, a.error_type().as_str()), (500, "ModelError"));
                } else {
                    assert_eq!(a.status, 200, "{}", a.body);
                    assert_eq!(a.json()["output"][0][0].as_f64(), Some(x * x + 1.0));
                }
            });
        }
    });
}
