//! The elongation index of a cell shape: the x-binned contour of its projection onto the x–y
//! plane (in HemoCell's frame, where the shear protocol measures, the flow–gradient plane), a
//! direct least-squares ellipse fit, `EL = (a − b)/(a + b)`.
//!
//! The contour follows HemoCell `scripts/measure/EL.py` (`elongation_index`): the vertices are
//! binned along x and, in each bin, the vertex of largest y and the vertex of smallest y are
//! kept. The bin width is 0.5 µm ([`crate::protocol::CONTOUR_BIN_WIDTH`]; EL.py uses 1.5 in
//! its own units). Bins are `[x_min + k·w, x_min + (k+1)·w)`, so the vertex at `x_min` is kept
//! (EL.py's open lower bound drops it, a detail of no consequence). The ellipse is the direct
//! least-squares fit of Fitzgibbon, Pilu & Fisher (1999) in the numerically stable form of
//! Halír & Flusser (1998), on coordinates centred and scaled to unit root-mean-square radius.

use crate::error::{RbcError, Result};

/// An ellipse in the plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ellipse {
    /// Centre (x, y).
    pub centre: [f64; 2],
    /// Semi-major axis a.
    pub semi_major: f64,
    /// Semi-minor axis b ≤ a.
    pub semi_minor: f64,
    /// Angle of the major axis to the x axis, in (−π/2, π/2].
    pub angle: f64,
}

impl Ellipse {
    /// The elongation (deformation) index `(a − b)/(a + b)`.
    pub fn elongation_index(&self) -> f64 {
        (self.semi_major - self.semi_minor) / (self.semi_major + self.semi_minor)
    }
}

/// The most x bins a contour may span: a cell is a few hundred bins long; a shape spanning more
/// is in another unit or broken, and would ask for bins beyond memory.
pub const MAX_CONTOUR_BINS: usize = 1 << 20;

/// The contour points of the x–y projection of `vertices`: per x bin of width `bin_width`, the
/// vertex with the largest and the one with the smallest y (once if they coincide). No points
/// when the coordinates are not finite, the width is not positive or the shape spans more than
/// [`MAX_CONTOUR_BINS`] bins.
pub fn contour_points(vertices: &[[f64; 3]], bin_width: f64) -> Vec<[f64; 2]> {
    let x_min = vertices.iter().map(|v| v[0]).fold(f64::INFINITY, f64::min);
    let x_max = vertices
        .iter()
        .map(|v| v[0])
        .fold(f64::NEG_INFINITY, f64::max);
    if !(x_min.is_finite() && x_max.is_finite() && bin_width > 0.0) {
        return Vec::new();
    }
    let span = ((x_max - x_min) / bin_width).floor();
    if span >= MAX_CONTOUR_BINS as f64 {
        return Vec::new();
    }
    let bins = span as usize + 1;
    let mut top: Vec<Option<usize>> = vec![None; bins];
    let mut bottom: Vec<Option<usize>> = vec![None; bins];
    for (i, v) in vertices.iter().enumerate() {
        let b = (((v[0] - x_min) / bin_width).floor() as usize).min(bins - 1);
        if top[b].is_none_or(|t| v[1] > vertices[t][1]) {
            top[b] = Some(i);
        }
        if bottom[b].is_none_or(|t| v[1] < vertices[t][1]) {
            bottom[b] = Some(i);
        }
    }
    let mut points = Vec::with_capacity(2 * bins);
    for (t, b) in top.into_iter().zip(bottom) {
        if let (Some(t), Some(b)) = (t, b) {
            points.push([vertices[t][0], vertices[t][1]]);
            if b != t {
                points.push([vertices[b][0], vertices[b][1]]);
            }
        }
    }
    points
}

/// The elongation index of a shape: [`contour_points`] then [`fit_ellipse`].
pub fn elongation_index(vertices: &[[f64; 3]], bin_width: f64) -> Result<f64> {
    let extent = |k: usize| {
        let values = vertices.iter().map(|v| v[k]);
        values.clone().fold(f64::NEG_INFINITY, f64::max) - values.fold(f64::INFINITY, f64::min)
    };
    let span = extent(0) / bin_width;
    if span.is_finite() && span >= MAX_CONTOUR_BINS as f64 {
        return Err(RbcError::NoEllipse(format!(
            "the shape spans {:.3e} lattice units along x, more than {MAX_CONTOUR_BINS} contour bins of {bin_width}: is the coordinate unit right?",
            extent(0)
        )));
    }
    Ok(fit_ellipse(&contour_points(vertices, bin_width))?.elongation_index())
}

type M3 = [[f64; 3]; 3];

fn mat_mul(a: &M3, b: &M3) -> M3 {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

fn transpose(a: &M3) -> M3 {
    std::array::from_fn(|i| std::array::from_fn(|j| a[j][i]))
}

fn determinant(a: &M3) -> f64 {
    a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
        - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
}

fn inverse(a: &M3) -> Option<M3> {
    let det = determinant(a);
    let scale = a.iter().flatten().map(|v| v.abs()).fold(0.0, f64::max);
    if det.abs().partial_cmp(&(1e-13 * scale.powi(3))) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let c = |i: usize, j: usize| {
        let (r0, r1) = ((i + 1) % 3, (i + 2) % 3);
        let (c0, c1) = ((j + 1) % 3, (j + 2) % 3);
        a[r0][c0] * a[r1][c1] - a[r0][c1] * a[r1][c0]
    };
    // inverse = adjugate / det, adjugate[j][i] = cofactor(i, j).
    Some(std::array::from_fn(|j| {
        std::array::from_fn(|i| c(i, j) / det)
    }))
}

fn cross3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Real roots of `λ³ + p λ² + q λ + r`, each polished by Newton steps.
fn cubic_roots(p: f64, q: f64, r: f64) -> Vec<f64> {
    // Depressed cubic t³ + a t + b with λ = t − p/3.
    let a = q - p * p / 3.0;
    let b = 2.0 * p * p * p / 27.0 - p * q / 3.0 + r;
    let disc = b * b / 4.0 + a * a * a / 27.0;
    let mut roots = if disc > 0.0 {
        let s = disc.sqrt();
        vec![(-b / 2.0 + s).cbrt() + (-b / 2.0 - s).cbrt()]
    } else if a == 0.0 {
        vec![0.0]
    } else {
        let m = 2.0 * (-a / 3.0).sqrt();
        let theta = (3.0 * b / (a * m)).clamp(-1.0, 1.0).acos() / 3.0;
        (0..3)
            .map(|k| m * (theta - 2.0 * std::f64::consts::PI * k as f64 / 3.0).cos())
            .collect()
    };
    for t in &mut roots {
        *t -= p / 3.0;
        for _ in 0..3 {
            let f = ((*t + p) * *t + q) * *t + r;
            let df = (3.0 * *t + 2.0 * p) * *t + q;
            if df != 0.0 {
                *t -= f / df;
            }
        }
    }
    roots
}

/// Direct least-squares ellipse fit (Halír & Flusser's form of Fitzgibbon's method).
///
/// Fails with [`RbcError::NoEllipse`] for fewer than 5 points, degenerate (e.g. collinear)
/// points, or when no real ellipse results.
pub fn fit_ellipse(points: &[[f64; 2]]) -> Result<Ellipse> {
    let n = points.len();
    if n < 5 {
        return Err(RbcError::NoEllipse(format!(
            "{n} contour points, at least 5 are needed"
        )));
    }
    let mx = points.iter().map(|p| p[0]).sum::<f64>() / n as f64;
    let my = points.iter().map(|p| p[1]).sum::<f64>() / n as f64;
    let rms = (points
        .iter()
        .map(|p| (p[0] - mx).powi(2) + (p[1] - my).powi(2))
        .sum::<f64>()
        / n as f64)
        .sqrt();
    if !(rms > 0.0 && rms.is_finite()) {
        return Err(RbcError::NoEllipse("the contour points coincide".into()));
    }
    let mut s1 = [[0.0; 3]; 3];
    let mut s2 = [[0.0; 3]; 3];
    let mut s3 = [[0.0; 3]; 3];
    for p in points {
        let (x, y) = ((p[0] - mx) / rms, (p[1] - my) / rms);
        let d1 = [x * x, x * y, y * y];
        let d2 = [x, y, 1.0];
        for i in 0..3 {
            for j in 0..3 {
                s1[i][j] += d1[i] * d1[j];
                s2[i][j] += d1[i] * d2[j];
                s3[i][j] += d2[i] * d2[j];
            }
        }
    }
    let s3_inv = inverse(&s3)
        .ok_or_else(|| RbcError::NoEllipse("the contour points are collinear".into()))?;
    let t = mat_mul(&s3_inv, &transpose(&s2)).map(|row| row.map(|v| -v));
    let st = mat_mul(&s2, &t);
    let m: M3 = std::array::from_fn(|i| std::array::from_fn(|j| s1[i][j] + st[i][j]));
    // Premultiply by C1⁻¹, C1 = [[0, 0, 2], [0, −1, 0], [2, 0, 0]].
    let mm: M3 = [
        m[2].map(|v| v / 2.0),
        m[1].map(|v| -v),
        m[0].map(|v| v / 2.0),
    ];
    let trace = mm[0][0] + mm[1][1] + mm[2][2];
    let minors = mm[0][0] * mm[1][1] - mm[0][1] * mm[1][0] + mm[0][0] * mm[2][2]
        - mm[0][2] * mm[2][0]
        + mm[1][1] * mm[2][2]
        - mm[1][2] * mm[2][1];
    let det = determinant(&mm);
    let mut best: Option<([f64; 3], f64)> = None;
    for lambda in cubic_roots(-trace, minors, -det) {
        let rows: M3 = std::array::from_fn(|i| {
            std::array::from_fn(|j| mm[i][j] - if i == j { lambda } else { 0.0 })
        });
        // The eigenvector is orthogonal to the rows of M − λI: the largest cross product.
        let candidates = [
            cross3(rows[0], rows[1]),
            cross3(rows[0], rows[2]),
            cross3(rows[1], rows[2]),
        ];
        let v = candidates
            .iter()
            .copied()
            .max_by(|a, b| {
                let na = a.iter().map(|x| x * x).sum::<f64>();
                let nb = b.iter().map(|x| x * x).sum::<f64>();
                na.total_cmp(&nb)
            })
            .unwrap_or([0.0; 3]);
        let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            continue;
        }
        let v = v.map(|x| x / norm);
        let constraint = 4.0 * v[0] * v[2] - v[1] * v[1];
        if constraint > 0.0 && best.is_none_or(|(_, c)| constraint > c) {
            best = Some((v, constraint));
        }
    }
    let (a1, _) = best
        .ok_or_else(|| RbcError::NoEllipse("the least-squares conic is not an ellipse".into()))?;
    let a2: [f64; 3] = std::array::from_fn(|i| (0..3).map(|k| t[i][k] * a1[k]).sum());
    let (a, b, c, d, e, f) = (a1[0], a1[1], a1[2], a2[0], a2[1], a2[2]);
    // Centre: ∇(conic) = 0.
    let den = 4.0 * a * c - b * b;
    let x0 = (b * e - 2.0 * c * d) / den;
    let y0 = (b * d - 2.0 * a * e) / den;
    let f0 = f + 0.5 * (d * x0 + e * y0);
    // Eigenvalues of [[a, b/2], [b/2, c]].
    let mean = 0.5 * (a + c);
    let radius = (0.25 * (a - c) * (a - c) + 0.25 * b * b).sqrt();
    let (l1, l2) = (mean - radius, mean + radius);
    let (r1, r2) = (-f0 / l1, -f0 / l2);
    if !(r1 > 0.0 && r2 > 0.0 && r1.is_finite() && r2.is_finite()) {
        return Err(RbcError::NoEllipse(
            "the fitted conic is an imaginary ellipse".into(),
        ));
    }
    let (ax1, ax2) = (r1.sqrt() * rms, r2.sqrt() * rms);
    let (semi_major, semi_minor, lambda_major) = if ax1 >= ax2 {
        (ax1, ax2, l1)
    } else {
        (ax2, ax1, l2)
    };
    // Direction of the major axis: the eigenvector (b/2, λ − a) of [[a, b/2], [b/2, c]].
    let angle = if b.abs() <= 1e-14 * (a.abs() + c.abs()) {
        if (lambda_major - a).abs() <= (lambda_major - c).abs() {
            0.0
        } else {
            std::f64::consts::FRAC_PI_2
        }
    } else {
        (lambda_major - a).atan2(b / 2.0)
    };
    let angle = if angle > std::f64::consts::FRAC_PI_2 {
        angle - std::f64::consts::PI
    } else if angle <= -std::f64::consts::FRAC_PI_2 {
        angle + std::f64::consts::PI
    } else {
        angle
    };
    Ok(Ellipse {
        centre: [mx + x0 * rms, my + y0 * rms],
        semi_major,
        semi_minor,
        angle,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn ellipse_points(c: [f64; 2], a: f64, b: f64, phi: f64, n: usize, arc: f64) -> Vec<[f64; 2]> {
        (0..n)
            .map(|i| {
                let t = arc * i as f64 / n as f64 + 0.1;
                let (x, y) = (a * t.cos(), b * t.sin());
                [
                    c[0] + x * phi.cos() - y * phi.sin(),
                    c[1] + x * phi.sin() + y * phi.cos(),
                ]
            })
            .collect()
    }

    #[test]
    fn the_fit_recovers_a_known_ellipse() {
        for (c, a, b, phi) in [
            ([19.0, 21.0], 9.0, 5.0, 0.3),
            ([-3.0, 2.0], 4.0, 3.9, -1.2),
            ([0.0, 0.0], 12.0, 2.0, PI / 2.0 - 1e-3),
            ([100.0, -50.0], 7.0, 7.0 * 0.6, 0.0),
        ] {
            let e = fit_ellipse(&ellipse_points(c, a, b, phi, 40, 2.0 * PI)).unwrap();
            assert!((e.centre[0] - c[0]).abs() < 1e-9 && (e.centre[1] - c[1]).abs() < 1e-9);
            assert!((e.semi_major - a).abs() < 1e-9, "{e:?}");
            assert!((e.semi_minor - b).abs() < 1e-9, "{e:?}");
            if a - b > 1e-3 {
                let d = (e.angle - phi).rem_euclid(PI);
                assert!(d < 1e-7 || PI - d < 1e-7, "{e:?} vs {phi}");
            }
            let el = (a - b) / (a + b);
            assert!((e.elongation_index() - el).abs() < 1e-10);
        }
        // A partial arc determines the ellipse too.
        let e = fit_ellipse(&ellipse_points([1.0, 2.0], 5.0, 2.0, 0.4, 12, 2.5)).unwrap();
        assert!((e.semi_major - 5.0).abs() < 1e-8 && (e.semi_minor - 2.0).abs() < 1e-8);
    }

    #[test]
    fn noisy_points_give_a_close_ellipse() {
        let mut pts = ellipse_points([3.0, 4.0], 8.0, 4.0, 0.2, 60, 2.0 * PI);
        for (i, p) in pts.iter_mut().enumerate() {
            p[0] += 0.02 * ((i * 7919) % 13) as f64 / 13.0 - 0.01;
            p[1] += 0.02 * ((i * 104_729) % 17) as f64 / 17.0 - 0.01;
        }
        let e = fit_ellipse(&pts).unwrap();
        assert!((e.semi_major - 8.0).abs() < 0.02 && (e.semi_minor - 4.0).abs() < 0.02);
    }

    #[test]
    fn degenerate_contours_have_no_ellipse() {
        assert!(matches!(
            fit_ellipse(&[[0.0, 0.0], [1.0, 1.0], [2.0, 0.0]]),
            Err(RbcError::NoEllipse(_))
        ));
        let line: Vec<[f64; 2]> = (0..10).map(|i| [i as f64, 2.0 * i as f64]).collect();
        assert!(matches!(fit_ellipse(&line), Err(RbcError::NoEllipse(_))));
        // (Points on a hyperbola still get an ellipse: the method is ellipse-specific.)
    }

    #[test]
    fn the_contour_of_an_ellipsoid_gives_its_elongation() {
        let sphere = crate::mesh::Mesh::icosphere(600);
        let (a, b) = (9.0, 6.0);
        let v: Vec<[f64; 3]> = sphere
            .vertices
            .iter()
            .map(|p| [20.0 + a * p[0], 20.0 + b * p[1], 9.0 + 2.0 * p[2]])
            .collect();
        let points = contour_points(&v, 1.0);
        assert!(points.len() >= 30);
        let el = elongation_index(&v, 1.0).unwrap();
        let exact = (a - b) / (a + b);
        assert!((el - exact).abs() < 0.01, "{el} vs {exact}");
    }
}
