//! The size and z boundary of a lattice ([`LatticeGeometry`], [`ZBoundary`]): what the sweep and
//! the immersed-boundary kernel need to place nodes.

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
