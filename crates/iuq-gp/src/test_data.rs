//! Data sets shared by the unit tests (compiled for tests only).

/// φ: the real root of x⁴ = x + 1.
const PHI: f64 = 1.220_744_084_605_759_6;

/// The GP reference data (docs/methods.md §7): X_i = frac(0.5 + i·α), α = (φ⁻¹, φ⁻², φ⁻³),
/// i = 1..=n; y_i = sin(2π x_i1) + x_i2² + 0.5 x_i3 + 0.01 sin(37 i).
pub(crate) fn quasi_random_data(n: usize) -> (Vec<Vec<f64>>, Vec<f64>) {
    let a = [1.0 / PHI, 1.0 / (PHI * PHI), 1.0 / (PHI * PHI * PHI)];
    let mut x = Vec::with_capacity(n);
    let mut y = Vec::with_capacity(n);
    for i in 1..=n {
        let p: Vec<f64> = a
            .iter()
            .map(|ak| (0.5 + i as f64 * ak).rem_euclid(1.0))
            .collect();
        y.push(
            (2.0 * std::f64::consts::PI * p[0]).sin()
                + p[1] * p[1]
                + 0.5 * p[2]
                + 0.01 * (37.0 * i as f64).sin(),
        );
        x.push(p);
    }
    (x, y)
}

/// The 64-point GP reference data set (docs/methods.md §7).
pub(crate) fn spec_data() -> (Vec<Vec<f64>>, Vec<f64>) {
    quasi_random_data(64)
}

/// (y − mean)/std with ddof 0.
pub(crate) fn standardized(y: &[f64]) -> Vec<f64> {
    let n = y.len() as f64;
    let m = y.iter().sum::<f64>() / n;
    let s = (y.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / n).sqrt();
    y.iter().map(|v| (v - m) / s).collect()
}

#[test]
fn spec_data_matches_the_first_point() {
    let (x, y) = spec_data();
    let x0 = [0.319172513396, 0.171043606704, 0.049700477902];
    for (a, b) in x[0].iter().zip(x0) {
        assert!((a - b).abs() < 1e-11);
    }
    assert!((y[0] - 0.954699319483703).abs() < 1e-13);
}
