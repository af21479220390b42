//! `iuq`: inverse uncertainty quantification of expensive simulation models.
//!
//! Exit codes: 0 success, 1 failure of the work, 2 bad input (the message names the file, key
//! and reason). With `--json` every verb prints exactly one JSON object on stdout; on an error
//! that object is `{"error": {"kind": "bad_input" | "failure", "message": ...}}`.

// No panic reachable from user input: every failure exits 1 or 2 with its message.
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

mod commands;
mod input_error;
mod markdown_help;
mod report_output;

use clap::{CommandFactory, Parser, Subcommand};

use input_error::{EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_SUCCESS, is_input_error};

/// Calibrate expensive simulation models against measurements and quantify the uncertainty of
/// their parameters: designs, Gaussian-process surrogates, Sobol' sensitivity indices.
#[derive(Debug, Parser)]
#[command(name = "iuq", version, about, propagate_version = true)]
struct Cli {
    /// Print exactly one JSON object on stdout instead of text.
    #[arg(long, global = true)]
    json: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// The calibration study end to end: model runs, GPs, Sobol' indices, BASIS, report.
    Pipeline(commands::pipeline::PipelineArgs),
    /// Space-filling designs (Latin hypercube, Sobol', Saltelli) written as CSV.
    Design(commands::design::DesignArgs),
    /// Gaussian-process surrogates: fit, predict, validate.
    #[command(subcommand)]
    Gp(commands::gp::GpCommand),
    /// Sobol' sensitivity indices of a study's model (expression, rbc-shear, umbridge).
    Sobol(commands::sobol::SobolArgs),
    /// Posterior samples and evidence with BASIS (annealed sequential importance sampling).
    Basis(commands::basis::BasisArgs),
    /// In-process timings of numerical kernels, for the side-by-side benchmark scripts.
    #[command(subcommand)]
    Bench(commands::bench::BenchCommand),
    /// Run the study's design as a campaign of model runs (resumes an interrupted campaign).
    Run(commands::run::RunArgs),
    /// Runs of a campaign per status, and its failures with their reasons.
    Status(commands::status::StatusArgs),
    /// Run the failed (--failed) or lost (--lost) runs of a campaign again.
    Retry(commands::retry::RetryArgs),
    /// Set the pending runs of a design aside (one a pipeline abandoned), so that nothing runs them.
    Cancel(commands::cancel::CancelArgs),
    /// Decode the outputs of a campaign's finished runs again from their run directories.
    Redecode(commands::redecode::RedecodeArgs),
    /// Export a campaign's runs (parameters, outputs, status) as tidy CSV or JSON.
    Export(commands::export::ExportArgs),
    /// Execute one task of a job array (started by the Slurm and HyperQueue executors).
    Worker(commands::worker::WorkerArgs),
    /// The native single red-blood-cell shear simulator: one run, validation, benchmark.
    #[command(subcommand)]
    Rbc(commands::rbc::RbcCommand),
    /// Serve a study's model and its log-posterior to other tools (UM-Bridge 1.0 over HTTP).
    #[command(subcommand)]
    Serve(commands::serve::ServeCommand),
    /// Print the whole command-line reference as Markdown (the documentation site's CLI page).
    #[command(hide = true)]
    MarkdownHelp,
}

fn main() {
    let cli = Cli::parse();
    // Ctrl-C, `kill` or a scheduler's stop take the model commands this process runs with it
    // (each runs in a process group of its own and would otherwise run on, orphaned).
    iuq_campaign::supervised_process::forward_termination_signals();
    let result = match &cli.command {
        Command::Pipeline(args) => commands::pipeline::run(args, cli.json),
        Command::Design(args) => commands::design::run(args, cli.json),
        Command::Gp(command) => commands::gp::run(command, cli.json),
        Command::Sobol(args) => commands::sobol::run(args, cli.json),
        Command::Basis(args) => commands::basis::run(args, cli.json),
        Command::Bench(command) => commands::bench::run(command, cli.json),
        Command::Run(args) => commands::run::run(args, cli.json),
        Command::Status(args) => commands::status::run(args, cli.json),
        Command::Retry(args) => commands::retry::run(args, cli.json),
        Command::Cancel(args) => commands::cancel::run(args, cli.json),
        Command::Redecode(args) => commands::redecode::run(args, cli.json),
        Command::Export(args) => commands::export::run(args, cli.json),
        Command::Worker(args) => commands::worker::run(args, cli.json),
        Command::Rbc(command) => commands::rbc::run(command, cli.json),
        Command::Serve(command) => commands::serve::run(command, cli.json),
        Command::MarkdownHelp => {
            print!("{}", markdown_help::markdown_help(&Cli::command()));
            Ok(())
        }
    };
    let code = match result {
        Ok(()) => EXIT_SUCCESS,
        Err(error) => {
            let bad_input = is_input_error(&error);
            let message = input_error::message(&error);
            if cli.json {
                println!(
                    "{}",
                    serde_json::json!({"error": {
                        "kind": if bad_input { "bad_input" } else { "failure" },
                        "message": message,
                    }})
                );
            }
            eprintln!("error: {message}");
            if bad_input {
                EXIT_BAD_INPUT
            } else {
                EXIT_FAILURE
            }
        }
    };
    std::process::exit(code);
}
