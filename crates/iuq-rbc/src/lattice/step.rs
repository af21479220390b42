//! One AA step over every row of the lattice: the row kernel of the chosen instruction set on
//! each row (in parallel or not) and, after an odd step, the ghosts folded back onto the nodes
//! they stand for.

use rayon::prelude::*;

use super::d3q19::{Q, SHIFTED_SLOTS, VELOCITIES};
use super::geometry::LatticeGeometry;
use super::numbers::Stored;
use super::simd::{Simd, even_row, odd_row};
use super::sweep::{Fields, SharedBuffer};

/// One even or odd AA step over every row of `f`.
pub(super) fn sweep<S: Stored>(
    fields: &Fields,
    f: &mut [S],
    odd: bool,
    parallel: bool,
    simd: Simd,
) {
    let row_len = Q * fields.stride;
    if !odd {
        let kernel = |(r, row): (usize, &mut [S])| even_row(fields, r, row, simd);
        if parallel {
            f.par_chunks_mut(row_len)
                .enumerate()
                .with_min_len(4)
                .for_each(kernel);
        } else {
            f.chunks_mut(row_len).enumerate().for_each(kernel);
        }
    } else {
        let shared = SharedBuffer::new(f);
        let rows = fields.row_links.len();
        let kernel = |r: usize| odd_row(fields, &shared, r, simd);
        let g = fields.geometry;
        let stride = fields.stride;
        let fold = |(r, row): (usize, &mut [S])| fold_ghosts(row, &g, stride, r);
        if parallel {
            (0..rows).into_par_iter().with_min_len(4).for_each(kernel);
            f.par_chunks_mut(row_len)
                .enumerate()
                .with_min_len(16)
                .for_each(fold);
        } else {
            (0..rows).for_each(kernel);
            f.chunks_mut(row_len).enumerate().for_each(fold);
        }
    }
}

/// After an odd step: move what the scatter wrote into the ghosts onto the node they stand for.
/// Runs that a wall feeds (slot p of a row whose upstream row `z − c_z(p)` is beyond a wall)
/// were written in place by the bounce-back and are left alone.
#[inline]
fn fold_ghosts<S: Stored>(row: &mut [S], g: &LatticeGeometry, stride: usize, r: usize) {
    let nx = g.nx;
    let z = (r / g.ny) as i64;
    for (p, cx) in SHIFTED_SLOTS {
        let upstream = z - VELOCITIES[p][2] as i64;
        if !g.z_periodic() && !(0..g.nz as i64).contains(&upstream) {
            continue;
        }
        let run = p * stride;
        if cx > 0 {
            row[run + 1] = row[run + nx + 1];
        } else {
            row[run + nx] = row[run];
        }
    }
}
