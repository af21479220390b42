//! The coordinator: registers designs in the store, hands pending runs to the executor, ingests
//! results as they arrive (one committed transaction per group of events), retries by policy,
//! and resumes after its own death.
//!
//! Each turn of the loop waits for events, then writes in one transaction everything that
//! happened since the last turn (attempts started, attempts finished with their outputs, the
//! attempts of the tasks about to be submitted); only then are the new tasks handed to the
//! executor. A result is therefore on disk before the coordinator looks at the next one, and an
//! execution never starts without its attempt row.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use iuq_core::{Control, Observer};
use serde::Serialize;

use crate::error::{CampaignError, Result};
use crate::executor::hyperqueue::{HyperQueueExecutor, HyperQueueSettings};
use crate::executor::local::LocalExecutor;
use crate::executor::slurm::{SlurmExecutor, SlurmSettings};
use crate::executor::{
    Executor, ExecutorEvent, OpenTask, SubmittedTask, report_events, report_matches,
};
use crate::outcome::OutcomeKind;
use crate::run_directory::{Task, TaskRun, task_directory};
use crate::start_watch::StartWatch;
use crate::store::{CampaignStore, Disposition, StatusCounts};
use crate::study::{CampaignStudy, CommandKind, ExecutorKind};
use crate::worker::{CompiledSpec, read_report, write_spec};

/// The store file inside the campaign directory.
pub const STORE_FILE: &str = "campaign.sqlite";

/// Where the campaign's progress stands, for progress bars and log lines.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Progress {
    /// Runs per status: of the store ([`Campaign::run`]) or of the runs asked for
    /// ([`Campaign::run_only`]; runs of an abandoned design left pending do not count).
    pub counts: StatusCounts,
    /// Runs finished since this coordinator started.
    pub finished_this_session: u64,
    /// Seconds since this coordinator started running.
    pub elapsed_seconds: f64,
    /// Estimated seconds until every run counted is final, from the rate of finished runs.
    pub eta_seconds: Option<f64>,
}

/// What resuming found.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct ResumeSummary {
    /// Attempts whose results were found and ingested.
    pub ingested: u64,
    /// Attempts the scheduler still runs, followed again.
    pub reattached: u64,
    /// Attempts declared lost (retried by policy).
    pub lost: u64,
    /// Runs put back to pending because they had no attempt.
    pub requeued: u64,
    /// Runs whose command could not start in an earlier session, pending again
    /// ([`crate::start_watch`]).
    pub restarted: u64,
}

/// Options of a campaign beyond its study file.
#[derive(Debug, Clone, Default)]
pub struct CampaignOptions {
    /// The command that starts `iuq worker` for the Slurm and HyperQueue executors (default:
    /// `executor.worker` of the study).
    pub worker_command: Option<Vec<String>>,
    /// Overrides `executor.max_parallel`.
    pub max_parallel: Option<usize>,
    /// Overrides `executor.poll_interval` (seconds).
    pub poll_interval: Option<f64>,
    /// Evaluate the runs in this process with this model instead of starting the study's
    /// command (local executor only; see [`crate::in_process`]).
    pub in_process: Option<crate::in_process::SharedModel>,
    /// Set from outside (a Ctrl-C seen by an embedding program): the campaign submits no more
    /// runs, files the results of those under way and returns [`CampaignError::Interrupted`].
    pub interrupt: Option<Interrupt>,
}

/// A flag another thread raises to stop a campaign (or a pipeline) at its next check; runs
/// already finished stay stored, runs under way are filed as they end.
#[derive(Debug, Clone, Default)]
pub struct Interrupt(pub std::sync::Arc<std::sync::atomic::AtomicBool>);

impl Interrupt {
    /// Raise the flag.
    pub fn raise(&self) {
        self.0.store(true, std::sync::atomic::Ordering::SeqCst);
    }

    /// Whether the flag is raised.
    pub fn is_raised(&self) -> bool {
        self.0.load(std::sync::atomic::Ordering::SeqCst)
    }
}

impl PartialEq for Interrupt {
    fn eq(&self, other: &Self) -> bool {
        std::sync::Arc::ptr_eq(&self.0, &other.0)
    }
}

impl Eq for Interrupt {}

/// The run ids of `ids` in increasing order.
fn sorted_ids(ids: &std::collections::HashSet<i64>) -> Vec<i64> {
    let mut sorted: Vec<i64> = ids.iter().copied().collect();
    sorted.sort_unstable();
    sorted
}

/// A campaign: a study, its store and an executor.
pub struct Campaign {
    /// Held (with an exclusive `flock`) while this coordinator lives; released by the kernel
    /// when it dies, however it dies.
    _lock: std::fs::File,
    study: CampaignStudy,
    store: CampaignStore,
    compiled: CompiledSpec,
    executor: Box<dyn Executor>,
    directory: PathBuf,
    session_start: Option<Instant>,
    finished_this_session: u64,
    start_watch: StartWatch,
    interrupt: Option<Interrupt>,
}

impl std::fmt::Debug for Campaign {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Campaign")
            .field("study", &self.study.name)
            .field("directory", &self.directory)
            .finish()
    }
}

/// The path of the store of `study`.
pub fn store_path(study: &CampaignStudy) -> PathBuf {
    study.executor.directory.join(STORE_FILE)
}

/// Take the coordinator lock of a campaign directory: only one coordinator may run a campaign.
fn lock_campaign(directory: &Path) -> Result<std::fs::File> {
    use std::io::{Read, Seek, Write};
    use std::os::unix::io::AsRawFd;
    let path = directory.join("coordinator.lock");
    let mut file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(&path)
        .map_err(|e| CampaignError::io(&path, e))?;
    // A lock just released can still be held for a moment by a child forked (by any thread of
    // this process) while it was open and not yet exec'd, which closes it: try for 2 s before
    // taking it for another coordinator's.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(2);
    let locked = loop {
        // SAFETY: flock on a descriptor we own.
        if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0 {
            break true;
        }
        if std::time::Instant::now() >= deadline {
            break false;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    if !locked {
        let mut holder = String::new();
        let _ = file.read_to_string(&mut holder);
        return Err(CampaignError::BadInput(format!(
            "{}: another coordinator ({}) is running this campaign; wait for it, or stop it and run again to resume",
            directory.display(),
            holder.trim()
        )));
    }
    let _ = file.set_len(0);
    let _ = file.rewind();
    let _ = write!(
        file,
        "pid {} on {}",
        std::process::id(),
        crate::outcome::host_name()
    );
    Ok(file)
}

/// The name shared by every scheduler job of the campaign.
fn job_name(study: &CampaignStudy) -> String {
    let clean: String = study
        .name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .take(24)
        .collect();
    let dir_hash =
        crate::study::hex_sha256(study.executor.directory.display().to_string().as_bytes());
    format!("iuq-{clean}-{}", &dir_hash[..8])
}

/// The most runs the local executor makes at once: it keeps one thread per run, and an operating
/// system refuses threads long before a count that a study could mistype.
pub const MAX_LOCAL_PARALLEL: usize = 1024;

impl Campaign {
    /// Open the campaign of `study`: create its directory and store, write the worker
    /// specification, build the executor, and resume whatever an earlier coordinator left open.
    pub fn open(study: CampaignStudy, options: &CampaignOptions) -> Result<(Self, ResumeSummary)> {
        let directory = study.executor.directory.clone();
        std::fs::create_dir_all(&directory).map_err(|e| CampaignError::io(&directory, e))?;
        let directory =
            std::fs::canonicalize(&directory).map_err(|e| CampaignError::io(&directory, e))?;
        let lock = lock_campaign(&directory)?;
        let store = CampaignStore::open(&directory.join(STORE_FILE), &study)?;
        let spec_path = write_spec(&directory, &study.model)?;
        let compiled = CompiledSpec::new(study.model.clone())?;
        let max_parallel = options.max_parallel.or(study.executor.max_parallel);
        if study.executor.kind == ExecutorKind::Local
            && let Some(n) = max_parallel.filter(|&n| n > MAX_LOCAL_PARALLEL)
        {
            let key = if options.max_parallel.is_some() {
                "--max-parallel".to_string()
            } else {
                format!("{}: key `executor.max_parallel`", study.path.display())
            };
            return Err(CampaignError::BadInput(format!(
                "{key}: {n} runs at once is more than the local executor's {MAX_LOCAL_PARALLEL} (one thread each)"
            )));
        }
        let poll = Duration::from_secs_f64(
            options
                .poll_interval
                .unwrap_or(study.executor.poll_interval)
                .max(0.01),
        );
        let worker_command = || -> Result<Vec<String>> {
            if let Some(w) = options
                .worker_command
                .clone()
                .or_else(|| study.executor.worker.clone())
            {
                return Ok(w);
            }
            Err(CampaignError::BadInput(format!(
                "{}: key `executor.worker`: the {} executor needs the command that starts `iuq worker` on the compute nodes",
                study.path.display(),
                study.executor.kind.as_str()
            )))
        };
        let executor: Box<dyn Executor> = match study.executor.kind {
            ExecutorKind::Local => Box::new(LocalExecutor::new(
                compiled.clone(),
                max_parallel,
                options.in_process.clone(),
            )),
            ExecutorKind::Slurm => Box::new(SlurmExecutor::new(SlurmSettings {
                campaign_dir: directory.clone(),
                spec_path,
                worker_command: worker_command()?,
                job_name: job_name(&study),
                throttle: max_parallel,
                array_chunk: study.executor.array_chunk,
                sbatch_args: study.executor.submit_args.clone(),
                poll_interval: poll,
            })),
            ExecutorKind::Hyperqueue => Box::new(HyperQueueExecutor::new(HyperQueueSettings {
                hq: study
                    .executor
                    .hq
                    .clone()
                    .or_else(|| std::env::var("HQ_BIN").ok())
                    .unwrap_or_else(|| "hq".into()),
                campaign_dir: directory.clone(),
                spec_path,
                worker_command: worker_command()?,
                job_name: job_name(&study),
                submit_args: study.executor.submit_args.clone(),
                poll_interval: poll,
            })),
        };
        let mut campaign = Self {
            _lock: lock,
            study,
            store,
            compiled,
            executor,
            directory,
            session_start: None,
            finished_this_session: 0,
            start_watch: StartWatch::default(),
            interrupt: options.interrupt.clone(),
        };
        let summary = campaign.resume()?;
        Ok((campaign, summary))
    }

    /// The study.
    pub fn study(&self) -> &CampaignStudy {
        &self.study
    }

    /// The store.
    pub fn store(&self) -> &CampaignStore {
        &self.store
    }

    /// The store, for recording results derived from the runs
    /// ([`CampaignStore::record_derived_result`]); runs are changed through the campaign only.
    pub fn store_mut(&mut self) -> &mut CampaignStore {
        &mut self.store
    }

    /// The campaign directory.
    pub fn directory(&self) -> &Path {
        &self.directory
    }

    fn resume(&mut self) -> Result<ResumeSummary> {
        let mut summary = ResumeSummary {
            requeued: self.store.requeue_orphans()? as u64,
            restarted: self.store.restart_unstarted()? as u64,
            ..ResumeSummary::default()
        };
        let open = self.store.open_attempts()?;
        if open.is_empty() {
            return Ok(summary);
        }
        // Group the open attempts by task directory.
        let mut groups: BTreeMap<PathBuf, (String, Option<String>, SubmittedTask)> =
            BTreeMap::new();
        for a in open {
            let entry = groups.entry(a.directory.clone()).or_insert_with(|| {
                (
                    a.executor.clone(),
                    a.external_id.clone(),
                    SubmittedTask {
                        task: Task {
                            directory: a.directory.clone(),
                            runs: Vec::new(),
                        },
                        attempt_ids: Vec::new(),
                    },
                )
            });
            entry.2.task.runs.push(TaskRun {
                run_id: a.run_id,
                attempt: a.number,
                parameters: a.parameters,
            });
            entry.2.attempt_ids.push(a.attempt_id);
            if entry.1.is_none() {
                entry.1 = a.external_id;
            }
        }
        let mut events = Vec::new();
        let mut to_reattach = Vec::new();
        let mut foreign = 0;
        for (_, (executor, external_id, task)) in groups {
            if !task.task.directory.starts_with(&self.directory) {
                // A copy (or a moved) store names the run directories of the campaign it was
                // copied from, whose coordinator may still run them: reading results there or
                // stopping "orphans" would take or kill that campaign's runs.
                foreign += task.attempt_ids.len() as u64;
                events.extend(crate::executor::failure_events(
                    &task,
                    OutcomeKind::Lost,
                    &format!(
                        "its run directory {} is not in this campaign's directory {} (the store was copied or moved while the run was open); nothing there was read or stopped",
                        task.task.directory.display(),
                        self.directory.display()
                    ),
                ));
                continue;
            }
            if let Some(report) =
                read_report(&task.task.directory).filter(|r| report_matches(&task, r))
            {
                summary.ingested += task.attempt_ids.len() as u64;
                events.extend(report_events(&task, report));
            } else if executor == self.executor.kind().as_str() {
                to_reattach.push(OpenTask {
                    submitted: task,
                    external_id,
                });
            } else {
                events.extend(crate::executor::failure_events(
                    &task,
                    OutcomeKind::Lost,
                    &format!("submitted to the {executor} executor, which this study no longer uses, and left no result"),
                ));
            }
        }
        let reattach_count: u64 = to_reattach
            .iter()
            .map(|t| t.submitted.attempt_ids.len() as u64)
            .sum();
        let reattach_events = self.executor.reattach(to_reattach)?;
        let closed = reattach_events
            .iter()
            .filter(|e| matches!(e, ExecutorEvent::Finished { result, .. } if result.kind == OutcomeKind::Lost))
            .count() as u64;
        summary.lost = closed + foreign;
        summary.reattached = reattach_count.saturating_sub(
            reattach_events
                .iter()
                .filter(|e| matches!(e, ExecutorEvent::Finished { .. }))
                .count() as u64,
        );
        events.extend(reattach_events);
        let outputs = self.study.model.outputs.clone();
        let policy = self.study.executor.retry.clone();
        self.store.write(|w| {
            for e in &events {
                apply_event(w, e, &outputs, &policy)?;
            }
            Ok(())
        })?;
        Ok(summary)
    }

    /// Record a design (a batch of points) and return the run id of each point; identical
    /// vectors share a run, and a vector already in the store is not run again.
    pub fn add_points(&mut self, label: &str, points: &[Vec<f64>]) -> Result<Vec<i64>> {
        let dim = self.study.space.dimension();
        if let Some((i, p)) = points.iter().enumerate().find(|(_, p)| p.len() != dim) {
            return Err(CampaignError::BadInput(format!(
                "design `{label}`: point {i} has {} coordinates, the study has {dim} parameters",
                p.len()
            )));
        }
        self.store.add_design(label, points)
    }

    /// Run every pending run until all runs of the store are final, calling `observer` with the
    /// progress at most every `report_every`. Returns the final counts.
    ///
    /// An observer that answers [`Control::Stop`] stops the campaign as a raised [`Interrupt`]
    /// does: no more runs are submitted, the runs under way are filed as they end, and the call
    /// returns [`CampaignError::Interrupted`]. Run again, it goes on with the runs left pending.
    pub fn run(
        &mut self,
        report_every: Duration,
        observer: &mut dyn Observer<Progress>,
    ) -> Result<StatusCounts> {
        self.run_among(None, report_every, observer)
    }

    /// Run the pending runs among `run_ids` (and wait for any reattached from an earlier
    /// coordinator) until they are final; other pending runs of the store stay pending. A
    /// pipeline asks for the runs of its current design this way, so that the runs of a design it
    /// abandoned (an earlier posterior's check, stopped half-way) do not run before them.
    pub fn run_only(
        &mut self,
        run_ids: &[i64],
        report_every: Duration,
        observer: &mut dyn Observer<Progress>,
    ) -> Result<StatusCounts> {
        let among: std::collections::HashSet<i64> = run_ids.iter().copied().collect();
        self.run_among(Some(&among), report_every, observer)
    }

    fn run_among(
        &mut self,
        among: Option<&std::collections::HashSet<i64>>,
        report_every: Duration,
        observer: &mut dyn Observer<Progress>,
    ) -> Result<StatusCounts> {
        let start = *self.session_start.get_or_insert_with(Instant::now);
        // A run after a stop starts runs again (unless the interrupt is still raised).
        self.executor.resume_starting();
        let counted: Option<Vec<i64>> = among.map(sorted_ids);
        let counted = counted.as_deref();
        let runs_per_task = match self.study.model.kind {
            CommandKind::Command => 1,
            CommandKind::BatchCommand { batch_size, .. } => batch_size,
        };
        let outputs = self.study.model.outputs.clone();
        let policy = self.study.executor.retry.clone();
        let executor_name = self.executor.kind().as_str();
        let mut events: Vec<ExecutorEvent> = Vec::new();
        let mut external: Vec<(i64, String)> = Vec::new();
        let mut last_report: Option<Instant> = None;
        let mut cannot_start: Option<String> = None;
        let mut stop_asked = false;
        loop {
            let interrupted =
                stop_asked || self.interrupt.as_ref().is_some_and(Interrupt::is_raised);
            let stopping = interrupted || cannot_start.is_some();
            if stopping {
                self.executor.stop_starting();
            }
            let free = if stopping {
                0
            } else {
                self.executor
                    .capacity()
                    .saturating_sub(self.executor.in_flight())
            };
            let pending = if free > 0 {
                self.store
                    .pending_runs_among(among, free.saturating_mul(runs_per_task).min(100_000))?
            } else {
                Vec::new()
            };
            let directory = self.directory.clone();
            let spec = &self.study.model;
            let mut finished_now = 0u64;
            let watch = &mut self.start_watch;
            let tasks = self.store.write(|w| {
                for e in &events {
                    let disposition = apply_event(w, e, &outputs, &policy)?;
                    if let ExecutorEvent::Finished { result, .. } = e {
                        watch.observe(result, disposition);
                    }
                    if let Disposition::Succeeded | Disposition::Failed = disposition {
                        finished_now += 1;
                    }
                }
                for (attempt_id, id) in &external {
                    w.set_external_id(*attempt_id, id)?;
                }
                let mut tasks = Vec::new();
                for group in pending.chunks(runs_per_task.max(1)) {
                    let dir = task_directory(&directory, spec, group[0].run_id);
                    let mut task = SubmittedTask {
                        task: Task {
                            directory: dir.clone(),
                            runs: Vec::with_capacity(group.len()),
                        },
                        attempt_ids: Vec::with_capacity(group.len()),
                    };
                    for run in group {
                        let (attempt_id, number) =
                            w.begin_attempt(run.run_id, executor_name, &dir)?;
                        task.task.runs.push(TaskRun {
                            run_id: run.run_id,
                            attempt: number,
                            parameters: run.parameters.clone(),
                        });
                        task.attempt_ids.push(attempt_id);
                    }
                    tasks.push(task);
                }
                Ok(tasks)
            })?;
            self.finished_this_session += finished_now;
            events.clear();
            external.clear();
            let submitted_any = !tasks.is_empty();
            if submitted_any {
                external = self.executor.submit(tasks)?;
            }
            let due = last_report.is_none_or(|t| t.elapsed() >= report_every);
            if due {
                last_report = Some(Instant::now());
                stop_asked |= observer.observe(&self.progress_of(start, counted)?) == Control::Stop;
            }
            if interrupted && self.executor.in_flight() == 0 {
                observer.observe(&self.progress_of(start, counted)?);
                return Err(CampaignError::Interrupted);
            }
            if cannot_start.is_none() {
                cannot_start = self.start_watch.verdict();
            }
            if let Some(reason) = cannot_start.take_if(|_| self.executor.in_flight() == 0) {
                self.store.restart_unstarted()?;
                observer.observe(&self.progress_of(start, counted)?);
                return Err(CampaignError::BadInput(format!(
                    "{}: {reason}",
                    self.study.path.display()
                )));
            }
            if self.executor.in_flight() == 0 && !submitted_any {
                if self.store.pending_runs_among(among, 1)?.is_empty() {
                    if !external.is_empty() {
                        let ext = std::mem::take(&mut external);
                        self.store.write(|w| {
                            for (attempt_id, id) in &ext {
                                w.set_external_id(*attempt_id, id)?;
                            }
                            Ok(())
                        })?;
                    }
                    break;
                }
                continue;
            }
            if !external.is_empty() {
                // Record scheduler ids at once: a coordinator that dies now can reattach.
                let ext = std::mem::take(&mut external);
                self.store.write(|w| {
                    for (attempt_id, id) in &ext {
                        w.set_external_id(*attempt_id, id)?;
                    }
                    Ok(())
                })?;
            }
            events =
                self.executor
                    .wait(report_every.min(Duration::from_millis(if interrupted {
                        20
                    } else {
                        500
                    })))?;
        }
        let progress = self.progress_of(start, counted)?;
        observer.observe(&progress);
        Ok(progress.counts)
    }

    /// The current progress of the whole store.
    pub fn progress(&self, start: Instant) -> Result<Progress> {
        self.progress_of(start, None)
    }

    /// The current progress of the runs `run_ids` (all of the store's: `None`).
    fn progress_of(&self, start: Instant, run_ids: Option<&[i64]>) -> Result<Progress> {
        let counts = self.store.counts(run_ids)?;
        let elapsed = start.elapsed().as_secs_f64();
        let remaining = counts.pending + counts.queued + counts.running;
        let eta = (self.finished_this_session > 0 && elapsed > 0.0)
            .then(|| remaining as f64 * elapsed / self.finished_this_session as f64);
        Ok(Progress {
            counts,
            finished_this_session: self.finished_this_session,
            elapsed_seconds: elapsed,
            eta_seconds: if remaining == 0 { Some(0.0) } else { eta },
        })
    }

    /// Put failed runs back to pending (`failed`: model failures and other failures; `lost`:
    /// runs whose last attempt was lost). Returns how many.
    pub fn reset_for_retry(&mut self, failed: bool, lost: bool) -> Result<usize> {
        self.store.reset_for_retry(failed, lost)
    }

    /// Decode the outputs of every succeeded run again from its run directory with the study's
    /// current decoder, replacing what differs (see [`crate::redecode`]).
    pub fn redecode(&mut self) -> Result<crate::redecode::RedecodeSummary> {
        crate::redecode::redecode(&mut self.store, &self.study, &self.directory)
    }

    /// The executor's compiled model specification.
    pub fn compiled_spec(&self) -> &CompiledSpec {
        &self.compiled
    }
}

/// Apply one executor event to the store.
fn apply_event(
    w: &crate::store::StoreWriter<'_>,
    event: &ExecutorEvent,
    outputs: &[String],
    policy: &crate::retry_policy::RetryPolicy,
) -> Result<Disposition> {
    match event {
        ExecutorEvent::Started {
            attempt_id,
            external_id,
            host,
            started_at,
        } => {
            w.mark_started(
                *attempt_id,
                external_id.as_deref(),
                host.as_deref(),
                *started_at,
            )?;
            Ok(Disposition::Ignored)
        }
        ExecutorEvent::Finished {
            attempt_id,
            result,
            report,
        } => w.finish_attempt(*attempt_id, result, report.as_ref(), outputs, policy),
    }
}
