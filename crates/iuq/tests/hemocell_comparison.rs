//! The native model against the real HemoCell, and the HemoCell adapter against the real
//! program's ways of failing.
//!
//! * `data/hemocell_vs_native.csv` (provenance: `data/hemocell_vs_native.md`) holds 12 points
//!   run through `examples/hemocell/` with HemoCell v2.1 (Palabos v2.1r0, interior viscosity) and
//!   with `iuq rbc shear` in both protocols. [`the_comparison_table_is_complete_and_consistent`]
//!   checks the table against its own frames and the agreement criterion below (fast);
//!   [`native_scaled_model_agrees_with_hemocell`] reruns the native model (scaled protocol, 12
//!   runs of about 40 s on one core) and compares it with HemoCell's columns:
//!
//!   ```sh
//!   flock /tmp/iuq-cargo.lock cargo test --release -p iuq --test hemocell_comparison -- --ignored
//!   ```
//!
//! * The adapter (`run-hemocell.sh`, `decode-el.py`): HemoCell's own reason when it exits
//!   non-zero (it prints it on stdout) reaches the campaign's record; a cell HemoCell deleted
//!   fails the run with HemoCell's message; HemoCell's z-wall layout (v2.2 and later) is refused
//!   from its fluid output; a frame that lost vertices fails. The HDF5 parts need h5py and are
//!   skipped, with the reason printed, without it.

mod common;

use common::{iuq, json_of, scratch};

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

const SUITE: &str = "hemocell-comparison";

fn example_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/hemocell")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn h5py_available(test: &str) -> bool {
    match Command::new("python3")
        .args(["-c", "import numpy, h5py"])
        .output()
    {
        Ok(o) if o.status.success() => true,
        Ok(o) => {
            println!(
                "skipping {test}: `import numpy, h5py` failed: {} (install with `python3 -m pip install h5py`)",
                String::from_utf8_lossy(&o.stderr).trim()
            );
            false
        }
        Err(e) => {
            println!("skipping {test}: python3 cannot be started: {e}");
            false
        }
    }
}

// ------------------------------------------------------------------------------------------
// The adapter against HemoCell's failures.

/// A folder with the filled templates of one run, as the campaign writes it.
fn run_folder(name: &str) -> PathBuf {
    let dir = scratch(SUITE, name);
    let fill = |file: &str, pairs: &[(&str, &str)]| {
        let mut text = std::fs::read_to_string(example_dir().join(file)).unwrap();
        for (k, v) in pairs {
            text = text.replace(&format!("{{{{ {k} }}}}"), v);
        }
        std::fs::write(dir.join(file), text).unwrap();
    };
    fill(
        "config.xml",
        &[("shearrate", "5000"), ("tmax", "200"), ("tmeas", "10")],
    );
    fill(
        "RBC.xml",
        &[
            ("kLink", "36.7"),
            ("kBend", "367"),
            ("viscosityRatio", "5.9"),
        ],
    );
    dir
}

/// An executable stand-in for oneCellShear with the given shell body.
fn fake_onecellshear(dir: &Path, body: &str) -> PathBuf {
    let path = dir.join("fake-oneCellShear");
    std::fs::write(&path, format!("#!/usr/bin/env bash\n{body}\n")).unwrap();
    Command::new("chmod").arg("+x").arg(&path).status().unwrap();
    path
}

fn run_adapter(dir: &Path, simulator: &Path) -> Output {
    Command::new(example_dir().join("run-hemocell.sh"))
        .args(["100", "200"])
        .current_dir(dir)
        .env("HEMOCELL_ONECELLSHEAR", simulator)
        .env("IUQ", env!("CARGO_BIN_EXE_iuq"))
        .output()
        .unwrap()
}

fn last_stderr_line(o: &Output) -> String {
    stderr(o).lines().last().unwrap_or("").to_string()
}

/// HemoCell v2.1's start-up failure without the interior-viscosity build, as it prints it (on
/// stdout, then `exit(1)`), from `core/hemoCellField.cpp`.
const NO_INTERIOR_VISCOSITY: &str = "(HemoCell) (AddCellType) (RBC) Cannot enable interior viscosity when INTERIOR_VISCOSITY is not defined at compile time";

#[test]
fn hemocell_s_reason_for_a_non_zero_exit_is_the_run_s_last_stderr_line() {
    let dir = run_folder("exit-reason");
    let fake = fake_onecellshear(
        &dir,
        &format!(
            "echo '(HemoCell) (Config) reading config.xml'\n\
             echo '(HemoCell) WARNING: Force limit active at 50 pN. Results can be inaccurate due to force capping.'\n\
             echo '{NO_INTERIOR_VISCOSITY}'\nexit 1"
        ),
    );
    let o = run_adapter(&dir, &fake);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert_eq!(
        last_stderr_line(&o),
        format!("run-hemocell.sh: oneCellShear exited with status 1: {NO_INTERIOR_VISCOSITY}")
    );
    // HemoCell's output is kept in the run folder and passed on to stdout.
    let log = std::fs::read_to_string(dir.join("hemocell.log")).unwrap();
    assert!(log.contains(NO_INTERIOR_VISCOSITY));
    assert!(String::from_utf8_lossy(&o.stdout).contains(NO_INTERIOR_VISCOSITY));

    // An uncaught exception (a key missing from config.xml): terminate, then SIGABRT.
    let fake = fake_onecellshear(
        &dir,
        "echo \"terminate called after throwing an instance of 'std::invalid_argument'\"\n\
         echo '  what():  XML child tmeas does not exist.'\nkill -ABRT $$",
    );
    let o = run_adapter(&dir, &fake);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert_eq!(
        last_stderr_line(&o),
        "run-hemocell.sh: oneCellShear was killed by signal 6: what(): XML child tmeas does not exist."
    );

    // A cell HemoCell deleted and a crash after it: the deletion is the reason.
    let fake = fake_onecellshear(
        &dir,
        "echo '(HemoCell) (Delete Cells) WARNING! Particle deleted from local domain. This means the whole cell will be deleted!'\n\
         echo '\t Particle ID:0'\n\
         echo '\t Position: 3.2, 45.1, 9; vel.: 0, 0, 0; force: 0, 0, 0'\nkill -SEGV $$",
    );
    let o = run_adapter(&dir, &fake);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let last = last_stderr_line(&o);
    assert!(
        last.starts_with("run-hemocell.sh: oneCellShear was killed by signal 11; HemoCell deleted the cell: (HemoCell) (Delete Cells) WARNING! Particle deleted"),
        "{last}"
    );
    assert!(last.contains("Position: 3.2, 45.1, 9"), "{last}");
}

#[test]
fn the_campaign_records_hemocell_s_reason() {
    let dir = scratch(SUITE, "campaign-reason");
    for f in [
        "hemocell-shear.toml",
        "config.xml",
        "RBC.xml",
        "RBC.pos",
        "run-hemocell.sh",
        "decode-el.py",
    ] {
        std::fs::copy(example_dir().join(f), dir.join(f)).unwrap();
    }
    let study = dir.join("hemocell-shear.toml");
    let text = std::fs::read_to_string(&study).unwrap();
    std::fs::write(&study, text.replace("n = 16", "n = 3")).unwrap();
    let fake = fake_onecellshear(&dir, &format!("echo '{NO_INTERIOR_VISCOSITY}'\nexit 1"));
    let o = Command::new(env!("CARGO_BIN_EXE_iuq"))
        .args(["run", study.to_str().unwrap(), "--json"])
        .env("HEMOCELL_ONECELLSHEAR", &fake)
        .env("IUQ", env!("CARGO_BIN_EXE_iuq"))
        .output()
        .unwrap();
    let v = json_of(&o);
    assert_eq!(v["counts"]["failed"], 3, "{v}\n{}", stderr(&o));
    let export = iuq(&["export", study.to_str().unwrap(), "--json"]);
    assert!(export.status.success(), "{}", stderr(&export));
    let runs = json_of(&export);
    let runs = runs.as_array().expect("an array of runs");
    assert_eq!(runs.len(), 3);
    for run in runs {
        let reason = run["reason"].as_str().unwrap_or_default();
        assert!(
            reason.contains(
                "Cannot enable interior viscosity when INTERIOR_VISCOSITY is not defined"
            ),
            "{run}"
        );
    }
}

/// Ten native frames (a short run) as shape files: the raw material of an HDF5 tree.
fn shapes(dir: &Path) -> (Value, Vec<PathBuf>) {
    let shapes = dir.join("shapes");
    let o = iuq(&[
        "rbc",
        "shear",
        "--stress",
        "4",
        "--klink",
        "30",
        "--start-strain",
        "0.3",
        "--shape-out",
        shapes.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v = json_of(&o);
    let files = v["shapes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| PathBuf::from(s.as_str().unwrap()))
        .collect();
    (v, files)
}

/// Write `files` at iterations 100, 110, … (and iteration 0) under `case/tmp/hdf5` with the
/// writer's `extra` options; then decode [100, 190] with `decode_extra`.
fn write_and_decode(
    case: &Path,
    files: &[PathBuf],
    extra: &[&str],
    decode_extra: &[&str],
) -> Output {
    std::fs::create_dir_all(case).unwrap();
    let hdf5 = case.join("tmp/hdf5");
    let mut c = Command::new("python3");
    c.arg(example_dir().join("tests/write_hemocell_hdf5.py"))
        .arg(&hdf5)
        .args(["--frame", "0"])
        .arg(&files[0]);
    for (k, f) in files.iter().enumerate() {
        c.arg("--frame").arg((100 + 10 * k).to_string()).arg(f);
    }
    c.args(["--cell-type", "RBC"]).args(extra);
    let o = c.output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    Command::new("python3")
        .arg(example_dir().join("decode-el.py"))
        .arg(&hdf5)
        .args([
            "--from", "100", "--to", "190", "--frames", "10", "--out", "el.json",
        ])
        .args(decode_extra)
        .current_dir(case)
        .env("IUQ", env!("CARGO_BIN_EXE_iuq"))
        .output()
        .unwrap()
}

#[test]
fn the_decoder_refuses_the_z_wall_layout_and_cells_hemocell_deleted() {
    if !h5py_available("the decoder's HemoCell checks") {
        return;
    }
    let dir = scratch(SUITE, "decoder-checks");
    let (native, files) = shapes(&dir);

    // HemoCell v2.1's layout (walls on the y planes), read from its fluid output: decoded, with
    // the fluid's shear in the summary.
    let case = dir.join("y-walls");
    let o = write_and_decode(&case, &files, &["--fluid", "y"], &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let el: Value =
        serde_json::from_str(&std::fs::read_to_string(case.join("el.json")).unwrap()).unwrap();
    assert!(
        (el["el"]["value"].as_f64().unwrap() - native["el"]["value"].as_f64().unwrap()).abs()
            < 1e-9
    );
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(case.join("hemocell-frames.json")).unwrap())
            .unwrap();
    assert_eq!(summary["frames"].as_array().unwrap().len(), 10);
    assert_eq!(summary["frames"][0]["vertices"], 642);
    let g = &summary["fluid_du_x_per_node"];
    // u_x = 5000/s × 0.5 µm per node along y: 2.5e-3 m/s per node, none along z.
    assert!((g["y"].as_f64().unwrap() - 2.5e-3).abs() < 1e-6, "{g}");
    assert!(g["z"].as_f64().unwrap().abs() < 1e-9, "{g}");

    // HemoCell >= 2.2 (walls on the z planes): refused, with the reason.
    let case = dir.join("z-walls");
    let o = write_and_decode(&case, &files, &["--fluid", "z"], &[]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let last = last_stderr_line(&o);
    assert!(last.contains("the fluid is sheared along z"), "{last}");
    assert!(last.contains("HemoCell >= 2.2"), "{last}");
    assert!(!case.join("el.json").exists());
    // ... unless the check is turned off.
    let o = write_and_decode(
        &dir.join("z-walls-unchecked"),
        &files,
        &["--fluid", "z"],
        &["--layout-check", "off"],
    );
    assert!(o.status.success(), "{}", stderr(&o));

    // A cell HemoCell deleted: its warning in HemoCell's stdout fails the run, frames or not.
    let case = dir.join("deleted");
    std::fs::create_dir_all(&case).unwrap();
    std::fs::write(
        case.join("hemocell.log"),
        "(HemoCell) (Output) writing output at timestep 100\n\
         (HemoCell) (Delete Cells) WARNING! Particle deleted from local domain. This means the whole cell will be deleted!\n\
         \t Particle ID:0\n\t Position: 3.2, 45.1, 9; vel.: 0, 0, 0; force: 0, 0, 0\n",
    )
    .unwrap();
    let o = write_and_decode(&case, &files, &["--fluid", "y"], &["--log", "hemocell.log"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let last = last_stderr_line(&o);
    assert!(last.contains("HemoCell deleted the cell"), "{last}");
    assert!(last.contains("Particle ID:0"), "{last}");

    // A frame with fewer vertices than the cell's first output.
    let o = write_and_decode(
        &dir.join("lost-vertices"),
        &files,
        &["--drop-vertices", "150:5"],
        &[],
    );
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let last = last_stderr_line(&o);
    assert!(
        last.contains("iteration 150: 637 of the cell's 642 vertices"),
        "{last}"
    );
}
