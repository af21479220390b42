//! Study files and the calibration pipeline of iuq as a library: the command line, the tests
//! and the Python package (`python/`, `iuq.calibrate`) call it.
//!
//! A study file (TOML) names the parameters with their priors, the model, the data and the
//! prediction-error model, and the settings of every stage. This crate reads and validates it
//! ([`Study`]), builds its model and its posterior, samples the posterior with BASIS
//! ([`posterior`]), and runs the whole calibration study — model runs through a campaign, GP
//! surrogates, Sobol' indices, BASIS, the report — as [`pipeline::run`].
//!
//! Every error is a [`StudyError`]: bad input (a message naming the file, the key and the
//! reason) or a failure of the work, keeping the typed error it came from as its source.
//!
//! | module | what |
//! |---|---|
//! | [`study`] | study files: `name`, `[parameters]`, `[model]`, `[sensitivity]`; the study's model |
//! | [`likelihood_section`] | `[likelihood]`: a log-density, or data and the prediction-error model |
//! | [`sampler_section`] | `[sampler]`: the BASIS settings |
//! | [`rbc_section`] | `[model] kind = "rbc-shear"`: the native single-cell shear simulator |
//! | [`umbridge_section`] | `[model] kind = "umbridge"`: a model on a UM-Bridge server |
//! | [`posterior`] | a study's posterior, sampled with BASIS into a results directory |
//! | [`campaign_runs`] | campaigns of model runs: opening, resuming, progress lines |
//! | [`campaign_study`] | the campaign a study file stands for (a campaign study, or a pipeline's runs) |
//! | [`gp_bank_benchmark`] | the benchmark problem of `iuq bench basis-gp-bank` |
//! | [`gp_file`] | GP files: a GP bank of one output |
//! | [`pipeline`] | the calibration study end to end, its settings, the report's data |
//! | [`table_io`] | numeric CSV tables, atomic writes |
//! | [`error`] | the crate's error type [`StudyError`] and its helpers |
//!
//! ```
//! use iuq_basis::LogLikelihood;
//! use iuq_study::{Study, build_posterior};
//!
//! // A study of T = 20 + (T0 − 20)·e^(−k t) at t = 1, 2 against two measurements with their
//! // stds (one output per data row, in order).
//! let dir = std::env::temp_dir().join(format!("iuq-study-doc-{}", std::process::id()));
//! std::fs::create_dir_all(&dir)?;
//! std::fs::write(dir.join("data.csv"), "t,T,T_err\n1,60,0.5\n2,45,0.5\n")?;
//! let text = r#"
//! name = "cooling"
//! [parameters]
//! k = { uniform = [0.05, 0.8] }
//! T0 = { uniform = [60, 100] }
//! [likelihood]
//! data = { file = "data.csv", x = "t", y = "T", y_err = "T_err" }
//! [model]
//! kind = "expression"
//! outputs = { T1 = "20 + (T0 - 20) * exp(-k * 1)", T2 = "20 + (T0 - 20) * exp(-k * 2)" }
//! "#;
//! let study = Study::parse(text, &dir.join("study.toml"))?;
//! let posterior = build_posterior(&study)?;
//! // The likelihood is exactly N(y | model, y_err²): at k = 0.3, T0 = 80 against the formula.
//! let (k, t0) = (0.3f64, 80.0f64);
//! let mut expected = 0.0;
//! for (t, y) in [(1.0f64, 60.0f64), (2.0, 45.0)] {
//!     let r = (y - (20.0 + (t0 - 20.0) * (-k * t).exp())) / 0.5;
//!     expected += -0.5 * r * r - (0.5 * (2.0 * std::f64::consts::PI).sqrt()).ln();
//! }
//! let value = posterior.likelihood.log_likelihood_batch(&[vec![k, t0]])?[0].clone().unwrap();
//! assert!((value - expected).abs() < 1e-9, "{value} against {expected}");
//! std::fs::remove_dir_all(&dir)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]
// No panic reachable from user input: a library reports every failure in its error type.
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

pub mod campaign_runs;
pub mod campaign_study;
pub mod error;
pub mod gp_bank_benchmark;
pub mod gp_file;
pub mod likelihood_section;
pub mod pipeline;
pub mod posterior;
pub mod rbc_section;
pub mod sampler_section;
pub mod study;
pub mod table_io;
pub mod umbridge_section;

pub use error::{BadInput, Context, Result, StudyError, input_error};
pub use pipeline::{PipelineEvent, PipelineObserver, PipelineOptions, PipelineOutcome};
pub use posterior::{
    SampledPosterior, StudyPosterior, build_posterior, build_posterior_with, sample_posterior,
};
pub use study::{ModelSection, SensitivitySection, Study, StudyModel};
