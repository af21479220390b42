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

use rayon::prelude::*;

/// Number of discrete velocities.
pub const Q: usize = 19;

/// Run `work` on a rayon worker thread (directly if already on one), so that the sweeps of a
/// time loop inside it keep their rows on the same cores from step to step (module docs).
/// Results do not depend on it.
pub fn on_pool_worker<R: Send>(work: impl FnOnce() -> R + Send) -> R {
    if rayon::current_thread_index().is_some() {
        work()
    } else {
        rayon::scope(|_| work())
    }
}

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

const W0: f64 = 1.0 / 3.0;
const W1: f64 = 1.0 / 18.0;
const W2: f64 = 1.0 / 36.0;

/// The D3Q19 lattice weights.
pub const WEIGHTS: [f64; Q] = [
    W0, W1, W1, W1, W1, W1, W1, W2, W2, W2, W2, W2, W2, W2, W2, W2, W2, W2, W2,
];

/// Index of the opposite velocity, `c_{OPPOSITE[q]} = −c_q`.
pub const OPPOSITE: [usize; Q] = [
    0, 2, 1, 4, 3, 6, 5, 8, 7, 10, 9, 12, 11, 14, 13, 16, 15, 18, 17,
];

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

/// What bounds the lattice in z.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ZBoundary {
    /// Periodic in z, node plane `k` at height `z = k`.
    Periodic,
    /// Halfway bounce-back walls at `z = 0` (velocity `bottom`) and `z = nz` (velocity `top`);
    /// node plane `k` at height `z = k + ½`.
    Walls {
        /// Velocity of the wall below the plane `k = 0`, in lattice units.
        bottom: [f64; 3],
        /// Velocity of the wall above the plane `k = nz − 1`, in lattice units.
        top: [f64; 3],
    },
}

/// Size and boundaries of a lattice: what the immersed-boundary kernel needs to place nodes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LatticeGeometry {
    /// Nodes along x (periodic).
    pub nx: usize,
    /// Nodes along y (periodic).
    pub ny: usize,
    /// Nodes along z.
    pub nz: usize,
    /// The z boundary.
    pub z_boundary: ZBoundary,
}

impl LatticeGeometry {
    /// Number of nodes.
    pub fn nodes(&self) -> usize {
        self.nx * self.ny * self.nz
    }

    /// Height of node plane 0: ½ between walls (the wall is at z = 0), 0 when periodic.
    pub fn z_offset(&self) -> f64 {
        match self.z_boundary {
            ZBoundary::Periodic => 0.0,
            ZBoundary::Walls { .. } => 0.5,
        }
    }

    /// Node index of `(x, y, z)`.
    #[inline]
    pub fn node(&self, x: usize, y: usize, z: usize) -> usize {
        (z * self.ny + y) * self.nx + x
    }

    /// True when z is periodic.
    pub fn z_periodic(&self) -> bool {
        matches!(self.z_boundary, ZBoundary::Periodic)
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

/// Read-only node fields and boundary data of one sweep.
struct Fields<'a> {
    fx: &'a [f64],
    fy: &'a [f64],
    fz: &'a [f64],
    omega: &'a [f64],
    default_omega: f64,
    row_forced: &'a [bool],
    row_special_omega: &'a [u32],
    geometry: LatticeGeometry,
    row_links: &'a [RowLinks],
    stride: usize,
}

/// One even or odd AA step over every row of `f`.
fn sweep<S: Stored>(fields: &Fields, f: &mut [S], odd: bool, parallel: bool, simd: Simd) {
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
        let shared = SharedBuffer {
            ptr: f.as_mut_ptr(),
            len: f.len(),
        };
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

/// Slots whose runs are read (odd-step gather) or written (odd-step scatter) with an x shift:
/// `(slot, c_x)`.
const SHIFTED_SLOTS: [(usize, i32); 10] = [
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

/// After an even step: the ghost an odd-step gather of slot p reads past the run's end (p moves
/// in +x: the right ghost stands for x = 0; in −x: the left ghost for x = nx − 1).
#[inline]
fn fill_ghosts<S: Stored>(row: &mut [S], nx: usize, stride: usize) {
    for (p, cx) in SHIFTED_SLOTS {
        let run = p * stride;
        if cx > 0 {
            row[run + nx + 1] = row[run + 1];
        } else {
            row[run] = row[run + nx];
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

/// The population buffer shared by the threads of an odd step. Sound because every slot is
/// read and written by exactly one node (see the module docs), and only through raw pointers.
struct SharedBuffer<S> {
    ptr: *mut S,
    len: usize,
}

// SAFETY: the threads of an odd step access disjoint slots (module docs), so sharing the
// pointer is race-free.
unsafe impl<S: Send> Sync for SharedBuffer<S> {}

/// One link of an odd step: the start of a slot run (its left ghost), the x shift
/// (`x_source = x − shift`, `x_target = x + shift`) and an additive wall term.
#[derive(Debug, Clone, Copy)]
struct Link {
    run: usize,
    shift: i64,
    add: f64,
}

/// Where the nodes of a row gather their 19 populations from and scatter them to in an odd
/// step.
#[derive(Debug, Clone, Copy)]
struct RowLinks {
    from: [Link; Q],
    to: [Link; Q],
}

fn row_links(g: &LatticeGeometry, stride: usize, wall_terms: &[[f64; Q]; 2], r: usize) -> RowLinks {
    let (y, z) = (r % g.ny, r / g.ny);
    let walls = !g.z_periodic();
    let from = std::array::from_fn(|q| {
        let c = VELOCITIES[q];
        let zs = z as i64 - c[2] as i64;
        if walls && (zs < 0 || zs >= g.nz as i64) {
            // Reflected by the wall: the node's own f*_q̄, kept in its slot q.
            Link {
                run: (r * Q + q) * stride,
                shift: 0,
                add: wall_terms[usize::from(zs >= 0)][q],
            }
        } else {
            let row = wrap(zs, g.nz) * g.ny + wrap(y as i64 - c[1] as i64, g.ny);
            Link {
                run: (row * Q + OPPOSITE[q]) * stride,
                shift: c[0] as i64,
                add: 0.0,
            }
        }
    });
    let to = std::array::from_fn(|q| {
        let c = VELOCITIES[q];
        let zd = z as i64 + c[2] as i64;
        if walls && (zd < 0 || zd >= g.nz as i64) {
            // Leaving through a wall: comes back as q̄ at this node.
            let p = OPPOSITE[q];
            Link {
                run: (r * Q + p) * stride,
                shift: 0,
                add: wall_terms[usize::from(zd >= 0)][p],
            }
        } else {
            let row = wrap(zd, g.nz) * g.ny + wrap(y as i64 + c[1] as i64, g.ny);
            Link {
                run: (row * Q + q) * stride,
                shift: c[0] as i64,
                add: 0.0,
            }
        }
    });
    RowLinks { from, to }
}

/// `i` wrapped into `0..n` for `−n ≤ i < 2n` (no division).
#[inline(always)]
fn wrap(i: i64, n: usize) -> usize {
    let n = n as i64;
    (if i < 0 {
        i + n
    } else if i >= n {
        i - n
    } else {
        i
    }) as usize
}

/// Even step of one row, in place: collide and write into the opposite slots.
fn even_row<S: Stored>(fields: &Fields, r: usize, row: &mut [S], simd: Simd) {
    match simd {
        #[cfg(all(target_arch = "x86_64", iuq_avx512))]
        // SAFETY: `Simd::Avx512` is only chosen when the CPU reports AVX-512F.
        Simd::Avx512 => unsafe { x86::avx512::even_row(fields, r, row) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Simd::Avx2` is only chosen when the CPU reports AVX2 and FMA.
        Simd::Avx2 => unsafe { x86::even_row_avx2(fields, r, row) },
        Simd::Scalar => even_row_with::<f64, S>(fields, r, row),
    }
}

/// Odd step of one row: gather from the neighbours, collide, scatter to the neighbours.
fn odd_row<S: Stored>(fields: &Fields, f: &SharedBuffer<S>, r: usize, simd: Simd) {
    match simd {
        #[cfg(all(target_arch = "x86_64", iuq_avx512))]
        // SAFETY: `Simd::Avx512` is only chosen when the CPU reports AVX-512F.
        Simd::Avx512 => unsafe { x86::avx512::odd_row(fields, f, r) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Simd::Avx2` is only chosen when the CPU reports AVX2 and FMA.
        Simd::Avx2 => unsafe { x86::odd_row_avx2(fields, f, r) },
        Simd::Scalar => odd_row_with::<f64, S>(fields, f, r),
    }
}

/// A node field (force component, relaxation rate) for the nodes `x0 …` of the row starting at
/// node `node0` (a function rather than a closure, so that it is compiled with the kernel's
/// instruction set).
#[inline(always)]
fn node_field<V: Vector>(field: &[f64], node0: usize, x0: usize, nx: usize, full: bool) -> V {
    if full {
        V::load(&field[node0 + x0..])
    } else {
        V::gather(|l| field[node0 + (x0 + l).min(nx - 1)])
    }
}

/// The collision of the pack of nodes `x0 …` of row `r`.
#[inline(always)]
fn collide_pack<V: Vector>(fields: &Fields, r: usize, x0: usize, f: &[V; Q], full: bool) -> [V; Q] {
    let nx = fields.geometry.nx;
    let node0 = r * nx;
    if !fields.row_forced[r] && fields.row_special_omega[r] == 0 {
        collide_unforced(f, V::splat(fields.default_omega))
    } else {
        collide(
            f,
            [
                node_field(fields.fx, node0, x0, nx, full),
                node_field(fields.fy, node0, x0, nx, full),
                node_field(fields.fz, node0, x0, nx, full),
            ],
            node_field(fields.omega, node0, x0, nx, full),
        )
    }
}

/// Load the pack `x0 …` of a run of `nx` values (lanes past the row's end repeat its last node;
/// they are never stored).
#[inline(always)]
fn load_run<V: Vector, S: Stored>(run: &[S], x0: usize, nx: usize, full: bool) -> V {
    if full {
        S::load::<V>(&run[x0..])
    } else {
        V::gather(|l| run[(x0 + l).min(nx - 1)].to_f64())
    }
}

#[inline(always)]
fn even_row_with<V: Vector, S: Stored>(fields: &Fields, r: usize, row: &mut [S]) {
    let nx = fields.geometry.nx;
    let stride = fields.stride;
    let mut x0 = 0;
    while x0 < nx {
        let width = V::LANES.min(nx - x0);
        let full = width == V::LANES;
        macro_rules! load_all {
            ($($q:literal)*) => {
                [$(load_run::<V, S>(&row[$q * stride + 1..$q * stride + 1 + nx], x0, nx, full)),*]
            };
        }
        let f: [V; Q] = load_all!(0 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18);
        let post = collide_pack(fields, r, x0, &f, full);
        for (q, p) in post.into_iter().enumerate() {
            S::store(p, &mut row[OPPOSITE[q] * stride + 1 + x0..], width);
        }
        x0 += V::LANES;
    }
    fill_ghosts(row, nx, stride);
}

/// How many rows ahead the odd step prefetches its gather runs.
const PREFETCH_ROWS: usize = 2;

/// Gather the pack `x0 …` of direction `link` in an odd step.
///
/// # Safety
/// `f` must be the buffer the links were built for, and no other thread may touch the slots
/// these nodes gather (guaranteed by the AA pattern).
#[inline(always)]
unsafe fn gather_pack<V: Vector, S: Stored>(
    f: &SharedBuffer<S>,
    link: &Link,
    x0: usize,
    nx: usize,
    full: bool,
) -> V {
    // x − shift lies in −1..=nx: the ghosts (run + 0 and run + nx + 1) hold the periodic
    // neighbours.
    let start = (link.run as i64 + 1 + x0 as i64 - link.shift) as usize;
    let v = if full {
        debug_assert!(start + V::LANES <= f.len);
        // SAFETY: the LANES slots lie in the buffer and are read only by these nodes.
        unsafe { S::load_ptr::<V>(f.ptr.add(start)) }
    } else {
        V::gather(|l| {
            // Lanes past the row's end repeat its last node; they are never stored.
            let i = start + l.min(nx - 1 - x0);
            debug_assert!(i < f.len);
            // SAFETY: in bounds, and read only by this node.
            unsafe { (*f.ptr.add(i)).to_f64() }
        })
    };
    if link.add != 0.0 {
        v + V::splat(link.add)
    } else {
        v
    }
}

#[inline(always)]
fn odd_row_with<V: Vector, S: Stored>(fields: &Fields, f: &SharedBuffer<S>, r: usize) {
    let nx = fields.geometry.nx;
    let links = &fields.row_links[r];
    if let Some(ahead) = fields.row_links.get(r + PREFETCH_ROWS) {
        let line = 64 / std::mem::size_of::<S>();
        for link in &ahead.from {
            for x in (0..nx + 2).step_by(line).chain([nx + 1]) {
                debug_assert!(link.run + x < f.len);
                // SAFETY: the index lies inside the buffer; a prefetch reads nothing.
                V::prefetch(unsafe { f.ptr.add(link.run + x) });
            }
        }
    }
    let mut x0 = 0;
    while x0 < nx {
        let width = V::LANES.min(nx - x0);
        let full = width == V::LANES;
        macro_rules! gather_all {
            ($($q:literal)*) => {
                // SAFETY: the links belong to `f`; the AA pattern keeps other threads away.
                [$(unsafe { gather_pack::<V, S>(f, &links.from[$q], x0, nx, full) }),*]
            };
        }
        let f_in: [V; Q] = gather_all!(0 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18);
        let post = collide_pack(fields, r, x0, &f_in, full);
        for (q, p) in post.into_iter().enumerate() {
            let link = links.to[q];
            let p = if link.add != 0.0 {
                p + V::splat(link.add)
            } else {
                p
            };
            // x + shift lies in −1..=nx: writes past the run's ends go to the ghosts, which
            // the fold pass moves onto the periodic neighbour.
            let start = (link.run as i64 + 1 + x0 as i64 + link.shift) as usize;
            if full {
                debug_assert!(start + V::LANES <= f.len);
                // SAFETY: the LANES slots lie in the buffer and are written only by these
                // nodes.
                unsafe { S::store_ptr::<V>(p, f.ptr.add(start)) };
            } else {
                let mut lanes = [0.0; 8];
                p.spill(&mut lanes);
                for (l, &value) in lanes.iter().enumerate().take(width) {
                    debug_assert!(start + l < f.len);
                    // SAFETY: in bounds, and written only by this node.
                    unsafe { *f.ptr.add(start + l) = S::from_f64(value) };
                }
            }
        }
        x0 += V::LANES;
    }
}

/// Density `1 + s`, and momentum, of deviations `δ`.
#[inline(always)]
fn moments<T: Real>(f: &[T; Q]) -> (T, [T; 3]) {
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
fn collide<T: Real>(f: &[T; Q], force: [T; 3], omega: T) -> [T; Q] {
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
fn collide_unforced<T: Real>(f: &[T; Q], omega: T) -> [T; Q] {
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

/// The arithmetic the collision needs, for one value (`f64`) or a SIMD vector of values.
trait Real:
    Copy
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::Div<Output = Self>
    + std::ops::Neg<Output = Self>
{
    fn splat(v: f64) -> Self;
    /// `a·b + c` with a single rounding.
    fn fma(a: Self, b: Self, c: Self) -> Self;
}

impl Real for f64 {
    #[inline(always)]
    fn splat(v: f64) -> Self {
        v
    }
    #[inline(always)]
    fn fma(a: Self, b: Self, c: Self) -> Self {
        a.mul_add(b, c)
    }
}

/// A SIMD vector of `LANES` node values.
trait Vector: Real {
    const LANES: usize;
    /// Load `LANES` values from `s[..LANES]`.
    fn load(s: &[f64]) -> Self;
    /// Load `LANES` single-precision values from `s[..LANES]`, widened.
    fn load_single(s: &[f32]) -> Self;
    /// Build a vector lane by lane.
    fn gather(value: impl Fn(usize) -> f64) -> Self;
    /// Store the first `width` lanes into `out[..width]`.
    fn store(self, out: &mut [f64], width: usize);
    /// Store the first `width` lanes, rounded to single precision, into `out[..width]`.
    fn store_single(self, out: &mut [f32], width: usize);
    /// Copy the lanes into `out[..LANES]`.
    fn spill(self, out: &mut [f64; 8]);
    /// Load `LANES` values from `p`.
    ///
    /// # Safety
    /// `p..p + LANES` must be valid for reads.
    unsafe fn load_ptr(p: *const f64) -> Self;
    /// Load `LANES` single-precision values from `p`, widened.
    ///
    /// # Safety
    /// `p..p + LANES` must be valid for reads.
    unsafe fn load_single_ptr(p: *const f32) -> Self;
    /// Store the lanes at `p`.
    ///
    /// # Safety
    /// `p..p + LANES` must be valid for writes.
    unsafe fn store_ptr(self, p: *mut f64);
    /// Store the lanes, rounded to single precision, at `p`.
    ///
    /// # Safety
    /// `p..p + LANES` must be valid for writes.
    unsafe fn store_single_ptr(self, p: *mut f32);
    /// Hint that the cache line at `p` will be read soon.
    fn prefetch<T>(_p: *const T) {}
}

impl Vector for f64 {
    const LANES: usize = 1;
    #[inline(always)]
    fn load(s: &[f64]) -> Self {
        s[0]
    }
    #[inline(always)]
    fn load_single(s: &[f32]) -> Self {
        s[0] as f64
    }
    #[inline(always)]
    fn gather(value: impl Fn(usize) -> f64) -> Self {
        value(0)
    }
    #[inline(always)]
    fn store(self, out: &mut [f64], _width: usize) {
        out[0] = self;
    }
    #[inline(always)]
    fn store_single(self, out: &mut [f32], _width: usize) {
        out[0] = self as f32;
    }
    #[inline(always)]
    fn spill(self, out: &mut [f64; 8]) {
        out[0] = self;
    }
    #[inline(always)]
    unsafe fn load_ptr(p: *const f64) -> Self {
        // SAFETY: the caller guarantees `p` is valid for reads.
        unsafe { *p }
    }
    #[inline(always)]
    unsafe fn load_single_ptr(p: *const f32) -> Self {
        // SAFETY: the caller guarantees `p` is valid for reads.
        unsafe { *p as f64 }
    }
    #[inline(always)]
    unsafe fn store_ptr(self, p: *mut f64) {
        // SAFETY: the caller guarantees `p` is valid for writes.
        unsafe { *p = self }
    }
    #[inline(always)]
    unsafe fn store_single_ptr(self, p: *mut f32) {
        // SAFETY: the caller guarantees `p` is valid for writes.
        unsafe { *p = self as f32 }
    }
}

/// A stored population format.
trait Stored: Copy + Send + Sync {
    fn to_f64(self) -> f64;
    fn from_f64(v: f64) -> Self;
    fn load<V: Vector>(s: &[Self]) -> V;
    fn store<V: Vector>(v: V, out: &mut [Self], width: usize);
    /// # Safety
    /// `p..p + V::LANES` must be valid for reads.
    unsafe fn load_ptr<V: Vector>(p: *const Self) -> V;
    /// # Safety
    /// `p..p + V::LANES` must be valid for writes.
    unsafe fn store_ptr<V: Vector>(v: V, p: *mut Self);
}

impl Stored for f64 {
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        v
    }
    #[inline(always)]
    unsafe fn load_ptr<V: Vector>(p: *const Self) -> V {
        // SAFETY: forwarded from the caller.
        unsafe { V::load_ptr(p) }
    }
    #[inline(always)]
    unsafe fn store_ptr<V: Vector>(v: V, p: *mut Self) {
        // SAFETY: forwarded from the caller.
        unsafe { v.store_ptr(p) }
    }
    #[inline(always)]
    fn load<V: Vector>(s: &[Self]) -> V {
        V::load(s)
    }
    #[inline(always)]
    fn store<V: Vector>(v: V, out: &mut [Self], width: usize) {
        v.store(out, width)
    }
}

impl Stored for f32 {
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self as f64
    }
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        v as f32
    }
    #[inline(always)]
    unsafe fn load_ptr<V: Vector>(p: *const Self) -> V {
        // SAFETY: forwarded from the caller.
        unsafe { V::load_single_ptr(p) }
    }
    #[inline(always)]
    unsafe fn store_ptr<V: Vector>(v: V, p: *mut Self) {
        // SAFETY: forwarded from the caller.
        unsafe { v.store_single_ptr(p) }
    }
    #[inline(always)]
    fn load<V: Vector>(s: &[Self]) -> V {
        V::load_single(s)
    }
    #[inline(always)]
    fn store<V: Vector>(v: V, out: &mut [Self], width: usize) {
        v.store_single(out, width)
    }
}

/// The instruction set the row kernel is compiled for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Simd {
    #[cfg(all(target_arch = "x86_64", iuq_avx512))]
    Avx512,
    #[cfg(target_arch = "x86_64")]
    Avx2,
    Scalar,
}

impl Simd {
    fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            // A diagnostic override (results are identical on every path).
            let choice = std::env::var("IUQ_RBC_SIMD").unwrap_or_default();
            if choice == "scalar" {
                return Simd::Scalar;
            }
            #[cfg(iuq_avx512)]
            if choice != "avx2" && std::arch::is_x86_feature_detected!("avx512f") {
                return Simd::Avx512;
            }
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                return Simd::Avx2;
            }
        }
        Simd::Scalar
    }

    fn name(self) -> &'static str {
        match self {
            #[cfg(all(target_arch = "x86_64", iuq_avx512))]
            Simd::Avx512 => "avx512f",
            #[cfg(target_arch = "x86_64")]
            Simd::Avx2 => "avx2+fma",
            Simd::Scalar => "scalar",
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    //! AVX2 vectors (4 lanes) and the row kernel compiled for them. (AVX-512 intrinsics need
    //! Rust 1.89, above the workspace's minimum; on the shear box the update is bound by memory,
    //! not by vector width.)
    use super::{Fields, Real, SharedBuffer, Stored, Vector, even_row_with, odd_row_with};
    use std::arch::x86_64::*;

    macro_rules! vector {
        ($name:ident, $t:ty, $lanes:expr, $set1:ident, $add:ident, $sub:ident, $mul:ident,
         $div:ident, $fmadd:ident, $loadu:ident, $storeu:ident, $cvt_up:ident, $loadu_s:ident,
         $cvt_down:ident, $storeu_s:ident) => {
            /// A SIMD register of f64 lanes. Its operations are only reached from the row
            /// kernel compiled for (and dispatched after detecting) the instruction set.
            #[derive(Clone, Copy)]
            pub(super) struct $name($t);
            impl std::ops::Add for $name {
                type Output = Self;
                #[inline(always)]
                fn add(self, o: Self) -> Self {
                    // SAFETY: the instruction set was detected before dispatch.
                    Self(unsafe { $add(self.0, o.0) })
                }
            }
            impl std::ops::Sub for $name {
                type Output = Self;
                #[inline(always)]
                fn sub(self, o: Self) -> Self {
                    // SAFETY: the instruction set was detected before dispatch.
                    Self(unsafe { $sub(self.0, o.0) })
                }
            }
            impl std::ops::Mul for $name {
                type Output = Self;
                #[inline(always)]
                fn mul(self, o: Self) -> Self {
                    // SAFETY: the instruction set was detected before dispatch.
                    Self(unsafe { $mul(self.0, o.0) })
                }
            }
            impl std::ops::Div for $name {
                type Output = Self;
                #[inline(always)]
                fn div(self, o: Self) -> Self {
                    // SAFETY: the instruction set was detected before dispatch.
                    Self(unsafe { $div(self.0, o.0) })
                }
            }
            impl std::ops::Neg for $name {
                type Output = Self;
                #[inline(always)]
                fn neg(self) -> Self {
                    Self::splat(0.0) - self
                }
            }
            impl Real for $name {
                #[inline(always)]
                fn splat(v: f64) -> Self {
                    // SAFETY: the instruction set was detected before dispatch.
                    Self(unsafe { $set1(v) })
                }
                #[inline(always)]
                fn fma(a: Self, b: Self, c: Self) -> Self {
                    // SAFETY: the instruction set was detected before dispatch.
                    Self(unsafe { $fmadd(a.0, b.0, c.0) })
                }
            }
            impl Vector for $name {
                const LANES: usize = $lanes;
                #[inline(always)]
                fn load(s: &[f64]) -> Self {
                    let s = &s[..$lanes];
                    // SAFETY: `s` holds LANES values (the slice is bounds checked).
                    Self(unsafe { $loadu(s.as_ptr()) })
                }
                #[inline(always)]
                fn load_single(s: &[f32]) -> Self {
                    let s = &s[..$lanes];
                    // SAFETY: `s` holds LANES values (the slice is bounds checked).
                    Self(unsafe { $cvt_up($loadu_s(s.as_ptr())) })
                }
                #[inline(always)]
                fn gather(value: impl Fn(usize) -> f64) -> Self {
                    let a: [f64; $lanes] = std::array::from_fn(value);
                    Self::load(&a)
                }
                #[inline(always)]
                fn store(self, out: &mut [f64], width: usize) {
                    if width == $lanes {
                        let out = &mut out[..$lanes];
                        // SAFETY: `out` holds LANES values (the slice is bounds checked).
                        unsafe { $storeu(out.as_mut_ptr(), self.0) };
                    } else {
                        let mut a = [0.0; $lanes];
                        // SAFETY: `a` holds LANES values.
                        unsafe { $storeu(a.as_mut_ptr(), self.0) };
                        out[..width].copy_from_slice(&a[..width]);
                    }
                }
                #[inline(always)]
                fn prefetch<T>(p: *const T) {
                    // SAFETY: a prefetch never faults.
                    unsafe { _mm_prefetch::<_MM_HINT_T0>(p.cast::<i8>()) };
                }
                #[inline(always)]
                fn spill(self, out: &mut [f64; 8]) {
                    // SAFETY: `out` holds at least LANES values; the feature was detected.
                    unsafe { $storeu(out.as_mut_ptr(), self.0) };
                }
                #[inline(always)]
                unsafe fn load_ptr(p: *const f64) -> Self {
                    // SAFETY: forwarded from the caller; the feature was detected.
                    Self(unsafe { $loadu(p) })
                }
                #[inline(always)]
                unsafe fn load_single_ptr(p: *const f32) -> Self {
                    // SAFETY: forwarded from the caller; the feature was detected.
                    Self(unsafe { $cvt_up($loadu_s(p)) })
                }
                #[inline(always)]
                unsafe fn store_ptr(self, p: *mut f64) {
                    // SAFETY: forwarded from the caller; the feature was detected.
                    unsafe { $storeu(p, self.0) }
                }
                #[inline(always)]
                unsafe fn store_single_ptr(self, p: *mut f32) {
                    // SAFETY: forwarded from the caller; the feature was detected.
                    unsafe { $storeu_s(p, $cvt_down(self.0)) }
                }
                #[inline(always)]
                fn store_single(self, out: &mut [f32], width: usize) {
                    // SAFETY: the instruction set was detected before dispatch.
                    let narrow = unsafe { $cvt_down(self.0) };
                    if width == $lanes {
                        let out = &mut out[..$lanes];
                        // SAFETY: `out` holds LANES values (the slice is bounds checked).
                        unsafe { $storeu_s(out.as_mut_ptr(), narrow) };
                    } else {
                        let mut a = [0.0f32; $lanes];
                        // SAFETY: `a` holds LANES values.
                        unsafe { $storeu_s(a.as_mut_ptr(), narrow) };
                        out[..width].copy_from_slice(&a[..width]);
                    }
                }
            }
        };
    }
    vector!(
        Avx2,
        __m256d,
        4,
        _mm256_set1_pd,
        _mm256_add_pd,
        _mm256_sub_pd,
        _mm256_mul_pd,
        _mm256_div_pd,
        _mm256_fmadd_pd,
        _mm256_loadu_pd,
        _mm256_storeu_pd,
        _mm256_cvtps_pd,
        _mm_loadu_ps,
        _mm256_cvtpd_ps,
        _mm_storeu_ps
    );

    /// AVX-512 vectors (8 lanes) and the row kernels compiled for them; built only by compilers
    /// that have the AVX-512 intrinsics (Rust ≥ 1.89, see `build.rs`).
    #[cfg(iuq_avx512)]
    #[allow(clippy::incompatible_msrv)]
    pub(super) mod avx512 {
        use super::super::{
            Fields, Real, SharedBuffer, Stored, Vector, even_row_with, odd_row_with,
        };
        use std::arch::x86_64::*;

        vector!(
            Avx512,
            __m512d,
            8,
            _mm512_set1_pd,
            _mm512_add_pd,
            _mm512_sub_pd,
            _mm512_mul_pd,
            _mm512_div_pd,
            _mm512_fmadd_pd,
            _mm512_loadu_pd,
            _mm512_storeu_pd,
            _mm512_cvtps_pd,
            _mm256_loadu_ps,
            _mm512_cvtpd_ps,
            _mm256_storeu_ps
        );

        /// The even-step row kernel compiled for AVX-512F.
        ///
        /// # Safety
        /// The CPU must support AVX-512F.
        #[target_feature(enable = "avx512f")]
        pub(in super::super) unsafe fn even_row<S: Stored>(
            fields: &Fields,
            r: usize,
            row: &mut [S],
        ) {
            even_row_with::<Avx512, S>(fields, r, row);
        }

        /// The odd-step row kernel compiled for AVX-512F.
        ///
        /// # Safety
        /// The CPU must support AVX-512F.
        #[target_feature(enable = "avx512f")]
        pub(in super::super) unsafe fn odd_row<S: Stored>(
            fields: &Fields,
            f: &SharedBuffer<S>,
            r: usize,
        ) {
            odd_row_with::<Avx512, S>(fields, f, r);
        }
    }

    /// The even-step row kernel compiled for AVX2 and FMA.
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn even_row_avx2<S: Stored>(fields: &Fields, r: usize, row: &mut [S]) {
        even_row_with::<Avx2, S>(fields, r, row);
    }

    /// The odd-step row kernel compiled for AVX2 and FMA.
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn odd_row_avx2<S: Stored>(fields: &Fields, f: &SharedBuffer<S>, r: usize) {
        odd_row_with::<Avx2, S>(fields, f, r);
    }
}

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
    fn pool_work_runs_on_a_worker_thread() {
        assert_eq!(rayon::current_thread_index(), None);
        let (outer, inner) = on_pool_worker(|| {
            let outer = rayon::current_thread_index();
            (outer, on_pool_worker(rayon::current_thread_index))
        });
        assert!(outer.is_some());
        assert_eq!(outer, inner, "nested work stays on its thread");
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
