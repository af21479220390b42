//! `iuq rbc elongation FILE…`: the elongation index of membrane shapes written by another
//! simulator (HemoCell, through `examples/hemocell/decode-el.py`) or by `iuq rbc shear
//! --shape-out`, measured exactly as the native simulator measures its own frames.
//!
//! Each file is one frame: a vertex CSV (a header with columns `x`, `y`, `z`, one vertex per
//! row), a legacy ASCII VTK polydata file (`.vtk`) or an ASCII PLY file (`.ply`). Coordinates
//! are in HemoCell's frame (x flow, y gradient, z vorticity) and in lattice units (dx = 0.5 µm),
//! micrometres or metres (`--unit`). Each frame's EL is
//! [`iuq_rbc::ellipse::elongation_index`] of its vertices with 0.5 µm bins; the result is
//! `{"el": {"value": mean, "std": sample std}, "el_frames": [...], "frames": n}`, the form a
//! campaign's JSON decoder reads.
//!
//! Exit codes: 2 for a file that cannot be read or parsed (missing, bad header, a non-finite
//! number, no vertices) or fewer than 2 frames; 1 when a valid shape admits no ellipse.

use std::path::{Path, PathBuf};

use anyhow::{Result, anyhow};
use clap::{Args, ValueEnum};
use serde_json::json;

use iuq_rbc::ellipse::elongation_index;
use iuq_rbc::protocol::{CONTOUR_BIN_WIDTH, mean_and_sample_std};
use iuq_rbc::shape_input::{vertices_from_ply, vertices_from_vtk};
use iuq_study::table_io::{read_numeric_csv, write_atomically};

use crate::input_error::input_error;
use crate::report_output::{emit, short};

/// The lattice spacing of the shear experiment, in metres (HemoCell's `dx`).
pub const LATTICE_SPACING_M: f64 = 0.5e-6;

/// Unit of the coordinates in the shape files.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CoordinateUnit {
    /// Lattice units of 0.5 µm (what `iuq rbc shear --shape-out` writes).
    Lattice,
    /// Micrometres.
    Um,
    /// Metres (HemoCell's output in SI units).
    M,
}

impl CoordinateUnit {
    /// The factor that turns a coordinate in this unit into lattice units.
    pub fn to_lattice(self) -> f64 {
        match self {
            Self::Lattice => 1.0,
            Self::Um => 1e-6 / LATTICE_SPACING_M,
            Self::M => 1.0 / LATTICE_SPACING_M,
        }
    }
}

/// Arguments of `iuq rbc elongation`.
#[derive(Debug, Args)]
pub struct ElongationArgs {
    /// Membrane frames, one per file: vertex CSV (`x,y,z` header), `.vtk` or `.ply`.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Unit of the coordinates.
    #[arg(long, value_enum, default_value_t = CoordinateUnit::Lattice)]
    pub unit: CoordinateUnit,
    /// Also write the result (the JSON object) to this file, atomically.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Run `iuq rbc elongation`.
pub fn run(args: &ElongationArgs, json: bool) -> Result<()> {
    if args.files.len() < 2 {
        return Err(input_error(format!(
            "{} frame given; at least 2 are needed for a mean and a sample standard deviation",
            args.files.len()
        )));
    }
    let scale = args.unit.to_lattice();
    let bin_width = CONTOUR_BIN_WIDTH / LATTICE_SPACING_M;
    let mut el_frames = Vec::with_capacity(args.files.len());
    for path in &args.files {
        let read = read_vertices(path)?;
        let vertices: Vec<[f64; 3]> = read.iter().map(|v| v.map(|c| c * scale)).collect();
        if let Some(i) = vertices
            .iter()
            .position(|v| v.iter().any(|c| !c.is_finite()))
        {
            return Err(input_error(format!(
                "{}: vertex {i} ({:?} in the file's unit) is beyond the range of numbers in lattice units",
                path.display(),
                read[i]
            )));
        }
        let el = elongation_index(&vertices, bin_width)
            .map_err(|e| anyhow!("{}: {e}", path.display()))?;
        el_frames.push(el);
    }
    let (mean, std) = mean_and_sample_std(&el_frames);
    let value = json!({
        "el": { "value": mean, "std": std },
        "el_frames": el_frames,
        "frames": el_frames.len(),
    });
    if let Some(out) = &args.out {
        write_atomically(out, format!("{value}\n").as_bytes())?;
    }
    emit(json, &value, || {
        let frames: Vec<String> = el_frames.iter().map(|v| format!("{v:.4}")).collect();
        format!(
            "EL = {} ± {} over {} frames\nframes: {}",
            short(mean),
            short(std),
            el_frames.len(),
            frames.join(" ")
        )
    });
    Ok(())
}

/// The vertices of one shape file, in the file's own unit. The format follows the extension
/// (`.vtk`, `.ply`, anything else is read as CSV).
pub fn read_vertices(path: &Path) -> Result<Vec<[f64; 3]>> {
    let extension = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let vertices = match extension.as_str() {
        "vtk" => vertices_from_vtk(&read_text(path)?).map_err(|e| bad(path, &e))?,
        "ply" => vertices_from_ply(&read_text(path)?).map_err(|e| bad(path, &e))?,
        _ => read_csv_vertices(path)?,
    };
    if vertices.is_empty() {
        return Err(bad(path, "the file holds no vertices"));
    }
    if let Some(i) = vertices
        .iter()
        .position(|v| v.iter().any(|c| !c.is_finite()))
    {
        return Err(bad(
            path,
            &format!("vertex {i} has a non-finite coordinate {:?}", vertices[i]),
        ));
    }
    Ok(vertices)
}

fn bad(path: &Path, reason: &str) -> anyhow::Error {
    input_error(format!("{}: {reason}", path.display()))
}

fn read_text(path: &Path) -> Result<String> {
    std::fs::read_to_string(path).map_err(|e| bad(path, &format!("cannot read: {e}")))
}

fn read_csv_vertices(path: &Path) -> Result<Vec<[f64; 3]>> {
    let table = read_numeric_csv(path, false)?;
    let mut index = [0usize; 3];
    for (slot, name) in index.iter_mut().zip(["x", "y", "z"]) {
        *slot = table
            .columns
            .iter()
            .position(|c| c.eq_ignore_ascii_case(name))
            .ok_or_else(|| {
                bad(
                    path,
                    &format!(
                        "bad header: no column `{name}` (expected `x,y,z`; columns: {})",
                        table.columns.join(", ")
                    ),
                )
            })?;
    }
    Ok(table
        .rows
        .iter()
        .map(|r| [r[index[0]], r[index[1]], r[index[2]]])
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_convert_to_lattice_units() {
        assert_eq!(CoordinateUnit::Lattice.to_lattice(), 1.0);
        assert_eq!(CoordinateUnit::Um.to_lattice(), 2.0);
        assert!((CoordinateUnit::M.to_lattice() - 2e6).abs() < 1e-6);
    }
}
