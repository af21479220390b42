//! GP files: the GP bank file format (`iuq_gp::GpBank`) holding one output, as `iuq gp fit` and
//! the Python package's `GaussianProcess.save` write it and `iuq gp predict|validate|serve` and
//! `GaussianProcess.load` read it.

use std::path::Path;

use iuq_gp::GpBank;

use crate::error::{Result, input_error};

/// Read the GP file at `path`: a GP bank of exactly one output. `reader` names who reads it in
/// the message for a bank of several outputs (e.g. "`iuq gp`").
///
/// # Errors
/// A file that cannot be read, is not a GP bank, or holds more than one output (bad input).
pub fn read_gp_file(path: &Path, reader: &str) -> Result<GpBank> {
    let file = path.display();
    let text = std::fs::read_to_string(path)
        .map_err(|e| input_error(format!("{file}: cannot read: {e}")).with_source(e))?;
    let bank = GpBank::from_json_str(&text)
        .map_err(|e| input_error(format!("{file}: not a GP file: {e}")).with_source(e))?;
    if bank.gps().len() != 1 {
        return Err(input_error(format!(
            "{file}: a GP bank of {} outputs; {reader} takes a GP file of one output",
            bank.gps().len()
        )));
    }
    Ok(bank)
}
