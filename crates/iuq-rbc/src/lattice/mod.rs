//! D3Q19 lattice Boltzmann fluid: BGK collision with Guo forcing, a relaxation time per node,
//! periodic x and y, and in z either periodicity or two moving walls (halfway bounce-back).
//!
//! # Scheme
//! Each time step streams, `f_q(x) ← f*_q(x − c_q)`, and collides: `ρ = Σ f_q`,
//! `u = (Σ f_q c_q + F/2)/ρ`,
//! `f*_q = f_q − ω(f_q − f_q^eq(ρ, u)) + (1 − ω/2)·w_q[3(c_q − u) + 9(c_q·u)c_q]·F`
//! (Guo, Zheng & Shi 2002; the forcing of Palabos' `GuoExternalForceBGKdynamics`, which HemoCell
//! uses), with `f^eq_q = w_q ρ (1 + 3c_q·u + 4.5(c_q·u)² − 1.5u²)`.
//!
//! Streaming and collision are fused in place with the AA pattern (Bailey et al. 2009), on one
//! buffer `A`:
//! * even steps are local: node x reads `A[x][q] = f_q(x)`, collides and writes
//!   `A[x][q̄] = f*_q(x)` (the opposite slot);
//! * odd steps gather `f_q(y) = A[y − c_q][q̄]`, collide and scatter `A[y + c_q][q] = f*_q(y)`,
//!   which leaves `A[x][q] = f_q(x)` for the next even step.
//!
//! In an odd step the slot `A[z][p]` is read and written only by the node `z − c_p`, so nodes
//! never touch each other's data: the update is race-free on any number of threads and the same
//! bit for bit whatever the thread count. One buffer instead of two halves the memory footprint
//! (2.3 MB for the shear box in single precision) and each cache line is read and written by the
//! same sweep, which saves the write-allocate traffic of a two-buffer scheme.
//!
//! # Walls
//! With [`ZBoundary::Walls`] the node planes `k = 0 … nz−1` sit at heights `z = k + ½` and the
//! walls at `z = 0` and `z = nz` (halfway bounce-back, `nz` lattice units apart). A population
//! that would be pulled from beyond a wall is the node's own opposite population reflected by the
//! wall moving with velocity `u_w` (Ladd 1994): `f_q(x) = f*_q̄(x) + 6 w_q ρ_w (c_q·u_w)` (in
//! odd steps it is read from the node's own slot, and a population leaving through a wall is
//! written back into the node's opposite slot), with
//! the wall density ρ_w = 1 (the rest density; the correction sums to zero for a tangential wall
//! velocity, so mass is conserved exactly). Halfway bounce-back reproduces linear (Couette)
//! profiles exactly, independent of τ, and stands in for HemoCell's regularized velocity walls on
//! two node planes: with `nz` equal to HemoCell's gap (39 in the shear box, docs/cell-model.md)
//! the walls lie at the same heights as HemoCell's.
//!
//! # Storage and precision
//! Populations are stored as deviations from the rest weights, `δ_q = f_q − w_q` (so that their
//! O(1e-3) variations are not lost against the O(0.1) weights), in single ([`Precision::Single`],
//! the default) or double precision; all arithmetic is done in double precision. Single
//! precision halves the memory footprint and traffic (2.3 instead of 4.6 MB for the shear box,
//! about the size of a core's L2 cache); the gain in speed is modest where the update is bound
//! by arithmetic rather than memory. The unit test `single_precision_storage_matches_double`
//! shows that it changes a sheared, forced flow by less than 1e-9 (relative 3e-7), the Couette
//! test by 1e-8 of the wall speed, and the ignored end-to-end test
//! `single_precision_storage_gives_the_double_precision_elongation` compares a whole run.
//!
//! # Vector instructions
//! The row kernels run on AVX-512 (8 lanes; compiled when the compiler has the AVX-512
//! intrinsics, Rust ≥ 1.89, see `build.rs`), AVX2 with FMA (4 lanes) or scalar code, chosen at
//! run time from what the CPU reports. All paths perform the same IEEE operations (fused
//! multiply-adds included: the scalar path uses `f64::mul_add`), so results are identical
//! bit for bit on every path. The environment variable `IUQ_RBC_SIMD=avx2` or `=scalar` forces
//! a narrower path, for diagnostics.
//!
//! # Memory layout
//! Structure of arrays blocked by rows: `δ_q` of node `(x, y, z)` is stored at
//! `((z·ny + y)·19 + q)·(nx + 2) + 1 + x`, so a row of `nx` nodes holds 19 contiguous runs
//! (unit-stride vector loads for every direction) and rows are independent work items for the
//! threads. Each run has one ghost entry at each end that stands for the periodic neighbour in
//! x: even steps copy the first and last node into the ghosts, odd steps read and write through
//! them and a final pass folds the ghosts back, so no vector load or store ever wraps. Node
//! fields (relaxation rate, force) are indexed by `(z·ny + y)·nx + x`. Rows that carry no force
//! and only the default relaxation rate use a cheaper kernel that reads neither field.
//!
//! A time loop should run on one of rayon's worker threads ([`on_pool_worker`]): a sweep then
//! splits its rows the same way every step (the loop's thread keeps the first half, the others
//! steal the rest), so each core finds its rows in its own cache. Called from outside the pool,
//! every sweep is injected afresh and the halves change cores from step to step; on the 2.4 MB
//! shear box that costs about a fifth of the run time (measured: 12.8 s → 10.0 s per scaled run).

mod collision;
mod d3q19;
mod geometry;
mod numbers;
mod pool;
mod simd;
mod step;
mod sweep;

pub use d3q19::{OPPOSITE, Q, VELOCITIES, WEIGHTS};
pub use geometry::{LatticeGeometry, ZBoundary};
pub use pool::on_pool_worker;

use collision::moments;
use numbers::Stored;
use simd::Simd;
use step::sweep;
use sweep::{Fields, RowLinks, fill_ghosts, row_links, wrap};

/// Floating-point format of the stored populations.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Precision {
    /// 4-byte floats (deviations from the rest weights); arithmetic in double precision.
    #[default]
    Single,
    /// 8-byte floats.
    Double,
}

impl Precision {
    /// Bytes of one stored population.
    pub fn bytes(self) -> usize {
        match self {
            Precision::Single => 4,
            Precision::Double => 8,
        }
    }

    /// Bytes moved per node update at the minimum: 19 populations read and 19 written. Rows
    /// touched by the cell also read the relaxation rate and the force (32 bytes more).
    pub fn bytes_per_node_update(self) -> usize {
        2 * Q * self.bytes()
    }
}

/// The population buffer in the chosen precision.
#[derive(Debug, Clone)]
enum Buffers {
    Single(Vec<f32>),
    Double(Vec<f64>),
}

/// The D3Q19 fluid: populations, the per-node relaxation rate and the force density.
#[derive(Debug, Clone)]
pub struct Lattice {
    geometry: LatticeGeometry,
    buffers: Buffers,
    omega: Vec<f64>,
    default_omega: f64,
    force: [Vec<f64>; 3],
    /// Rows whose nodes may carry a force.
    row_forced: Vec<bool>,
    /// Number of nodes per row whose relaxation rate differs from the default.
    row_special_omega: Vec<u32>,
    /// `6 w_q (c_q·u_w)` for a population pulled from the bottom (index 0) or top (index 1) wall.
    wall_terms: [[f64; Q]; 2],
    /// Offset, relative to `(row·19)·nx + x`, of the slot holding the streamed `f_q` of an
    /// interior node after an even step (`[0]`) and after an odd step (`[1]`).
    interior_offsets: [[isize; Q]; 2],
    /// Where each row gathers from and scatters to in odd steps.
    row_links: Vec<RowLinks>,
    /// True when the next step is odd (the buffer then holds post-collision populations in
    /// the opposite slots of their node).
    odd: bool,
    /// Length of a run: `nx` nodes and two ghosts.
    stride: usize,
    parallel: bool,
    simd: Simd,
}

impl Lattice {
    /// A fluid at rest (ρ = 1, u = 0) with relaxation time `tau` everywhere and no force.
    ///
    /// Sizes below 3 nodes per axis are raised to 3.
    pub fn new(
        nx: usize,
        ny: usize,
        nz: usize,
        z_boundary: ZBoundary,
        tau: f64,
        precision: Precision,
    ) -> Self {
        let (nx, ny, nz) = (nx.max(3), ny.max(3), nz.max(3));
        let geometry = LatticeGeometry {
            nx,
            ny,
            nz,
            z_boundary,
        };
        let n = geometry.nodes();
        let stride = nx + 2;
        let slots = ny * nz * Q * stride;
        let buffers = match precision {
            Precision::Single => Buffers::Single(vec![0.0; slots]),
            Precision::Double => Buffers::Double(vec![0.0; slots]),
        };
        let mut wall_terms = [[0.0; Q]; 2];
        if let ZBoundary::Walls { bottom, top } = z_boundary {
            for (side, u) in [bottom, top].iter().enumerate() {
                for q in 0..Q {
                    let c = VELOCITIES[q];
                    let cu = c[0] as f64 * u[0] + c[1] as f64 * u[1] + c[2] as f64 * u[2];
                    wall_terms[side][q] = 6.0 * WEIGHTS[q] * cu;
                }
            }
        }
        Self {
            geometry,
            buffers,
            omega: vec![1.0 / tau; n],
            default_omega: 1.0 / tau,
            force: [vec![0.0; n], vec![0.0; n], vec![0.0; n]],
            row_forced: vec![false; ny * nz],
            row_special_omega: vec![0; ny * nz],
            wall_terms,
            row_links: (0..ny * nz)
                .map(|r| row_links(&geometry, stride, &wall_terms, r))
                .collect(),
            interior_offsets: [
                std::array::from_fn(|q| {
                    let c = VELOCITIES[q];
                    let row_shift = c[2] as isize * ny as isize + c[1] as isize;
                    (OPPOSITE[q] * stride) as isize
                        - row_shift * (Q * stride) as isize
                        - c[0] as isize
                }),
                std::array::from_fn(|q| (q * stride) as isize),
            ],
            odd: false,
            stride,
            parallel: true,
            simd: Simd::detect(),
        }
    }

    /// Size and boundaries.
    pub fn geometry(&self) -> &LatticeGeometry {
        &self.geometry
    }

    /// The storage precision.
    pub fn precision(&self) -> Precision {
        match self.buffers {
            Buffers::Single(..) => Precision::Single,
            Buffers::Double(..) => Precision::Double,
        }
    }

    /// Name of the vector instruction set the update uses (`avx2+fma` or `scalar`).
    pub fn instruction_set(&self) -> &'static str {
        self.simd.name()
    }

    /// Spread the node updates of one step over rayon's threads (default) or run them on the
    /// calling thread. The result is identical either way.
    pub fn set_parallel(&mut self, parallel: bool) {
        self.parallel = parallel;
    }

    /// Whether the update is spread over rayon's threads.
    pub fn is_parallel(&self) -> bool {
        self.parallel
    }

    /// The relaxation rate ω = 1/τ given to every node at construction.
    pub fn default_omega(&self) -> f64 {
        self.default_omega
    }

    /// Set the relaxation rate ω = 1/τ of one node.
    #[inline]
    pub fn set_omega(&mut self, node: usize, omega: f64) {
        let row = node / self.geometry.nx;
        let was = self.omega[node] != self.default_omega;
        let is = omega != self.default_omega;
        if was != is {
            if is {
                self.row_special_omega[row] += 1;
            } else {
                self.row_special_omega[row] -= 1;
            }
        }
        self.omega[node] = omega;
    }

    /// The relaxation rate of one node.
    #[inline]
    pub fn omega(&self, node: usize) -> f64 {
        self.omega[node]
    }

    /// Add `f` to the force density of `node`.
    #[inline]
    pub fn add_force(&mut self, node: usize, f: [f64; 3]) {
        self.row_forced[node / self.geometry.nx] = true;
        self.force[0][node] += f[0];
        self.force[1][node] += f[1];
        self.force[2][node] += f[2];
    }

    /// The force density at `node`.
    #[inline]
    pub fn force(&self, node: usize) -> [f64; 3] {
        [
            self.force[0][node],
            self.force[1][node],
            self.force[2][node],
        ]
    }

    /// Zero the force density everywhere (touching only the rows that carry force).
    pub fn clear_forces(&mut self) {
        let nx = self.geometry.nx;
        for (row, forced) in self.row_forced.iter_mut().enumerate() {
            if *forced {
                for d in 0..3 {
                    self.force[d][row * nx..(row + 1) * nx].fill(0.0);
                }
                *forced = false;
            }
        }
    }

    /// Zero the force density at `nodes` and mark their rows as carrying none: the clear for a
    /// caller that knows these are the only nodes with force (the immersed boundary's stencil
    /// nodes), a few thousand stores instead of every forced row.
    pub fn clear_forces_at(&mut self, nodes: impl IntoIterator<Item = usize>) {
        let nx = self.geometry.nx;
        for node in nodes {
            for d in 0..3 {
                self.force[d][node] = 0.0;
            }
            self.row_forced[node / nx] = false;
        }
    }

    /// Set the same force density on every node (a body force).
    pub fn fill_force(&mut self, f: [f64; 3]) {
        for d in 0..3 {
            self.force[d].fill(f[d]);
        }
        self.row_forced.fill(true);
    }

    /// Density and momentum Σ f_q c_q of the populations that node `(x, y, z)` will collide
    /// next, i.e. the post-streaming state, gathered from its neighbours.
    pub fn streamed_moments(&self, x: usize, y: usize, z: usize) -> (f64, [f64; 3]) {
        let mut s = 0.0;
        let mut j = [0.0; 3];
        for (q, c) in VELOCITIES.iter().enumerate() {
            let d = self.streamed_deviation(q, x, y, z);
            s += d;
            j[0] += d * c[0] as f64;
            j[1] += d * c[1] as f64;
            j[2] += d * c[2] as f64;
        }
        (1.0 + s, j)
    }

    /// Density and velocity `u = (Σ f_q c_q + F/2)/ρ` at node `(x, y, z)` with the force density
    /// currently stored there (Guo's half-force correction).
    pub fn velocity(&self, x: usize, y: usize, z: usize) -> (f64, [f64; 3]) {
        let (rho, j) = self.streamed_moments(x, y, z);
        let f = self.force(self.geometry.node(x, y, z));
        (
            rho,
            [
                (j[0] + 0.5 * f[0]) / rho,
                (j[1] + 0.5 * f[1]) / rho,
                (j[2] + 0.5 * f[2]) / rho,
            ],
        )
    }

    /// Velocity `u = (Σ f_q c_q + F/2)/ρ` of the post-streaming populations at `node`, as
    /// [`Lattice::velocity`], with a fast path for nodes away from the domain's faces (where
    /// every source sits at a constant offset).
    #[inline]
    pub fn node_velocity(&self, node: usize) -> [f64; 3] {
        let g = &self.geometry;
        let row = node / g.nx;
        self.velocity_at(node % g.nx, row % g.ny, row / g.ny)
    }

    /// [`Lattice::node_velocity`] of the node `(x, y, z)`.
    #[inline]
    pub fn velocity_at(&self, x: usize, y: usize, z: usize) -> [f64; 3] {
        let g = &self.geometry;
        if x == 0 || y == 0 || z == 0 || x + 1 == g.nx || y + 1 == g.ny || z + 1 == g.nz {
            return self.velocity(x, y, z).1;
        }
        let row = z * g.ny + y;
        let base = row * Q * self.stride + 1 + x;
        let offsets = &self.interior_offsets[usize::from(!self.odd)];
        let (rho, j) = match &self.buffers {
            Buffers::Single(f) => interior_moments(f, base, offsets),
            Buffers::Double(f) => interior_moments(f, base, offsets),
        };
        let f = self.force(row * g.nx + x);
        let inv = 1.0 / rho;
        [
            (j[0] + 0.5 * f[0]) * inv,
            (j[1] + 0.5 * f[1]) * inv,
            (j[2] + 0.5 * f[2]) * inv,
        ]
    }

    /// Total mass Σ ρ of the stored populations (the same before and after streaming).
    pub fn total_mass(&self) -> f64 {
        let n = self.geometry.nodes() as f64;
        let nx = self.geometry.nx;
        let interior = |run: usize| (run * self.stride + 1)..(run * self.stride + 1 + nx);
        let runs = self.geometry.ny * self.geometry.nz * Q;
        n + match &self.buffers {
            Buffers::Single(f) => (0..runs)
                .flat_map(|r| f[interior(r)].iter().map(|&v| v as f64))
                .sum::<f64>(),
            Buffers::Double(f) => (0..runs).flat_map(|r| f[interior(r)].iter()).sum::<f64>(),
        }
    }

    /// Index of `δ_q` of node `x` of row `row`.
    #[inline]
    fn slot(&self, row: usize, q: usize, x: usize) -> usize {
        (row * Q + q) * self.stride + 1 + x
    }

    #[inline]
    fn stored(&self, index: usize) -> f64 {
        match &self.buffers {
            Buffers::Single(f) => f[index] as f64,
            Buffers::Double(f) => f[index],
        }
    }

    /// `f_q − w_q` of the streamed population of direction `q` at node `(x, y, z)`.
    #[inline]
    fn streamed_deviation(&self, q: usize, x: usize, y: usize, z: usize) -> f64 {
        let g = &self.geometry;
        let row = z * g.ny + y;
        if !self.odd {
            // After an odd step every node holds its own streamed populations.
            return self.stored(self.slot(row, q, x));
        }
        // After an even step f_q(x) = f*_q(x − c_q), stored in the opposite slot of x − c_q.
        let c = VELOCITIES[q];
        let zs = z as i64 - c[2] as i64;
        if (zs < 0 || zs >= g.nz as i64) && !g.z_periodic() {
            let side = usize::from(zs >= 0);
            return self.stored(self.slot(row, q, x)) + self.wall_terms[side][q];
        }
        let zs = wrap(zs, g.nz);
        let ys = wrap(y as i64 - c[1] as i64, g.ny);
        let xs = wrap(x as i64 - c[0] as i64, g.nx);
        self.stored(self.slot(zs * g.ny + ys, OPPOSITE[q], xs))
    }

    /// One time step: stream and collide with Guo forcing (even or odd AA step).
    pub fn step(&mut self) {
        let (parallel, simd) = (self.parallel, self.simd);
        let fields = Fields {
            fx: &self.force[0],
            fy: &self.force[1],
            fz: &self.force[2],
            omega: &self.omega,
            default_omega: self.default_omega,
            row_forced: &self.row_forced,
            row_special_omega: &self.row_special_omega,
            geometry: self.geometry,
            row_links: &self.row_links,
            stride: self.stride,
        };
        let odd = self.odd;
        match &mut self.buffers {
            Buffers::Single(f) => sweep(&fields, f, odd, parallel, simd),
            Buffers::Double(f) => sweep(&fields, f, odd, parallel, simd),
        }
        self.odd = !odd;
    }

    /// Set every node to equilibrium with density 1 and velocity `u(x, y, z)` (the streamed
    /// populations of the next step).
    pub fn set_equilibrium(&mut self, u: impl Fn(usize, usize, usize) -> [f64; 3]) {
        let g = self.geometry;
        self.odd = false;
        for z in 0..g.nz {
            for y in 0..g.ny {
                let row = z * g.ny + y;
                for x in 0..g.nx {
                    let v = u(x, y, z);
                    let usq = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
                    for q in 0..Q {
                        let c = VELOCITIES[q];
                        let cu = c[0] as f64 * v[0] + c[1] as f64 * v[1] + c[2] as f64 * v[2];
                        let d = WEIGHTS[q] * (3.0 * cu + 4.5 * cu * cu - 1.5 * usq);
                        let i = self.slot(row, q, x);
                        match &mut self.buffers {
                            Buffers::Single(f) => f[i] = d as f32,
                            Buffers::Double(f) => f[i] = d,
                        }
                    }
                }
            }
        }
        let (nx, stride) = (g.nx, self.stride);
        match &mut self.buffers {
            Buffers::Single(f) => f
                .chunks_mut(Q * stride)
                .for_each(|row| fill_ghosts(row, nx, stride)),
            Buffers::Double(f) => f
                .chunks_mut(Q * stride)
                .for_each(|row| fill_ghosts(row, nx, stride)),
        }
    }
}

/// Density and momentum streamed into the interior node whose row-block entry is `base`.
#[inline(always)]
fn interior_moments<S: Stored>(f: &[S], base: usize, offsets: &[isize; Q]) -> (f64, [f64; 3]) {
    let d: [f64; Q] = std::array::from_fn(|q| f[(base as isize + offsets[q]) as usize].to_f64());
    moments(&d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rest_state_is_stationary_and_threads_do_not_change_results() {
        let mut a = Lattice::new(8, 6, 5, ZBoundary::Periodic, 0.9, Precision::Double);
        a.step();
        assert!((a.total_mass() - 240.0).abs() < 1e-12);
        let walls = ZBoundary::Walls {
            bottom: [-0.01, 0.0, 0.0],
            top: [0.01, 0.0, 0.0],
        };
        for precision in [Precision::Single, Precision::Double] {
            let mut p = Lattice::new(13, 5, 6, walls, 1.3, precision);
            let mut s = p.clone();
            s.set_parallel(false);
            let mut w = p.clone();
            let twenty_steps = |l: &mut Lattice| {
                l.add_force(17, [1e-3, 2e-3, -1e-3]);
                l.set_omega(40, 1.0 / 4.0);
                for _ in 0..20 {
                    l.step();
                }
            };
            twenty_steps(&mut p);
            twenty_steps(&mut s);
            on_pool_worker(|| twenty_steps(&mut w));
            for node in 0..p.geometry().nodes() {
                let g = p.geometry();
                let (x, y, z) = (node % g.nx, (node / g.nx) % g.ny, node / (g.nx * g.ny));
                assert_eq!(p.velocity(x, y, z), s.velocity(x, y, z));
                assert_eq!(p.velocity(x, y, z), w.velocity(x, y, z));
            }
        }
    }

    #[test]
    fn couette_flow_between_the_moving_walls_is_linear() {
        // Walls at z = 0 and z = 19 moving at ∓U: u_x(z) = U(2z/19 − 1) at the node heights
        // z = k + ½, for any τ (halfway bounce-back is exact for linear profiles).
        let u_wall = 0.005;
        for (tau, precision, tolerance) in [
            (1.16, Precision::Single, 1e-8),
            (0.7, Precision::Double, 1e-12),
        ] {
            let walls = ZBoundary::Walls {
                bottom: [-u_wall, 0.0, 0.0],
                top: [u_wall, 0.0, 0.0],
            };
            let mut l = Lattice::new(4, 3, 19, walls, tau, precision);
            l.set_parallel(false);
            // Diffusion time H²/ν ≈ 1640 steps at τ = 1.16; the slowest mode decays as
            // exp(−π²νt/H²), so 4 of them leave 1e-17 of the start-up transient.
            let steps = (4.0 * 19.0 * 19.0 / ((tau - 0.5) / 3.0)) as usize;
            for _ in 0..steps {
                l.step();
            }
            for k in 0..19 {
                let z = k as f64 + 0.5;
                let exact = u_wall * (2.0 * z / 19.0 - 1.0);
                let (rho, u) = l.velocity(1, 1, k);
                // Single-precision storage rounds the deviations at the 1e-7 relative level.
                assert!(
                    (u[0] - exact).abs() < tolerance,
                    "τ {tau} k {k}: {} vs {exact}",
                    u[0]
                );
                assert!(u[1].abs() < 1e-12 && u[2].abs() < 1e-9);
                assert!((rho - 1.0).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn a_body_force_drives_the_poiseuille_profile() {
        // u_x(z) = g z (H − z)/(2ν) between resting walls at z = 0 and z = H. With BGK and
        // halfway bounce-back the profile is exact for τ = ½ + √(3/16); at other τ the walls
        // slip by O((τ − ½)²) lattice units.
        let g = 1e-6;
        let nz = 16;
        for (tau, tolerance) in [(0.5 + (3.0f64 / 16.0).sqrt(), 1e-6), (1.16, 0.02)] {
            let walls = ZBoundary::Walls {
                bottom: [0.0; 3],
                top: [0.0; 3],
            };
            let mut l = Lattice::new(3, 3, nz, walls, tau, Precision::Double);
            l.fill_force([g, 0.0, 0.0]);
            let nu = (tau - 0.5) / 3.0;
            let steps = (20.0 * (nz * nz) as f64 / nu) as usize;
            for _ in 0..steps {
                l.step();
            }
            let h = nz as f64;
            let centre = g * (h / 2.0) * (h / 2.0) / (2.0 * nu);
            for k in 0..nz {
                let z = k as f64 + 0.5;
                let exact = g * z * (h - z) / (2.0 * nu);
                let u = l.velocity(1, 1, k).1[0];
                assert!(
                    (u - exact).abs() < tolerance * centre,
                    "τ {tau} k {k}: {u} vs {exact}"
                );
            }
        }
    }

    #[test]
    fn single_precision_storage_matches_double() {
        // The same sheared, forced flow stored in single and in double precision.
        let walls = ZBoundary::Walls {
            bottom: [-0.003, 0.0, 0.0],
            top: [0.003, 0.0, 0.0],
        };
        let mut a = Lattice::new(12, 10, 19, walls, 1.16, Precision::Single);
        let mut b = Lattice::new(12, 10, 19, walls, 1.16, Precision::Double);
        for l in [&mut a, &mut b] {
            l.set_omega(500, 1.0 / 4.4);
            for _ in 0..3000 {
                l.add_force(777, [2e-4, -1e-4, 3e-4]);
                l.step();
                l.clear_forces();
            }
        }
        let mut worst: f64 = 0.0;
        for node in 0..a.geometry().nodes() {
            let (ua, ub) = (a.node_velocity(node), b.node_velocity(node));
            for d in 0..3 {
                worst = worst.max((ua[d] - ub[d]).abs());
            }
        }
        // Velocities are O(3e-3); single-precision storage of the deviations changes them by
        // less than 1e-9 (relative 3e-7).
        assert!(worst < 1e-9, "largest difference {worst}");
    }

    #[test]
    fn fast_node_velocity_matches_the_general_gather() {
        let walls = ZBoundary::Walls {
            bottom: [-0.01, 0.0, 0.0],
            top: [0.01, 0.02, 0.0],
        };
        let mut l = Lattice::new(9, 7, 6, walls, 0.8, Precision::Double);
        l.add_force(100, [1e-3, -2e-3, 5e-4]);
        for _ in 0..5 {
            l.step();
        }
        l.add_force(100, [1e-3, -2e-3, 5e-4]);
        let g = *l.geometry();
        for node in 0..g.nodes() {
            let (x, y, z) = (node % g.nx, (node / g.nx) % g.ny, node / (g.nx * g.ny));
            let a = l.node_velocity(node);
            let b = l.velocity(x, y, z).1;
            for d in 0..3 {
                assert!((a[d] - b[d]).abs() < 1e-16, "node {node}");
            }
        }
    }

    #[test]
    fn vector_and_scalar_kernels_agree_bit_for_bit() {
        let walls = ZBoundary::Walls {
            bottom: [-0.01, 0.0, 0.0],
            top: [0.01, 0.0, 0.0],
        };
        let mut v = Lattice::new(21, 5, 4, walls, 1.1, Precision::Double);
        let mut s = v.clone();
        s.simd = Simd::Scalar;
        for l in [&mut v, &mut s] {
            l.add_force(30, [1e-3, 2e-3, -1e-3]);
            l.set_omega(33, 0.3);
            for _ in 0..15 {
                l.step();
            }
        }
        match (&v.buffers, &s.buffers) {
            (Buffers::Double(a), Buffers::Double(b)) => assert_eq!(a, b),
            _ => unreachable!(),
        }
    }
}
