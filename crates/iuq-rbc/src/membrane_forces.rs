//! HemoCell's high-order red-cell membrane forces (`mechanics/rbcHighOrderModel.cpp`), in
//! lattice units.
//!
//! With the reference state of the undeformed mesh (rest length per edge, rest area per
//! triangle, volume, bending height per vertex, mean edge length L̄):
//! 1. link, per edge i–j: `ε = (ℓ − L0)/L0`, `F = k_link·(ε + ε/|9 − ε²|)` along the unit edge
//!    vector, `+F` on i (towards j), `−F` on j;
//! 2. local area, per triangle: `α = (A − A0)/A0`, `f = k_area·(α + α/|0.09 − α²|)`, each
//!    corner v gets `f·(centroid − x_v)`;
//! 3. volume: `ν = (V − V0)/V0`, `f_V = −k_vol·ν/|0.01 − ν²|`, each triangle adds
//!    `f_V·n̂_t·(A_t/Ā)` to its three corners (Ā the mean rest triangle area,
//!    `cellConstants.area_mean_eq`);
//! 4. bending ("umbrella"), per vertex i with its ordered ring: `d = c − x_i` (c the mean of
//!    the ring), `N = normalize(Σ_j normalize((x_j − x_i) × (x_{j+1} − x_i)))`, `h = N·d`,
//!    `δ = (h − h0)/L̄`, `F = k_bend·(δ + δ/|0.055 − δ²|)·N`, `+F` on i and `−F/n` on each of
//!    its n neighbours;
//! 5. the total force on each vertex is capped at 50 pN.
//!
//! The denominators are absolute values, as in HemoCell: a strain past a singularity still
//! meets a restoring force, whose magnitude falls as the strain grows, and the 50 pN cap bounds
//! it near the singularity, so the run carries on ([`PastSingularity::CarryOn`], the default).
//! [`PastSingularity::Fail`] instead reports a strain at or beyond a singularity as
//! [`RbcError::MeshBroken`], for users who want to discard such runs.
//!
//! Every term's net force vanishes exactly. The link, area and volume terms also have zero net
//! torque; the umbrella bending term does not (its force on i is along N while the reactions sit
//! at the ring, whose centre is off the normal line by the in-plane part of d): its torque is
//! `−Σ_i d_⊥,i × F_i`. This is HemoCell's model, reproduced as it is.

use crate::error::{RbcError, Result};
use crate::mesh::{Mesh, add, cross, dot, norm, scale, sub};
use crate::units::{
    LatticeUnits, MESH_EQUILIBRIUM_LENGTH, SPECTRIN_PERSISTENCE_LENGTH, VERTEX_FORCE_CAP,
};

/// Link strain at which the link force is singular: `|ε| = 3` (300 % stretch).
pub const LINK_SINGULAR_STRAIN_SQ: f64 = 9.0;
/// Squared relative area change at which the area force is singular (`|α| = 0.3`).
pub const AREA_SINGULAR_SQ: f64 = 0.09;
/// Squared relative volume change at which the volume force is singular (`|ν| = 0.1`).
pub const VOLUME_SINGULAR_SQ: f64 = 0.01;
/// Squared bending deviation at which the bending force is singular (`|δ| = √0.055`).
pub const BENDING_SINGULAR_SQ: f64 = 0.055;

/// Membrane material parameters in HemoCell's configuration units (multiples of kBT).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MembraneParameters {
    /// Link (spectrin) force coefficient `kLink`.
    pub k_link: f64,
    /// Bending coefficient `kBend`.
    pub k_bend: f64,
    /// Local area coefficient `kArea`.
    pub k_area: f64,
    /// Volume coefficient `kVolume`.
    pub k_volume: f64,
}

impl Default for MembraneParameters {
    /// HemoCell's defaults: kLink = 15, kBend = 80, kArea = 5, kVolume = 20.
    fn default() -> Self {
        Self {
            k_link: 15.0,
            k_bend: 80.0,
            k_area: 5.0,
            k_volume: 20.0,
        }
    }
}

impl MembraneParameters {
    /// Check that every coefficient is finite, `kLink` positive and the others non-negative.
    pub fn validate(&self) -> Result<()> {
        for (name, v, positive) in [
            ("kLink", self.k_link, true),
            ("kBend", self.k_bend, false),
            ("kArea", self.k_area, false),
            ("kVolume", self.k_volume, false),
        ] {
            if !v.is_finite() || v < 0.0 || (positive && v == 0.0) {
                return Err(RbcError::invalid(
                    name,
                    v,
                    if positive {
                        "must be a positive finite number"
                    } else {
                        "must be a non-negative finite number"
                    },
                ));
            }
        }
        Ok(())
    }
}

/// The force coefficients and the vertex force cap, in lattice units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceCoefficients {
    /// `k_link = kLink·kBT_LU/(7.5 nm/dx)`.
    pub k_link: f64,
    /// `k_bend = kBend·kBT_LU/(0.5 µm/dx)`.
    pub k_bend: f64,
    /// `k_area = kArea·(1280/N_tri)·kBT_LU/(0.5 µm/dx)`.
    pub k_area: f64,
    /// `k_vol = kVolume·(1280/N_tri)·kBT_LU/(0.5 µm/dx)`.
    pub k_volume: f64,
    /// The cap on the total force of one vertex, 50 pN.
    pub force_cap: f64,
}

impl ForceCoefficients {
    /// HemoCell's coefficients (`RbcHighOrderModel::calculate_k*` of HemoCell v2.x) for a mesh of `triangles` triangles in the units `units`.
    pub fn hemocell(p: &MembraneParameters, units: &LatticeUnits, triangles: usize) -> Self {
        let kbt = units.kbt_lu();
        let eq = MESH_EQUILIBRIUM_LENGTH / units.dx;
        let density = 1280.0 / triangles.max(1) as f64;
        Self {
            k_link: p.k_link * kbt / (SPECTRIN_PERSISTENCE_LENGTH / units.dx),
            k_bend: p.k_bend * kbt / eq,
            k_area: p.k_area * density * kbt / eq,
            k_volume: p.k_volume * density * kbt / eq,
            force_cap: units.force_lu(VERTEX_FORCE_CAP),
        }
    }

    /// Every force-like constant, the cap included, multiplied by `factor`.
    pub fn scaled(&self, factor: f64) -> Self {
        Self {
            k_link: self.k_link * factor,
            k_bend: self.k_bend * factor,
            k_area: self.k_area * factor,
            k_volume: self.k_volume * factor,
            force_cap: self.force_cap * factor,
        }
    }
}

/// The stress-free reference state: the initial mesh itself.
#[derive(Debug, Clone, PartialEq)]
pub struct ReferenceState {
    /// Rest length of each edge (`Mesh::edges` order).
    pub edge_length: Vec<f64>,
    /// Rest area of each triangle.
    pub triangle_area: Vec<f64>,
    /// Mean rest triangle area Ā.
    pub mean_triangle_area: f64,
    /// Rest volume V0.
    pub volume: f64,
    /// Rest bending height h0 of each vertex.
    pub patch_height: Vec<f64>,
    /// Mean rest edge length L̄.
    pub mean_edge: f64,
}

impl ReferenceState {
    /// The reference state of `mesh` at positions `x`.
    pub fn new(mesh: &Mesh, x: &[[f64; 3]]) -> Self {
        let edge_length: Vec<f64> = mesh
            .edges
            .iter()
            .map(|&[a, b]| norm(sub(x[b], x[a])))
            .collect();
        let triangle_area: Vec<f64> = mesh
            .triangles
            .iter()
            .map(|&[a, b, c]| 0.5 * norm(cross(sub(x[b], x[a]), sub(x[c], x[a]))))
            .collect();
        let mean_edge = edge_length.iter().sum::<f64>() / edge_length.len().max(1) as f64;
        let mean_triangle_area =
            triangle_area.iter().sum::<f64>() / triangle_area.len().max(1) as f64;
        let mut areas = vec![0.0; mesh.triangles.len()];
        let mut normals = vec![[0.0; 3]; mesh.triangles.len()];
        triangle_geometry(mesh, x, &mut areas, &mut normals);
        let patch_height = (0..x.len())
            .map(|i| umbrella(mesh, x, &normals, i).1)
            .collect();
        Self {
            edge_length,
            triangle_area,
            mean_triangle_area,
            volume: crate::mesh::volume(&mesh.triangles, x),
            patch_height,
            mean_edge,
        }
    }
}

/// Area and unit outward normal of every triangle at positions `x`.
fn triangle_geometry(mesh: &Mesh, x: &[[f64; 3]], areas: &mut [f64], normals: &mut [[f64; 3]]) {
    for (k, &[a, b, c]) in mesh.triangles.iter().enumerate() {
        let n = cross(sub(x[b], x[a]), sub(x[c], x[a]));
        let twice = norm(n);
        areas[k] = 0.5 * twice;
        normals[k] = scale(n, 1.0 / twice);
    }
}

/// The umbrella normal `N = normalize(Σ_j normalize((x_j − x_i) × (x_{j+1} − x_i)))` and height
/// `h = N·(c − x_i)` of vertex `i`. The cross product of consecutive ring vectors is the
/// normal of triangle (i, j, j+1), so the sum runs over the unit normals of the triangles
/// around i (`normals`, computed once per step) instead of recomputing them at each corner.
#[inline]
fn umbrella(mesh: &Mesh, x: &[[f64; 3]], normals: &[[f64; 3]], i: usize) -> ([f64; 3], f64) {
    let ring = mesh.ring(i);
    let mut centre = [0.0; 3];
    let mut normal = [0.0; 3];
    for (&j, &t) in ring.iter().zip(mesh.ring_triangles(i)) {
        centre = add(centre, x[j]);
        normal = add(normal, normals[t]);
    }
    let centre = scale(centre, 1.0 / ring.len() as f64);
    let normal = scale(normal, 1.0 / norm(normal));
    (normal, dot(normal, sub(centre, x[i])))
}

/// What a strain at or beyond a singularity of its force law means.
///
/// The force laws `x + x/|s − x²|` are singular at `x² = s`. HemoCell divides by the absolute
/// value and carries on (`mechanics/rbcHighOrderModel.cpp`, e.g. `k_link * (edge_frac +
/// edge_frac/std::fabs(9.0-edge_frac*edge_frac))`, unconditionally), and caps each vertex's
/// total force at `FORCE_LIMIT` = 50 pN (`config/constant_defaults.h` defines it unless the
/// build overrides it; `HemoCellParticleField::spreadParticleForce` applies it): past the
/// singularity the force still restores, with a magnitude that falls as the strain grows, and
/// the cap bounds it near the singularity. That is the default here; `Fail` takes reaching a
/// singularity as a broken mesh instead.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PastSingularity {
    /// The run fails with [`RbcError::MeshBroken`].
    Fail,
    /// The forces are evaluated as HemoCell does; only non-finite values and shapes without an
    /// ellipse fail.
    #[default]
    CarryOn,
}

impl PastSingularity {
    /// Both policies.
    pub const ALL: [PastSingularity; 2] = [Self::CarryOn, Self::Fail];

    /// The name used in study files and on the command line (`fail`, `carry-on`).
    pub fn name(&self) -> &'static str {
        match self {
            Self::Fail => "fail",
            Self::CarryOn => "carry-on",
        }
    }

    /// The policy called `name` (see [`PastSingularity::name`]).
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "fail" => Some(Self::Fail),
            "carry-on" => Some(Self::CarryOn),
            _ => None,
        }
    }
}

/// Which force terms to evaluate (all by default); the tests look at them one by one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ForceTerms {
    /// Link forces.
    pub link: bool,
    /// Local area forces.
    pub area: bool,
    /// Volume forces.
    pub volume: bool,
    /// Bending forces.
    pub bending: bool,
    /// The per-vertex force cap.
    pub cap: bool,
    /// Whether a strain past a singularity carries on (the default) or breaks the mesh.
    pub past_singularity: PastSingularity,
}

impl Default for ForceTerms {
    fn default() -> Self {
        Self {
            link: true,
            area: true,
            volume: true,
            bending: true,
            cap: true,
            past_singularity: PastSingularity::default(),
        }
    }
}

/// Extremes of the strains at one evaluation, for diagnostics.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StrainSummary {
    /// Largest |ε| over the edges.
    pub max_link_strain: f64,
    /// Largest |α| over the triangles.
    pub max_area_strain: f64,
    /// Relative volume change ν.
    pub volume_strain: f64,
    /// Largest |δ| over the vertices.
    pub max_bending_deviation: f64,
    /// Number of vertices whose force was capped.
    pub capped_vertices: usize,
}

/// Evaluates the membrane forces; holds the per-triangle scratch so that a step allocates
/// nothing.
#[derive(Debug, Clone)]
pub struct MembraneForces {
    coefficients: ForceCoefficients,
    terms: ForceTerms,
    areas: Vec<f64>,
    normals: Vec<[f64; 3]>,
}

impl MembraneForces {
    /// Forces with the given coefficients, all terms on.
    pub fn new(coefficients: ForceCoefficients) -> Self {
        Self {
            coefficients,
            terms: ForceTerms::default(),
            areas: Vec::new(),
            normals: Vec::new(),
        }
    }

    /// The same with only the selected terms.
    pub fn with_terms(mut self, terms: ForceTerms) -> Self {
        self.terms = terms;
        self
    }

    /// Select the terms from now on.
    pub fn set_terms(&mut self, terms: ForceTerms) {
        self.terms = terms;
    }

    /// The coefficients in use.
    pub fn coefficients(&self) -> &ForceCoefficients {
        &self.coefficients
    }

    /// Overwrite `forces` with the membrane force on each vertex at positions `x`.
    ///
    /// Fails with [`RbcError::NonFinite`] for a non-finite position and with
    /// [`RbcError::MeshBroken`] when a strain reaches a singularity of its force law; `step`
    /// only labels the error.
    pub fn compute(
        &mut self,
        mesh: &Mesh,
        reference: &ReferenceState,
        x: &[[f64; 3]],
        forces: &mut [[f64; 3]],
        step: u64,
    ) -> Result<StrainSummary> {
        let c = self.coefficients;
        let t = self.terms;
        let mut summary = StrainSummary::default();
        forces.fill([0.0; 3]);
        if x.iter()
            .any(|p| !(p[0].is_finite() && p[1].is_finite() && p[2].is_finite()))
        {
            return Err(RbcError::NonFinite {
                step,
                what: "vertex position".into(),
            });
        }
        let broken = |reason: String| RbcError::MeshBroken { step, reason };
        let fail_at_singularity = t.past_singularity == PastSingularity::Fail;

        if t.link {
            for (e, &[a, b]) in mesh.edges.iter().enumerate() {
                let v = sub(x[b], x[a]);
                let len = norm(v);
                let l0 = reference.edge_length[e];
                let eps = (len - l0) / l0;
                let eps2 = eps * eps;
                summary.max_link_strain = summary.max_link_strain.max(eps.abs());
                if fail_at_singularity && eps2 >= LINK_SINGULAR_STRAIN_SQ {
                    return Err(broken(format!(
                        "edge {a}-{b} strain {eps:.3} beyond the link singularity |ε| = 3"
                    )));
                }
                let f = c.k_link * (eps + eps / (LINK_SINGULAR_STRAIN_SQ - eps2).abs());
                let fv = scale(v, f / len);
                forces[a] = add(forces[a], fv);
                forces[b] = sub(forces[b], fv);
            }
        }

        self.areas.resize(mesh.triangles.len(), 0.0);
        self.normals.resize(mesh.triangles.len(), [0.0; 3]);
        triangle_geometry(mesh, x, &mut self.areas, &mut self.normals);
        if t.area {
            for (k, &[a, b, cc]) in mesh.triangles.iter().enumerate() {
                let a0 = reference.triangle_area[k];
                let alpha = (self.areas[k] - a0) / a0;
                let alpha2 = alpha * alpha;
                summary.max_area_strain = summary.max_area_strain.max(alpha.abs());
                if fail_at_singularity && alpha2 >= AREA_SINGULAR_SQ {
                    return Err(broken(format!(
                        "triangle {k} area change {alpha:.3} beyond the area singularity |α| = 0.3"
                    )));
                }
                let f = c.k_area * (alpha + alpha / (AREA_SINGULAR_SQ - alpha2).abs());
                let (p0, p1, p2) = (x[a], x[b], x[cc]);
                let centroid = scale(add(add(p0, p1), p2), 1.0 / 3.0);
                forces[a] = add(forces[a], scale(sub(centroid, p0), f));
                forces[b] = add(forces[b], scale(sub(centroid, p1), f));
                forces[cc] = add(forces[cc], scale(sub(centroid, p2), f));
            }
        }
        let volume6: f64 = mesh
            .triangles
            .iter()
            .map(|&[a, b, cc]| dot(x[a], cross(x[b], x[cc])))
            .sum();
        let nu = (volume6 / 6.0 - reference.volume) / reference.volume;
        summary.volume_strain = nu;
        if t.volume {
            let nu2 = nu * nu;
            if fail_at_singularity && nu2 >= VOLUME_SINGULAR_SQ {
                return Err(broken(format!(
                    "volume change {nu:.3} beyond the volume singularity |ν| = 0.1"
                )));
            }
            let fv = -c.k_volume * nu / (VOLUME_SINGULAR_SQ - nu2).abs();
            let per_area = fv / reference.mean_triangle_area;
            for (k, &[a, b, cc]) in mesh.triangles.iter().enumerate() {
                let f = scale(self.normals[k], per_area * self.areas[k]);
                forces[a] = add(forces[a], f);
                forces[b] = add(forces[b], f);
                forces[cc] = add(forces[cc], f);
            }
        }

        if t.bending {
            for i in 0..x.len() {
                let (normal, h) = umbrella(mesh, x, &self.normals, i);
                let delta = (h - reference.patch_height[i]) / reference.mean_edge;
                let delta2 = delta * delta;
                summary.max_bending_deviation = summary.max_bending_deviation.max(delta.abs());
                if fail_at_singularity && delta2 >= BENDING_SINGULAR_SQ {
                    return Err(broken(format!(
                        "vertex {i} bending deviation {delta:.3} beyond the bending singularity |δ| = √0.055"
                    )));
                }
                let f = scale(
                    normal,
                    c.k_bend * (delta + delta / (BENDING_SINGULAR_SQ - delta2).abs()),
                );
                forces[i] = add(forces[i], f);
                let ring = mesh.ring(i);
                let reaction = scale(f, -1.0 / ring.len() as f64);
                for &j in ring {
                    forces[j] = add(forces[j], reaction);
                }
            }
        }

        if t.cap {
            for f in forces.iter_mut() {
                let magnitude = norm(*f);
                if magnitude > c.force_cap {
                    *f = scale(*f, c.force_cap / magnitude);
                    summary.capped_vertices += 1;
                }
            }
        }
        if forces
            .iter()
            .any(|f| !(f[0].is_finite() && f[1].is_finite() && f[2].is_finite()))
        {
            return Err(RbcError::NonFinite {
                step,
                what: "membrane force".into(),
            });
        }
        Ok(summary)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cell() -> (Mesh, ReferenceState, ForceCoefficients) {
        let units = LatticeUnits::reference();
        let mesh = Mesh::red_blood_cell_lu(units.dx, [19.0, 19.0, 9.0]);
        let reference = ReferenceState::new(&mesh, &mesh.vertices);
        let p = MembraneParameters {
            k_link: 36.7,
            k_bend: 367.0,
            ..Default::default()
        };
        let c = ForceCoefficients::hemocell(&p, &units, mesh.triangles.len());
        (mesh, reference, c)
    }

    /// A smooth non-affine deformation (stretch, shear, twist and a bump), small enough to
    /// stay well inside every singularity.
    fn deformed(mesh: &Mesh) -> Vec<[f64; 3]> {
        mesh.vertices
            .iter()
            .map(|&[x, y, z]| {
                let (u, v, w) = (x - 19.0, y - 19.0, z - 9.0);
                [
                    19.0 + 1.06 * u + 0.05 * v + 0.02 * (0.7 * v).sin(),
                    19.0 + 0.96 * v + 0.03 * w + 0.01 * u * w,
                    9.0 + 1.02 * w + 0.04 * (0.5 * u).cos() * w,
                ]
            })
            .collect()
    }

    fn total(f: &[[f64; 3]]) -> [f64; 3] {
        f.iter().fold([0.0; 3], |s, v| add(s, *v))
    }

    fn torque(x: &[[f64; 3]], f: &[[f64; 3]]) -> [f64; 3] {
        x.iter()
            .zip(f)
            .fold([0.0; 3], |s, (p, v)| add(s, cross(*p, *v)))
    }

    fn magnitude_sum(f: &[[f64; 3]]) -> f64 {
        f.iter().map(|v| norm(*v)).sum()
    }

    #[test]
    fn hemocell_coefficients_in_lattice_units() {
        let units = LatticeUnits::reference();
        let c = ForceCoefficients::hemocell(&MembraneParameters::default(), &units, 1280);
        let kbt = 4.100531391e-21 / (2.5625e-8 * 0.5e-6);
        assert!((c.k_link - 15.0 * kbt / 0.015).abs() < 1e-15);
        assert!((c.k_bend - 80.0 * kbt).abs() < 1e-15);
        assert!((c.k_area - 5.0 * kbt).abs() < 1e-15);
        assert!((c.k_volume - 20.0 * kbt).abs() < 1e-15);
        assert!((c.force_cap - 50e-12 / 2.5625e-8).abs() < 1e-15);
    }

    #[test]
    fn reference_state_has_zero_forces() {
        let (mesh, reference, c) = cell();
        let mut forces = vec![[1.0; 3]; mesh.vertices.len()];
        let summary = MembraneForces::new(c)
            .compute(&mesh, &reference, &mesh.vertices, &mut forces, 0)
            .unwrap();
        let largest = forces.iter().map(|f| norm(*f)).fold(0.0, f64::max);
        assert!(largest < 1e-12 * c.k_link, "largest {largest}");
        assert_eq!(summary.capped_vertices, 0);
        assert!(summary.max_link_strain < 1e-12);
    }

    #[test]
    fn net_force_and_torque_vanish_for_a_deformed_mesh() {
        let (mesh, reference, c) = cell();
        let x = deformed(&mesh);
        let only = |link, area, volume, bending| ForceTerms {
            link,
            area,
            volume,
            bending,
            cap: false,
            past_singularity: PastSingularity::Fail,
        };
        let mut f = vec![[0.0; 3]; x.len()];
        for (name, terms) in [
            ("link", only(true, false, false, false)),
            ("area", only(false, true, false, false)),
            ("volume", only(false, false, true, false)),
            ("bending", only(false, false, false, true)),
        ] {
            let s = MembraneForces::new(c)
                .with_terms(terms)
                .compute(&mesh, &reference, &x, &mut f, 0)
                .unwrap();
            let scale_f = magnitude_sum(&f);
            assert!(scale_f > 0.0, "{name} produced no force ({s:?})");
            let net = norm(total(&f));
            assert!(
                net < 1e-12 * scale_f,
                "{name}: net force {net} vs {scale_f}"
            );
            // Torque about the centroid (any point, since the net force vanishes).
            let centroid = scale(
                x.iter().fold([0.0; 3], |s, p| add(s, *p)),
                1.0 / x.len() as f64,
            );
            let r: Vec<[f64; 3]> = x.iter().map(|p| sub(*p, centroid)).collect();
            let tq = norm(torque(&r, &f));
            let scale_t: f64 = r.iter().zip(&f).map(|(p, v)| norm(cross(*p, *v))).sum();
            if name == "bending" {
                // HemoCell's umbrella bending force is not torque-free (see the module docs);
                // its net torque stays a small fraction of the vertex torques.
                // (0.27 % of Σ|r × F| for this deformation.)
                assert!(tq < 0.01 * scale_t, "bending: torque {tq} vs {scale_t}");
            } else {
                assert!(tq < 1e-12 * scale_t, "{name}: torque {tq} vs {scale_t}");
            }
        }
    }

    #[test]
    fn stretching_an_edge_past_the_singularity_carries_on_by_default_and_breaks_the_mesh_on_request()
     {
        let (mesh, reference, c) = cell();
        let mut x = mesh.vertices.clone();
        let [a, b] = mesh.edges[0];
        let v = sub(x[b], x[a]);
        x[b] = add(x[a], scale(v, 4.5));
        let mut f = vec![[0.0; 3]; x.len()];
        let err = MembraneForces::new(c)
            .with_terms(ForceTerms {
                past_singularity: PastSingularity::Fail,
                ..Default::default()
            })
            .compute(&mesh, &reference, &x, &mut f, 7)
            .unwrap_err();
        assert!(matches!(err, RbcError::MeshBroken { step: 7, .. }), "{err}");
        // As HemoCell, the default carries on with a finite force that still pulls the edge
        // back (|ε| = 3.5: ε + ε/|9 − ε²| = 3.5 + 3.5/3.25 > 0 along the edge).
        assert_eq!(
            ForceTerms::default().past_singularity,
            PastSingularity::CarryOn
        );
        let mut carry_on = vec![[0.0; 3]; x.len()];
        MembraneForces::new(c)
            .compute(&mesh, &reference, &x, &mut carry_on, 7)
            .unwrap();
        assert!(carry_on.iter().flatten().all(|f| f.is_finite()));
        assert!(
            dot(carry_on[b], v) < 0.0,
            "the stretched vertex is pulled back"
        );
        x[b][0] = f64::NAN;
        let err = MembraneForces::new(c)
            .compute(&mesh, &reference, &x, &mut f, 8)
            .unwrap_err();
        assert!(matches!(err, RbcError::NonFinite { .. }), "{err}");
    }

    #[test]
    fn the_cap_limits_every_vertex_force() {
        let (mesh, reference, c) = cell();
        let x: Vec<[f64; 3]> = mesh
            .vertices
            .iter()
            .map(|&[x, y, z]| [19.0 + 1.5 * (x - 19.0), y, z])
            .collect();
        let mut f = vec![[0.0; 3]; x.len()];
        let c = ForceCoefficients {
            force_cap: 1e-5,
            ..c
        };
        let s = MembraneForces::new(c)
            .with_terms(ForceTerms {
                volume: false,
                area: false,
                ..Default::default()
            })
            .compute(&mesh, &reference, &x, &mut f, 0)
            .unwrap();
        assert!(s.capped_vertices > 0);
        assert!(f.iter().all(|v| norm(*v) <= 1e-5 * (1.0 + 1e-12)));
    }
}
