//! How fast the fluid solver runs compared with what the memory allows.
//!
//! A lattice Boltzmann update is bound by memory traffic: each node update reads and writes its
//! 19 populations (`2·19·b` bytes for `b`-byte storage; write-allocate traffic not counted).
//! [`memory_copy_bandwidth`] measures, in the same process, what a large `memcpy` moves per
//! second (bytes read plus bytes written, on all threads); the fraction of the bandwidth limit
//! reached is `MLUPS·bytes per update / copy bandwidth`. On the shear box (40×20×39 nodes,
//! 2.4 MB per buffer in single precision) the populations live in cache, so this fraction can
//! exceed 1; a box far larger than the last-level cache gives the memory-bound figure.

use std::time::Instant;

use rayon::prelude::*;

use crate::lattice::{Lattice, Precision, ZBoundary, on_pool_worker};

/// Memory copy bandwidth in GB/s (bytes read + bytes written per second) of copying a buffer of
/// `bytes` bytes, best of `repeats`, split over rayon's threads when `parallel`.
pub fn memory_copy_bandwidth(bytes: usize, repeats: usize, parallel: bool) -> f64 {
    let n = (bytes / 8).max(1);
    let source = vec![1.0f64; n];
    let mut target = vec![0.0f64; n];
    let chunk = n.div_ceil(rayon::current_num_threads().max(1)).max(1);
    let mut best = f64::INFINITY;
    for _ in 0..repeats.max(1) + 1 {
        let t = Instant::now();
        if parallel {
            target
                .par_chunks_mut(chunk)
                .zip(source.par_chunks(chunk))
                .for_each(|(t, s)| t.copy_from_slice(s));
        } else {
            target.copy_from_slice(&source);
        }
        std::hint::black_box(&mut target);
        best = best.min(t.elapsed().as_secs_f64());
    }
    2.0 * (n * 8) as f64 / best / 1e9
}

/// One timing of the fluid update.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LatticeBenchmark {
    /// Nodes in x, y, z.
    pub domain: [usize; 3],
    /// Storage precision.
    pub precision: String,
    /// Vector instruction set of the update.
    pub instruction_set: String,
    /// Threads used.
    pub threads: usize,
    /// Whether every node carried a force (the kernel of the rows the cell touches).
    pub forced: bool,
    /// Steps per timing.
    pub steps: usize,
    /// Million lattice updates per second (best timing).
    pub mlups: f64,
    /// Bytes moved per node update (populations read and written; forced rows also read the
    /// relaxation rate and the force).
    pub bytes_per_update: usize,
    /// `mlups · bytes_per_update` in GB/s.
    pub achieved_gb_per_s: f64,
    /// The memory copy bandwidth measured alongside, GB/s.
    pub copy_gb_per_s: f64,
    /// `achieved / copy`.
    pub bandwidth_fraction: f64,
}

/// Time `steps` updates of a `domain` lattice (walls in z moving at ±0.003), best of
/// `repeats`, and relate it to the copy bandwidth `copy_gb_per_s`.
pub fn benchmark_lattice(
    domain: [usize; 3],
    steps: usize,
    repeats: usize,
    precision: Precision,
    parallel: bool,
    forced: bool,
    copy_gb_per_s: f64,
) -> LatticeBenchmark {
    let [nx, ny, nz] = domain;
    let walls = ZBoundary::Walls {
        bottom: [-0.003, 0.0, 0.0],
        top: [0.003, 0.0, 0.0],
    };
    let mut lattice = Lattice::new(nx, ny, nz, walls, 1.16, precision);
    lattice.set_parallel(parallel);
    if forced {
        lattice.fill_force([1e-7, 0.0, 0.0]);
    }
    for _ in 0..3 {
        lattice.step();
    }
    let best = on_pool_worker(|| {
        let mut best = f64::INFINITY;
        for _ in 0..repeats.max(1) {
            let t = Instant::now();
            for _ in 0..steps.max(1) {
                lattice.step();
            }
            best = best.min(t.elapsed().as_secs_f64());
        }
        best
    });
    let nodes = lattice.geometry().nodes();
    let mlups = (nodes * steps.max(1)) as f64 / best / 1e6;
    let bytes = precision.bytes_per_node_update() + if forced { 32 } else { 0 };
    let achieved = mlups * bytes as f64 / 1e3;
    LatticeBenchmark {
        domain: [
            lattice.geometry().nx,
            lattice.geometry().ny,
            lattice.geometry().nz,
        ],
        precision: format!("{precision:?}").to_lowercase(),
        instruction_set: lattice.instruction_set().to_string(),
        threads: if parallel {
            rayon::current_num_threads()
        } else {
            1
        },
        forced,
        steps,
        mlups,
        bytes_per_update: bytes,
        achieved_gb_per_s: achieved,
        copy_gb_per_s,
        bandwidth_fraction: achieved / copy_gb_per_s,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_small_benchmark_reports_consistent_numbers() {
        let copy = memory_copy_bandwidth(1 << 20, 2, false);
        assert!(copy > 0.0);
        let b = benchmark_lattice([16, 8, 6], 5, 1, Precision::Single, false, false, copy);
        assert!(b.mlups > 0.0);
        assert_eq!(b.bytes_per_update, 152);
        assert!((b.achieved_gb_per_s - b.mlups * 152.0 / 1e3).abs() < 1e-9);
        assert!((b.bandwidth_fraction - b.achieved_gb_per_s / copy).abs() < 1e-12);
    }
}
