//! The Sobol' sequence (Sobol' 1967) with Joe–Kuo direction numbers, optionally scrambled.
//!
//! Points are generated in Gray-code order (Antonov & Saleev 1979): point `k` is
//! `x_k = s ⊕ ⨁_{b : bit b of g(k) set} v_b` with `g(k) = k ⊕ (k >> 1)`, so consecutive points
//! differ by one XOR, `x_(k+1) = x_k ⊕ v_(ctz(k+1))`. The direction numbers `v_b` are those of
//! Joe & Kuo (2008), table `new-joe-kuo-6.21201` (see [`crate::direction_numbers`]), with
//! [`SOBOL_BITS`] = 52 bits, and the first point is the origin — exactly the points of
//! `scipy.stats.qmc.Sobol(d, scramble=False)` (which uses 30 bits; the first `2^30` points
//! coincide).
//!
//! Scrambling follows SciPy: a linear matrix scramble (Matoušek 1998) — each direction number
//! of coordinate `j` is multiplied (over GF(2), digits most-significant first) by a random
//! non-singular lower-triangular binary matrix `L_j` with unit diagonal — plus a random digital
//! shift `s_j` (XOR with random digits). Output digit `i` depends only on input digits `1..=i`,
//! bijectively, so every `(t, m, s)`-net property survives; in particular, the first `2^m` points
//! of each coordinate still put exactly one point in each interval `[k/2^m, (k+1)/2^m)`. The
//! randomness of replicate `r` comes from `iuq_core::random::stream(seed, SOBOL_SCRAMBLE, r)`, so
//! replicates `r = 0, 1, 2, …` are independent randomisations of the same sequence (used for
//! confidence intervals of quasi-Monte Carlo estimates) and any of them can be regenerated alone.
//!
//! The balance properties of Sobol' points hold for `n` a power of two (and for sub-sequences
//! starting at a multiple of that power); other `n` are allowed without warning, at the price of
//! a slightly less uniform design.

use iuq_core::random::{stages, stream};
use rand::Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::direction_numbers::{SOBOL_BITS, direction_numbers};
use crate::error::{DoeError, Result};
use crate::size::check_size;

/// Number of points a sequence holds, `2^SOBOL_BITS`.
const CAPACITY: u64 = 1 << SOBOL_BITS;

/// Scale from the integer digits to `[0, 1)`: `2^-SOBOL_BITS`.
const SCALE: f64 = 1.0 / CAPACITY as f64;

/// Points generated sequentially per parallel task (a task starts from its own Gray-code state,
/// so the result does not depend on the number of threads).
const CHUNK: usize = 2048;

/// How (and whether) a Sobol' sequence is randomised.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Scrambling {
    /// The plain sequence, identical to `scipy.stats.qmc.Sobol(d, scramble=False)`; its first
    /// point is the origin.
    #[default]
    None,
    /// Linear matrix scrambling plus a digital shift (as `scipy.stats.qmc.Sobol(scramble=True)`),
    /// drawn from the stream `(seed, SOBOL_SCRAMBLE, replicate)`: replicates with the same seed
    /// are independent randomisations of one sequence.
    LinearMatrixWithShift {
        /// The user's seed.
        seed: u64,
        /// Index of the independent randomisation (0, 1, 2, …).
        replicate: u64,
    },
}

/// A (possibly scrambled) Sobol' sequence in `dim` dimensions, generating its points in order.
///
/// ```
/// use iuq_doe::{Scrambling, SobolSequence};
/// let mut seq = SobolSequence::new(6, Scrambling::None)?;
/// seq.fast_forward(100)?;
/// let p = seq.points(1)?;
/// let expected: Vec<f64> = [53.0, 33.0, 99.0, 93.0, 113.0, 95.0].iter().map(|v| v / 128.0).collect();
/// assert_eq!(p[0], expected);
/// # Ok::<(), iuq_doe::DoeError>(())
/// ```
#[derive(Debug, Clone)]
pub struct SobolSequence {
    /// Number of coordinates.
    dim: usize,
    /// The randomisation applied.
    scrambling: Scrambling,
    /// Direction numbers, `SOBOL_BITS` per coordinate (scrambled when scrambling is on).
    v: Vec<u64>,
    /// Digital shift per coordinate (zero without scrambling).
    shift: Vec<u64>,
    /// Integer digits of the point at `index` (stale once `index == CAPACITY`).
    state: Vec<u64>,
    /// Index of the next point to generate.
    index: u64,
}

impl SobolSequence {
    /// A Sobol' sequence in `dim` dimensions (`1..=SOBOL_MAX_DIM`), positioned at its first point.
    ///
    /// Only the first `dim` dimensions of the Joe–Kuo table are decoded. With scrambling, the
    /// random matrices and shifts are drawn coordinate by coordinate, so a sequence in `d`
    /// dimensions equals the first `d` columns of one in more dimensions with the same
    /// [`Scrambling`].
    pub fn new(dim: usize, scrambling: Scrambling) -> Result<Self> {
        let mut v = direction_numbers(dim)?;
        let shift = match scrambling {
            Scrambling::None => vec![0; dim],
            Scrambling::LinearMatrixWithShift { seed, replicate } => {
                scramble(&mut v, dim, seed, replicate)
            }
        };
        Ok(Self {
            dim,
            scrambling,
            v,
            state: shift.clone(),
            shift,
            index: 0,
        })
    }

    /// Number of coordinates of each point.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// The randomisation of this sequence.
    pub fn scrambling(&self) -> Scrambling {
        self.scrambling
    }

    /// Index of the next point [`points`](Self::points) returns (points generated or skipped so
    /// far).
    pub fn index(&self) -> u64 {
        self.index
    }

    /// Goes back to the first point.
    pub fn reset(&mut self) {
        self.index = 0;
        self.state.clone_from(&self.shift);
    }

    /// Skips the next `n` points (as `scipy.stats.qmc.Sobol.fast_forward`), in `O(dim · bits)`.
    ///
    /// Errors if the sequence would move past its `2^52` points.
    pub fn fast_forward(&mut self, n: u64) -> Result<()> {
        let target = self.checked_target(n)?;
        self.index = target;
        if target < CAPACITY {
            self.state = self.state_at(target);
        }
        Ok(())
    }

    /// The next `n` points, each a vector of `dim` coordinates in `[0, 1)` (multiples of
    /// `2^-52`). `n = 0` gives an empty vector; `n · dim` may not exceed
    /// [`MAX_DESIGN_VALUES`](crate::MAX_DESIGN_VALUES).
    ///
    /// Large requests are generated in parallel chunks, each starting from its own Gray-code
    /// state, so the points do not depend on the number of threads. Errors if the sequence
    /// would move past its `2^52` points.
    pub fn points(&mut self, n: usize) -> Result<Vec<Vec<f64>>> {
        if n > 0 {
            check_size(n, self.dim, "Sobol' design")?;
        }
        let target = self.checked_target(n as u64)?;
        let mut out = vec![Vec::new(); n];
        let start = self.index;
        out.par_chunks_mut(CHUNK).enumerate().for_each(|(c, rows)| {
            let first = start + (c * CHUNK) as u64;
            let mut state = if c == 0 {
                self.state.clone()
            } else {
                self.state_at(first)
            };
            for (offset, row) in rows.iter_mut().enumerate() {
                *row = state.iter().map(|&x| x as f64 * SCALE).collect();
                let next = first + offset as u64 + 1;
                if next < CAPACITY {
                    self.advance(&mut state, next);
                }
            }
        });
        self.index = target;
        if target < CAPACITY {
            self.state = self.state_at(target);
        }
        Ok(out)
    }

    /// The index reached after `n` more points, or an error past the sequence's capacity.
    fn checked_target(&self, n: u64) -> Result<u64> {
        match self.index.checked_add(n) {
            Some(t) if t <= CAPACITY => Ok(t),
            _ => Err(DoeError::SequenceExhausted {
                bits: SOBOL_BITS,
                index: u128::from(self.index) + u128::from(n),
            }),
        }
    }

    /// Turns the digits of point `next - 1` into those of point `next` (`0 < next < 2^52`).
    fn advance(&self, state: &mut [u64], next: u64) {
        let bits = SOBOL_BITS as usize;
        let b = next.trailing_zeros() as usize;
        for (j, x) in state.iter_mut().enumerate() {
            *x ^= self.v[j * bits + b];
        }
    }

    /// The digits of point `index` (`index < 2^52`) from its Gray code.
    fn state_at(&self, index: u64) -> Vec<u64> {
        let bits = SOBOL_BITS as usize;
        let gray = index ^ (index >> 1);
        let mut state = self.shift.clone();
        for (j, x) in state.iter_mut().enumerate() {
            let v = &self.v[j * bits..(j + 1) * bits];
            let mut g = gray;
            while g != 0 {
                let b = g.trailing_zeros() as usize;
                *x ^= v[b];
                g &= g - 1;
            }
        }
        state
    }
}

/// Applies a random linear matrix scramble to the direction numbers `v` (in place) and returns
/// the random digital shift of each coordinate.
///
/// For coordinate `j`, row `b` of the matrix (the row producing output bit `b`, with bit
/// `SOBOL_BITS − 1` the most significant digit) has bit `b` set (unit diagonal) and random bits
/// above it (more significant input digits), none below: lower triangular in digit order.
fn scramble(v: &mut [u64], dim: usize, seed: u64, replicate: u64) -> Vec<u64> {
    let bits = SOBOL_BITS as usize;
    let full = CAPACITY - 1;
    let mut rng = stream(seed, stages::SOBOL_SCRAMBLE, replicate);
    let mut shift = Vec::with_capacity(dim);
    let mut rows = [0u64; SOBOL_BITS as usize];
    for j in 0..dim {
        shift.push(rng.random::<u64>() & full);
        for (b, row) in rows.iter_mut().enumerate() {
            let above = full & !((1u64 << (b + 1)) - 1);
            *row = (1u64 << b) | (rng.random::<u64>() & above);
        }
        for vk in &mut v[j * bits..(j + 1) * bits] {
            let x = *vk;
            let mut y = 0u64;
            for (b, row) in rows.iter().enumerate() {
                y |= u64::from((row & x).count_ones() & 1) << b;
            }
            *vk = y;
        }
    }
    shift
}

/// The first `n` points of a Sobol' sequence in `dim` dimensions (see [`SobolSequence`]).
///
/// Errors for `n = 0`, `dim = 0`, `dim > SOBOL_MAX_DIM` or `n · dim >
/// MAX_DESIGN_VALUES`. Use `n` a power of two for the
/// balance properties of the sequence.
pub fn sobol_points(dim: usize, n: usize, scrambling: Scrambling) -> Result<Vec<Vec<f64>>> {
    check_size(n, dim, "Sobol' design")?;
    SobolSequence::new(dim, scrambling)?.points(n)
}
