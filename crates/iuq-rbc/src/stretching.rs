//! The optical-tweezers stretching check (HemoCell `examples/stretchCell`, validated against
//! Mills et al. 2004): the cell in fluid at rest is pulled apart along x by a force F and its
//! axial diameter at equilibrium is compared with the measured one.
//!
//! As in HemoCell `helper/hemoCellStretch.cpp`, the 7 vertices with the smallest x of the
//! undeformed cell (a rim vertex and its one-ring) are pulled along −x and the 7 with the largest
//! x along +x. HemoCell's helper adds the configured force to each of the 7; here F is the
//! tweezers' total force on each side, the quantity the experiment measured, so each vertex
//! carries F/7.
//! The box is HemoCell's, 26×13×13 µm (52×26×26 nodes), here periodic in x and y with resting
//! walls in z (HemoCell closes all faces with resting velocity walls; the equilibrium shape does
//! not depend on the fluid). The cell lies in the x–y plane, so x and y are in-plane diameters.
//!
//! Only the equilibrium matters, so every force (membrane coefficients, the cap and the pull)
//! is multiplied by the same factor (10 by default) to shorten the relaxation, which changes
//! neither the equilibrium nor the force balance. The run stops when the axial diameter changes
//! by less than `tolerance` (relative) over 1000 steps.

use std::time::Instant;

use crate::cell_in_flow::CellInFlow;
use crate::error::{RbcError, Result};
use crate::lattice::{Lattice, Precision, ZBoundary, on_pool_worker};
use crate::membrane_forces::{ForceCoefficients, MembraneParameters};
use crate::mesh::Mesh;
use crate::units::LatticeUnits;

/// One optical-tweezers measurement: the cell's diameters under a pulling force.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TweezersMeasurement {
    /// Total pulling force on each side, pN.
    pub force_pn: f64,
    /// Diameter along the pull, µm.
    pub axial_um: f64,
    /// In-plane diameter across the pull, µm.
    pub transverse_um: f64,
}

/// The measurements of the check (Mills et al. 2004). Axial diameters: HemoCell
/// `examples/stretchCell/validation/reference-axial.dat`. Transverse diameters: its
/// `reference-transverse.dat`, interpolated linearly at the same forces. The transverse diameter
/// tells the membrane's in-plane elasticity apart from the local deformation under the pulled
/// vertices, which only the axial diameter contains.
pub const OPTICAL_TWEEZERS: [TweezersMeasurement; 4] = [
    TweezersMeasurement {
        force_pn: 1.8,
        axial_um: 8.0,
        transverse_um: 7.776,
    },
    TweezersMeasurement {
        force_pn: 15.0,
        axial_um: 9.4,
        transverse_um: 7.168,
    },
    TweezersMeasurement {
        force_pn: 35.0,
        axial_um: 10.9,
        transverse_um: 6.427,
    },
    TweezersMeasurement {
        force_pn: 62.0,
        axial_um: 12.3,
        transverse_um: 5.654,
    },
];

/// Nodes of the stretching box.
pub const STRETCH_DOMAIN: [usize; 3] = [52, 26, 26];

/// One stretching run.
#[derive(Debug, Clone, PartialEq)]
pub struct StretchExperiment {
    /// Membrane coefficients (HemoCell's defaults kLink = 15, kBend = 80 for the check).
    pub membrane: MembraneParameters,
    /// Total pulling force on each side, in pN.
    pub force_pn: f64,
    /// Vertices pulled on each side.
    pub forced_vertices: usize,
    /// Factor on every force (equilibrium-neutral; shortens the relaxation).
    pub force_scale: f64,
    /// Convergence: relative change of the axial diameter per 1000 steps.
    pub tolerance: f64,
    /// Give up after this many steps (the result then says `converged: false`).
    pub max_steps: u64,
    /// Storage precision of the fluid.
    pub precision: Precision,
    /// Spread the fluid update over rayon's threads.
    pub parallel: bool,
}

impl StretchExperiment {
    /// The check at `force_pn` with HemoCell's default membrane.
    pub fn new(force_pn: f64) -> Self {
        Self {
            membrane: MembraneParameters::default(),
            force_pn,
            forced_vertices: 7,
            force_scale: 10.0,
            tolerance: 2e-4,
            max_steps: 100_000,
            precision: Precision::default(),
            parallel: true,
        }
    }
}

/// Result of a stretching run.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct StretchResult {
    /// Pulling force in pN.
    pub force_pn: f64,
    /// Diameter along the pull (x extent), in µm.
    pub axial_um: f64,
    /// In-plane diameter across the pull (y extent), in µm.
    pub transverse_um: f64,
    /// Steps run.
    pub steps: u64,
    /// Whether the convergence criterion was met.
    pub converged: bool,
    /// Wall-clock seconds.
    pub seconds: f64,
}

fn extent(x: &[[f64; 3]], d: usize) -> f64 {
    let lo = x.iter().map(|p| p[d]).fold(f64::INFINITY, f64::min);
    let hi = x.iter().map(|p| p[d]).fold(f64::NEG_INFINITY, f64::max);
    hi - lo
}

/// The `n` vertices with the smallest x and the `n` with the largest x (HemoCell's choice; on
/// the icosphere mesh, n = 7 is a rim vertex and its one-ring on each side).
pub fn pulled_vertices(mesh: &Mesh, n: usize) -> (Vec<usize>, Vec<usize>) {
    let mut order: Vec<usize> = (0..mesh.vertices.len()).collect();
    order.sort_by(|&a, &b| mesh.vertices[a][0].total_cmp(&mesh.vertices[b][0]));
    let n = n.min(order.len() / 2);
    let upper = order.iter().rev().take(n).copied().collect();
    order.truncate(n);
    (order, upper)
}

/// Run one stretching experiment to equilibrium.
pub fn run_stretch(e: &StretchExperiment) -> Result<StretchResult> {
    on_pool_worker(|| run_stretch_on_worker(e))
}

fn run_stretch_on_worker(e: &StretchExperiment) -> Result<StretchResult> {
    e.membrane.validate()?;
    if !(e.force_pn.is_finite() && e.force_pn >= 0.0) {
        return Err(RbcError::invalid(
            "force",
            e.force_pn,
            "must be a non-negative number of pN",
        ));
    }
    if !(e.force_scale.is_finite() && e.force_scale > 0.0) {
        return Err(RbcError::invalid(
            "force_scale",
            e.force_scale,
            "must be positive",
        ));
    }
    if e.forced_vertices == 0 || 2 * e.forced_vertices > 642 {
        return Err(RbcError::invalid(
            "forced_vertices",
            e.forced_vertices as f64,
            "must lie between 1 and 321",
        ));
    }
    let started = Instant::now();
    let units = LatticeUnits::reference();
    let [nx, ny, nz] = STRETCH_DOMAIN;
    let mut lattice = Lattice::new(
        nx,
        ny,
        nz,
        ZBoundary::Walls {
            bottom: [0.0; 3],
            top: [0.0; 3],
        },
        units.relaxation_time(),
        e.precision,
    );
    lattice.set_parallel(e.parallel);
    let centre = [nx as f64 / 2.0, ny as f64 / 2.0, nz as f64 / 2.0];
    let mesh = Mesh::red_blood_cell_lu(units.dx, centre);
    let coefficients = ForceCoefficients::hemocell(&e.membrane, &units, mesh.triangles.len())
        .scaled(e.force_scale);
    let pull = units.force_lu(e.force_pn * 1e-12) * e.force_scale / e.forced_vertices as f64;
    let (lower, upper) = pulled_vertices(&mesh, e.forced_vertices);
    let mut external = vec![[0.0; 3]; mesh.vertices.len()];
    for (&l, &u) in lower.iter().zip(&upper) {
        external[l] = [-pull, 0.0, 0.0];
        external[u] = [pull, 0.0, 0.0];
    }
    let mut cell = CellInFlow::new(lattice, mesh, coefficients, None)?;
    cell.set_external_forces(Some(external));
    let mut previous = extent(cell.positions(), 0);
    let mut converged = false;
    while cell.steps() < e.max_steps {
        cell.step()?;
        if cell.steps() % 1000 == 0 {
            let axial = extent(cell.positions(), 0);
            if ((axial - previous) / previous).abs() < e.tolerance && cell.steps() >= 3000 {
                converged = true;
                break;
            }
            previous = axial;
        }
    }
    let um = units.dx * 1e6;
    Ok(StretchResult {
        force_pn: e.force_pn,
        axial_um: extent(cell.positions(), 0) * um,
        transverse_um: extent(cell.positions(), 1) * um,
        steps: cell.steps(),
        converged,
        seconds: started.elapsed().as_secs_f64(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stretched_cells_are_longer_than_wide() {
        for m in &OPTICAL_TWEEZERS {
            assert!(
                m.axial_um > m.transverse_um,
                "stretched cells are longer than wide"
            );
        }
    }

    #[test]
    fn seven_pulled_vertices_are_a_rim_vertex_and_its_one_ring() {
        let mesh = Mesh::red_blood_cell_lu(0.5e-6, [26.0, 13.0, 13.0]);
        let (lower, upper) = pulled_vertices(&mesh, 7);
        for side in [&lower, &upper] {
            assert_eq!(side.len(), 7);
            let tip = side[0];
            assert_eq!(mesh.ring(tip).len(), 6);
            let mut ring: Vec<usize> = mesh.ring(tip).to_vec();
            let mut rest: Vec<usize> = side[1..].to_vec();
            ring.sort_unstable();
            rest.sort_unstable();
            assert_eq!(ring, rest);
            assert!(
                (mesh.vertices[tip][2] - 13.0).abs() < 1e-9,
                "the tip lies on the rim"
            );
        }
        assert!(mesh.vertices[lower[0]][0] < 26.0 && mesh.vertices[upper[0]][0] > 26.0);
    }
}
