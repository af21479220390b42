//! The `[model]` section of kind `rbc-shear`: the native single red-blood-cell shear simulator
//! (`iuq-rbc`) as the study's model, one elongation index per shear stress.
//!
//! ```toml
//! [model]
//! kind = "rbc-shear"
//! protocol = "scaled"           # or "reference" (HemoCell's time step)
//! lattice_shear_rate = 3e-4     # scaled protocol only
//! precision = "single"          # or "double"
//! past_singularity = "carry-on" # as HemoCell (default), or "fail"
//! initial_orientation = "unrotated" # or "hemocell" (the mesh turned 90° in the disk plane)
//! window_factor = 1.25          # the window ends at this × its start (strain 7.5 to 9.4)
//! frames = 10                   # shapes measured over the window
//! stresses = [0.64, 1.36]       # Pa; default: the `x` column of `[likelihood] data`
//! kArea = 5                     # fixed values of the cell parameters not in [parameters]
//! ```

use std::path::{Path, PathBuf};

use iuq_rbc::lattice::Precision;
use iuq_rbc::model::{CellParameters, PARAMETER_NAMES, RbcShearModel, RbcShearSettings};
use iuq_rbc::protocol::{DEFAULT_LATTICE_SHEAR_RATE, Protocol};
use iuq_rbc::{MeshOrientation, PastSingularity, RbcError};

use iuq_study_file::StudySection;

use crate::error::{Result, input_error};
use crate::table_io::read_numeric_csv;

/// Build the model of a study's `[model] kind = "rbc-shear"` section.
///
/// Keys: `protocol` (`"scaled"`, default, or `"reference"`), `lattice_shear_rate` (scaled
/// protocol, default 3e-4), `precision` (`"single"` or `"double"`), `stresses` (Pa; default: the
/// `x` column of `[likelihood] data`, within its `x_range`), and fixed values for the
/// parameters of the cell that are not in `[parameters]` (`kLink`, `kBend`, `viscosityRatio`,
/// `kArea`, `kVolume`; defaults 15, 80, 5, 5, 20). Paths are relative to the study file.
pub fn rbc_shear_model(
    table: &toml::Table,
    file: &str,
    study_path: &Path,
    inputs: Vec<String>,
    likelihood: Option<&toml::Table>,
) -> Result<RbcShearModel> {
    let mut s = StudySection::new(table, "model", file);
    s.allow(&["kind"]);
    let mut settings = RbcShearSettings::default();
    match s.choice("protocol", &["scaled", "reference"])? {
        Some("reference") => settings.protocol = Protocol::Reference,
        _ => settings.protocol = Protocol::default(),
    }
    let lattice_shear_rate = s.number("lattice_shear_rate")?;
    match (settings.protocol, lattice_shear_rate) {
        (Protocol::Scaled { .. }, rate) => {
            settings.protocol = Protocol::Scaled {
                lattice_shear_rate: rate.unwrap_or(DEFAULT_LATTICE_SHEAR_RATE),
            };
        }
        (_, Some(_)) => {
            return Err(s
                .error(
                    "lattice_shear_rate",
                    "only the scaled protocol has a lattice shear rate",
                )
                .into());
        }
        (_, None) => {}
    }
    let names = PastSingularity::ALL.map(|p| p.name());
    if let Some(name) = s.choice("past_singularity", &names)? {
        settings.past_singularity = PastSingularity::from_name(name)
            .ok_or_else(|| s.error("past_singularity", format!("unknown `{name}`")))?;
    }
    let orientations = MeshOrientation::ALL.map(|o| o.name());
    if let Some(name) = s.choice("initial_orientation", &orientations)? {
        settings.orientation = MeshOrientation::from_name(name)
            .ok_or_else(|| s.error("initial_orientation", format!("unknown `{name}`")))?;
    }
    // Quick checks and tests only: the study's window starts at 7.5 strain units.
    if let Some(v) = s.number("start_strain")? {
        settings.start_strain = v;
    }
    if let Some(v) = s.number("window_factor")? {
        if !(v > 1.0 && v <= 100.0) {
            return Err(s
                .error(
                    "window_factor",
                    "the window ends at window_factor × its start: expected a number in (1, 100]",
                )
                .into());
        }
        settings.window_factor = v;
    }
    if let Some(frames) = s.count("frames", 2)? {
        if frames > 1000 {
            return Err(s
                .error("frames", "expected a whole number of frames, 2 to 1000")
                .into());
        }
        settings.frames = frames;
    }
    match s.choice("precision", &["single", "double"])? {
        Some("single") => settings.precision = Precision::Single,
        Some(_) => settings.precision = Precision::Double,
        None => {}
    }
    let stresses = s.numbers("stresses")?;
    let mut fixed = CellParameters::default();
    for name in PARAMETER_NAMES {
        let Some(v) = s.number(name)? else {
            continue;
        };
        if inputs.iter().any(|i| i == name) {
            return Err(s
                .error(
                    name,
                    "this parameter is in [parameters]; fix it here or calibrate it, not both",
                )
                .into());
        }
        let positive = matches!(name, "kLink" | "viscosityRatio");
        if v < 0.0 || (positive && v == 0.0) {
            return Err(s
                .error(
                    name,
                    if positive {
                        "must be a positive number"
                    } else {
                        "must be a non-negative number"
                    },
                )
                .into());
        }
        fixed
            .set(name, v)
            .map_err(|e| s.error(name, e.to_string()))?;
    }
    s.finish()?;
    settings.fixed = fixed;
    let stresses = match stresses {
        Some(s) => s,
        None => stresses_from_likelihood(file, study_path, likelihood)?,
    };
    RbcShearModel::new(inputs, stresses, settings).map_err(|e| {
        let message = match &e {
            RbcError::InvalidParameter {
                name,
                value,
                reason,
            } => format!("{file}: section `[model]`: invalid value {value} for `{name}`: {reason}"),
            other => format!("{file}: section `[model]`: {other}"),
        };
        input_error(message).with_source(e)
    })
}

/// The stresses of `[likelihood] data = { file, x, x_range }`.
fn stresses_from_likelihood(
    file: &str,
    study_path: &Path,
    likelihood: Option<&toml::Table>,
) -> Result<Vec<f64>> {
    // Only the keys needed here; `[likelihood]` is checked whole where it is read.
    let mut l = StudySection::optional(likelihood, "likelihood", file);
    let Some(mut data) = l.section("data", "{ file, x, y, y_err, x_range }")? else {
        return Err(input_error(format!(
            "{file}: key `model.stresses`: missing; give `stresses = [...]` (Pa) or a `[likelihood] data = {{ file, x }}` table"
        )));
    };
    let Some(data_file) = data.string("file")? else {
        return Err(data.error("file", "missing (the data file's path)").into());
    };
    let Some(x) = data.string("x")? else {
        return Err(data.error("x", "missing (the stress column)").into());
    };
    let range = match data.numbers("x_range")? {
        None => (f64::NEG_INFINITY, f64::INFINITY),
        Some(r) if r.len() == 2 => (r[0], r[1]),
        Some(_) => return Err(data.error("x_range", "expected [lower, upper]").into()),
    };
    let data_file = data_file.as_str();
    let x = x.as_str();
    let relative = study_path
        .parent()
        .unwrap_or(Path::new("."))
        .join(data_file);
    let path = if relative.exists() {
        relative
    } else {
        PathBuf::from(data_file)
    };
    let table = read_numeric_csv(&path, false)?;
    let column = table.column_index(x, &path)?;
    let stresses: Vec<f64> = table
        .rows
        .iter()
        .map(|r| r[column])
        .filter(|s| *s >= range.0 && *s <= range.1)
        .collect();
    if stresses.is_empty() {
        return Err(input_error(format!(
            "{}: no value of column `{x}` lies within x_range",
            path.display()
        )));
    }
    Ok(stresses)
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use iuq_core::Model;

    use crate::study::Study;

    fn parse(text: &str) -> crate::error::Result<Study> {
        // The study "lives" in this crate's directory, so `../../data/...` finds the repo's data.
        Study::parse(
            text,
            &Path::new(env!("CARGO_MANIFEST_DIR")).join("study.toml"),
        )
    }

    const HEALTHY: &str = r#"
name = "rbc-healthy"
[parameters]
kLink = { uniform = [10, 300] }
kBend = { uniform = [50, 400] }
viscosityRatio = { uniform = [1, 15] }
[likelihood]
data = { file = "../../data/ektacytometry_gutierrez2018.csv", x = "stress_pa", y = "el_healthy", y_err = "el_healthy_err", x_range = [0.64, 9.04] }
[model]
kind = "rbc-shear"
"#;

    #[test]
    fn the_stresses_come_from_the_likelihood_data() {
        let study = parse(HEALTHY).unwrap();
        let model = study.rbc_shear_model().unwrap();
        assert_eq!(
            model.stresses(),
            [0.64, 0.93, 1.36, 1.99, 2.91, 4.24, 6.19, 9.04]
        );
        assert_eq!(model.input_names(), ["kLink", "kBend", "viscosityRatio"]);
        assert_eq!(model.output_dimension(), 8);
        assert!(study.expression_model().is_err());
    }

    #[test]
    fn explicit_keys_are_read_and_bad_ones_named() {
        let text = HEALTHY.replace(
            "kind = \"rbc-shear\"",
            "kind = \"rbc-shear\"\nprotocol = \"reference\"\nstresses = [1.0, 2.5]\nkArea = 6\nprecision = \"double\"",
        );
        let model = parse(&text).unwrap().rbc_shear_model().unwrap();
        assert_eq!(model.stresses(), [1.0, 2.5]);
        assert_eq!(model.settings().fixed.membrane.k_area, 6.0);
        for (change, key) in [
            ("protocol = \"fast\"", "model.protocol"),
            ("stresses = [-1.0]", "[model]"),
            ("kLink = 20", "model.kLink"),
            ("kVolume = -2", "model.kVolume"),
            ("frame_count = 3", "model.frame_count"),
            ("frames = 1", "model.frames"),
            ("window_factor = 0.5", "model.window_factor"),
            (
                "protocol = \"reference\"\nlattice_shear_rate = 1e-4",
                "model.lattice_shear_rate",
            ),
        ] {
            let text = HEALTHY.replace(
                "kind = \"rbc-shear\"",
                &format!("kind = \"rbc-shear\"\n{change}"),
            );
            let err = parse(&text).unwrap_err();
            let message = err.to_string();
            assert!(err.is_bad_input(), "{message}");
            assert!(
                message.contains(key) && message.contains("study.toml"),
                "{change}: {message}"
            );
        }
        let start = HEALTHY.find("[likelihood]").unwrap();
        let end = HEALTHY.find("[model]").unwrap();
        let no_data = format!("{}{}", &HEALTHY[..start], &HEALTHY[end..]);
        let message = parse(&no_data).unwrap_err().to_string();
        assert!(message.contains("model.stresses"), "{message}");
    }
}
