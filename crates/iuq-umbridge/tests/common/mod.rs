//! Models and a raw HTTP helper shared by the integration tests (servers on 127.0.0.1 only,
//! ephemeral ports).
#![allow(dead_code)]

use std::io::{BufRead, BufReader, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use iuq_core::{Evaluation, EvaluationFailure, Model, Outcome};
use iuq_umbridge::{Jacobian, ServedModel, Server, ServerHandle, ServerOptions};

pub fn names(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

/// f = x² + y, g = x·y, with its Jacobian [[2x, 1], [y, x]] and a std of 0.1·|f|, 0.1·|g|;
/// fails for x < 0, panics for x > 1e6, returns NaN for x = 12345.
pub struct Quadratic {
    inputs: Vec<String>,
    outputs: Vec<String>,
}

impl Quadratic {
    pub fn new() -> Self {
        Self {
            inputs: names(&["x", "y"]),
            outputs: names(&["f", "g"]),
        }
    }

    pub fn value(x: &[f64]) -> Vec<f64> {
        vec![x[0] * x[0] + x[1], x[0] * x[1]]
    }
}

impl Model for Quadratic {
    fn input_names(&self) -> &[String] {
        &self.inputs
    }
    fn output_names(&self) -> &[String] {
        &self.outputs
    }
    fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
        Ok(points
            .iter()
            .map(|p| {
                if p[0] > 1e6 {
                    panic!("x is far too large");
                }
                if p[0] < 0.0 {
                    return Err(EvaluationFailure::new("mesh broke: x < 0"));
                }
                if p[0] == 12345.0 {
                    return Ok(Evaluation::new(vec![f64::NAN, 0.0]));
                }
                let v = Self::value(p);
                let std = v.iter().map(|v| 0.1 * v.abs()).collect();
                Ok(Evaluation::with_std(v, std))
            })
            .collect())
    }
}

impl Jacobian for Quadratic {
    fn jacobian(&self, x: &[f64]) -> Result<Vec<Vec<f64>>, EvaluationFailure> {
        if x[0] < 0.0 {
            return Err(EvaluationFailure::new("no Jacobian for x < 0"));
        }
        Ok(vec![vec![2.0 * x[0], 1.0], vec![x[1], x[0]]])
    }
}

/// h = x + 1 after sleeping `millis` per batch; counts the points evaluated at once and the
/// calls.
pub struct Slow {
    pub millis: u64,
    pub running: AtomicUsize,
    pub most: AtomicUsize,
    pub calls: AtomicUsize,
    inputs: Vec<String>,
    outputs: Vec<String>,
}

impl Slow {
    pub fn new(millis: u64) -> Self {
        Self {
            millis,
            running: AtomicUsize::new(0),
            most: AtomicUsize::new(0),
            calls: AtomicUsize::new(0),
            inputs: names(&["x"]),
            outputs: names(&["h"]),
        }
    }
}

impl Model for Slow {
    fn input_names(&self) -> &[String] {
        &self.inputs
    }
    fn output_names(&self) -> &[String] {
        &self.outputs
    }
    fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
        let now = self.running.fetch_add(points.len(), Ordering::SeqCst) + points.len();
        self.most.fetch_max(now, Ordering::SeqCst);
        self.calls.fetch_add(1, Ordering::SeqCst);
        std::thread::sleep(Duration::from_millis(self.millis));
        self.running.fetch_sub(points.len(), Ordering::SeqCst);
        Ok(points
            .iter()
            .map(|p| Ok(Evaluation::new(vec![p[0] + 1.0])))
            .collect())
    }
}

/// The models most tests serve: `quadratic` (with Jacobian) and `plain` (the same model
/// without one).
pub fn quadratic_models() -> Vec<ServedModel> {
    let q = Arc::new(Quadratic::new());
    vec![
        ServedModel::new("quadratic", q.clone()).with_jacobian(q.clone()),
        ServedModel::new("plain", q),
    ]
}

pub fn serve(models: Vec<ServedModel>, options: ServerOptions) -> ServerHandle {
    Server::bind(models, "127.0.0.1:0", options)
        .expect("bind")
        .spawn()
        .expect("spawn")
}

/// A parsed HTTP response.
#[derive(Debug)]
pub struct Answer {
    pub status: u16,
    pub headers: Vec<(String, String)>,
    pub body: String,
}

impl Answer {
    pub fn json(&self) -> serde_json::Value {
        serde_json::from_str(&self.body).unwrap_or_else(|e| panic!("{e}: {}", self.body))
    }

    /// The error object's type.
    pub fn error_type(&self) -> String {
        self.json()["error"]["type"]
            .as_str()
            .unwrap_or_else(|| panic!("no error object: {}", self.body))
            .to_string()
    }

    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(n, _)| n.eq_ignore_ascii_case(name))
            .map(|(_, v)| v.as_str())
    }
}

/// Reads one response from a connection.
pub fn read_answer(reader: &mut impl BufRead) -> Answer {
    let mut status_line = String::new();
    reader.read_line(&mut status_line).expect("status line");
    let status: u16 = status_line
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("bad status line {status_line:?}"));
    let mut headers = Vec::new();
    loop {
        let mut line = String::new();
        reader.read_line(&mut line).expect("header");
        let line = line.trim_end();
        if line.is_empty() {
            break;
        }
        let (name, value) = line.split_once(':').expect("header colon");
        headers.push((name.trim().to_string(), value.trim().to_string()));
    }
    let length: usize = headers
        .iter()
        .find(|(n, _)| n.eq_ignore_ascii_case("content-length"))
        .map(|(_, v)| v.parse().expect("length"))
        .unwrap_or(0);
    let mut body = vec![0; length];
    reader.read_exact(&mut body).expect("body");
    Answer {
        status,
        headers,
        body: String::from_utf8(body).expect("utf-8 body"),
    }
}

/// A kept-alive connection for raw requests.
pub struct Connection {
    pub writer: TcpStream,
    pub reader: BufReader<TcpStream>,
}

impl Connection {
    pub fn open(address: SocketAddr) -> Self {
        let writer = TcpStream::connect(address).expect("connect");
        writer
            .set_read_timeout(Some(Duration::from_secs(20)))
            .unwrap();
        let reader = BufReader::new(writer.try_clone().unwrap());
        Self { writer, reader }
    }

    pub fn send_raw(&mut self, bytes: &[u8]) -> Answer {
        self.writer.write_all(bytes).expect("write");
        read_answer(&mut self.reader)
    }

    pub fn post(&mut self, path: &str, body: &str) -> Answer {
        let request = format!(
            "POST {path} HTTP/1.1\r\nHost: test\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
            body.len()
        );
        self.send_raw(request.as_bytes())
    }

    pub fn get(&mut self, path: &str) -> Answer {
        self.send_raw(format!("GET {path} HTTP/1.1\r\nHost: test\r\n\r\n").as_bytes())
    }
}

/// One request on a new connection.
pub fn post(address: SocketAddr, path: &str, body: &str) -> Answer {
    Connection::open(address).post(path, body)
}

/// The interpreter for the Python interoperability tests: `IUQ_PYTHON`, else `python3`; `None`
/// (with the reason printed) when it cannot import `umbridge`.
pub fn python_with_umbridge() -> Option<String> {
    let python = std::env::var("IUQ_PYTHON").unwrap_or_else(|_| "python3".into());
    let ok = std::process::Command::new(&python)
        .args(["-c", "import umbridge"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .map(|s| s.success())
        .unwrap_or(false);
    if ok {
        Some(python)
    } else {
        eprintln!(
            "SKIPPED: `{python}` cannot import the Python package `umbridge` (install it with `{python} -m pip install umbridge`, or point IUQ_PYTHON at an interpreter that has it)"
        );
        None
    }
}

/// A port that was free a moment ago on 127.0.0.1.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}
