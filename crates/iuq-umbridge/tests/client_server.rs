//! Our client against our server (and against small fake servers): batches, per-point
//! failures, the computational std, connection errors, reconnects and retries.

mod common;

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::Arc;
use std::time::{Duration, Instant};

use common::{Quadratic, Slow, names, quadratic_models, serve};
use iuq_core::{CoreError, ExpressionModel, Model};
use iuq_umbridge::{
    ClientOptions, ServedModel, Server, ServerOptions, UmBridgeError, UmBridgeModel,
};

fn fast_retries() -> ClientOptions {
    ClientOptions {
        retries: 3,
        retry_delay: Duration::from_millis(20),
        ..Default::default()
    }
}

#[test]
fn batches_match_the_model_in_process_bit_for_bit() {
    let ishigami = ExpressionModel::new(
        names(&["x1", "x2", "x3"]),
        &[
            (
                "f".into(),
                "sin(x1) + 7*sin(x2)^2 + 0.1*x3^4*sin(x1)".into(),
            ),
            ("g".into(), "x1*x2/3 - exp(x3/7)".into()),
        ],
    )
    .unwrap();
    let server = serve(
        vec![ServedModel::new("ishigami", Arc::new(ishigami.clone()))],
        ServerOptions::default(),
    );
    let client = UmBridgeModel::connect(
        &server.url(),
        "ishigami",
        names(&["x1", "x2", "x3"]),
        ClientOptions {
            output_names: Some(names(&["f", "g"])),
            ..fast_retries()
        },
    )
    .unwrap();
    assert_eq!(client.input_sizes(), &[3]);
    assert_eq!(client.output_sizes(), &[2]);
    assert_eq!(client.output_names(), &names(&["f", "g"])[..]);
    let points: Vec<Vec<f64>> = (0..300)
        .map(|i| {
            let t = i as f64 * 0.7548776662;
            vec![
                (t.sin() * 3.1).fract() * 3.0,
                (t * 1.3).cos() * std::f64::consts::PI,
                -1.0 / (1.0 + i as f64),
            ]
        })
        .collect();
    let remote = client.evaluate_batch(&points).unwrap();
    let local = ishigami.evaluate_batch(&points).unwrap();
    assert_eq!(remote, local);
    assert_eq!(client.evaluate_batch(&[]).unwrap(), vec![]);
    assert!(matches!(
        client.evaluate_batch(&[vec![1.0]]),
        Err(CoreError::DimensionMismatch {
            expected: 3,
            actual: 1
        })
    ));
}

#[test]
fn failures_are_per_point_and_the_std_travels_as_a_second_vector() {
    let server = serve(quadratic_models(), ServerOptions::default());
    let points = vec![
        vec![3.0, 0.5],
        vec![-1.0, 2.0],
        vec![2e6, 0.0],
        vec![12345.0, 1.0],
        vec![1.5, -2.0],
    ];
    for concurrency in [1, 3] {
        let client = UmBridgeModel::connect(
            &server.url(),
            "quadratic",
            names(&["x", "y"]),
            ClientOptions {
                concurrency,
                ..fast_retries()
            },
        )
        .unwrap();
        assert_eq!(
            client.output_names(),
            &names(&["quadratic_1", "quadratic_2"])[..]
        );
        let out = client.evaluate_batch(&points).unwrap();
        assert_eq!(out.len(), 5);
        let ok = out[0].as_ref().unwrap();
        assert_eq!(ok.outputs, vec![9.5, 1.5]);
        assert_eq!(ok.computational_std, None);
        let reason = &out[1].as_ref().unwrap_err().reason;
        assert!(
            reason.contains("ModelError") && reason.contains("mesh broke"),
            "{reason}"
        );
        assert!(out[2].as_ref().unwrap_err().reason.contains("panicked"));
        assert!(
            out[3]
                .as_ref()
                .unwrap_err()
                .reason
                .contains("InvalidOutput")
        );
        assert_eq!(
            out[4].as_ref().unwrap().outputs,
            Quadratic::value(&points[4])
        );
    }
    let with_std = UmBridgeModel::connect(
        &server.url(),
        "quadratic",
        names(&["x", "y"]),
        ClientOptions {
            config: serde_json::json!({"computational_std": true}),
            std_output: true,
            output_names: Some(names(&["f", "g"])),
            ..fast_retries()
        },
    )
    .unwrap();
    assert_eq!(with_std.output_sizes(), &[2, 2]);
    let out = with_std.evaluate_batch(&points[..1]).unwrap();
    let e = out[0].as_ref().unwrap();
    assert_eq!(e.outputs, vec![9.5, 1.5]);
    assert_eq!(
        e.computational_std,
        Some(vec![0.9500000000000001, 0.15000000000000002])
    );
    // Derivatives through the client.
    assert_eq!(
        with_std.gradient(0, 0, &[3.0, 0.5], &[1.0, 2.0]).unwrap(),
        vec![7.0, 7.0]
    );
    assert_eq!(
        with_std
            .apply_jacobian(0, 0, &[3.0, 0.5], &[1.0, -1.0])
            .unwrap(),
        vec![5.0, -2.5]
    );
    let plain =
        UmBridgeModel::connect(&server.url(), "plain", names(&["x", "y"]), fast_retries()).unwrap();
    assert!(matches!(
        plain.gradient(0, 0, &[3.0, 0.5], &[1.0, 2.0]),
        Err(UmBridgeError::UnsupportedFeature { .. })
    ));
}

#[test]
fn connection_errors_are_clear() {
    let server = serve(quadratic_models(), ServerOptions::default());
    let url = server.url();
    let e =
        UmBridgeModel::connect(&url, "nonesuch", names(&["x", "y"]), fast_retries()).unwrap_err();
    assert!(matches!(&e, UmBridgeError::ModelNotFound { available, .. } if available.len() == 2));
    assert!(e.is_bad_input());
    let e = UmBridgeModel::connect(&url, "quadratic", names(&["x", "y", "z"]), fast_retries())
        .unwrap_err();
    assert!(matches!(e, UmBridgeError::SizeMismatch { .. }), "{e}");
    assert!(
        e.to_string()
            .contains("add up to 2 values, but 3 parameters"),
        "{e}"
    );
    let e = UmBridgeModel::connect(
        &url,
        "quadratic",
        names(&["x", "y"]),
        ClientOptions {
            output_names: Some(names(&["only-one"])),
            ..fast_retries()
        },
    )
    .unwrap_err();
    assert!(matches!(e, UmBridgeError::SizeMismatch { .. }), "{e}");
    let e = UmBridgeModel::connect(
        &url,
        "quadratic",
        names(&["x", "y"]),
        ClientOptions {
            std_output: true,
            ..fast_retries()
        },
    )
    .unwrap_err();
    assert!(e.to_string().contains("std_output"), "{e}");
    let e = UmBridgeModel::connect("ftp://x", "quadratic", names(&["x", "y"]), fast_retries())
        .unwrap_err();
    assert!(matches!(e, UmBridgeError::InvalidUrl { .. }));
    // Nobody listening: retried, then unreachable (not bad input: exit code 1 in the CLI).
    let port = common::free_port();
    let started = Instant::now();
    let e = UmBridgeModel::connect(
        &format!("http://127.0.0.1:{port}"),
        "quadratic",
        names(&["x", "y"]),
        fast_retries(),
    )
    .unwrap_err();
    assert!(
        matches!(e, UmBridgeError::Unreachable { attempts: 4, .. }),
        "{e}"
    );
    assert!(!e.is_bad_input());
    // 20 + 40 + 80 ms of backoff.
    assert!(started.elapsed() >= Duration::from_millis(140));
}

/// A fake server answering every request on its connections with `answer(path)`.
fn fake_server(answer: impl Fn(&str) -> (u16, String) + Send + Sync + 'static) -> String {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let url = format!("http://{}", listener.local_addr().unwrap());
    let answer = Arc::new(answer);
    std::thread::spawn(move || {
        for stream in listener.incoming().flatten() {
            let answer = answer.clone();
            std::thread::spawn(move || {
                let mut writer = stream.try_clone().unwrap();
                let mut reader = BufReader::new(stream);
                loop {
                    let mut line = String::new();
                    if reader.read_line(&mut line).unwrap_or(0) == 0 {
                        return;
                    }
                    let path = line.split_whitespace().nth(1).unwrap_or("").to_string();
                    let mut length = 0;
                    loop {
                        let mut h = String::new();
                        reader.read_line(&mut h).unwrap();
                        if h.trim().is_empty() {
                            break;
                        }
                        if let Some(v) = h.to_ascii_lowercase().strip_prefix("content-length:") {
                            length = v.trim().parse().unwrap();
                        }
                    }
                    let mut body = vec![0; length];
                    reader.read_exact(&mut body).unwrap();
                    let (status, text) = answer(&path);
                    if status == 0 {
                        return; // drop the connection without an answer
                    }
                    let _ = write!(
                        writer,
                        "HTTP/1.1 {status} X\r\nContent-Length: {}\r\n\r\n{text}",
                        text.len()
                    );
                }
            });
        }
    });
    url
}

fn fake_model(path: &str) -> Option<(u16, String)> {
    Some(match path {
        "/Info" => (200, r#"{"protocolVersion": 1.0, "models": ["m"]}"#.into()),
        "/ModelInfo" => (200, r#"{"support": {"Evaluate": true}}"#.into()),
        "/InputSizes" => (200, r#"{"inputSizes": [1]}"#.into()),
        "/OutputSizes" => (200, r#"{"outputSizes": [1]}"#.into()),
        _ => return None,
    })
}

#[test]
fn sizes_no_model_could_have_are_refused_not_allocated() {
    for (endpoint, body) in [
        (
            "/InputSizes",
            r#"{"inputSizes": [18446744073709551615, 2]}"#,
        ),
        ("/OutputSizes", r#"{"outputSizes": [100000000000000000]}"#),
    ] {
        let url = fake_server(move |path| {
            if path == endpoint {
                (200, body.to_string())
            } else {
                fake_model(path).unwrap_or((404, "{}".into()))
            }
        });
        let e = UmBridgeModel::connect(&url, "m", names(&["x"]), fast_retries()).unwrap_err();
        let message = e.to_string();
        assert!(
            matches!(e, UmBridgeError::InvalidResponse { .. })
                && message.contains(endpoint)
                && message.contains("add up to more than"),
            "{message}"
        );
    }
}

#[test]
fn another_protocol_version_is_refused_with_a_clear_error() {
    for (info, found) in [
        (r#"{"protocolVersion": 0.9, "models": ["m"]}"#, "0.9"),
        (r#"{"protocolVersion": 2.0, "models": ["m"]}"#, "2.0"),
        (r#"{"models": ["m"]}"#, "none"),
    ] {
        let url = fake_server(move |_| (200, info.to_string()));
        let e = UmBridgeModel::connect(&url, "m", names(&["x"]), fast_retries()).unwrap_err();
        assert!(
            matches!(e, UmBridgeError::UnsupportedProtocolVersion { .. }),
            "{e}"
        );
        let message = e.to_string();
        assert!(
            message.contains(&format!("protocol version {found}"))
                && message.contains("supports protocol version 1.0 only"),
            "{message}"
        );
    }
    let url = fake_server(|path| match path {
        "/ModelInfo" => (200, r#"{"support": {"Evaluate": false}}"#.into()),
        p => fake_model(p).unwrap_or((404, String::new())),
    });
    let e = UmBridgeModel::connect(&url, "m", names(&["x"]), fast_retries()).unwrap_err();
    assert!(matches!(e, UmBridgeError::UnsupportedFeature { .. }), "{e}");
}

#[test]
fn dropped_connections_and_busy_answers_are_retried() {
    use std::sync::atomic::{AtomicUsize, Ordering};
    let calls = Arc::new(AtomicUsize::new(0));
    let counter = calls.clone();
    // Evaluate: first a dropped connection, then 503, then the answer; a Python-style 500
    // without an error object, and NaN (which JSON cannot carry) for input 7.
    let url = fake_server(move |path| {
        if let Some(a) = fake_model(path) {
            return a;
        }
        match counter.fetch_add(1, Ordering::SeqCst) {
            0 => (0, String::new()),
            1 => (
                503,
                r#"{"error": {"type": "ServerBusy", "message": "later"}}"#.into(),
            ),
            2 => (200, r#"{"output": [[42.0]]}"#.into()),
            3 => (
                500,
                "500 Internal Server Error\n\nServer got itself in trouble".into(),
            ),
            _ => (200, "{\"output\": [[NaN]] }".into()),
        }
    });
    let one_at_a_time = ClientOptions {
        concurrency: 1,
        ..fast_retries()
    };
    let client = UmBridgeModel::connect(&url, "m", names(&["x"]), one_at_a_time).unwrap();
    let out = client
        .evaluate_batch(&[vec![1.0], vec![2.0], vec![7.0]])
        .unwrap();
    assert_eq!(out[0].as_ref().unwrap().outputs, vec![42.0]);
    let reason = &out[1].as_ref().unwrap_err().reason;
    assert!(
        reason.contains("HTTP 500") && reason.contains("Server got itself in trouble"),
        "{reason}"
    );
    assert!(
        out[2]
            .as_ref()
            .unwrap_err()
            .reason
            .contains("invalid output")
    );
    assert_eq!(calls.load(Ordering::SeqCst), 5);
    // Retries spent: the batch fails as a whole (an infrastructure failure, not a point's).
    let url = fake_server(|path| fake_model(path).unwrap_or((503, String::new())));
    let client = UmBridgeModel::connect(&url, "m", names(&["x"]), fast_retries()).unwrap();
    match client.evaluate_batch(&[vec![1.0]]) {
        Err(CoreError::ModelUnavailable(m)) => assert!(m.contains("after 4 attempt"), "{m}"),
        other => panic!("{other:?}"),
    }
    // A status the protocol does not use for a point fails the batch too.
    let url = fake_server(|path| fake_model(path).unwrap_or((404, "gone".into())));
    let client = UmBridgeModel::connect(&url, "m", names(&["x"]), fast_retries()).unwrap();
    assert!(matches!(
        client.evaluate_batch(&[vec![1.0]]),
        Err(CoreError::ModelUnavailable(_))
    ));
}

#[test]
fn the_client_reconnects_when_the_server_restarts_mid_batch() {
    let slow = Arc::new(Slow::new(300));
    let first = Server::bind(
        vec![ServedModel::new("slow", slow.clone())],
        "127.0.0.1:0",
        ServerOptions::default(),
    )
    .unwrap();
    let address = first.local_addr();
    let first = first.spawn().unwrap();
    let client = UmBridgeModel::connect(
        &format!("http://{address}"),
        "slow",
        names(&["x"]),
        ClientOptions {
            concurrency: 2,
            retries: 8,
            retry_delay: Duration::from_millis(50),
            ..Default::default()
        },
    )
    .unwrap();
    let points: Vec<Vec<f64>> = (0..6).map(|i| vec![i as f64]).collect();
    let restarted = std::thread::scope(|s| {
        let batch = s.spawn(|| client.evaluate_batch(&points));
        // Kill the server while two evaluations are in flight, restart it on the same port.
        std::thread::sleep(Duration::from_millis(150));
        first.shutdown();
        std::thread::sleep(Duration::from_millis(200));
        let second = Server::bind(
            vec![ServedModel::new("slow", Arc::new(Slow::new(10)))],
            &address.to_string(),
            ServerOptions::default(),
        )
        .unwrap()
        .spawn()
        .unwrap();
        let out = batch.join().unwrap();
        second.shutdown();
        out
    });
    let out = restarted.unwrap();
    for (i, o) in out.iter().enumerate() {
        assert_eq!(o.as_ref().unwrap().outputs, vec![i as f64 + 1.0]);
    }
    // A client may also start before its server: connect retries until it is up.
    let port = common::free_port();
    let late = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(300));
        serve_on(port)
    });
    let client = UmBridgeModel::connect(
        &format!("http://127.0.0.1:{port}"),
        "quadratic",
        names(&["x", "y"]),
        ClientOptions {
            retries: 10,
            retry_delay: Duration::from_millis(50),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(
        client.evaluate(&[1.0, 1.0]).unwrap().unwrap().outputs,
        vec![2.0, 1.0]
    );
    late.join().unwrap().shutdown();
}

fn serve_on(port: u16) -> iuq_umbridge::ServerHandle {
    Server::bind(
        quadratic_models(),
        &format!("127.0.0.1:{port}"),
        ServerOptions::default(),
    )
    .unwrap()
    .spawn()
    .unwrap()
}

#[test]
fn long_runs_wait_without_a_read_timeout_unless_one_is_set() {
    let server = serve(
        vec![ServedModel::new("slow", Arc::new(Slow::new(1500)))],
        ServerOptions::default(),
    );
    let client = UmBridgeModel::connect(
        &server.url(),
        "slow",
        names(&["x"]),
        ClientOptions::default(),
    )
    .unwrap();
    assert_eq!(client.options().read_timeout, None);
    assert_eq!(client.evaluate(&[2.0]).unwrap().unwrap().outputs, vec![3.0]);
    let impatient = UmBridgeModel::connect(
        &server.url(),
        "slow",
        names(&["x"]),
        ClientOptions {
            read_timeout: Some(Duration::from_millis(300)),
            ..ClientOptions::default()
        },
    )
    .unwrap();
    let reason = impatient.evaluate(&[2.0]).unwrap().unwrap_err().reason;
    assert!(reason.contains("read timeout"), "{reason}");
    // The raw socket of a client that vanished mid-request does not disturb the server.
    let mut s = TcpStream::connect(server.local_addr()).unwrap();
    s.write_all(b"POST /Evaluate HTTP/1.1\r\nContent-Length: 100\r\n\r\n{\"na")
        .unwrap();
    drop(s);
    assert_eq!(client.evaluate(&[4.0]).unwrap().unwrap().outputs, vec![5.0]);
}
