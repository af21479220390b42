//! Tests of the store: opening (and refusing) stores, designs sharing runs, attempts and the
//! retry policy, derived results.

use super::*;
use crate::outcome::{OutcomeKind, RunResult};
use crate::retry_policy::RetryPolicy;

const STUDY: &str = r#"
name = "s"
[parameters]
x = { uniform = [-1, 1] }
[model]
kind = "command"
command = ["true"]
outputs = ["f"]
output = { file = "r.json", format = "json" }
"#;

fn fresh(name: &str) -> (PathBuf, CampaignStudy) {
    let dir = std::env::temp_dir().join(format!("iuq-store-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let study = CampaignStudy::parse(STUDY, &dir.join("study.toml")).unwrap();
    (dir, study)
}

#[test]
fn a_derived_result_is_read_back_only_under_its_key_and_fingerprint_and_survives_reopening() {
    let (dir, study) = fresh("derived");
    let path = dir.join("c.sqlite");
    let mut store = CampaignStore::open(&path, &study).unwrap();
    assert_eq!(store.derived_result("round-1", "abc").unwrap(), None);
    store
        .record_derived_result("round-1", "abc", "{\"u\":1}")
        .unwrap();
    store
        .record_derived_result("round-1", "def", "{\"u\":2}")
        .unwrap();
    assert_eq!(
        store.derived_result("round-1", "abc").unwrap().as_deref(),
        Some("{\"u\":1}")
    );
    assert_eq!(store.derived_result("round-2", "abc").unwrap(), None);
    // The same key and fingerprint again replaces the value.
    store
        .record_derived_result("round-1", "abc", "{\"u\":3}")
        .unwrap();
    drop(store);
    let store = CampaignStore::open(&path, &study).unwrap();
    assert_eq!(
        store.derived_result("round-1", "abc").unwrap().as_deref(),
        Some("{\"u\":3}")
    );
    assert_eq!(
        store.derived_result("round-1", "def").unwrap().as_deref(),
        Some("{\"u\":2}")
    );
}

#[test]
fn a_store_moved_with_its_study_and_its_program_keeps_its_runs() {
    let (dir, _) = fresh("moved");
    let text = STUDY.replace(r#"["true"]"#, r#"["./sim.sh", "{{x}}"]"#);
    let here = dir.join("here");
    let there = dir.join("elsewhere/deeper");
    let study = CampaignStudy::parse(&text, &here.join("study.toml")).unwrap();
    let moved = CampaignStudy::parse(&text, &there.join("study.toml")).unwrap();
    assert_ne!(study.legacy_model_hash(), moved.legacy_model_hash());
    assert_eq!(study.model_hash(), moved.model_hash());
    let path = dir.join("c.sqlite");
    drop(CampaignStore::open(&path, &study).unwrap());
    assert!(CampaignStore::open(&path, &moved).is_ok());
    // Another program is another model.
    let other = CampaignStudy::parse(
        &text.replace("./sim.sh", "./other.sh"),
        &there.join("study.toml"),
    )
    .unwrap();
    assert!(CampaignStore::open(&path, &other).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_store_hashed_with_the_program_s_absolute_path_is_rewritten_once_opened_where_it_was_made() {
    let (dir, _) = fresh("legacy");
    let text = STUDY.replace(r#"["true"]"#, r#"["./sim.sh"]"#);
    let here = dir.join("here");
    let study = CampaignStudy::parse(&text, &here.join("study.toml")).unwrap();
    let path = dir.join("c.sqlite");
    let store = CampaignStore::open(&path, &study).unwrap();
    store
        .connection
        .execute(
            "UPDATE studies SET model_hash = ?1",
            params![study.legacy_model_hash()],
        )
        .unwrap();
    drop(store);
    let elsewhere = CampaignStudy::parse(&text, &dir.join("b/study.toml")).unwrap();
    assert!(
        CampaignStore::open(&path, &elsewhere).is_err(),
        "an old hash holds the folder it was made in"
    );
    let store = CampaignStore::open(&path, &study).unwrap();
    let stored: String = store
        .connection
        .query_row("SELECT model_hash FROM studies", [], |r| r.get(0))
        .unwrap();
    assert_eq!(stored, study.model_hash());
    drop(store);
    assert!(CampaignStore::open(&path, &elsewhere).is_ok());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn identical_vectors_share_a_run_and_local_disks_use_wal() {
    let (dir, study) = fresh("dedup");
    let mut store = CampaignStore::open(&dir.join("c.sqlite"), &study).unwrap();
    assert_eq!(store.journal_mode(), JournalMode::Wal);
    let ids = store
        .add_design("a", &[vec![0.5], vec![0.0], vec![0.5], vec![-0.0]])
        .unwrap();
    assert_eq!(ids, vec![1, 2, 1, 2]);
    let ids = store.add_design("b", &[vec![0.25], vec![0.5]]).unwrap();
    assert_eq!(ids, vec![3, 1]);
    assert_eq!(store.counts(None).unwrap().pending, 3);
    assert!(store.add_design("c", &[vec![f64::NAN]]).is_err());
    // The same design again (a rerun of the study) adds nothing; another label or order does.
    let designs = |store: &CampaignStore| -> i64 {
        store
            .connection
            .query_row("SELECT COUNT(*) FROM designs", [], |r| r.get(0))
            .unwrap()
    };
    assert_eq!(designs(&store), 2);
    let again = store.add_design("b", &[vec![0.25], vec![0.5]]).unwrap();
    assert_eq!(again, vec![3, 1]);
    assert_eq!(designs(&store), 2);
    store.add_design("b", &[vec![0.5], vec![0.25]]).unwrap();
    store.add_design("d", &[vec![0.25], vec![0.5]]).unwrap();
    assert_eq!(designs(&store), 4);
    // A design's points read back in order, bit for bit; the latest of a label wins.
    assert_eq!(
        store.design_points("b").unwrap(),
        Some(vec![vec![0.5], vec![0.25]])
    );
    let a = store.design_points("a").unwrap().unwrap();
    assert_eq!(a.len(), 4);
    assert_eq!(
        a[3][0].to_bits(),
        0.0f64.to_bits(),
        "-0.0 and 0.0 are one run"
    );
    assert_eq!(store.design_points("nope").unwrap(), None);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn attempts_close_once_and_follow_the_retry_policy() {
    let (dir, study) = fresh("attempts");
    let mut store = CampaignStore::open(&dir.join("c.sqlite"), &study).unwrap();
    store.add_design("a", &[vec![0.1], vec![0.2]]).unwrap();
    let policy = RetryPolicy::default();
    let names = vec!["f".to_string()];
    let (a1, n1) = store
        .write(|w| w.begin_attempt(1, "local", Path::new("/tmp/r1")))
        .unwrap();
    assert_eq!(n1, 1);
    let lost = RunResult::failure(1, 1, OutcomeKind::Lost, "gone");
    let d = store
        .write(|w| w.finish_attempt(a1, &lost, None, &names, &policy))
        .unwrap();
    assert_eq!(d, Disposition::Retry);
    // A late duplicate report of the same attempt changes nothing.
    let d = store
        .write(|w| w.finish_attempt(a1, &lost, None, &names, &policy))
        .unwrap();
    assert_eq!(d, Disposition::Ignored);
    assert_eq!(store.pending_runs(10).unwrap().len(), 2);
    let (a2, n2) = store
        .write(|w| w.begin_attempt(1, "local", Path::new("/tmp/r1")))
        .unwrap();
    assert_eq!(n2, 2);
    let ok = RunResult {
        run_id: 1,
        attempt: 2,
        kind: OutcomeKind::Succeeded,
        reason: None,
        outputs: vec![4.0],
        std: Some(vec![0.5]),
    };
    let d = store
        .write(|w| w.finish_attempt(a2, &ok, None, &names, &policy))
        .unwrap();
    assert_eq!(d, Disposition::Succeeded);
    let (a3, _) = store
        .write(|w| w.begin_attempt(2, "local", Path::new("/tmp/r2")))
        .unwrap();
    let bad = RunResult::failure(2, 1, OutcomeKind::ExitStatus, "exited with status 1");
    let d = store
        .write(|w| w.finish_attempt(a3, &bad, None, &names, &policy))
        .unwrap();
    assert_eq!(d, Disposition::Failed);
    let outcomes = store.outcomes(&[1, 2]).unwrap();
    assert_eq!(outcomes[0], Some(Ok((vec![4.0], Some(vec![0.5])))));
    assert_eq!(outcomes[1], Some(Err("exited with status 1".into())));
    assert_eq!(store.failures().unwrap()[0].kind, "exit_status");
    assert_eq!(store.reset_for_retry(false, true).unwrap(), 0);
    assert_eq!(store.reset_for_retry(true, false).unwrap(), 1);
    assert_eq!(store.integrity_check().unwrap(), "ok");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_file_that_is_not_a_store_is_bad_input_and_left_as_it_was() {
    let (dir, study) = fresh("not-a-store");
    let path = dir.join("c.sqlite");
    let garbage =
        "not a database, just text that happens to sit where the store should be\n".repeat(20);
    std::fs::write(&path, &garbage).unwrap();
    for e in [
        CampaignStore::open(&path, &study).map(drop).unwrap_err(),
        CampaignStore::open_existing(&path).map(drop).unwrap_err(),
    ] {
        let message = e.to_string();
        assert!(e.is_bad_input(), "{message}");
        assert!(
            message.contains("c.sqlite") && message.contains("not an SQLite database"),
            "{message}"
        );
    }
    assert_eq!(std::fs::read_to_string(&path).unwrap(), garbage);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_store_refuses_a_study_with_another_model() {
    let (dir, study) = fresh("model");
    drop(CampaignStore::open(&dir.join("c.sqlite"), &study).unwrap());
    let other =
        CampaignStudy::parse(&STUDY.replace("[\"true\"]", "[\"false\"]"), &study.path).unwrap();
    let e = CampaignStore::open(&dir.join("c.sqlite"), &other).unwrap_err();
    assert!(
        e.is_bad_input() && e.to_string().contains("key `model`"),
        "{e}"
    );
    // Another text with the same model (a comment, a new design) is fine.
    let same = CampaignStudy::parse(&format!("# note\n{STUDY}"), &study.path).unwrap();
    assert!(CampaignStore::open(&dir.join("c.sqlite"), &same).is_ok());
    assert_eq!(parameter_key(&[1.0, -0.0]), parameter_key(&[1.0, 0.0]));
    assert!(!is_network_file_system(&dir));
    let _ = std::fs::remove_dir_all(&dir);
}
