//! The optical-tweezers stretching check (HemoCell `examples/stretchCell`, validated against
//! Mills et al. 2004): the cell in fluid at rest is pulled apart along x by a force F and its
//! axial diameter at equilibrium is compared with the measured one.
//!
//! As in HemoCell `helper/hemoCellStretch.cpp`, the 7 vertices with the smallest x of the
//! undeformed cell are pulled with −F/7 each along x and the 7 with the largest x with +F/7.
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

/// Axial diameters (µm) measured at a stretching force (pN): HemoCell
/// `examples/stretchCell/validation/reference-axial.dat`, as quoted by the spec.
pub const OPTICAL_TWEEZERS_AXIAL: [(f64, f64); 4] =
    [(1.8, 8.0), (15.0, 9.4), (35.0, 10.9), (62.0, 12.3)];

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
    let mut order: Vec<usize> = (0..mesh.vertices.len()).collect();
    order.sort_by(|&a, &b| mesh.vertices[a][0].total_cmp(&mesh.vertices[b][0]));
    let mut external = vec![[0.0; 3]; mesh.vertices.len()];
    for k in 0..e.forced_vertices {
        external[order[k]] = [-pull, 0.0, 0.0];
        external[order[order.len() - 1 - k]] = [pull, 0.0, 0.0];
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
