//! The UM-Bridge client: a model on a UM-Bridge server, usable wherever a [`Model`] is.
//!
//! [`UmBridgeModel::connect`] asks the server for its protocol version (`/Info`; anything but
//! 1.0 is refused with [`UmBridgeError::UnsupportedProtocolVersion`]), checks that it serves the
//! model and that the model supports `Evaluate` (`/ModelInfo`), and reads its input and output
//! sizes for the configured `config`. The caller's parameter vector (d values) is split into
//! the model's input vectors in order, so the input sizes must add up to d; the output vectors
//! are concatenated into the model's outputs.
//!
//! A batch is evaluated as one `/Evaluate` per point — the protocol has no batch request — with
//! up to [`ClientOptions::concurrency`] requests in flight, over kept-alive connections. Per
//! point:
//! - 200 with an `output` of the declared sizes → an [`iuq_core::Evaluation`] (with
//!   [`ClientOptions::std_output`], the second output vector is its computational std);
//! - 500 (any error object, or none: a server whose model raised) → a per-point
//!   [`EvaluationFailure`] carrying the server's message; an answer that is not valid JSON of
//!   the declared sizes (e.g. a Python server printing `NaN`) likewise;
//! - 400 `InvalidInput` → a per-point failure (the server refused this input);
//! - a lost connection, a refused connection, or 502/503/504 (a restarting server or a load
//!   balancer without a free model) → reconnect and retry, up to [`ClientOptions::retries`]
//!   times with exponential backoff from [`ClientOptions::retry_delay`] (capped at
//!   [`ClientOptions::max_retry_delay`]); when the retries are spent the whole batch fails with
//!   [`iuq_core::CoreError::ModelUnavailable`];
//! - any other status (404, 413, `ModelNotFound`…) fails the whole batch: the server is not
//!   what the client connected to.
//!
//! There is no read timeout by default: a model run may take hours, and the request waits for
//! it ([`ClientOptions::read_timeout`] sets one; a run that exceeds it is a per-point failure).

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Duration;

use serde_json::Value;

use iuq_core::model::reject_non_finite;
use iuq_core::{CoreError, Evaluation, EvaluationFailure, Model, Outcome};

use crate::error::{Result, UmBridgeError};
use crate::protocol::{self, EVALUATE, INFO, INPUT_SIZES, Info, MODEL_INFO, OUTPUT_SIZES, Support};

/// How the client talks to the server.
#[derive(Debug, Clone, PartialEq)]
pub struct ClientOptions {
    /// The model-specific `config` JSON sent with every request (default `{}`).
    pub config: Value,
    /// Names of the outputs (default: the model name for a single output, else
    /// `<name>_1 … <name>_m`). With [`ClientOptions::std_output`], names of the first output
    /// vector only.
    pub output_names: Option<Vec<String>>,
    /// The model answers two output vectors of equal size: the outputs and their computational
    /// standard deviations (an iuq server does with `config = {"computational_std": true}`).
    pub std_output: bool,
    /// `/Evaluate` requests in flight at once when a batch is evaluated (default 4).
    pub concurrency: usize,
    /// Retries of a request after a lost or refused connection or a 502/503/504 (default 5).
    pub retries: u32,
    /// Wait before the first retry; doubled after every further one (default 1 s).
    pub retry_delay: Duration,
    /// The longest wait between two retries (default 60 s).
    pub max_retry_delay: Duration,
    /// Time allowed to open a connection (default 30 s).
    pub connect_timeout: Duration,
    /// Time allowed for the server to answer a request, model run included (default: none).
    pub read_timeout: Option<Duration>,
    /// The largest answer body read (default 64 MiB).
    pub max_response_bytes: u64,
}

impl Default for ClientOptions {
    fn default() -> Self {
        Self {
            config: Value::Object(serde_json::Map::new()),
            output_names: None,
            std_output: false,
            concurrency: 4,
            retries: 5,
            retry_delay: Duration::from_secs(1),
            max_retry_delay: Duration::from_secs(60),
            connect_timeout: Duration::from_secs(30),
            read_timeout: None,
            max_response_bytes: 64 << 20,
        }
    }
}

/// A model on a UM-Bridge server (protocol 1.0); implements [`Model`].
pub struct UmBridgeModel {
    url: String,
    name: String,
    options: ClientOptions,
    agent: ureq::Agent,
    support: Support,
    input_sizes: Vec<usize>,
    output_sizes: Vec<usize>,
    input_names: Vec<String>,
    output_names: Vec<String>,
}

impl std::fmt::Debug for UmBridgeModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("UmBridgeModel")
            .field("url", &self.url)
            .field("name", &self.name)
            .field("input_sizes", &self.input_sizes)
            .field("output_sizes", &self.output_sizes)
            .field("options", &self.options)
            .finish_non_exhaustive()
    }
}

/// A transport failure worth a retry, or an answer.
enum Exchange {
    Answer { status: u16, body: String },
    Transient(String),
}

/// Checks `http://host[:port][/prefix]` and returns it without a trailing `/`.
fn normalise_url(url: &str) -> Result<String> {
    let invalid = |reason: &str| UmBridgeError::InvalidUrl {
        url: url.to_string(),
        reason: reason.to_string(),
    };
    let trimmed = url.trim();
    let Some(rest) = trimmed.strip_prefix("http://") else {
        if trimmed.starts_with("https://") {
            return Err(invalid(
                "https is not supported (UM-Bridge servers speak plain HTTP; use an SSH tunnel or a proxy)",
            ));
        }
        return Err(invalid("expected http://host:port"));
    };
    let host = rest.split('/').next().unwrap_or("");
    if host.is_empty() || host.contains(char::is_whitespace) || host.contains('@') {
        return Err(invalid("expected http://host:port"));
    }
    Ok(trimmed.trim_end_matches('/').to_string())
}

impl UmBridgeModel {
    /// Connects to model `name` on the server at `url` (`http://host:port`) for a parameter
    /// vector with the given `input_names`.
    ///
    /// # Errors
    /// A bad URL or options, an unreachable server (after the retries), a protocol version
    /// other than 1.0, an unknown model, a model without `Evaluate`, input sizes that do not
    /// add up to `input_names.len()`, output names that do not match the output sizes.
    pub fn connect(
        url: &str,
        name: &str,
        input_names: Vec<String>,
        options: ClientOptions,
    ) -> Result<Self> {
        let url = normalise_url(url)?;
        if options.concurrency == 0 {
            return Err(UmBridgeError::InvalidOptions(
                "concurrency must be at least 1".into(),
            ));
        }
        let agent: ureq::Agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .timeout_connect(Some(options.connect_timeout))
            .timeout_recv_response(options.read_timeout)
            .timeout_recv_body(options.read_timeout)
            .max_idle_connections(options.concurrency.max(4))
            .max_idle_connections_per_host(options.concurrency.max(4))
            .build()
            .into();
        let mut model = Self {
            url,
            name: name.to_string(),
            options,
            agent,
            support: Support::default(),
            input_sizes: Vec::new(),
            output_sizes: Vec::new(),
            input_names,
            output_names: Vec::new(),
        };
        model.handshake()?;
        Ok(model)
    }

    fn handshake(&mut self) -> Result<()> {
        let body = self.expect_ok(INFO, None)?;
        let info = Info::from_json(&body).map_err(|reason| self.invalid(INFO, reason))?;
        if !info.is_supported_version() {
            return Err(UmBridgeError::UnsupportedProtocolVersion {
                url: self.url.clone(),
                found: info
                    .protocol_version
                    .as_ref()
                    .map_or_else(|| "none".to_string(), Value::to_string),
            });
        }
        if !info.models.contains(&self.name) {
            return Err(UmBridgeError::ModelNotFound {
                url: self.url.clone(),
                name: self.name.clone(),
                available: info.models,
            });
        }
        let body = self.expect_ok(MODEL_INFO, Some(protocol::model_info_request(&self.name)))?;
        self.support = Support::from_json(&body).map_err(|r| self.invalid(MODEL_INFO, r))?;
        if !self.support.evaluate {
            return Err(UmBridgeError::UnsupportedFeature {
                name: self.name.clone(),
                feature: "Evaluate".into(),
            });
        }
        let request = protocol::sizes_request(&self.name, &self.options.config);
        let body = self.expect_ok(INPUT_SIZES, Some(request.clone()))?;
        self.input_sizes =
            protocol::parse_sizes(&body, "inputSizes").map_err(|r| self.invalid(INPUT_SIZES, r))?;
        let body = self.expect_ok(OUTPUT_SIZES, Some(request))?;
        self.output_sizes = protocol::parse_sizes(&body, "outputSizes")
            .map_err(|r| self.invalid(OUTPUT_SIZES, r))?;

        let mismatch = |reason: String| UmBridgeError::SizeMismatch {
            name: self.name.clone(),
            reason,
        };
        let d: usize = self.input_sizes.iter().sum();
        if d != self.input_names.len() {
            return Err(mismatch(format!(
                "its input sizes {:?} add up to {d} values, but {} parameters are given ({})",
                self.input_sizes,
                self.input_names.len(),
                self.input_names.join(", ")
            )));
        }
        let m = if self.options.std_output {
            match self.output_sizes.as_slice() {
                [a, b] if a == b => *a,
                other => {
                    return Err(mismatch(format!(
                        "std_output needs two output vectors of equal size (outputs and their stds), the model has output sizes {other:?}"
                    )));
                }
            }
        } else {
            self.output_sizes.iter().sum()
        };
        if m == 0 {
            return Err(mismatch("the model has no outputs".into()));
        }
        self.output_names = match &self.options.output_names {
            Some(names) if names.len() != m => {
                return Err(mismatch(format!(
                    "{} output names are given for {m} outputs (output sizes {:?})",
                    names.len(),
                    self.output_sizes
                )));
            }
            Some(names) => names.clone(),
            None if m == 1 => vec![self.name.clone()],
            None => (1..=m).map(|j| format!("{}_{j}", self.name)).collect(),
        };
        Ok(())
    }

    fn invalid(&self, endpoint: &str, reason: String) -> UmBridgeError {
        UmBridgeError::InvalidResponse {
            endpoint: format!("{}{endpoint}", self.url),
            reason,
        }
    }

    /// The server's URL.
    pub fn url(&self) -> &str {
        &self.url
    }

    /// The model's name on the server.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The options the client was connected with.
    pub fn options(&self) -> &ClientOptions {
        &self.options
    }

    /// The features the model supports (`/ModelInfo`).
    pub fn support(&self) -> Support {
        self.support
    }

    /// The model's input sizes for the configured `config`.
    pub fn input_sizes(&self) -> &[usize] {
        &self.input_sizes
    }

    /// The model's output sizes for the configured `config`.
    pub fn output_sizes(&self) -> &[usize] {
        &self.output_sizes
    }

    /// One request, without retries.
    fn exchange_once(&self, endpoint: &str, body: Option<&str>) -> Result<Exchange> {
        let url = format!("{}{endpoint}", self.url);
        let sent = match body {
            None => self.agent.get(&url).call(),
            Some(body) => self
                .agent
                .post(&url)
                .header("Content-Type", "application/json")
                .send(body),
        };
        let response = match sent {
            Ok(response) => response,
            Err(e) => return self.classify(endpoint, e),
        };
        let status = response.status().as_u16();
        let read = response
            .into_body()
            .with_config()
            .limit(self.options.max_response_bytes)
            .read_to_string();
        match read {
            Ok(body) => Ok(Exchange::Answer { status, body }),
            Err(e) => self.classify(endpoint, e),
        }
    }

    /// Transport errors: a lost/refused connection is transient, a timeout waiting for the
    /// answer is reported as such, the rest is an invalid answer.
    fn classify(&self, endpoint: &str, error: ureq::Error) -> Result<Exchange> {
        use ureq::Timeout;
        match error {
            ureq::Error::Io(_)
            | ureq::Error::ConnectionFailed
            | ureq::Error::HostNotFound
            | ureq::Error::Protocol(_)
            | ureq::Error::Timeout(
                Timeout::Connect | Timeout::Resolve | Timeout::SendRequest | Timeout::SendBody,
            ) => Ok(Exchange::Transient(error.to_string())),
            ureq::Error::Timeout(_) => Ok(Exchange::Answer {
                status: 0,
                body: format!(
                    "no answer within the read timeout of {:?}",
                    self.options.read_timeout.unwrap_or_default()
                ),
            }),
            ureq::Error::BadUri(reason) => Err(UmBridgeError::InvalidUrl {
                url: self.url.clone(),
                reason,
            }),
            other => Err(self.invalid(endpoint, other.to_string())),
        }
    }

    /// A request with reconnects and retries: transient failures and 502/503/504 are retried
    /// with exponential backoff; the answer (any other status) is returned.
    fn exchange(&self, endpoint: &str, body: Option<&str>) -> Result<(u16, String)> {
        let mut delay = self.options.retry_delay;
        let mut attempt = 0u32;
        loop {
            attempt += 1;
            let last_reason = match self.exchange_once(endpoint, body)? {
                Exchange::Answer { status, body } if !matches!(status, 502..=504) => {
                    return Ok((status, body));
                }
                Exchange::Answer { status, body } => format!(
                    "HTTP {status}: {}",
                    protocol::parse_error_object(&body)
                        .map_or_else(|| snippet(&body), |(t, m)| format!("{t}: {m}"))
                ),
                Exchange::Transient(reason) => reason,
            };
            if attempt > self.options.retries {
                return Err(UmBridgeError::Unreachable {
                    url: self.url.clone(),
                    attempts: attempt,
                    reason: last_reason,
                });
            }
            std::thread::sleep(delay);
            delay = delay.saturating_mul(2).min(self.options.max_retry_delay);
        }
    }

    /// A request whose answer must be 200; another status is an error with the server's
    /// error object.
    fn expect_ok(&self, endpoint: &str, body: Option<String>) -> Result<String> {
        let (status, text) = self.exchange(endpoint, body.as_deref())?;
        if status == 200 {
            return Ok(text);
        }
        Err(self.server_error(endpoint, status, &text))
    }

    fn server_error(&self, endpoint: &str, status: u16, body: &str) -> UmBridgeError {
        let (error_type, message) = protocol::parse_error_object(body)
            .unwrap_or_else(|| ("HTTP".to_string(), snippet(body)));
        if error_type == "ModelNotFound" {
            return UmBridgeError::ModelNotFound {
                url: self.url.clone(),
                name: self.name.clone(),
                available: Vec::new(),
            };
        }
        UmBridgeError::Server {
            endpoint: format!("{}{endpoint}", self.url),
            status,
            error_type,
            message,
        }
    }

    /// The caller's parameter vector split into the model's input vectors.
    fn split_input(&self, x: &[f64]) -> Vec<Vec<f64>> {
        let mut start = 0;
        self.input_sizes
            .iter()
            .map(|&size| {
                let end = (start + size).min(x.len());
                let part = x[start.min(end)..end].to_vec();
                start = end;
                part
            })
            .collect()
    }

    fn check_point(&self, x: &[f64]) -> Result<()> {
        if x.len() != self.input_names.len() {
            return Err(UmBridgeError::SizeMismatch {
                name: self.name.clone(),
                reason: format!(
                    "a point has {} values, the model takes {}",
                    x.len(),
                    self.input_names.len()
                ),
            });
        }
        Ok(())
    }

    /// Evaluates the model at one point: the outcome (a per-point failure included), or an
    /// error when the server cannot be used (unreachable after the retries, an unexpected
    /// status).
    ///
    /// # Errors
    /// A point of the wrong length; the server unreachable; an answer other than 200, 400
    /// `InvalidInput` or 5xx.
    pub fn evaluate(&self, x: &[f64]) -> Result<Outcome> {
        self.check_point(x)?;
        let body =
            protocol::evaluate_request(&self.name, &self.split_input(x), &self.options.config);
        let (status, text) = self.exchange(EVALUATE, Some(&body))?;
        let failure = |reason: String| Ok(Err(EvaluationFailure::new(reason)));
        match status {
            200 => match self.read_outputs(&text) {
                Ok(evaluation) => Ok(reject_non_finite(Ok(evaluation))),
                Err(reason) => failure(format!(
                    "UM-Bridge model `{}` answered an invalid output: {reason}",
                    self.name
                )),
            },
            0 => failure(text),
            400 => match protocol::parse_error_object(&text) {
                Some((t, m)) if t == "InvalidInput" => {
                    failure(format!("UM-Bridge server refused the input: {t}: {m}"))
                }
                _ => Err(self.server_error(EVALUATE, status, &text)),
            },
            500..=599 => failure(match protocol::parse_error_object(&text) {
                Some((t, m)) => format!("UM-Bridge model `{}` failed ({t}): {m}", self.name),
                None => format!(
                    "UM-Bridge model `{}` failed (HTTP {status}): {}",
                    self.name,
                    snippet(&text)
                ),
            }),
            _ => Err(self.server_error(EVALUATE, status, &text)),
        }
    }

    fn read_outputs(&self, body: &str) -> std::result::Result<Evaluation, String> {
        let mut output = protocol::parse_output_lists(body)?;
        protocol::check_sizes(&output, &self.output_sizes, "output")?;
        if self.options.std_output {
            let std = output.pop().unwrap_or_default();
            let values = output.pop().unwrap_or_default();
            Ok(Evaluation::with_std(values, std))
        } else {
            Ok(Evaluation::new(output.concat()))
        }
    }

    /// sensᵀ·∂output_{out_wrt}/∂input_{in_wrt} at `x` (`/Gradient`).
    ///
    /// # Errors
    /// The model has no gradient; wrong sizes; the server fails or answers an error.
    pub fn gradient(
        &self,
        out_wrt: usize,
        in_wrt: usize,
        x: &[f64],
        sens: &[f64],
    ) -> Result<Vec<f64>> {
        if !self.support.gradient {
            return Err(UmBridgeError::UnsupportedFeature {
                name: self.name.clone(),
                feature: "Gradient".into(),
            });
        }
        self.check_point(x)?;
        let body = protocol::gradient_request(
            &self.name,
            out_wrt,
            in_wrt,
            &self.split_input(x),
            sens,
            &self.options.config,
        );
        self.vector_answer(protocol::GRADIENT, &body)
    }

    /// ∂output_{out_wrt}/∂input_{in_wrt}·vec at `x` (`/ApplyJacobian`).
    ///
    /// # Errors
    /// The model has no Jacobian action; wrong sizes; the server fails or answers an error.
    pub fn apply_jacobian(
        &self,
        out_wrt: usize,
        in_wrt: usize,
        x: &[f64],
        vec: &[f64],
    ) -> Result<Vec<f64>> {
        if !self.support.apply_jacobian {
            return Err(UmBridgeError::UnsupportedFeature {
                name: self.name.clone(),
                feature: "ApplyJacobian".into(),
            });
        }
        self.check_point(x)?;
        let body = protocol::apply_jacobian_request(
            &self.name,
            out_wrt,
            in_wrt,
            &self.split_input(x),
            vec,
            &self.options.config,
        );
        self.vector_answer(protocol::APPLY_JACOBIAN, &body)
    }

    fn vector_answer(&self, endpoint: &str, body: &str) -> Result<Vec<f64>> {
        let text = self.expect_ok(endpoint, Some(body.to_string()))?;
        protocol::parse_output_vector(&text).map_err(|reason| self.invalid(endpoint, reason))
    }
}

/// Outcomes of one request thread, with the indices of their points.
type Evaluated = Vec<(usize, Result<Outcome>)>;

/// The start of a body, for messages.
fn snippet(body: &str) -> String {
    let text = body.trim();
    match text.char_indices().nth(200) {
        Some((cut, _)) => format!("{}…", &text[..cut]),
        None => text.to_string(),
    }
}

impl Model for UmBridgeModel {
    fn input_names(&self) -> &[String] {
        &self.input_names
    }

    fn output_names(&self) -> &[String] {
        &self.output_names
    }

    /// One `/Evaluate` per point, [`ClientOptions::concurrency`] at a time; outcomes in order.
    fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
        let d = self.input_names.len();
        if let Some(p) = points.iter().find(|p| p.len() != d) {
            return Err(CoreError::DimensionMismatch {
                expected: d,
                actual: p.len(),
            });
        }
        let n = points.len();
        let workers = self.options.concurrency.min(n);
        if workers <= 1 {
            return points
                .iter()
                .map(|p| self.evaluate(p))
                .collect::<Result<Vec<_>>>()
                .map_err(|e| CoreError::ModelUnavailable(e.to_string()));
        }
        let next = AtomicUsize::new(0);
        let stop = AtomicBool::new(false);
        let worker = || {
            let mut done: Evaluated = Vec::new();
            while !stop.load(Ordering::SeqCst) {
                let i = next.fetch_add(1, Ordering::SeqCst);
                if i >= n {
                    break;
                }
                let result = self.evaluate(&points[i]);
                if result.is_err() {
                    stop.store(true, Ordering::SeqCst);
                }
                done.push((i, result));
            }
            done
        };
        let mut slots: Vec<Option<Outcome>> = vec![None; n];
        let mut first_error: Option<(usize, UmBridgeError)> = None;
        let joined: Vec<std::thread::Result<Evaluated>> = std::thread::scope(|scope| {
            // Threads the system refuses are simply not used; with none, this thread works.
            let handles: Vec<_> = (0..workers)
                .filter_map(|_| {
                    std::thread::Builder::new()
                        .name("umbridge-request".into())
                        .spawn_scoped(scope, worker)
                        .ok()
                })
                .collect();
            if handles.is_empty() {
                return vec![Ok(worker())];
            }
            handles.into_iter().map(|h| h.join()).collect()
        });
        for part in joined {
            let part = part.map_err(|_| {
                CoreError::ModelUnavailable("a UM-Bridge request thread panicked".into())
            })?;
            for (i, result) in part {
                match result {
                    Ok(outcome) => slots[i] = Some(outcome),
                    Err(e) => {
                        if first_error.as_ref().is_none_or(|(j, _)| i < *j) {
                            first_error = Some((i, e));
                        }
                    }
                }
            }
        }
        if let Some((_, e)) = first_error {
            return Err(CoreError::ModelUnavailable(e.to_string()));
        }
        slots
            .into_iter()
            .map(|slot| {
                slot.ok_or_else(|| {
                    CoreError::ModelUnavailable("a point of the batch was not evaluated".into())
                })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urls_are_checked() {
        assert_eq!(
            normalise_url("http://127.0.0.1:4242/").unwrap(),
            "http://127.0.0.1:4242"
        );
        assert_eq!(normalise_url(" http://host ").unwrap(), "http://host");
        assert!(
            normalise_url("https://host")
                .unwrap_err()
                .to_string()
                .contains("https")
        );
        assert!(normalise_url("localhost:4242").is_err());
        assert!(normalise_url("http://").is_err());
        assert!(normalise_url("http://user@host").is_err());
    }

    #[test]
    fn defaults_have_no_read_timeout_and_bounded_retries() {
        let o = ClientOptions::default();
        assert_eq!(o.read_timeout, None);
        assert!(o.retries > 0 && o.concurrency > 0);
        assert_eq!(o.config, serde_json::json!({}));
    }

    #[test]
    fn snippets_are_cut_on_character_boundaries() {
        let long = "é".repeat(300);
        let s = snippet(&long);
        assert!(s.ends_with('…') && s.chars().count() == 201);
    }
}
