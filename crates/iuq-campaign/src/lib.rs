//! Campaigns of expensive model runs for iuq.
//!
//! A campaign takes a batch of parameter vectors (a training design, a Sobol' design, one BASIS
//! stage), runs the model for each one in parallel — on this machine or on a cluster through
//! Slurm or HyperQueue — keeps every result in an SQLite store the moment it exists, survives
//! crashes of the simulator and of itself, and hands the results back as a batch: a
//! [`CampaignModel`] is an [`iuq_core::Model`].
//!
//! | module | what |
//! |---|---|
//! | [`study`] | campaign study files: `[model]` (`command`, `batch-command`), `[design]`, `[executor]`, validated up front (read with `iuq_study_file::StudySection`) |
//! | [`template`] | `{{ name }}` templates for input files and command arguments |
//! | [`decoder`] | outputs from a JSON file, a CSV column or a regex over a file |
//! | [`run_directory`] | run directories: `params.json`, filled templates, batch input CSVs |
//! | [`supervised_process`] | process groups, timeouts (SIGTERM, then SIGKILL) |
//! | [`in_process`] | models evaluated in this process (formulas, UM-Bridge, the cell model) |
//! | [`worker`] | executes one task, writes `result.json`/`status.json` atomically (`iuq worker`) |
//! | [`store`] | the SQLite campaign store, whose connection is its own: every query is one of its methods |
//! | [`store::recorded_designs`] | the designs a store has recorded, how far each got, setting one aside (`iuq cancel`) |
//! | [`executor`] | local, Slurm and HyperQueue executors |
//! | [`campaign`] | the coordinator: submit, ingest, retry, resume |
//! | [`campaign_model`] | a campaign as a batch `Model` |
//! | [`redecode`] | outputs of finished runs decoded again from their run directories |
//! | [`retry_policy`] | which failures are retried |
//! | [`start_watch`] | a campaign whose model command cannot start stops early |
//! | [`outcome`] | outcome kinds and worker reports |
//! | [`study_design`] | the study's `[design]` ([`StudyDesign`]) and the points it makes for `iuq run` |
//! | [`export`] | tidy CSV/JSON of parameters and outputs |
//! | [`atomic_file`] | atomic file writes |
//! | [`error`] | the crate's error type [`CampaignError`] |
//!
//! # Example
//!
//! A study's store keeps one run per distinct parameter vector: a design that repeats a point,
//! or a second design that shares points with the first, adds no run for them, and recording
//! the same design again (a rerun of the study) leaves the store as it was.
//!
//! ```
//! use iuq_campaign::{CampaignStore, CampaignStudy};
//!
//! let dir = std::env::temp_dir().join(format!("iuq-campaign-doc-{}", std::process::id()));
//! std::fs::create_dir_all(&dir)?;
//! let study = CampaignStudy::parse(
//!     r#"
//! name = "decay"
//! [parameters]
//! k = { uniform = [0.1, 1] }
//! [model]
//! kind = "command"
//! command = ["./decay.sh", "{{ k }}"]
//! outputs = ["y"]
//! output = { file = "result.json", format = "json" }
//! "#,
//!     &dir.join("decay.toml"),
//! )?;
//! let mut store = CampaignStore::open(&dir.join("campaign.sqlite"), &study)?;
//! let first = store.add_design("initial", &[vec![0.2], vec![0.5], vec![0.2]])?;
//! assert_eq!(first[0], first[2]);
//! let second = store.add_design("round-1", &[vec![0.5], vec![0.9]])?;
//! assert_eq!(second[0], first[1]);
//! assert_eq!(store.add_design("initial", &[vec![0.2], vec![0.5], vec![0.2]])?, first);
//! let counts = store.counts(None)?;
//! assert_eq!((counts.pending, counts.total()), (3, 3));
//! # drop(store);
//! # std::fs::remove_dir_all(&dir)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]
// No panic reachable from user input: a library reports every failure in its error type.
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

pub mod atomic_file;
pub mod campaign;
pub mod campaign_model;
pub mod decoder;
pub mod error;
pub mod executor;
pub mod export;
pub mod in_process;
pub mod outcome;
pub mod redecode;
pub mod retry_policy;
pub mod run_directory;
pub mod start_watch;
pub mod store;
pub mod study;
pub mod study_design;
pub mod supervised_process;
pub mod template;
pub mod worker;

pub use campaign::{
    Campaign, CampaignOptions, Interrupt, Progress, ResumeSummary, STORE_FILE, store_path,
};
pub use campaign_model::CampaignModel;
pub use error::{CampaignError, Result};
pub use in_process::{InProcessError, InProcessModel, InProcessOutputs, SharedModel};
pub use outcome::{OutcomeKind, RunResult, TaskReport};
pub use redecode::RedecodeSummary;
pub use retry_policy::RetryPolicy;
pub use store::{CampaignStore, RunStatus, StatusCounts};
pub use study::{CampaignStudy, CommandSpec, ExecutorKind};
pub use study_design::StudyDesign;
