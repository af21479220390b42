//! The native single red-blood-cell shear simulator, compatible with HemoCell's one-cell shear
//! experiment (spec: `specs/rbc-shear-model.md`).
//!
//! One red blood cell, a 642-vertex biconcave membrane with HemoCell's link, area, volume and
//! bending forces ([`membrane_forces`]), is immersed through the immersed-boundary method
//! ([`immersed_boundary`]) in a D3Q19 lattice Boltzmann fluid ([`lattice`]) sheared between
//! two moving walls; the interior fluid is Λ times more viscous ([`interior`]). The elongation
//! index of the cell's projection on the flow–vorticity plane ([`ellipse`]), averaged over a
//! measuring window ([`protocol`]), is the quantity calibrated against ektacytometry
//! ([`ektacytometry`]). [`model::RbcShearModel`] wraps it as an `iuq_core::Model`;
//! [`stretching`] and [`validation`] hold the checks against HemoCell and optical tweezers;
//! [`benchmark`] measures the fluid solver against the memory bandwidth.
//!
//! Everything here is numerical: no file or terminal I/O ([`shape_output`] returns strings).
//!
//! ```no_run
//! use iuq_rbc::membrane_forces::MembraneParameters;
//! use iuq_rbc::protocol::{ShearExperiment, run_shear};
//!
//! let cell = MembraneParameters { k_link: 36.7, k_bend: 367.0, ..Default::default() };
//! let result = run_shear(&ShearExperiment::new(cell, 5.9, 1.36))?;
//! println!("EL = {} ± {}", result.el_mean, result.el_std);
//! # Ok::<(), iuq_rbc::RbcError>(())
//! ```

#![warn(missing_docs)]

pub mod benchmark;
pub mod cell_in_flow;
pub mod ektacytometry;
pub mod ellipse;
pub mod error;
pub mod immersed_boundary;
pub mod interior;
pub mod lattice;
pub mod membrane_forces;
pub mod mesh;
pub mod model;
pub mod protocol;
pub mod shape_output;
pub mod stretching;
pub mod units;
pub mod validation;

pub use error::{RbcError, Result};
pub use membrane_forces::MembraneParameters;
pub use model::{CellParameters, RbcShearModel, RbcShearSettings};
pub use protocol::{Protocol, ShearExperiment, ShearResult, run_shear};
