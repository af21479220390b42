//! End-to-end tests of `iuq run`, `iuq status`, `iuq retry`, `iuq redecode`, `iuq export` and
//! `iuq worker`:
//! real processes, a fake simulator driven by its parameters, a coordinator killed with SIGKILL
//! in the middle of a campaign, and fake `sbatch`/`squeue`/`scontrol` and `hq` programs on PATH
//! (the HyperQueue one prints the JSON shapes of `tests/fixtures/hq` in iuq-campaign).

use crate::common::{json_of, scratch};

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

/// The fake simulator of the campaign tests (modes 0–9, see the script).
const FAKE_SIMULATOR: &str = include_str!("../../iuq-campaign/tests/fixtures/fake-simulator.sh");

fn iuq(args: &[&str]) -> Output {
    iuq_with_path(args, None)
}

fn iuq_with_path(args: &[&str], extra_path: Option<(&Path, &Path)>) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_iuq"));
    c.args(args);
    if let Some((bin, state)) = extra_path {
        let path = format!(
            "{}:{}",
            bin.display(),
            std::env::var("PATH").unwrap_or_default()
        );
        c.env("PATH", path).env("FAKE_SCHED_DIR", state);
    }
    c.output().expect("the iuq binary runs")
}

fn executable(path: &Path, text: &str) {
    std::fs::write(path, text).unwrap();
    Command::new("chmod").arg("+x").arg(path).status().unwrap();
}

/// A study of the fake simulator over the points `(mode, x)`.
fn study(dir: &Path, points: &[(u32, f64)], executor: &str) -> PathBuf {
    executable(&dir.join("sim.sh"), FAKE_SIMULATOR);
    let mut csv = String::from("mode,x\n");
    for (m, x) in points {
        csv.push_str(&format!("{m},{x}\n"));
    }
    std::fs::write(dir.join("points.csv"), csv).unwrap();
    let text = format!(
        r#"name = "fake"
[parameters]
mode = {{ uniform = [0, 10] }}
x = {{ uniform = [0, 1000] }}
[model]
kind = "command"
command = ["./sim.sh", "{{{{ mode }}}}", "{{{{ x }}}}"]
outputs = ["f"]
output = {{ file = "result.json", format = "json" }}
timeout = "1s"
kill_grace = "200ms"
[design]
kind = "file"
file = "points.csv"
[executor]
{executor}
"#
    );
    let path = dir.join("study.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn store_of(dir: &Path) -> iuq_campaign::CampaignStore {
    iuq_campaign::CampaignStore::open_existing(&dir.join("study.campaign/campaign.sqlite")).unwrap()
}

/// A connection of the test's own to the campaign store in `dir` (the store keeps its own
/// private), to look at its tables.
fn store_sql(dir: &Path) -> rusqlite::Connection {
    rusqlite::Connection::open(dir.join("study.campaign/campaign.sqlite")).unwrap()
}

/// A connection of the test's own to the campaign store `store` (the store keeps its own
/// private), to look at its tables.
fn sql(store: &iuq_campaign::CampaignStore) -> rusqlite::Connection {
    rusqlite::Connection::open(store.path()).unwrap()
}

#[test]
fn run_status_export_and_retry_of_a_misbehaving_simulator() {
    let dir = scratch("cli-campaign", "verbs");
    let points: Vec<(u32, f64)> = (0..8)
        .filter(|m| *m != 1)
        .map(|m| (m, m as f64 + 0.5))
        .collect();
    let path = study(&dir, &points, "max_parallel = 3");
    let p = path.to_str().unwrap();
    let o = iuq(&["run", p, "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json_of(&o);
    assert_eq!(v["counts"]["succeeded"], 1);
    assert_eq!(v["counts"]["failed"], 6);
    // Without a terminal, progress goes to stderr as log lines.
    assert!(String::from_utf8_lossy(&o.stderr).contains("campaign fake: "));

    let v = json_of(&iuq(&["status", p, "--json"]));
    assert_eq!(v["total"], 7);
    let failures = v["failures"].as_array().unwrap();
    let kinds: Vec<&str> = failures
        .iter()
        .map(|f| f["kind"].as_str().unwrap())
        .collect();
    assert_eq!(
        kinds,
        [
            "exit_status",
            "signal",
            "timeout",
            "bad_output",
            "non_finite",
            "missing_output"
        ]
    );
    assert!(
        failures[0]["reason"]
            .as_str()
            .unwrap()
            .contains("solver diverged")
    );
    assert_eq!(failures[0]["parameters"]["mode"], 2.0);
    let text = String::from_utf8_lossy(&iuq(&["status", p]).stdout).to_string();
    assert!(text.contains("killed by SIGSEGV"), "{text}");

    let csv_path = dir.join("runs.csv");
    let o = iuq(&["export", p, "--out", csv_path.to_str().unwrap()]);
    assert!(o.status.success());
    let csv = std::fs::read_to_string(&csv_path).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next().unwrap(),
        "run_id,status,mode,x,f,attempts,outcome,reason"
    );
    assert!(
        lines
            .next()
            .unwrap()
            .starts_with("1,succeeded,0.0,0.5,0.5,1,succeeded,")
    );
    let v = json_of(&iuq(&["export", p, "--json"]));
    assert_eq!(v.as_array().unwrap().len(), 7);
    assert_eq!(v[0]["f"], 0.5);
    assert_eq!(v[1]["f"], Value::Null);

    // A second `iuq run` runs nothing again.
    let v = json_of(&iuq(&["run", p, "--json"]));
    assert_eq!(v["total"], 7);
    // `iuq retry --failed` runs the failures again (and they fail again, deterministically).
    let v = json_of(&iuq(&["retry", p, "--failed", "--json"]));
    assert_eq!(v["retried"], 6);
    assert_eq!(v["counts"]["failed"], 6);
    let attempts: i64 = store_sql(&dir)
        .query_row("SELECT COUNT(*) FROM attempts", [], |r| r.get(0))
        .unwrap();
    assert_eq!(attempts, 13);
    let v = json_of(&iuq(&["retry", p, "--lost", "--json"]));
    assert_eq!(v["retried"], 0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn status_gives_what_each_designs_runs_cost_since_it_was_recorded() {
    let dir = scratch("cli-campaign", "design-time");
    let path = study(&dir, &[(8, 1.0), (8, 2.0)], "max_parallel = 1");
    let p = path.to_str().unwrap();
    assert!(iuq(&["run", p]).status.success());
    // A later design: one point already run (reused: it costs this design nothing) and a new one.
    let ids = store_of(&dir)
        .add_design("later", &[vec![8.0, 2.0], vec![8.0, 3.0]])
        .unwrap();
    assert!(iuq(&["run", p]).status.success());
    // And one recorded but not run yet.
    store_of(&dir)
        .add_design("waiting", &[vec![8.0, 4.0]])
        .unwrap();
    // Each attempt's start and finish, straight from the store.
    let attempt = |run_id: i64| -> (f64, f64) {
        store_sql(&dir)
            .query_row(
                "SELECT started_at, finished_at FROM attempts WHERE run_id = ?1",
                [run_id],
                |r| Ok((r.get(0)?, r.get(1)?)),
            )
            .unwrap()
    };
    let (first, second, new) = (attempt(ids[0] - 1), attempt(ids[0]), attempt(ids[1]));
    let v = json_of(&iuq(&["status", p, "--json"]));
    let designs = v["designs"].as_array().unwrap();
    assert_eq!(designs.len(), 3, "{v}");
    let number = |d: &Value, key: &str| d[key].as_f64().unwrap();
    // Both runs of the first design were made for it, one after the other.
    let d = &designs[0];
    let both = (first.1 - first.0) + (second.1 - second.0);
    assert!((number(d, "run_seconds") - both).abs() < 1e-9, "{d}");
    assert!(number(d, "run_seconds") >= 0.8, "two runs of 0.4 s: {d}");
    assert_eq!(number(d, "first_started_at"), first.0);
    assert_eq!(number(d, "last_finished_at"), second.1);
    // The later design paid for its new run only.
    let d = &designs[1];
    assert!(
        (number(d, "run_seconds") - (new.1 - new.0)).abs() < 1e-9,
        "{d}"
    );
    assert_eq!(number(d, "first_started_at"), new.0);
    assert_eq!(number(d, "last_finished_at"), new.1);
    // Nothing run for the waiting one; the text names what the open design has cost so far.
    let d = &designs[2];
    assert_eq!(number(d, "run_seconds"), 0.0);
    assert!(
        d["first_started_at"].is_null() && d["last_finished_at"].is_null(),
        "{d}"
    );
    let text = String::from_utf8_lossy(&iuq(&["status", p]).stdout).to_string();
    assert!(
        text.contains("`waiting`: 1 points, 0 succeeded, 0 failed, 0 cancelled, 1 pending, 0 queued or running\n")
            || text.ends_with("`waiting`: 1 points, 0 succeeded, 0 failed, 0 cancelled, 1 pending, 0 queued or running"),
        "{text}"
    );
    assert!(iuq(&["run", p]).status.success());
    let v = json_of(&iuq(&["status", p, "--json"]));
    let d = &v["designs"][2];
    assert!(number(d, "run_seconds") >= 0.4, "{d}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn cancel_sets_an_abandoned_designs_pending_runs_aside_until_a_design_asks_again() {
    let dir = scratch("cli-campaign", "cancel");
    let path = study(&dir, &[(0, 1.0), (0, 2.0)], "max_parallel = 2");
    let p = path.to_str().unwrap();
    assert!(iuq(&["run", p]).status.success());
    // A design a pipeline recorded and then abandoned: two new points and one already run.
    let abandoned = {
        let mut store = store_of(&dir);
        store
            .add_design(
                "abandoned",
                &[vec![0.0, 7.0], vec![0.0, 8.0], vec![0.0, 1.0]],
            )
            .unwrap();
        store.design_summaries().unwrap().last().unwrap().id
    };
    let v = json_of(&iuq(&["status", p, "--json"]));
    let designs = v["designs"].as_array().unwrap();
    assert_eq!(designs.len(), 2, "{v}");
    assert_eq!(designs[1]["id"], abandoned);
    assert_eq!(designs[1]["label"], "abandoned");
    assert_eq!(designs[1]["size"], 3);
    assert_eq!(designs[1]["counts"]["pending"], 2);
    assert_eq!(designs[1]["counts"]["succeeded"], 1);
    let text = String::from_utf8_lossy(&iuq(&["status", p]).stdout).to_string();
    assert!(
        text.contains(&format!("designs: 2, 1 with runs left:\n  {abandoned} `abandoned`: 3 points, 1 succeeded, 0 failed, 0 cancelled, 2 pending")),
        "{text}"
    );

    // A design the store does not have is bad input, and nothing is cancelled, not even the
    // designs named before it.
    let missing = (abandoned + 40).to_string();
    let a = abandoned.to_string();
    let o = iuq(&["cancel", p, "--design", &a, "--design", &missing]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains(&format!("--design {missing}"))
            && err.contains("campaign.sqlite has no design"),
        "{err}"
    );
    assert_eq!(store_of(&dir).counts(None).unwrap().cancelled, 0);

    let v = json_of(&iuq(&["cancel", p, "--design", &a, "--json"]));
    assert_eq!(v["cancelled"][0]["cancelled"], 2, "{v}");
    assert_eq!(v["cancelled"][0]["design"]["counts"]["cancelled"], 2);
    // `iuq run` runs no cancelled run, and says so in its counts.
    let v = json_of(&iuq(&["run", p, "--json"]));
    assert_eq!(v["counts"]["pending"], 0, "{v}");
    assert_eq!(v["counts"]["cancelled"], 2);
    assert_eq!(v["counts"]["succeeded"], 2);
    let reason: String = store_sql(&dir)
        .query_row(
            "SELECT reason FROM runs WHERE status = 'cancelled' LIMIT 1",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(
        reason,
        format!("design {abandoned} (`abandoned`) set aside with `iuq cancel`")
    );

    // A later design that asks for a cancelled point gets it run.
    let ids = store_of(&dir)
        .add_design("later", &[vec![0.0, 8.0]])
        .unwrap();
    let v = json_of(&iuq(&["run", p, "--json"]));
    assert_eq!(v["counts"]["succeeded"], 3, "{v}");
    assert_eq!(v["counts"]["cancelled"], 1);
    let outcome = store_of(&dir).outcomes(&ids).unwrap();
    assert_eq!(outcome[0].clone().unwrap().unwrap().0, vec![8.0]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_model_command_that_cannot_start_stops_the_campaign_and_leaves_its_runs_pending() {
    let dir = scratch("cli-campaign", "cannot-start");
    let points: Vec<(u32, f64)> = (0..12).map(|i| (0, i as f64)).collect();
    let path = study(&dir, &points, "max_parallel = 2");
    let p = path.to_str().unwrap();
    std::fs::rename(dir.join("sim.sh"), dir.join("sim.sh.aside")).unwrap();
    let o = iuq(&["run", p]);
    assert_eq!(o.status.code(), Some(2), "bad input: the study's command");
    let err = String::from_utf8_lossy(&o.stderr);
    // At least 3 runs (those whose attempts ended in the same poll may add to them).
    let failed_to_start: usize = err
        .split("the model command cannot start: ")
        .nth(1)
        .and_then(|rest| rest.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{err}"));
    assert!((3..12).contains(&failed_to_start), "{err}");
    assert!(
        err.contains("study.toml: the model command cannot start: ")
            && err.contains("sim.sh`: No such file or directory")
            && err.contains("Fix the study's `[model] command`"),
        "{err}"
    );
    // Stopped after a few runs (each tried by the retry policy), not after all 12; none is
    // filed as a failure of the model.
    let store = store_of(&dir);
    let counts = store.counts(None).unwrap();
    assert_eq!(
        (counts.pending, counts.failed, counts.succeeded),
        (12, 0, 0)
    );
    let attempts: i64 = sql(&store)
        .query_row("SELECT COUNT(*) FROM attempts", [], |r| r.get(0))
        .unwrap();
    assert!(attempts < 3 * 12, "{attempts} attempts");
    drop(store);

    // With the program back, the next run makes every run.
    std::fs::rename(dir.join("sim.sh.aside"), dir.join("sim.sh")).unwrap();
    let v = json_of(&iuq(&["run", p, "--json"]));
    assert_eq!(v["counts"]["succeeded"], 12, "{v}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn runs_that_could_not_start_in_an_earlier_session_run_again_when_the_campaign_resumes() {
    let dir = scratch("cli-campaign", "restart");
    let path = study(&dir, &[(0, 1.0), (0, 2.0)], "max_parallel = 1");
    let p = path.to_str().unwrap();
    std::fs::rename(dir.join("sim.sh"), dir.join("sim.sh.aside")).unwrap();
    // Two runs that cannot start are fewer than the campaign stops at: they fail.
    let v = json_of(&iuq(&["run", p, "--json"]));
    assert_eq!(v["counts"]["failed"], 2, "{v}");
    std::fs::rename(dir.join("sim.sh.aside"), dir.join("sim.sh")).unwrap();
    let v = json_of(&iuq(&["run", p, "--json"]));
    assert_eq!(v["counts"]["succeeded"], 2, "{v}");
    assert_eq!(v["resumed"]["restarted"], 2, "{v}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn redecode_reads_the_run_directories_again_and_keeps_what_it_cannot_read() {
    let dir = scratch("cli-campaign", "redecode");
    let path = study(&dir, &[(0, 1.5), (0, 2.5), (0, 3.5)], "max_parallel = 1");
    let p = path.to_str().unwrap();
    let v = json_of(&iuq(&["run", p, "--json"]));
    assert_eq!(v["counts"]["succeeded"], 3);
    let stored = |run_id: i64| -> (f64, Option<f64>) {
        store_sql(&dir)
            .query_row(
                "SELECT value, std FROM outputs WHERE run_id = ?1",
                [run_id],
                |r| Ok((r.get(0)?, r.get(1)?)),
            )
            .unwrap()
    };
    assert_eq!(stored(1), (1.5, None));
    // Run 1's output gains a std (the decoder of an older iuq dropped it), run 2's value
    // differs (the user fixed the output), run 3's directory is gone (a clone without `runs/`).
    let runs = dir.join("study.campaign/runs");
    std::fs::write(
        runs.join("000001/result.json"),
        r#"{"f": {"value": 1.5, "std": 0.25}}"#,
    )
    .unwrap();
    std::fs::write(runs.join("000002/result.json"), r#"{"f": 7.0}"#).unwrap();
    std::fs::remove_dir_all(runs.join("000003")).unwrap();
    let o = iuq(&["redecode", p, "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json_of(&o);
    assert_eq!(v["runs"], 3);
    assert_eq!(v["updated"], 2);
    assert_eq!(v["values_changed"], 1);
    assert_eq!(v["unchanged"], 0);
    assert_eq!(v["missing_directory"], 1);
    assert_eq!(stored(1), (1.5, Some(0.25)));
    assert_eq!(stored(2).0, 7.0);
    assert_eq!(stored(3), (3.5, None));
    // Again: nothing differs. An output that no longer decodes keeps what the store holds.
    std::fs::write(runs.join("000002/result.json"), "garbage{").unwrap();
    let v = json_of(&iuq(&["redecode", p, "--json"]));
    assert_eq!(v["updated"], 0);
    assert_eq!(v["unchanged"], 1);
    let undecodable = v["undecodable"].as_array().unwrap();
    assert_eq!(undecodable.len(), 1);
    assert_eq!(undecodable[0]["run_id"], 2);
    assert!(
        undecodable[0]["reason"]
            .as_str()
            .unwrap()
            .contains("result.json"),
        "{v}"
    );
    assert_eq!(stored(2).0, 7.0);
    let text = String::from_utf8_lossy(&iuq(&["redecode", p]).stdout).to_string();
    assert!(text.contains("run 2: not decoded (kept)"), "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_study_files_exit_2_naming_file_key_and_reason() {
    let dir = scratch("cli-campaign", "bad");
    let path = study(&dir, &[(0, 1.0)], "max_parallel = 2");
    let text = std::fs::read_to_string(&path).unwrap();
    let cases = [
        (text.replace("{{ x }}", "{{ y }}"), "model.command[2]"),
        (
            text.replace("timeout = \"1s\"", "timeout = \"a while\""),
            "model.timeout",
        ),
        (
            text.replace("max_parallel = 2", "max_parallel = 0"),
            "executor.max_parallel",
        ),
        (
            text.replace("file = \"points.csv\"", "file = \"nope.csv\""),
            "design.file",
        ),
        // Durations and counts past what a clock or a machine holds are input errors, not
        // panics or hung coordinators.
        (
            text.replace("timeout = \"1s\"", "timeout = 1e20"),
            "model.timeout",
        ),
        (
            text.replace("timeout = \"1s\"", "timeout = \"99999999999999999999d\""),
            "model.timeout",
        ),
        (
            text.replace("max_parallel = 2", "max_parallel = 100000"),
            "executor.max_parallel",
        ),
        (
            text.replace("max_parallel = 2", "max_parallel = 9223372036854775807"),
            "executor.max_parallel",
        ),
    ];
    for (body, key) in cases {
        std::fs::write(&path, body).unwrap();
        let o = iuq(&["run", path.to_str().unwrap(), "--json"]);
        assert_eq!(o.status.code(), Some(2), "{key}");
        let v = json_of(&o);
        assert_eq!(v["error"]["kind"], "bad_input");
        let m = v["error"]["message"].as_str().unwrap();
        assert!(m.contains("study.toml") && m.contains(key), "{m}");
        // The message is printed once: the error the study layer keeps as its source (the
        // campaign's) is not repeated after it.
        assert_eq!(String::from_utf8_lossy(&o.stderr), format!("error: {m}\n"));
        assert_eq!(m.matches(key).count(), 1, "{m}");
    }
    let o = iuq(&["status", dir.join("missing.toml").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    std::fs::write(&path, &text).unwrap();
    // A store that is not an SQLite database is a bad input too: every verb names it and exits
    // 2, and the file is left as it was.
    let store = dir.join("study.campaign/campaign.sqlite");
    std::fs::create_dir_all(store.parent().unwrap()).unwrap();
    let garbage = "a spreadsheet saved under the store's name\n".repeat(40);
    std::fs::write(&store, &garbage).unwrap();
    for verb in ["status", "export", "run"] {
        let o = iuq(&[verb, path.to_str().unwrap(), "--json"]);
        assert_eq!(o.status.code(), Some(2), "{verb}");
        let v = json_of(&o);
        assert_eq!(v["error"]["kind"], "bad_input", "{verb}");
        let m = v["error"]["message"].as_str().unwrap();
        assert!(
            m.contains("campaign.sqlite") && m.contains("not an SQLite database"),
            "{verb}: {m}"
        );
    }
    assert_eq!(std::fs::read_to_string(&store).unwrap(), garbage);
    std::fs::remove_file(&store).unwrap();
    for interval in ["inf", "1e300", "0", "soon"] {
        let o = iuq(&["run", path.to_str().unwrap(), "--log-interval", interval]);
        assert_eq!(o.status.code(), Some(2), "--log-interval {interval}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("--log-interval"), "{err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_coordinator_killed_mid_campaign_resumes_without_losing_or_repeating_results() {
    let dir = scratch("cli-campaign", "crash");
    let points: Vec<(u32, f64)> = (0..200).map(|i| (1, i as f64)).collect();
    let path = study(&dir, &points, "max_parallel = 4");
    let p = path.to_str().unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_iuq"))
        .args(["run", p, "--json"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let db = dir.join("study.campaign/campaign.sqlite");
    let start = Instant::now();
    let mut before = 0;
    while start.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(20));
        if !db.exists() {
            continue;
        }
        let Ok(store) = iuq_campaign::CampaignStore::open_existing(&db) else {
            continue;
        };
        before = store.counts(None).map_or(0, |c| c.succeeded);
        if before >= 40 {
            break;
        }
    }
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    assert!((40..200).contains(&before), "killed after {before} results");
    let store = store_of(&dir);
    let committed: Vec<(i64, f64, i64)> = sql(&store)
        .prepare("SELECT o.run_id, o.value, o.attempt_id FROM outputs o ORDER BY o.run_id")
        .unwrap()
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    drop(store);

    let o = iuq(&["run", p, "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json_of(&o);
    assert_eq!(v["counts"]["succeeded"], 200, "{v}");
    let resumed = &v["resumed"];
    assert!(
        resumed["lost"].as_u64().unwrap() + resumed["ingested"].as_u64().unwrap() >= 1,
        "the executions in flight at the kill were ingested or declared lost: {v}"
    );
    let store = store_of(&dir);
    assert_eq!(store.integrity_check().unwrap(), "ok");
    let per_run: Vec<(i64, i64)> = sql(&store)
        .prepare("SELECT r.id, (SELECT COUNT(*) FROM attempts a WHERE a.run_id = r.id AND a.outcome_kind = 'succeeded') FROM runs r")
        .unwrap()
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?)))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(per_run.len(), 200);
    assert!(
        per_run.iter().all(|(_, n)| *n == 1),
        "every run has exactly one successful execution"
    );
    let open: i64 = sql(&store)
        .query_row(
            "SELECT COUNT(*) FROM attempts WHERE outcome_kind IS NULL",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(open, 0);
    for (run_id, value, attempt_id) in committed {
        let (v2, a2): (f64, i64) = sql(&store)
            .query_row(
                "SELECT value, attempt_id FROM outputs WHERE run_id = ?1",
                [run_id],
                |r| Ok((r.get(0)?, r.get(1)?)),
            )
            .unwrap();
        assert_eq!(
            (v2, a2),
            (value, attempt_id),
            "result of run {run_id} kept as committed"
        );
    }
    for (run_id, _) in &per_run {
        let x: f64 = sql(&store)
            .query_row(
                "SELECT value FROM outputs WHERE run_id = ?1",
                [run_id],
                |r| r.get(0),
            )
            .unwrap();
        assert_eq!(x, (*run_id - 1) as f64);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

const FAKE_SBATCH: &str = r#"#!/bin/sh
D="$FAKE_SCHED_DIR"; mkdir -p "$D/queue"
echo "$@" >> "$D/sbatch.log"
array=""; name=""; script=""
for a in "$@"; do
  case "$a" in
    --array=*) array="${a#--array=}" ;;
    --job-name=*) name="${a#--job-name=}" ;;
    --*) ;;
    *) script="$a" ;;
  esac
done
n=$(cat "$D/counter" 2>/dev/null || echo 100); n=$((n+1)); echo $n > "$D/counter"
range="${array%%\%*}"; first="${range%-*}"; last="${range#*-}"
i=$first; while [ $i -le $last ]; do echo "PENDING|$name" > "$D/queue/${n}_$i"; i=$((i+1)); done
(
  i=$first
  while [ $i -le $last ]; do
    echo "RUNNING|$name" > "$D/queue/.${n}_$i" && mv "$D/queue/.${n}_$i" "$D/queue/${n}_$i"
    SLURM_ARRAY_TASK_ID=$i SLURM_ARRAY_JOB_ID=$n sh "$script" > "$D/${n}_$i.out" 2>&1
    rm -f "$D/queue/${n}_$i"
    i=$((i+1))
  done
) > /dev/null 2>&1 < /dev/null &
echo "$n"
"#;

const FAKE_SQUEUE: &str = r#"#!/bin/sh
D="$FAKE_SCHED_DIR"; name=""
for a in "$@"; do case "$a" in --name=*) name="${a#--name=}" ;; esac; done
for f in "$D"/queue/*; do
  [ -e "$f" ] || continue
  IFS='|' read -r state jn < "$f" 2>/dev/null || continue
  [ "$jn" = "$name" ] && echo "$(basename "$f")|$state|localhost"
done
exit 0
"#;

const FAKE_SCONTROL: &str = r#"#!/bin/sh
case "$1 $2" in
  "show config") echo "MaxArraySize            = 5" ;;
  *) echo "slurm_load_jobs error: Invalid job id specified" >&2; exit 1 ;;
esac
"#;

#[test]
fn slurm_executor_with_fake_sbatch_chunks_arrays_retries_lost_tasks_and_records_failures() {
    let dir = scratch("cli-campaign", "fake-slurm");
    let bin = dir.join("bin");
    let state = dir.join("slurm-state");
    std::fs::create_dir_all(&bin).unwrap();
    std::fs::create_dir_all(&state).unwrap();
    executable(&bin.join("sbatch"), FAKE_SBATCH);
    executable(&bin.join("squeue"), FAKE_SQUEUE);
    executable(&bin.join("scontrol"), FAKE_SCONTROL);
    let mut points: Vec<(u32, f64)> = (0..10).map(|i| (0, i as f64)).collect();
    points.push((2, 50.0)); // fails: exit status 3
    points.push((9, 60.0)); // kills its worker on the first attempt: lost, then retried
    let path = study(
        &dir,
        &points,
        "kind = \"slurm\"\nmax_parallel = 2\narray_chunk = 100\npoll_interval = \"100ms\"",
    );
    let o = iuq_with_path(
        &["run", path.to_str().unwrap(), "--json"],
        Some((&bin, &state)),
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json_of(&o);
    assert_eq!(v["counts"]["succeeded"], 11, "{v}");
    assert_eq!(v["counts"]["failed"], 1);
    let log = std::fs::read_to_string(state.join("sbatch.log")).unwrap();
    let arrays: Vec<&str> = log.lines().collect();
    // 12 tasks below MaxArraySize = 5: arrays of 5, 5 and 2, then the retry of the lost task.
    assert_eq!(arrays.len(), 4, "{log}");
    assert!(
        arrays[0].contains("--array=0-4%2") && arrays[2].contains("--array=0-1%2"),
        "{log}"
    );
    assert!(arrays[3].contains("--array=0-0%2"), "{log}");
    let store = store_of(&dir);
    let kinds: Vec<(String, Option<String>, Option<String>)> = sql(&store)
        .prepare("SELECT outcome_kind, external_id, host FROM attempts WHERE run_id = 12 ORDER BY number")
        .unwrap()
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(kinds.len(), 2);
    assert_eq!(kinds[0].0, "lost");
    assert_eq!(kinds[1].0, "succeeded");
    assert!(
        kinds[1].1.as_deref().unwrap().contains('_'),
        "a Slurm array id: {:?}",
        kinds[1].1
    );
    let failed: String = sql(&store)
        .query_row("SELECT reason FROM runs WHERE status = 'failed'", [], |r| {
            r.get(0)
        })
        .unwrap();
    assert!(failed.contains("exited with status 3"), "{failed}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_coordinator_killed_while_slurm_runs_its_arrays_reattaches_without_resubmitting() {
    let dir = scratch("cli-campaign", "slurm-reattach");
    let bin = dir.join("bin");
    let state = dir.join("slurm-state");
    std::fs::create_dir_all(&bin).unwrap();
    std::fs::create_dir_all(&state).unwrap();
    executable(&bin.join("sbatch"), FAKE_SBATCH);
    executable(&bin.join("squeue"), FAKE_SQUEUE);
    executable(&bin.join("scontrol"), FAKE_SCONTROL);
    let points: Vec<(u32, f64)> = (0..5).map(|i| (8, i as f64)).collect();
    let path = study(&dir, &points, "kind = \"slurm\"\npoll_interval = \"100ms\"");
    let p = path.to_str().unwrap();
    let path_var = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let mut child = Command::new(env!("CARGO_BIN_EXE_iuq"))
        .args(["run", p, "--json"])
        .env("PATH", &path_var)
        .env("FAKE_SCHED_DIR", &state)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while !state.join("sbatch.log").exists() && start.elapsed() < Duration::from_secs(30) {
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(500));
    child.kill().unwrap();
    child.wait().unwrap();
    let o = iuq_with_path(&["run", p, "--json"], Some((&bin, &state)));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json_of(&o);
    assert_eq!(v["counts"]["succeeded"], 5, "{v}");
    assert!(v["resumed"]["reattached"].as_u64().unwrap() >= 1, "{v}");
    assert_eq!(v["resumed"]["lost"], 0, "{v}");
    let log = std::fs::read_to_string(state.join("sbatch.log")).unwrap();
    assert_eq!(log.lines().count(), 1, "one array, not resubmitted: {log}");
    let attempts: i64 = store_sql(&dir)
        .query_row("SELECT COUNT(*) FROM attempts", [], |r| r.get(0))
        .unwrap();
    assert_eq!(attempts, 5);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A fake `hq` printing what HyperQueue v0.26.2 prints in JSON output mode (the recorded
/// shapes of `tests/fixtures/hq` in iuq-campaign): `{"id": N}` from `submit`; from `job info`
/// the known jobs only (an unknown one is an error on stderr, exit status 0), each task with
/// `started_at`/`worker` once started, `finished_at` once ended, `error` when failed.
const FAKE_HQ: &str = r#"#!/bin/sh
D="$FAKE_SCHED_DIR"; mkdir -p "$D/hq"
echo "$@" >> "$D/hq.log"
[ "$1" = "--output-mode=json" ] || { echo "fake hq: JSON output mode only" >&2; exit 2; }
shift
now='"2026-11-24T16:04:31.797188603Z"'
case "$1" in
  submit)
    shift; array=""; name="main"
    while [ $# -gt 0 ]; do case "$1" in --array=*) array="${1#--array=}" ;; --name=*) name="${1#--name=}" ;; --) shift; break ;; esac; shift; done
    n=$(cat "$D/hq_counter" 2>/dev/null || echo 0); n=$((n+1)); echo $n > "$D/hq_counter"
    echo "$name" > "$D/hq/$n.name"
    first="${array%-*}"; last="${array#*-}"
    i=$first; while [ $i -le $last ]; do echo waiting > "$D/hq/$n.$i"; i=$((i+1)); done
    (
      i=$first
      while [ $i -le $last ]; do
        echo running > "$D/hq/.t" && mv "$D/hq/.t" "$D/hq/$n.$i"
        HQ_JOB_ID=$n HQ_TASK_ID=$i "$@" > /dev/null 2>&1
        code=$?; if [ $code = 0 ]; then s=finished; else s="failed $code"; fi
        echo "$s" > "$D/hq/.t" && mv "$D/hq/.t" "$D/hq/$n.$i"
        i=$((i+1))
      done
    ) > /dev/null 2>&1 < /dev/null &
    printf '{\n  "id": %s\n}\n' "$n" ;;
  job)
    [ "$2" = info ] || { echo "fake hq: unknown command job $2" >&2; exit 2; }
    ids=$(echo "$3" | tr ',' ' ')
    printf '['; sep=''
    for j in $ids; do
      [ -e "$D/hq/$j.name" ] || { echo "ERROR Job $j not found" >&2; continue; }
      count=0; w=0; r=0; f=0; x=0; tasks=''; tsep=''
      for file in "$D"/hq/$j.[0-9]*; do
        t=${file##*.}; set -- $(cat "$file"); s=$1; count=$((count+1))
        case $s in
          waiting) w=$((w+1)); extra='' ;;
          running) r=$((r+1)); extra=", \"started_at\": $now, \"worker\": 1" ;;
          finished) f=$((f+1)); extra=", \"started_at\": $now, \"worker\": 1, \"finished_at\": $now" ;;
          failed) x=$((x+1)); extra=", \"started_at\": $now, \"worker\": 1, \"finished_at\": $now, \"error\": \"Program terminated with exit code $2.\"" ;;
        esac
        tasks="$tasks$tsep{\"id\": $t, \"state\": \"$s\"$extra}"; tsep=', '
      done
      printf '%s{"finished_at": null, "info": {"cancel_reason": null, "id": %s, "is_open": false, "name": "%s", "task_count": %s, "task_stats": {"aborted": 0, "canceled": 0, "failed": %s, "finished": %s, "running": %s, "waiting": %s}}, "max_fails": null, "tasks": [%s]}' \
        "$sep" "$j" "$(cat "$D/hq/$j.name")" "$count" "$x" "$f" "$r" "$w" "$tasks"
      sep=', '
    done
    printf ']\n' ;;
  *) echo "fake hq: unknown command $1" >&2; exit 2 ;;
esac
"#;

/// Run a four-point campaign (one model failure) through the HyperQueue executor using `hq`;
/// returns the attempts' external ids (`<job>.<task>`).
fn hyperqueue_campaign(hq: &Path, state: Option<&Path>, dir: &Path) -> Vec<String> {
    let points: Vec<(u32, f64)> = vec![(0, 1.0), (0, 2.0), (2, 3.0), (0, 4.0)];
    let executor = format!(
        "kind = \"hyperqueue\"\nhq = \"{}\"\npoll_interval = \"100ms\"",
        hq.display()
    );
    let path = study(dir, &points, &executor);
    let mut c = Command::new(env!("CARGO_BIN_EXE_iuq"));
    c.args(["run", path.to_str().unwrap(), "--json"]);
    if let Some(state) = state {
        c.env("FAKE_SCHED_DIR", state);
    }
    let o = c.output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json_of(&o);
    assert_eq!(v["counts"]["succeeded"], 3, "{v}");
    assert_eq!(v["counts"]["failed"], 1);
    let v = json_of(&iuq(&["status", path.to_str().unwrap(), "--json"]));
    assert!(
        v["failures"][0]["reason"]
            .as_str()
            .unwrap()
            .contains("exited with status 3")
    );
    let ids: Vec<Option<String>> = store_sql(dir)
        .prepare("SELECT external_id FROM attempts ORDER BY id")
        .unwrap()
        .query_map([], |r| r.get(0))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert!(
        ids.iter()
            .all(|i| i.as_deref().is_some_and(|i| i.contains('.'))),
        "{ids:?}"
    );
    ids.into_iter().flatten().collect()
}

#[test]
fn hyperqueue_executor_with_a_fake_hq_printing_recorded_json() {
    let dir = scratch("cli-campaign", "fake-hq");
    let state = dir.join("hq-state");
    std::fs::create_dir_all(&state).unwrap();
    let hq = dir.join("hq");
    executable(&hq, FAKE_HQ);
    let ids = hyperqueue_campaign(&hq, Some(&state), &dir);
    assert_eq!(ids, ["1.0", "1.1", "1.2", "1.3"]);
    let log = std::fs::read_to_string(state.join("hq.log")).unwrap();
    assert!(
        log.lines().next().unwrap().contains("submit --array=0-3"),
        "{log}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Against a real HyperQueue (run by hand; CI without `hq` skips it):
///
/// ```text
/// git clone https://github.com/It4innovations/hyperqueue && cd hyperqueue && git checkout v0.26.2
/// cargo build --release -p hyperqueue --no-default-features --features microlp
/// HQ_BIN=$PWD/target/release/hq cargo test --release -p iuq --test cli cli_campaign::hyperqueue -- --nocapture
/// ```
///
/// (the default features build the HiGHS solver and jemalloc from C/C++ sources, which needs
/// cmake and a C++ compiler). The test starts its own server (waiting until `hq server info`
/// answers) and a worker (waiting until it is registered) in a scratch server directory; both
/// are stopped when the test ends, also when it fails.
#[test]
fn hyperqueue_executor_with_a_real_hq_when_hq_bin_is_set() {
    let Ok(hq) = std::env::var("HQ_BIN") else {
        eprintln!(
            "skipped: set HQ_BIN to a HyperQueue `hq` binary to run the campaign against a real server"
        );
        return;
    };
    let dir = scratch("cli-campaign", "real-hq");
    let cluster = HqCluster::start(&hq, &dir);
    let wrapper = dir.join("hq-wrapper.sh");
    executable(
        &wrapper,
        &format!(
            "#!/bin/sh\nexec '{hq}' --server-dir '{}' \"$@\"\n",
            cluster.server_dir.display()
        ),
    );
    let ids = hyperqueue_campaign(&wrapper, None, &dir);
    // One array of four tasks, under the campaign's job name; the ids are HyperQueue's.
    let jobs = cluster.json(&["job", "list", "--all"]);
    let jobs = jobs.as_array().expect("`hq job list` prints an array");
    assert_eq!(jobs.len(), 1, "{jobs:?}");
    let job = &jobs[0];
    assert!(
        job["name"].as_str().unwrap().starts_with("iuq-fake-"),
        "{job}"
    );
    assert_eq!(job["task_count"], 4, "{job}");
    let id = job["id"].as_u64().unwrap();
    let expected: Vec<String> = (0..4).map(|t| format!("{id}.{t}")).collect();
    assert_eq!(ids, expected);

    // A task HyperQueue stops at its time limit (100 ms; the model, mode 8, takes 0.4 s) leaves
    // no worker result: a timeout. (HyperQueue signals the worker's process group only, so the
    // model, in a process group of its own, runs on to its end: hence a short model here.)
    let limited = dir.join("time-limit");
    std::fs::create_dir_all(&limited).unwrap();
    let executor = format!(
        "kind = \"hyperqueue\"\nhq = \"{}\"\npoll_interval = \"100ms\"\nsubmit_args = [\"--time-limit=100ms\"]",
        wrapper.display()
    );
    let path = study(&limited, &[(8, 1.0)], &executor);
    let o = iuq(&["run", path.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json_of(&o);
    assert_eq!(v["counts"]["failed"], 1, "{v}");
    let v = json_of(&iuq(&["status", path.to_str().unwrap(), "--json"]));
    let failure = &v["failures"][0];
    assert_eq!(failure["kind"], "timeout", "{v}");
    assert!(
        failure["reason"]
            .as_str()
            .unwrap()
            .contains("reached its time limit"),
        "{v}"
    );
    drop(cluster);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A HyperQueue server and one worker in `<dir>/hq-server`, stopped when dropped (also while a
/// failing test unwinds).
struct HqCluster {
    hq: String,
    server_dir: PathBuf,
    server: std::process::Child,
    worker: Option<std::process::Child>,
}

impl HqCluster {
    const STARTUP: Duration = Duration::from_secs(60);

    fn start(hq: &str, dir: &Path) -> Self {
        let server_dir = dir.join("hq-server");
        std::fs::create_dir_all(&server_dir).unwrap();
        let log = |name: &str| std::fs::File::create(dir.join(name)).unwrap();
        let server = Command::new(hq)
            .args(["server", "start", "--server-dir"])
            .arg(&server_dir)
            .stdin(Stdio::null())
            .stdout(log("hq-server.log"))
            .stderr(log("hq-server.err"))
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start `{hq} server start`: {e}"));
        let mut cluster = HqCluster {
            hq: hq.to_string(),
            server_dir,
            server,
            worker: None,
        };
        cluster.wait_for("the server to answer `hq server info`", dir, |c| {
            c.hq_command(&["server", "info"])
                .output()
                .is_ok_and(|o| o.status.success())
        });
        cluster.worker = Some(
            Command::new(hq)
                .args(["worker", "start", "--server-dir"])
                .arg(&cluster.server_dir)
                .stdin(Stdio::null())
                .stdout(log("hq-worker.log"))
                .stderr(log("hq-worker.err"))
                .spawn()
                .unwrap_or_else(|e| panic!("cannot start `{hq} worker start`: {e}")),
        );
        cluster.wait_for("the worker to register", dir, |c| {
            c.try_json(&["worker", "list"])
                .and_then(|v| v.as_array().map(Vec::len))
                .is_some_and(|n| n >= 1)
        });
        cluster
    }

    /// Poll `ready` every 100 ms until it holds; panics (with the server's and worker's logs)
    /// when the server or the worker exits, or after a minute.
    fn wait_for(&mut self, what: &str, dir: &Path, ready: impl Fn(&Self) -> bool) {
        let start = Instant::now();
        while !ready(self) {
            let exited = std::iter::once(&mut self.server)
                .chain(self.worker.as_mut())
                .find_map(|c| c.try_wait().ok().flatten());
            if exited.is_some() || start.elapsed() > Self::STARTUP {
                let logs: Vec<String> = ["hq-server.err", "hq-worker.err"]
                    .iter()
                    .map(|f| std::fs::read_to_string(dir.join(f)).unwrap_or_default())
                    .collect();
                panic!(
                    "gave up waiting for {what} (a process exited: {exited:?})\nserver: {}\nworker: {}",
                    logs[0], logs[1]
                );
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    fn hq_command(&self, args: &[&str]) -> Command {
        let mut c = Command::new(&self.hq);
        c.arg("--server-dir")
            .arg(&self.server_dir)
            .args(args)
            .stdin(Stdio::null());
        c
    }

    fn try_json(&self, args: &[&str]) -> Option<Value> {
        let o = self
            .hq_command(&["--output-mode=json"])
            .args(args)
            .output()
            .ok()?;
        if !o.status.success() {
            return None;
        }
        serde_json::from_slice(&o.stdout).ok()
    }

    fn json(&self, args: &[&str]) -> Value {
        self.try_json(args)
            .unwrap_or_else(|| panic!("`hq {}` printed no JSON", args.join(" ")))
    }
}

impl Drop for HqCluster {
    fn drop(&mut self) {
        // `server stop` also stops the worker (which stops its tasks); then make sure.
        let _ = self
            .hq_command(&["server", "stop"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status();
        let deadline = Instant::now() + Duration::from_secs(10);
        for child in std::iter::once(&mut self.server).chain(self.worker.as_mut()) {
            while Instant::now() < deadline && matches!(child.try_wait(), Ok(None)) {
                std::thread::sleep(Duration::from_millis(50));
            }
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// A scheduler stops a worker by signalling it (HyperQueue's time limit or cancel, Slurm's
/// `scancel`); the model runs in a process group of its own, and `iuq worker` passes the signal
/// on, so the model stops with the worker instead of running on orphaned.
#[test]
fn a_worker_stopped_by_sigterm_stops_its_model() {
    let dir = scratch("cli-campaign", "worker-sigterm");
    let path = dir.join("study.toml");
    let text = r#"name = "long"
[parameters]
x = { uniform = [0, 1] }
[model]
kind = "command"
command = ["sh", "-c", "echo $$ > model.pid; exec sleep 60"]
outputs = ["f"]
output = { file = "result.json", format = "json" }
timeout = "5min"
[design]
kind = "lhs"
n = 1
"#;
    std::fs::write(&path, text).unwrap();
    let study = iuq_campaign::CampaignStudy::parse(text, &path).unwrap();
    let spec = iuq_campaign::worker::write_spec(&dir, &study.model).unwrap();
    let run_dir = dir.join("runs/000001");
    std::fs::create_dir_all(&run_dir).unwrap();
    let manifest = iuq_campaign::worker::ArrayManifest {
        spec,
        tasks: vec![iuq_campaign::run_directory::Task {
            directory: run_dir.clone(),
            runs: vec![iuq_campaign::run_directory::TaskRun {
                run_id: 1,
                attempt: 1,
                parameters: vec![0.5],
            }],
        }],
    };
    let manifest_path = dir.join("manifest.json");
    std::fs::write(&manifest_path, serde_json::to_vec(&manifest).unwrap()).unwrap();
    let mut worker = Command::new(env!("CARGO_BIN_EXE_iuq"))
        .args([
            "worker",
            "--manifest",
            manifest_path.to_str().unwrap(),
            "--index",
            "0",
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let pid_file = run_dir.join("model.pid");
    let started = Instant::now();
    let model_pid = loop {
        if let Some(pid) = std::fs::read_to_string(&pid_file)
            .ok()
            .and_then(|t| t.trim().parse::<u32>().ok())
        {
            break pid;
        }
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "the model did not start"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(is_running(model_pid));
    assert_eq!(
        signal_and_wait(&mut worker, "TERM"),
        Some(15),
        "the worker dies of the signal"
    );
    assert!(
        still_running_after_grace(&[model_pid]).is_empty(),
        "the model runs on after its worker stopped"
    );
}

/// Whether process `pid` runs: one that is gone, or a zombie waiting for a reaper, has stopped.
fn is_running(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|s| {
        s.rsplit(')')
            .next()
            .is_some_and(|rest| !rest.trim_start().starts_with('Z'))
    })
}

/// Sends SIG`signal` (e.g. "TERM") to `child` with `kill` and returns the signal it died of.
fn signal_and_wait(child: &mut std::process::Child, signal: &str) -> Option<i32> {
    use std::os::unix::process::ExitStatusExt;
    let status = Command::new("kill")
        .args([&format!("-{signal}"), &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    child.wait().unwrap().signal()
}

/// The processes of `pids` still running after waiting up to 5 s for them to stop.
fn still_running_after_grace(pids: &[u32]) -> Vec<u32> {
    let stopped = Instant::now();
    while pids.iter().any(|&p| is_running(p)) && stopped.elapsed() < Duration::from_secs(5) {
        std::thread::sleep(Duration::from_millis(20));
    }
    pids.iter().copied().filter(|&p| is_running(p)).collect()
}

/// Ctrl-C (SIGINT) or `kill` (SIGTERM) of `iuq run` on a local campaign stops the model
/// commands it runs, each in a process group of its own (a terminal's Ctrl-C reaches only the
/// foreground group): before, they ran on, orphaned, until the next run of the campaign killed
/// them. The stopped runs are lost, not failed, and the next run makes them once more.
#[test]
fn an_interrupted_coordinator_takes_its_running_model_commands_with_it() {
    for (signal, number) in [("INT", 2), ("TERM", 15)] {
        let dir = scratch("cli-campaign", &format!("interrupted-{signal}"));
        let hold = dir.join("hold");
        std::fs::write(&hold, "").unwrap();
        let path = slow_study(&dir);
        let p = path.to_str().unwrap();
        let (mut coordinator, model_pids) = start_held_campaign(&dir, p);
        assert!(model_pids.iter().all(|&pid| is_running(pid)));
        assert_eq!(
            signal_and_wait(&mut coordinator, signal),
            Some(number),
            "the coordinator dies of SIG{signal}"
        );
        let survivors = still_running_after_grace(&model_pids);
        assert!(
            survivors.is_empty(),
            "SIG{signal}: model processes {survivors:?} run on after their coordinator stopped"
        );

        std::fs::remove_file(&hold).unwrap();
        let o = iuq(&["run", p, "--json"]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v = json_of(&o);
        assert_eq!(v["counts"]["succeeded"], 2, "{v}");
        let store = store_of(&dir);
        // Each stopped execution is lost (retried by the default policy), not a failed run;
        // whether the coordinator filed it before it died or the next run found it unfinished.
        let first: Vec<(String, String)> = sql(&store)
            .prepare("SELECT outcome_kind, COALESCE(reason, '') FROM attempts WHERE number = 1")
            .unwrap()
            .query_map([], |r| Ok((r.get(0)?, r.get(1)?)))
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(first.len(), 2);
        for (kind, reason) in &first {
            assert_eq!(kind, "lost", "{first:?}");
            assert!(
                *reason == format!("stopped by SIG{signal} with the process that ran it")
                    || reason.ends_with("the run was executing, and it left no result"),
                "{first:?}"
            );
        }
        let values: Vec<f64> = sql(&store)
            .prepare("SELECT value FROM outputs ORDER BY value")
            .unwrap()
            .query_map([], |r| r.get(0))
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(values, [0.25, 0.75]);
        drop(store);
        let _ = std::fs::remove_dir_all(&dir);
    }
}

/// A study of two runs (x = 0.25, 0.75) of a model that, while the file `hold` of the study's
/// directory exists, waits a minute and records its pid and its `sleep`'s in the file `pids`
/// there; its output f is x. The study file is the same text in every directory (the model is
/// an inline `sh` script: a path would make a copy in another directory another model).
fn slow_study(dir: &Path) -> PathBuf {
    std::fs::write(dir.join("points.csv"), "x\n0.25\n0.75\n").unwrap();
    let path = dir.join("study.toml");
    std::fs::write(
        &path,
        r#"name = "slow"
[parameters]
x = { uniform = [0, 1] }
[model]
kind = "command"
command = ["sh", "-c", '''
if [ -f "$IUQ_STUDY_DIR/hold" ]; then
  sleep 60 & echo $$ $! >> "$IUQ_STUDY_DIR/pids"; wait
fi
echo "{\"f\": $1}" > result.json
''', "slow", "{{ x }}"]
outputs = ["f"]
output = { file = "result.json", format = "json" }
timeout = "120s"
[design]
kind = "file"
file = "points.csv"
[executor]
max_parallel = 2
"#,
    )
    .unwrap();
    path
}

/// Starts `iuq run` on the slow study `study` of `dir` (held) and waits until both of its
/// models run: the coordinator and the four pids (models and their `sleep`s).
/// (The child is returned to the caller, which waits for it.)
#[allow(clippy::zombie_processes)]
fn start_held_campaign(dir: &Path, study: &str) -> (std::process::Child, Vec<u32>) {
    let mut coordinator = Command::new(env!("CARGO_BIN_EXE_iuq"))
        .args(["run", study, "--json"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let started = Instant::now();
    loop {
        let text = std::fs::read_to_string(dir.join("pids")).unwrap_or_default();
        let found: Vec<u32> = text
            .split_whitespace()
            .filter_map(|t| t.parse().ok())
            .collect();
        if found.len() == 4 {
            return (coordinator, found);
        }
        if started.elapsed() > Duration::from_secs(30) {
            let _ = coordinator.kill();
            let _ = coordinator.wait();
            panic!("the models did not start: {text:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A copy of a running campaign's store (say, a backup taken while it runs) names the run
/// directories of the original. Running the copy must neither stop the original's models as
/// "orphans" nor read their results: the copy's open runs are lost and made again in its own
/// directory. (Found when a copied red-cell store killed a live cell-model run.)
#[test]
fn a_copied_store_leaves_the_original_campaigns_runs_alone() {
    let dir = scratch("cli-campaign", "original");
    let hold = dir.join("hold");
    std::fs::write(&hold, "").unwrap();
    let original = slow_study(&dir);
    let (mut coordinator, model_pids) = start_held_campaign(&dir, original.to_str().unwrap());

    let copy = scratch("cli-campaign", "copy");
    std::fs::create_dir_all(copy.join("study.campaign")).unwrap();
    let backup = copy.join("study.campaign/campaign.sqlite");
    store_sql(&dir)
        .execute("VACUUM INTO ?1", [backup.to_str().unwrap()])
        .unwrap();
    // The copy's own model does not wait (its hold file does not exist).
    let study = slow_study(&copy);
    let o = iuq(&["run", study.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json_of(&o);
    assert_eq!(v["counts"]["succeeded"], 2, "{v}");
    assert_eq!(v["resumed"]["lost"], 2, "{v}");
    assert_eq!(v["resumed"]["ingested"], 0, "{v}");
    let running: Vec<u32> = model_pids
        .iter()
        .copied()
        .filter(|&p| is_running(p))
        .collect();
    assert_eq!(
        running, model_pids,
        "the copy stopped the original's models"
    );
    let store = iuq_campaign::CampaignStore::open_existing(&backup).unwrap();
    let reasons: Vec<String> = sql(&store)
        .prepare("SELECT reason FROM attempts WHERE number = 1")
        .unwrap()
        .query_map([], |r| r.get(0))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(reasons.len(), 2);
    assert!(
        reasons
            .iter()
            .all(|r| r.contains("is not in this campaign's directory")),
        "{reasons:?}"
    );
    drop(store);

    assert_eq!(signal_and_wait(&mut coordinator, "TERM"), Some(15));
    assert!(still_running_after_grace(&model_pids).is_empty());
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&copy);
}
