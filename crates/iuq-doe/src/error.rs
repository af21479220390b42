//! The error type of `iuq-doe`.

use thiserror::Error;

/// Errors raised when a design cannot be built from the inputs given.
///
/// Every public function of the crate validates its inputs (sizes, dimensions, bounds, option
/// values) and returns one of these instead of panicking, so that a CLI can report bad input as
/// such.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum DoeError {
    /// A number of points that the design cannot have (zero, or too many for the method).
    #[error("invalid number of points {n}: {reason}")]
    InvalidSampleSize {
        /// The number of points asked for.
        n: usize,
        /// Why it cannot be used.
        reason: String,
    },
    /// A dimension that the design cannot have (zero, or above what the method supports).
    #[error("invalid dimension {dim}: {reason}")]
    InvalidDimension {
        /// The dimension asked for.
        dim: usize,
        /// Why it cannot be used.
        reason: String,
    },
    /// An option of a design method outside its valid range (e.g. zero maximin candidates).
    #[error("invalid option `{name}`: {reason}")]
    InvalidOption {
        /// The option's name.
        name: &'static str,
        /// Why its value cannot be used.
        reason: String,
    },
    /// A box whose bounds are not finite or not ordered (`lower < upper` is required).
    #[error(
        "invalid bounds for coordinate {index}: [{lower}, {upper}] (need finite lower < upper)"
    )]
    InvalidBounds {
        /// The coordinate (column) whose bounds are invalid.
        index: usize,
        /// The lower bound given.
        lower: f64,
        /// The upper bound given.
        upper: f64,
    },
    /// A point whose number of coordinates does not match the dimension it is used with.
    #[error("dimension mismatch in row {row}: expected {expected} values, got {actual}")]
    DimensionMismatch {
        /// The row (point) index.
        row: usize,
        /// The expected number of coordinates.
        expected: usize,
        /// The number of coordinates found.
        actual: usize,
    },
    /// A coordinate that is NaN or infinite where a finite value is required.
    #[error("non-finite value {value} in row {row}, column {column}")]
    NonFinite {
        /// The row (point) index.
        row: usize,
        /// The column (coordinate) index.
        column: usize,
        /// The offending value.
        value: f64,
    },
    /// A vector of model outputs whose length does not match the design it belongs to.
    #[error("expected {expected} output values for the design, got {actual}")]
    OutputLength {
        /// The number of rows of the design.
        expected: usize,
        /// The number of values given.
        actual: usize,
    },
    /// A Sobol' sequence asked for more points than its direction numbers can index.
    #[error(
        "Sobol' sequence exhausted: at most 2^{bits} points can be generated, asked for index {index}"
    )]
    SequenceExhausted {
        /// The number of bits of the direction numbers (the sequence holds `2^bits` points).
        bits: u32,
        /// The point index that would have been reached.
        index: u128,
    },
}

/// Result type of `iuq-doe`.
pub type Result<T, E = DoeError> = std::result::Result<T, E>;
