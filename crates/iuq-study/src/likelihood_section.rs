//! The `[likelihood]` section of a study: a direct log-density of the parameters, or data and
//! the prediction-error model (docs/methods.md §4).
//!
//! ```toml
//! [likelihood]
//! # either a direct log-density expression of the parameters ...
//! log_density = "-(100*(y - x^2)^2 + (x - 1)^2)"
//! # ... or data and the prediction-error model:
//! data = { file = "data/ekta.csv", x = "stress_pa", y = "el_healthy", y_err = "el_healthy_err", x_range = [0.64, 9.04] }
//! modelling_error = { uniform = [0.001, 0.1] }   # optional: σ_m, relative to the data
//! measurement_error = true                        # use y_err (default true)
//! computational_error = "absolute"                # default; | "relative" | "absolute-times-data" | "none"
//! prediction = "a + b*x"                          # optional, see below
//! ```
//!
//! **Defaults.** With `data = { file, x, y, y_err }` alone the likelihood is exactly
//! N(y | model(θ), diag(y_err²)): no modelling error unless a `modelling_error` prior is given
//! (σ_m, sampled with θ, adds σ_m²·y_j² to each variance), and a computational std s_j of the
//! model (a surrogate's predictive std while it stands in for the model) adds s_j²
//! (`"absolute"`). The red-cell study's likelihood names its keys: `modelling_error =
//! { uniform = [0.001, 0.1] }` and `computational_error = "relative"`. Without `y_err` (or with
//! `measurement_error = false`) a `modelling_error` prior is required: the likelihood would have
//! no spread.
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

use iuq_basis::{ComputationalError, Observations};
use iuq_core::Prior;

use iuq_study_file::StudySection;

use crate::error::{BadInput, Result, input_error};
use crate::study::Study;
use crate::table_io::read_numeric_csv;

/// The bounds of the modelling-error prior the messages suggest (the red-cell study's,
/// U(0.001, 0.1): 0.1 % to 10 % of each datum).
const MODELLING_ERROR_EXAMPLE: (f64, f64) = (0.001, 0.1);

/// The keys of a data-driven `[likelihood]` besides `data`.
const DATA_LIKELIHOOD_KEYS: [&str; 4] = [
    "modelling_error",
    "measurement_error",
    "computational_error",
    "prediction",
];

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

/// Parse and load the `[likelihood]` section of `study` (reading the data file).
pub fn parse_likelihood(study: &Study) -> Result<LikelihoodSection> {
    let file = study.path.display().to_string();
    let Some(table) = study.likelihood.as_ref() else {
        return Err(input_error(format!(
            "{file}: section `[likelihood]`: missing (give `log_density = \"...\"` or `data = {{ file, x, y, y_err }}`)"
        )));
    };
    let mut s = StudySection::new(table, "likelihood", &file);
    let log_density = s.string("log_density")?;
    let data = s.section("data", "{ file, x, y, y_err, x_range }")?;
    match (log_density, data) {
        (Some(_), Some(_)) => Err(s
            .error(
                "log_density",
                "give either `log_density` or `data`, not both",
            )
            .into()),
        (None, None) => {
            // A misspelt `log_density` or `data` is named as such.
            s.allow(&DATA_LIKELIHOOD_KEYS);
            s.finish()?;
            Err(s
                .section_error("give `log_density = \"...\"` or `data = { file, x, y, y_err }`")
                .into())
        }
        (Some(log_density), None) => {
            if let Some(key) = table.keys().find(|k| *k != "log_density") {
                return Err(s
                    .error(
                        key,
                        "only applies to a data-driven likelihood, not to `log_density`",
                    )
                    .into());
            }
            Ok(LikelihoodSection::LogDensity(log_density))
        }
        (None, Some(data)) => Ok(LikelihoodSection::Data(parse_data(study, s, data)?)),
    }
}

/// Read `data = { ... }` and the prediction-error keys of `[likelihood]` (`s`).
fn parse_data(
    study: &Study,
    mut s: StudySection<'_>,
    mut data: StudySection<'_>,
) -> Result<DataLikelihood> {
    let mut required = |key: &str| -> Result<String> {
        match data.string(key)? {
            Some(v) => Ok(v),
            None => Err(data.error(key, "missing").into()),
        }
    };
    let data_file = required("file")?;
    let x_column = required("x")?;
    let y_column = required("y")?;
    let y_err_column = data.string("y_err")?;
    let x_range = match data.numbers("x_range")? {
        None => None,
        Some(v) if v.len() == 2 && v[0] <= v[1] => Some((v[0], v[1])),
        Some(v) => {
            return Err(data
                .error(
                    "x_range",
                    format!("expected [lower, upper] with lower ≤ upper, found {v:?}"),
                )
                .into());
        }
    };
    data.finish()?;
    let file = s.file();
    let base = study.path.parent().unwrap_or(Path::new("."));
    let path = base.join(&data_file);
    let table_data = read_numeric_csv(&path, false).map_err(|e| {
        input_error(format!("{file}: key `likelihood.data.file`: {e}")).with_source(e)
    })?;
    let column = |name: &str, key: &str| -> Result<usize> {
        table_data.column_index(name, &path).map_err(|e| {
            input_error(format!("{file}: key `likelihood.data.{key}`: {e}")).with_source(e)
        })
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

    let modelling_error = match s.value("modelling_error") {
        None | Some(toml::Value::Boolean(false)) => None,
        Some(toml::Value::Boolean(true)) => {
            return Err(s
                .error(
                    "modelling_error",
                    format!(
                        "name the prior of sigma_m (relative to the data), e.g. {{ uniform = [{}, {}] }} (the red-cell study's), or false",
                        MODELLING_ERROR_EXAMPLE.0, MODELLING_ERROR_EXAMPLE.1
                    ),
                )
                .into());
        }
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
                return Err(s
                    .error(
                        "modelling_error",
                        "the prior of sigma_m must not allow negative values",
                    )
                    .into());
            }
            Some(prior)
        }
    };
    let measurement_error = s.boolean("measurement_error")?.unwrap_or(true);
    if modelling_error.is_none() && !(measurement_error && observations.measurement_std.is_some()) {
        let missing = if observations.measurement_std.is_none() {
            "the data give no measurement stds (`data.y_err`)"
        } else {
            "`measurement_error = false` leaves the measurement stds out"
        };
        return Err(s
            .error(
                "modelling_error",
                format!(
                    "missing: {missing} and no modelling error is given, so the likelihood has no spread; give `data.y_err`, or a prior of sigma_m relative to the data such as {{ uniform = [{}, {}] }}",
                    MODELLING_ERROR_EXAMPLE.0, MODELLING_ERROR_EXAMPLE.1
                ),
            )
            .into());
    }
    let names = ComputationalError::ALL.map(|c| c.name());
    let computational_error = match s.choice("computational_error", &names)? {
        None => ComputationalError::Absolute,
        Some(name) => ComputationalError::from_name(name).ok_or_else(|| {
            s.error(
                "computational_error",
                format!("unknown convention `{name}`"),
            )
        })?,
    };
    let prediction = s.string("prediction")?;
    s.finish()?;
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
