//! The native single red-blood-cell shear simulator, compatible with HemoCell's one-cell shear
//! experiment (docs/cell-model.md describes the model, its units, protocols and validation).
//!
//! One red blood cell, a 642-vertex biconcave membrane with HemoCell's link, area, volume and
//! bending forces ([`membrane_forces`]), is immersed through the immersed-boundary method
//! ([`immersed_boundary`]) in a D3Q19 lattice Boltzmann fluid ([`lattice`]) sheared between
//! two moving walls; the interior fluid is Λ times more viscous ([`interior`]). The elongation
//! index of the cell's projection on the shear (flow–gradient) plane ([`ellipse`]), averaged
//! over a measuring window ([`protocol`]), is the quantity calibrated against ektacytometry
//! ([`ektacytometry`]). [`model::RbcShearModel`] wraps it as an `iuq_core::Model`;
//! [`stretching`] and [`validation`] hold the checks against HemoCell and optical tweezers;
//! [`benchmark`] measures the fluid solver against the memory bandwidth.
//!
//! Everything here is numerical: no file or terminal I/O ([`shape_output`] returns strings,
//! [`shape_input`] reads them).
//!
//! # Validation
//! The long checks against HemoCell and the optical-tweezers data (docs/cell-model.md) stay out
//! of the default test suite: `iuq rbc validate --protocol scaled|reference|both --stretch`, or
//! the ignored tests
//! `cargo test --release -p iuq-rbc --test shear_experiment -- --ignored`.
//! No model constant is fitted to the validation numbers.
//!
//! # Performance
//! The fluid update is a fused AA-pattern stream-and-collide on one buffer of single-precision
//! deviations, vectorised with AVX-512 or AVX2 and spread over rayon's threads by rows; the
//! membrane forces and the coupling geometry of a step run side by side on two threads. Nothing
//! is allocated per step and results do not depend on the number of threads or the instruction
//! set. `iuq rbc bench` reports the update rate next to the memory copy bandwidth.
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
// No panic reachable from user input: a library reports every failure in its error type.
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

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
pub mod shape_input;
pub mod shape_output;
pub mod shear_trace;
pub mod stretching;
pub mod units;
pub mod validation;

pub use error::{RbcError, Result};
pub use membrane_forces::{MembraneParameters, PastSingularity};
pub use model::{CellParameters, RbcShearModel, RbcShearSettings};
pub use protocol::{MeshOrientation, Protocol, ShearExperiment, ShearResult, run_shear};
pub use shear_trace::{ShearPortrait, shear_portrait};
