//! Renders the synthetic study's report: `cargo run -p iuq-report --example demo -- DIR`
//! (default `/tmp/iuq-report-demo`), to look at the figures and the page.

#[path = "../tests/synthetic/mod.rs"]
mod synthetic;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "/tmp/iuq-report-demo".to_string());
    let stresses = [0.64, 0.93, 1.36, 1.99, 2.91, 4.24, 6.19, 9.04];
    let mut report = synthetic::synthetic_report(&stresses, 2, 2000, 7);
    synthetic::add_adaptive_results(&mut report, 4, 3, 7);
    let files = iuq_report::write_report(&report, std::path::Path::new(&dir))?;
    println!("{}", files.html.display());
    Ok(())
}
