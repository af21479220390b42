//! The native model against the real HemoCell, and the HemoCell adapter against the real
//! program's ways of failing.
//!
//! * `data/hemocell_vs_native.csv` (provenance: `data/hemocell_vs_native.md`) holds 12 points
//!   run through `examples/hemocell/` with HemoCell v2.1 (Palabos v2.1r0, interior viscosity) and
//!   with `iuq rbc shear` in both protocols, and in the scaled protocol with HemoCell's
//!   orientation of the mesh (`--initial-orientation hemocell`), with which every point agrees.
//!   [`the_comparison_table_is_complete_and_consistent`]
//!   checks the table against its own frames and the agreement criterion below (fast);
//!   [`native_scaled_model_agrees_with_hemocell`] reruns the native model (scaled protocol, 12
//!   runs of about 40 s on one core) and compares it with HemoCell's columns:
//!
//!   ```sh
//!   flock /tmp/iuq-cargo.lock cargo test --release -p iuq --test cli hemocell_comparison:: -- --ignored
//!   ```
//!
//! * The adapter (`run-hemocell.sh`, `decode-el.py`): HemoCell's own reason when it exits
//!   non-zero (it prints it on stdout) reaches the campaign's record; a cell HemoCell deleted
//!   fails the run with HemoCell's message; both wall layouts (v2.1's y walls, v2.2 and later's z
//!   walls) decode to the same EL, a layout the fluid output contradicts fails, and so do a cell
//!   beyond a wall, one split by the periodic boundary and a frame that lost vertices.
//! * `data/hemocell27_vs_hemocell21.csv` (provenance: `data/hemocell27_vs_hemocell21.md`) holds
//!   HemoCell 2.7's runs at the same 12 points beside 2.1's and the native model's:
//!   [`the_hemocell_versions_table_is_complete_and_consistent`] checks it against its own frames,
//!   the 2.1 table, and what its provenance says of it. The HDF5 parts need h5py and are
//!   skipped, with the reason printed, without it.

use crate::common::{
    hemocell_campaign_in, hemocell_example_dir, iuq, json_of, native_frames, scratch, stderr_of,
};

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

const SUITE: &str = "hemocell-comparison";

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
        let mut text = std::fs::read_to_string(hemocell_example_dir().join(file)).unwrap();
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
    Command::new(hemocell_example_dir().join("run-hemocell.sh"))
        .args(["100", "200"])
        .current_dir(dir)
        .env("HEMOCELL_ONECELLSHEAR", simulator)
        .env("IUQ", env!("CARGO_BIN_EXE_iuq"))
        .output()
        .unwrap()
}

fn last_stderr_line(o: &Output) -> String {
    stderr_of(o).lines().last().unwrap_or("").to_string()
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
    assert_eq!(o.status.code(), Some(1), "{}", stderr_of(&o));
    assert_eq!(
        last_stderr_line(&o),
        format!("run-hemocell.sh: oneCellShear exited with status 1: {NO_INTERIOR_VISCOSITY}")
    );
    // HemoCell's output is kept in the run folder and passed on to stdout.
    let log = std::fs::read_to_string(dir.join("hemocell.log")).unwrap();
    assert!(log.contains(NO_INTERIOR_VISCOSITY));
    assert!(String::from_utf8_lossy(&o.stdout).contains(NO_INTERIOR_VISCOSITY));

    // An uncaught exception (a key missing from config.xml): terminate, Open MPI's signal
    // handler's backtrace, SIGABRT (what HemoCell v2.1 printed without <tmeas>).
    let fake = fake_onecellshear(
        &dir,
        "echo \"terminate called after throwing an instance of 'std::invalid_argument'\"\n\
         echo '  what():  XML child tmeas does not exist.'\n\
         echo '[vm:21654] *** Process received signal ***'\n\
         echo '[vm:21654] Signal: Aborted (6)'\n\
         echo '[vm:21654] *** End of error message ***'\nkill -ABRT $$",
    );
    let o = run_adapter(&dir, &fake);
    assert_eq!(o.status.code(), Some(1), "{}", stderr_of(&o));
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
    assert_eq!(o.status.code(), Some(1), "{}", stderr_of(&o));
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
    let study = hemocell_campaign_in(&dir, 3);
    let fake = fake_onecellshear(&dir, &format!("echo '{NO_INTERIOR_VISCOSITY}'\nexit 1"));
    let o = Command::new(env!("CARGO_BIN_EXE_iuq"))
        .args(["run", study.to_str().unwrap(), "--json"])
        .env("HEMOCELL_ONECELLSHEAR", &fake)
        .env("IUQ", env!("CARGO_BIN_EXE_iuq"))
        .output()
        .unwrap();
    let v = json_of(&o);
    assert_eq!(v["counts"]["failed"], 3, "{v}\n{}", stderr_of(&o));
    let export = iuq(&["export", study.to_str().unwrap(), "--json"]);
    assert!(export.status.success(), "{}", stderr_of(&export));
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
    c.arg(hemocell_example_dir().join("tests/write_hemocell_hdf5.py"))
        .arg(&hdf5)
        .args(["--frame", "0"])
        .arg(&files[0]);
    for (k, f) in files.iter().enumerate() {
        c.arg("--frame").arg((100 + 10 * k).to_string()).arg(f);
    }
    c.args(["--cell-type", "RBC"]).args(extra);
    let o = c.output().unwrap();
    assert!(o.status.success(), "{}", stderr_of(&o));
    Command::new("python3")
        .arg(hemocell_example_dir().join("decode-el.py"))
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
fn the_decoder_reads_both_wall_layouts_and_fails_cells_deleted_or_out_of_the_box() {
    if !h5py_available("the decoder's HemoCell checks") {
        return;
    }
    let dir = scratch(SUITE, "decoder-checks");
    let (native, files) = native_frames(&dir, None);
    let native_el = native["el"]["value"].as_f64().unwrap();
    let decoded_el = |case: &Path| -> f64 {
        let el: Value =
            serde_json::from_str(&std::fs::read_to_string(case.join("el.json")).unwrap()).unwrap();
        el["el"]["value"].as_f64().unwrap()
    };
    let summary_of = |case: &Path| -> Value {
        serde_json::from_str(&std::fs::read_to_string(case.join("hemocell-frames.json")).unwrap())
            .unwrap()
    };

    // HemoCell v2.1's layout (walls on the y planes), read from its fluid output: decoded, with
    // the fluid's shear in the summary.
    let case = dir.join("y-walls");
    let o = write_and_decode(&case, &files, &["--fluid", "y"], &[]);
    assert!(o.status.success(), "{}", stderr_of(&o));
    assert!((decoded_el(&case) - native_el).abs() < 1e-9);
    let summary = summary_of(&case);
    assert_eq!(summary["layout"], "y-walls");
    assert_eq!(summary["frames"].as_array().unwrap().len(), 10);
    assert_eq!(summary["frames"][0]["vertices"], 642);
    let g = &summary["fluid_du_x_per_node"];
    // u_x = 5000/s × 0.5 µm per node along y: 2.5e-3 m/s per node, none along z.
    assert!((g["y"].as_f64().unwrap() - 2.5e-3).abs() < 1e-6, "{g}");
    assert!(g["z"].as_f64().unwrap().abs() < 1e-9, "{g}");

    // HemoCell >= 2.2 (walls on the z planes, the shear plane x-z): the same shapes turned into
    // that layout decode to the same EL, the layout read from the fluid output ...
    let case = dir.join("z-walls");
    let o = write_and_decode(&case, &files, &["--fluid", "z", "--layout", "z-walls"], &[]);
    assert!(o.status.success(), "{}", stderr_of(&o));
    assert!((decoded_el(&case) - native_el).abs() < 1e-9);
    let summary = summary_of(&case);
    assert_eq!(summary["layout"], "z-walls");
    // HemoCell's axes in the summary: the cell's thin direction is y (vorticity) here.
    let extent = &summary["frames"][0]["extent_um"];
    assert!(
        extent[2].as_f64().unwrap() > extent[1].as_f64().unwrap(),
        "{extent}"
    );
    // ... or named, without fluid output.
    let case = dir.join("z-walls-named");
    let o = write_and_decode(
        &case,
        &files,
        &["--layout", "z-walls"],
        &["--layout", "z-walls"],
    );
    assert!(o.status.success(), "{}", stderr_of(&o));
    assert!((decoded_el(&case) - native_el).abs() < 1e-9);
    // A named layout the fluid output contradicts fails the run, saying which it is.
    let case = dir.join("z-walls-named-wrong");
    let o = write_and_decode(
        &case,
        &files,
        &["--fluid", "z", "--layout", "z-walls"],
        &["--layout", "y-walls"],
    );
    assert_eq!(o.status.code(), Some(1), "{}", stderr_of(&o));
    let last = last_stderr_line(&o);
    assert!(last.contains("the fluid is sheared along z"), "{last}");
    assert!(last.contains("HEMOCELL_LAYOUT=z-walls"), "{last}");
    assert!(!case.join("el.json").exists());

    // A cell beyond a wall (a gap of 12 nodes instead of 20): failed with the frame, never a
    // number.
    let case = dir.join("beyond-a-wall");
    let o = write_and_decode(
        &case,
        &files,
        &["--fluid", "z", "--layout", "z-walls"],
        &["--box", "40,40,12"],
    );
    assert_eq!(o.status.code(), Some(1), "{}", stderr_of(&o));
    let last = last_stderr_line(&o);
    assert!(
        last.contains("iteration 100: the cell left the box: vertices beyond a wall along z"),
        "{last}"
    );
    assert!(!case.join("el.json").exists());
    // A cell split by the periodic boundary along x (moved by 15 nodes and wrapped): failed too.
    let case = dir.join("across-the-periodic-boundary");
    let o = write_and_decode(
        &case,
        &files,
        &["--fluid", "z", "--layout", "z-walls", "--wrap-x", "15"],
        &[],
    );
    assert_eq!(o.status.code(), Some(1), "{}", stderr_of(&o));
    let last = last_stderr_line(&o);
    assert!(
        last.contains("the cell lies across the periodic boundary along x"),
        "{last}"
    );
    assert!(!case.join("el.json").exists());

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
    assert_eq!(o.status.code(), Some(1), "{}", stderr_of(&o));
    let last = last_stderr_line(&o);
    assert!(last.contains("HemoCell deleted the cell"), "{last}");
    assert!(last.contains("Particle ID:0"), "{last}");

    // A cell HemoCell 2.7 deleted without its warning: from then on its outputs hold no
    // vertices.
    let o = write_and_decode(
        &dir.join("silently-deleted"),
        &files,
        &[
            "--fluid",
            "z",
            "--layout",
            "z-walls",
            "--drop-vertices",
            "190:642",
        ],
        &[],
    );
    assert_eq!(o.status.code(), Some(1), "{}", stderr_of(&o));
    let last = last_stderr_line(&o);
    assert!(
        last.contains(
            "iteration 190: no membrane vertices in the output (HemoCell deleted the cell"
        ),
        "{last}"
    );

    // A frame with fewer vertices than the cell's first output.
    let o = write_and_decode(
        &dir.join("lost-vertices"),
        &files,
        &["--drop-vertices", "150:5"],
        &[],
    );
    assert_eq!(o.status.code(), Some(1), "{}", stderr_of(&o));
    let last = last_stderr_line(&o);
    assert!(
        last.contains("iteration 150: 637 of the cell's 642 vertices"),
        "{last}"
    );
}

// ------------------------------------------------------------------------------------------
// The native model against HemoCell's table.

/// How many combined frame standard deviations two window means may lie apart. The study's
/// likelihood takes a run's frame std as the computational uncertainty of its EL; two
/// computations of the same EL with uncertainties s_h and s_n differ by a quantity of spread
/// sqrt(s_h² + s_n²), and 3 of those bound it at 99.7 % for a Gaussian error (about 3 % that one
/// of 12 points exceeds it by chance). The frames are not independent (EL drifts and oscillates
/// over the window), so the frame std is a scale, not a standard error; no larger k is used to
/// absorb the disagreements below, which are listed and explained instead.
const K: f64 = 3.0;

/// Points where the native model (scaled protocol) and HemoCell v2.1 disagree beyond `K`, each
/// with the reason found and the largest |difference| accepted before the test calls it a
/// change (`data/hemocell_vs_native.md`, "Disagreements"):
/// (kLink, kBend, Λ, stress, largest |native − HemoCell|, reason).
const KNOWN_DISAGREEMENTS: [(f64, f64, f64, f64, f64, &str); 3] = [
    (
        30.0,
        200.0,
        5.0,
        6.19,
        0.08,
        "native triangles cross the area singularity (|ΔA/A| > 0.3) from strain ≈ 4 and its EL falls \
         (0.56 → 0.44); HemoCell's stay pinned at ±0.30 and its EL stays at 0.52–0.53",
    ),
    (
        36.7,
        367.0,
        5.9,
        9.04,
        0.12,
        "both meshes pass the area singularity; the native's EL falls from strain ≈ 6.5 (0.61 → 0.45 \
         scaled, → 0.54 reference), HemoCell's stays at 0.58–0.60",
    ),
    (
        80.0,
        100.0,
        10.0,
        4.24,
        0.03,
        "EL oscillates with strain (shape memory of the tank-treading membrane) with a shorter period \
         in the native model (≈ 4.5 strain units) than in HemoCell: the window catches the native \
         near a peak and HemoCell near a trough",
    ),
];

#[test]
fn the_hemocell_versions_table_is_complete_and_consistent() {
    let reference = read_table();
    let rows = read_table_at(&versions_table_path());
    assert_eq!(rows.len(), 12);
    for row in &rows {
        let point = row.point();
        assert_eq!(row.0["v2.7_status"], "succeeded", "{point:?}");
        // The summary columns are those of the 10 frames.
        let frames = row.frames("v2.7_el_frames");
        assert_eq!(frames.len(), 10, "{point:?}");
        let (m, s) = mean_std(&frames);
        assert!((m - row.f("v2.7_el_mean")).abs() < 5e-6, "{point:?}");
        assert!((s - row.f("v2.7_el_std")).abs() < 5e-6, "{point:?}");
        // The 2.1 and native columns are the 2.1 table's, at the same point.
        let r = reference
            .iter()
            .find(|r| r.point() == point)
            .unwrap_or_else(|| panic!("{point:?} is not a point of the 2.1 table"));
        for (ours, theirs) in [
            ("v2.1_el_mean", "hemocell_el_mean"),
            ("v2.1_el_std", "hemocell_el_std"),
            ("native_el_mean", "native_hemocell_orientation_mean"),
            ("native_el_std", "native_hemocell_orientation_std"),
        ] {
            assert!((row.f(ours) - r.f(theirs)).abs() < 5e-6, "{point:?} {ours}");
        }
        let diff = row.f("v2.7_el_mean") - row.f("v2.1_el_mean");
        assert!((diff - row.f("diff_v2.7_v2.1")).abs() < 5e-6, "{point:?}");
        let z = diff / (row.f("v2.7_el_std").powi(2) + row.f("v2.1_el_std").powi(2)).sqrt();
        assert!(
            (z - row.f("z_v2.7_v2.1")).abs() < 1e-3 * z.abs(),
            "{point:?}"
        );
        // What the provenance says: 2.7's cell is longer at every point, by 0.07-0.17.
        assert!((0.07..0.17).contains(&diff), "{point:?}: {diff}");
    }
    // ... and EL falls with kLink at every stress and rises with stress for every cell, in 2.7
    // as in 2.1 (the points are sorted by kLink, then stress).
    for (i, a) in rows.iter().enumerate() {
        for b in &rows[i + 1..] {
            let (pa, pb) = (a.point(), b.point());
            if pa.3 == pb.3 && pa.0 < pb.0 {
                assert!(a.f("v2.7_el_mean") > b.f("v2.7_el_mean"), "{pa:?} {pb:?}");
            }
            if pa.0 == pb.0 && pa.3 < pb.3 {
                assert!(a.f("v2.7_el_mean") < b.f("v2.7_el_mean"), "{pa:?} {pb:?}");
            }
        }
    }
}

/// One row of `data/hemocell_vs_native.csv`, by column name.
struct Row(BTreeMap<String, String>);

impl Row {
    fn f(&self, column: &str) -> f64 {
        self.0[column]
            .parse()
            .unwrap_or_else(|_| panic!("{column}: {:?}", self.0[column]))
    }
    fn frames(&self, column: &str) -> Vec<f64> {
        self.0[column]
            .split(';')
            .map(|v| v.parse().unwrap())
            .collect()
    }
    fn point(&self) -> (f64, f64, f64, f64) {
        (
            self.f("kLink"),
            self.f("kBend"),
            self.f("viscosityRatio"),
            self.f("stress"),
        )
    }
    fn known(&self) -> Option<&'static (f64, f64, f64, f64, f64, &'static str)> {
        let (l, b, r, s) = self.point();
        KNOWN_DISAGREEMENTS
            .iter()
            .find(|k| k.0 == l && k.1 == b && k.2 == r && k.3 == s)
    }
}

fn read_table() -> Vec<Row> {
    read_table_at(&table_path())
}

fn read_table_at(path: &Path) -> Vec<Row> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    lines
        .map(|l| {
            let values: Vec<&str> = l.split(',').collect();
            assert_eq!(values.len(), header.len(), "{l}");
            Row(header
                .iter()
                .cloned()
                .zip(values.into_iter().map(String::from))
                .collect())
        })
        .collect()
}

/// HemoCell 2.7's runs at the same 12 points (provenance: `data/hemocell27_vs_hemocell21.md`).
fn versions_table_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/hemocell27_vs_hemocell21.csv")
}

fn table_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/hemocell_vs_native.csv")
}

fn mean_std(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    (
        m,
        (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt(),
    )
}

/// Least-squares change of evenly spaced frames over the window (slope × (n − 1)).
fn trend(v: &[f64]) -> f64 {
    let n = v.len() as f64;
    let mx = (n - 1.0) / 2.0;
    let my = v.iter().sum::<f64>() / n;
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (i, y) in v.iter().enumerate() {
        sxy += (i as f64 - mx) * (y - my);
        sxx += (i as f64 - mx).powi(2);
    }
    sxy / sxx * (n - 1.0)
}

/// `|native − HemoCell| ≤ K·sqrt(s_h² + s_n²)` unless the point is a known disagreement, which
/// must then still disagree beyond K (else the list is stale) and stay below its recorded size.
/// Returns the lines of a printed table.
fn check_agreement(
    row: &Row,
    native_mean: f64,
    native_std: f64,
    orientation: Orientation,
    failures: &mut Vec<String>,
) -> String {
    let (h, sh) = (row.f("hemocell_el_mean"), row.f("hemocell_el_std"));
    let diff = native_mean - h;
    let z = diff / (sh * sh + native_std * native_std).sqrt();
    let (l, b, r, s) = row.point();
    let label = format!("kLink {l} kBend {b} Λ {r} at {s} Pa");
    // HemoCell's own orientation of the mesh has no known disagreement.
    let known = match orientation {
        Orientation::Unrotated => row.known(),
        Orientation::Hemocell => None,
    };
    match known {
        None if z.abs() > K => failures.push(format!(
            "{label}: native {native_mean:.4} ± {native_std:.4}, HemoCell {h:.4} ± {sh:.4}: |z| = {:.2} > {K}",
            z.abs()
        )),
        Some(k) if z.abs() <= K => failures.push(format!(
            "{label}: listed as a known disagreement ({}) but now agrees (z = {z:.2}): update KNOWN_DISAGREEMENTS and the provenance",
            k.5
        )),
        Some(k) if diff.abs() > k.4 => failures.push(format!(
            "{label}: known disagreement grew: |diff| = {:.4} > {} ({})",
            diff.abs(),
            k.4,
            k.5
        )),
        _ => {}
    }
    format!(
        "{label:<36} HemoCell {h:.4} ± {sh:.4}  native {native_mean:.4} ± {native_std:.4}  diff {diff:+.4}  z {z:+.2}{}",
        if known.is_some() { "  (known)" } else { "" }
    )
}

/// How the native runs started their mesh (`iuq rbc shear --initial-orientation`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Orientation {
    /// The icosahedron's axes (the columns `native_scaled_*`, `native_reference_*`).
    Unrotated,
    /// HemoCell's, turned 90° in the disk plane (the columns `native_hemocell_orientation_*`).
    Hemocell,
}

impl Orientation {
    fn name(self) -> &'static str {
        match self {
            Self::Unrotated => "unrotated",
            Self::Hemocell => "hemocell",
        }
    }
}

#[test]
fn the_comparison_table_is_complete_and_consistent() {
    let rows = read_table();
    assert!(rows.len() >= 12, "{} points", rows.len());
    // The four parameter sets of the brief, each at 4.24, 6.19 and 9.04 Pa.
    let sets: Vec<(f64, f64, f64)> = {
        let mut s: Vec<_> = rows
            .iter()
            .map(|r| (r.f("kLink"), r.f("kBend"), r.f("viscosityRatio")))
            .collect();
        s.sort_by(|a, b| a.partial_cmp(b).unwrap());
        s.dedup();
        s
    };
    assert!(
        sets.iter().any(|s| s.0 <= 40.0 && s.0 != 36.7),
        "a soft cell: {sets:?}"
    );
    assert!(
        sets.contains(&(36.7, 367.0, 5.9)),
        "the validation cell: {sets:?}"
    );
    assert!(sets.iter().any(|s| s.0 >= 120.0), "a stiff cell: {sets:?}");
    assert!(sets.len() >= 4, "{sets:?}");
    for set in &sets {
        for stress in [4.24, 6.19, 9.04] {
            assert!(
                rows.iter().any(
                    |r| (r.f("kLink"), r.f("kBend"), r.f("viscosityRatio")) == *set
                        && r.f("stress") == stress
                ),
                "{set:?} at {stress} Pa missing"
            );
        }
    }
    let mut failures = Vec::new();
    for row in &rows {
        // Every summary column follows from the frames (written with 6 decimals).
        for (prefix, frames) in [
            ("hemocell_el", "hemocell_el_frames"),
            ("native_scaled", "native_scaled_el_frames"),
            ("native_reference", "native_reference_el_frames"),
            (
                "native_hemocell_orientation",
                "native_hemocell_orientation_el_frames",
            ),
        ] {
            let v = row.frames(frames);
            assert_eq!(v.len(), 10, "{frames}");
            let (m, s) = mean_std(&v);
            assert!(
                (m - row.f(&format!("{prefix}_mean"))).abs() < 2e-6,
                "{prefix}"
            );
            assert!(
                (s - row.f(&format!("{prefix}_std"))).abs() < 2e-6,
                "{prefix}"
            );
            // HemoCell's frames are evenly spaced; the native's to within a step.
            assert!(
                (trend(&v) - row.f(&format!("{prefix}_trend"))).abs() < 2e-3,
                "{prefix}"
            );
        }
        for protocol in ["scaled", "reference", "hemocell_orientation"] {
            let n = row.f(&format!("native_{protocol}_mean"));
            let d = row.f(&format!("diff_{protocol}"));
            assert!((d - (n - row.f("hemocell_el_mean"))).abs() < 2e-6);
            let z = d
                / (row.f("hemocell_el_std").powi(2)
                    + row.f(&format!("native_{protocol}_std")).powi(2))
                .sqrt();
            assert!((z - row.f(&format!("z_{protocol}"))).abs() < 1e-3 * z.abs().max(1.0));
        }
        let line = check_agreement(
            row,
            row.f("native_scaled_mean"),
            row.f("native_scaled_std"),
            Orientation::Unrotated,
            &mut failures,
        );
        println!("{line}");
        // With HemoCell's orientation of the mesh, every point agrees: no exception.
        let line = check_agreement(
            row,
            row.f("native_hemocell_orientation_mean"),
            row.f("native_hemocell_orientation_std"),
            Orientation::Hemocell,
            &mut failures,
        );
        println!("{line}  (HemoCell's orientation)");
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Reruns the native model (scaled protocol, carry-on past the singularities, as HemoCell) at
/// the table's 12 points and compares each with HemoCell's columns by the criterion of
/// [`check_agreement`]. About 15–40 s per point on one core:
///
/// ```sh
/// flock /tmp/iuq-cargo.lock cargo test --release -p iuq --test cli hemocell_comparison:: -- --ignored --nocapture
/// ```
#[test]
#[ignore = "runs the native model 24 times (several minutes)"]
fn native_scaled_model_agrees_with_hemocell() {
    let mut failures = Vec::new();
    for orientation in [Orientation::Unrotated, Orientation::Hemocell] {
        for row in read_table() {
            let (l, b, r, s) = row.point();
            let o = iuq(&[
                "rbc",
                "shear",
                "--json",
                "--klink",
                &l.to_string(),
                "--kbend",
                &b.to_string(),
                "--viscosity-ratio",
                &r.to_string(),
                "--stress",
                &s.to_string(),
                "--protocol",
                "scaled",
                "--past-singularity",
                "carry-on",
                "--initial-orientation",
                orientation.name(),
            ]);
            assert!(o.status.success(), "{}", stderr_of(&o));
            let v = json_of(&o);
            let frames: Vec<f64> = v["el_frames"]
                .as_array()
                .unwrap()
                .iter()
                .map(|e| e.as_f64().unwrap())
                .collect();
            let (m, sd) = mean_std(&frames);
            println!(
                "{} ({})",
                check_agreement(&row, m, sd, orientation, &mut failures),
                orientation.name()
            );
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
