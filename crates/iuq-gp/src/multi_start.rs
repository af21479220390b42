//! Start points of the multi-start likelihood maximisation: a random Latin hypercube in the
//! log-bounds box (space-filling: every θ-coordinate is stratified into as many equal slices
//! as there are starts, one start per slice), plus one data-driven start.

use rand::Rng;
use rand::seq::SliceRandom;

use crate::data::ColumnMajor;
use crate::kernel::{Hyperparameters, Kernel, LengthScales};

/// `count` points of a random Latin hypercube in the box [`lower`, `upper`]: coordinate k of
/// point i is lower_k + (π_k(i) + u_ik)/count·(upper_k − lower_k), π_k a random permutation,
/// u_ik ~ U[0, 1).
pub(crate) fn latin_hypercube<R: Rng>(
    count: usize,
    lower: &[f64],
    upper: &[f64],
    rng: &mut R,
) -> Vec<Vec<f64>> {
    let mut points = vec![vec![0.0; lower.len()]; count];
    let mut perm: Vec<usize> = (0..count).collect();
    for (k, (&lo, &hi)) in lower.iter().zip(upper).enumerate() {
        perm.shuffle(rng);
        for (point, &slot) in points.iter_mut().zip(&perm) {
            let u: f64 = rng.random();
            point[k] = lo + (slot as f64 + u) / count as f64 * (hi - lo);
        }
    }
    points
}

/// The data-driven start: length scales = the per-input std (ddof 0) of the (scaled) inputs
/// (their mean for an isotropic kernel; 1 for a constant input), c = var(ỹ), σ² = 1e−2·var(ỹ)
/// (var(ỹ) = 1 with standardised outputs); clamped into the box by the caller.
pub(crate) fn data_driven_start(kernel: &Kernel, x: &ColumnMajor, y: &[f64]) -> Vec<f64> {
    let std = |v: &[f64]| {
        let n = v.len().max(1) as f64;
        let m = v.iter().sum::<f64>() / n;
        (v.iter().map(|a| (a - m) * (a - m)).sum::<f64>() / n).sqrt()
    };
    let stds: Vec<f64> = (0..x.d)
        .map(|k| {
            let s = std(x.column(k));
            if s > 0.0 { s } else { 1.0 }
        })
        .collect();
    let length_scales = match kernel.length_scales {
        LengthScales::Ard => stds,
        LengthScales::Isotropic => vec![stds.iter().sum::<f64>() / stds.len().max(1) as f64],
    };
    let var_y = {
        let s = std(y);
        if s > 0.0 { s * s } else { 1.0 }
    };
    kernel.theta(&Hyperparameters {
        signal_variance: var_y,
        length_scales,
        noise_variance: 1e-2 * var_y,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use iuq_core::random::{stages::GP_MULTI_START, stream};

    #[test]
    fn latin_hypercube_stratifies_every_coordinate() {
        let mut rng = stream(3, GP_MULTI_START, 0);
        let pts = latin_hypercube(10, &[-1.0, 0.0], &[1.0, 10.0], &mut rng);
        for (k, (lo, hi)) in [(-1.0, 1.0), (0.0, 10.0)].into_iter().enumerate() {
            let mut slots: Vec<usize> = pts
                .iter()
                .map(|p| ((p[k] - lo) / (hi - lo) * 10.0).floor() as usize)
                .collect();
            slots.sort();
            assert_eq!(slots, (0..10).collect::<Vec<_>>());
        }
        let mut rng = stream(3, GP_MULTI_START, 0);
        assert_eq!(
            pts,
            latin_hypercube(10, &[-1.0, 0.0], &[1.0, 10.0], &mut rng)
        );
    }

    #[test]
    fn data_driven_start_uses_spreads() {
        let x = ColumnMajor {
            n: 2,
            d: 2,
            values: vec![0.0, 1.0, 3.0, 3.0],
        };
        let t = data_driven_start(&Kernel::ard(), &x, &[1.0, -1.0]);
        assert!((t[0] - 0.0).abs() < 1e-15); // var = 1
        assert!((t[1] - 0.5f64.ln()).abs() < 1e-15);
        assert!((t[2] - 0.0).abs() < 1e-15); // constant input → 1
        assert!((t[3] - 1e-2f64.ln()).abs() < 1e-15);
    }
}
