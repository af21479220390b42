//! Stopping a pipeline that is busy between its checks (`PipelineOptions::interrupt_grace`):
//! `run` returns `StudyError::Interrupted` once the grace is over, not when the pipeline reaches
//! its next check; the campaign starts none of its queued runs after the stop (the local
//! executor's `stop_starting`); and the next `run` in the process waits for the pipeline left
//! behind before it touches the same campaign store.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use iuq_campaign::{InProcessError, InProcessModel, InProcessOutputs, SharedModel};
use iuq_core::{Control, Observer};
use iuq_study::pipeline::{PipelineEvent, PipelineOptions, run};
use iuq_study::{Study, StudyError};

const X: [f64; 5] = [0.5, 1.0, 2.0, 4.0, 8.0];

/// y = a·exp(−k x) at the data's x, each run taking `delay`.
struct SlowDecay {
    delay: Duration,
    calls: AtomicUsize,
}

impl InProcessModel for SlowDecay {
    fn evaluate(&self, p: &[f64]) -> Result<InProcessOutputs, InProcessError> {
        self.calls.fetch_add(1, Ordering::SeqCst);
        std::thread::sleep(self.delay);
        Ok((X.iter().map(|x| p[0] * (-p[1] * x).exp()).collect(), None))
    }
}

fn study_in(dir: &Path) -> PathBuf {
    let mut data = String::from("x,y,y_err\n");
    for x in X {
        data.push_str(&format!("{x},{},0.05\n", 2.0 * (-0.3 * x).exp()));
    }
    std::fs::write(dir.join("data.csv"), data).unwrap();
    let path = dir.join("study.toml");
    std::fs::write(
        &path,
        r#"name = "interrupt"
[parameters]
a = { uniform = [0.5, 4.0] }
k = { uniform = [0.05, 0.8] }
[likelihood]
data = { file = "data.csv", x = "x", y = "y", y_err = "y_err" }
modelling_error = false
[model]
kind = "callable"
description = "a slow decay"
[surrogate]
design = { kind = "lhs", n = 4, seed = 1 }
test = { kind = "sobol", n = 0 }
"#,
    )
    .unwrap();
    path
}

fn options(dir: &Path, model: &Arc<SlowDecay>, grace: Option<Duration>) -> PipelineOptions {
    PipelineOptions {
        out: dir.join("report"),
        max_parallel: Some(1),
        model_posterior: false,
        fresh: false,
        runs_only: true,
        recompute_rounds: false,
        callable: Some(SharedModel(model.clone())),
        low_fidelity_callable: None,
        interrupt_grace: grace,
    }
}

/// Asks the pipeline to stop once `stop_once_called` has been called (inside its first run),
/// and keeps the pipeline's messages.
struct StopInsideFirstRun {
    stop_once_called: Option<Arc<SlowDecay>>,
    messages: Arc<Mutex<Vec<String>>>,
}

impl Observer<PipelineEvent<'_>> for StopInsideFirstRun {
    fn observe(&mut self, event: &PipelineEvent<'_>) -> Control {
        if let PipelineEvent::Message(line) = event {
            self.messages.lock().unwrap().push(line.to_string());
        }
        if self
            .stop_once_called
            .as_ref()
            .is_some_and(|m| m.calls.load(Ordering::SeqCst) > 0)
        {
            Control::Stop
        } else {
            Control::Continue
        }
    }
}

#[test]
fn a_busy_pipeline_returns_after_the_grace_and_the_next_run_waits_for_it() {
    let dir = std::env::temp_dir().join(format!("iuq-study-interrupt-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let study = Study::load(&study_in(&dir)).unwrap();

    // Each run takes 2 s and the pipeline checks only between runs: with a grace of 50 ms, run
    // returns long before the run under way ends.
    let slow = Arc::new(SlowDecay {
        delay: Duration::from_secs(2),
        calls: AtomicUsize::new(0),
    });
    let messages = Arc::new(Mutex::new(Vec::new()));
    let mut observer = StopInsideFirstRun {
        stop_once_called: Some(slow.clone()),
        messages: messages.clone(),
    };
    let started = Instant::now();
    let result = run(
        &study,
        &options(&dir, &slow, Some(Duration::from_millis(50))),
        &mut observer,
    );
    let elapsed = started.elapsed();
    assert!(matches!(result, Err(StudyError::Interrupted)), "{result:?}");
    // The stop is asked inside the first run; 50 ms of grace later run returns: far below the
    // 2 s of that run (which started a few milliseconds after the pipeline did).
    assert!(elapsed < Duration::from_secs(1), "{elapsed:?}");

    // The next run waits for that pipeline (still inside its 2 s run), then makes the runs that
    // are missing with a fast model.
    let fast = Arc::new(SlowDecay {
        delay: Duration::ZERO,
        calls: AtomicUsize::new(0),
    });
    let mut observer = StopInsideFirstRun {
        stop_once_called: None,
        messages: messages.clone(),
    };
    let outcome = run(&study, &options(&dir, &fast, None), &mut observer).unwrap();
    assert_eq!(outcome.runs, 4);
    assert!(
        messages
            .lock()
            .unwrap()
            .iter()
            .any(|m| m.contains("waiting for the interrupted pipeline")),
        "{:?}",
        messages.lock().unwrap()
    );
    // The interrupted pipeline made its one run (whichever way it was filed); the rest fell to
    // the fast model, and no run was made twice at the same time.
    assert_eq!(slow.calls.load(Ordering::SeqCst), 1);
    assert!((3..=4).contains(&fast.calls.load(Ordering::SeqCst)));
    let _ = std::fs::remove_dir_all(&dir);
}
