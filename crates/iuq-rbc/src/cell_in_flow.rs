//! One cell immersed in the lattice fluid: the time step of the coupled system.
//!
//! Each step (docs/cell-model.md, "Immersed-boundary coupling"):
//! 1. spread the vertex forces (membrane plus any external force) onto the fluid with the
//!    hat kernel;
//! 2. collide and stream (Guo forcing, per-node relaxation time);
//! 3. interpolate the vertex velocities with the same weights and advance `x += v`
//!    (explicit Euler, Δt = 1);
//! 4. recompute the membrane forces at the new positions and, independently (on a second
//!    thread when the fluid uses threads), place the stencils of the next step and re-tag the
//!    interior (near the membrane every 10 steps, everywhere every 1000);
//! 5. clear the force field.

use crate::error::{RbcError, Result};
use crate::immersed_boundary::ImmersedBoundary;
use crate::interior::InteriorViscosity;
use crate::lattice::{Lattice, LatticeGeometry, ZBoundary};
use crate::membrane_forces::{
    ForceCoefficients, ForceTerms, MembraneForces, ReferenceState, StrainSummary,
};
use crate::mesh::{Mesh, add};

/// Steps between two ray-parity re-taggings of the whole interior.
pub const FULL_RETAG_INTERVAL: u64 = 1000;
/// Steps between two updates of the nodes near the membrane.
pub const NEAR_RETAG_INTERVAL: u64 = 10;

/// Place the stencils at `x`; fail when a vertex has no fluid node around it or sits in a wall.
fn locate(
    ibm: &mut ImmersedBoundary,
    geometry: &LatticeGeometry,
    x: &[[f64; 3]],
    step: u64,
) -> Result<()> {
    if let Some(v) = ibm.locate(geometry, x) {
        return Err(RbcError::CellLeftDomain {
            step,
            reason: format!("vertex {v} at {:?} has no fluid node", x[v]),
        });
    }
    if let ZBoundary::Walls { .. } = geometry.z_boundary {
        let top = geometry.nz as f64;
        if let Some((v, p)) = x
            .iter()
            .enumerate()
            .find(|(_, p)| !(p[2] > 0.0 && p[2] < top))
        {
            return Err(RbcError::CellLeftDomain {
                step,
                reason: format!("vertex {v} at z = {} is in a wall", p[2]),
            });
        }
    }
    Ok(())
}

/// A cell in a lattice fluid.
#[derive(Debug, Clone)]
pub struct CellInFlow {
    lattice: Lattice,
    mesh: Mesh,
    reference: ReferenceState,
    membrane: MembraneForces,
    positions: Vec<[f64; 3]>,
    forces: Vec<[f64; 3]>,
    total_forces: Vec<[f64; 3]>,
    external: Option<Vec<[f64; 3]>>,
    velocities: Vec<[f64; 3]>,
    ibm: ImmersedBoundary,
    interior: Option<InteriorViscosity>,
    step: u64,
    strain: StrainSummary,
}

impl CellInFlow {
    /// Immerse `mesh` (its vertices are the stress-free reference state and the initial
    /// positions) in `lattice`. With `viscosity_ratio` the interior relaxes with
    /// `τ_in = Λ(τ − ½) + ½`, τ the lattice's default.
    pub fn new(
        lattice: Lattice,
        mesh: Mesh,
        coefficients: ForceCoefficients,
        viscosity_ratio: Option<f64>,
    ) -> Result<Self> {
        let positions = mesh.vertices.clone();
        let reference = ReferenceState::new(&mesh, &positions);
        let n = positions.len();
        let ibm = ImmersedBoundary::new(n, lattice.geometry());
        let interior = viscosity_ratio.map(|ratio| {
            InteriorViscosity::new(lattice.geometry(), 1.0 / lattice.default_omega(), ratio)
        });
        let mut cell = Self {
            lattice,
            mesh,
            reference,
            membrane: MembraneForces::new(coefficients),
            positions,
            forces: vec![[0.0; 3]; n],
            total_forces: vec![[0.0; 3]; n],
            external: None,
            velocities: vec![[0.0; 3]; n],
            ibm,
            interior,
            step: 0,
            strain: StrainSummary::default(),
        };
        if let Some(interior) = &mut cell.interior {
            interior.retag_all(&cell.mesh, &cell.positions, &mut cell.lattice);
        }
        cell.strain = cell.membrane.compute(
            &cell.mesh,
            &cell.reference,
            &cell.positions,
            &mut cell.forces,
            0,
        )?;
        locate(&mut cell.ibm, cell.lattice.geometry(), &cell.positions, 0)?;
        Ok(cell)
    }

    /// Evaluate the membrane forces with `terms` from now on (e.g. HemoCell's behaviour past a
    /// singularity, [`crate::membrane_forces::PastSingularity`]).
    pub fn set_force_terms(&mut self, terms: ForceTerms) {
        self.membrane.set_terms(terms);
    }

    /// Apply a constant external force to each vertex (added after the cap), e.g. the optical
    /// tweezers' pull.
    pub fn set_external_forces(&mut self, forces: Option<Vec<[f64; 3]>>) {
        self.external = forces;
    }

    /// Advance one time step.
    pub fn step(&mut self) -> Result<()> {
        let forces = match &self.external {
            Some(external) => {
                for ((t, f), e) in self.total_forces.iter_mut().zip(&self.forces).zip(external) {
                    *t = add(*f, *e);
                }
                &self.total_forces
            }
            None => &self.forces,
        };
        self.ibm.spread(forces, &mut self.lattice);
        self.lattice.step();
        let parallel = self.lattice.is_parallel();
        self.ibm
            .interpolate(&self.lattice, &mut self.velocities, parallel);
        // The force was spread onto these stencil nodes only; clear it before they move.
        self.ibm.clear_spread(&mut self.lattice);
        for (x, v) in self.positions.iter_mut().zip(&self.velocities) {
            *x = add(*x, *v);
        }
        self.step += 1;
        let step = self.step;
        // The membrane forces and the geometry of the next coupling (stencils, interior) both
        // depend only on the new positions: with threads, compute them side by side.
        let Self {
            lattice,
            mesh,
            reference,
            membrane,
            positions,
            forces,
            ibm,
            interior,
            ..
        } = self;
        let (mesh, reference, positions) = (&*mesh, &*reference, &*positions);
        let mut membrane_task = move || membrane.compute(mesh, reference, positions, forces, step);
        let mut geometry_task = move || -> Result<()> {
            locate(ibm, lattice.geometry(), positions, step)?;
            if let Some(interior) = interior.as_mut() {
                if step % FULL_RETAG_INTERVAL == 0 {
                    interior.retag_all(mesh, positions, lattice);
                } else if step % NEAR_RETAG_INTERVAL == 0 {
                    interior.update_near_membrane(mesh, positions, reference.mean_edge, lattice);
                }
            }
            Ok(())
        };
        let (strain, geometry) = if parallel {
            rayon::join(membrane_task, geometry_task)
        } else {
            (membrane_task(), geometry_task())
        };
        self.strain = strain?;
        geometry?;
        Ok(())
    }

    /// Move the vertices to `x` (the reference state stays) and recompute the forces: a
    /// perturbed initial shape for relaxation experiments.
    pub fn set_positions(&mut self, x: &[[f64; 3]]) -> Result<()> {
        self.positions.copy_from_slice(x);
        self.strain = self.membrane.compute(
            &self.mesh,
            &self.reference,
            &self.positions,
            &mut self.forces,
            self.step,
        )?;
        if let Some(interior) = &mut self.interior {
            interior.retag_all(&self.mesh, &self.positions, &mut self.lattice);
        }
        locate(
            &mut self.ibm,
            self.lattice.geometry(),
            &self.positions,
            self.step,
        )
    }

    /// Steps taken.
    pub fn steps(&self) -> u64 {
        self.step
    }

    /// Vertex positions now.
    pub fn positions(&self) -> &[[f64; 3]] {
        &self.positions
    }

    /// Vertex velocities of the last step.
    pub fn velocities(&self) -> &[[f64; 3]] {
        &self.velocities
    }

    /// The membrane forces at the current positions (capped, without external forces).
    pub fn membrane_forces(&self) -> &[[f64; 3]] {
        &self.forces
    }

    /// The mesh (connectivity and reference positions).
    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// The reference state.
    pub fn reference(&self) -> &ReferenceState {
        &self.reference
    }

    /// Strain extremes at the current positions.
    pub fn strain(&self) -> &StrainSummary {
        &self.strain
    }

    /// The fluid.
    pub fn lattice(&self) -> &Lattice {
        &self.lattice
    }

    /// The fluid, mutably (e.g. to choose threading).
    pub fn lattice_mut(&mut self) -> &mut Lattice {
        &mut self.lattice
    }
}
