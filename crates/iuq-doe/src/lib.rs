//! Designs of experiments for iuq: where to run an expensive model.
//!
//! All designs live on the unit cube `[0, 1)^d` and are reproducible from a seed through the
//! keyed random streams of [`iuq_core::random`] (stages `LATIN_HYPERCUBE` and `SOBOL_SCRAMBLE`);
//! results never depend on the number of rayon threads.
//!
//! | module | what |
//! |---|---|
//! | [`sobol`] | the Sobol' sequence ([`SobolSequence`], [`sobol_points`]), Gray-code order, optionally scrambled ([`Scrambling`]: linear matrix scramble + digital shift, independent replicates) |
//! | [`direction_numbers`] | the Joe & Kuo (2008) direction numbers `new-joe-kuo-6.21201` (21201 dimensions), embedded and decoded lazily |
//! | [`latin_hypercube`](mod@latin_hypercube) | Latin hypercubes ([`latin_hypercube()`](fn@latin_hypercube), [`LhsMethod`]): random, maximin (best of k), optimised |
//! | [`ese`] | the enhanced stochastic evolutionary optimiser of the φ_p criterion ([`EseOptions`]) |
//! | [`distance`] | space-filling criteria: [`min_distance`], [`phi_p`] |
//! | [`saltelli`] | the Saltelli design for Sobol' indices ([`SaltelliDesign`], [`SaltelliOutputs`]) |
//! | [`scaling`] | unit cube ↔ box of bounds ([`scale_to_bounds`], [`scale_to_unit_cube`]) |
//! | [`size`] | the size limit of all designs, [`MAX_DESIGN_VALUES`] |
//! | [`error`] | the crate's error type [`DoeError`] |
//!
//! Designs are returned as `Vec<Vec<f64>>`, one inner vector (of `d` coordinates) per point.
//!
//! ```
//! use iuq_doe::{LhsMethod, latin_hypercube, min_distance};
//!
//! // 10 points in the unit square, one per row and column stratum, seeded.
//! let design = latin_hypercube(10, 2, LhsMethod::Random, 7)?;
//! assert_eq!(design.len(), 10);
//! for k in 0..2 {
//!     let mut strata: Vec<usize> = design.iter().map(|p| (p[k] * 10.0) as usize).collect();
//!     strata.sort();
//!     assert_eq!(strata, (0..10).collect::<Vec<_>>());
//! }
//! assert!(min_distance(&design) > 0.0);
//! # Ok::<(), iuq_doe::DoeError>(())
//! ```

#![warn(missing_docs)]
// No panic reachable from user input: a library reports every failure in its error type.
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

pub mod direction_numbers;
pub mod distance;
pub mod error;
pub mod ese;
pub mod latin_hypercube;
pub mod saltelli;
pub mod scaling;
pub mod size;
pub mod sobol;

pub use direction_numbers::{SOBOL_BITS, SOBOL_MAX_DIM};
pub use distance::{min_distance, phi_p};
pub use error::{DoeError, Result};
pub use ese::EseOptions;
pub use latin_hypercube::{DEFAULT_MAXIMIN_CANDIDATES, LhsMethod, latin_hypercube};
pub use saltelli::{SaltelliDesign, SaltelliOutputs};
pub use scaling::{scale_to_bounds, scale_to_unit_cube};
pub use size::MAX_DESIGN_VALUES;
pub use sobol::{Scrambling, SobolSequence, sobol_points};
