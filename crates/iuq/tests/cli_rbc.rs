//! End-to-end tests of `iuq rbc`: real processes. The shear runs use a short measuring window
//! (`--start-strain`) so that they take a second or two.

use crate::common;

use std::path::PathBuf;

use crate::common::{iuq, json_of};

/// A fresh, empty directory for one test.
fn scratch(name: &str) -> PathBuf {
    common::scratch("cli-rbc", name)
}

#[test]
fn a_short_shear_run_prints_the_elongation_index_and_writes_shapes() {
    let dir = scratch("shapes");
    let o = iuq(&[
        "rbc",
        "shear",
        "--klink",
        "36.7",
        "--kbend",
        "367",
        "--viscosity-ratio",
        "5.9",
        "--stress",
        "1.36",
        "--start-strain",
        "0.05",
        "--shape-out",
        dir.to_str().unwrap(),
        "--shape-format",
        "ply",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json_of(&o);
    for key in [
        "el_mean",
        "el_std",
        "el_frames",
        "steps",
        "seconds",
        "mlups",
    ] {
        assert!(v.get(key).is_some(), "missing {key}: {v}");
    }
    let frames = v["el_frames"].as_array().unwrap();
    assert_eq!(frames.len(), 10);
    let mean = frames.iter().map(|f| f.as_f64().unwrap()).sum::<f64>() / 10.0;
    assert!((mean - v["el_mean"].as_f64().unwrap()).abs() < 1e-12);
    assert_eq!(v["protocol"], "scaled");
    assert_eq!(
        v["steps"].as_u64().unwrap(),
        (1.25f64 * 166.0).ceil() as u64
    );
    let files: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
    assert_eq!(files.len(), 10);
    let first = std::fs::read_to_string(v["shapes"][0].as_str().unwrap()).unwrap();
    assert!(first.starts_with("ply") && first.contains("element vertex 642"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A longer window with more frames: the window keeps its start, ends at the factor times it,
/// and the run reports the frames' drift, carrying on past force singularities by default.
#[test]
fn a_longer_window_reports_its_strains_and_the_drift_of_the_frames() {
    let o = iuq(&[
        "rbc",
        "shear",
        "--stress",
        "4.24",
        "--start-strain",
        "0.05",
        "--window-factor",
        "3",
        "--frames",
        "4",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json_of(&o);
    assert_eq!(v["past_singularity"], "carry-on");
    let steps: Vec<u64> = v["frame_steps"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_u64().unwrap())
        .collect();
    // t_start = int(0.05 / 3e-4) = 166, t_max = ceil(3 · 166) = 498.
    assert_eq!(steps, [166, 277, 387, 498]);
    let rate = v["lattice_shear_rate"].as_f64().unwrap();
    assert!((v["end_strain"].as_f64().unwrap() - 498.0 * rate).abs() < 1e-12);
    // The drift is the least-squares line's change over the window.
    let el: Vec<f64> = v["el_frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e.as_f64().unwrap())
        .collect();
    let x: Vec<f64> = steps.iter().map(|&s| s as f64).collect();
    let (mx, my) = (x.iter().sum::<f64>() / 4.0, el.iter().sum::<f64>() / 4.0);
    let slope = x
        .iter()
        .zip(&el)
        .map(|(a, b)| (a - mx) * (b - my))
        .sum::<f64>()
        / x.iter().map(|a| (a - mx).powi(2)).sum::<f64>();
    let drift = v["el_drift"].as_f64().unwrap();
    assert!(
        (drift - slope * 332.0).abs() < 1e-12,
        "{drift} vs {}",
        slope * 332.0
    );
    // The cell is still being stretched from rest: its elongation grows through the window.
    assert!(drift > 0.0, "{drift}");
}

#[test]
fn bad_values_are_input_errors_naming_the_flag() {
    for (args, flag) in [
        (vec!["--stress", "-1"], "--stress"),
        (vec!["--stress", "1", "--klink", "0"], "--klink"),
        (
            vec!["--stress", "1", "--viscosity-ratio", "nan"],
            "--viscosity-ratio",
        ),
        (vec!["--stress", "1", "--kbend", "-5"], "--kbend"),
        (
            vec!["--stress", "400", "--protocol", "reference"],
            "--stress",
        ),
        (
            vec!["--stress", "1", "--lattice-shear-rate", "0.5"],
            "--lattice-shear-rate",
        ),
        (
            vec!["--stress", "1", "--lattice-shear-rate", "1e-300"],
            "--lattice-shear-rate",
        ),
        (
            vec!["--stress", "1", "--window-factor", "1"],
            "--window-factor",
        ),
        (vec!["--stress", "1", "--frames", "1"], "--frames"),
    ] {
        let mut full = vec!["rbc", "shear"];
        full.extend(args.iter().copied());
        full.push("--json");
        let o = iuq(&full);
        assert_eq!(
            o.status.code(),
            Some(2),
            "{args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let v = json_of(&o);
        assert_eq!(v["error"]["kind"], "bad_input");
        let message = v["error"]["message"].as_str().unwrap();
        assert!(message.contains(flag), "{args:?}: {message}");
    }
    // A missing --stress is a usage error (clap also exits with 2).
    assert_eq!(iuq(&["rbc", "shear"]).status.code(), Some(2));
    assert_eq!(
        iuq(&["rbc", "shear", "--stress", "1", "--protocol", "fast"])
            .status
            .code(),
        Some(2)
    );
    assert_eq!(
        iuq(&[
            "rbc",
            "shear",
            "--stress",
            "1",
            "--past-singularity",
            "ignore"
        ])
        .status
        .code(),
        Some(2)
    );
}

#[test]
fn the_benchmark_reports_mlups_and_the_bandwidth_fraction() {
    let o = iuq(&[
        "rbc",
        "bench",
        "--steps",
        "2",
        "--repeats",
        "1",
        "--large",
        "0,0,0",
        "--copy-mb",
        "8",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json_of(&o);
    assert!(
        v["copy_bandwidth_gb_per_s"]["all_threads"]
            .as_f64()
            .unwrap()
            > 0.0
    );
    let runs = v["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 8);
    for r in runs {
        assert!(r["mlups"].as_f64().unwrap() > 0.0);
        assert!(r["bandwidth_fraction"].as_f64().unwrap() > 0.0);
    }
    assert_eq!(
        iuq(&["rbc", "bench", "--large", "1,2"]).status.code(),
        Some(2)
    );
}
