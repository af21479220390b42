//! The D3Q19 velocity set: the velocities, their weights and opposites, and the directions
//! that move along x (whose runs the sweep shifts through the ghost entries).

/// Number of discrete velocities.
pub const Q: usize = 19;

/// The D3Q19 velocities, in pairs `q` (odd) and `q + 1` = −`c_q`.
pub const VELOCITIES: [[i32; 3]; Q] = [
    [0, 0, 0],
    [1, 0, 0],
    [-1, 0, 0],
    [0, 1, 0],
    [0, -1, 0],
    [0, 0, 1],
    [0, 0, -1],
    [1, 1, 0],
    [-1, -1, 0],
    [1, -1, 0],
    [-1, 1, 0],
    [1, 0, 1],
    [-1, 0, -1],
    [1, 0, -1],
    [-1, 0, 1],
    [0, 1, 1],
    [0, -1, -1],
    [0, 1, -1],
    [0, -1, 1],
];

pub(super) const W0: f64 = 1.0 / 3.0;
pub(super) const W1: f64 = 1.0 / 18.0;
pub(super) const W2: f64 = 1.0 / 36.0;

/// The D3Q19 lattice weights.
pub const WEIGHTS: [f64; Q] = [
    W0, W1, W1, W1, W1, W1, W1, W2, W2, W2, W2, W2, W2, W2, W2, W2, W2, W2, W2,
];

/// Index of the opposite velocity, `c_{OPPOSITE[q]} = −c_q`.
pub const OPPOSITE: [usize; Q] = [
    0, 2, 1, 4, 3, 6, 5, 8, 7, 10, 9, 12, 11, 14, 13, 16, 15, 18, 17,
];

/// Slots whose runs are read (odd-step gather) or written (odd-step scatter) with an x shift:
/// `(slot, c_x)`.
pub(super) const SHIFTED_SLOTS: [(usize, i32); 10] = [
    (1, 1),
    (2, -1),
    (7, 1),
    (8, -1),
    (9, 1),
    (10, -1),
    (11, 1),
    (12, -1),
    (13, 1),
    (14, -1),
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn velocity_tables_are_consistent() {
        let mut w = 0.0;
        for q in 0..Q {
            w += WEIGHTS[q];
            let (c, o) = (VELOCITIES[q], VELOCITIES[OPPOSITE[q]]);
            assert_eq!([c[0], c[1], c[2]], [-o[0], -o[1], -o[2]]);
        }
        assert!((w - 1.0).abs() < 1e-15);
    }
}
