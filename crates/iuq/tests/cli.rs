//! The command line's integration tests, one module per subject, in one test binary: one link
//! instead of fifteen, and cargo's test threads shared by every test instead of one binary's
//! tests after another's (the binaries' slowest tests no longer run alone at their ends).
//!
//! Run one subject with its module's name as the filter, e.g.
//! `cargo test -p iuq --test cli cli_model_posterior::`.

mod common;

mod cli_adaptive;
mod cli_basis;
mod cli_campaign;
mod cli_campaign_slurm;
mod cli_design_and_sobol;
mod cli_gp;
mod cli_hemocell_adapter;
mod cli_low_fidelity;
mod cli_model_posterior;
mod cli_pipeline;
mod cli_rbc;
mod cli_reduced_basis;
mod cli_sampler_check;
mod cli_umbridge;
mod hemocell_comparison;
