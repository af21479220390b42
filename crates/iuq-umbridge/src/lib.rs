//! UM-Bridge 1.0 for iuq, in both directions.
//!
//! [UM-Bridge](https://um-bridge-benchmarks.readthedocs.io) is the HTTP interface between UQ
//! tools and simulation models (MUQ, PyMC, emcee, QMCPy clients; HPC load balancers). This
//! crate makes iuq a part of it:
//!
//! - [`Server`] serves any [`iuq_core::Model`] (an expression, a GP bank, the cell model, a
//!   log-posterior…) under a name, with `/Gradient` and `/ApplyJacobian` when a [`Jacobian`]
//!   is given, a bounded number of model calls at once and, for cheap models, concurrent
//!   requests grouped into one batch ([`server`]);
//! - [`UmBridgeModel`] is a model on any UM-Bridge server, itself an [`iuq_core::Model`], so
//!   sensitivity analysis, BASIS and surrogate training can use it ([`client`]);
//! - [`protocol`] holds the endpoints, the JSON bodies and the error objects.
//!
//! | status | error type | when |
//! |---|---|---|
//! | 400 | `InvalidInput` | malformed JSON, a missing key, a vector of the wrong size |
//! | 400 | `ModelNotFound` | no model of that name |
//! | 400 | `UnsupportedFeature` | `/Gradient` of a model without Jacobian, `/ApplyHessian` |
//! | 404 | `UnsupportedFeature` | an unknown endpoint |
//! | 405 | `InvalidInput` | a known endpoint with the wrong method |
//! | 413 | `InvalidInput` | a body over the size limit (the connection is then closed) |
//! | 431 | `InvalidInput` | a request head over the size limit |
//! | 500 | `ModelError` | the model failed at this input (the reason is the message) |
//! | 500 | `InvalidOutput` | an output of the wrong size, or NaN/±∞ (JSON has no such numbers) |
//! | 503 | `ServerBusy` | too many open connections |
//!
//! Dependencies, chosen for a blocking, thread-per-evaluation design that compiles in seconds:
//! the client uses `ureq` (blocking HTTP/1.1 with a connection pool, built without TLS or
//! compression); the server parses requests with `httparse` (hyper's parser, no dependencies)
//! and does the framing itself (`http.rs`) — hyper or axum would bring an async runtime for
//! nothing, and tiny_http cannot refuse an oversized body safely (it drains the unread rest of
//! a body by allocating a buffer of the whole declared length, so one forged `Content-Length`
//! aborts the process). Both speak plain HTTP only.
//!
//! The crate does no other I/O than its sockets and never panics on network input.

#![warn(missing_docs)]

mod batching;
pub mod client;
pub mod error;
mod http;
pub mod protocol;
pub mod server;

pub use client::{ClientOptions, UmBridgeModel};
pub use error::{Result, UmBridgeError};
pub use protocol::{ErrorAnswer, ErrorType, PROTOCOL_VERSION, Support};
pub use server::{Jacobian, ServedModel, Server, ServerHandle, ServerOptions};
