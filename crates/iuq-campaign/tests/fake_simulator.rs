//! A fake simulator driven by its parameters — it succeeds, sleeps, exits non-zero, kills itself
//! with a signal, hangs past the timeout, writes garbage, writes NaN or writes nothing — run as a
//! campaign through the batch `Model` interface: every outcome is recorded with its reason, the
//! campaign goes on, and failures reach the caller as failures.

use std::path::{Path, PathBuf};

use iuq_campaign::{
    Campaign, CampaignError, CampaignModel, CampaignOptions, CampaignStudy, Progress,
};
use iuq_core::{Control, Model};

/// The fake simulator (modes 0–9, see the script).
const FAKE_SIMULATOR: &str = include_str!("fixtures/fake-simulator.sh");

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("iuq-campaign-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn write_study(dir: &Path, extra_model: &str) -> PathBuf {
    let sim = dir.join("sim.sh");
    std::fs::write(&sim, FAKE_SIMULATOR).unwrap();
    std::process::Command::new("chmod")
        .arg("+x")
        .arg(&sim)
        .status()
        .unwrap();
    std::fs::write(
        dir.join("input.cfg"),
        "mode = {{ mode }}\nsteps = {{ steps }}\nrun = {{ run_id }}\n",
    )
    .unwrap();
    let study = format!(
        r#"
name = "fake"
[parameters]
mode = {{ uniform = [0, 8] }}
x = {{ uniform = [0, 10] }}
[model]
kind = "command"
command = ["./sim.sh", "{{{{ mode }}}}", "{{{{ x }}}}"]
templates = ["input.cfg"]
derived = {{ steps = "ceil(100 / (x + 1))" }}
outputs = ["f", "g"]
output = {{ file = "result.json", format = "json" }}
timeout = "1s"
kill_grace = "300ms"
{extra_model}
[executor]
max_parallel = 4
"#
    );
    let path = dir.join("study.toml");
    std::fs::write(&path, study).unwrap();
    path
}

fn open(path: &Path) -> Campaign {
    let study = CampaignStudy::load(path).unwrap();
    Campaign::open(study, &CampaignOptions::default())
        .unwrap()
        .0
}

/// A connection of the test's own to the campaign store `store` (the store keeps its own
/// private), to look at its tables.
fn sql(store: &iuq_campaign::CampaignStore) -> rusqlite::Connection {
    rusqlite::Connection::open(store.path()).unwrap()
}

#[test]
fn every_outcome_is_recorded_with_its_reason_and_failures_reach_the_caller() {
    let dir = scratch("outcomes");
    let path = write_study(&dir, "");
    let model = CampaignModel::new(open(&path));
    assert_eq!(model.input_names(), ["mode", "x"]);
    assert_eq!(model.output_names(), ["f", "g"]);
    let points: Vec<Vec<f64>> = (0..8).map(|m| vec![m as f64, 0.5 + m as f64]).collect();
    let outcomes = model.evaluate_batch(&points).unwrap();
    assert_eq!(outcomes.len(), 8);
    let ok = outcomes[0].as_ref().unwrap();
    assert_eq!(ok.outputs, vec![0.5, 1.0]);
    // Only g has a std; f, without one, has no computational uncertainty stated: 0.
    assert_eq!(ok.computational_std, Some(vec![0.0, 0.5]));
    assert_eq!(outcomes[1].as_ref().unwrap().outputs, vec![1.5, 1.0]);
    let reason = |k: usize| outcomes[k].as_ref().unwrap_err().reason.clone();
    assert!(
        reason(2).contains("exited with status 3") && reason(2).contains("solver diverged"),
        "{}",
        reason(2)
    );
    assert!(reason(3).contains("SIGSEGV"), "{}", reason(3));
    assert!(
        reason(4).contains("timeout") && reason(4).contains("SIGKILL"),
        "{}",
        reason(4)
    );
    assert!(reason(5).contains("not valid JSON"), "{}", reason(5));
    assert!(reason(6).contains("not finite"), "{}", reason(6));
    assert!(reason(7).contains("not written"), "{}", reason(7));

    let campaign = model.into_campaign().unwrap();
    let store = campaign.store();
    let kinds: Vec<AttemptRow> = sql(store)
        .prepare("SELECT run_id, outcome_kind, exit_code, signal, COALESCE(stderr_tail, '') FROM attempts ORDER BY run_id")
        .unwrap()
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?, r.get(4)?)))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    let names: Vec<&str> = kinds.iter().map(|k| k.1.as_str()).collect();
    assert_eq!(
        names,
        [
            "succeeded",
            "succeeded",
            "exit_status",
            "signal",
            "timeout",
            "bad_output",
            "non_finite",
            "missing_output"
        ]
    );
    assert_eq!(kinds[2].2, Some(3));
    assert!(kinds[2].4.contains("solver diverged"));
    assert_eq!(kinds[3].3, Some(libc_sigsegv()));
    assert_eq!(store.integrity_check().unwrap(), "ok");

    // The run directory holds params.json and the filled template.
    let run1 = campaign.directory().join("runs/000001");
    let params: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run1.join("params.json")).unwrap()).unwrap();
    assert_eq!(params["x"], 0.5);
    assert_eq!(params["steps"], 67.0);
    assert_eq!(params["run_id"], 1);
    assert_eq!(
        std::fs::read_to_string(run1.join("input.cfg")).unwrap(),
        "mode = 0\nsteps = 67\nrun = 1\n"
    );
    assert!(run1.join("iuq-result.json").exists() && run1.join("iuq-status.json").exists());
    assert!(
        !run1.join("iuq-stdout.log").exists(),
        "a silent run leaves no log files"
    );
    let run3 = campaign.directory().join("runs/000003");
    assert!(
        std::fs::read_to_string(run3.join("iuq-stderr.log"))
            .unwrap()
            .contains("solver diverged")
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `(run_id, outcome_kind, exit_code, signal, stderr_tail)` of an attempt.
type AttemptRow = (i64, String, Option<i64>, Option<i64>, String);

fn libc_sigsegv() -> i64 {
    11
}

#[test]
fn identical_vectors_are_not_run_twice_across_batches_and_sessions() {
    let dir = scratch("dedup");
    let path = write_study(&dir, "");
    let model = CampaignModel::new(open(&path));
    let p = vec![
        vec![0.0, 1.0],
        vec![0.0, 2.0],
        vec![0.0, 1.0],
        vec![2.0, 1.0],
    ];
    let first = model.evaluate_batch(&p).unwrap();
    assert_eq!(first[0], first[2]);
    assert!(first[3].is_err());
    drop(model);
    // A new coordinator on the same store: nothing runs again, failures included.
    let model = CampaignModel::new(open(&path));
    let second = model
        .evaluate_batch(&[vec![0.0, 2.0], vec![2.0, 1.0], vec![0.0, 3.0]])
        .unwrap();
    assert_eq!(second[0], first[1]);
    assert_eq!(second[1], first[3]);
    assert_eq!(second[2].as_ref().unwrap().outputs[0], 3.0);
    let campaign = model.into_campaign().unwrap();
    let attempts: i64 = sql(campaign.store())
        .query_row("SELECT COUNT(*) FROM attempts", [], |r| r.get(0))
        .unwrap();
    assert_eq!(attempts, 4);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_run_whose_stored_parameters_do_not_parse_is_an_error_not_a_run_without_parameters() {
    let dir = scratch("tampered");
    let path = write_study(&dir, "");
    let mut campaign = open(&path);
    campaign.add_points("design", &[vec![0.0, 4.0]]).unwrap();
    sql(campaign.store())
        .execute("UPDATE runs SET parameters = 'four'", [])
        .unwrap();
    let error = campaign
        .run(std::time::Duration::from_secs(60), &mut |_: &Progress| {
            Control::Continue
        })
        .unwrap_err()
        .to_string();
    assert!(
        error.contains("`four` are not a JSON array of numbers"),
        "{error}"
    );
    // Nothing ran: no attempt, no run directory.
    let attempts: i64 = sql(campaign.store())
        .query_row("SELECT COUNT(*) FROM attempts", [], |r| r.get(0))
        .unwrap();
    assert_eq!(attempts, 0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_batch_runs_only_its_own_runs_and_leaves_an_abandoned_design_pending() {
    let dir = scratch("only");
    let path = write_study(&dir, "");
    // A design recorded by an earlier coordinator that stopped before running it.
    let mut campaign = open(&path);
    campaign
        .add_points("abandoned", &[vec![0.0, 7.0], vec![0.0, 8.0]])
        .unwrap();
    let model = CampaignModel::new(campaign);
    let outcomes = model.evaluate_batch(&[vec![0.0, 1.0]]).unwrap();
    assert_eq!(outcomes[0].as_ref().unwrap().outputs[0], 1.0);
    let campaign = model.into_campaign().unwrap();
    let counts = campaign.store().counts(None).unwrap();
    assert_eq!((counts.succeeded, counts.pending), (1, 2));
    // Asked for later, an abandoned run runs then.
    let model = CampaignModel::new(campaign);
    let later = model.evaluate_batch(&[vec![0.0, 8.0]]).unwrap();
    assert_eq!(later[0].as_ref().unwrap().outputs[0], 8.0);
    let mut campaign = model.into_campaign().unwrap();
    let counts = campaign.store().counts(None).unwrap();
    assert_eq!((counts.succeeded, counts.pending), (2, 1));
    // The progress of a batch counts its own runs (one stored, one new), not the abandoned
    // run left pending: its ETA is the batch's.
    let ids = campaign
        .add_points("progress", &[vec![0.0, 1.0], vec![0.0, 2.0]])
        .unwrap();
    let mut seen = Vec::new();
    campaign
        .run_only(&ids, std::time::Duration::ZERO, &mut |p: &Progress| {
            seen.push(p.clone());
            Control::Continue
        })
        .unwrap();
    assert!(!seen.is_empty());
    for p in &seen {
        assert_eq!(p.counts.total(), 2, "{p:?}");
        assert_eq!(
            p.counts.pending + p.counts.succeeded + p.counts.queued + p.counts.running,
            2
        );
    }
    let last = seen.last().unwrap();
    assert_eq!((last.counts.succeeded, last.eta_seconds), (2, Some(0.0)));
    let whole = campaign.progress(std::time::Instant::now()).unwrap();
    assert_eq!((whole.counts.total(), whole.counts.pending), (4, 1));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn batch_command_reads_a_csv_of_vectors_and_writes_a_csv_of_outputs() {
    let dir = scratch("batch");
    let script = r#"#!/bin/sh
# inputs.csv: run_id,a,b,twice ; outputs.csv: f,error (a row with a < 0 fails)
awk -F, 'NR==1 {print "f,error"; next} { if ($2 < 0) print ",negative a"; else if ($2 > 100) print "nan,"; else print ($2 + $3 + $4) "," }' inputs.csv > outputs.csv
"#;
    std::fs::write(dir.join("vec.sh"), script).unwrap();
    std::process::Command::new("chmod")
        .arg("+x")
        .arg(dir.join("vec.sh"))
        .status()
        .unwrap();
    let study = r#"
name = "vectorised"
[parameters]
a = { uniform = [-1000, 1000] }
b = { uniform = [0, 1] }
[model]
kind = "batch-command"
command = ["./vec.sh"]
derived = { twice = "2 * b" }
outputs = ["f"]
batch_size = 3
[executor]
max_parallel = 2
"#;
    let path = dir.join("study.toml");
    std::fs::write(&path, study).unwrap();
    let model = CampaignModel::new(open(&path));
    let points = vec![
        vec![1.0, 0.5],
        vec![2.0, 0.25],
        vec![-1.0, 0.5],
        vec![200.0, 0.5],
        vec![3.0, 0.0],
    ];
    let out = model.evaluate_batch(&points).unwrap();
    assert_eq!(out[0].as_ref().unwrap().outputs, vec![2.5]);
    assert_eq!(out[1].as_ref().unwrap().outputs, vec![2.75]);
    assert!(out[2].as_ref().unwrap_err().reason.contains("negative a"));
    assert!(out[3].as_ref().unwrap_err().reason.contains("not finite"));
    assert_eq!(out[4].as_ref().unwrap().outputs, vec![3.0]);
    let campaign = model.into_campaign().unwrap();
    assert!(
        campaign
            .directory()
            .join("batches/000001/inputs.csv")
            .exists()
    );
    assert!(
        campaign
            .directory()
            .join("batches/000004/outputs.csv")
            .exists()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_command_that_cannot_start_is_retried_as_an_infrastructure_failure() {
    let dir = scratch("spawn");
    let study = r#"
name = "missing"
[parameters]
x = { uniform = [0, 1] }
[model]
kind = "command"
command = ["/nonexistent/simulator"]
outputs = ["f"]
output = { file = "out.json", format = "json" }
[executor]
retry = { max_attempts = 2 }
"#;
    let path = dir.join("study.toml");
    std::fs::write(&path, study).unwrap();
    let model = CampaignModel::new(open(&path));
    let out = model.evaluate_batch(&[vec![0.5]]).unwrap();
    assert!(out[0].as_ref().unwrap_err().reason.contains("cannot start"));
    let campaign = model.into_campaign().unwrap();
    let attempts: i64 = sql(campaign.store())
        .query_row(
            "SELECT COUNT(*) FROM attempts WHERE outcome_kind = 'spawn_failed'",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(
        attempts, 2,
        "retried once by the default policy, then failed"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn only_one_coordinator_runs_a_campaign_at_a_time() {
    let dir = scratch("lock");
    let path = write_study(&dir, "");
    let first = open(&path);
    let study = CampaignStudy::load(&path).unwrap();
    let e = Campaign::open(study, &CampaignOptions::default()).unwrap_err();
    assert!(
        e.is_bad_input() && e.to_string().contains("another coordinator"),
        "{e}"
    );
    drop(first);
    let study = CampaignStudy::load(&path).unwrap();
    assert!(Campaign::open(study, &CampaignOptions::default()).is_ok());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_observer_that_answers_stop_stops_the_campaign_and_files_the_runs_under_way() {
    let dir = scratch("observer-stop");
    let path = write_study(&dir, "");
    let text = std::fs::read_to_string(&path)
        .unwrap()
        .replace("max_parallel = 4", "max_parallel = 2");
    std::fs::write(&path, text).unwrap();
    let mut campaign = open(&path);
    // Mode 8 sleeps 0.4 s. The observer answers Stop at the first report that shows a run under
    // way (reports come at every pass of the loop: `report_every` is zero).
    let points: Vec<Vec<f64>> = (0..6).map(|i| vec![8.0, i as f64]).collect();
    campaign.add_points("slow", &points).unwrap();
    let mut calls = 0;
    let error = campaign
        .run(std::time::Duration::ZERO, &mut |p: &Progress| {
            calls += 1;
            if p.counts.running > 0 {
                Control::Stop
            } else {
                Control::Continue
            }
        })
        .unwrap_err();
    assert!(matches!(error, CampaignError::Interrupted), "{error}");
    let counts = campaign.store().counts(None).unwrap();
    // The runs under way (at least the one seen, at most `max_parallel` = 2) were waited for
    // and stored; the others never started.
    assert!((1..=2).contains(&counts.succeeded), "{counts:?}");
    assert_eq!(
        (
            counts.succeeded + counts.pending,
            counts.running,
            counts.queued
        ),
        (6, 0, 0),
        "{counts:?}"
    );
    assert!(calls >= 2, "{calls}");
    // Run again with an observer that goes on, the same campaign runs the rest.
    let done = campaign
        .run(std::time::Duration::ZERO, &mut |_: &Progress| {
            Control::Continue
        })
        .unwrap();
    assert_eq!((done.succeeded, done.pending), (6, 0), "{done:?}");
    let _ = std::fs::remove_dir_all(&dir);
}
