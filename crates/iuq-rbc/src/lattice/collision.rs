//! The BGK collision with Guo forcing, with and without force, and the moments it starts from,
//! written once for a single value or a SIMD vector of node values.

use super::d3q19::{Q, W0, W1, W2};
use super::numbers::Real;

/// Density `1 + s`, and momentum, of deviations `δ`.
#[inline(always)]
pub(super) fn moments<T: Real>(f: &[T; Q]) -> (T, [T; 3]) {
    let p = |q: usize| f[q] + f[q + 1];
    let d = |q: usize| f[q] - f[q + 1];
    let s = f[0] + ((p(1) + p(3)) + (p(5) + p(7))) + ((p(9) + p(11)) + ((p(13) + p(15)) + p(17)));
    let (d1, d3, d5, d7, d9) = (d(1), d(3), d(5), d(7), d(9));
    let (d11, d13, d15, d17) = (d(11), d(13), d(15), d(17));
    let jx = (d1 + d7) + (d9 + d11) + d13;
    let jy = (d3 + d7) - (d9 - d15) + d17;
    let jz = (d5 + d11) - (d13 - d15) - d17;
    (T::splat(1.0) + s, [jx, jy, jz])
}

/// BGK collision with Guo forcing in deviation form: with `f_q = w_q + δ_q`,
/// `δ*_q = (1 − ω)δ_q + ω w_q[ρ(1 + 3c·u + 4.5(c·u)² − 1.5u²) − 1]
///        + (1 − ω/2) w_q [3(c·F − u·F) + 9(c·u)(c·F)]`.
#[inline(always)]
pub(super) fn collide<T: Real>(f: &[T; Q], force: [T; 3], omega: T) -> [T; Q] {
    let (rho, [jx, jy, jz]) = moments(f);
    let [gx, gy, gz] = force;
    let half = T::splat(0.5);
    let inv_rho = T::splat(1.0) / rho;
    let ux = T::fma(half, gx, jx) * inv_rho;
    let uy = T::fma(half, gy, jy) * inv_rho;
    let uz = T::fma(half, gz, jz) * inv_rho;
    let usq = T::fma(uz, uz, T::fma(uy, uy, ux * ux));
    let uf = T::fma(uz, gz, T::fma(uy, gy, ux * gx));
    let k = T::fma(-half, omega, T::splat(1.0));
    let keep = T::splat(1.0) - omega;
    // Isotropic part ω(ρ(1 − 1.5u²) − 1) − 3k u·F, and the coefficients of c·u and c·F.
    let iso = T::fma(
        omega,
        T::fma(
            rho,
            T::fma(T::splat(-1.5), usq, T::splat(1.0)),
            T::splat(-1.0),
        ),
        T::splat(-3.0) * k * uf,
    );
    let a4 = T::splat(4.5) * omega * rho;
    let a9 = T::splat(9.0) * k;
    let b3 = T::splat(3.0) * omega * rho;
    let c3 = T::splat(3.0) * k;
    let mut out = [T::splat(0.0); Q];
    out[0] = T::fma(keep, f[0], T::splat(W0) * iso);
    macro_rules! pair {
        ($q:expr, $w:expr, $cu:expr, $cf:expr) => {{
            let (cu, cf) = ($cu, $cf);
            let w = T::splat($w);
            let even = w * T::fma(cu, T::fma(a4, cu, a9 * cf), iso);
            let odd = w * T::fma(b3, cu, c3 * cf);
            out[$q] = T::fma(keep, f[$q], even + odd);
            out[$q + 1] = T::fma(keep, f[$q + 1], even - odd);
        }};
    }
    pair!(1, W1, ux, gx);
    pair!(3, W1, uy, gy);
    pair!(5, W1, uz, gz);
    pair!(7, W2, ux + uy, gx + gy);
    pair!(9, W2, ux - uy, gx - gy);
    pair!(11, W2, ux + uz, gx + gz);
    pair!(13, W2, ux - uz, gx - gz);
    pair!(15, W2, uy + uz, gy + gz);
    pair!(17, W2, uy - uz, gy - gz);
    out
}

/// [`collide`] without force (the rows the cell does not touch).
#[inline(always)]
pub(super) fn collide_unforced<T: Real>(f: &[T; Q], omega: T) -> [T; Q] {
    let (rho, [jx, jy, jz]) = moments(f);
    let inv_rho = T::splat(1.0) / rho;
    let (ux, uy, uz) = (jx * inv_rho, jy * inv_rho, jz * inv_rho);
    let usq = T::fma(uz, uz, T::fma(uy, uy, ux * ux));
    let keep = T::splat(1.0) - omega;
    let iso = omega
        * T::fma(
            rho,
            T::fma(T::splat(-1.5), usq, T::splat(1.0)),
            T::splat(-1.0),
        );
    let a4 = T::splat(4.5) * omega * rho;
    let b3 = T::splat(3.0) * omega * rho;
    let mut out = [T::splat(0.0); Q];
    out[0] = T::fma(keep, f[0], T::splat(W0) * iso);
    macro_rules! pair {
        ($q:expr, $w:expr, $cu:expr) => {{
            let cu = $cu;
            let w = T::splat($w);
            let even = w * T::fma(a4 * cu, cu, iso);
            let odd = w * (b3 * cu);
            out[$q] = T::fma(keep, f[$q], even + odd);
            out[$q + 1] = T::fma(keep, f[$q + 1], even - odd);
        }};
    }
    pair!(1, W1, ux);
    pair!(3, W1, uy);
    pair!(5, W1, uz);
    pair!(7, W2, ux + uy);
    pair!(9, W2, ux - uy);
    pair!(11, W2, ux + uz);
    pair!(13, W2, ux - uz);
    pair!(15, W2, uy + uz);
    pair!(17, W2, uy - uz);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lattice::{VELOCITIES, WEIGHTS};

    fn deviations() -> [f64; Q] {
        std::array::from_fn(|q| WEIGHTS[q] * 0.01 * (q as f64 * 0.37).sin())
    }

    #[test]
    fn collision_conserves_mass_and_adds_the_force_to_the_momentum() {
        let f = deviations();
        let g = [1e-4, -2e-4, 3e-5];
        let post = collide::<f64>(&f, g, 1.0 / 0.8);
        let m = |f: &[f64; Q], d: usize| -> f64 {
            (0..Q).map(|q| f[q] * VELOCITIES[q][d] as f64).sum()
        };
        assert!((post.iter().sum::<f64>() - f.iter().sum::<f64>()).abs() < 1e-15);
        for d in 0..3 {
            assert!((m(&post, d) - m(&f, d) - g[d]).abs() < 1e-15, "dir {d}");
        }
    }

    #[test]
    fn unforced_collision_is_the_forced_one_without_force() {
        let f = deviations();
        let a = collide::<f64>(&f, [0.0; 3], 0.7);
        let b = collide_unforced::<f64>(&f, 0.7);
        for q in 0..Q {
            assert!((a[q] - b[q]).abs() < 1e-17);
        }
    }

    #[test]
    fn equilibrium_is_a_fixed_point_of_the_collision() {
        let u = [0.01, -0.02, 0.005];
        let usq = u[0] * u[0] + u[1] * u[1] + u[2] * u[2];
        let f: [f64; Q] = std::array::from_fn(|q| {
            let c = VELOCITIES[q];
            let cu = c[0] as f64 * u[0] + c[1] as f64 * u[1] + c[2] as f64 * u[2];
            WEIGHTS[q] * (3.0 * cu + 4.5 * cu * cu - 1.5 * usq)
        });
        let post = collide_unforced::<f64>(&f, 1.3);
        for q in 0..Q {
            assert!((post[q] - f[q]).abs() < 1e-16, "q {q}");
        }
    }
}
