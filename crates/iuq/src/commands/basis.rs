//! `iuq basis STUDY`: posterior sampling and evidence with BASIS (Wu et al. 2017).
//!
//! Reads the study's parameters and priors, its `[likelihood]` (see
//! [`iuq_study::likelihood_section`]) and `[sampler]` ([`iuq_study::sampler_section`]) sections,
//! and writes to the output directory (by [`iuq_study::posterior::sample_posterior`]):
//! - `checkpoint.json` — the state after every stage, written atomically (format:
//!   `iuq_basis::checkpoint`); `--resume DIR` continues from `DIR/checkpoint.json`
//!   bit-identically;
//! - `stages.json` (every diagnostic, failure reasons included) and `stages.csv` (the numeric
//!   ones), rewritten after every stage;
//! - `samples.csv` — the final population: one column per parameter (with `sigma_m` when the
//!   modelling error is estimated), then `ll` (log-likelihood) and `lp` (log-prior);
//! - `summary.json` — evidence, stop reason, settings, MAP, mean, std, quantiles, failures;
//! - `marginals.json` — 1-D (200 points) and 2-D (50×50) Gaussian KDE marginals.
//!
//! Progress is reported after every stage on stderr: a progress bar on a terminal, log lines
//! otherwise. A run that stops before p = 1 (stage limit, minimum step) still writes its
//! results, reports why, and exits with 0; `"converged"` in the JSON says whether it reached the
//! posterior.

use std::io::IsTerminal;
use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;

use iuq_basis::checkpoint::from_json;
use iuq_basis::summary::DEFAULT_PROBABILITIES;
use iuq_basis::{BasisState, StopReason};
use iuq_study::Study;
use iuq_study::posterior::{SamplingJob, build_posterior, by_name, sample_posterior};
use iuq_study::sampler_section::{SamplerOverrides, parse_sampler};

use crate::input_error::{BadInput, input_error};
use crate::report_output::{emit, short};

/// Arguments of `iuq basis`.
#[derive(Debug, Args)]
pub struct BasisArgs {
    /// The study file (TOML) with `[parameters]`, `[likelihood]` and optionally `[sampler]`.
    pub study: PathBuf,
    /// Population size N (default from `[sampler] samples`, else 1000).
    #[arg(long)]
    pub samples: Option<usize>,
    /// Burn-in steps n_burn of every chain, at a fixed proposal scale (default from `[sampler] burn`,
    /// else "auto": each chain moves until it decorrelates from its start).
    #[arg(long)]
    pub burn: Option<usize>,
    /// Maximum chain length l_max (default from `[sampler] max_chain`, else 1).
    #[arg(long)]
    pub max_chain: Option<usize>,
    /// Seed of the random streams (default from `[sampler] seed`, else 0).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Output directory (default: `<study name>-basis` in the current directory, or the
    /// `--resume` directory).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Continue the run whose checkpoint is `DIR/checkpoint.json` (same study and settings).
    #[arg(long, value_name = "DIR")]
    pub resume: Option<PathBuf>,
    /// Stop (resumably) after this stage, e.g. to fit a job's time limit; continue later with
    /// `--resume`.
    #[arg(long, value_name = "STAGE")]
    pub stop_after: Option<usize>,
}

/// The progress of a BASIS run on stderr after every stage: a progress bar on a terminal, log
/// lines (`basis: stage …`) otherwise.
pub struct StageProgress {
    bar: Option<ProgressBar>,
}

impl StageProgress {
    /// Start reporting (the bar, on a terminal, shows the elapsed time from now on).
    pub fn start() -> Self {
        let bar = if std::io::stderr().is_terminal() {
            let bar = ProgressBar::new(1000);
            bar.set_style(
                ProgressStyle::with_template(
                    "basis [{elapsed_precise}] {bar:25} p {pos}/{len}‰ {wide_msg}",
                )
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            // keep the elapsed time moving during long stages (an expensive model)
            bar.enable_steady_tick(std::time::Duration::from_millis(500));
            Some(bar)
        } else {
            None
        };
        Self { bar }
    }

    /// Report the stage that just ended.
    pub fn report(&self, state: &BasisState) {
        let Some(d) = state.diagnostics.last() else {
            return;
        };
        let line = format!(
            "stage {}: p = {} (dp {}), CV {}, ESS/N {}, acceptance {}, ln Z so far {}, evaluations {} ({} total), failures {}, {:.2} s",
            d.stage,
            short(d.exponent),
            short(d.step),
            short(d.cv),
            short(d.ess_fraction),
            short(d.acceptance_rate),
            short(d.log_evidence),
            d.evaluations,
            state.evaluations,
            d.failures,
            d.wall_seconds
        );
        match &self.bar {
            Some(bar) => {
                bar.set_position((state.exponent * 1000.0).round() as u64);
                bar.set_message(format!(
                    "stage {} p={} CV={} acc={} lnZ={} evals={} fail={}",
                    d.stage,
                    short(d.exponent),
                    short(d.cv),
                    short(d.acceptance_rate),
                    short(d.log_evidence),
                    state.evaluations,
                    state.failures()
                ));
            }
            None => eprintln!("basis: {line}"),
        }
    }

    /// The run is over: clear the bar.
    pub fn finish(self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}

/// Run `iuq basis`.
pub fn run(args: &BasisArgs, json_output: bool) -> Result<()> {
    let study = Study::load(&args.study)?;
    let posterior = build_posterior(&study)?;
    let overrides = SamplerOverrides {
        samples: args.samples,
        burn: args.burn,
        max_chain: args.max_chain,
        seed: args.seed,
    };
    let settings = parse_sampler(&study, &overrides)?;
    let checkpoint = match &args.resume {
        None => None,
        Some(dir) => {
            let path = dir.join("checkpoint.json");
            let text = std::fs::read_to_string(&path).map_err(|e| {
                input_error(format!("--resume: cannot read {}: {e}", path.display()))
            })?;
            let state = from_json(&text).bad_input(|| format!("--resume: {}", path.display()))?;
            Some(state)
        }
    };
    let out = match (&args.out, &args.resume) {
        (Some(out), _) => out.clone(),
        (None, Some(dir)) => dir.clone(),
        (None, None) => PathBuf::from(format!("{}-basis", study.name)),
    };
    std::fs::create_dir_all(&out)
        .map_err(|e| input_error(format!("--out: cannot create {}: {e}", out.display())))?;

    let progress = StageProgress::start();
    let job = SamplingJob {
        study_name: &study.name,
        study_file: &study.path,
        out: &out,
        checkpoint,
        resume_dir: args.resume.as_deref(),
        stop_after: args.stop_after,
        marginals: true,
    };
    let sampled = sample_posterior(job, &posterior, settings, &mut |state: &BasisState| {
        progress.report(state);
        iuq_basis::Control::Continue
    });
    progress.finish();
    let sampled = sampled?;
    let (run, summary) = (&sampled.run, &sampled.summary);
    let state = &run.state;
    let names = &state.parameter_names;
    let converged = run.stop_reason == StopReason::Converged;
    let value = json!({
        "study": study.name,
        "log_evidence": state.log_evidence,
        "stages": state.stages(),
        "evaluations": state.evaluations,
        "stop_reason": run.stop_reason.name(),
        "stop_message": run.stop_reason.to_string(),
        "converged": converged,
        "exponent": state.exponent,
        "samples": state.samples.len(),
        "map": by_name(names, &summary.map),
        "mean": by_name(names, &summary.mean),
        "std": by_name(names, &summary.std),
        "map_log_likelihood": summary.map_log_likelihood,
        "map_log_prior": summary.map_log_prior,
        "failures": state.failures(),
        "failure_reasons": state.failure_reasons(),
        "out_of_support": state.out_of_support(),
        "out": out.display().to_string(),
        "wall_seconds": sampled.seconds,
    });
    if !converged {
        eprintln!("basis: {}", run.stop_reason);
    }
    emit(json_output, &value, || {
        let mut text = format!(
            "BASIS posterior of `{}`: ln Z = {} after {} stages, {} evaluations ({} failed, {} proposals outside the prior)\n{}\n\n{:<16} {:>12} {:>12} {:>12} {:>12} {:>12}\n",
            study.name,
            short(state.log_evidence),
            state.stages(),
            state.evaluations,
            state.failures(),
            state.out_of_support(),
            run.stop_reason,
            "parameter",
            "MAP",
            "mean",
            "std",
            "2.5%",
            "97.5%"
        );
        let lo = DEFAULT_PROBABILITIES.iter().position(|p| *p == 0.025);
        let hi = DEFAULT_PROBABILITIES.iter().position(|p| *p == 0.975);
        for (k, name) in names.iter().enumerate() {
            let q =
                |i: Option<usize>| i.map_or("-".to_string(), |i| short(summary.quantiles[k][i]));
            text.push_str(&format!(
                "{:<16} {:>12} {:>12} {:>12} {:>12} {:>12}\n",
                name,
                short(summary.map[k]),
                short(summary.mean[k]),
                short(summary.std[k]),
                q(lo),
                q(hi)
            ));
        }
        text.push_str(&format!("\nresults in {}", out.display()));
        text
    });
    Ok(())
}
