//! End-to-end tests of `iuq gp fit|predict|validate`.

use crate::common::{iuq, json_of, scratch};

use std::path::Path;

/// The GP reference data (docs/methods.md §7): X_i = frac(0.5 + i·α), α = (φ⁻¹, φ⁻², φ⁻³),
/// y_i = sin(2π x_i1) + x_i2² + 0.5 x_i3 + 0.01 sin(37 i), i = first..first+n−1.
fn spec_data(first: usize, n: usize) -> Vec<[f64; 4]> {
    let phi = 1.220_744_084_605_759_6_f64;
    let alpha = [1.0 / phi, 1.0 / (phi * phi), 1.0 / (phi * phi * phi)];
    (first..first + n)
        .map(|i| {
            let x: Vec<f64> = alpha.iter().map(|a| (0.5 + i as f64 * a).fract()).collect();
            let y = (2.0 * std::f64::consts::PI * x[0]).sin()
                + x[1] * x[1]
                + 0.5 * x[2]
                + 0.01 * (37.0 * i as f64).sin();
            [x[0], x[1], x[2], y]
        })
        .collect()
}

fn write_data(path: &Path, rows: &[[f64; 4]]) {
    let mut text = String::from("a,b,c,y\n");
    for r in rows {
        text.push_str(&format!("{},{},{},{}\n", r[0], r[1], r[2], r[3]));
    }
    std::fs::write(path, text).unwrap();
}

#[test]
fn fit_predict_validate_round_trip() {
    let dir = scratch("cli-gp", "roundtrip");
    let train = dir.join("train.csv");
    let test = dir.join("test.csv");
    write_data(&train, &spec_data(1, 64));
    write_data(&test, &spec_data(1000, 200));
    let gp = dir.join("gp.json");
    let o = iuq(&[
        "gp",
        "fit",
        "--data",
        train.to_str().unwrap(),
        "--inputs",
        "a,b,c",
        "--output",
        "y",
        "--out",
        gp.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let fit = json_of(&o);
    assert_eq!(fit["length_scales"].as_array().unwrap().len(), 3);
    assert!(fit["loo_q2"].as_f64().unwrap() > 0.99, "{fit}");
    assert!(fit["seconds"].as_f64().unwrap() >= 0.0);
    assert_eq!(fit["degenerate"], false);

    let o = iuq(&[
        "gp",
        "validate",
        "--model",
        gp.to_str().unwrap(),
        "--data",
        test.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(json_of(&o)["q2"].as_f64().unwrap() > 0.99);

    let out = dir.join("pred.csv");
    let o = iuq(&[
        "gp",
        "predict",
        "--model",
        gp.to_str().unwrap(),
        "--points",
        test.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success());
    let text = std::fs::read_to_string(&out).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next().unwrap(), "a,b,c,mean,std,std_with_noise");
    let truth = spec_data(1000, 200);
    let mut within = 0;
    for (line, t) in lines.zip(&truth) {
        let v: Vec<f64> = line.split(',').map(|s| s.parse().unwrap()).collect();
        assert!(v[4] > 0.0 && v[5] >= v[4]);
        if (v[3] - t[3]).abs() < 3.0 * v[5] + 0.02 {
            within += 1;
        }
    }
    // the predictive intervals are honest: nearly all truths lie within 3 std (+ noise floor)
    assert!(within >= 190, "{within} of 200");
}

#[test]
fn bad_gp_inputs_exit_with_code_2() {
    let dir = scratch("cli-gp", "bad");
    let train = dir.join("train.csv");
    write_data(&train, &spec_data(1, 20));
    let gp = dir.join("gp.json");
    let o = iuq(&[
        "gp",
        "fit",
        "--data",
        train.to_str().unwrap(),
        "--inputs",
        "a,b,z",
        "--output",
        "y",
        "--out",
        gp.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("no column `z`"));
    assert!(!gp.exists());
    std::fs::write(dir.join("nan.csv"), "a,b,c,y\n0.1,0.2,0.3,1\n0.2,0.3,x,2\n").unwrap();
    let o = iuq(&[
        "gp",
        "fit",
        "--data",
        dir.join("nan.csv").to_str().unwrap(),
        "--inputs",
        "a,b,c",
        "--output",
        "y",
        "--out",
        gp.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("line 3, column `c`"));
    std::fs::write(dir.join("garbage.json"), "{\"format\": \"something\"}").unwrap();
    let o = iuq(&[
        "gp",
        "predict",
        "--model",
        dir.join("garbage.json").to_str().unwrap(),
        "--points",
        train.to_str().unwrap(),
        "--out",
        dir.join("p.csv").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
}
