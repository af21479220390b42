//! The validation runs of the spec, one JSON line per row:
//!
//! ```text
//! cargo run --release -p iuq-rbc --example validate -- scaled      # 7 runs, minutes
//! cargo run --release -p iuq-rbc --example validate -- reference   # 7 runs, an hour or more
//! cargo run --release -p iuq-rbc --example validate -- stretch     # 4 runs, minutes
//! ```
//!
//! `iuq rbc validate` runs the same tables from the command line.

use iuq_rbc::protocol::Protocol;
use iuq_rbc::validation::{validate_shear, validate_stretch};

fn main() {
    let which = std::env::args().nth(1).unwrap_or_else(|| "scaled".into());
    let rows: Vec<serde_json::Value> = match which.as_str() {
        "stretch" => validate_stretch()
            .iter()
            .map(|r| serde_json::json!(r))
            .collect(),
        other => match other.parse::<Protocol>() {
            Ok(protocol) => validate_shear(protocol)
                .iter()
                .map(|r| serde_json::json!(r))
                .collect(),
            Err(e) => {
                eprintln!("{e}; expected scaled, reference or stretch");
                std::process::exit(2);
            }
        },
    };
    for row in rows {
        println!("{row}");
    }
}
