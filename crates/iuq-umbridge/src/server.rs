//! The UM-Bridge server: serves any [`Model`] (with an optional [`Jacobian`]) over HTTP.
//!
//! Each served model has one input vector (the model's d inputs, in
//! [`Model::input_names`] order) and one output vector (its m outputs): input sizes `[d]`,
//! output sizes `[m]`. With `config = {"computational_std": true}` the output sizes are
//! `[m, m]` and `/Evaluate` answers the computational standard deviation of each output as the
//! second vector (an error if the model reports none). A model with a [`Jacobian`] supports
//! `/Gradient` and `/ApplyJacobian` of its first output vector; `/ApplyHessian` is not
//! supported. A model may come with a cheaper twin for requests that do not ask for the std
//! ([`ServedModel::with_values_only`], e.g. a GP bank's means without its variances).
//!
//! One thread per connection (HTTP/1.1 keep-alive), at most
//! [`ServerOptions::max_connections`] at once. At most [`ServerOptions::parallel`] model calls
//! run at any time (`/Evaluate`, `/Gradient`, `/ApplyJacobian`); each call evaluates one point,
//! or — for a model with a [`ServedModel::with_batch_limit`] above 1 — the `/Evaluate` points
//! of every request then waiting for that model, up to the limit, as one batch (results are the
//! same as point by point; a GP bank answers many concurrent clients for the price of few
//! calls). `/Info` and the size queries are answered at once. A request
//! that is bad in any way gets an error object and the server keeps serving: malformed JSON,
//! missing keys, wrong sizes and unknown models are 400, an oversized body 413 (the connection
//! is then closed without reading the body), a failed model run 500 with
//! [`ErrorType::ModelError`], a panic inside the model 500 as well.

use std::collections::HashMap;
use std::io::{BufReader, Read};
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, Shutdown, SocketAddr, TcpListener, TcpStream};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serde_json::{Map, Value};

use iuq_core::{EvaluationFailure, Model, Outcome};

use crate::batching::{Scheduler, lock};
use crate::error::{Result, UmBridgeError};
use crate::http::{self, Incoming, Limits};
use crate::protocol::{
    self, APPLY_HESSIAN, APPLY_JACOBIAN, COMPUTATIONAL_STD_KEY, EVALUATE, ErrorAnswer, ErrorType,
    GRADIENT, INFO, INPUT_SIZES, MODEL_INFO, OUTPUT_SIZES, Support,
};

/// The Jacobian of a model's outputs with respect to its inputs, for `/Gradient` and
/// `/ApplyJacobian`.
pub trait Jacobian: Send + Sync {
    /// ∂outputᵢ/∂inputₖ at `x` (one row per output, in [`Model::output_names`] order; one
    /// column per input), or why it cannot be computed there.
    fn jacobian(&self, x: &[f64]) -> std::result::Result<Vec<Vec<f64>>, EvaluationFailure>;
}

/// A model served under a name.
#[derive(Clone)]
pub struct ServedModel {
    name: String,
    model: Arc<dyn Model>,
    jacobian: Option<Arc<dyn Jacobian>>,
    values_only: Option<Arc<dyn Model>>,
    batch_limit: usize,
}

impl std::fmt::Debug for ServedModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ServedModel")
            .field("name", &self.name)
            .field("inputs", &self.model.input_names())
            .field("outputs", &self.model.output_names())
            .field("jacobian", &self.jacobian.is_some())
            .field("batch_limit", &self.batch_limit)
            .finish()
    }
}

impl ServedModel {
    /// `model` served as `name` (Evaluate only).
    pub fn new(name: impl Into<String>, model: Arc<dyn Model>) -> Self {
        Self {
            name: name.into(),
            model,
            jacobian: None,
            values_only: None,
            batch_limit: 1,
        }
    }

    /// The same model with concurrent `/Evaluate` requests evaluated together, up to `limit`
    /// points per call of the model (default 1: one point per call). Worth it for a model whose
    /// batches cost little more than one point (a GP bank, an expression); a limit of 0 counts
    /// as 1.
    pub fn with_batch_limit(mut self, limit: usize) -> Self {
        self.batch_limit = limit.max(1);
        self
    }

    /// The same model with a cheaper twin that gives the same outputs without their
    /// computational std (e.g. a GP bank's means without the variances), used for `/Evaluate`
    /// requests that do not ask for the std. It must have the same inputs and outputs.
    pub fn with_values_only(mut self, model: Arc<dyn Model>) -> Self {
        self.values_only = Some(model);
        self
    }

    /// The most points evaluated in one call of the model.
    pub fn batch_limit(&self) -> usize {
        self.batch_limit
    }

    /// The same model with `/Gradient` and `/ApplyJacobian` computed from `jacobian`.
    pub fn with_jacobian(mut self, jacobian: Arc<dyn Jacobian>) -> Self {
        self.jacobian = Some(jacobian);
        self
    }

    /// The name the model is served under.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The model.
    pub fn model(&self) -> &Arc<dyn Model> {
        &self.model
    }

    /// The features `/ModelInfo` reports.
    pub fn support(&self) -> Support {
        Support {
            evaluate: true,
            gradient: self.jacobian.is_some(),
            apply_jacobian: self.jacobian.is_some(),
            apply_hessian: false,
        }
    }
}

/// Settings of a [`Server`].
#[derive(Debug, Clone)]
pub struct ServerOptions {
    /// Model calls running at the same time, all models together (default: the number of
    /// CPUs). With the default batch limit of 1, the number of points evaluated at once.
    pub parallel: usize,
    /// The largest request body accepted; larger ones are answered with 413 (default 16 MiB).
    pub max_body_bytes: usize,
    /// The largest request head (request line and headers) accepted (default 64 KiB).
    pub max_head_bytes: usize,
    /// Open connections at most; more are answered with 503 `ServerBusy` (default 1024).
    pub max_connections: usize,
    /// How long a connection may stay silent between or inside requests before the server
    /// closes it (default 120 s; a model call is not limited).
    pub idle_timeout: Duration,
    /// How long writing a response may block (default 60 s).
    pub write_timeout: Duration,
    /// Print one line per request on stderr (method, path, status, time).
    pub log_requests: bool,
}

impl Default for ServerOptions {
    fn default() -> Self {
        Self {
            parallel: std::thread::available_parallelism().map_or(1, |n| n.get()),
            max_body_bytes: 16 << 20,
            max_head_bytes: 64 << 10,
            max_connections: 1024,
            idle_timeout: Duration::from_secs(120),
            write_timeout: Duration::from_secs(60),
            log_requests: false,
        }
    }
}

/// State shared by the accepting thread and the connections.
struct Shared {
    models: Vec<ServedModel>,
    options: ServerOptions,
    scheduler: Scheduler<std::result::Result<Outcome, ErrorAnswer>>,
    stopping: AtomicBool,
    connections: Mutex<HashMap<u64, TcpStream>>,
    next_connection: AtomicU64,
    open: AtomicUsize,
}

/// A UM-Bridge server bound to an address, not yet serving.
pub struct Server {
    listener: TcpListener,
    address: SocketAddr,
    shared: Arc<Shared>,
}

impl std::fmt::Debug for Server {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Server")
            .field("address", &self.address)
            .field("models", &self.shared.models)
            .finish()
    }
}

impl Server {
    /// Binds a server for `models` to `address` (e.g. `"127.0.0.1:4242"`; port 0 picks a free
    /// port, see [`Server::local_addr`]).
    ///
    /// # Errors
    /// No models, a duplicate or empty name, zero `parallel`/`max_body_bytes`/`max_connections`
    /// ([`UmBridgeError::InvalidOptions`]), or an address that cannot be bound
    /// ([`UmBridgeError::Listen`]).
    pub fn bind(models: Vec<ServedModel>, address: &str, options: ServerOptions) -> Result<Self> {
        if models.is_empty() {
            return Err(UmBridgeError::InvalidOptions(
                "a server needs at least one model".into(),
            ));
        }
        for (i, m) in models.iter().enumerate() {
            if m.name.is_empty() {
                return Err(UmBridgeError::InvalidOptions(
                    "a model name must not be empty".into(),
                ));
            }
            if models[..i].iter().any(|other| other.name == m.name) {
                return Err(UmBridgeError::InvalidOptions(format!(
                    "two models are named `{}`",
                    m.name
                )));
            }
        }
        if options.parallel == 0 || options.max_body_bytes == 0 || options.max_connections == 0 {
            return Err(UmBridgeError::InvalidOptions(
                "parallel, max_body_bytes and max_connections must be at least 1".into(),
            ));
        }
        let listen_error = |reason: String| UmBridgeError::Listen {
            address: address.to_string(),
            reason,
        };
        let listener = TcpListener::bind(address).map_err(|e| listen_error(e.to_string()))?;
        let bound = listener
            .local_addr()
            .map_err(|e| listen_error(e.to_string()))?;
        Ok(Self {
            listener,
            address: bound,
            shared: Arc::new(Shared {
                // One queue per model and kind of request (with or without the std).
                scheduler: Scheduler::new(options.parallel, 2 * models.len()),
                models,
                options,
                stopping: AtomicBool::new(false),
                connections: Mutex::new(HashMap::new()),
                next_connection: AtomicU64::new(0),
                open: AtomicUsize::new(0),
            }),
        })
    }

    /// The address the server listens on (with the actual port when bound to port 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.address
    }

    /// `http://host:port` of the server (a wildcard address is written as the loopback).
    pub fn url(&self) -> String {
        url_of(reachable(self.address))
    }

    /// The served models.
    pub fn models(&self) -> &[ServedModel] {
        &self.shared.models
    }

    /// Serves until [`ServerHandle::shutdown`] (for a spawned server); for a server run in the
    /// foreground this returns only when accepting connections fails for good.
    ///
    /// # Errors
    /// [`UmBridgeError::Listen`] when the listening socket fails persistently.
    pub fn run(self) -> Result<()> {
        let mut consecutive_errors = 0u32;
        for stream in self.listener.incoming() {
            if self.shared.stopping.load(Ordering::SeqCst) {
                break;
            }
            match stream {
                Ok(stream) => {
                    consecutive_errors = 0;
                    accept(&self.shared, stream);
                }
                Err(e) => {
                    // Out of file descriptors or a connection reset before accept: wait and
                    // go on; give up only if accepting keeps failing for a long time.
                    consecutive_errors += 1;
                    if consecutive_errors > 10_000 {
                        return Err(UmBridgeError::Listen {
                            address: self.address.to_string(),
                            reason: e.to_string(),
                        });
                    }
                    std::thread::sleep(Duration::from_millis(10));
                }
            }
        }
        Ok(())
    }

    /// Serves on a background thread; the handle stops the server when shut down or dropped.
    ///
    /// # Errors
    /// [`UmBridgeError::Listen`] if the thread cannot be started.
    pub fn spawn(self) -> Result<ServerHandle> {
        let address = self.address;
        let shared = Arc::clone(&self.shared);
        let thread = std::thread::Builder::new()
            .name("umbridge-accept".into())
            .spawn(move || self.run())
            .map_err(|e| UmBridgeError::Listen {
                address: address.to_string(),
                reason: e.to_string(),
            })?;
        Ok(ServerHandle {
            address,
            shared,
            thread: Some(thread),
        })
    }
}

/// A server serving on a background thread ([`Server::spawn`]).
#[derive(Debug)]
pub struct ServerHandle {
    address: SocketAddr,
    shared: Arc<Shared>,
    thread: Option<JoinHandle<Result<()>>>,
}

impl std::fmt::Debug for Shared {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Shared")
            .field("models", &self.models)
            .field("options", &self.options)
            .finish_non_exhaustive()
    }
}

impl ServerHandle {
    /// The address the server listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.address
    }

    /// `http://host:port` of the server.
    pub fn url(&self) -> String {
        url_of(reachable(self.address))
    }

    /// Stops accepting, closes every open connection (requests in flight get no answer) and
    /// waits for the accepting thread. Model calls already running finish in the background.
    pub fn shutdown(mut self) {
        self.stop();
    }

    fn stop(&mut self) {
        self.shared.stopping.store(true, Ordering::SeqCst);
        // Wake the accepting thread.
        let _ = TcpStream::connect_timeout(&reachable(self.address), Duration::from_secs(1));
        for (_, stream) in lock(&self.shared.connections).drain() {
            let _ = stream.shutdown(Shutdown::Both);
        }
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

impl Drop for ServerHandle {
    fn drop(&mut self) {
        if self.thread.is_some() {
            self.stop();
        }
    }
}

/// A connectable form of a listening address (the loopback for a wildcard).
fn reachable(address: SocketAddr) -> SocketAddr {
    match address.ip() {
        IpAddr::V4(ip) if ip.is_unspecified() => {
            SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), address.port())
        }
        IpAddr::V6(ip) if ip.is_unspecified() => {
            SocketAddr::new(IpAddr::V6(Ipv6Addr::LOCALHOST), address.port())
        }
        _ => address,
    }
}

fn url_of(address: SocketAddr) -> String {
    format!("http://{address}")
}

/// Starts a thread for a new connection, or answers 503 when there are too many.
fn accept(shared: &Arc<Shared>, stream: TcpStream) {
    let _ = stream.set_write_timeout(Some(shared.options.write_timeout));
    if shared.open.load(Ordering::SeqCst) >= shared.options.max_connections {
        let busy = ErrorAnswer::new(
            ErrorType::ServerBusy,
            format!(
                "the server has {} open connections; try again later",
                shared.options.max_connections
            ),
        );
        let mut stream = stream;
        let _ = http::write_response(&mut stream, busy.status, &busy.to_json(), false);
        return;
    }
    let id = shared.next_connection.fetch_add(1, Ordering::SeqCst);
    if let Ok(registered) = stream.try_clone() {
        lock(&shared.connections).insert(id, registered);
    }
    shared.open.fetch_add(1, Ordering::SeqCst);
    let worker = Arc::clone(shared);
    let spawned = std::thread::Builder::new()
        .name("umbridge-connection".into())
        .spawn(move || {
            serve_connection(&worker, stream);
            lock(&worker.connections).remove(&id);
            worker.open.fetch_sub(1, Ordering::SeqCst);
        });
    if spawned.is_err() {
        // The stream was moved into the closure and dropped with it: the connection is closed.
        lock(&shared.connections).remove(&id);
        shared.open.fetch_sub(1, Ordering::SeqCst);
    }
}

/// Answers requests on one connection until the client closes it, it stays idle too long, a
/// request is refused, or the server stops.
fn serve_connection(shared: &Shared, stream: TcpStream) {
    let _ = stream.set_nodelay(true);
    let _ = stream.set_read_timeout(Some(shared.options.idle_timeout));
    let Ok(read_half) = stream.try_clone() else {
        return;
    };
    let mut reader = BufReader::new(read_half);
    let mut writer = stream;
    let limits = Limits {
        max_head_bytes: shared.options.max_head_bytes,
        max_body_bytes: shared.options.max_body_bytes,
    };
    loop {
        if shared.stopping.load(Ordering::SeqCst) {
            return;
        }
        match http::read_request(&mut reader, &mut writer, &limits) {
            Ok(Incoming::Request(request)) => {
                let started = Instant::now();
                let (status, body) = route(shared, &request);
                let keep_alive = request.keep_alive && !shared.stopping.load(Ordering::SeqCst);
                if shared.options.log_requests {
                    eprintln!(
                        "umbridge: {} {} -> {status} ({:.1} ms)",
                        request.method,
                        request.path,
                        started.elapsed().as_secs_f64() * 1e3
                    );
                }
                if http::write_response(&mut writer, status, &body, keep_alive).is_err()
                    || !keep_alive
                {
                    return;
                }
            }
            Ok(Incoming::Closed) | Err(_) => return,
            Ok(Incoming::Refused(error)) => {
                if shared.options.log_requests {
                    eprintln!(
                        "umbridge: refused request -> {}: {}",
                        error.status, error.message
                    );
                }
                if http::write_response(&mut writer, error.status, &error.to_json(), false).is_ok()
                {
                    linger(&mut writer, &mut reader);
                }
                return;
            }
        }
    }
}

/// Closes a connection whose request was refused unread so that the client can still read the
/// answer: stop writing, then discard what the client is still sending for a short while
/// (closing with unread data would reset the connection and could destroy the answer).
fn linger(writer: &mut TcpStream, reader: &mut BufReader<TcpStream>) {
    let _ = writer.shutdown(Shutdown::Write);
    let _ = writer.set_read_timeout(Some(Duration::from_millis(200)));
    let deadline = Instant::now() + Duration::from_secs(2);
    let mut budget: usize = 8 << 20;
    let mut buffer = [0u8; 16 << 10];
    while budget > 0 && Instant::now() < deadline {
        match reader.read(&mut buffer) {
            Ok(0) | Err(_) => break,
            Ok(n) => budget = budget.saturating_sub(n),
        }
    }
}

/// The answer (status, JSON body) to a request.
fn route(shared: &Shared, request: &http::Request) -> (u16, String) {
    let method = request.method.as_str();
    let path = request.path.as_str();
    let body = &request.body;
    let result = match (method, path) {
        ("GET" | "POST", INFO) => Ok(protocol::info_json(
            shared.models.iter().map(|m| m.name.as_str()),
        )),
        ("POST", MODEL_INFO) => model_info(shared, body),
        ("POST", INPUT_SIZES) => sizes(shared, body, true),
        ("POST", OUTPUT_SIZES) => sizes(shared, body, false),
        ("POST", EVALUATE) => evaluate(shared, body),
        ("POST", GRADIENT) => derivative(shared, body, Derivative::Gradient),
        ("POST", APPLY_JACOBIAN) => derivative(shared, body, Derivative::ApplyJacobian),
        ("POST", APPLY_HESSIAN) => apply_hessian(shared, body),
        (
            _,
            INFO | MODEL_INFO | INPUT_SIZES | OUTPUT_SIZES | EVALUATE | GRADIENT | APPLY_JACOBIAN
            | APPLY_HESSIAN,
        ) => Err(ErrorAnswer::invalid_input(format!(
            "method {method} is not allowed on {path} (use {})",
            if path == INFO { "GET" } else { "POST" }
        ))
        .with_status(405)),
        _ => Err(ErrorAnswer::new(
            ErrorType::UnsupportedFeature,
            format!("this server has no endpoint {path}"),
        )
        .with_status(404)),
    };
    match result {
        Ok(body) => (200, body),
        Err(error) => (error.status, error.to_json()),
    }
}

/// The served model a request names, with its index.
fn find<'a>(
    shared: &'a Shared,
    object: &Map<String, Value>,
) -> Result<(usize, &'a ServedModel), ErrorAnswer> {
    let name = protocol::model_name(object)?;
    shared
        .models
        .iter()
        .enumerate()
        .find(|(_, m)| m.name == name)
        .ok_or_else(|| {
            ErrorAnswer::new(
                ErrorType::ModelNotFound,
                format!(
                    "Model `{name}` not found! The following are available: {:?}.",
                    shared
                        .models
                        .iter()
                        .map(|m| m.name.as_str())
                        .collect::<Vec<_>>()
                ),
            )
        })
}

/// Whether the request's config asks for the computational std as a second output vector.
fn wants_std(config: &Value) -> Result<bool, ErrorAnswer> {
    match config {
        Value::Null => Ok(false),
        Value::Object(map) => match map.get(COMPUTATIONAL_STD_KEY) {
            None | Some(Value::Null) => Ok(false),
            Some(Value::Bool(b)) => Ok(*b),
            Some(other) => Err(ErrorAnswer::invalid_input(format!(
                "config key `{COMPUTATIONAL_STD_KEY}` must be true or false, got {other}"
            ))),
        },
        other => Err(ErrorAnswer::invalid_input(format!(
            "`config` must be a JSON object, got {other}"
        ))),
    }
}

fn output_sizes(model: &ServedModel, with_std: bool) -> Vec<usize> {
    let m = model.model.output_dimension();
    if with_std { vec![m, m] } else { vec![m] }
}

fn model_info(shared: &Shared, body: &[u8]) -> Result<String, ErrorAnswer> {
    let object = protocol::parse_object(body)?;
    Ok(find(shared, &object)?.1.support().to_json())
}

fn sizes(shared: &Shared, body: &[u8], input: bool) -> Result<String, ErrorAnswer> {
    let object = protocol::parse_object(body)?;
    let (_, served) = find(shared, &object)?;
    let with_std = wants_std(protocol::config(&object))?;
    Ok(if input {
        protocol::sizes_json("inputSizes", &[served.model.input_dimension()])
    } else {
        protocol::sizes_json("outputSizes", &output_sizes(served, with_std))
    })
}

/// The single input vector of a request, checked against the model's input size.
fn input_point(object: &Map<String, Value>, served: &ServedModel) -> Result<Vec<f64>, ErrorAnswer> {
    let input = protocol::vector_list(protocol::required(object, "input")?, "input")?;
    protocol::check_sizes(&input, &[served.model.input_dimension()], "input")
        .map_err(ErrorAnswer::invalid_input)?;
    Ok(input.into_iter().next().unwrap_or_default())
}

fn panic_message(panic: &(dyn std::any::Any + Send)) -> String {
    panic
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "no message".into())
}

/// Runs `call` holding the capacity of one point, turning a panic into a 500 error object.
fn call_model<T>(shared: &Shared, name: &str, call: impl FnOnce() -> T) -> Result<T, ErrorAnswer> {
    shared
        .scheduler
        .with_one(|| catch_unwind(AssertUnwindSafe(call)))
        .map_err(|panic| {
            ErrorAnswer::new(
                ErrorType::ModelError,
                format!("model `{name}` panicked: {}", panic_message(panic.as_ref())),
            )
        })
}

/// Evaluates a batch: one outcome (or error answer) per point. A batch that panics is
/// evaluated again point by point, so that only the points that panic fail.
fn run_batch(
    name: &str,
    model: &dyn Model,
    points: &[Vec<f64>],
) -> Vec<std::result::Result<Outcome, ErrorAnswer>> {
    let n = points.len();
    match catch_unwind(AssertUnwindSafe(|| model.evaluate_batch(points))) {
        Ok(Ok(outcomes)) if outcomes.len() == n => outcomes.into_iter().map(Ok).collect(),
        Ok(Ok(outcomes)) => {
            let error = ErrorAnswer::new(
                ErrorType::InvalidOutput,
                format!(
                    "model `{name}` returned {} outcomes for {n} points",
                    outcomes.len()
                ),
            );
            vec![Err(error); n]
        }
        Ok(Err(e)) => {
            let error = ErrorAnswer::new(ErrorType::ModelError, format!("model `{name}`: {e}"));
            vec![Err(error); n]
        }
        Err(_) if n > 1 => points
            .iter()
            .flat_map(|p| run_batch(name, model, std::slice::from_ref(p)))
            .collect(),
        Err(panic) => vec![Err(ErrorAnswer::new(
            ErrorType::ModelError,
            format!("model `{name}` panicked: {}", panic_message(panic.as_ref())),
        ))],
    }
}

fn non_finite(served: &ServedModel, what: &str, values: &[f64]) -> Result<(), ErrorAnswer> {
    if let Some(k) = values.iter().position(|v| !v.is_finite()) {
        let output = served
            .model
            .output_names()
            .get(k)
            .map_or_else(|| k.to_string(), |n| format!("`{n}`"));
        return Err(ErrorAnswer::new(
            ErrorType::InvalidOutput,
            format!(
                "{what} of output {output} is {} (JSON cannot carry non-finite numbers)",
                values[k]
            ),
        ));
    }
    Ok(())
}

fn evaluate(shared: &Shared, body: &[u8]) -> Result<String, ErrorAnswer> {
    let object = protocol::parse_object(body)?;
    let (index, served) = find(shared, &object)?;
    let with_std = wants_std(protocol::config(&object))?;
    let x = input_point(&object, served)?;
    let name = served.name.as_str();
    // Without the std, the cheaper twin (if any) answers; each kind has its own queue.
    let model = match (&served.values_only, with_std) {
        (Some(values), false) => values,
        _ => &served.model,
    };
    let queue = 2 * index + usize::from(with_std);
    let outcome = shared
        .scheduler
        .evaluate(queue, served.batch_limit, x, |points| {
            run_batch(name, model.as_ref(), points)
        })?;
    let evaluation = outcome.map_err(|failure| {
        ErrorAnswer::new(
            ErrorType::ModelError,
            format!("model `{name}` failed at this input: {}", failure.reason),
        )
    })?;
    let m = served.model.output_dimension();
    if evaluation.outputs.len() != m {
        return Err(ErrorAnswer::new(
            ErrorType::InvalidOutput,
            format!(
                "model `{name}` declared {m} outputs but returned {}",
                evaluation.outputs.len()
            ),
        ));
    }
    non_finite(served, "the value", &evaluation.outputs)?;
    let mut output = vec![evaluation.outputs];
    if with_std {
        let std = evaluation.computational_std.ok_or_else(|| {
            ErrorAnswer::new(
                ErrorType::InvalidOutput,
                format!("model `{name}` reports no computational std at this input"),
            )
        })?;
        if std.len() != m {
            return Err(ErrorAnswer::new(
                ErrorType::InvalidOutput,
                format!("model `{name}` returned {} stds for {m} outputs", std.len()),
            ));
        }
        non_finite(served, "the std", &std)?;
        output.push(std);
    }
    Ok(protocol::output_lists_json(&output))
}

#[derive(Clone, Copy)]
enum Derivative {
    Gradient,
    ApplyJacobian,
}

fn derivative(shared: &Shared, body: &[u8], kind: Derivative) -> Result<String, ErrorAnswer> {
    let object = protocol::parse_object(body)?;
    let (_, served) = find(shared, &object)?;
    let feature = match kind {
        Derivative::Gradient => "Gradient",
        Derivative::ApplyJacobian => "ApplyJacobian",
    };
    let name = served.name.as_str();
    let Some(jacobian) = &served.jacobian else {
        return Err(ErrorAnswer::new(
            ErrorType::UnsupportedFeature,
            format!("{feature} is not supported by model `{name}`"),
        ));
    };
    let with_std = wants_std(protocol::config(&object))?;
    let in_wrt = protocol::index(&object, "inWrt")?;
    let out_wrt = protocol::index(&object, "outWrt")?;
    if in_wrt != 0 {
        return Err(ErrorAnswer::invalid_input(format!(
            "Invalid inWrt index! Expected 0 (the model has one input vector) but got {in_wrt}"
        )));
    }
    let outputs = output_sizes(served, with_std).len();
    if out_wrt >= outputs {
        return Err(ErrorAnswer::invalid_input(format!(
            "Invalid outWrt index! Expected between 0 and {} but got {out_wrt}",
            outputs - 1
        )));
    }
    if out_wrt == 1 {
        return Err(ErrorAnswer::new(
            ErrorType::UnsupportedFeature,
            format!("{feature} of the computational std is not supported by model `{name}`"),
        ));
    }
    let x = input_point(&object, served)?;
    let d = served.model.input_dimension();
    let m = served.model.output_dimension();
    let (key, expected) = match kind {
        Derivative::Gradient => ("sens", m),
        Derivative::ApplyJacobian => ("vec", d),
    };
    let weights = protocol::number_vector(protocol::required(&object, key)?, key)?;
    if weights.len() != expected {
        return Err(ErrorAnswer::invalid_input(format!(
            "Vector `{key}` has invalid length! Expected {expected} but got {}.",
            weights.len()
        )));
    }
    let rows = call_model(shared, name, || jacobian.jacobian(&x))?.map_err(|failure| {
        ErrorAnswer::new(
            ErrorType::ModelError,
            format!(
                "the Jacobian of model `{name}` failed at this input: {}",
                failure.reason
            ),
        )
    })?;
    if rows.len() != m || rows.iter().any(|r| r.len() != d) {
        return Err(ErrorAnswer::new(
            ErrorType::InvalidOutput,
            format!("the Jacobian of model `{name}` is not {m}×{d}"),
        ));
    }
    let output: Vec<f64> = match kind {
        Derivative::Gradient => (0..d)
            .map(|k| rows.iter().zip(&weights).map(|(row, s)| s * row[k]).sum())
            .collect(),
        Derivative::ApplyJacobian => rows
            .iter()
            .map(|row| row.iter().zip(&weights).map(|(j, v)| j * v).sum())
            .collect(),
    };
    if output.iter().any(|v| !v.is_finite()) {
        return Err(ErrorAnswer::new(
            ErrorType::InvalidOutput,
            format!("the {feature} of model `{name}` is not finite at this input"),
        ));
    }
    Ok(protocol::output_vector_json(&output))
}

fn apply_hessian(shared: &Shared, body: &[u8]) -> Result<String, ErrorAnswer> {
    let object = protocol::parse_object(body)?;
    let (_, served) = find(shared, &object)?;
    Err(ErrorAnswer::new(
        ErrorType::UnsupportedFeature,
        format!("ApplyHessian is not supported by model `{}`", served.name),
    ))
}
