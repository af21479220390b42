//! The local executor: `max_parallel` worker threads (default: the number of cores), each
//! running one task at a time through [`crate::worker::execute_task`].
//!
//! The commands run in their own process groups, so they outlive a coordinator that is killed.
//! A coordinator that resumes the campaign finds them through the tasks' `status.json` (pid and
//! kernel start time, so a reused pid is never mistaken for them), kills their process groups
//! and declares those attempts lost; tasks whose `result.json` was written are ingested instead.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender, channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How long a run must be running before the executor reports it as started.
pub const STARTED_DELAY: Duration = Duration::from_millis(50);

/// Tasks queued per worker thread beyond the running one, so that a thread never waits for the
/// coordinator's commit before it starts its next task.
const QUEUE_DEPTH: usize = 3;

/// The same for a model evaluated in this process, whose runs may take microseconds: the
/// coordinator commits the results it has at each wake-up, so a deep queue lets one commit (one
/// flush to disk) ingest hundreds of runs instead of a handful. A queued task is started only
/// while the executor starts tasks, so an interrupt still stops after the running ones.
const IN_PROCESS_QUEUE_DEPTH: usize = 63;

use crate::error::Result;
use crate::executor::{
    Executor, ExecutorEvent, OpenTask, SubmittedTask, failure_events, report_events,
};
use crate::in_process::{SharedModel, execute_in_process};
use crate::outcome::{OutcomeKind, RunResult, TaskReport, host_name, unix_now};
use crate::study::ExecutorKind;
use crate::supervised_process::signal_group;
use crate::worker::{CompiledSpec, execute_task, process_start_ticks, read_status};

/// Runs tasks as processes on this machine.
pub struct LocalExecutor {
    capacity: usize,
    /// Tasks queued per worker thread beyond the running one.
    queue_depth: usize,
    in_flight: usize,
    /// `Started` events held back for [`STARTED_DELAY`]: runs that finish sooner are never
    /// reported as running, which saves one store commit per short run.
    held_started: Vec<(Instant, ExecutorEvent)>,
    tasks: Option<Sender<SubmittedTask>>,
    events: Receiver<(bool, Vec<ExecutorEvent>)>,
    threads: Vec<JoinHandle<()>>,
    /// Raised by [`Executor::stop_starting`]: the workers start no more tasks.
    stop_starting: Arc<AtomicBool>,
}

impl std::fmt::Debug for LocalExecutor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LocalExecutor")
            .field("capacity", &self.capacity)
            .field("in_flight", &self.in_flight)
            .finish()
    }
}

/// The number of cores of this machine.
pub fn default_parallelism() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

impl LocalExecutor {
    /// An executor running `max_parallel` tasks at once (default: the number of cores), as
    /// processes of the spec's command, or with `in_process` in this process.
    pub fn new(
        spec: CompiledSpec,
        max_parallel: Option<usize>,
        in_process: Option<SharedModel>,
    ) -> Self {
        let capacity = max_parallel.unwrap_or_else(default_parallelism).max(1);
        let (task_tx, task_rx) = channel::<SubmittedTask>();
        let (event_tx, event_rx) = channel();
        let task_rx = Arc::new(Mutex::new(task_rx));
        let spec = Arc::new(spec);
        let host = host_name();
        let stop_starting = Arc::new(AtomicBool::new(false));
        let threads = (0..capacity)
            .map(|_| {
                let task_rx = Arc::clone(&task_rx);
                let event_tx = event_tx.clone();
                let spec = Arc::clone(&spec);
                let host = host.clone();
                let in_process = in_process.clone();
                let stop_starting = Arc::clone(&stop_starting);
                std::thread::spawn(move || {
                    loop {
                        let next = match task_rx.lock() {
                            Ok(rx) => rx.recv(),
                            Err(_) => return,
                        };
                        let Ok(task) = next else { return };
                        let report = if stop_starting.load(Ordering::SeqCst) {
                            report_events(&task, not_started(&task, &host))
                        } else {
                            execute_task_with_start(
                                &spec,
                                in_process.as_ref(),
                                &task,
                                &event_tx,
                                &host,
                            )
                        };
                        if event_tx.send((true, report)).is_err() {
                            return;
                        }
                    }
                })
            })
            .collect();
        Self {
            capacity,
            queue_depth: if in_process.is_some() {
                IN_PROCESS_QUEUE_DEPTH
            } else {
                QUEUE_DEPTH
            },
            in_flight: 0,
            held_started: Vec::new(),
            tasks: Some(task_tx),
            events: event_rx,
            threads,
            stop_starting,
        }
    }
}

/// The report of a task the worker did not start: every run lost.
fn not_started(task: &SubmittedTask, host: &str) -> TaskReport {
    let now = unix_now();
    TaskReport {
        runs: task
            .task
            .runs
            .iter()
            .map(|run| {
                RunResult::failure(
                    run.run_id,
                    run.attempt,
                    OutcomeKind::Lost,
                    "interrupted before it started",
                )
            })
            .collect(),
        exit_code: None,
        signal: None,
        host: host.to_string(),
        pid: None,
        started_at: now,
        finished_at: now,
        stderr_tail: String::new(),
    }
}

fn execute_task_with_start(
    spec: &CompiledSpec,
    in_process: Option<&SharedModel>,
    task: &SubmittedTask,
    events: &Sender<(bool, Vec<ExecutorEvent>)>,
    host: &str,
) -> Vec<ExecutorEvent> {
    let started_at = unix_now();
    let started = task
        .attempt_ids
        .iter()
        .map(|&attempt_id| ExecutorEvent::Started {
            attempt_id,
            external_id: None,
            host: Some(host.to_string()),
            started_at,
        })
        .collect();
    let _ = events.send((false, started));
    let report = match in_process {
        Some(model) => execute_in_process(model.0.as_ref(), &task.task, spec.spec.outputs.len()),
        None => execute_task(spec, &task.task, false),
    };
    report_events(task, report)
}

impl LocalExecutor {
    /// File one message from a worker thread: hold `Started` events back, drop those whose
    /// attempt finished meanwhile.
    fn take(
        &mut self,
        (finished, events): (bool, Vec<ExecutorEvent>),
        out: &mut Vec<ExecutorEvent>,
    ) {
        if finished {
            self.in_flight = self.in_flight.saturating_sub(1);
        }
        for event in events {
            match event {
                ExecutorEvent::Started { .. } => self.held_started.push((Instant::now(), event)),
                ExecutorEvent::Finished { attempt_id, .. } => {
                    self.held_started.retain(|(_, e)| {
                        !matches!(e, ExecutorEvent::Started { attempt_id: a, .. } if *a == attempt_id)
                    });
                    out.push(event);
                }
            }
        }
    }
}

impl Executor for LocalExecutor {
    fn kind(&self) -> ExecutorKind {
        ExecutorKind::Local
    }

    fn capacity(&self) -> usize {
        self.capacity * (1 + self.queue_depth)
    }

    fn in_flight(&self) -> usize {
        self.in_flight
    }

    fn stop_starting(&mut self) {
        self.stop_starting.store(true, Ordering::SeqCst);
    }

    fn resume_starting(&mut self) {
        self.stop_starting.store(false, Ordering::SeqCst);
    }

    fn submit(&mut self, tasks: Vec<SubmittedTask>) -> Result<Vec<(i64, String)>> {
        let sender = self.tasks.as_ref().ok_or_else(|| {
            crate::error::CampaignError::executor("local", "the executor is shut down")
        })?;
        for task in tasks {
            sender.send(task).map_err(|_| {
                crate::error::CampaignError::executor("local", "the worker threads stopped")
            })?;
            self.in_flight += 1;
        }
        Ok(Vec::new())
    }

    fn wait(&mut self, timeout: Duration) -> Result<Vec<ExecutorEvent>> {
        let mut out = Vec::new();
        if self.in_flight == 0 && self.held_started.is_empty() {
            return Ok(out);
        }
        let deadline = Instant::now() + timeout;
        loop {
            let now = Instant::now();
            let next_release = self.held_started.first().map(|(t, _)| *t + STARTED_DELAY);
            let until = next_release.map_or(deadline, |r| r.min(deadline));
            match self
                .events
                .recv_timeout(until.saturating_duration_since(now))
            {
                Ok(message) => {
                    self.take(message, &mut out);
                    while let Ok(message) = self.events.try_recv() {
                        self.take(message, &mut out);
                    }
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(crate::error::CampaignError::executor(
                        "local",
                        "the worker threads stopped",
                    ));
                }
            }
            let now = Instant::now();
            while self
                .held_started
                .first()
                .is_some_and(|(t, _)| now >= *t + STARTED_DELAY)
            {
                out.push(self.held_started.remove(0).1);
            }
            if !out.is_empty() || now >= deadline {
                return Ok(out);
            }
        }
    }

    fn reattach(&mut self, tasks: Vec<OpenTask>) -> Result<Vec<ExecutorEvent>> {
        let mut events = Vec::new();
        for open in tasks {
            let task = &open.submitted;
            let status = read_status(&task.task.directory);
            let killed = status.as_ref().and_then(|s| {
                let pid = s.pid?;
                let attempt_matches = task
                    .task
                    .runs
                    .iter()
                    .all(|r| s.runs.contains(&(r.run_id, r.attempt)));
                (attempt_matches
                    && s.pid_start.is_some()
                    && process_start_ticks(pid) == s.pid_start)
                    .then(|| {
                        signal_group(pid, libc::SIGKILL);
                        pid
                    })
            });
            let reason = match killed {
                Some(pid) => format!(
                    "the coordinator stopped while the run was executing; its orphaned process group {pid} was killed"
                ),
                None => {
                    "the coordinator stopped while the run was executing, and it left no result"
                        .to_string()
                }
            };
            events.extend(failure_events(task, OutcomeKind::Lost, &reason));
        }
        Ok(events)
    }
}

impl Drop for LocalExecutor {
    fn drop(&mut self) {
        self.tasks = None;
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}
