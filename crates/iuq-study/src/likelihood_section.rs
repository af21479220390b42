//! The `[likelihood]` section of a study: a direct log-density of the parameters, or data and
//! the prediction-error model (docs/methods.md §4).
//!
//! ```toml
//! [likelihood]
//! # either a direct log-density expression of the parameters ...
//! log_density = "-(100*(y - x^2)^2 + (x - 1)^2)"
//! # ... or data and the prediction-error model:
//! data = { file = "data/ekta.csv", x = "stress_pa", y = "el_healthy", y_err = "el_healthy_err", x_range = [0.64, 9.04] }
//! modelling_error = { uniform = [0.001, 0.1] }   # default; `false` leaves σ_m out
//! measurement_error = true                        # use y_err (default true)
//! computational_error = "relative"                # | "absolute-times-data" | "absolute" | "none"
//! prediction = "a + b*x"                          # optional, see below
//! ```
//!
//! The data file is a CSV with a header; its path is relative to the study file's directory.
//! Rows whose `x` lies outside `x_range` (inclusive) are dropped; the remaining rows, in file
//! order, are the data points j = 1..n.
//!
//! **Which model output is compared with which datum.** Output j of the model is compared with
//! data point j, by order:
//! - with `prediction = "formula"`, the formula of the parameters and `x` (the data's abscissa)
//!   is evaluated at each data point's x, so output j is f(θ, x_j) (the `[model]` section is then
//!   not used);
//! - otherwise the study's `[model]` (kind = "expression") must have exactly n outputs, and its
//!   j-th output in file order is compared with the j-th data point (e.g. outputs `y1`…`yn`, or
//!   one GP per shear stress in the order of the data file).

use std::path::{Path, PathBuf};

use iuq_basis::{ComputationalError, DEFAULT_MODELLING_ERROR_PRIOR, Observations};
use iuq_core::Prior;

use crate::error::{BadInput, Result, input_error};
use crate::study::Study;
use crate::table_io::read_numeric_csv;

/// The keys the `[likelihood]` section accepts.
pub const LIKELIHOOD_KEYS: [&str; 6] = [
    "log_density",
    "data",
    "modelling_error",
    "measurement_error",
    "computational_error",
    "prediction",
];

/// The keys of `[likelihood] data = { ... }`.
pub const DATA_KEYS: [&str; 5] = ["file", "x", "y", "y_err", "x_range"];

/// A parsed `[likelihood]` section.
#[derive(Debug, Clone)]
pub enum LikelihoodSection {
    /// `log_density = "..."`.
    LogDensity(String),
    /// Data and the prediction-error model.
    Data(DataLikelihood),
}

/// The data-driven likelihood of a study.
#[derive(Debug, Clone)]
pub struct DataLikelihood {
    /// The data file, resolved against the study's directory.
    pub file: PathBuf,
    /// The data file's column of the abscissa (`data.x`).
    pub x_column: String,
    /// The data file's column of the observations (`data.y`).
    pub y_column: String,
    /// The abscissa of each selected data point (file order).
    pub x: Vec<f64>,
    /// The observations (and their measurement errors when `y_err` is given).
    pub observations: Observations,
    /// The prior of σ_m, or `None` when `modelling_error = false`.
    pub modelling_error: Option<Prior>,
    /// Whether the measurement errors enter Σ.
    pub measurement_error: bool,
    /// The computational-error convention.
    pub computational_error: ComputationalError,
    /// The curve formula of the parameters and `x`, when given.
    pub prediction: Option<String>,
}

fn string_of(value: &toml::Value, file: &str, key: &str) -> Result<String> {
    value
        .as_str()
        .map(str::to_string)
        .ok_or_else(|| input_error(format!("{file}: key `{key}`: expected a string")))
}

fn number_of(value: &toml::Value) -> Option<f64> {
    value
        .as_float()
        .or_else(|| value.as_integer().map(|i| i as f64))
}

/// Parse and load the `[likelihood]` section of `study` (reading the data file).
pub fn parse_likelihood(study: &Study) -> Result<LikelihoodSection> {
    let file = study.path.display().to_string();
    let table = study.likelihood.as_ref().ok_or_else(|| {
        input_error(format!(
            "{file}: section `[likelihood]`: missing (give `log_density = \"...\"` or `data = {{ file, x, y, y_err }}`)"
        ))
    })?;
    if let Some(key) = table
        .keys()
        .find(|k| !LIKELIHOOD_KEYS.contains(&k.as_str()))
    {
        return Err(input_error(format!(
            "{file}: key `likelihood.{key}`: unknown key (expected one of {})",
            LIKELIHOOD_KEYS.join(", ")
        )));
    }
    match (table.get("log_density"), table.get("data")) {
        (Some(_), Some(_)) => Err(input_error(format!(
            "{file}: key `likelihood.log_density`: give either `log_density` or `data`, not both"
        ))),
        (None, None) => Err(input_error(format!(
            "{file}: section `[likelihood]`: give `log_density = \"...\"` or `data = {{ file, x, y, y_err }}`"
        ))),
        (Some(source), None) => {
            if let Some(key) = table.keys().find(|k| *k != "log_density") {
                return Err(input_error(format!(
                    "{file}: key `likelihood.{key}`: only applies to a data-driven likelihood, not to `log_density`"
                )));
            }
            Ok(LikelihoodSection::LogDensity(string_of(
                source,
                &file,
                "likelihood.log_density",
            )?))
        }
        (None, Some(data)) => Ok(LikelihoodSection::Data(parse_data(
            study, table, data, &file,
        )?)),
    }
}

fn parse_data(
    study: &Study,
    table: &toml::Table,
    data: &toml::Value,
    file: &str,
) -> Result<DataLikelihood> {
    let data = data.as_table().ok_or_else(|| {
        input_error(format!(
            "{file}: key `likelihood.data`: expected a table {{ file, x, y, y_err, x_range }}"
        ))
    })?;
    if let Some(key) = data.keys().find(|k| !DATA_KEYS.contains(&k.as_str())) {
        return Err(input_error(format!(
            "{file}: key `likelihood.data.{key}`: unknown key (expected one of {})",
            DATA_KEYS.join(", ")
        )));
    }
    let required = |key: &str| -> Result<String> {
        let value = data
            .get(key)
            .ok_or_else(|| input_error(format!("{file}: key `likelihood.data.{key}`: missing")))?;
        string_of(value, file, &format!("likelihood.data.{key}"))
    };
    let data_file = required("file")?;
    let x_column = required("x")?;
    let y_column = required("y")?;
    let y_err_column = match data.get("y_err") {
        Some(v) => Some(string_of(v, file, "likelihood.data.y_err")?),
        None => None,
    };
    let x_range = match data.get("x_range") {
        None => None,
        Some(v) => {
            let pair = v
                .as_array()
                .filter(|a| a.len() == 2)
                .and_then(|a| Some((number_of(&a[0])?, number_of(&a[1])?)))
                .ok_or_else(|| {
                    input_error(format!(
                        "{file}: key `likelihood.data.x_range`: expected [lower, upper]"
                    ))
                })?;
            if !(pair.0.is_finite() && pair.1.is_finite() && pair.0 <= pair.1) {
                return Err(input_error(format!(
                    "{file}: key `likelihood.data.x_range`: [{}, {}] must be finite with lower ≤ upper",
                    pair.0, pair.1
                )));
            }
            Some(pair)
        }
    };
    let base = study.path.parent().unwrap_or(Path::new("."));
    let path = base.join(&data_file);
    let table_data = read_numeric_csv(&path, false)
        .map_err(|e| input_error(format!("{file}: key `likelihood.data.file`: {e}")))?;
    let column = |name: &str, key: &str| -> Result<usize> {
        table_data
            .column_index(name, &path)
            .map_err(|e| input_error(format!("{file}: key `likelihood.data.{key}`: {e}")))
    };
    let ix = column(&x_column, "x")?;
    let iy = column(&y_column, "y")?;
    let ie = match &y_err_column {
        Some(c) => Some(column(c, "y_err")?),
        None => None,
    };
    let rows: Vec<&Vec<f64>> = table_data
        .rows
        .iter()
        .filter(|r| x_range.is_none_or(|(lo, hi)| r[ix] >= lo && r[ix] <= hi))
        .collect();
    if rows.is_empty() {
        return Err(input_error(format!(
            "{file}: key `likelihood.data`: no data point of {} lies in x_range",
            path.display()
        )));
    }
    let observations = Observations {
        values: rows.iter().map(|r| r[iy]).collect(),
        measurement_std: ie.map(|ie| rows.iter().map(|r| r[ie]).collect()),
    };
    observations
        .validate()
        .bad_input(|| format!("{file}: key `likelihood.data` ({})", path.display()))?;

    let modelling_error = match table.get("modelling_error") {
        None => Some(DEFAULT_MODELLING_ERROR_PRIOR),
        Some(toml::Value::Boolean(false)) => None,
        Some(toml::Value::Boolean(true)) => Some(DEFAULT_MODELLING_ERROR_PRIOR),
        Some(value) => {
            let prior: Prior = value.clone().try_into().bad_input(|| {
                format!(
                    "{file}: key `likelihood.modelling_error`: expected a prior such as {{ uniform = [0.001, 0.1] }}, or false"
                )
            })?;
            prior
                .validate("sigma_m")
                .bad_input(|| format!("{file}: key `likelihood.modelling_error`"))?;
            if prior.support().0 < 0.0 {
                return Err(input_error(format!(
                    "{file}: key `likelihood.modelling_error`: the prior of sigma_m must not allow negative values"
                )));
            }
            Some(prior)
        }
    };
    let measurement_error = match table.get("measurement_error") {
        None => true,
        Some(v) => v.as_bool().ok_or_else(|| {
            input_error(format!(
                "{file}: key `likelihood.measurement_error`: expected true or false"
            ))
        })?,
    };
    let computational_error = match table.get("computational_error") {
        None => ComputationalError::default(),
        Some(v) => {
            let name = string_of(v, file, "likelihood.computational_error")?;
            ComputationalError::from_name(&name).ok_or_else(|| {
                input_error(format!(
                    "{file}: key `likelihood.computational_error`: unknown convention `{name}` (one of {})",
                    ComputationalError::ALL.map(|c| c.name()).join(", ")
                ))
            })?
        }
    };
    let prediction = match table.get("prediction") {
        None => None,
        Some(v) => Some(string_of(v, file, "likelihood.prediction")?),
    };
    Ok(DataLikelihood {
        file: path,
        x_column: x_column.clone(),
        y_column: y_column.clone(),
        x: rows.iter().map(|r| r[ix]).collect(),
        observations,
        modelling_error,
        measurement_error,
        computational_error,
        prediction,
    })
}
