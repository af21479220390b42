//! `iuq serve umbridge STUDY`: serve a study's model and its log-posterior over UM-Bridge 1.0.
//!
//! Two models are served (`/Info` lists them):
//! - `<study name>`: the study's `[model]` (expression, rbc-shear, umbridge), or with
//!   `--surrogate FILE` a fitted GP (a file of `iuq gp fit`, or a GP bank JSON such as
//!   `iuq bench basis-gp-bank --out` writes) whose inputs are the study's parameters. Input
//!   sizes `[d]` (the parameters in file order), output sizes `[m]`; with
//!   `config = {"computational_std": true}`, `[m, m]` with the computational std (a GP's
//!   predictive std) as the second vector. A GP surrogate also answers `/Gradient` and
//!   `/ApplyJacobian` with the exact derivative of its posterior mean.
//! - `<study name>-posterior`: the log-posterior ln p(θ) + ln f(D | θ) of the study's
//!   `[likelihood]` (as `iuq basis` samples it; with `--surrogate`, computed on the surrogate).
//!   Input: the sampled parameters (the study's, then `sigma_m` when the modelling error is
//!   estimated); output: `[log_posterior]`. Outside the prior's support the answer is
//!   −1.7976931348623157e308 (the most negative double: JSON has no −∞); a failed model run is
//!   a 500 `ModelError`.
//!
//! Without `[likelihood]` only the model is served; without `[model]` only the posterior.
//! The server listens on `--host` (default 127.0.0.1) and `--port` (default 4242, 0 for a free
//! one), runs `--parallel` model calls at once — one point each for the cell model and a
//! UM-Bridge model; for a cheap model (GP surrogate, expression, their posteriors) the points of
//! all requests then waiting, up to `--batch` (64), in one call — and prints its URL once it
//! listens (with `--json`: one JSON object), then serves until it is stopped.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use serde_json::{Value, json};

use iuq_basis::LogLikelihood;
use iuq_core::{CoreError, Evaluation, EvaluationFailure, Model, Outcome, ParameterSpace};
use iuq_gp::GpBank;
use iuq_study::posterior::build_posterior_with;
use iuq_study::study::{ModelSection, Study};
use iuq_umbridge::{Jacobian, ServedModel, Server, ServerOptions};

use crate::input_error::{BadInput, input_error};

/// The verbs of `iuq serve`.
#[derive(Debug, Subcommand)]
pub enum ServeCommand {
    /// Serve the study's model and its log-posterior over UM-Bridge 1.0 (HTTP) until stopped.
    Umbridge(UmbridgeArgs),
}

/// Arguments of `iuq serve umbridge`.
#[derive(Debug, Args)]
pub struct UmbridgeArgs {
    /// The study file (TOML).
    pub study: PathBuf,
    /// Port to listen on (0: a free port, printed when listening).
    #[arg(long, default_value_t = 4242)]
    pub port: u16,
    /// Address to listen on (0.0.0.0: every interface).
    #[arg(long, default_value = "127.0.0.1")]
    pub host: String,
    /// Model calls run at once (default: the number of CPUs).
    #[arg(long)]
    pub parallel: Option<usize>,
    /// Points one model call evaluates together when requests wait for the same model
    /// (default: 64 for a GP surrogate, an expression and their posteriors; 1 for the cell
    /// model and a UM-Bridge model, so that --parallel runs are at most --parallel points).
    #[arg(long)]
    pub batch: Option<usize>,
    /// Serve this fitted GP instead of the study's `[model]`: a GP file of `iuq gp fit` or a
    /// GP bank JSON, with the study's parameters as inputs.
    #[arg(long, value_name = "FILE")]
    pub surrogate: Option<PathBuf>,
    /// The largest request body accepted, in bytes (larger ones get 413).
    #[arg(long, default_value_t = 16 << 20)]
    pub max_body_bytes: usize,
    /// Print one line per request on stderr.
    #[arg(long)]
    pub log: bool,
}

/// Run `iuq serve`.
pub fn run(command: &ServeCommand, json_output: bool) -> Result<()> {
    match command {
        ServeCommand::Umbridge(args) => serve_umbridge(args, json_output),
    }
}

/// A model shared between the served model and the posterior's likelihood.
struct SharedModel(Arc<dyn Model>);

impl Model for SharedModel {
    fn input_names(&self) -> &[String] {
        self.0.input_names()
    }
    fn output_names(&self) -> &[String] {
        self.0.output_names()
    }
    fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
        self.0.evaluate_batch(points)
    }
}

fn serve_umbridge(args: &UmbridgeArgs, json_output: bool) -> Result<()> {
    let study = Study::load(&args.study)?;
    let file = study.path.display().to_string();
    let parallel = match args.parallel {
        Some(0) => return Err(input_error("--parallel: must be at least 1")),
        Some(n) => n,
        None => ServerOptions::default().parallel,
    };
    if args.batch == Some(0) {
        return Err(input_error("--batch: must be at least 1"));
    }
    if args.max_body_bytes < 1024 {
        return Err(input_error(format!(
            "--max-body-bytes: {} is too small for a request (at least 1024)",
            args.max_body_bytes
        )));
    }

    // The forward model: the surrogate, or the study's [model] (none without one).
    let mut jacobian: Option<Arc<dyn Jacobian>> = None;
    let mut values_only: Option<Arc<dyn Model>> = None;
    let forward: Option<Arc<dyn Model>> = match &args.surrogate {
        Some(path) => {
            let bank = load_surrogate(path, &study)?;
            jacobian = Some(Arc::new(GpMeanJacobian(bank.clone())));
            values_only = Some(Arc::new(GpBankMeans(bank.clone())));
            Some(Arc::new(bank) as Arc<dyn Model>)
        }
        None if matches!(study.model, ModelSection::Absent) => None,
        None => Some(Arc::new(study.model()?) as Arc<dyn Model>),
    };

    // The log-posterior, when the study has a likelihood.
    let posterior = match &study.likelihood {
        None => None,
        Some(_) => {
            let shared = forward.clone();
            let posterior = build_posterior_with(&study, || match shared {
                Some(model) => Ok(SharedModel(model)),
                None => Err(iuq_study::input_error(format!(
                    "{file}: section `[model]`: missing; the `[likelihood]` compares model outputs with data"
                ))),
            })?;
            Some(LogPosterior::new(posterior.space, posterior.likelihood))
        }
    };

    // Cheap models share a batch among the requests that wait; expensive ones run one point
    // per call.
    let cheap = args.surrogate.is_some()
        || matches!(
            study.model,
            ModelSection::Expression { .. } | ModelSection::Absent
        );
    let batch = args.batch.unwrap_or(if cheap { CHEAP_BATCH } else { 1 });
    let mut models = Vec::new();
    if let Some(model) = forward {
        let mut served = ServedModel::new(study.name.clone(), model).with_batch_limit(batch);
        if let Some(j) = jacobian {
            served = served.with_jacobian(j);
        }
        if let Some(v) = values_only {
            served = served.with_values_only(v);
        }
        models.push(served);
    }
    if let Some(p) = posterior {
        models.push(
            ServedModel::new(format!("{}-posterior", study.name), Arc::new(p))
                .with_batch_limit(batch),
        );
    }
    if models.is_empty() {
        return Err(input_error(format!(
            "{file}: nothing to serve: the study has neither a `[model]` nor a `[likelihood]`"
        )));
    }

    let address = if args.host.contains(':') && !args.host.starts_with('[') {
        format!("[{}]:{}", args.host, args.port)
    } else {
        format!("{}:{}", args.host, args.port)
    };
    let options = ServerOptions {
        parallel,
        max_body_bytes: args.max_body_bytes,
        log_requests: args.log,
        ..ServerOptions::default()
    };
    let server = Server::bind(models, &address, options)
        .bad_input(|| format!("--host/--port: cannot listen on {address}"))?;
    announce(&server, parallel, json_output);
    server.run().context("the UM-Bridge server stopped")?;
    Ok(())
}

/// The batch limit of cheap models (a GP bank predicts in groups of 8 points; 64 lets many
/// waiting clients share a call).
const CHEAP_BATCH: usize = 64;

/// Prints where the server listens and what it serves, once it listens.
fn announce(server: &Server, parallel: usize, json_output: bool) {
    let models: Vec<Value> = server
        .models()
        .iter()
        .map(|m| {
            json!({
                "name": m.name(),
                "inputs": m.model().input_names(),
                "outputs": m.model().output_names(),
                "gradient": m.support().gradient,
                "batch": m.batch_limit(),
            })
        })
        .collect();
    if json_output {
        println!(
            "{}",
            json!({
                "url": server.url(),
                "protocol_version": iuq_umbridge::PROTOCOL_VERSION,
                "parallel": parallel,
                "models": models,
            })
        );
    } else {
        println!(
            "iuq serve: UM-Bridge 1.0 on {} ({parallel} evaluations at once; stop with Ctrl-C)",
            server.url()
        );
        for m in server.models() {
            println!(
                "  model \"{}\": inputs [{}] -> outputs [{}]{}",
                m.name(),
                m.model().input_names().join(", "),
                m.model().output_names().join(", "),
                if m.support().gradient {
                    "; Gradient, ApplyJacobian"
                } else {
                    ""
                }
            );
        }
    }
    use std::io::Write;
    let _ = std::io::stdout().flush();
}

/// Reads a GP file (`iuq gp fit`'s, or the pipeline's `gp-bank.json`) whose inputs are the
/// study's parameters.
fn load_surrogate(path: &Path, study: &Study) -> Result<GpBank> {
    let shown = path.display();
    let text = std::fs::read_to_string(path)
        .map_err(|e| input_error(format!("--surrogate {shown}: cannot read: {e}")))?;
    let bank =
        GpBank::from_json_str(&text).bad_input(|| format!("--surrogate {shown}: not a GP file"))?;
    let names = study.space.names();
    if bank.input_names() != names.as_slice() {
        return Err(input_error(format!(
            "--surrogate {shown}: its inputs [{}] are not the study's parameters [{}] (same names, same order)",
            bank.input_names().join(", "),
            names.join(", ")
        )));
    }
    Ok(bank)
}

/// A GP bank's posterior means without the predictive variances: what `/Evaluate` answers when
/// the computational std is not asked for (O(n·d) per point instead of a triangular solve).
/// The means are those of [`GpBank`]'s evaluation, bit for bit.
struct GpBankMeans(GpBank);

impl Model for GpBankMeans {
    fn input_names(&self) -> &[String] {
        self.0.input_names()
    }

    fn output_names(&self) -> &[String] {
        self.0.output_names()
    }

    fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
        let d = self.0.input_dimension();
        let valid: Vec<bool> = points
            .iter()
            .map(|p| p.len() == d && p.iter().all(|v| v.is_finite()))
            .collect();
        let inside: Vec<Vec<f64>> = points
            .iter()
            .zip(&valid)
            .filter(|(_, ok)| **ok)
            .map(|(p, _)| p.clone())
            .collect();
        let means = self
            .0
            .gps()
            .iter()
            .map(|gp| gp.predict_mean(&inside))
            .collect::<std::result::Result<Vec<_>, _>>()
            .map_err(|e| CoreError::ModelUnavailable(e.to_string()))?;
        let mut next = 0;
        Ok(valid
            .into_iter()
            .map(|ok| {
                if !ok {
                    return Err(EvaluationFailure::new(format!(
                        "expected {d} finite inputs"
                    )));
                }
                let i = next;
                next += 1;
                Ok(Evaluation::new(means.iter().map(|m| m[i]).collect()))
            })
            .collect())
    }
}

/// The answer for a point outside the prior's support: the most negative double (JSON has no
/// −∞; a sampler rejects it as it would −∞).
pub const OUTSIDE_SUPPORT: f64 = f64::MIN;

/// ln p(θ) + ln f(D | θ) as a model of one output, `log_posterior`.
struct LogPosterior {
    space: ParameterSpace,
    likelihood: Box<dyn LogLikelihood>,
    inputs: Vec<String>,
    outputs: Vec<String>,
}

impl LogPosterior {
    fn new(space: ParameterSpace, likelihood: Box<dyn LogLikelihood>) -> Self {
        Self {
            inputs: space.names(),
            outputs: vec!["log_posterior".to_string()],
            space,
            likelihood,
        }
    }
}

impl Model for LogPosterior {
    fn input_names(&self) -> &[String] {
        &self.inputs
    }

    fn output_names(&self) -> &[String] {
        &self.outputs
    }

    /// The prior everywhere; the likelihood (one batch) only inside the prior's support, as
    /// the sampler does.
    fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
        let log_priors = points
            .iter()
            .map(|p| self.space.log_prior(p))
            .collect::<iuq_core::Result<Vec<f64>>>()?;
        let inside: Vec<usize> = (0..points.len())
            .filter(|&i| log_priors[i].is_finite())
            .collect();
        let batch: Vec<Vec<f64>> = inside.iter().map(|&i| points[i].clone()).collect();
        let log_likelihoods = self
            .likelihood
            .log_likelihood_batch(&batch)
            .map_err(|e| CoreError::ModelUnavailable(e.to_string()))?;
        if log_likelihoods.len() != batch.len() {
            return Err(CoreError::ModelUnavailable(format!(
                "the likelihood returned {} values for {} points",
                log_likelihoods.len(),
                batch.len()
            )));
        }
        let mut outcomes: Vec<Outcome> =
            vec![Ok(Evaluation::new(vec![OUTSIDE_SUPPORT])); points.len()];
        for (&i, ll) in inside.iter().zip(log_likelihoods) {
            outcomes[i] = match ll {
                Ok(v) if v.is_finite() => Ok(Evaluation::new(vec![
                    (log_priors[i] + v).max(OUTSIDE_SUPPORT),
                ])),
                Ok(v) if v == f64::NEG_INFINITY => Ok(Evaluation::new(vec![OUTSIDE_SUPPORT])),
                Ok(v) => Err(EvaluationFailure::new(format!("the log-likelihood is {v}"))),
                Err(failure) => Err(failure),
            };
        }
        Ok(outcomes)
    }
}

/// The exact Jacobian of the posterior means of a GP bank: one row per GP, from
/// [`iuq_gp::GaussianProcess::mean_and_gradient`] (its own α, O(n·d) per point).
struct GpMeanJacobian(GpBank);

impl Jacobian for GpMeanJacobian {
    fn jacobian(&self, x: &[f64]) -> std::result::Result<Vec<Vec<f64>>, EvaluationFailure> {
        self.0
            .gps()
            .iter()
            .map(|gp| {
                gp.mean_and_gradient(x)
                    .map(|(_, gradient)| gradient)
                    .map_err(|e| EvaluationFailure::new(e.to_string()))
            })
            .collect()
    }
}
