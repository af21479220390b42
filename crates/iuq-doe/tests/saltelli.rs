//! Saltelli design: shapes, the AB_i matrices, row order and splitting outputs.

use iuq_doe::{DoeError, SaltelliDesign, Scrambling, sobol_points};

#[test]
fn base_matrices_come_from_one_2d_dimensional_sobol_sequence() {
    for scrambling in [
        Scrambling::None,
        Scrambling::LinearMatrixWithShift {
            seed: 3,
            replicate: 1,
        },
    ] {
        let (n, d) = (16, 3);
        let design = SaltelliDesign::new(n, d, scrambling).expect("valid");
        let base = sobol_points(2 * d, n, scrambling).expect("valid");
        assert_eq!(design.n(), n);
        assert_eq!(design.dim(), d);
        assert_eq!(design.a().len(), n);
        assert_eq!(design.b().len(), n);
        for (j, row) in base.iter().enumerate() {
            assert_eq!(design.a()[j], row[..d].to_vec());
            assert_eq!(design.b()[j], row[d..].to_vec());
        }
    }
}

#[test]
fn ab_i_is_a_with_column_i_from_b() {
    let design = SaltelliDesign::new(8, 4, Scrambling::None).expect("valid");
    for i in 0..4 {
        let ab = design.ab(i).expect("i < d");
        assert_eq!(ab.len(), 8);
        for (j, row) in ab.iter().enumerate() {
            for (c, &v) in row.iter().enumerate() {
                let expected = if c == i {
                    design.b()[j][c]
                } else {
                    design.a()[j][c]
                };
                assert_eq!(v, expected);
            }
            assert_eq!(design.ab_row(i, j).as_ref(), Some(row));
        }
    }
    assert!(design.ab(4).is_none());
    assert!(design.ab_row(0, 8).is_none());
}

#[test]
fn rows_are_grouped_per_base_point() {
    let (n, d) = (8, 3);
    let design = SaltelliDesign::new(
        n,
        d,
        Scrambling::LinearMatrixWithShift {
            seed: 1,
            replicate: 0,
        },
    )
    .expect("valid");
    let rows = design.rows();
    assert_eq!(rows.len(), n * (d + 2));
    assert_eq!(design.len(), n * (d + 2));
    assert_eq!(design.group_size(), d + 2);
    assert!(!design.is_empty());
    for j in 0..n {
        let g = design.group(j);
        assert_eq!(g, j * (d + 2)..(j + 1) * (d + 2));
        let group = &rows[g];
        assert_eq!(group[0], design.a()[j]);
        for i in 0..d {
            assert_eq!(Some(group[1 + i].clone()), design.ab_row(i, j));
        }
        assert_eq!(group[d + 1], design.b()[j]);
    }
}

#[test]
fn split_outputs_inverts_the_row_order() {
    let (n, d) = (4, 2);
    let design = SaltelliDesign::new(n, d, Scrambling::None).expect("valid");
    // A model that records its row: f(x) = index of the row in `rows()`.
    let values: Vec<f64> = (0..design.len()).map(|r| r as f64).collect();
    let out = design.split_outputs(&values).expect("right length");
    for j in 0..n {
        let base = (j * (d + 2)) as f64;
        assert_eq!(out.f_a[j], base);
        assert_eq!(out.f_ab[0][j], base + 1.0);
        assert_eq!(out.f_ab[1][j], base + 2.0);
        assert_eq!(out.f_b[j], base + 3.0);
    }
    assert_eq!(out.f_ab.len(), d);
    // Model evaluated on the rows agrees with evaluation on the matrices.
    let f = |x: &[f64]| x[0] + 10.0 * x[1];
    let outputs: Vec<f64> = design.rows().iter().map(|x| f(x)).collect();
    let split = design.split_outputs(&outputs).expect("right length");
    let f_a: Vec<f64> = design.a().iter().map(|x| f(x)).collect();
    let f_ab1: Vec<f64> = design.ab(1).expect("i < d").iter().map(|x| f(x)).collect();
    assert_eq!(split.f_a, f_a);
    assert_eq!(split.f_ab[1], f_ab1);
    // Any value type can be split, e.g. per-point outcomes.
    let tagged: Vec<Result<f64, String>> = outputs.iter().map(|&v| Ok(v)).collect();
    assert_eq!(design.split_outputs(&tagged).expect("ok").f_b.len(), n);
    assert!(matches!(
        design.split_outputs(&values[1..]),
        Err(DoeError::OutputLength {
            expected: 16,
            actual: 15
        })
    ));
}

#[test]
fn from_matrices_validates_shapes() {
    let a = vec![vec![0.1, 0.2], vec![0.3, 0.4]];
    let b = vec![vec![0.5, 0.6], vec![0.7, 0.8]];
    let design = SaltelliDesign::from_matrices(a.clone(), b.clone()).expect("valid");
    assert_eq!(design.rows()[1], vec![0.5, 0.2]);
    assert!(SaltelliDesign::from_matrices(a.clone(), b[..1].to_vec()).is_err());
    assert!(matches!(
        SaltelliDesign::from_matrices(a, vec![vec![0.5], vec![0.7, 0.8]]),
        Err(DoeError::DimensionMismatch { row: 2, .. })
    ));
}
