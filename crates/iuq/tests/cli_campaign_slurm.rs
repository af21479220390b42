//! A campaign of 20 runs, one of them failing, on a real single-node Slurm cluster (Debian's
//! slurm-wlm and munge, configured on localhost by `scripts/ci/setup-slurm.sh`).
//!
//! Skipped, with a message, where `sbatch` is not installed; in CI (`CI` set) a missing or
//! unreachable Slurm is a failure, so that the test cannot silently stop running there.

use std::path::Path;
use std::process::Command;

use serde_json::Value;

fn slurm_available() -> bool {
    let has_sbatch = Command::new("sh")
        .args(["-c", "command -v sbatch"])
        .output()
        .is_ok_and(|o| o.status.success());
    let in_ci = std::env::var_os("CI").is_some();
    if !has_sbatch {
        assert!(
            !in_ci,
            "CI must run the real Slurm test: run scripts/ci/setup-slurm.sh first"
        );
        eprintln!(
            "skipped: `sbatch` is not installed (run `bash scripts/ci/setup-slurm.sh` as root for a local single-node Slurm)"
        );
        return false;
    }
    let ping = Command::new("scontrol").arg("ping").output();
    let up = ping
        .as_ref()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).contains("UP"));
    if !up {
        assert!(
            !in_ci,
            "Slurm is installed but slurmctld does not answer: run scripts/ci/setup-slurm.sh"
        );
        eprintln!(
            "skipped: slurmctld does not answer `scontrol ping` (run `bash scripts/ci/setup-slurm.sh` as root)"
        );
        return false;
    }
    true
}

fn write(path: &Path, text: &str) {
    std::fs::write(path, text).unwrap();
}

/// A connection of the test's own to the campaign store `store` (the store keeps its own
/// private), to look at its tables.
fn sql(store: &iuq_campaign::CampaignStore) -> rusqlite::Connection {
    rusqlite::Connection::open(store.path()).unwrap()
}

#[test]
fn twenty_runs_with_one_failure_on_a_real_single_node_slurm() {
    if !slurm_available() {
        return;
    }
    let dir = std::env::temp_dir().join(format!("iuq-cli-slurm-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    write(
        &dir.join("sim.sh"),
        "#!/bin/sh\nif [ \"$1\" = 13 ]; then echo 'unstable at run 13' >&2; exit 4; fi\necho \"{\\\"f\\\": $(( $1 * 2 ))}\" > out.json\n",
    );
    Command::new("chmod")
        .arg("+x")
        .arg(dir.join("sim.sh"))
        .status()
        .unwrap();
    let mut csv = String::from("k\n");
    for k in 0..20 {
        csv.push_str(&format!("{k}\n"));
    }
    write(&dir.join("points.csv"), &csv);
    write(
        &dir.join("study.toml"),
        r#"name = "slurm-twenty"
[parameters]
k = { uniform = [0, 100] }
[model]
kind = "command"
command = ["./sim.sh", "{{ k }}"]
outputs = ["f"]
output = { file = "out.json", format = "json" }
timeout = "60s"
[design]
kind = "file"
file = "points.csv"
[executor]
kind = "slurm"
max_parallel = 4
array_chunk = 8
poll_interval = "500ms"
"#,
    );
    let o = Command::new(env!("CARGO_BIN_EXE_iuq"))
        .args(["run", dir.join("study.toml").to_str().unwrap(), "--json"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["counts"]["succeeded"], 19, "{v}");
    assert_eq!(v["counts"]["failed"], 1, "{v}");
    let o = Command::new(env!("CARGO_BIN_EXE_iuq"))
        .args(["status", dir.join("study.toml").to_str().unwrap(), "--json"])
        .output()
        .unwrap();
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    let failure = &v["failures"][0];
    assert_eq!(failure["parameters"]["k"], 13.0);
    assert!(
        failure["reason"]
            .as_str()
            .unwrap()
            .contains("exited with status 4"),
        "{failure}"
    );
    let store =
        iuq_campaign::CampaignStore::open_existing(&dir.join("study.campaign/campaign.sqlite"))
            .unwrap();
    let rows: Vec<(String, String, f64)> = sql(&store)
        .prepare("SELECT a.external_id, a.host, o.value FROM attempts a JOIN outputs o ON o.attempt_id = a.id ORDER BY a.run_id")
        .unwrap()
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(rows.len(), 19);
    assert!(
        rows.iter()
            .all(|(id, host, _)| id.contains('_') && !host.is_empty()),
        "{rows:?}"
    );
    assert_eq!(rows[5].2, 10.0);
    assert_eq!(store.integrity_check().unwrap(), "ok");
    let _ = std::fs::remove_dir_all(&dir);
}
