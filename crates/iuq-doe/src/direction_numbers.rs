//! Sobol' direction numbers from the Joe–Kuo table `new-joe-kuo-6.21201`.
//!
//! Source: S. Joe and F. Y. Kuo, "Constructing Sobol sequences with better two-dimensional
//! projections", SIAM J. Sci. Comput. 30 (2008) 2635–2654, table `new-joe-kuo-6.21201`
//! (21201 dimensions), taken from SciPy's copy (`scipy/stats/_sobol_direction_numbers.npz`) by
//! `data/make_direction_numbers.py`, which documents the binary format of
//! `data/new-joe-kuo-6.21201.bin` (varint-coded primitive polynomials and initial numbers
//! `m_1..m_s`, grouped in blocks of 1024 dimensions).
//!
//! The table is embedded with `include_bytes!` and decoded lazily: each block of 1024 dimensions
//! is decoded once, on first use, behind its own [`OnceLock`], so a 6-dimensional sequence never
//! decodes the other 21195 dimensions.
//!
//! From the polynomial `x^s + a_1 x^(s-1) + … + a_(s-1) x + 1` and the initial odd integers
//! `m_1..m_s` (`m_k < 2^k`), the remaining `m_k` follow Bratley & Fox (1988):
//! `m_k = 2 a_1 m_(k-1) ⊕ 4 a_2 m_(k-2) ⊕ … ⊕ 2^(s-1) a_(s-1) m_(k-s+1) ⊕ 2^s m_(k-s) ⊕ m_(k-s)`,
//! and the direction number of bit `k` (1-based) is `v_k = m_k / 2^k`, stored as the integer
//! `m_k · 2^(BITS-k)`. Dimension 0 is the van der Corput sequence (`m_k = 1` for all `k`).

use std::sync::OnceLock;

use crate::error::{DoeError, Result};

/// The embedded table (format: see `data/make_direction_numbers.py`).
static TABLE: &[u8] = include_bytes!("../data/new-joe-kuo-6.21201.bin");

/// File magic of the embedded table.
const MAGIC: &[u8; 8] = b"IUQJK621";

/// Number of dimensions of the Joe–Kuo table `new-joe-kuo-6.21201`.
pub const SOBOL_MAX_DIM: usize = 21201;

/// Bits of the direction numbers: a sequence holds `2^52` points, each coordinate an integer
/// multiple of `2^-52` (exactly representable in an `f64`, and never equal to 1).
pub const SOBOL_BITS: u32 = 52;

/// Dimensions per block of the table (fixed by the data file; checked when decoding).
const BLOCK: usize = 1024;

/// Number of blocks of the table.
const N_BLOCKS: usize = SOBOL_MAX_DIM.div_ceil(BLOCK);

/// One decoded block: the polynomials and initial numbers of up to [`BLOCK`] dimensions.
#[derive(Debug)]
struct Block {
    /// Primitive polynomial of each dimension, leading and trailing coefficients included.
    polys: Vec<u32>,
    /// Start of each dimension's initial numbers in `ms` (one more entry than `polys`).
    starts: Vec<usize>,
    /// Initial numbers `m_1..m_s` of all dimensions, concatenated.
    ms: Vec<u32>,
}

/// Lazily decoded blocks; `Err` holds a description of a corrupt table (a build defect).
static BLOCKS: [OnceLock<std::result::Result<Block, String>>; N_BLOCKS] =
    [const { OnceLock::new() }; N_BLOCKS];

/// Reads a little-endian `u32` at `pos`.
fn read_u32(bytes: &[u8], pos: usize) -> Option<u32> {
    let b = bytes.get(pos..pos.checked_add(4)?)?;
    Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

/// Reads an unsigned LEB128 varint at `*pos` (at most 32 bits), advancing `*pos`.
fn read_varint(bytes: &[u8], pos: &mut usize) -> Option<u32> {
    let mut value: u64 = 0;
    let mut shift = 0;
    loop {
        let byte = *bytes.get(*pos)?;
        *pos += 1;
        value |= u64::from(byte & 0x7F) << shift;
        if byte < 0x80 {
            return u32::try_from(value).ok();
        }
        shift += 7;
        if shift > 28 {
            return None;
        }
    }
}

/// Decodes block `b` of the table.
fn decode_block(b: usize) -> std::result::Result<Block, String> {
    let corrupt = |what: &str| format!("embedded Joe-Kuo table is corrupt: {what}");
    if TABLE.get(..8) != Some(MAGIC.as_slice()) {
        return Err(corrupt("bad magic"));
    }
    let dims = read_u32(TABLE, 8).ok_or_else(|| corrupt("header"))? as usize;
    let block = read_u32(TABLE, 12).ok_or_else(|| corrupt("header"))? as usize;
    let blocks = read_u32(TABLE, 16).ok_or_else(|| corrupt("header"))? as usize;
    if dims != SOBOL_MAX_DIM || block != BLOCK || blocks != N_BLOCKS {
        return Err(corrupt("unexpected header values"));
    }
    let payload = 20 + 4 * N_BLOCKS;
    let offset = read_u32(TABLE, 20 + 4 * b).ok_or_else(|| corrupt("block offsets"))? as usize;
    let mut pos = payload + offset;
    let first = b * BLOCK;
    let last = (first + BLOCK).min(SOBOL_MAX_DIM);
    let mut polys = Vec::with_capacity(last - first);
    let mut starts = Vec::with_capacity(last - first + 1);
    let mut ms = Vec::new();
    let mut prev: u32 = 1;
    starts.push(0);
    for j in first..last {
        let delta = read_varint(TABLE, &mut pos).ok_or_else(|| corrupt("polynomial"))?;
        let poly = delta
            .checked_mul(2)
            .and_then(|d| d.checked_add(prev))
            .ok_or_else(|| corrupt("polynomial overflow"))?;
        prev = poly;
        let degree = 31 - poly.leading_zeros();
        if (j == 0) != (degree == 0) || degree >= SOBOL_BITS {
            return Err(corrupt("polynomial degree"));
        }
        for k in 1..=degree {
            let half = read_varint(TABLE, &mut pos).ok_or_else(|| corrupt("initial numbers"))?;
            let m = u64::from(half) * 2 + 1;
            if m >= 1u64 << k {
                return Err(corrupt("initial number out of range"));
            }
            ms.push(m as u32);
        }
        polys.push(poly);
        starts.push(ms.len());
    }
    Ok(Block { polys, starts, ms })
}

/// The decoded block `b`, decoding it on first use.
fn block(b: usize) -> Result<&'static Block> {
    BLOCKS[b]
        .get_or_init(|| decode_block(b))
        .as_ref()
        .map_err(|reason| DoeError::InvalidDimension {
            dim: b * BLOCK,
            reason: reason.clone(),
        })
}

/// Checks that `dim` is a usable Sobol' dimension (`1..=SOBOL_MAX_DIM`).
pub(crate) fn check_dim(dim: usize) -> Result<()> {
    if dim == 0 || dim > SOBOL_MAX_DIM {
        return Err(DoeError::InvalidDimension {
            dim,
            reason: format!(
                "a Sobol' sequence has 1 to {SOBOL_MAX_DIM} dimensions (Joe-Kuo new-joe-kuo-6.21201)"
            ),
        });
    }
    Ok(())
}

/// The direction numbers of the first `dim` dimensions, `SOBOL_BITS` integers per dimension
/// (row-major: entry `j * SOBOL_BITS + k` is bit `k + 1` of dimension `j`, i.e.
/// `m_(k+1) · 2^(SOBOL_BITS-1-k)`).
pub(crate) fn direction_numbers(dim: usize) -> Result<Vec<u64>> {
    check_dim(dim)?;
    let bits = SOBOL_BITS as usize;
    let mut v = vec![0u64; dim * bits];
    let mut m = [0u64; SOBOL_BITS as usize];
    for j in 0..dim {
        let blk = block(j / BLOCK)?;
        let local = j % BLOCK;
        let poly = u64::from(blk.polys[local]);
        let init = &blk.ms[blk.starts[local]..blk.starts[local + 1]];
        let s = init.len();
        if s == 0 {
            m.fill(1);
        } else {
            for (mk, &i) in m.iter_mut().zip(init) {
                *mk = u64::from(i);
            }
            for k in s..bits {
                let mut new = m[k - s];
                for i in 1..=s {
                    if (poly >> (s - i)) & 1 == 1 {
                        new ^= m[k - i] << i;
                    }
                }
                m[k] = new;
            }
        }
        for (k, (vk, &mk)) in v[j * bits..(j + 1) * bits].iter_mut().zip(&m).enumerate() {
            *vk = mk << (bits - 1 - k);
        }
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whole_table_decodes() {
        let mut total = 0;
        for b in 0..N_BLOCKS {
            let blk = block(b).expect("block decodes");
            total += blk.polys.len();
        }
        assert_eq!(total, SOBOL_MAX_DIM);
        // Last entry of new-joe-kuo-6.21201: polynomial 524263 (degree 18).
        let last = block(N_BLOCKS - 1).expect("block decodes");
        assert_eq!(last.polys.last().copied(), Some(524_263));
        assert_eq!(last.ms.len() - last.starts[last.polys.len() - 1], 18);
    }

    #[test]
    fn first_dimensions_match_bratley_fox() {
        let v = direction_numbers(3).expect("valid dim");
        let bits = SOBOL_BITS as usize;
        let top = |j: usize, k: usize| v[j * bits + k] >> (bits - 1 - k);
        // Dimension 0: m_k = 1; dimension 1 (x + 1, m_1 = 1): m_k = 2 m_(k-1) ^ m_(k-1).
        assert_eq!(
            (0..5).map(|k| top(0, k)).collect::<Vec<_>>(),
            [1, 1, 1, 1, 1]
        );
        assert_eq!(
            (0..5).map(|k| top(1, k)).collect::<Vec<_>>(),
            [1, 3, 5, 15, 17]
        );
        // Dimension 2 (x^2 + x + 1, m = 1, 3): m_3 = 2·3 ⊕ 4·1 ⊕ 1 = 3.
        assert_eq!((0..3).map(|k| top(2, k)).collect::<Vec<_>>(), [1, 3, 3]);
    }

    #[test]
    fn invalid_dimensions_are_errors() {
        assert!(direction_numbers(0).is_err());
        assert!(direction_numbers(SOBOL_MAX_DIM + 1).is_err());
        assert!(direction_numbers(SOBOL_MAX_DIM).is_ok());
    }
}
