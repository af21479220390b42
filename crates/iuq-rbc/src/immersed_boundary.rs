//! Immersed-boundary coupling of the membrane vertices to the fluid nodes.
//!
//! Each vertex interacts with the 8 nodes around it through the 2-point hat kernel
//! `φ(r) = max(1 − |r|, 0)` per axis (HemoCell's `phi2` kernel). The weights are renormalised to
//! sum to one over the nodes that exist (only a vertex within half a spacing of a wall loses
//! nodes; elsewhere the hat weights already sum to one). The same weights spread the vertex
//! forces onto the force field and interpolate the fluid velocity back to the vertices, so the
//! coupling conserves momentum and does no spurious work.

use crate::lattice::{Lattice, LatticeGeometry, ZBoundary};

/// Nodes and weights of one vertex.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Stencil {
    /// Node indices (the first `len` are used).
    pub nodes: [usize; 8],
    /// Weights, summing to one over the first `len` entries.
    pub weights: [f64; 8],
    /// Number of nodes in use (0 when the vertex is outside the fluid).
    pub len: usize,
}

impl Stencil {
    /// The hat-kernel stencil of a point `p` (lattice units; node `(i, j, k)` sits at
    /// `(i, j, k + z_offset)`), x and y periodic, z periodic or bounded by walls.
    pub fn at(geometry: &LatticeGeometry, p: [f64; 3]) -> Self {
        let g = geometry;
        let coords = [p[0], p[1], p[2] - g.z_offset()];
        let sizes = [g.nx, g.ny, g.nz];
        // Per axis: the two node indices (None when beyond a wall) and their hat weights.
        let mut index = [[None; 2]; 3];
        let mut weight = [[0.0; 2]; 3];
        for d in 0..3 {
            let b = floor(coords[d]);
            let frac = coords[d] - b;
            weight[d] = [1.0 - frac, frac];
            let n = sizes[d] as i64;
            let periodic = d < 2 || matches!(g.z_boundary, ZBoundary::Periodic);
            for (k, slot) in index[d].iter_mut().enumerate() {
                let i = b as i64 + k as i64;
                *slot = if (0..n).contains(&i) {
                    Some(i as usize)
                } else if periodic {
                    Some(i.rem_euclid(n) as usize)
                } else {
                    None
                };
            }
        }
        let mut s = Stencil::default();
        let mut total = 0.0;
        for corner in 0..8 {
            let (cx, cy, cz) = (corner & 1, (corner >> 1) & 1, (corner >> 2) & 1);
            let w = weight[0][cx] * weight[1][cy] * weight[2][cz];
            if let (Some(i), Some(j), Some(k)) = (index[0][cx], index[1][cy], index[2][cz]) {
                if w > 0.0 {
                    s.nodes[s.len] = g.node(i, j, k);
                    s.weights[s.len] = w;
                    s.len += 1;
                    total += w;
                }
            }
        }
        if total > 0.0 {
            for w in &mut s.weights[..s.len] {
                *w /= total;
            }
        } else {
            s.len = 0;
        }
        s
    }
}

/// `x.floor()` without a library call (the baseline x86-64 target has no rounding instruction);
/// exact for |x| < 2⁵³.
#[inline(always)]
pub(crate) fn floor(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t > x { t - 1.0 } else { t }
}

/// The stencils of all vertices, the distinct nodes they cover and their velocities.
#[derive(Debug, Clone)]
pub struct ImmersedBoundary {
    stencils: Vec<Stencil>,
    /// For each stencil entry (vertex-major, 8 per vertex), its index in `unique`.
    entry_slot: Vec<u32>,
    /// The distinct nodes of all stencils and their coordinates.
    unique: Vec<[u32; 3]>,
    unique_velocity: Vec<[f64; 3]>,
    /// One bit per lattice node: covered by a stencil of this locate (cleared as it is read).
    covered: Vec<u64>,
    /// Per covered node, its index in `unique`.
    slot_of: Vec<u32>,
}

impl ImmersedBoundary {
    /// Coupling for `vertices` vertices on a lattice of `geometry`.
    pub fn new(vertices: usize, geometry: &LatticeGeometry) -> Self {
        Self {
            stencils: vec![Stencil::default(); vertices],
            entry_slot: vec![0; 8 * vertices],
            unique: Vec::new(),
            unique_velocity: Vec::new(),
            covered: vec![0; geometry.nodes().div_ceil(64)],
            slot_of: vec![0; geometry.nodes()],
        }
    }

    /// Compute the stencils at the vertex positions and the distinct nodes they touch. Returns
    /// the index of the first vertex that has no fluid node around it (it left the channel),
    /// if any.
    pub fn locate(&mut self, geometry: &LatticeGeometry, x: &[[f64; 3]]) -> Option<usize> {
        self.unique.clear();
        let mut outside = None;
        let (mut lowest, mut highest) = (usize::MAX, 0);
        for (i, (s, p)) in self.stencils.iter_mut().zip(x).enumerate() {
            *s = Stencil::at(geometry, *p);
            if s.len == 0 && outside.is_none() {
                outside = Some(i);
            }
            for &node in &s.nodes[..s.len] {
                self.covered[node / 64] |= 1 << (node % 64);
                lowest = lowest.min(node);
                highest = highest.max(node);
            }
        }
        // The distinct nodes in the order of their index, so that gathering their populations
        // walks memory row by row (neighbours in x share cache lines) instead of jumping.
        if lowest <= highest {
            let (nx, ny) = (geometry.nx, geometry.ny);
            for word in lowest / 64..=highest / 64 {
                let mut bits = std::mem::take(&mut self.covered[word]);
                while bits != 0 {
                    let node = 64 * word + bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    self.slot_of[node] = self.unique.len() as u32;
                    self.unique.push([
                        (node % nx) as u32,
                        ((node / nx) % ny) as u32,
                        (node / (nx * ny)) as u32,
                    ]);
                }
            }
        }
        for (i, s) in self.stencils.iter().enumerate() {
            for k in 0..s.len {
                self.entry_slot[8 * i + k] = self.slot_of[s.nodes[k]];
            }
        }
        outside
    }

    /// The stencils of the last [`ImmersedBoundary::locate`].
    pub fn stencils(&self) -> &[Stencil] {
        &self.stencils
    }

    /// Number of distinct fluid nodes the stencils cover.
    pub fn covered_nodes(&self) -> usize {
        self.unique.len()
    }

    /// Add each vertex force, weighted, to the force density of its stencil nodes.
    pub fn spread(&self, forces: &[[f64; 3]], lattice: &mut Lattice) {
        for (s, f) in self.stencils.iter().zip(forces) {
            for k in 0..s.len {
                let w = s.weights[k];
                lattice.add_force(s.nodes[k], [w * f[0], w * f[1], w * f[2]]);
            }
        }
    }

    /// Zero the force density that [`ImmersedBoundary::spread`] left on the stencil nodes of
    /// this locate (the lattice must carry no other force).
    pub fn clear_spread(&self, lattice: &mut Lattice) {
        let g = *lattice.geometry();
        lattice.clear_forces_at(
            self.unique
                .iter()
                .map(|c| c[0] as usize + g.nx * (c[1] as usize + g.ny * c[2] as usize)),
        );
    }

    /// Interpolate the fluid velocity (post-streaming populations plus half the force density
    /// now stored) to every vertex. The velocity of each covered node is computed once, on
    /// rayon's threads when `parallel` (the result does not depend on it).
    pub fn interpolate(&mut self, lattice: &Lattice, velocities: &mut [[f64; 3]], parallel: bool) {
        use rayon::prelude::*;
        self.unique_velocity.resize(self.unique.len(), [0.0; 3]);
        let node = |c: &[u32; 3]| lattice.velocity_at(c[0] as usize, c[1] as usize, c[2] as usize);
        if parallel {
            self.unique_velocity
                .par_iter_mut()
                .zip(self.unique.par_iter())
                .with_min_len(256)
                .for_each(|(v, c)| *v = node(c));
        } else {
            for (v, c) in self.unique_velocity.iter_mut().zip(&self.unique) {
                *v = node(c);
            }
        }
        for (i, (s, v)) in self.stencils.iter().zip(velocities.iter_mut()).enumerate() {
            let mut u = [0.0; 3];
            for k in 0..s.len {
                let n = self.unique_velocity[self.entry_slot[8 * i + k] as usize];
                let w = s.weights[k];
                u[0] += w * n[0];
                u[1] += w * n[1];
                u[2] += w * n[2];
            }
            *v = u;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lattice::Precision;

    #[test]
    fn weights_sum_to_one_and_reproduce_the_point() {
        let walls = ZBoundary::Walls {
            bottom: [0.0; 3],
            top: [0.0; 3],
        };
        let l = Lattice::new(10, 8, 6, walls, 1.0, Precision::Double);
        let g = *l.geometry();
        for p in [
            [3.3, 4.7, 2.2],
            [0.2, 7.9, 3.5],
            [9.6, 0.1, 5.4],
            [5.0, 5.0, 0.3],
        ] {
            let s = Stencil::at(&g, p);
            let total: f64 = s.weights[..s.len].iter().sum();
            assert!((total - 1.0).abs() < 1e-15);
            if (0.5..=5.5).contains(&p[2]) && p[0] < 9.0 && p[1] < 7.0 {
                // Away from the periodic seams and walls the weighted node positions give p.
                let mut c = [0.0; 3];
                for k in 0..s.len {
                    let n = s.nodes[k];
                    let pos = [
                        (n % g.nx) as f64,
                        ((n / g.nx) % g.ny) as f64,
                        (n / (g.nx * g.ny)) as f64 + 0.5,
                    ];
                    for d in 0..3 {
                        c[d] += s.weights[k] * pos[d];
                    }
                }
                for d in 0..3 {
                    assert!((c[d] - p[d]).abs() < 1e-12, "{p:?} {c:?}");
                }
            }
        }
        // Near a wall some nodes drop out and the rest are renormalised.
        let s = Stencil::at(&g, [2.5, 2.5, 0.2]);
        assert_eq!(s.len, 4);
        assert!((s.weights[..4].iter().sum::<f64>() - 1.0).abs() < 1e-15);
        assert_eq!(Stencil::at(&g, [2.5, 2.5, -1.0]).len, 0);
    }

    #[test]
    fn interpolation_of_a_uniform_flow_is_exact() {
        let u0 = [0.013, -0.007, 0.004];
        for precision in [Precision::Single, Precision::Double] {
            let mut l = Lattice::new(12, 10, 8, ZBoundary::Periodic, 0.9, precision);
            l.set_equilibrium(|_, _, _| u0);
            // One step of a uniform flow leaves it uniform (periodic, no force).
            l.step();
            let points: Vec<[f64; 3]> = (0..50)
                .map(|i| {
                    let t = i as f64;
                    [
                        (t * 0.37).rem_euclid(12.0),
                        (t * 0.53 + 1.0).rem_euclid(10.0),
                        (t * 0.29 + 2.0).rem_euclid(8.0),
                    ]
                })
                .collect();
            let mut ibm = ImmersedBoundary::new(points.len(), l.geometry());
            assert_eq!(ibm.locate(l.geometry(), &points), None);
            let mut v = vec![[0.0; 3]; points.len()];
            ibm.interpolate(&l, &mut v, precision == Precision::Double);
            let tolerance = match precision {
                Precision::Double => 1e-15,
                Precision::Single => 1e-8,
            };
            for w in &v {
                for d in 0..3 {
                    assert!((w[d] - u0[d]).abs() < tolerance, "{w:?} {precision:?}");
                }
            }
        }
    }

    #[test]
    fn spreading_conserves_the_total_force() {
        let mut l = Lattice::new(12, 10, 8, ZBoundary::Periodic, 0.9, Precision::Single);
        let x = vec![[3.3, 4.4, 5.5], [11.7, 0.2, 7.9]];
        let f = vec![[1e-3, 2e-3, -3e-3], [-4e-4, 5e-4, 6e-4]];
        let mut ibm = ImmersedBoundary::new(2, l.geometry());
        ibm.locate(l.geometry(), &x);
        ibm.spread(&f, &mut l);
        let mut total = [0.0; 3];
        for n in 0..l.geometry().nodes() {
            let g = l.force(n);
            for d in 0..3 {
                total[d] += g[d];
            }
        }
        for d in 0..3 {
            assert!((total[d] - f[0][d] - f[1][d]).abs() < 1e-15);
        }
        l.clear_forces();
        assert!((0..l.geometry().nodes()).all(|n| l.force(n) == [0.0; 3]));
        // The stencil-only clear leaves the same empty field.
        ibm.spread(&f, &mut l);
        assert!((0..l.geometry().nodes()).any(|n| l.force(n) != [0.0; 3]));
        ibm.clear_spread(&mut l);
        assert!((0..l.geometry().nodes()).all(|n| l.force(n) == [0.0; 3]));
    }
}
