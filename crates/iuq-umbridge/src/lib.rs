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
//!
//! # Example
//!
//! Serve a formula on a free local port and evaluate it through the client: the client is an
//! [`iuq_core::Model`] whose answers equal the model's own, bit for bit.
//!
//! ```
//! use std::sync::Arc;
//! use iuq_core::{ExpressionModel, Model};
//! use iuq_umbridge::{ClientOptions, ServedModel, Server, ServerOptions, UmBridgeModel};
//!
//! let names = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
//! let decay = ExpressionModel::new(names(&["a", "k"]), &[("y".into(), "a * exp(-k)".into())])?;
//! let server = Server::bind(
//!     vec![ServedModel::new("decay", Arc::new(decay.clone()))],
//!     "127.0.0.1:0",
//!     ServerOptions::default(),
//! )?
//! .spawn()?;
//! let client = UmBridgeModel::connect(&server.url(), "decay", names(&["a", "k"]),
//!                                     ClientOptions::default())?;
//! let points = vec![vec![2.0, 0.5], vec![1.0, 0.0]];
//! let remote = client.evaluate_batch(&points)?;
//! assert_eq!(remote, decay.evaluate_batch(&points)?);
//! assert_eq!(remote[1].as_ref().map(|e| e.outputs[0]).ok(), Some(1.0));
//! server.shutdown();
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]
// No panic reachable from user input: a library reports every failure in its error type.
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

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
