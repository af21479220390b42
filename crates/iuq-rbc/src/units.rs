//! Physical constants of the HemoCell shear experiment and the conversion to lattice units.
//!
//! Lattice units (LU) take the lattice spacing `dx`, the time step `dt` and the fluid density
//! `ρ` as units of length, time and density, so that a force is measured in
//! `df = ρ·dx⁴/dt²` (HemoCell `core/constantConversion.cpp`, `param::df`) and an energy in
//! `df·dx`.

/// Thermal energy kBT at 23 °C in joules (HemoCell `core/constantConversion.cpp`).
pub const BOLTZMANN_TEMPERATURE: f64 = 4.100531391e-21;
/// Density of plasma in kg/m³.
pub const PLASMA_DENSITY: f64 = 1025.0;
/// Kinematic viscosity of plasma in m²/s.
pub const PLASMA_KINEMATIC_VISCOSITY: f64 = 1.1e-6;
/// Lattice spacing of HemoCell's one-cell shear experiment in metres (0.5 µm).
pub const REFERENCE_DX: f64 = 0.5e-6;
/// Time step of HemoCell's one-cell shear experiment in seconds.
pub const REFERENCE_DT: f64 = 5e-8;
/// Persistence length of spectrin in metres: the length scale of the link force coefficient
/// (`persistenceLengthFine` in HemoCell `mechanics/rbcHighOrderModel.cpp`, `calculate_kLink`).
pub const SPECTRIN_PERSISTENCE_LENGTH: f64 = 7.5e-9;
/// Equilibrium edge length of HemoCell's RBC mesh in metres: the length scale of the bending,
/// area and volume coefficients (`mechanics/rbcHighOrderModel.cpp`).
pub const MESH_EQUILIBRIUM_LENGTH: f64 = 0.5e-6;
/// Cap of the total membrane force on one vertex, in newtons (50 pN; HemoCell
/// `core/hemoCell.cpp`, the force limit applied after the constitutive model).
pub const VERTEX_FORCE_CAP: f64 = 50e-12;
/// Radius of the undeformed cell in metres (diameter 7.82 µm).
pub const CELL_RADIUS: f64 = 3.91e-6;

/// The unit system of one simulation: lattice spacing, time step and the fluid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LatticeUnits {
    /// Lattice spacing in metres.
    pub dx: f64,
    /// Time step in seconds.
    pub dt: f64,
    /// Fluid density in kg/m³.
    pub density: f64,
    /// Fluid kinematic viscosity in m²/s.
    pub kinematic_viscosity: f64,
}

impl LatticeUnits {
    /// HemoCell's units for the shear experiment: dx = 0.5 µm, dt = 5e-8 s, plasma.
    pub fn reference() -> Self {
        Self {
            dx: REFERENCE_DX,
            dt: REFERENCE_DT,
            density: PLASMA_DENSITY,
            kinematic_viscosity: PLASMA_KINEMATIC_VISCOSITY,
        }
    }

    /// Kinematic viscosity in lattice units, ν_LU = ν·dt/dx² (0.22 for the reference units).
    pub fn viscosity_lu(&self) -> f64 {
        self.kinematic_viscosity * self.dt / (self.dx * self.dx)
    }

    /// BGK relaxation time τ = 3ν_LU + 0.5 (1.16 for the reference units).
    pub fn relaxation_time(&self) -> f64 {
        3.0 * self.viscosity_lu() + 0.5
    }

    /// The force unit df = ρ·dx⁴/dt² in newtons.
    pub fn force_unit(&self) -> f64 {
        self.density * self.dx.powi(4) / (self.dt * self.dt)
    }

    /// kBT in lattice units, kBT / (df·dx).
    pub fn kbt_lu(&self) -> f64 {
        BOLTZMANN_TEMPERATURE / (self.force_unit() * self.dx)
    }

    /// A length in metres expressed in lattice units.
    pub fn length_lu(&self, metres: f64) -> f64 {
        metres / self.dx
    }

    /// A force in newtons expressed in lattice units.
    pub fn force_lu(&self, newtons: f64) -> f64 {
        newtons / self.force_unit()
    }
}

/// Shear rate γ̇ = τ/(ρν) in 1/s of plasma under the wall shear stress `stress` (Pa), as the
/// ektacytometer imposes it.
pub fn shear_rate(stress: f64) -> f64 {
    stress / (PLASMA_DENSITY * PLASMA_KINEMATIC_VISCOSITY)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_units_match_the_spec() {
        let u = LatticeUnits::reference();
        assert!((u.viscosity_lu() - 0.22).abs() < 1e-12);
        assert!((u.relaxation_time() - 1.16).abs() < 1e-12);
        // df = 1025 · (0.5e-6)^4 / (5e-8)^2
        assert!((u.force_unit() - 2.5625e-8).abs() < 1e-20);
        // 50 pN in LU
        assert!((u.force_lu(VERTEX_FORCE_CAP) - 1.951_219_5e-3).abs() < 1e-9);
    }
}
