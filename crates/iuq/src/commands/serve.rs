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
use iuq_gp::{GaussianProcess, GpBank};
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
            match GpMeanJacobian::new(&bank) {
                Ok(j) => jacobian = Some(Arc::new(j)),
                Err(reason) => {
                    eprintln!("iuq serve: warning: no /Gradient for the surrogate ({reason})")
                }
            }
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

/// Reads a GP file of `iuq gp fit` or a GP bank JSON whose inputs are the study's parameters.
fn load_surrogate(path: &Path, study: &Study) -> Result<GpBank> {
    let shown = path.display();
    let text = std::fs::read_to_string(path)
        .map_err(|e| input_error(format!("--surrogate {shown}: cannot read: {e}")))?;
    let value: Value =
        serde_json::from_str(&text).bad_input(|| format!("--surrogate {shown}: not JSON"))?;
    let bank = if value.get("format").and_then(Value::as_str) == Some("iuq-gp")
        && value.get("gp").is_some()
    {
        let (gp_file, gp) = crate::commands::gp::load_gp(path)?;
        GpBank::new(gp_file.inputs, vec![gp_file.output], vec![gp])
            .bad_input(|| format!("--surrogate {shown}"))?
    } else {
        GpBank::from_json_str(&text)
            .bad_input(|| format!("--surrogate {shown}: neither a GP file nor a GP bank"))?
    };
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

/// The exact Jacobian of the posterior means of a GP bank: for one GP with training inputs
/// x̃ᵢ (scaled), weights α = K⁻¹ỹ, signal variance c and length scales l,
///
/// ∂μ/∂x_k = (s_y / r_k) · Σᵢ αᵢ · c·exp(−½ Σ_j (x̃_j − x̃ᵢⱼ)²/l_j²) · (−(x̃_k − x̃ᵢₖ)/l_k²),
///
/// with x̃_k = (x_k − a_k)/r_k the input scaling and s_y the output scale. The GP keeps its α
/// private, so α is recomputed here from what it publishes (hyper-parameters, jitter, scalings,
/// training data): K = c·R + (σ² + jitter)·I factorised by Cholesky, O(n³/6) once per GP at
/// start. The reconstruction is checked against the GP's own mean at probe points; a GP that
/// fails the check is served without a gradient (with a warning).
struct GpMeanJacobian {
    terms: Vec<GpTerms>,
}

struct GpTerms {
    /// Scaled training inputs, row-major n×d.
    x: Vec<f64>,
    alpha: Vec<f64>,
    inverse_squared_length_scales: Vec<f64>,
    signal_variance: f64,
    lower: Vec<f64>,
    range: Vec<f64>,
    mean: f64,
    scale: f64,
}

/// Solves K·α = b for a symmetric positive definite K (row-major n×n, overwritten by its
/// Cholesky factor); `None` when K is not positive definite.
fn cholesky_solve(k: &mut [f64], n: usize, b: &[f64]) -> Option<Vec<f64>> {
    for j in 0..n {
        for i in j..n {
            let (row_i, row_j) = (i * n, j * n);
            let dot: f64 = (0..j).map(|t| k[row_i + t] * k[row_j + t]).sum();
            let v = k[row_i + j] - dot;
            if i == j {
                if !(v > 0.0 && v.is_finite()) {
                    return None;
                }
                k[row_j + j] = v.sqrt();
            } else {
                k[row_i + j] = v / k[row_j + j];
            }
        }
    }
    // L y = b, then Lᵀ α = y.
    let mut y = b.to_vec();
    for i in 0..n {
        let dot: f64 = (0..i).map(|t| k[i * n + t] * y[t]).sum();
        y[i] = (y[i] - dot) / k[i * n + i];
    }
    for i in (0..n).rev() {
        let dot: f64 = (i + 1..n).map(|t| k[t * n + i] * y[t]).sum();
        y[i] = (y[i] - dot) / k[i * n + i];
    }
    Some(y)
}

impl GpTerms {
    fn new(gp: &GaussianProcess) -> std::result::Result<Self, String> {
        let d = gp.dimension();
        let h = gp.hyperparameters();
        let length_scales: Vec<f64> = match h.length_scales.as_slice() {
            [l] => vec![*l; d],
            ls if ls.len() == d => ls.to_vec(),
            ls => return Err(format!("{} length scales for {d} inputs", ls.len())),
        };
        let inverse_squared_length_scales: Vec<f64> =
            length_scales.iter().map(|l| 1.0 / (l * l)).collect();
        let scaling = gp.input_scaling();
        let output = gp.output_scaling();
        let training = gp.training_inputs();
        let n = training.len();
        let x: Vec<f64> = training
            .iter()
            .flat_map(|p| (0..d).map(move |k| (p[k] - scaling.lower[k]) / scaling.range[k]))
            .collect();
        let c = h.signal_variance;
        let mut kernel = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..=i {
                let r2: f64 = (0..d)
                    .map(|k| {
                        let t = x[i * d + k] - x[j * d + k];
                        t * t * inverse_squared_length_scales[k]
                    })
                    .sum();
                let v = c * (-0.5 * r2).exp();
                kernel[i * n + j] = v;
                kernel[j * n + i] = v;
            }
            kernel[i * n + i] += h.noise_variance + gp.jitter();
        }
        let standardised: Vec<f64> = gp
            .training_outputs()
            .iter()
            .map(|&y| output.apply(y))
            .collect();
        let alpha = cholesky_solve(&mut kernel, n, &standardised)
            .ok_or("the kernel matrix is not positive definite")?;
        let terms = Self {
            x,
            alpha,
            inverse_squared_length_scales,
            signal_variance: c,
            lower: scaling.lower.clone(),
            range: scaling.range.clone(),
            mean: output.mean,
            scale: output.std,
        };
        // Check the reconstruction at midpoints of consecutive training points.
        let probes: Vec<Vec<f64>> = training
            .windows(2)
            .take(16)
            .map(|w| w[0].iter().zip(&w[1]).map(|(a, b)| 0.5 * (a + b)).collect())
            .collect();
        let expected = gp.predict_mean(&probes).map_err(|e| e.to_string())?;
        for (p, e) in probes.iter().zip(expected) {
            let (mine, _) = terms.mean_and_gradient(p);
            if (mine - e).abs() > 1e-6 * (output.std + (e - output.mean).abs()) {
                return Err(format!(
                    "the mean recomputed from the GP's hyper-parameters ({mine}) differs from the GP's ({e})"
                ));
            }
        }
        Ok(terms)
    }

    /// The posterior mean and its gradient at `p` (original units).
    fn mean_and_gradient(&self, p: &[f64]) -> (f64, Vec<f64>) {
        let d = self.lower.len();
        let xs: Vec<f64> = (0..d)
            .map(|k| (p[k] - self.lower[k]) / self.range[k])
            .collect();
        let mut value = 0.0;
        let mut gradient = vec![0.0; d];
        for (row, &a) in self.x.chunks_exact(d).zip(&self.alpha) {
            let mut r2 = 0.0;
            for k in 0..d {
                let t = xs[k] - row[k];
                r2 += t * t * self.inverse_squared_length_scales[k];
            }
            let w = a * self.signal_variance * (-0.5 * r2).exp();
            value += w;
            for k in 0..d {
                gradient[k] -= w * (xs[k] - row[k]) * self.inverse_squared_length_scales[k];
            }
        }
        for k in 0..d {
            gradient[k] *= self.scale / self.range[k];
        }
        (self.mean + self.scale * value, gradient)
    }
}

impl GpMeanJacobian {
    fn new(bank: &GpBank) -> std::result::Result<Self, String> {
        Ok(Self {
            terms: bank
                .gps()
                .iter()
                .map(GpTerms::new)
                .collect::<std::result::Result<_, _>>()?,
        })
    }
}

impl Jacobian for GpMeanJacobian {
    fn jacobian(&self, x: &[f64]) -> std::result::Result<Vec<Vec<f64>>, EvaluationFailure> {
        if x.iter().any(|v| !v.is_finite()) {
            return Err(EvaluationFailure::new("non-finite input"));
        }
        Ok(self
            .terms
            .iter()
            .map(|t| t.mean_and_gradient(x).1)
            .collect())
    }
}
