//! End-to-end tests of `iuq design` and `iuq sobol`: real processes, real files.

use crate::common::{iuq, json_of, scratch};

use std::path::Path;

fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_string)
        .collect();
    let rows = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    (header, rows)
}

#[test]
fn lhs_design_is_a_latin_hypercube_within_bounds_and_reports_min_distance() {
    let dir = scratch("cli", "lhs");
    let out = dir.join("lhs.csv");
    let o = iuq(&[
        "design",
        "lhs",
        "--n",
        "50",
        "--dim",
        "2",
        "--bounds",
        "-1:1,10:20",
        "--seed",
        "4",
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json_of(&o);
    assert_eq!(v["rows"], 50);
    let min_distance = v["min_distance"].as_f64().unwrap();
    let (header, rows) = read_csv(&out);
    assert_eq!(header, vec!["x1", "x2"]);
    assert_eq!(rows.len(), 50);
    let bounds = [(-1.0, 1.0), (10.0, 20.0)];
    for (k, (lo, hi)) in bounds.iter().enumerate() {
        let mut strata: Vec<usize> = rows
            .iter()
            .map(|r| (((r[k] - lo) / (hi - lo)) * 50.0).floor() as usize)
            .collect();
        strata.sort();
        assert_eq!(
            strata,
            (0..50).collect::<Vec<_>>(),
            "column {k} is not a Latin hypercube"
        );
    }
    // min_distance is reported on the unit cube
    let unit: Vec<Vec<f64>> = rows
        .iter()
        .map(|r| vec![(r[0] + 1.0) / 2.0, (r[1] - 10.0) / 10.0])
        .collect();
    let mut d_min = f64::INFINITY;
    for i in 0..unit.len() {
        for j in 0..i {
            let d = ((unit[i][0] - unit[j][0]).powi(2) + (unit[i][1] - unit[j][1]).powi(2)).sqrt();
            d_min = d_min.min(d);
        }
    }
    assert!((d_min - min_distance).abs() < 1e-9);
    // same seed, same design
    let out2 = dir.join("lhs2.csv");
    iuq(&[
        "design",
        "lhs",
        "--n",
        "50",
        "--dim",
        "2",
        "--bounds",
        "-1:1,10:20",
        "--seed",
        "4",
        "--out",
        out2.to_str().unwrap(),
    ]);
    assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&out2).unwrap());
}

#[test]
fn unscrambled_sobol_points_equal_scipy() {
    let dir = scratch("cli", "sobol");
    let out = dir.join("sobol.csv");
    let o = iuq(&[
        "design",
        "sobol",
        "--n",
        "128",
        "--dim",
        "6",
        "--unscrambled",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success());
    let (_, rows) = read_csv(&out);
    let expected: Vec<f64> = [53.0, 33.0, 99.0, 93.0, 113.0, 95.0]
        .iter()
        .map(|v| v / 128.0)
        .collect();
    assert_eq!(rows[100], expected);
}

#[test]
fn saltelli_design_has_n_times_d_plus_2_rows() {
    let dir = scratch("cli", "saltelli");
    let out = dir.join("s.csv");
    let o = iuq(&[
        "design",
        "saltelli",
        "--n",
        "16",
        "--dim",
        "3",
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success());
    assert_eq!(json_of(&o)["rows"], 80);
    let (_, rows) = read_csv(&out);
    // group j: A_j, AB_1j, AB_2j, AB_3j, B_j; AB_ij equals A_j except column i from B_j
    for g in rows.chunks(5) {
        for i in 0..3 {
            for k in 0..3 {
                let expected = if k == i { g[4][k] } else { g[0][k] };
                assert_eq!(g[1 + i][k], expected);
            }
        }
    }
}

#[test]
fn sobol_of_ishigami_matches_the_reference() {
    let study = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/ishigami.toml");
    let o = iuq(&["sobol", study, "--n", "8192", "--seed", "3", "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = json_of(&o);
    assert_eq!(v["evaluations"], 8192 * 5);
    let f = &v["outputs"]["f"];
    let s1 = [0.313_905_191_147_811, 0.442_411_144_790_041, 0.0];
    let st = [
        0.557_588_855_209_959,
        0.442_411_144_790_041,
        0.243_683_664_062_148,
    ];
    for (i, name) in ["x1", "x2", "x3"].iter().enumerate() {
        assert!(
            (f["S1"][name].as_f64().unwrap() - s1[i]).abs() < 0.01,
            "S1 {name}"
        );
        assert!(
            (f["ST"][name].as_f64().unwrap() - st[i]).abs() < 0.01,
            "ST {name}"
        );
        assert!(f["S1_conf"][name].as_f64().unwrap() > 0.0);
    }
}

#[test]
fn bad_input_exits_with_code_2_and_names_file_key_and_reason() {
    let dir = scratch("cli", "bad");
    let study = dir.join("bad.toml");
    std::fs::write(
        &study,
        "name = \"bad\"\n[parameters]\nx = { uniform = [2, 1] }\n[model]\nkind = \"expression\"\noutputs = { y = \"x^2\" }\n",
    )
    .unwrap();
    let o = iuq(&["sobol", study.to_str().unwrap(), "--json"]);
    assert_eq!(o.status.code(), Some(2));
    let message = json_of(&o)["error"]["message"]
        .as_str()
        .unwrap()
        .to_string();
    assert!(
        message.contains("bad.toml")
            && message.contains("parameters.x")
            && message.contains("below"),
        "{message}"
    );

    std::fs::write(&study, "name = \"bad\"\n[parameters]\nx = { uniform = [0, 1] }\n[model]\nkind = \"expression\"\noutputs = { y = \"z^2\" }\n").unwrap();
    let o = iuq(&["sobol", study.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        stderr.contains("model.outputs.y") && stderr.contains("unknown variable `z`"),
        "{stderr}"
    );

    let out = dir.join("never.csv");
    let o = iuq(&[
        "design",
        "lhs",
        "--n",
        "10",
        "--dim",
        "2",
        "--bounds",
        "0:1",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(!out.exists(), "nothing may be written on bad input");
    let o = iuq(&[
        "design",
        "lhs",
        "--n",
        "10",
        "--dim",
        "2",
        "--out",
        "/nonexistent-dir/x.csv",
    ]);
    assert_eq!(o.status.code(), Some(2));
    let o = iuq(&[
        "design",
        "lhs",
        "--n",
        "0",
        "--dim",
        "2",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
}
