//! The HemoCell adapter (`examples/hemocell/`) without HemoCell: shapes of `iuq rbc shear` are
//! written into HemoCell's HDF5 output layout (`tests/write_hemocell_hdf5.py`), decoded by
//! `decode-el.py`, and must give the EL of `iuq rbc shear --json`; the campaign study runs end to
//! end with a fake `oneCellShear` built the same way; and `iuq rbc elongation` names bad input.
//! The parts that need h5py are skipped, with the reason printed, when `import h5py` fails.

use crate::common::{
    hemocell_campaign_in, hemocell_example_dir, iuq, json_of, native_frames, scratch, stderr_of,
};

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

const SUITE: &str = "cli-hemocell";

/// `None` when python3 with numpy and h5py is available, else why not.
fn h5py_missing() -> Option<String> {
    match Command::new("python3")
        .args(["-c", "import numpy, h5py"])
        .output()
    {
        Ok(o) if o.status.success() => None,
        Ok(o) => Some(format!(
            "`import numpy, h5py` failed: {}",
            String::from_utf8_lossy(&o.stderr).trim()
        )),
        Err(e) => Some(format!("python3 cannot be started: {e}")),
    }
}

fn skip_without_h5py(test: &str) -> bool {
    match h5py_missing() {
        Some(reason) => {
            println!("skipping {test}: {reason} (install with `python3 -m pip install h5py`)");
            true
        }
        None => false,
    }
}

fn assert_same_el(decoded: &Value, native: &Value) {
    let close = |a: &Value, b: &Value, what: &str| {
        let (a, b) = (a.as_f64().unwrap(), b.as_f64().unwrap());
        assert!((a - b).abs() <= 1e-9, "{what}: {a} vs {b}");
    };
    close(&decoded["el"]["value"], &native["el"]["value"], "mean");
    close(&decoded["el"]["std"], &native["el"]["std"], "std");
    assert_eq!(decoded["frames"], 10);
    let (d, n) = (
        decoded["el_frames"].as_array().unwrap(),
        native["el_frames"].as_array().unwrap(),
    );
    assert_eq!(d.len(), n.len());
    for (a, b) in d.iter().zip(n) {
        close(a, b, "frame");
    }
    // A real measurement, not a degenerate one.
    assert!(native["el"]["value"].as_f64().unwrap() > 0.02, "{native}");
}

#[test]
fn elongation_of_the_shape_files_equals_the_native_measurement() {
    for format in ["vtk", "ply"] {
        let dir = scratch(SUITE, &format!("shapes-{format}"));
        let (native, files) = native_frames(&dir, Some(format));
        let mut args = vec!["--json", "rbc", "elongation"];
        args.extend(files.iter().map(|f| f.to_str().unwrap()));
        let out = dir.join("el.json");
        args.extend(["--out", out.to_str().unwrap()]);
        let o = iuq(&args);
        assert!(o.status.success(), "{}", stderr_of(&o));
        let printed = json_of(&o);
        assert_same_el(&printed, &native);
        let written: Value = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
        assert_eq!(written, printed);
        // The same frames in micrometres and metres (CSV) give the same EL.
        for (unit, factor) in [("um", 0.5), ("m", 0.5e-6)] {
            let mut csvs = Vec::new();
            for (i, f) in files.iter().enumerate() {
                let text = std::fs::read_to_string(f).unwrap();
                let vertices = points_of(&text, format);
                let mut csv = String::from("x,y,z\n");
                for v in vertices {
                    csv.push_str(&format!(
                        "{:?},{:?},{:?}\n",
                        v[0] * factor,
                        v[1] * factor,
                        v[2] * factor
                    ));
                }
                let path = dir.join(format!("frame{i}-{unit}.csv"));
                std::fs::write(&path, csv).unwrap();
                csvs.push(path.display().to_string());
            }
            let mut args = vec!["--json", "rbc", "elongation", "--unit", unit];
            args.extend(csvs.iter().map(String::as_str));
            let o = iuq(&args);
            assert!(o.status.success(), "{}", stderr_of(&o));
            assert_same_el(&json_of(&o), &native);
        }
    }
}

/// The vertex coordinates of a VTK or PLY file written by `iuq rbc shear`.
fn points_of(text: &str, format: &str) -> Vec<[f64; 3]> {
    let mut lines = text.lines();
    let count: usize = if format == "vtk" {
        let header = lines.find(|l| l.starts_with("POINTS")).unwrap();
        header.split_whitespace().nth(1).unwrap().parse().unwrap()
    } else {
        let header = lines
            .by_ref()
            .find(|l| l.starts_with("element vertex"))
            .unwrap();
        let n = header.split_whitespace().nth(2).unwrap().parse().unwrap();
        lines.find(|l| *l == "end_header").unwrap();
        n
    };
    lines
        .take(count)
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|w| w.parse().unwrap()).collect();
            [v[0], v[1], v[2]]
        })
        .collect()
}

/// Write the frames into HemoCell's layout under `dir/tmp/hdf5` at the native frame steps, plus
/// decoys outside the window (iteration 0 and one past the last frame).
fn write_hemocell_tree(dir: &Path, native: &Value, files: &[PathBuf], extra: &[&str]) -> PathBuf {
    let hdf5 = dir.join("tmp/hdf5");
    let steps: Vec<u64> = native["frame_steps"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_u64().unwrap())
        .collect();
    let mut c = Command::new("python3");
    c.arg(hemocell_example_dir().join("tests/write_hemocell_hdf5.py"))
        .arg(&hdf5);
    for (step, file) in steps.iter().zip(files) {
        c.arg("--frame").arg(step.to_string()).arg(file);
    }
    c.args(["--frame", "0"]).arg(&files[0]);
    c.args(["--frame", &(steps[9] + 1).to_string()])
        .arg(&files[0]);
    c.args(extra);
    let o = c.output().unwrap();
    assert!(o.status.success(), "{}", stderr_of(&o));
    hdf5
}

fn decode(dir: &Path, hdf5: &Path, from: u64, to: u64) -> Output {
    Command::new("python3")
        .arg(hemocell_example_dir().join("decode-el.py"))
        .arg(hdf5)
        .args(["--from", &from.to_string(), "--to", &to.to_string()])
        .args(["--frames", "10", "--out", "el.json"])
        .current_dir(dir)
        .env("IUQ", env!("CARGO_BIN_EXE_iuq"))
        .output()
        .unwrap()
}

#[test]
fn decoded_hemocell_hdf5_output_equals_the_native_measurement() {
    if skip_without_h5py("the HemoCell HDF5 decoding test") {
        return;
    }
    let dir = scratch(SUITE, "hdf5");
    let (native, files) = native_frames(&dir, Some("vtk"));
    let steps = native["frame_steps"].as_array().unwrap();
    let (first, last) = (steps[0].as_u64().unwrap(), steps[9].as_u64().unwrap());
    // Metres on three ranks, the cell whole on every rank it touches (HemoCell's own layout);
    // lattice units split across four ranks; metres split, with cell and vertex ids.
    for (name, extra) in [
        ("whole-cells-m", &["--ranks", "3", "--unit", "m"][..]),
        (
            "split-lattice",
            &["--ranks", "4", "--unit", "lattice", "--split"][..],
        ),
        (
            "split-ids-m",
            &["--ranks", "2", "--unit", "m", "--split", "--with-ids"][..],
        ),
    ] {
        let case = dir.join(name);
        std::fs::create_dir_all(&case).unwrap();
        let hdf5 = write_hemocell_tree(&case, &native, &files, extra);
        let o = decode(&case, &hdf5, first, last);
        assert!(o.status.success(), "{name}: {}", stderr_of(&o));
        let decoded: Value =
            serde_json::from_str(&std::fs::read_to_string(case.join("el.json")).unwrap()).unwrap();
        assert_same_el(&decoded, &native);
        // One CSV per frame, in micrometres, with every vertex once.
        let csvs: Vec<_> = std::fs::read_dir(case.join("el-frames"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        assert_eq!(csvs.len(), 10, "{name}");
        let text = std::fs::read_to_string(&csvs[0]).unwrap();
        assert!(text.starts_with("x,y,z\n"));
        assert_eq!(text.lines().count(), 1 + 642, "{name}");
    }

    // No output in the window, and no output folder: failures with their reason (exit 1).
    let case = dir.join("whole-cells-m");
    let o = decode(&case, &case.join("tmp/hdf5"), last + 10, last + 20);
    assert_eq!(o.status.code(), Some(1), "{}", stderr_of(&o));
    assert!(
        stderr_of(&o).contains("0 output iteration(s)"),
        "{}",
        stderr_of(&o)
    );
    let o = decode(&case, &case.join("nothing"), first, last);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr_of(&o).contains("no such folder"),
        "{}",
        stderr_of(&o)
    );
}

/// A stand-in for HemoCell's `oneCellShear config.xml`: reads the filled templates, runs
/// `iuq rbc shear` with their parameters, and writes its frames at HemoCell's output iterations
/// (the last 10 multiples of tmeas in [t_start, t_max]) in HemoCell's HDF5 layout.
const FAKE_ONECELLSHEAR: &str = r#"#!/usr/bin/env python3
import json, os, re, subprocess, sys
def value(path, tag):
    return float(re.search(r"<%s>\s*([^<\s]+)\s*</%s>" % (tag, tag), open(path).read()).group(1))
config = sys.argv[1]
rate, tmax, tmeas = value(config, "shearrate"), int(value(config, "tmax")), int(value(config, "tmeas"))
assert os.path.exists("RBC_HO.pos") and os.path.exists("RBC.pos"), "no position file"
layout = os.environ.get("FAKE_LAYOUT", "y-walls")
angles = open("RBC.pos").read().split("\n")[1].split()[3:]
assert angles == (["0", "0", "0"] if layout == "z-walls" else ["90", "0", "0"]), angles
material = "RBC_HO.xml"
t_start = int(7.5 / (rate * 0.5e-7))
iterations = [i for i in range(0, tmax + 1, tmeas) if i >= t_start][-10:]
stress = rate * 1025 * 1.1e-6
run = subprocess.run([os.environ["IUQ"], "rbc", "shear", "--stress", repr(stress),
    "--klink", repr(value(material, "kLink")), "--kbend", repr(value(material, "kBend")),
    "--viscosity-ratio", repr(value(material, "viscosityRatio")),
    "--start-strain", "0.05", "--shape-out", "shapes", "--json"], capture_output=True, text=True)
if run.returncode != 0:
    sys.exit(run.stderr)
open("native.json", "w").write(run.stdout)
shapes = json.loads(run.stdout)["shapes"]
args = []
for i, s in zip(iterations, shapes):
    args += ["--frame", str(i), s]
extra = ["--layout", "z-walls", "--fluid", "z"] if layout == "z-walls" else []
subprocess.run([sys.executable, os.environ["WRITER"], "tmp/hdf5", "--ranks", "2", *extra, *args], check=True)
"#;

#[test]
fn the_campaign_study_runs_end_to_end_with_a_fake_onecellshear() {
    if skip_without_h5py("the HemoCell campaign test") {
        return;
    }
    // HemoCell <= 2.1 (walls on the y planes), the fake outside a HemoCell tree: the layout
    // cannot be read before the run, y-walls is assumed (and checked by the decoder); and
    // HemoCell >= 2.2 (walls on the z planes), the fake inside a HemoCell tree whose
    // helper/hemocellInit.hh says so: the cell is placed by RBC-z-walls.pos, the frames are
    // written in HemoCell 2.7's axes with its fluid output, and the EL is measured in the shear
    // plane all the same.
    for layout in ["y-walls", "z-walls"] {
        campaign_with_a_fake_onecellshear(layout);
    }
}

fn campaign_with_a_fake_onecellshear(layout: &str) {
    let dir = scratch(SUITE, &format!("campaign-{layout}"));
    let study = hemocell_campaign_in(&dir, 3);
    let fake = if layout == "z-walls" {
        let tree = dir.join("HemoCell");
        std::fs::create_dir_all(tree.join("helper")).unwrap();
        std::fs::create_dir_all(tree.join("examples/oneCellShear")).unwrap();
        // The wall line of HemoCell 2.7's iniLatticeSquareCouette.
        std::fs::write(
            tree.join("helper/hemocellInit.hh"),
            "    plb::Box3D top = plb::Box3D(0, nx-1, 0, ny-1, nz-1, nz-1);\n",
        )
        .unwrap();
        tree.join("examples/oneCellShear/oneCellShear")
    } else {
        dir.join("oneCellShear")
    };
    std::fs::write(&fake, FAKE_ONECELLSHEAR).unwrap();
    Command::new("chmod").arg("+x").arg(&fake).status().unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_iuq"))
        .args(["run", study.to_str().unwrap(), "--json"])
        .env("HEMOCELL_ONECELLSHEAR", &fake)
        .env("FAKE_LAYOUT", layout)
        .env("IUQ", env!("CARGO_BIN_EXE_iuq"))
        .env(
            "WRITER",
            hemocell_example_dir().join("tests/write_hemocell_hdf5.py"),
        )
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr_of(&o));
    let v = json_of(&o);
    assert_eq!(v["counts"]["succeeded"], 3, "{v}\n{}", stderr_of(&o));
    // Every run's decoded EL is the fake's native measurement of the same frames.
    let runs = dir.join("hemocell-shear.campaign/runs");
    let mut checked = 0;
    for entry in std::fs::read_dir(&runs).unwrap() {
        let run = entry.unwrap().path();
        let read = |name: &str| -> Value {
            serde_json::from_str(&std::fs::read_to_string(run.join(name)).unwrap()).unwrap()
        };
        let (decoded, native) = (read("el.json"), read("native.json"));
        let close = |a: &Value, b: &Value| (a.as_f64().unwrap() - b.as_f64().unwrap()).abs() < 1e-9;
        assert!(close(&decoded["el"]["value"], &native["el"]["value"]));
        assert!(close(&decoded["el"]["std"], &native["el"]["std"]));
        let params = read("params.json");
        let config = std::fs::read_to_string(run.join("config.xml")).unwrap();
        let tmax = params["tmax"].as_f64().unwrap();
        assert!(
            config.contains(&format!("<tmax> {tmax} </tmax>")),
            "{config}"
        );
        let material = std::fs::read_to_string(run.join("RBC.xml")).unwrap();
        assert!(!material.contains("{{"), "{material}");
        assert_eq!(read("hemocell-frames.json")["layout"], layout);
        checked += 1;
    }
    assert_eq!(checked, 3);
    let export = Command::new(env!("CARGO_BIN_EXE_iuq"))
        .args(["export", study.to_str().unwrap(), "--json"])
        .output()
        .unwrap();
    assert!(export.status.success(), "{}", stderr_of(&export));
}

#[test]
fn bad_input_to_elongation_is_named_with_exit_code_2_and_no_ellipse_with_1() {
    let dir = scratch(SUITE, "bad-input");
    let write = |name: &str, text: &str| {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p.display().to_string()
    };
    // A valid, elongated set of vertices: an ellipse of semi-axes 8 and 4 in the x–y plane.
    let mut ellipse = String::from("x,y,z\n");
    for k in 0..64 {
        let t = k as f64 * std::f64::consts::TAU / 64.0;
        ellipse.push_str(&format!("{},{},0\n", 8.0 * t.cos(), 4.0 * t.sin()));
    }
    let good = write("good.csv", &ellipse);
    let o = iuq(&["--json", "rbc", "elongation", &good, &good]);
    assert!(o.status.success(), "{}", stderr_of(&o));
    let v = json_of(&o);
    assert!(
        (v["el"]["value"].as_f64().unwrap() - 1.0 / 3.0).abs() < 0.02,
        "{v}"
    );
    assert_eq!(v["el"]["std"], 0.0);
    assert_eq!(v["frames"], 2);

    let missing = dir.join("missing.csv").display().to_string();
    let bad_header = write("header.csv", "a,b,c\n1,2,3\n");
    let not_finite = write("nan.csv", &ellipse.replace("\n8,0,0\n", "\n8,nan,0\n"));
    let not_number = write("word.csv", &ellipse.replace("\n8,0,0\n", "\n8,zero,0\n"));
    let empty = write("empty.csv", "x,y,z\n");
    let bad_vtk = write(
        "bad.vtk",
        "# vtk DataFile Version 3.0\nt\nASCII\nDATASET POLYDATA\nPOINTS 5 double\n0 0 0\n",
    );
    let bad_ply = write(
        "bad.ply",
        "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty double x\nend_header\n",
    );
    // Counts no file of this size could hold: an error, not an allocation that aborts.
    let huge_vtk = write(
        "huge.vtk",
        "# vtk DataFile Version 3.0\nt\nASCII\nDATASET POLYDATA\nPOINTS 18446744073709551615 double\n0 0 0\n",
    );
    let huge_ply = write(
        "huge.ply",
        "ply\nformat ascii 1.0\nelement vertex 1000000000000000000\nproperty double x\nproperty double y\nproperty double z\nend_header\n0 0 0\n",
    );
    for (file, reason) in [
        (&huge_vtk, "more than the file holds"),
        (&huge_ply, "more than the file holds"),
        (&missing, "cannot read"),
        (&bad_header, "no column `x`"),
        (&not_finite, "not a finite number"),
        (&not_number, "is not a number"),
        (&empty, "no vertices"),
        (&bad_vtk, "announces 5 points"),
        (&bad_ply, "not supported"),
    ] {
        let o = iuq(&["--json", "rbc", "elongation", &good, file]);
        assert_eq!(o.status.code(), Some(2), "{file}: {}", stderr_of(&o));
        let v = json_of(&o);
        assert_eq!(v["error"]["kind"], "bad_input");
        let message = v["error"]["message"].as_str().unwrap();
        assert!(
            message.contains(file.as_str()) && message.contains(reason),
            "{message}"
        );
    }
    // Fewer than 2 frames.
    let o = iuq(&["--json", "rbc", "elongation", &good]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        json_of(&o)["error"]["message"]
            .as_str()
            .unwrap()
            .contains("at least 2")
    );
    let o = iuq(&["rbc", "elongation"]);
    assert_eq!(o.status.code(), Some(2));
    // A valid shape whose contour admits no ellipse: a failure of the measurement.
    let line = write(
        "line.csv",
        "x,y,z\n0,0,0\n1,0,0\n2,0,0\n3,0,0\n4,0,0\n5,0,0\n6,0,0\n",
    );
    let o = iuq(&["--json", "rbc", "elongation", &good, &line]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr_of(&o));
    let v = json_of(&o);
    assert_eq!(v["error"]["kind"], "failure");
    let message = v["error"]["message"].as_str().unwrap();
    assert!(
        message.contains(&line) && message.contains("no ellipse"),
        "{message}"
    );
    // A shape far wider than any cell (a wrong unit): a failed measurement that says so, not
    // a contour of 10^30 bins; one beyond the range of numbers once converted: an input error.
    let wide = write("wide.csv", &ellipse.replace("\n8,0,0\n", "\n1e30,0,0\n"));
    let o = iuq(&["--json", "rbc", "elongation", &good, &wide]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr_of(&o));
    let message = json_of(&o)["error"]["message"]
        .as_str()
        .unwrap()
        .to_string();
    assert!(message.contains("contour bins"), "{message}");
    let vast = write("vast.csv", &ellipse.replace("\n8,0,0\n", "\n1e305,0,0\n"));
    let o = iuq(&["--json", "rbc", "elongation", "--unit", "m", &vast, &good]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr_of(&o));
    let message = json_of(&o)["error"]["message"]
        .as_str()
        .unwrap()
        .to_string();
    assert!(message.contains("beyond the range"), "{message}");
    // --out: nothing is written when the measurement fails.
    let out = dir.join("el.json");
    let o = iuq(&[
        "rbc",
        "elongation",
        &good,
        &line,
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(!out.exists());
}
