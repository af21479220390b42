//! What every end-to-end test of the `iuq` binary needs: run it, read its one JSON object, and a
//! scratch directory of its own.
#![allow(dead_code)] // each test binary uses its own subset

use std::path::PathBuf;
use std::process::{Command, Output};

/// Run the `iuq` binary built for these tests with `args`.
pub fn iuq(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_iuq"))
        .args(args)
        .output()
        .expect("the iuq binary runs")
}

/// The single JSON object a `--json` run printed on stdout (fails the test otherwise).
pub fn json_of(output: &Output) -> serde_json::Value {
    let stdout = String::from_utf8_lossy(&output.stdout);
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(
        lines.len(),
        1,
        "exactly one JSON line expected, got: {stdout}\nstderr: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_str(lines[0]).expect("valid JSON")
}

/// A fresh, empty directory for one test: `<tmp>/iuq-<suite>-<pid>-<name>`.
pub fn scratch(suite: &str, name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("iuq-{suite}-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("a scratch directory can be made");
    dir
}
