//! One module per verb of the command line.

pub mod basis;
pub mod bench;
pub mod design;
pub mod gp;
pub mod sobol;
