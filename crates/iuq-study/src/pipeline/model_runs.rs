//! The study's model, whatever its kind, as a campaign of runs: every run of a pipeline — the
//! initial design, the test runs, the adaptive rounds, Sobol' designs and BASIS stages on the
//! model — is recorded in the campaign's SQLite store the moment it finishes, reused by later
//! pipelines, and resumed after a crash.
//!
//! **How runs map to the data.** The data have n points (x_j, y_j), in file order after
//! `x_range`. A study's runs take one of two shapes:
//! - *one run per (θ, x_j)* — `[model] abscissa = "<name>"` (and always the cell model, whose
//!   abscissa is the shear stress): every run receives the data's abscissa under that name (a
//!   command in `params.json` and its templates, an expression as a variable, a UM-Bridge server
//!   as the last input value after the parameters) and returns a single output, compared with
//!   y_j. The runs at x_j form group j, with a GP of its own.
//! - *one run per θ* — no `abscissa`: a run returns n outputs, and output j (the j-th name of
//!   `outputs`, or the j-th output of the model) is compared with y_j. All runs form one group,
//!   with one GP per output.
//!
//! **Where runs execute.** `command` and `batch-command` models run as processes of the
//! campaign's executor (local, Slurm or HyperQueue). Expressions and UM-Bridge servers are
//! evaluated in this process (see `iuq_campaign::in_process`). The native cell model runs as
//! `iuq rbc shear` processes when an iuq executable can be started (the `iuq` command line, or
//! `$IUQ_EXECUTABLE`; see `iuq_campaign::worker::iuq_executable`), and otherwise — a library
//! host such as Python with the local executor — in this process, with the same results: a
//! pipeline never depends on the running executable being `iuq`.

use std::ops::Range;
use std::sync::Arc;

use toml::{Table, Value};

use iuq_campaign::campaign_model::ProgressObserver;
use iuq_campaign::{
    CampaignModel, CampaignOptions, CampaignStudy, InProcessError, InProcessModel,
    InProcessOutputs, Interrupt, SharedModel,
};
use iuq_core::{Evaluation, EvaluationFailure, Model, Outcome};

use super::campaign_text::campaign_text;
use super::cell_model_campaign::{STRESS, campaign_study_text, cell_model_runs, output_name};
use super::events::Events;
use crate::campaign_runs::{campaign_error, open_campaign_with};
use crate::error::{Result, StudyError, input_error};
use crate::likelihood_section::DataLikelihood;
use crate::study::{ModelSection, Study};

/// Runs to make: each a run group and a parameter vector θ.
pub type RunRequests = Vec<(usize, Vec<f64>)>;

/// How runs map to data points (see the module documentation).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RunShape {
    /// One run per (θ, x_j), the abscissa passed under `name`.
    PerAbscissa {
        /// The abscissa's name in the runs' inputs.
        name: String,
    },
    /// One run per θ returning one output per data point.
    Curve,
}

/// The study's model as a campaign, with the data's abscissae.
#[derive(Clone)]
pub struct ModelRuns {
    campaign: Arc<CampaignModel>,
    shape: RunShape,
    abscissae: Vec<f64>,
    parameters: Vec<String>,
    outputs: Vec<String>,
    /// A command model's `[model]` table, the study file and the length its arrays must have,
    /// for the input error of an array of another length.
    array_check: Option<(Table, String, String)>,
    /// Raised when the pipeline's observer asked it to stop: the campaign's error is then the
    /// interruption.
    interrupt: Interrupt,
}

/// A [`Model`] evaluated one point at a time as an in-process campaign model.
struct InProcess<M>(M);

impl<M: Model + Send + Sync> InProcessModel for InProcess<M> {
    fn evaluate(
        &self,
        parameters: &[f64],
    ) -> std::result::Result<InProcessOutputs, InProcessError> {
        match self.0.evaluate_batch(&[parameters.to_vec()]) {
            // The model could not be reached (a server down, a connection lost): not an answer
            // of the model at these parameters, so the run is retried rather than stored as a
            // failure.
            Err(e) => Err(InProcessError::Unavailable(e.to_string())),
            Ok(mut outcomes) => match outcomes.pop() {
                Some(Ok(e)) => Ok((e.outputs, e.computational_std)),
                Some(Err(f)) => Err(InProcessError::Failed(f.reason)),
                None => Err(InProcessError::Failed(
                    "the model returned no outcome".into(),
                )),
            },
        }
    }
}

/// A prior for the abscissa in the campaign's parameter table: the campaign needs one for every
/// input; it is never sampled. It covers the data's abscissae with room on both sides.
fn abscissa_prior(abscissae: &[f64]) -> Value {
    let (lo, hi) = abscissae
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), x| (a.min(*x), b.max(*x)));
    let span = (hi - lo).abs().max(1.0);
    let mut table = Table::new();
    table.insert(
        "uniform".into(),
        Value::Array(vec![Value::Float(lo - span), Value::Float(hi + span)]),
    );
    Value::Table(table)
}

/// The study's own campaign text (command and in-process kinds), the abscissa added when
/// `[model] abscissa` names one.
fn model_campaign_text(study: &Study, model: Table, abscissae: &[f64]) -> Result<String> {
    let extra = study
        .abscissa
        .as_ref()
        .map(|name| (name.clone(), abscissa_prior(abscissae)));
    campaign_text(study, "Model runs", extra, model)
}

/// The `[model]` table of an in-process model: a command that names the model (it is never
/// started; it makes the store's model hash change when the model does).
fn in_process_model_table(description: Vec<String>, outputs: &[String]) -> Table {
    let mut model = Table::new();
    model.insert("kind".into(), Value::String("command".into()));
    let mut command = vec![Value::String("iuq-in-process".into())];
    command.extend(description.into_iter().map(Value::String));
    model.insert("command".into(), Value::Array(command));
    model.insert(
        "outputs".into(),
        Value::Array(outputs.iter().cloned().map(Value::String).collect()),
    );
    let mut output = Table::new();
    output.insert("file".into(), Value::String("in-process.json".into()));
    output.insert("format".into(), Value::String("json".into()));
    model.insert("output".into(), Value::Table(output));
    model
}

/// The campaign study of a pipeline study's model runs, as `iuq pipeline` writes it into the
/// store, for the campaign commands (`iuq status`, `export`, `retry`, `redecode`): models of
/// kind `rbc-shear` and `command` (an in-process model's runs are made by the pipeline alone).
pub fn pipeline_campaign_study(study: &Study) -> Result<CampaignStudy> {
    let file = study.path.display().to_string();
    let data = super::designs::study_data(study)?;
    let text = match &study.model {
        ModelSection::RbcShear { .. } => campaign_study_text(study, &data.x)?,
        ModelSection::Command { table, .. } => {
            let per_run = if study.abscissa.is_some() {
                1
            } else {
                data.x.len()
            };
            let table = super::array_outputs::with_array_outputs(table.clone(), per_run);
            model_campaign_text(study, table, &data.x)?
        }
        ModelSection::Expression { .. }
        | ModelSection::UmBridge(_)
        | ModelSection::Callable { .. } => {
            return Err(input_error(format!(
                "{file}: key `model.kind`: the runs of an in-process model (expression, umbridge, callable) are made and read by `iuq pipeline` alone"
            )));
        }
        ModelSection::Absent => {
            return Err(input_error(format!(
                "{file}: section `[model]`: missing; the pipeline runs a model (kind = \"command\", \"expression\", \"umbridge\" or \"rbc-shear\")"
            )));
        }
    };
    CampaignStudy::parse(&text, &study.path).map_err(campaign_error)
}

/// What [`ModelRuns::open`] holds a model to: the outputs a run must return (one per run per
/// data point, or one per data point) and, for an in-process model, the local executor.
struct ModelCheck<'a> {
    /// The study file, for the errors.
    file: &'a str,
    /// The number of data points.
    n: usize,
    /// One run per (θ, x_j).
    per_abscissa: bool,
    /// The executor is local.
    local: bool,
}

impl ModelCheck<'_> {
    fn outputs_per_run(&self) -> usize {
        if self.per_abscissa { 1 } else { self.n }
    }

    /// A model returning `count` outputs per run fits the data.
    fn check_outputs(&self, count: usize) -> Result<()> {
        let (file, n) = (self.file, self.n);
        if count != self.outputs_per_run() {
            let expected = if self.per_abscissa {
                "1 (one run per parameter vector and data point returns the model's value at that point)".to_string()
            } else {
                format!(
                    "{n}, one per data point (output j is compared with data row j; or set `model.abscissa` to run the model once per data point)"
                )
            };
            return Err(input_error(format!(
                "{file}: key `model.outputs`: the model has {count} outputs, expected {expected}"
            )));
        }
        Ok(())
    }

    /// A model of `kind`, evaluated in this process, needs the local executor.
    fn in_process_only(&self, kind: &str) -> Result<()> {
        if self.local {
            Ok(())
        } else {
            let file = self.file;
            Err(input_error(format!(
                "{file}: key `executor.kind`: a model of kind `{kind}` is evaluated in this process; use kind = \"local\""
            )))
        }
    }
}

/// The campaign text of `study`'s model at the data's abscissae, and the model evaluated in this
/// process where it is one (`callable`: the model a program supplies for kind `callable`).
fn campaign_of_model(
    study: &Study,
    data: &DataLikelihood,
    check: &ModelCheck<'_>,
    callable: Option<SharedModel>,
) -> Result<(String, Option<SharedModel>)> {
    let (file, n) = (check.file, check.n);
    Ok(match &study.model {
        ModelSection::RbcShear { .. } => {
            let text = campaign_study_text(study, &data.x)?;
            // `iuq rbc shear` processes (isolated, with a timeout, surviving the coordinator)
            // when there is an iuq executable to start; else, on this machine, this process.
            let in_process = check.local && iuq_campaign::worker::iuq_executable().is_none();
            let model = in_process
                .then(|| cell_model_runs(study, &data.x))
                .transpose()?
                .map(|m| SharedModel(Arc::new(m)));
            (text, model)
        }
        ModelSection::Command { table, .. } => {
            let table =
                super::array_outputs::with_array_outputs(table.clone(), check.outputs_per_run());
            let count = table
                .get("outputs")
                .and_then(Value::as_array)
                .map_or(0, Vec::len);
            check.check_outputs(count)?;
            (model_campaign_text(study, table, &data.x)?, None)
        }
        ModelSection::Expression { outputs } => {
            check.in_process_only("expression")?;
            check.check_outputs(outputs.len())?;
            let model = study.expression_model()?;
            let mut description = vec!["expression".to_string()];
            description.extend(outputs.iter().map(|(name, formula)| {
                format!("{name} = {}", formula.as_str().unwrap_or_default())
            }));
            description.push(format!("inputs = {}", study.model_inputs().join(", ")));
            let names: Vec<String> = outputs.keys().cloned().collect();
            let table = in_process_model_table(description, &names);
            (
                model_campaign_text(study, table, &data.x)?,
                Some(SharedModel(Arc::new(InProcess(model)))),
            )
        }
        ModelSection::UmBridge(section) => {
            check.in_process_only("umbridge")?;
            let model = study.umbridge_model()?;
            check.check_outputs(model.output_names().len())?;
            let description = vec![
                "umbridge".to_string(),
                section.url.clone(),
                section.name.clone(),
                format!("inputs = {}", study.model_inputs().join(", ")),
            ];
            let names = model.output_names().to_vec();
            let table = in_process_model_table(description, &names);
            (
                model_campaign_text(study, table, &data.x)?,
                Some(SharedModel(Arc::new(InProcess(model)))),
            )
        }
        ModelSection::Callable { description } => {
            check.in_process_only("callable")?;
            let Some(model) = callable else {
                return Err(input_error(format!(
                    "{file}: key `model.kind`: a model of kind `callable` is supplied by the program that runs the study (`iuq.calibrate` in Python); `iuq pipeline` cannot run it"
                )));
            };
            let names: Vec<String> = if check.per_abscissa {
                vec!["y".to_string()]
            } else {
                (0..n).map(|j| format!("y[{j}]")).collect()
            };
            let description = vec![
                "callable".to_string(),
                description.clone(),
                format!("inputs = {}", study.model_inputs().join(", ")),
            ];
            let table = in_process_model_table(description, &names);
            (model_campaign_text(study, table, &data.x)?, Some(model))
        }
        ModelSection::Absent => {
            return Err(input_error(format!(
                "{file}: section `[model]`: missing; the pipeline runs a model (kind = \"command\", \"expression\", \"umbridge\" or \"rbc-shear\")"
            )));
        }
    })
}

impl ModelRuns {
    /// Open (create or resume) the campaign of `study`'s model at the data `data`, running at
    /// most `max_parallel` runs at once, with campaign progress sent to `progress`.
    pub(super) fn open(
        study: &Study,
        data: &DataLikelihood,
        max_parallel: Option<usize>,
        callable: Option<SharedModel>,
        events: &Events,
        progress: ProgressObserver,
    ) -> Result<Self> {
        let file = study.path.display().to_string();
        let n = data.x.len();
        let parameters = study.space.names();
        let shape = match (&study.model, &study.abscissa) {
            (ModelSection::RbcShear { .. }, _) => RunShape::PerAbscissa {
                name: STRESS.to_string(),
            },
            (_, Some(name)) => RunShape::PerAbscissa { name: name.clone() },
            (_, None) => RunShape::Curve,
        };
        let executor_kind = study
            .executor
            .as_ref()
            .and_then(|t| t.get("kind"))
            .and_then(Value::as_str)
            .unwrap_or("local");
        let per_abscissa = matches!(shape, RunShape::PerAbscissa { .. });
        let check = ModelCheck {
            file: &file,
            n,
            per_abscissa,
            local: executor_kind == "local",
        };
        let (text, in_process) = campaign_of_model(study, data, &check, callable)?;
        let campaign_study = CampaignStudy::parse(&text, &study.path).map_err(campaign_error)?;
        let (campaign, resumed) = open_campaign_with(
            campaign_study,
            CampaignOptions {
                max_parallel,
                in_process,
                interrupt: Some(events.interrupt.clone()),
                ..Default::default()
            },
        )?;
        if resumed.requeued + resumed.ingested + resumed.reattached > 0 {
            events.message(format!(
                "resumed the campaign in {} ({} runs requeued, {} results ingested, {} reattached)",
                campaign.directory().display(),
                resumed.requeued,
                resumed.ingested,
                resumed.reattached
            ));
        }
        let campaign_outputs = campaign.study().model.outputs.clone();
        let outputs = match (&study.model, &shape) {
            (ModelSection::RbcShear { .. }, _) => data.x.iter().map(|s| output_name(*s)).collect(),
            (_, RunShape::PerAbscissa { name }) => data
                .x
                .iter()
                .map(|x| format!("{}({name}={x})", campaign_outputs[0]))
                .collect(),
            (_, RunShape::Curve) => campaign_outputs,
        };
        Ok(Self {
            campaign: Arc::new(
                CampaignModel::new(campaign)
                    .with_progress(std::time::Duration::from_secs(10), progress),
            ),
            shape,
            abscissae: data.x.clone(),
            parameters,
            outputs,
            array_check: match &study.model {
                ModelSection::Command { table, .. } => Some((
                    table.clone(),
                    file.clone(),
                    if per_abscissa {
                        "1 value per run (one run per parameter vector and data point)".to_string()
                    } else {
                        format!("{n} values, one per data row")
                    },
                )),
                _ => None,
            },
            interrupt: events.interrupt.clone(),
        })
    }

    /// How runs map to data points.
    pub fn shape(&self) -> &RunShape {
        &self.shape
    }

    /// The campaign.
    pub fn campaign(&self) -> &Arc<CampaignModel> {
        &self.campaign
    }

    /// The calibrated parameters, in order.
    pub fn parameters(&self) -> &[String] {
        &self.parameters
    }

    /// One name per data point for the model's output there (GP and Sobol' tables).
    pub fn output_names(&self) -> &[String] {
        &self.outputs
    }

    /// The number of run groups: one per data point (per abscissa) or one (curve).
    pub fn groups(&self) -> usize {
        match self.shape {
            RunShape::PerAbscissa { .. } => self.abscissae.len(),
            RunShape::Curve => 1,
        }
    }

    /// The data points whose outputs a run of group `g` returns.
    pub fn group_outputs(&self, g: usize) -> Range<usize> {
        match self.shape {
            RunShape::PerAbscissa { .. } => g..g + 1,
            RunShape::Curve => 0..self.abscissae.len(),
        }
    }

    /// The abscissa of data point `j`.
    pub fn abscissa_of_output(&self, j: usize) -> f64 {
        self.abscissae[j]
    }

    /// The group's abscissa (per-abscissa shape only).
    pub fn group_abscissa(&self, g: usize) -> Option<f64> {
        match self.shape {
            RunShape::PerAbscissa { .. } => self.abscissae.get(g).copied(),
            RunShape::Curve => None,
        }
    }

    /// Run each `(group, θ)` of `requests` (recorded under `label` when given) and return one
    /// outcome per request, its outputs those of [`ModelRuns::group_outputs`].
    pub fn run(&self, label: Option<&str>, requests: &[(usize, Vec<f64>)]) -> Result<Vec<Outcome>> {
        let mut outcomes = self.run_with_diagnostics(label, requests)?;
        for ((g, _), outcome) in requests.iter().zip(&mut outcomes) {
            if let Ok(e) = outcome {
                let width = self.group_outputs(*g).len();
                if e.outputs.len() > width {
                    e.outputs.truncate(width);
                    if let Some(s) = &mut e.computational_std {
                        s.truncate(width);
                    }
                }
            }
        }
        Ok(outcomes)
    }

    /// [`ModelRuns::run`] with every output of the runs: for the cell model the elongation
    /// index, then its drift over the measuring window.
    pub fn run_with_diagnostics(
        &self,
        label: Option<&str>,
        requests: &[(usize, Vec<f64>)],
    ) -> Result<Vec<Outcome>> {
        let points: Vec<Vec<f64>> = requests
            .iter()
            .map(|(g, theta)| {
                let mut x = theta.clone();
                x.extend(self.group_abscissa(*g));
                x
            })
            .collect();
        let outcomes = self
            .campaign
            .evaluate_labelled(label, &points)
            .map_err(|e| {
                if self.interrupt.is_raised() {
                    StudyError::Interrupted
                } else {
                    StudyError::from(e)
                }
            })?;
        if let Some((model, file, expected)) = &self.array_check {
            super::array_outputs::check_lengths(file, Some(model), &outcomes, expected)?;
        }
        Ok(outcomes)
    }

    /// The requests of the design recorded under `label`, if the store has it: each point back
    /// as (run group, θ), the group found by its abscissa. `None` also when a point's abscissa
    /// is none of the data's (the store belongs to other data).
    pub fn recorded_requests(&self, label: &str) -> Result<Option<RunRequests>> {
        let Some(points) = self.campaign.recorded_design(label)? else {
            return Ok(None);
        };
        let d = self.parameters.len();
        let mut requests = Vec::with_capacity(points.len());
        for p in points {
            match self.shape {
                RunShape::Curve if p.len() == d => requests.push((0, p)),
                RunShape::PerAbscissa { .. } if p.len() == d + 1 => {
                    let Some(g) = self.abscissae.iter().position(|x| *x == p[d]) else {
                        return Ok(None);
                    };
                    requests.push((g, p[..d].to_vec()));
                }
                _ => return Ok(None),
            }
        }
        Ok(Some(requests))
    }

    /// A result derived from the runs, recorded in the campaign store under `key` with
    /// `fingerprint` (see `iuq_campaign::CampaignStore::derived_result`).
    pub fn derived_result(&self, key: &str, fingerprint: &str) -> Result<Option<String>> {
        Ok(self.campaign.derived_result(key, fingerprint)?)
    }

    /// Record a result derived from the runs in the campaign store.
    pub fn record_derived_result(&self, key: &str, fingerprint: &str, value: &str) -> Result<()> {
        Ok(self
            .campaign
            .record_derived_result(key, fingerprint, value)?)
    }

    /// The model at the data as a [`Model`] of θ with one output per data point: a point's runs
    /// (one per abscissa, or one) go into the same campaign batch; it fails when one fails.
    pub fn model_at_data(&self) -> ModelAtData {
        ModelAtData { runs: self.clone() }
    }
}

/// [`ModelRuns::model_at_data`].
pub struct ModelAtData {
    runs: ModelRuns,
}

impl Model for ModelAtData {
    fn input_names(&self) -> &[String] {
        &self.runs.parameters
    }

    fn output_names(&self) -> &[String] {
        &self.runs.outputs
    }

    fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
        self.evaluate(None, points)
    }
}

impl ModelAtData {
    /// [`Model::evaluate_batch`] with the runs recorded in the campaign store under `label`.
    pub fn evaluate_labelled(
        &self,
        label: &str,
        points: &[Vec<f64>],
    ) -> iuq_core::Result<Vec<Outcome>> {
        self.evaluate(Some(label), points)
    }

    fn evaluate(&self, label: Option<&str>, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
        let groups = self.runs.groups();
        let requests: Vec<(usize, Vec<f64>)> = points
            .iter()
            .flat_map(|p| (0..groups).map(move |g| (g, p.clone())))
            .collect();
        let outcomes = self.runs.run(label, &requests).map_err(|e| {
            if e.is_bad_input() {
                iuq_core::CoreError::ModelInput(e.message().to_string())
            } else {
                iuq_core::CoreError::ModelUnavailable(e.to_string())
            }
        })?;
        Ok(outcomes
            .chunks(groups.max(1))
            .map(|group| {
                let mut values = Vec::new();
                let mut stds = Vec::new();
                for (g, o) in group.iter().enumerate() {
                    match o {
                        Ok(e) => {
                            let width = self.runs.group_outputs(g).len();
                            if e.outputs.len() != width {
                                return Err(EvaluationFailure::new(format!(
                                    "a run returned {} outputs, expected {width}",
                                    e.outputs.len()
                                )));
                            }
                            values.extend(&e.outputs);
                            match &e.computational_std {
                                Some(s) if s.len() == width => stds.extend(s),
                                _ => stds.extend(std::iter::repeat_n(0.0, width)),
                            }
                        }
                        Err(f) => {
                            return Err(EvaluationFailure::new(
                                match self.runs.group_abscissa(g) {
                                    Some(x) => format!("at {x}: {}", f.reason),
                                    None => f.reason.clone(),
                                },
                            ));
                        }
                    }
                }
                Ok(Evaluation::with_std(values, stds))
            })
            .collect())
    }
}
