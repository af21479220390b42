//! The cell model as a campaign: every `rbc-shear` run of a pipeline is one `iuq rbc shear`
//! process of the campaign executor (local, Slurm or HyperQueue), so runs survive crashes and
//! restarts, run on a cluster when the study says so, and are stored once in the campaign's
//! SQLite file, where later pipelines (and fresh clones of a repository that ships the file)
//! find them.
//!
//! The campaign's parameters are the study's calibrated parameters plus `stress` (Pa); its
//! outputs are `el`, the run's mean elongation index with the frames' standard deviation as the
//! computational std, and `el_drift`, the least-squares change of the frames' index over the
//! window (a diagnostic the report shows per stress). The command is machine-independent (`iuq` names the iuq executable, see
//! `iuq_campaign::worker::iuq_executable`), so the store's model hash is the same on every
//! machine. With the local executor the runs are computed in this process
//! ([`CellModelRuns`]), with the same result as the command's.

use std::path::Path;

use toml::{Table, Value};

use iuq_campaign::{InProcessError, InProcessModel, InProcessOutputs};
use iuq_rbc::{RbcShearModel, run_shear};

use super::campaign_text::campaign_text;
use crate::error::{Result, input_error};
use crate::study::{ModelSection, Study};

/// Name of the stress parameter of the campaign.
pub const STRESS: &str = "stress";

/// Command-line flag of `iuq rbc shear` for each model parameter the study may calibrate or fix.
const PARAMETER_FLAGS: [(&str, &str); 5] = [
    ("kLink", "--klink"),
    ("kBend", "--kbend"),
    ("viscosityRatio", "--viscosity-ratio"),
    ("kArea", "--karea"),
    ("kVolume", "--kvolume"),
];

/// Keys of the `[model]` section of kind `rbc-shear` passed on to `iuq rbc shear`.
const SETTING_FLAGS: [(&str, &str); 7] = [
    ("protocol", "--protocol"),
    ("initial_orientation", "--initial-orientation"),
    ("lattice_shear_rate", "--lattice-shear-rate"),
    ("precision", "--precision"),
    ("start_strain", "--start-strain"),
    ("window_factor", "--window-factor"),
    ("frames", "--frames"),
];

/// The campaign's outputs: the quantity of interest, then the elongation's drift over the
/// measuring window (a diagnostic: how far the shape still moves while it is measured).
pub const CAMPAIGN_OUTPUTS: [&str; 2] = ["el", "el_drift"];

fn value_text(v: &Value) -> Option<String> {
    match v {
        Value::String(s) => Some(s.clone()),
        Value::Integer(i) => Some(i.to_string()),
        Value::Float(f) => Some(f.to_string()),
        _ => None,
    }
}

/// The text of the campaign study that runs `study`'s cell model at the given stresses.
pub fn campaign_study_text(study: &Study, stresses: &[f64]) -> Result<String> {
    let file = study.path.display().to_string();
    let ModelSection::RbcShear { table } = &study.model else {
        return Err(input_error(format!(
            "{file}: key `model.kind`: `iuq pipeline` builds the calibration study of the cell model; expected kind = \"rbc-shear\""
        )));
    };
    let (lo, hi) = stresses
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), s| (a.min(*s), b.max(*s)));
    if stresses.is_empty() || stresses.iter().any(|s| !s.is_finite() || *s <= 0.0) {
        return Err(input_error(format!(
            "{file}: section `[likelihood]`: no positive shear stress selected from the data"
        )));
    }
    let mut stress = Table::new();
    stress.insert(
        "uniform".into(),
        Value::Array(vec![Value::Float(0.5 * lo), Value::Float(2.0 * hi)]),
    );

    let mut command: Vec<Value> = ["iuq", "rbc", "shear", "--json"]
        .iter()
        .map(|s| Value::String((*s).into()))
        .collect();
    let mut push = |flag: &str, value: String| {
        command.push(Value::String(flag.into()));
        command.push(Value::String(value));
    };
    for (name, flag) in PARAMETER_FLAGS {
        if study.space.index_of(name).is_some() {
            push(flag, format!("{{{{ {name} }}}}"));
        } else if let Some(v) = table.get(name).and_then(value_text) {
            push(flag, v);
        }
    }
    for (key, flag) in SETTING_FLAGS {
        if let Some(v) = table.get(key).and_then(value_text) {
            push(flag, v);
        }
    }
    // Always named: the store's model hash then says how the runs treated a strain past a
    // force singularity, whatever the default of the `iuq` that made them.
    let past_singularity = study.rbc_shear_model()?.settings().past_singularity;
    push("--past-singularity", past_singularity.name().to_string());
    push("--stress", format!("{{{{ {STRESS} }}}}"));

    let mut model = Table::new();
    model.insert("kind".into(), Value::String("command".into()));
    model.insert("command".into(), Value::Array(command));
    model.insert(
        "outputs".into(),
        Value::Array(
            CAMPAIGN_OUTPUTS
                .iter()
                .map(|s| Value::String((*s).into()))
                .collect(),
        ),
    );
    let mut keys = Table::new();
    for name in CAMPAIGN_OUTPUTS {
        keys.insert(name.into(), Value::String(format!("/{name}")));
    }
    let mut output = Table::new();
    output.insert(
        "file".into(),
        Value::String(iuq_campaign::run_directory::STDOUT_FILE.into()),
    );
    output.insert("format".into(), Value::String("json".into()));
    output.insert("keys".into(), Value::Table(keys));
    model.insert("output".into(), Value::Table(output));
    model.insert("timeout".into(), Value::String("6h".into()));
    // One thread per run: the executor runs as many runs at once as there are cores, and a run's
    // result does not depend on its thread count.
    let mut env = Table::new();
    env.insert("RAYON_NUM_THREADS".into(), Value::String("1".into()));
    model.insert("env".into(), Value::Table(env));

    campaign_text(
        study,
        "Cell-model runs",
        Some((STRESS.to_string(), Value::Table(stress))),
        model,
    )
}

/// The name of the output at stress `s` (Pa).
pub fn output_name(s: f64) -> String {
    format!("el_{s}Pa")
}

/// The native cell model evaluated in this process: a run's inputs are the study's calibrated
/// parameters, then the stress; its outputs are the mean elongation index over the measuring
/// window, with the frames' standard deviation as the computational std, and the drift over the
/// window — what `iuq rbc shear --json` prints for the same settings.
pub struct CellModelRuns {
    model: RbcShearModel,
    parameters: usize,
}

/// The in-process runs of `study`'s cell model (the keys of its `[model]`).
pub(super) fn cell_model_runs(study: &Study, stresses: &[f64]) -> Result<CellModelRuns> {
    if stresses.is_empty() {
        return Err(input_error(format!(
            "{}: section `[likelihood]`: no shear stress selected from the data",
            study.path.display()
        )));
    }
    Ok(CellModelRuns {
        model: study.rbc_shear_model()?,
        parameters: study.space.dimension(),
    })
}

impl InProcessModel for CellModelRuns {
    fn evaluate(
        &self,
        parameters: &[f64],
    ) -> std::result::Result<InProcessOutputs, InProcessError> {
        self.run(parameters).map_err(InProcessError::Failed)
    }
}

impl CellModelRuns {
    fn run(&self, parameters: &[f64]) -> std::result::Result<InProcessOutputs, String> {
        let d = self.parameters;
        let (theta, stress) = match parameters {
            [theta @ .., stress] if theta.len() == d => (theta, *stress),
            _ => {
                return Err(format!(
                    "expected {d} parameters and the stress, got {} values",
                    parameters.len()
                ));
            }
        };
        let cell = self
            .model
            .cell_parameters(theta)
            .map_err(|e| e.to_string())?;
        let experiment = self.model.experiment(&cell, stress);
        experiment.validate().map_err(|e| e.to_string())?;
        let result = run_shear(&experiment).map_err(|e| e.to_string())?;
        Ok((
            vec![result.el_mean, result.el_drift()],
            Some(vec![result.el_std, 0.0]),
        ))
    }
}

/// The campaign directory of `study`: `executor.directory` (relative to the study file), else
/// `<study stem>.campaign` beside the study file.
pub fn campaign_directory(study: &Study) -> std::path::PathBuf {
    let stem = study
        .path
        .file_stem()
        .map_or_else(|| "study".into(), |s| s.to_string_lossy().into_owned());
    study
        .executor
        .as_ref()
        .and_then(|t| t.get("directory"))
        .and_then(Value::as_str)
        .map(|d| study.path.parent().unwrap_or(Path::new(".")).join(d))
        .unwrap_or_else(|| {
            study
                .path
                .parent()
                .unwrap_or(Path::new("."))
                .join(format!("{stem}.campaign"))
        })
}
