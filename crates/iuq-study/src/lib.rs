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
//! reason) or a failure of the work.
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
//! | [`gp_bank_benchmark`] | the benchmark problem of `iuq bench basis-gp-bank` |
//! | [`gp_file`] | GP files: a GP bank of one output |
//! | [`pipeline`] | the calibration study end to end, its settings, the report's data |
//! | [`table_io`] | numeric CSV tables, atomic writes |
//! | [`error`] | the crate's error type [`StudyError`] and its helpers |

#![warn(missing_docs)]

pub mod campaign_runs;
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
