//! What every end-to-end test of the `iuq` binary needs: run it, read its one JSON object, and a
//! scratch directory of its own.
#![allow(dead_code)] // not every helper is used in every configuration

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};

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

/// A copy of `examples/cooling` in a scratch directory of `suite` (runs and reports stay out of
/// the repository).
#[allow(dead_code)]
pub fn cooling_example(suite: &str, name: &str) -> PathBuf {
    let dir = scratch(suite, name);
    let source = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/cooling");
    for entry in std::fs::read_dir(&source).unwrap() {
        let path = entry.unwrap().path();
        if path.is_file() {
            std::fs::copy(&path, dir.join(path.file_name().unwrap())).unwrap();
        }
    }
    dir
}

/// `iuq serve umbridge STUDY` running in the background on a free port of 127.0.0.1; killed
/// when dropped.
pub struct Served {
    child: Child,
    /// The server's announcement (its one JSON line): `url`, `models`, …
    pub announcement: serde_json::Value,
}

impl Served {
    /// Start serving `study` with the extra flags `extra`.
    pub fn start(study: &Path, extra: &[&str]) -> Self {
        let mut child = Command::new(env!("CARGO_BIN_EXE_iuq"))
            .args(["serve", "umbridge"])
            .arg(study)
            .args(["--port", "0", "--json"])
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start iuq serve");
        let mut line = String::new();
        BufReader::new(child.stdout.take().expect("stdout is piped"))
            .read_line(&mut line)
            .expect("the announcement line");
        if line.trim().is_empty() {
            let mut err = String::new();
            child
                .stderr
                .take()
                .expect("stderr is piped")
                .read_to_string(&mut err)
                .expect("the server's stderr");
            panic!("iuq serve did not start: {err}");
        }
        let announcement = serde_json::from_str(&line).expect("one JSON object");
        Self {
            child,
            announcement,
        }
    }

    /// The server's URL.
    pub fn url(&self) -> String {
        self.announcement["url"]
            .as_str()
            .expect("the announcement has a url")
            .to_string()
    }
}

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The stderr of a finished `iuq` as text.
pub fn stderr_of(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// `iuq pipeline <study> --out <out> --json <extra…>`, which must succeed: its `--json` summary
/// and its progress lines (stderr).
pub fn pipeline(study: &Path, out: &Path, extra: &[&str]) -> (serde_json::Value, String) {
    let mut args = vec![
        "pipeline",
        study.to_str().expect("a UTF-8 path"),
        "--out",
        out.to_str().expect("a UTF-8 path"),
        "--json",
    ];
    args.extend(extra);
    let output = iuq(&args);
    let log = stderr_of(&output);
    assert!(output.status.success(), "{log}");
    (json_of(&output), log)
}

/// A short native run (`iuq rbc shear` at 4 Pa, kLink 30, from strain 0.3) with its ten frames
/// written to `dir/shapes` (in `format`, or the default one): the JSON result and the shape
/// files in frame order — the raw material of the HemoCell-format tests.
pub fn native_frames(dir: &Path, format: Option<&str>) -> (serde_json::Value, Vec<PathBuf>) {
    let shapes = dir.join("shapes");
    let mut args = vec![
        "rbc",
        "shear",
        "--stress",
        "4",
        "--klink",
        "30",
        "--start-strain",
        "0.3",
        "--shape-out",
        shapes.to_str().expect("a UTF-8 scratch path"),
    ];
    if let Some(format) = format {
        args.extend(["--shape-format", format]);
    }
    args.push("--json");
    let o = iuq(&args);
    assert!(o.status.success(), "{}", stderr_of(&o));
    let v = json_of(&o);
    let files: Vec<PathBuf> = v["shapes"]
        .as_array()
        .expect("the run lists its shape files")
        .iter()
        .map(|s| PathBuf::from(s.as_str().expect("a path")))
        .collect();
    assert_eq!(files.len(), 10);
    (v, files)
}

/// `examples/hemocell`, the HemoCell adapter.
pub fn hemocell_example_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/hemocell")
}

/// The HemoCell adapter's campaign study and files copied into `dir`, its design cut to `n`
/// points; returns the study file.
pub fn hemocell_campaign_in(dir: &Path, n: usize) -> PathBuf {
    for f in [
        "hemocell-shear.toml",
        "config.xml",
        "RBC.xml",
        "RBC.pos",
        "RBC-z-walls.pos",
        "run-hemocell.sh",
        "decode-el.py",
    ] {
        std::fs::copy(hemocell_example_dir().join(f), dir.join(f))
            .expect("the adapter's files copy into a scratch directory");
    }
    let study = dir.join("hemocell-shear.toml");
    let text = std::fs::read_to_string(&study).expect("the study reads back");
    assert!(
        text.contains("n = 16"),
        "the adapter's design has 16 points"
    );
    std::fs::write(&study, text.replace("n = 16", &format!("n = {n}")))
        .expect("the study is written");
    study
}
