//! The membrane mesh: a subdivided icosahedron mapped onto the biconcave red-cell shape.
//!
//! The construction follows HemoCell `helper/meshGeneratingFunctions.hh`
//! (`constructSphereIcosahedron`, `spherePointToRBCPoint`): the 12 vertices and 20 faces of the
//! icosahedron, midpoint subdivision with projection onto the unit sphere until there are at
//! least 600 triangles (1280 triangles, 642 vertices, 1920 edges), then the map
//! `z' = sign(z)·√(1−ρ²)·(C0 + C2ρ² + C4ρ⁴)`, `ρ² = x² + y²` (x and y unchanged), scaled by the
//! cell radius. HemoCell rotates the sphere by the Euler angles (π/2, π/2, 0) before the map;
//! that rotation is the cyclic permutation (x, y, z) → (y, z, x), which maps the icosahedron and
//! its subdivisions onto themselves, so it is omitted here. The disk axis is z. HemoCell's later
//! rotations (after the map, and the study's `RBC.pos` angles) turn the mesh by 90° in its disk
//! plane; `protocol::MeshOrientation::Hemocell` applies that turn.

use crate::units::CELL_RADIUS;

/// Coefficients of the biconcave shape map (HemoCell `spherePointToRBCPoint`).
pub const SHAPE_C0: f64 = 0.054322;
/// See [`SHAPE_C0`].
pub const SHAPE_C2: f64 = 1.001279;
/// See [`SHAPE_C0`].
pub const SHAPE_C4: f64 = -0.561381;

/// Minimum number of triangles of the subdivided icosahedron (HemoCell's `minNumOfTriangles`
/// for the RBC: subdivision stops at the first level with at least this many).
pub const MIN_TRIANGLES: usize = 600;

/// A closed, consistently oriented triangle mesh with its connectivity.
#[derive(Debug, Clone, PartialEq)]
pub struct Mesh {
    /// Vertex positions.
    pub vertices: Vec<[f64; 3]>,
    /// Triangles as vertex indices, counter-clockwise seen from outside (outward normals).
    pub triangles: Vec<[usize; 3]>,
    /// Undirected edges, each once, lower index first.
    pub edges: Vec<[usize; 2]>,
    /// One-ring of each vertex, cyclically ordered counter-clockwise about the outward normal:
    /// `ring_offsets[i]..ring_offsets[i+1]` indexes `ring_vertices`.
    pub ring_offsets: Vec<usize>,
    /// Neighbours of all vertices, concatenated (see `ring_offsets`).
    pub ring_vertices: Vec<usize>,
    /// Triangles around each vertex: `ring_offsets[i]..ring_offsets[i+1]` indexes
    /// `ring_triangles` too; `ring_triangles[k]` is the triangle `(i, ring[k], ring[k+1])`.
    pub ring_triangles: Vec<usize>,
}

/// Summary statistics of a mesh (in the mesh's length unit).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshStatistics {
    /// Number of vertices.
    pub vertices: usize,
    /// Number of triangles.
    pub triangles: usize,
    /// Number of edges.
    pub edges: usize,
    /// Mean edge length.
    pub mean_edge: f64,
    /// Total area.
    pub area: f64,
    /// Enclosed volume.
    pub volume: f64,
    /// Largest distance between two vertices.
    pub diameter: f64,
}

impl Mesh {
    /// Build a mesh (connectivity included) from vertices and outward-oriented triangles.
    pub fn from_triangles(vertices: Vec<[f64; 3]>, triangles: Vec<[usize; 3]>) -> Self {
        let n = vertices.len();
        let mut edges: Vec<[usize; 2]> = triangles
            .iter()
            .flat_map(|t| [[t[0], t[1]], [t[1], t[2]], [t[2], t[0]]])
            .map(|[a, b]| [a.min(b), a.max(b)])
            .collect();
        edges.sort_unstable();
        edges.dedup();
        // For each vertex, the directed links a→b of its incident triangles (i, a, b) in
        // counter-clockwise order; chaining them gives the ordered ring.
        let mut links: Vec<Vec<(usize, usize, usize)>> = vec![Vec::new(); n];
        for (index, t) in triangles.iter().enumerate() {
            for k in 0..3 {
                links[t[k]].push((t[(k + 1) % 3], t[(k + 2) % 3], index));
            }
        }
        let mut ring_offsets = Vec::with_capacity(n + 1);
        let mut ring_vertices = Vec::with_capacity(6 * n);
        let mut ring_triangles = Vec::with_capacity(6 * n);
        ring_offsets.push(0);
        for l in &links {
            if let Some(&(first, _, _)) = l.first() {
                let mut current = first;
                for _ in 0..l.len() {
                    match l.iter().find(|(a, _, _)| *a == current) {
                        Some(&(_, b, t)) => {
                            ring_vertices.push(current);
                            ring_triangles.push(t);
                            current = b;
                        }
                        None => break,
                    }
                }
            }
            ring_offsets.push(ring_vertices.len());
        }
        Self {
            vertices,
            triangles,
            edges,
            ring_offsets,
            ring_vertices,
            ring_triangles,
        }
    }

    /// The icosahedron of HemoCell `constructSphereIcosahedron` subdivided until it has at
    /// least `min_triangles` triangles, on the unit sphere.
    pub fn icosphere(min_triangles: usize) -> Self {
        let t = (1.0 + 5f64.sqrt()) / 2.0;
        // HemoCell writes tau = -0.8506508084 and one = -0.5257311121; these are their exact
        // values, t/√(1+t²) and 1/√(1+t²).
        let tau = -t / (1.0 + t * t).sqrt();
        let one = -1.0 / (1.0 + t * t).sqrt();
        let mut vertices = vec![
            [tau, one, 0.0],
            [-tau, one, 0.0],
            [-tau, -one, 0.0],
            [tau, -one, 0.0],
            [one, 0.0, tau],
            [one, 0.0, -tau],
            [-one, 0.0, -tau],
            [-one, 0.0, tau],
            [0.0, tau, one],
            [0.0, -tau, one],
            [0.0, -tau, -one],
            [0.0, tau, -one],
        ];
        // HemoCell's 20 faces (1-based v1..v12 there).
        let faces: [[usize; 3]; 20] = [
            [5, 8, 9],
            [5, 10, 8],
            [6, 12, 7],
            [6, 7, 11],
            [1, 4, 5],
            [1, 6, 4],
            [3, 2, 8],
            [3, 7, 2],
            [9, 12, 1],
            [9, 2, 12],
            [10, 4, 11],
            [10, 11, 3],
            [9, 1, 5],
            [12, 6, 1],
            [5, 4, 10],
            [6, 11, 4],
            [8, 2, 9],
            [7, 12, 2],
            [8, 10, 3],
            [7, 3, 11],
        ];
        let mut triangles: Vec<[usize; 3]> = faces
            .iter()
            .map(|f| [f[0] - 1, f[1] - 1, f[2] - 1])
            .collect();
        while triangles.len() < min_triangles.max(1) {
            let mut midpoints = std::collections::HashMap::new();
            let mut mid = |a: usize, b: usize, vertices: &mut Vec<[f64; 3]>| -> usize {
                *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    let (p, q) = (vertices[a], vertices[b]);
                    let m = [
                        0.5 * (p[0] + q[0]),
                        0.5 * (p[1] + q[1]),
                        0.5 * (p[2] + q[2]),
                    ];
                    vertices.push(scale(m, 1.0 / norm(m)));
                    vertices.len() - 1
                })
            };
            let mut next = Vec::with_capacity(4 * triangles.len());
            for &[a, b, c] in &triangles {
                let d = mid(a, b, &mut vertices);
                let e = mid(b, c, &mut vertices);
                let f = mid(c, a, &mut vertices);
                next.extend([[d, e, f], [a, d, f], [d, b, e], [f, e, c]]);
            }
            triangles = next;
        }
        let mut mesh = Self::from_triangles(vertices, triangles);
        if mesh.volume() < 0.0 {
            for t in &mut mesh.triangles {
                t.swap(1, 2);
            }
            mesh = Self::from_triangles(mesh.vertices, mesh.triangles);
        }
        mesh
    }

    /// HemoCell's red blood cell: the icosphere with at least [`MIN_TRIANGLES`] triangles
    /// mapped onto the biconcave shape of radius `radius`, centred at `centre`, disk axis z.
    pub fn red_blood_cell(radius: f64, centre: [f64; 3]) -> Self {
        let mut mesh = Self::icosphere(MIN_TRIANGLES);
        for v in &mut mesh.vertices {
            let [x, y, z] = biconcave(*v);
            *v = [
                centre[0] + radius * x,
                centre[1] + radius * y,
                centre[2] + radius * z,
            ];
        }
        mesh
    }

    /// HemoCell's red blood cell in lattice units of spacing `dx` (metres), centred at
    /// `centre` (lattice units).
    pub fn red_blood_cell_lu(dx: f64, centre: [f64; 3]) -> Self {
        Self::red_blood_cell(CELL_RADIUS / dx, centre)
    }

    /// The ordered one-ring of vertex `i`.
    #[inline]
    pub fn ring(&self, i: usize) -> &[usize] {
        &self.ring_vertices[self.ring_offsets[i]..self.ring_offsets[i + 1]]
    }

    /// The triangles around vertex `i`, in ring order: the k-th is `(i, ring[k], ring[k+1])`.
    #[inline]
    pub fn ring_triangles(&self, i: usize) -> &[usize] {
        &self.ring_triangles[self.ring_offsets[i]..self.ring_offsets[i + 1]]
    }

    /// Enclosed volume of the mesh at its own vertices.
    pub fn volume(&self) -> f64 {
        volume(&self.triangles, &self.vertices)
    }

    /// Statistics at the mesh's own vertices.
    pub fn statistics(&self) -> MeshStatistics {
        self.statistics_at(&self.vertices)
    }

    /// Statistics of the mesh's connectivity at the given vertex positions.
    pub fn statistics_at(&self, x: &[[f64; 3]]) -> MeshStatistics {
        let mean_edge = self
            .edges
            .iter()
            .map(|&[a, b]| norm(sub(x[b], x[a])))
            .sum::<f64>()
            / self.edges.len().max(1) as f64;
        let area = self
            .triangles
            .iter()
            .map(|&[a, b, c]| 0.5 * norm(cross(sub(x[b], x[a]), sub(x[c], x[a]))))
            .sum();
        let mut diameter: f64 = 0.0;
        for i in 0..x.len() {
            for j in i + 1..x.len() {
                diameter = diameter.max(norm(sub(x[j], x[i])));
            }
        }
        MeshStatistics {
            vertices: x.len(),
            triangles: self.triangles.len(),
            edges: self.edges.len(),
            mean_edge,
            area,
            volume: volume(&self.triangles, x),
            diameter,
        }
    }
}

/// Map a point of the unit sphere onto the biconcave shape of unit radius (HemoCell
/// `spherePointToRBCPoint`; `1 − ρ² < 0` from rounding is clamped as there).
pub fn biconcave(p: [f64; 3]) -> [f64; 3] {
    let r2 = p[0] * p[0] + p[1] * p[1];
    let r2 = if 1.0 - r2 < 0.0 { 1.0 } else { r2 };
    let sign = if p[2] > 0.0 {
        1.0
    } else if p[2] < 0.0 {
        -1.0
    } else {
        0.0
    };
    [
        p[0],
        p[1],
        sign * (1.0 - r2).sqrt() * (SHAPE_C0 + SHAPE_C2 * r2 + SHAPE_C4 * r2 * r2),
    ]
}

/// Signed volume enclosed by outward-oriented triangles, Σ x0·(x1 × x2)/6.
pub fn volume(triangles: &[[usize; 3]], x: &[[f64; 3]]) -> f64 {
    triangles
        .iter()
        .map(|&[a, b, c]| dot(x[a], cross(x[b], x[c])))
        .sum::<f64>()
        / 6.0
}

/// `a − b`.
#[inline(always)]
pub fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `a + b`.
#[inline(always)]
pub fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// `s·a`.
#[inline(always)]
pub fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// `a·b`.
#[inline(always)]
pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `a × b`.
#[inline(always)]
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// `|a|`.
#[inline(always)]
pub fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn icosphere_has_the_counts_of_the_spec() {
        let m = Mesh::icosphere(MIN_TRIANGLES);
        assert_eq!(m.vertices.len(), 642);
        assert_eq!(m.triangles.len(), 1280);
        assert_eq!(m.edges.len(), 1920);
        for v in &m.vertices {
            assert!((norm(*v) - 1.0).abs() < 1e-12);
        }
        // 12 vertices of valence 5, the rest 6; every ring closes.
        let valences: Vec<usize> = (0..642).map(|i| m.ring(i).len()).collect();
        for i in 0..642 {
            let (ring, tris) = (m.ring(i), m.ring_triangles(i));
            assert_eq!(ring.len(), tris.len());
            for k in 0..ring.len() {
                let t = m.triangles[tris[k]];
                let (a, b) = (ring[k], ring[(k + 1) % ring.len()]);
                let pos = t.iter().position(|&v| v == i).unwrap();
                assert_eq!([t[(pos + 1) % 3], t[(pos + 2) % 3]], [a, b]);
            }
        }
        assert_eq!(valences.iter().filter(|&&v| v == 5).count(), 12);
        assert_eq!(valences.iter().filter(|&&v| v == 6).count(), 630);
        assert!(m.volume() > 0.0);
    }

    #[test]
    fn red_blood_cell_mesh_statistics_match_the_spec() {
        // In micrometres: mean edge ≈ 0.500, area ≈ 129, volume ≈ 81, diameter 7.82.
        let m = Mesh::red_blood_cell(3.91, [0.0; 3]);
        let s = m.statistics();
        assert_eq!((s.vertices, s.triangles, s.edges), (642, 1280, 1920));
        assert!((s.mean_edge - 0.500).abs() < 0.01, "{s:?}");
        assert!((s.area - 129.0).abs() < 1.5, "{s:?}");
        assert!((s.volume - 81.0).abs() < 1.5, "{s:?}");
        assert!((s.diameter - 7.82).abs() < 1e-9, "{s:?}");
    }

    #[test]
    fn rings_are_ordered_counter_clockwise_about_the_outward_normal() {
        // On the sphere the outward normal at a vertex is the vertex itself; the shape map
        // scales z by the positive factor C0 + C2ρ² + C4ρ⁴ and so keeps the orientation.
        let m = Mesh::icosphere(MIN_TRIANGLES);
        for i in 0..m.vertices.len() {
            let ring = m.ring(i);
            for k in 0..ring.len() {
                let a = sub(m.vertices[ring[k]], m.vertices[i]);
                let b = sub(m.vertices[ring[(k + 1) % ring.len()]], m.vertices[i]);
                assert!(dot(cross(a, b), m.vertices[i]) > 0.0, "vertex {i}");
            }
        }
    }
}
