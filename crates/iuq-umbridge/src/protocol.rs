//! The UM-Bridge 1.0 protocol: endpoints, JSON bodies, error objects and status codes.
//!
//! A UM-Bridge model maps a list of input vectors to a list of output vectors (sizes from
//! `/InputSizes` and `/OutputSizes`). Every body is JSON:
//!
//! | endpoint | method | request | answer |
//! |---|---|---|---|
//! | `/Info` | GET | – | `{"protocolVersion": 1.0, "models": [names]}` |
//! | `/ModelInfo` | POST | `{"name"}` | `{"support": {"Evaluate", "Gradient", "ApplyJacobian", "ApplyHessian"}}` |
//! | `/InputSizes` | POST | `{"name", "config"}` | `{"inputSizes": [sizes]}` |
//! | `/OutputSizes` | POST | `{"name", "config"}` | `{"outputSizes": [sizes]}` |
//! | `/Evaluate` | POST | `{"name", "input": [[…]…], "config"}` | `{"output": [[…]…]}` |
//! | `/Gradient` | POST | `{"name", "outWrt", "inWrt", "input", "sens", "config"}` | `{"output": […]}` = sensᵀ·∂output_outWrt/∂input_inWrt |
//! | `/ApplyJacobian` | POST | `{"name", "outWrt", "inWrt", "input", "vec", "config"}` | `{"output": […]}` = ∂output_outWrt/∂input_inWrt·vec |
//! | `/ApplyHessian` | POST | `{"name", "outWrt", "inWrt1", "inWrt2", "input", "sens", "vec", "config"}` | `{"output": […]}` |
//!
//! `config` is optional everywhere (model-specific JSON). There is no batch endpoint: one
//! `/Evaluate` carries one parameter point, so a batch is many requests.
//!
//! Errors are answered as `{"error": {"type": T, "message": M}}` with status 400 for errors of
//! the client and 500 for errors of the model side. The protocol names four types
//! ([`ErrorType::InvalidInput`], [`ErrorType::InvalidOutput`], [`ErrorType::ModelNotFound`],
//! [`ErrorType::UnsupportedFeature`]); this crate adds [`ErrorType::ModelError`] (the model
//! produced no output at this input: a failed run, status 500) and [`ErrorType::ServerBusy`]
//! (status 503, too many connections), which clients treat like any other error object.

use serde_json::{Map, Value, json};

/// The protocol version this crate speaks, answered by `/Info` as a JSON number.
pub const PROTOCOL_VERSION: f64 = 1.0;

/// The most input or output values a model may declare in all its vectors together (2²⁴): every
/// value is a parameter or a data point of a study, and a server declaring more is taken to be
/// broken rather than allocated for.
pub const MAX_VALUES: usize = 1 << 24;

/// `GET /Info`: protocol version and model names.
pub const INFO: &str = "/Info";
/// `POST /ModelInfo`: the features a model supports.
pub const MODEL_INFO: &str = "/ModelInfo";
/// `POST /InputSizes`: the sizes of the input vectors.
pub const INPUT_SIZES: &str = "/InputSizes";
/// `POST /OutputSizes`: the sizes of the output vectors.
pub const OUTPUT_SIZES: &str = "/OutputSizes";
/// `POST /Evaluate`: the outputs at one parameter point.
pub const EVALUATE: &str = "/Evaluate";
/// `POST /Gradient`: sensᵀ·J.
pub const GRADIENT: &str = "/Gradient";
/// `POST /ApplyJacobian`: J·vec.
pub const APPLY_JACOBIAN: &str = "/ApplyJacobian";
/// `POST /ApplyHessian`: the action of the Hessian of sensᵀ·output.
pub const APPLY_HESSIAN: &str = "/ApplyHessian";

/// The `config` key (an extension of this crate's server) that asks for the computational
/// standard deviation as a second output vector: with `{"computational_std": true}` a model of
/// m outputs has output sizes `[m, m]`, the second vector being the std of each output.
pub const COMPUTATIONAL_STD_KEY: &str = "computational_std";

/// The `type` of an error object.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ErrorType {
    /// The request does not match the model's dimensions or is otherwise invalid (malformed
    /// JSON, a missing key, an oversized body). Status 400 (413 for an oversized body).
    InvalidInput,
    /// The model delivered an output that does not match its declared sizes, or one JSON cannot
    /// carry (NaN, ±∞). Status 500.
    InvalidOutput,
    /// No model of that name on this server. Status 400.
    ModelNotFound,
    /// The model does not support the requested feature (or the endpoint does not exist).
    /// Status 400 (404 for an unknown endpoint).
    UnsupportedFeature,
    /// Extension: the model ran but produced no output at this input (a failed run, with its
    /// reason). Status 500.
    ModelError,
    /// Extension: the server has too many open connections. Status 503.
    ServerBusy,
}

impl ErrorType {
    /// The name written in the error object.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::InvalidInput => "InvalidInput",
            Self::InvalidOutput => "InvalidOutput",
            Self::ModelNotFound => "ModelNotFound",
            Self::UnsupportedFeature => "UnsupportedFeature",
            Self::ModelError => "ModelError",
            Self::ServerBusy => "ServerBusy",
        }
    }

    /// The HTTP status this crate's server answers the type with (by default).
    pub fn status(self) -> u16 {
        match self {
            Self::InvalidInput | Self::ModelNotFound | Self::UnsupportedFeature => 400,
            Self::InvalidOutput | Self::ModelError => 500,
            Self::ServerBusy => 503,
        }
    }
}

impl std::fmt::Display for ErrorType {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// An error answer: the HTTP status and the error object's type and message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ErrorAnswer {
    /// The HTTP status code.
    pub status: u16,
    /// The error type.
    pub error_type: ErrorType,
    /// A human-readable message.
    pub message: String,
}

impl ErrorAnswer {
    /// An error with the type's default status.
    pub fn new(error_type: ErrorType, message: impl Into<String>) -> Self {
        Self {
            status: error_type.status(),
            error_type,
            message: message.into(),
        }
    }

    /// The same error with another HTTP status.
    pub fn with_status(mut self, status: u16) -> Self {
        self.status = status;
        self
    }

    /// Shorthand for an [`ErrorType::InvalidInput`] error.
    pub fn invalid_input(message: impl Into<String>) -> Self {
        Self::new(ErrorType::InvalidInput, message)
    }

    /// The error object `{"error": {"type": …, "message": …}}` as JSON text.
    pub fn to_json(&self) -> String {
        error_object(self.error_type.as_str(), &self.message)
    }
}

/// The error object `{"error": {"type": error_type, "message": message}}` as JSON text.
pub fn error_object(error_type: &str, message: &str) -> String {
    json!({"error": {"type": error_type, "message": message}}).to_string()
}

/// The `(type, message)` of an error object, if `body` is one.
pub fn parse_error_object(body: &str) -> Option<(String, String)> {
    let value: Value = serde_json::from_str(body).ok()?;
    let error = value.get("error")?;
    let error_type = error.get("type")?.as_str()?.to_string();
    let message = match error.get("message") {
        Some(Value::String(s)) => s.clone(),
        Some(other) => other.to_string(),
        None => String::new(),
    };
    Some((error_type, message))
}

/// Which optional endpoints a model supports (the `support` object of `/ModelInfo`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Support {
    /// `/Evaluate`.
    pub evaluate: bool,
    /// `/Gradient`.
    pub gradient: bool,
    /// `/ApplyJacobian`.
    pub apply_jacobian: bool,
    /// `/ApplyHessian`.
    pub apply_hessian: bool,
}

impl Support {
    /// The `/ModelInfo` answer.
    pub fn to_json(self) -> String {
        json!({"support": {
            "Evaluate": self.evaluate,
            "Gradient": self.gradient,
            "ApplyJacobian": self.apply_jacobian,
            "ApplyHessian": self.apply_hessian,
        }})
        .to_string()
    }

    /// Reads a `/ModelInfo` answer (missing features count as unsupported).
    pub fn from_json(body: &str) -> Result<Self, String> {
        let value: Value = serde_json::from_str(body).map_err(|e| format!("not JSON ({e})"))?;
        let support = value
            .get("support")
            .and_then(Value::as_object)
            .ok_or("no `support` object")?;
        let flag = |key: &str| support.get(key).and_then(Value::as_bool).unwrap_or(false);
        Ok(Self {
            evaluate: flag("Evaluate"),
            gradient: flag("Gradient"),
            apply_jacobian: flag("ApplyJacobian"),
            apply_hessian: flag("ApplyHessian"),
        })
    }
}

/// The `/Info` answer for the given model names.
pub fn info_json<'a>(models: impl IntoIterator<Item = &'a str>) -> String {
    json!({
        "protocolVersion": PROTOCOL_VERSION,
        "models": models.into_iter().collect::<Vec<_>>(),
    })
    .to_string()
}

/// The server's `/Info` answer as read by a client.
#[derive(Debug, Clone, PartialEq)]
pub struct Info {
    /// `protocolVersion` as written (a number in protocol 1.0; `None` when absent).
    pub protocol_version: Option<Value>,
    /// The model names.
    pub models: Vec<String>,
}

impl Info {
    /// Reads an `/Info` answer.
    pub fn from_json(body: &str) -> Result<Self, String> {
        let value: Value = serde_json::from_str(body).map_err(|e| format!("not JSON ({e})"))?;
        let object = value.as_object().ok_or("not a JSON object")?;
        let models = match object.get("models") {
            Some(Value::Array(names)) => names
                .iter()
                .map(|n| {
                    n.as_str()
                        .map(str::to_string)
                        .ok_or_else(|| format!("model name {n} is not a string"))
                })
                .collect::<Result<Vec<_>, _>>()?,
            Some(_) => return Err("`models` is not an array".into()),
            None => Vec::new(),
        };
        Ok(Self {
            protocol_version: object.get("protocolVersion").cloned(),
            models,
        })
    }

    /// True when the server speaks protocol 1.0 (the number 1.0, or the string "1.0").
    pub fn is_supported_version(&self) -> bool {
        match &self.protocol_version {
            Some(Value::Number(n)) => n.as_f64() == Some(PROTOCOL_VERSION),
            Some(Value::String(s)) => s.trim().parse::<f64>().ok() == Some(PROTOCOL_VERSION),
            _ => false,
        }
    }
}

/// The `/InputSizes` or `/OutputSizes` answer: `{key: sizes}`.
pub fn sizes_json(key: &str, sizes: &[usize]) -> String {
    let mut object = Map::new();
    object.insert(key.to_string(), json!(sizes));
    Value::Object(object).to_string()
}

/// Reads the sizes under `key` (`inputSizes` or `outputSizes`) of an answer.
pub fn parse_sizes(body: &str, key: &str) -> Result<Vec<usize>, String> {
    let value: Value = serde_json::from_str(body).map_err(|e| format!("not JSON ({e})"))?;
    let sizes = value
        .get(key)
        .and_then(Value::as_array)
        .ok_or_else(|| format!("no `{key}` array"))?;
    let sizes: Vec<usize> = sizes
        .iter()
        .map(|s| {
            s.as_u64()
                .and_then(|s| usize::try_from(s).ok())
                .ok_or_else(|| format!("`{key}` entry {s} is not a size"))
        })
        .collect::<Result<_, _>>()?;
    match sizes
        .iter()
        .try_fold(0usize, |total, &s| total.checked_add(s))
    {
        Some(total) if total <= MAX_VALUES => Ok(sizes),
        _ => Err(format!(
            "`{key}` {sizes:?} add up to more than the {MAX_VALUES} values iuq accepts"
        )),
    }
}

/// The body of a `/ModelInfo` request.
pub fn model_info_request(name: &str) -> String {
    json!({"name": name}).to_string()
}

/// The body of an `/InputSizes` or `/OutputSizes` request.
pub fn sizes_request(name: &str, config: &Value) -> String {
    json!({"name": name, "config": config}).to_string()
}

/// The body of an `/Evaluate` request.
pub fn evaluate_request(name: &str, input: &[Vec<f64>], config: &Value) -> String {
    json!({"name": name, "input": input, "config": config}).to_string()
}

/// The body of a `/Gradient` request.
pub fn gradient_request(
    name: &str,
    out_wrt: usize,
    in_wrt: usize,
    input: &[Vec<f64>],
    sens: &[f64],
    config: &Value,
) -> String {
    json!({"name": name, "outWrt": out_wrt, "inWrt": in_wrt, "input": input, "sens": sens,
           "config": config})
    .to_string()
}

/// The body of an `/ApplyJacobian` request.
pub fn apply_jacobian_request(
    name: &str,
    out_wrt: usize,
    in_wrt: usize,
    input: &[Vec<f64>],
    vec: &[f64],
    config: &Value,
) -> String {
    json!({"name": name, "outWrt": out_wrt, "inWrt": in_wrt, "input": input, "vec": vec,
           "config": config})
    .to_string()
}

/// `{"output": [[…], …]}`: the answer of `/Evaluate`.
pub fn output_lists_json(output: &[Vec<f64>]) -> String {
    json!({ "output": output }).to_string()
}

/// `{"output": […]}`: the answer of `/Gradient`, `/ApplyJacobian`, `/ApplyHessian`.
pub fn output_vector_json(output: &[f64]) -> String {
    json!({ "output": output }).to_string()
}

/// Reads the `output` list of vectors of an `/Evaluate` answer.
pub fn parse_output_lists(body: &str) -> Result<Vec<Vec<f64>>, String> {
    let value: Value = serde_json::from_str(body).map_err(|e| format!("not JSON ({e})"))?;
    let output = value.get("output").ok_or("no `output` key")?;
    vector_list(output, "output").map_err(|e| e.message)
}

/// Reads the `output` vector of a `/Gradient` or `/ApplyJacobian` answer.
pub fn parse_output_vector(body: &str) -> Result<Vec<f64>, String> {
    let value: Value = serde_json::from_str(body).map_err(|e| format!("not JSON ({e})"))?;
    let output = value.get("output").ok_or("no `output` key")?;
    number_vector(output, "output").map_err(|e| e.message)
}

/// A request body parsed as a JSON object, or an [`ErrorType::InvalidInput`] error.
pub fn parse_object(body: &[u8]) -> Result<Map<String, Value>, ErrorAnswer> {
    let value: Value = serde_json::from_slice(body)
        .map_err(|e| ErrorAnswer::invalid_input(format!("malformed JSON body: {e}")))?;
    match value {
        Value::Object(object) => Ok(object),
        other => Err(ErrorAnswer::invalid_input(format!(
            "the body must be a JSON object, got {}",
            kind_of(&other)
        ))),
    }
}

fn kind_of(value: &Value) -> &'static str {
    match value {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    }
}

/// The value of a required key.
pub fn required<'a>(object: &'a Map<String, Value>, key: &str) -> Result<&'a Value, ErrorAnswer> {
    object
        .get(key)
        .ok_or_else(|| ErrorAnswer::invalid_input(format!("missing key `{key}`")))
}

/// The string `name` of a request.
pub fn model_name(object: &Map<String, Value>) -> Result<&str, ErrorAnswer> {
    required(object, "name")?
        .as_str()
        .ok_or_else(|| ErrorAnswer::invalid_input("key `name` must be a string"))
}

/// The `config` of a request (`null` when absent).
pub fn config(object: &Map<String, Value>) -> &Value {
    object.get("config").unwrap_or(&Value::Null)
}

/// A non-negative integer index (`outWrt`, `inWrt`); integral floats such as `0.0` are accepted.
pub fn index(object: &Map<String, Value>, key: &str) -> Result<usize, ErrorAnswer> {
    let value = required(object, key)?;
    let invalid = || {
        ErrorAnswer::invalid_input(format!(
            "key `{key}` must be a non-negative integer, got {value}"
        ))
    };
    if let Some(i) = value.as_u64() {
        return usize::try_from(i).map_err(|_| invalid());
    }
    match value.as_f64() {
        Some(f) if f >= 0.0 && f.fract() == 0.0 && f < 1e15 => Ok(f as usize),
        _ => Err(invalid()),
    }
}

/// A vector of numbers.
pub fn number_vector(value: &Value, key: &str) -> Result<Vec<f64>, ErrorAnswer> {
    let items = value.as_array().ok_or_else(|| {
        ErrorAnswer::invalid_input(format!(
            "`{key}` must be an array of numbers, got {}",
            kind_of(value)
        ))
    })?;
    items
        .iter()
        .enumerate()
        .map(|(i, v)| {
            v.as_f64().ok_or_else(|| {
                ErrorAnswer::invalid_input(format!(
                    "`{key}[{i}]` must be a number, got {}",
                    kind_of(v)
                ))
            })
        })
        .collect()
}

/// A list of vectors of numbers (`input`, `output`).
pub fn vector_list(value: &Value, key: &str) -> Result<Vec<Vec<f64>>, ErrorAnswer> {
    let items = value.as_array().ok_or_else(|| {
        ErrorAnswer::invalid_input(format!(
            "`{key}` must be a list of vectors (array of arrays of numbers), got {}",
            kind_of(value)
        ))
    })?;
    items
        .iter()
        .enumerate()
        .map(|(i, v)| number_vector(v, &format!("{key}[{i}]")))
        .collect()
}

/// Checks a list of vectors against declared sizes; the message follows the reference
/// implementations ("Input parameter 0 has invalid length! Expected 3 but got 2.").
pub fn check_sizes(vectors: &[Vec<f64>], sizes: &[usize], what: &str) -> Result<(), String> {
    if vectors.len() != sizes.len() {
        return Err(format!(
            "Number of {what} vectors does not match the model: expected {} but got {}.",
            sizes.len(),
            vectors.len()
        ));
    }
    for (i, (v, &size)) in vectors.iter().zip(sizes).enumerate() {
        if v.len() != size {
            return Err(format!(
                "{} {i} has invalid length! Expected {size} but got {}.",
                if what == "input" {
                    "Input parameter"
                } else {
                    "Output vector"
                },
                v.len()
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn info_reports_version_as_a_number() {
        let body = info_json(["a", "b"]);
        let value: Value = serde_json::from_str(&body).unwrap();
        assert!(value["protocolVersion"].is_f64());
        assert_eq!(value["protocolVersion"].as_f64(), Some(1.0));
        let info = Info::from_json(&body).unwrap();
        assert!(info.is_supported_version());
        assert_eq!(info.models, vec!["a", "b"]);
        let old = Info::from_json(r#"{"protocolVersion": 0.9, "models": []}"#).unwrap();
        assert!(!old.is_supported_version());
        assert!(
            !Info::from_json(r#"{"models": []}"#)
                .unwrap()
                .is_supported_version()
        );
        assert!(
            Info::from_json(r#"{"protocolVersion": "1.0"}"#)
                .unwrap()
                .is_supported_version()
        );
    }

    #[test]
    fn error_objects_round_trip() {
        let e = ErrorAnswer::new(ErrorType::ModelNotFound, "no model `x`");
        assert_eq!(e.status, 400);
        assert_eq!(
            parse_error_object(&e.to_json()),
            Some(("ModelNotFound".into(), "no model `x`".into()))
        );
        assert_eq!(parse_error_object("500 Internal Server Error"), None);
        assert_eq!(ErrorType::ModelError.status(), 500);
    }

    #[test]
    fn requests_are_validated_with_protocol_errors() {
        assert!(parse_object(b"{not json").is_err());
        assert!(parse_object(b"[1, 2]").is_err());
        let o = parse_object(br#"{"name": 3, "outWrt": 1.0, "inWrt": -1, "input": [[1, "a"]]}"#)
            .unwrap();
        assert!(model_name(&o).is_err());
        assert_eq!(index(&o, "outWrt").unwrap(), 1);
        assert!(index(&o, "inWrt").is_err());
        assert!(index(&o, "missing").is_err());
        let e = vector_list(&o["input"], "input").unwrap_err();
        assert_eq!(e.error_type, ErrorType::InvalidInput);
        assert!(e.message.contains("input[0][1]"), "{}", e.message);
        assert!(
            check_sizes(&[vec![1.0, 2.0]], &[3], "input")
                .unwrap_err()
                .contains("Expected 3 but got 2")
        );
        assert!(check_sizes(&[vec![1.0], vec![2.0]], &[1], "input").is_err());
        assert!(check_sizes(&[vec![1.0, 2.0]], &[2], "input").is_ok());
    }

    #[test]
    fn floats_cross_the_wire_exactly() {
        let x = vec![vec![
            0.1,
            1.0 / 3.0,
            -2.5e-300,
            123456789.12345679,
            f64::MAX,
        ]];
        let body = output_lists_json(&x);
        assert_eq!(parse_output_lists(&body).unwrap(), x);
        let support = Support {
            evaluate: true,
            gradient: true,
            ..Default::default()
        };
        assert_eq!(Support::from_json(&support.to_json()).unwrap(), support);
        assert_eq!(
            parse_sizes(&sizes_json("inputSizes", &[3, 1]), "inputSizes").unwrap(),
            vec![3, 1]
        );
        assert!(parse_sizes(r#"{"inputSizes": [-1]}"#, "inputSizes").is_err());
    }
}
