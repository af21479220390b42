//! Study files (TOML): the study's `name`, its `[parameters]` with their priors, the `[model]`
//! (expression, rbc-shear, umbridge) and `[sensitivity]`. The sections of the other stages
//! (`[likelihood]`, `[sampler]`, `[surrogate]`, `[model_sampler]`, `[model_posterior]`,
//! `[executor]`, `[design]`) are
//! kept as written and validated by the code that uses them ([`crate::likelihood_section`],
//! [`crate::sampler_section`], [`crate::pipeline`], campaigns).
//!
//! Every error names the file, the key and the reason, and is an input error (exit code 2).

use std::path::{Path, PathBuf};

use iuq_core::{ExpressionModel, Parameter, ParameterSpace, Prior};
use iuq_study_file::StudySection;

use crate::error::{BadInput, Result, input_error};

/// The `[model]` section.
#[derive(Debug, Clone)]
pub enum ModelSection {
    /// `kind = "expression"`: analytic outputs, `outputs = { name = "formula" }` in file order.
    Expression {
        /// Output name → formula over the parameter names.
        outputs: toml::Table,
    },
    /// `kind = "rbc-shear"`: the native single-cell shear simulator
    /// ([`Study::rbc_shear_model`] builds it; keys in [`crate::rbc_section`]).
    RbcShear {
        /// The section as written.
        table: toml::Table,
    },
    /// `kind = "umbridge"`: a model on a UM-Bridge 1.0 server ([`Study::umbridge_model`]
    /// connects to it; keys in [`crate::umbridge_section`]).
    UmBridge(crate::umbridge_section::UmBridgeSection),
    /// `kind = "command"` or `"batch-command"`: a program run once per run (or per batch of
    /// runs) by a campaign; the keys are those of `iuq run` (see `iuq_campaign::study`), read by
    /// the pipeline. Verbs that evaluate a model in this process reject it.
    Command {
        /// The kind as written.
        kind: String,
        /// The section as written, without `abscissa`.
        table: toml::Table,
    },
    /// `kind = "callable"`: a model the program running the study supplies (a Python function
    /// given to `iuq.calibrate`), evaluated in this process; `description` names it in the
    /// campaign store, so that runs of another model are never taken for its runs.
    Callable {
        /// What the model is (the function's name and a digest of its code).
        description: String,
    },
    /// No `[model]` section: allowed for studies whose likelihood needs no model
    /// (`[likelihood] log_density = ...` or a `prediction` formula).
    Absent,
}

/// Model kinds a study file may name.
pub const MODEL_KINDS: [&str; 6] = [
    "expression",
    "rbc-shear",
    "command",
    "batch-command",
    "umbridge",
    "callable",
];

/// The `abscissa` key of `[model]`: the name under which every run receives the data's abscissa
/// (one run per parameter vector and data point). It must not name a parameter.
fn parse_abscissa(model: &mut StudySection<'_>, space: &ParameterSpace) -> Result<Option<String>> {
    let Some(name) = model.string("abscissa")? else {
        return Ok(None);
    };
    let valid = name
        .chars()
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
    if !valid {
        return Err(model
            .error(
                "abscissa",
                format!(
                    "`{name}` is not a name (letters, digits and _, not starting with a digit)"
                ),
            )
            .into());
    }
    if space.index_of(&name).is_some() {
        return Err(model
            .error(
                "abscissa",
                format!(
                    "`{name}` is also a parameter; the abscissa is set by the data, not calibrated"
                ),
            )
            .into());
    }
    Ok(Some(name))
}

/// Read `[model]`: its kind and what that kind needs here (the keys of the cell model, a
/// program and a UM-Bridge server are read by their own sections).
fn parse_model_section(mut model: StudySection<'_>) -> Result<ModelSection> {
    let table = model.table();
    let Some(kind) = model.choice("kind", &MODEL_KINDS)? else {
        return Err(model
            .error(
                "kind",
                format!("missing (one of {})", MODEL_KINDS.join(", ")),
            )
            .into());
    };
    match kind {
        "expression" => {
            let Some(outputs) = model.sub_table("outputs")? else {
                return Err(model
                    .error("outputs", "missing (outputs = { name = \"formula\" })")
                    .into());
            };
            model.finish()?;
            Ok(ModelSection::Expression {
                outputs: outputs.clone(),
            })
        }
        "rbc-shear" => {
            if model.has("abscissa") {
                return Err(model
                    .error(
                        "abscissa",
                        "the cell model's abscissa is the shear stress of the data; remove the key",
                    )
                    .into());
            }
            Ok(ModelSection::RbcShear {
                table: table.clone(),
            })
        }
        "umbridge" => {
            let mut without = table.clone();
            without.remove("abscissa");
            Ok(ModelSection::UmBridge(
                crate::umbridge_section::parse_umbridge_section(&without, model.file())?,
            ))
        }
        "callable" => {
            let description = model.string("description")?.unwrap_or_default();
            model.allow(&["abscissa"]);
            model.finish()?;
            Ok(ModelSection::Callable { description })
        }
        _ => {
            let mut without = table.clone();
            without.remove("abscissa");
            Ok(ModelSection::Command {
                kind: kind.to_string(),
                table: without,
            })
        }
    }
}

/// The `[sensitivity]` section.
#[derive(Debug, Clone, Default)]
pub struct SensitivitySection {
    /// Base points N of the Saltelli design.
    pub n: Option<usize>,
    /// Seed of the scrambling and bootstrap.
    pub seed: Option<u64>,
    /// Independent scramblings for replicate intervals (bootstrap when absent).
    pub replicates: Option<usize>,
    /// Bootstrap resamples.
    pub resamples: Option<usize>,
    /// Confidence level of the intervals.
    pub confidence: Option<f64>,
    /// Base points N of the Saltelli design run on the model itself by `iuq pipeline` (0 or
    /// absent: indices from the surrogate only).
    pub model_n: Option<usize>,
}

impl SensitivitySection {
    /// Read `[sensitivity]` (every key optional).
    fn parse(mut s: StudySection<'_>) -> Result<Self> {
        let section = Self {
            n: s.count("n", 1)?,
            seed: s.seed("seed")?,
            replicates: s.count_in("replicates", 1, iuq_sensitivity::analysis::MAX_REPLICATES)?,
            resamples: s.count_in("resamples", 1, iuq_sensitivity::analysis::MAX_RESAMPLES)?,
            confidence: s.number("confidence")?,
            model_n: s.count_in("model_n", 0, 1 << 20)?,
        };
        s.finish()?;
        Ok(section)
    }
}

/// A study read from a file.
#[derive(Debug, Clone)]
pub struct Study {
    /// The file it was read from.
    pub path: PathBuf,
    /// The study's name.
    pub name: String,
    /// The parameters and priors, in file order.
    pub space: ParameterSpace,
    /// The model section.
    pub model: ModelSection,
    /// `[model] abscissa`: the name under which each run receives the data's abscissa (one run
    /// per parameter vector and data point), or `None` (one run per parameter vector returning
    /// one output per data point). Always `None` for `rbc-shear`, whose abscissa is the stress.
    pub abscissa: Option<String>,
    /// The sensitivity section (defaults when absent).
    pub sensitivity: SensitivitySection,
    /// The `[likelihood]` section as written (read by the inference verbs).
    pub likelihood: Option<toml::Table>,
    /// The `[sampler]` section as written (read by the inference verbs).
    pub sampler: Option<toml::Table>,
    /// The `[surrogate]` section as written (read by `iuq pipeline`).
    pub surrogate: Option<toml::Table>,
    /// The `[model_sampler]` section as written: BASIS directly on the model in `iuq pipeline`.
    pub model_sampler: Option<toml::Table>,
    /// The `[model_posterior]` section as written: how `iuq pipeline --model-posterior` samples
    /// the model's own posterior.
    pub model_posterior: Option<toml::Table>,
    /// The `[executor]` section as written (campaigns of model runs).
    pub executor: Option<toml::Table>,
    /// The `[low_fidelity]` section as written: a cheaper model of the same outputs that helps
    /// the pipeline's surrogate (read by `iuq pipeline`, `pipeline::low_fidelity`).
    pub low_fidelity: Option<toml::Table>,
}

impl Study {
    /// Read and validate a study file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| {
            input_error(format!("{}: cannot read: {e}", path.display())).with_source(e)
        })?;
        Self::parse(&text, path)
    }

    /// Parse and validate study text; `path` names the file in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self> {
        let file = path.display().to_string();
        let root: toml::Table = text.parse().bad_input(|| file.clone())?;
        let mut top = StudySection::new(&root, "", &file);
        let Some(name) = top.string("name")? else {
            return Err(top.error("name", "missing (the study's name)").into());
        };
        if name.trim().is_empty() {
            return Err(top.error("name", "must not be empty").into());
        }
        top.string("description")?;
        let Some(parameter_table) = top.sub_table("parameters")? else {
            return Err(top
                .error(
                    "parameters",
                    "missing (a table of priors, e.g. k = { uniform = [0, 1] })",
                )
                .into());
        };
        let mut parameters = Vec::with_capacity(parameter_table.len());
        for (name, value) in parameter_table {
            let prior: Prior = value.clone().try_into().bad_input(|| {
                format!(
                    "{file}: key `parameters.{name}`: expected a prior such as {{ uniform = [lower, upper] }}, {{ normal = [mean, std] }}, {{ log_normal = [mu, sigma] }} or {{ truncated_normal = [mean, std, lower, upper] }}"
                )
            })?;
            prior
                .validate(name)
                .bad_input(|| format!("{file}: key `parameters.{name}`"))?;
            parameters.push(Parameter {
                name: name.clone(),
                prior,
            });
        }
        let space = ParameterSpace::new(parameters)
            .bad_input(|| format!("{file}: section `[parameters]`"))?;
        let (model, abscissa) = match top.section("model", "{ kind = \"expression\" }")? {
            Some(mut section) => {
                let abscissa = parse_abscissa(&mut section, &space)?;
                (parse_model_section(section)?, abscissa)
            }
            None => (ModelSection::Absent, None),
        };
        let sensitivity = match top.section("sensitivity", "{ n = 1024, seed = 3 }")? {
            Some(section) => SensitivitySection::parse(section)?,
            None => SensitivitySection::default(),
        };
        // Sections of later stages, read by the code that uses them.
        let likelihood = top.sub_table("likelihood")?.cloned();
        let surrogate = top.sub_table("surrogate")?.cloned();
        let sampler = top.sub_table("sampler")?.cloned();
        let model_sampler = top.sub_table("model_sampler")?.cloned();
        let model_posterior = top.sub_table("model_posterior")?.cloned();
        let executor = top.sub_table("executor")?.cloned();
        let low_fidelity = top.sub_table("low_fidelity")?.cloned();
        top.sub_table("design")?;
        top.finish()?;
        let study = Self {
            path: path.to_path_buf(),
            name,
            space,
            model,
            abscissa,
            sensitivity,
            likelihood,
            sampler,
            surrogate,
            model_sampler,
            model_posterior,
            executor,
            low_fidelity,
        };
        if let ModelSection::Expression { .. } = study.model {
            study.expression_model()?;
        }
        if let ModelSection::RbcShear { .. } = study.model {
            study.rbc_shear_model()?;
        }
        Ok(study)
    }

    /// The single-cell shear simulator of a `kind = "rbc-shear"` study, or an input error.
    pub fn rbc_shear_model(&self) -> Result<iuq_rbc::RbcShearModel> {
        let file = self.path.display().to_string();
        match &self.model {
            ModelSection::RbcShear { table } => crate::rbc_section::rbc_shear_model(
                table,
                &file,
                &self.path,
                self.space.names(),
                self.likelihood.as_ref(),
            ),
            _ => Err(input_error(format!(
                "{file}: key `model.kind`: this command needs kind = \"rbc-shear\""
            ))),
        }
    }

    /// The UM-Bridge model of a `kind = "umbridge"` study, connected (an input error for a
    /// server that does not fit the study, a failure for an unreachable one).
    pub fn umbridge_model(&self) -> Result<iuq_umbridge::UmBridgeModel> {
        let file = self.path.display().to_string();
        match &self.model {
            ModelSection::UmBridge(section) => {
                crate::umbridge_section::connect(section, self.model_inputs(), &file)
            }
            _ => Err(input_error(format!(
                "{file}: key `model.kind`: this command needs kind = \"umbridge\""
            ))),
        }
    }

    /// The study's model, whatever its kind (expression, rbc-shear, umbridge), or an input
    /// error when the study has none or one of a kind this version does not build.
    pub fn model(&self) -> Result<StudyModel> {
        let file = self.path.display();
        if let Some(name) = &self.abscissa {
            return Err(input_error(format!(
                "{file}: key `model.abscissa`: this command evaluates the model at parameter vectors alone; a model that also takes the data's abscissa `{name}` runs through `iuq pipeline`"
            )));
        }
        match &self.model {
            ModelSection::Expression { .. } => Ok(StudyModel::Expression(self.expression_model()?)),
            ModelSection::RbcShear { .. } => Ok(StudyModel::RbcShear(self.rbc_shear_model()?)),
            ModelSection::UmBridge(_) => Ok(StudyModel::UmBridge(self.umbridge_model()?)),
            ModelSection::Command { kind, .. } => Err(input_error(format!(
                "{file}: key `model.kind`: this command evaluates the model in its own process; a model of kind `{kind}` runs through `iuq run` or `iuq pipeline`"
            ))),
            ModelSection::Callable { .. } => Err(input_error(format!(
                "{file}: key `model.kind`: a model of kind `callable` is supplied by the program that runs the study (`iuq.calibrate` in Python), not by a study file alone"
            ))),
            ModelSection::Absent => Err(input_error(format!(
                "{file}: section `[model]`: missing; this command needs a model"
            ))),
        }
    }

    /// The model's inputs: the parameters in file order, then the abscissa when `[model]`
    /// names one.
    pub fn model_inputs(&self) -> Vec<String> {
        let mut names = self.space.names();
        names.extend(self.abscissa.iter().cloned());
        names
    }

    /// The expression model of the study (inputs: [`Study::model_inputs`]), or an input error
    /// if the model is of another kind.
    pub fn expression_model(&self) -> Result<ExpressionModel> {
        let file = self.path.display();
        let outputs = match &self.model {
            ModelSection::Expression { outputs } => outputs,
            ModelSection::Absent => {
                return Err(input_error(format!(
                    "{file}: section `[model]`: missing; this command needs a model of kind = \"expression\""
                )));
            }
            ModelSection::Command { kind, .. } => {
                return Err(input_error(format!(
                    "{file}: key `model.kind`: this command needs kind = \"expression\", not \"{kind}\""
                )));
            }
            ModelSection::RbcShear { .. } => {
                return Err(input_error(format!(
                    "{file}: key `model.kind`: this command needs kind = \"expression\", not \"rbc-shear\""
                )));
            }
            ModelSection::Callable { .. } => {
                return Err(input_error(format!(
                    "{file}: key `model.kind`: this command needs kind = \"expression\", not \"callable\""
                )));
            }
            ModelSection::UmBridge(_) => {
                return Err(input_error(format!(
                    "{file}: key `model.kind`: this command needs kind = \"expression\", not \"umbridge\""
                )));
            }
        };
        if outputs.is_empty() {
            return Err(input_error(format!(
                "{file}: key `model.outputs`: at least one output is needed"
            )));
        }
        let mut formulas = Vec::with_capacity(outputs.len());
        for (name, value) in outputs {
            let formula = value.as_str().ok_or_else(|| {
                input_error(format!(
                    "{file}: key `model.outputs.{name}`: expected a formula string"
                ))
            })?;
            formulas.push((name.clone(), formula.to_string()));
        }
        let inputs = self.model_inputs();
        for (name, formula) in &formulas {
            iuq_core::Expression::parse(formula, &inputs)
                .bad_input(|| format!("{file}: key `model.outputs.{name}`"))?;
        }
        ExpressionModel::new(inputs, &formulas).bad_input(|| format!("{file}: key `model.outputs`"))
    }
}

/// A study's model, built ([`Study::model`]).
pub enum StudyModel {
    /// `kind = "expression"`.
    Expression(ExpressionModel),
    /// `kind = "rbc-shear"`.
    RbcShear(iuq_rbc::RbcShearModel),
    /// `kind = "umbridge"`.
    UmBridge(iuq_umbridge::UmBridgeModel),
}

impl StudyModel {
    fn inner(&self) -> &dyn iuq_core::Model {
        match self {
            Self::Expression(m) => m,
            Self::RbcShear(m) => m,
            Self::UmBridge(m) => m,
        }
    }
}

impl iuq_core::Model for StudyModel {
    fn input_names(&self) -> &[String] {
        self.inner().input_names()
    }

    fn output_names(&self) -> &[String] {
        self.inner().output_names()
    }

    fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<iuq_core::Outcome>> {
        self.inner().evaluate_batch(points)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Study> {
        Study::parse(text, Path::new("study.toml"))
    }

    const ISHIGAMI: &str = r#"
name = "ishigami"
[parameters]
x1 = { uniform = [-3.141592653589793, 3.141592653589793] }
x2 = { uniform = [-3.141592653589793, 3.141592653589793] }
x3 = { uniform = [-3.141592653589793, 3.141592653589793] }
[model]
kind = "expression"
outputs = { f = "sin(x1) + 7*sin(x2)^2 + 0.1*x3^4*sin(x1)" }
[sensitivity]
n = 1024
"#;

    #[test]
    fn a_valid_study_keeps_parameter_order() {
        let s = parse(ISHIGAMI).unwrap();
        assert_eq!(s.space.names(), vec!["x1", "x2", "x3"]);
        assert_eq!(s.sensitivity.n, Some(1024));
        assert!(s.expression_model().is_ok());
    }

    #[test]
    fn errors_name_the_file_key_and_reason() {
        let cases = [
            (
                ISHIGAMI.replace(
                    "uniform = [-3.141592653589793, 3.141592653589793] }\nx2",
                    "uniform = [3, 1] }\nx2",
                ),
                "parameters.x1",
            ),
            (ISHIGAMI.replace("x3^4", "x4^4"), "model.outputs.f"),
            (
                ISHIGAMI.replace(
                    "{ uniform = [-3.141592653589793, 3.141592653589793] }\nx3",
                    "{ unifrom = [0, 1] }\nx3",
                ),
                "parameters.x2",
            ),
            (ISHIGAMI.replace("n = 1024", "n = -3"), "study.toml"),
            (
                ISHIGAMI.replace("kind = \"expression\"", "kind = \"magic\""),
                "model.kind",
            ),
            (
                ISHIGAMI.replace("name = \"ishigami\"", "name = \"\""),
                "name",
            ),
        ];
        for (text, key) in cases {
            let err = parse(&text).unwrap_err();
            assert!(err.is_bad_input());
            let message = err.to_string();
            assert!(
                message.contains("study.toml") && message.contains(key),
                "{message}"
            );
        }
    }
}
