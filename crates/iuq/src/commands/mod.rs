//! One module per verb of the command line.

pub mod basis;
pub mod bench;
pub mod cancel;
pub mod design;
pub mod export;
pub mod gp;
pub mod pipeline;
pub mod rbc;
pub mod rbc_elongation;
pub mod redecode;
pub mod retry;
pub mod run;
pub mod serve;
pub mod sobol;
pub mod status;
pub mod worker;
