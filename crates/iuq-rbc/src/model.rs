//! The `rbc-shear` [`Model`]: the shear experiment at each stress of the study's data.
//!
//! Inputs are any of `kLink`, `kBend`, `viscosityRatio`, `kArea`, `kVolume` (the study's
//! parameter names); the others keep fixed values (HemoCell's defaults unless set). Outputs are
//! the mean elongation index at each shear stress, with the sample standard deviation of the
//! measuring window as computational std. A point fails, with the reason, when any of its runs
//! fails (non-finite values, no ellipse, or a strain past a force singularity under
//! `past_singularity = "fail"`) or its parameters are out of range.
//!
//! The runs of a batch (points × stresses) are spread over rayon's threads; each run uses one
//! thread when there are at least as many runs as threads, and all threads (for its fluid
//! update) otherwise. Results do not depend on the thread count.

use rayon::prelude::*;

use iuq_core::{CoreError, Evaluation, EvaluationFailure, Model, Outcome};

use crate::error::{RbcError, Result};
use crate::lattice::Precision;
use crate::membrane_forces::{MembraneParameters, PastSingularity};
use crate::protocol::{
    FRAMES, MeshOrientation, Protocol, START_STRAIN, ShearExperiment, WINDOW_FACTOR, run_shear,
};

/// Names of the parameters the model understands, in HemoCell's spelling.
pub const PARAMETER_NAMES: [&str; 5] = ["kLink", "kBend", "viscosityRatio", "kArea", "kVolume"];

/// Values of all five parameters (the fixed ones and the defaults of the varied ones).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CellParameters {
    /// Membrane coefficients.
    pub membrane: MembraneParameters,
    /// Interior/exterior viscosity ratio Λ.
    pub viscosity_ratio: f64,
}

impl Default for CellParameters {
    /// HemoCell's defaults: kLink 15, kBend 80, Λ 5, kArea 5, kVolume 20.
    fn default() -> Self {
        Self {
            membrane: MembraneParameters::default(),
            viscosity_ratio: 5.0,
        }
    }
}

impl CellParameters {
    /// The value of the parameter called `name` (one of [`PARAMETER_NAMES`]): the one place that
    /// maps HemoCell's names onto the fields.
    fn slot(&mut self, name: &str) -> Result<&mut f64> {
        Ok(match name {
            "kLink" => &mut self.membrane.k_link,
            "kBend" => &mut self.membrane.k_bend,
            "viscosityRatio" => &mut self.viscosity_ratio,
            "kArea" => &mut self.membrane.k_area,
            "kVolume" => &mut self.membrane.k_volume,
            other => {
                return Err(RbcError::InvalidData(format!(
                    "unknown parameter `{other}` (the rbc-shear model knows {})",
                    PARAMETER_NAMES.join(", ")
                )));
            }
        })
    }

    /// Set the parameter called `name` (one of [`PARAMETER_NAMES`]).
    pub fn set(&mut self, name: &str, value: f64) -> Result<()> {
        *self.slot(name)? = value;
        Ok(())
    }

    /// The value of the parameter called `name` (one of [`PARAMETER_NAMES`]).
    pub fn get(&self, name: &str) -> Result<f64> {
        let mut copy = *self;
        copy.slot(name).map(|v| *v)
    }
}

/// How the model simulates.
#[derive(Debug, Clone, PartialEq)]
pub struct RbcShearSettings {
    /// Time discretisation (scaled by default).
    pub protocol: Protocol,
    /// Values of the parameters that are not inputs.
    pub fixed: CellParameters,
    /// Storage precision of the fluid.
    pub precision: Precision,
    /// Strain at the start of the measuring window (7.5; shorter only for quick tests).
    pub start_strain: f64,
    /// Recorded shapes per run (10).
    pub frames: usize,
    /// The measuring window ends at this factor × its start (1.25).
    pub window_factor: f64,
    /// Whether a strain past a force singularity carries on as HemoCell does (the default) or
    /// fails the run.
    pub past_singularity: PastSingularity,
    /// How the mesh starts in the disk plane.
    pub orientation: MeshOrientation,
}

impl Default for RbcShearSettings {
    fn default() -> Self {
        Self {
            protocol: Protocol::default(),
            fixed: CellParameters::default(),
            precision: Precision::default(),
            start_strain: START_STRAIN,
            window_factor: WINDOW_FACTOR,
            frames: FRAMES,
            past_singularity: PastSingularity::default(),
            orientation: MeshOrientation::default(),
        }
    }
}

/// The single-cell shear simulator as a batch model.
#[derive(Debug, Clone)]
pub struct RbcShearModel {
    inputs: Vec<String>,
    outputs: Vec<String>,
    stresses: Vec<f64>,
    settings: RbcShearSettings,
}

impl RbcShearModel {
    /// A model over the named inputs (a subset of [`PARAMETER_NAMES`], in the order the points
    /// use) with one output per shear stress (Pa).
    pub fn new(
        inputs: Vec<String>,
        stresses: Vec<f64>,
        settings: RbcShearSettings,
    ) -> Result<Self> {
        if inputs.is_empty() {
            return Err(RbcError::InvalidData(
                "the rbc-shear model needs at least one input".into(),
            ));
        }
        for (i, name) in inputs.iter().enumerate() {
            if !PARAMETER_NAMES.contains(&name.as_str()) {
                return Err(RbcError::InvalidData(format!(
                    "unknown parameter `{name}` (the rbc-shear model knows {})",
                    PARAMETER_NAMES.join(", ")
                )));
            }
            if inputs[..i].contains(name) {
                return Err(RbcError::InvalidData(format!(
                    "parameter `{name}` given twice"
                )));
            }
        }
        if stresses.is_empty() {
            return Err(RbcError::InvalidData(
                "the rbc-shear model needs at least one shear stress".into(),
            ));
        }
        for &s in &stresses {
            if !(s.is_finite() && s > 0.0) {
                return Err(RbcError::invalid(
                    "stress",
                    s,
                    "must be a positive number of pascals",
                ));
            }
        }
        // Check the fixed values, the protocol and the stresses (the inputs take valid
        // defaults here; they are checked per point).
        let mut probe = settings.fixed;
        let defaults = CellParameters::default();
        for name in &inputs {
            probe.set(name, defaults.get(name)?)?;
        }
        let model = Self {
            inputs,
            outputs: Vec::new(),
            stresses,
            settings,
        };
        for &s in &model.stresses {
            model.experiment(&probe, s).validate()?;
        }
        let Self {
            inputs,
            stresses,
            settings,
            ..
        } = model;
        let outputs = stresses.iter().map(|s| format!("EL({s}Pa)")).collect();
        Ok(Self {
            inputs,
            outputs,
            stresses,
            settings,
        })
    }

    /// The shear stresses, in output order.
    pub fn stresses(&self) -> &[f64] {
        &self.stresses
    }

    /// The settings.
    pub fn settings(&self) -> &RbcShearSettings {
        &self.settings
    }

    /// The cell parameters of a point.
    pub fn cell_parameters(&self, point: &[f64]) -> Result<CellParameters> {
        let mut p = self.settings.fixed;
        for (name, &v) in self.inputs.iter().zip(point) {
            p.set(name, v)?;
        }
        Ok(p)
    }

    /// The experiment of one point at one stress.
    pub fn experiment(&self, cell: &CellParameters, stress: f64) -> ShearExperiment {
        ShearExperiment {
            protocol: self.settings.protocol,
            start_strain: self.settings.start_strain,
            window_factor: self.settings.window_factor,
            frames: self.settings.frames,
            precision: self.settings.precision,
            past_singularity: self.settings.past_singularity,
            orientation: self.settings.orientation,
            ..ShearExperiment::new(cell.membrane, cell.viscosity_ratio, stress)
        }
    }
}

impl Model for RbcShearModel {
    fn input_names(&self) -> &[String] {
        &self.inputs
    }

    fn output_names(&self) -> &[String] {
        &self.outputs
    }

    fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
        for p in points {
            if p.len() != self.inputs.len() {
                return Err(CoreError::DimensionMismatch {
                    expected: self.inputs.len(),
                    actual: p.len(),
                });
            }
        }
        // Check every point first; runs only for the valid ones.
        let cells: Vec<std::result::Result<CellParameters, EvaluationFailure>> = points
            .iter()
            .map(|p| {
                let cell = self
                    .cell_parameters(p)
                    .map_err(|e| EvaluationFailure::new(e.to_string()))?;
                for &s in &self.stresses {
                    self.experiment(&cell, s)
                        .validate()
                        .map_err(|e| EvaluationFailure::new(e.to_string()))?;
                }
                Ok(cell)
            })
            .collect();
        let runs: Vec<(usize, usize, CellParameters)> = cells
            .iter()
            .enumerate()
            .filter_map(|(i, c)| c.as_ref().ok().map(|cell| (i, *cell)))
            .flat_map(|(i, cell)| (0..self.stresses.len()).map(move |k| (i, k, cell)))
            .collect();
        let parallel_inside = runs.len() < rayon::current_num_threads();
        let results: Vec<Result<(f64, f64)>> = runs
            .par_iter()
            .map(|(_, k, cell)| {
                let mut experiment = self.experiment(cell, self.stresses[*k]);
                experiment.parallel = parallel_inside;
                run_shear(&experiment).map(|r| (r.el_mean, r.el_std))
            })
            .collect();
        let mut outcomes: Vec<Outcome> = cells
            .iter()
            .map(|c| match c {
                Ok(_) => Ok(Evaluation::with_std(
                    vec![0.0; self.stresses.len()],
                    vec![0.0; self.stresses.len()],
                )),
                Err(f) => Err(f.clone()),
            })
            .collect();
        for (&(i, k, _), result) in runs.iter().zip(results) {
            let outcome = &mut outcomes[i];
            match (outcome.as_mut(), result) {
                (Ok(evaluation), Ok((mean, std))) => {
                    evaluation.outputs[k] = mean;
                    if let Some(stds) = evaluation.computational_std.as_mut() {
                        stds[k] = std;
                    }
                }
                (Ok(_), Err(e)) => {
                    *outcome = Err(EvaluationFailure::new(format!(
                        "at {} Pa: {e}",
                        self.stresses[k]
                    )));
                }
                // A failure at an earlier stress is kept.
                (Err(_), _) => {}
            }
        }
        Ok(outcomes
            .into_iter()
            .map(iuq_core::model::reject_non_finite)
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn every_parameter_name_reads_back_what_was_set() {
        let mut c = CellParameters::default();
        for (k, name) in PARAMETER_NAMES.iter().enumerate() {
            c.set(name, 10.0 + k as f64).unwrap();
        }
        for (k, name) in PARAMETER_NAMES.iter().enumerate() {
            assert_eq!(c.get(name).unwrap(), 10.0 + k as f64, "{name}");
        }
        assert_eq!(c.membrane.k_volume, 14.0);
        assert_eq!(c.viscosity_ratio, 12.0);
        assert!(c.get("kLnk").is_err() && c.set("kLnk", 1.0).is_err());
    }

    #[test]
    fn construction_checks_names_and_stresses() {
        let s = RbcShearSettings::default();
        assert!(RbcShearModel::new(names(&["kLink", "kBend"]), vec![1.0], s.clone()).is_ok());
        assert!(RbcShearModel::new(names(&["kLnk"]), vec![1.0], s.clone()).is_err());
        assert!(RbcShearModel::new(names(&["kLink", "kLink"]), vec![1.0], s.clone()).is_err());
        assert!(RbcShearModel::new(names(&["kLink"]), vec![], s.clone()).is_err());
        assert!(RbcShearModel::new(names(&["kLink"]), vec![-1.0], s.clone()).is_err());
        let m = RbcShearModel::new(
            names(&["kLink", "kBend", "viscosityRatio"]),
            vec![0.64, 1.36],
            s,
        )
        .unwrap();
        assert_eq!(m.output_names(), ["EL(0.64Pa)", "EL(1.36Pa)"]);
        let c = m.cell_parameters(&[36.7, 367.0, 5.9]).unwrap();
        assert_eq!(c.membrane.k_link, 36.7);
        assert_eq!(c.membrane.k_area, 5.0);
        assert_eq!(c.viscosity_ratio, 5.9);
    }

    #[test]
    fn invalid_points_fail_with_a_reason_and_wrong_dimensions_fail_the_batch() {
        let m = RbcShearModel::new(
            names(&["kLink", "kBend", "viscosityRatio"]),
            vec![1.0],
            RbcShearSettings::default(),
        )
        .unwrap();
        let out = m.evaluate_batch(&[vec![-3.0, 80.0, 5.0]]).unwrap();
        let reason = out[0].as_ref().unwrap_err().reason.clone();
        assert!(reason.contains("kLink"), "{reason}");
        assert!(m.evaluate_batch(&[vec![1.0, 2.0]]).is_err());
    }
}
