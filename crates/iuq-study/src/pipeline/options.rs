//! How to run the pipeline: [`PipelineOptions`], the flags of `iuq pipeline`.

use std::path::PathBuf;

use iuq_campaign::SharedModel;

/// How to run the pipeline (the flags of `iuq pipeline`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PipelineOptions {
    /// Output directory of the report and every stage's results (created when missing).
    pub out: PathBuf,
    /// Model runs at once (overrides `executor.max_parallel`; `None`: the number of cores; 0 is
    /// an input error).
    pub max_parallel: Option<usize>,
    /// Also give the model's own posterior, through the campaign: from the surrogate's by
    /// certified importance stages (`[model_posterior]`, a few hundred runs per run group), or
    /// with `[model_posterior] method = "basis"` by BASIS on the model (`[model_sampler]`:
    /// samples × stages runs per run group).
    pub model_posterior: bool,
    /// Recompute every model run: move the campaign directory aside (to `<dir>.previous-N`)
    /// instead of reusing the results it holds.
    pub fresh: bool,
    /// Stop after the training and test runs (e.g. to make the campaign in a batch job).
    pub runs_only: bool,
    /// Recompute every adaptive round's measurement (surrogate fit, replicate samplers,
    /// surrogate error) instead of reading back the one the campaign store recorded for the
    /// same inputs; a recomputed measurement that differs from the recorded one is reported.
    pub recompute_rounds: bool,
    /// The model of a study whose `[model]` is of kind `callable`: supplied by the program that
    /// runs the study (the Python package's `iuq.calibrate`), evaluated in this process.
    pub callable: Option<SharedModel>,
    /// The cheap model of a `[low_fidelity]` of kind `callable`, supplied as `callable` is.
    pub low_fidelity_callable: Option<SharedModel>,
    /// How long [`run`](super::run) waits, once its observer asked it to stop, for the pipeline to reach its
    /// next check (between model runs, sampler stages, adaptive rounds). Past it, `run` returns
    /// [`StudyError::Interrupted`](crate::error::StudyError::Interrupted) at once and leaves the pipeline's thread to stop on its own
    /// (a GP fit or a sampler stage on many runs can take seconds); the next [`run`](super::run) in this
    /// process waits for such a thread before it starts, so two pipelines never share a store.
    /// `None` (the CLI's): wait for the thread.
    pub interrupt_grace: Option<std::time::Duration>,
}
