//! Random streams keyed by `(seed, stage, index)`.
//!
//! Every independent unit of random work (one design, one BASIS chain in one stage, one bootstrap
//! replicate) draws from its own stream, derived from the user's seed and the unit's coordinates.
//! Results therefore do not depend on how the work is split across threads, and a run can be
//! resumed at any stage without replaying earlier draws.

use rand::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

/// The generator behind every stream: xoshiro256++ (Blackman & Vigna 2019), 256-bit state.
pub type StreamRng = Xoshiro256PlusPlus;

/// Stage identifiers used by the crates of iuq, so that two consumers never share a stream.
pub mod stages {
    /// Latin hypercube designs.
    pub const LATIN_HYPERCUBE: u64 = 1;
    /// Sobol' sequence scrambling.
    pub const SOBOL_SCRAMBLE: u64 = 2;
    /// Gaussian-process hyper-parameter multi-start.
    pub const GP_MULTI_START: u64 = 3;
    /// Bootstrap resampling of sensitivity estimators.
    pub const BOOTSTRAP: u64 = 4;
    /// Prior sampling.
    pub const PRIOR_SAMPLING: u64 = 5;
    /// First stage number available to iterative samplers (BASIS stage k uses `SAMPLER_BASE + k`).
    pub const SAMPLER_BASE: u64 = 1 << 32;
    /// First stage of the model-posterior method (stage k uses `MODEL_POSTERIOR_BASE + k`; the
    /// choice of its batches uses `MODEL_POSTERIOR_BASE` itself).
    pub const MODEL_POSTERIOR_BASE: u64 = 2 << 32;
    /// The permutations of the test of a surrogate posterior against a noisy model's weights.
    pub const MISMATCH_PERMUTATION: u64 = 3 << 32;
    /// The draws that cap a moment-matched correction of a surrogate.
    pub const CORRECTION_CEILING: u64 = (3 << 32) + 1;
}

/// SplitMix64 finaliser (Steele, Lea & Flood 2014): a bijective 64-bit mixer.
pub fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The 256-bit generator seed of stream `(seed, stage, index)`.
///
/// The three coordinates are chained through SplitMix64 so that neighbouring keys give
/// unrelated states; the four state words are four further SplitMix64 outputs.
pub fn stream_key(seed: u64, stage: u64, index: u64) -> [u8; 32] {
    let mut h = splitmix64(seed ^ 0x6975_715f_7365_6564); // "iuq_seed"
    h = splitmix64(h ^ stage);
    h = splitmix64(h ^ index.rotate_left(17));
    let mut key = [0u8; 32];
    for (i, chunk) in key.chunks_exact_mut(8).enumerate() {
        h = splitmix64(h.wrapping_add(i as u64));
        chunk.copy_from_slice(&h.to_le_bytes());
    }
    key
}

/// The random stream for unit `index` of `stage` under the user's `seed`.
pub fn stream(seed: u64, stage: u64, index: u64) -> StreamRng {
    StreamRng::from_seed(stream_key(seed, stage, index))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;

    #[test]
    fn same_key_same_stream_and_different_keys_differ() {
        let mut s1 = stream(7, 1, 3);
        let mut s2 = stream(7, 1, 3);
        let x1: Vec<u64> = (0..8).map(|_| s1.random()).collect();
        let x2: Vec<u64> = (0..8).map(|_| s2.random()).collect();
        assert_eq!(x1, x2);
        for (seed, stage, index) in [(8, 1, 3), (7, 2, 3), (7, 1, 4), (7, 3, 1)] {
            let mut s = stream(seed, stage, index);
            let y: Vec<u64> = (0..8).map(|_| s.random()).collect();
            assert_ne!(x1, y, "key ({seed}, {stage}, {index})");
        }
    }

    #[test]
    fn uniform_draws_have_the_right_mean() {
        let mut s = stream(1, 0, 0);
        let n = 100_000;
        let mean = (0..n).map(|_| s.random::<f64>()).sum::<f64>() / n as f64;
        // sd of the mean of U(0,1) is sqrt(1/12/n) ≈ 9.1e-4; allow 5 sd.
        assert!((mean - 0.5).abs() < 5.0 * (1.0 / 12.0 / n as f64).sqrt());
    }
}
