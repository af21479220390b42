//! Campaign study files: the `[model]` of kind `command` or `batch-command`, the `[design]` that
//! `iuq run` executes and the `[executor]`, validated up front with errors naming the file, the
//! key and the reason.
//!
//! ```toml
//! name = "my-sim"
//! [parameters]
//! x = { uniform = [0, 1] }
//! stress = { uniform = [1, 10] }
//! [model]
//! kind = "command"                    # or "batch-command"
//! command = ["./sim.sh", "--steps", "{{ steps }}"]   # relative paths: from the study's folder
//! templates = ["config.xml"]          # copied into each run directory, {{ name }} filled
//! derived = { steps = "ceil(2e5 / stress)" }   # expressions of the parameters (and earlier derived values)
//! outputs = ["f"]
//! output = { file = "result.json", format = "json" }   # see the decoder module
//! timeout = "30m"                     # SIGTERM to the process group, then SIGKILL after kill_grace
//! kill_grace = "10s"
//! env = { OMP_NUM_THREADS = "1" }
//! [design]
//! kind = "lhs"                        # lhs | sobol | file
//! n = 200
//! seed = 5
//! [executor]
//! kind = "local"                      # local | slurm | hyperqueue
//! max_parallel = 2                    # local: processes at once (default: cores); slurm: array throttle
//! directory = "my-sim.campaign"       # store and run directories (default: <study stem>.campaign)
//! retry = { max_attempts = 3, on = ["lost", "infrastructure", "spawn_failed"] }
//! ```
//!
//! `batch-command` runs one process per `batch_size` runs: it finds `input` (default
//! `inputs.csv`: `run_id`, the parameters and derived values, one row per run) in its directory
//! and writes `output` (default `outputs.csv`: a header with the output names, optionally an
//! `error` column, one row per input row in the same order).
//!
//! Slurm keys: `sbatch_args = ["--partition=short"]`, `array_chunk` (default 1000, and never
//! above the cluster's MaxArraySize), `poll_interval` (default "5s"), `worker` (the command that
//! starts `iuq worker` on the compute nodes; default: this `iuq` binary). HyperQueue keys:
//! `hq` (the `hq` binary, default `hq` or `$HQ_BIN`), `submit_args`, `poll_interval`, `worker`.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use iuq_core::{Expression, Parameter, ParameterSpace, Prior};
use iuq_study_file::StudySection;

use crate::decoder::{CsvRow, DecoderFormat, DecoderSpec, OutputDecoder};
use crate::error::{CampaignError, Result};
use crate::outcome::OutcomeKind;
use crate::retry_policy::RetryPolicy;
use crate::template::{Segment, Template};

/// Top-level keys a study file may hold (the sections of other stages are not read here).
pub const TOP_LEVEL_KEYS: [&str; 13] = [
    "name",
    "description",
    "parameters",
    "likelihood",
    "model",
    "surrogate",
    "sensitivity",
    "sampler",
    "model_sampler",
    "model_posterior",
    "executor",
    "design",
    "low_fidelity",
];

/// A template file of the command model: where it goes in the run directory and its parsed text.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TemplateFile {
    /// Path relative to the run directory.
    pub target: String,
    /// The parsed template.
    pub template: Template,
}

/// `command` (one process per run) or `batch-command` (one process per batch of runs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CommandKind {
    /// One process per run; outputs decoded by [`CommandSpec::decoder`].
    Command,
    /// One process per batch of runs, reading a CSV of parameter vectors and writing a CSV of
    /// outputs.
    BatchCommand {
        /// Runs per process.
        batch_size: usize,
        /// The input CSV file name in the task directory.
        input: String,
        /// The output CSV file name in the task directory.
        output: String,
    },
}

/// Everything a worker needs to execute a run of the model: the `[model]` section, compiled to
/// data that is written once per campaign (`worker-spec-<hash>.json`) and read by `iuq worker`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CommandSpec {
    /// One process per run or per batch.
    pub kind: CommandKind,
    /// The command line, each argument a template.
    pub command: Vec<Template>,
    /// Parameter names, in vector order.
    pub parameters: Vec<String>,
    /// Derived values: name and expression over the parameters and the earlier derived values.
    pub derived: Vec<(String, String)>,
    /// Template files written into each run directory.
    pub templates: Vec<TemplateFile>,
    /// Output names, in the order of the outputs.
    pub outputs: Vec<String>,
    /// How a run's outputs are decoded (`command` only).
    pub decoder: Option<DecoderSpec>,
    /// Wall-clock limit of one process, seconds.
    pub timeout: Option<f64>,
    /// Seconds between SIGTERM and SIGKILL on a timeout.
    pub kill_grace: f64,
    /// Environment variables set for the command.
    pub env: Vec<(String, String)>,
    /// The study file's folder (`IUQ_STUDY_DIR`), from which relative command paths were resolved.
    pub study_dir: PathBuf,
}

impl CommandSpec {
    /// Names a template may use: parameters, derived values, `run_id`.
    pub fn template_names(&self) -> Vec<String> {
        let mut names = self.parameters.clone();
        names.extend(self.derived.iter().map(|(n, _)| n.clone()));
        names.push("run_id".into());
        names
    }

    /// A content hash of the specification (hex SHA-256 of its JSON form).
    pub fn hash(&self) -> String {
        let json = serde_json::to_vec(self).unwrap_or_default();
        hex_sha256(&json)
    }

    /// Compile the derived-value expressions.
    pub fn derived_expressions(&self) -> std::result::Result<Vec<Expression>, String> {
        let mut names = self.parameters.clone();
        let mut out = Vec::with_capacity(self.derived.len());
        for (name, formula) in &self.derived {
            out.push(Expression::parse(formula, &names).map_err(|e| format!("`{name}`: {e}"))?);
            names.push(name.clone());
        }
        Ok(out)
    }

    /// The output decoder (`command` only).
    pub fn output_decoder(&self) -> std::result::Result<Option<OutputDecoder>, String> {
        self.decoder
            .clone()
            .map(|d| OutputDecoder::new(d, self.outputs.clone()))
            .transpose()
    }
}

/// The study's `[design]`: how the points of `iuq run` are chosen.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StudyDesign {
    /// A maximin Latin hypercube of `n` points mapped through the priors.
    Lhs {
        /// Points.
        n: usize,
        /// Seed.
        seed: u64,
    },
    /// `n` scrambled Sobol' points mapped through the priors.
    Sobol {
        /// Points.
        n: usize,
        /// Seed of the scrambling.
        seed: u64,
    },
    /// Points read from a CSV file whose columns are named as the parameters.
    File {
        /// The file (absolute, or relative to the study's folder when written).
        path: PathBuf,
    },
}

/// Which executor runs the tasks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ExecutorKind {
    /// Processes on this machine.
    Local,
    /// Slurm job arrays.
    Slurm,
    /// HyperQueue task arrays.
    Hyperqueue,
}

impl ExecutorKind {
    /// The name used in study files and the store.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Local => "local",
            Self::Slurm => "slurm",
            Self::Hyperqueue => "hyperqueue",
        }
    }
}

/// The `[executor]` section.
#[derive(Debug, Clone, PartialEq)]
pub struct ExecutorSpec {
    /// Which executor.
    pub kind: ExecutorKind,
    /// Tasks at once (local: processes, default the number of cores; slurm: the array throttle;
    /// hyperqueue: tasks submitted at once).
    pub max_parallel: Option<usize>,
    /// The campaign directory (store and run directories).
    pub directory: PathBuf,
    /// The retry policy.
    pub retry: RetryPolicy,
    /// Seconds between scheduler polls.
    pub poll_interval: f64,
    /// Slurm: tasks per job array at most.
    pub array_chunk: usize,
    /// Slurm: extra `sbatch` arguments; HyperQueue: extra `hq submit` arguments.
    pub submit_args: Vec<String>,
    /// HyperQueue: the `hq` program.
    pub hq: Option<String>,
    /// The command that starts a worker on a compute node (default: this `iuq` binary + `worker`).
    pub worker: Option<Vec<String>>,
}

/// A campaign study read from a file.
#[derive(Debug, Clone)]
pub struct CampaignStudy {
    /// The study file.
    pub path: PathBuf,
    /// Its text as read.
    pub text: String,
    /// Hex SHA-256 of the text.
    pub hash: String,
    /// The study's name.
    pub name: String,
    /// The parameters and priors, in file order.
    pub space: ParameterSpace,
    /// The command model.
    pub model: CommandSpec,
    /// The design of `iuq run`, when the file has one.
    pub design: Option<StudyDesign>,
    /// The executor.
    pub executor: ExecutorSpec,
}

/// Hex SHA-256 of `bytes`.
pub fn hex_sha256(bytes: &[u8]) -> String {
    let digest = Sha256::digest(bytes);
    digest.iter().map(|b| format!("{b:02x}")).collect()
}

fn relative_to(base: &Path, p: &str) -> PathBuf {
    let p = Path::new(p);
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        base.join(p)
    }
}

impl CampaignStudy {
    /// Read and validate a study file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| CampaignError::Study {
            file: path.display().to_string(),
            key: "(file)".into(),
            reason: format!("cannot read: {e}"),
        })?;
        Self::parse(&text, path)
    }

    /// Parse and validate study text; `path` names the file in errors and locates relative paths.
    pub fn parse(text: &str, path: &Path) -> Result<Self> {
        let file = path.display().to_string();
        let study_dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let study_dir = std::path::absolute(&study_dir).unwrap_or(study_dir);
        let root: toml::Table = toml::from_str(text).map_err(|e| {
            CampaignError::study(&file, "(syntax)", e.to_string().trim().replace('\n', " "))
        })?;
        let mut top = StudySection::new(&root, "", &file);
        // The sections of the other stages are read by the pipeline (`iuq-study`).
        top.allow(&TOP_LEVEL_KEYS);
        top.finish_with_hint(&format!(
            "an unknown section or key (one of {})",
            TOP_LEVEL_KEYS.join(", ")
        ))?;
        let name = match top.string("name")? {
            Some(s) if !s.trim().is_empty() => s,
            Some(_) => return Err(top.error("name", "expected a non-empty string").into()),
            None => return Err(top.error("name", "missing").into()),
        };
        let Some(parameters) = top.sub_table("parameters")? else {
            return Err(top.error("parameters", "missing").into());
        };
        let space = parse_parameters(parameters, &file)?;
        let Some(model_table) = top.sub_table("model")? else {
            return Err(top.error(
                "model",
                "missing: a campaign needs [model] with kind = \"command\" or \"batch-command\"",
            ).into());
        };
        let model = parse_model(model_table, &space, &file, &study_dir)?;
        let design = top
            .sub_table("design")?
            .map(|t| parse_design(t, &file, &study_dir))
            .transpose()?;
        let empty = toml::Table::new();
        let executor_table = top.sub_table("executor")?.unwrap_or(&empty);
        let stem = path
            .file_stem()
            .map_or_else(|| "study".to_string(), |s| s.to_string_lossy().into_owned());
        let executor = parse_executor(executor_table, &file, &study_dir, &stem)?;
        Ok(Self {
            path: path.to_path_buf(),
            text: text.to_string(),
            hash: hex_sha256(text.as_bytes()),
            name,
            space,
            model,
            design,
            executor,
        })
    }

    /// A hash of what determines the result of a run: the parameter names and the model
    /// specification. Stores refuse a study whose model hash differs from theirs.
    ///
    /// The study's folder is left out, so a campaign directory moved or cloned with its study
    /// (e.g. results shipped in a repository) keeps its results.
    pub fn model_hash(&self) -> String {
        let mut model = self.model.clone();
        if let Some(program) = model.command.first_mut() {
            if let Some(relative) = program_in_study_dir(program, &self.model.study_dir) {
                *program = relative;
            }
        }
        Self::hash_of(&self.space, &model)
    }

    /// The model hash of stores written before [`Self::model_hash`] left the study's folder out
    /// of a program path: a program `./x` resolved against the folder the study is in now.
    /// [`crate::CampaignStore::open`] accepts it and rewrites the store's hash to the new one.
    pub fn legacy_model_hash(&self) -> String {
        Self::hash_of(&self.space, &self.model)
    }

    fn hash_of(space: &ParameterSpace, model: &CommandSpec) -> String {
        let mut model = serde_json::to_value(model).unwrap_or_default();
        if let Some(m) = model.as_object_mut() {
            m.remove("study_dir");
        }
        let json = serde_json::json!({
            "parameters": space.names(),
            "model": model,
        });
        hex_sha256(json.to_string().as_bytes())
    }
}

/// The program of a command, `./x` again where the study file's relative path was resolved
/// against `study_dir` (so the hash does not depend on where the study lies).
fn program_in_study_dir(program: &Template, study_dir: &Path) -> Option<Template> {
    let [Segment::Literal(text)] = program.segments() else {
        return None;
    };
    let relative = Path::new(text).strip_prefix(study_dir).ok()?;
    Template::parse(&format!("./{}", relative.display())).ok()
}

fn parse_parameters(table: &toml::Table, file: &str) -> Result<ParameterSpace> {
    let mut parameters = Vec::with_capacity(table.len());
    for (name, value) in table {
        let key = format!("parameters.{name}");
        let prior: Prior = value.clone().try_into().map_err(|_| {
            CampaignError::study(file, &key, "expected a prior such as { uniform = [lower, upper] }, { normal = [mean, std] }, { log_normal = [mu, sigma] } or { truncated_normal = [mean, std, lower, upper] }")
        })?;
        prior
            .validate(name)
            .map_err(|e| CampaignError::study(file, &key, e.to_string()))?;
        parameters.push(Parameter {
            name: name.clone(),
            prior,
        });
    }
    ParameterSpace::new(parameters)
        .map_err(|e| CampaignError::study(file, "parameters", e.to_string()))
}

fn parse_model(
    table: &toml::Table,
    space: &ParameterSpace,
    file: &str,
    study_dir: &Path,
) -> Result<CommandSpec> {
    let mut s = StudySection::new(table, "model", file);
    let batch = parse_model_kind(&mut s)?;
    let parameters = space.names();
    let command_text = parse_command_text(&mut s, study_dir)?;
    let mut known = parameters.clone();
    let derived = parse_derived(&mut s, &mut known)?;
    known.push("run_id".into());
    let command = parse_command(&s, &command_text, &known)?;
    let templates = parse_templates(&mut s, study_dir, &known)?;
    let outputs = parse_output_names(&mut s)?;
    let timeout = s.duration("timeout")?;
    if timeout == Some(0.0) {
        return Err(s.error("timeout", "must be positive").into());
    }
    let kill_grace = s.duration("kill_grace")?.unwrap_or(10.0);
    let env = parse_env(&mut s)?;
    let (kind, decoder) = if batch {
        let batch_size = s.count("batch_size", 1)?.unwrap_or(100);
        let input = s.string("input")?.unwrap_or_else(|| "inputs.csv".into());
        let output = s.string("output")?.unwrap_or_else(|| "outputs.csv".into());
        (
            CommandKind::BatchCommand {
                batch_size,
                input,
                output,
            },
            None,
        )
    } else {
        let t = s.sub_table("output")?.ok_or_else(|| {
            s.error(
                "output",
                "missing: e.g. { file = \"result.json\", format = \"json\" }",
            )
        })?;
        (
            CommandKind::Command,
            Some(parse_decoder(t, &outputs, file)?),
        )
    };
    let hint = if batch {
        "kind, command, templates, derived, outputs, batch_size, input, output, timeout, kill_grace, env"
    } else {
        "kind, command, templates, derived, outputs, output, timeout, kill_grace, env"
    };
    s.finish_with_hint(hint)?;
    let spec = CommandSpec {
        kind,
        command,
        parameters,
        derived,
        templates,
        outputs,
        decoder,
        timeout,
        kill_grace,
        env,
        study_dir: study_dir.to_path_buf(),
    };
    spec.output_decoder()
        .map_err(|r| CampaignError::study(file, "model.output", r))?;
    Ok(spec)
}

/// `model.kind`: true for `batch-command`, false for `command`; the other model kinds are
/// not run by a campaign.
fn parse_model_kind(s: &mut StudySection) -> Result<bool> {
    let kind_name = s
        .string("kind")?
        .ok_or_else(|| s.error("kind", "missing (\"command\" or \"batch-command\")"))?;
    match kind_name.as_str() {
        "command" => Ok(false),
        "batch-command" => Ok(true),
        "expression" | "rbc-shear" | "umbridge" => Err(s.error(
            "kind",
            format!("a campaign runs a model of kind \"command\" or \"batch-command\", not `{kind_name}`"),
        ).into()),
        other => Err(s.error(
            "kind",
            format!("unknown kind `{other}` (\"command\" or \"batch-command\")"),
        ).into()),
    }
}

/// `model.command` as written, its program resolved against the study's folder where it is a
/// relative path.
fn parse_command_text(s: &mut StudySection, study_dir: &Path) -> Result<Vec<String>> {
    let mut command_text = s.strings("command")?.ok_or_else(|| {
        s.error(
            "command",
            "missing: the program and its arguments, e.g. [\"./sim.sh\"]",
        )
    })?;
    if command_text.is_empty() || command_text[0].trim().is_empty() {
        return Err(s.error("command", "must name a program").into());
    }
    if command_text[0].contains('/') && !Path::new(&command_text[0]).is_absolute() {
        command_text[0] = study_dir.join(&command_text[0]).display().to_string();
    }
    Ok(command_text)
}

/// `model.derived`: (name, formula) in file order, each formula over the parameters and the
/// values derived before it; their names are added to `known`.
fn parse_derived(s: &mut StudySection, known: &mut Vec<String>) -> Result<Vec<(String, String)>> {
    let mut derived = Vec::new();
    if let Some(t) = s.sub_table("derived")? {
        for (name, v) in t {
            let key = format!("derived.{name}");
            let formula = v
                .as_str()
                .ok_or_else(|| s.error(&key, "expected a formula string"))?;
            if known.contains(name) || name == "run_id" {
                return Err(s
                    .error(
                        &key,
                        "the name is already taken by a parameter or derived value",
                    )
                    .into());
            }
            Expression::parse(formula, known).map_err(|e| s.error(&key, e.to_string()))?;
            known.push(name.clone());
            derived.push((name.clone(), formula.to_string()));
        }
    }
    Ok(derived)
}

/// The command's arguments as templates, which may name only `known` values.
fn parse_command(
    s: &StudySection,
    command_text: &[String],
    known: &[String],
) -> Result<Vec<Template>> {
    let is_known = |n: &str| known.iter().any(|k| k == n);
    let mut command = Vec::with_capacity(command_text.len());
    for (i, arg) in command_text.iter().enumerate() {
        let key = format!("command[{i}]");
        let t = Template::parse(arg).map_err(|e| s.error(&key, e.reason))?;
        if let Some((name, _)) = t.unknown_names(is_known).into_iter().next() {
            return Err(s
                .error(
                    &key,
                    format!("unknown name `{name}` (known: {})", known.join(", ")),
                )
                .into());
        }
        command.push(t);
    }
    Ok(command)
}

/// `model.templates`: the files read (relative to the study's folder) and parsed, naming only
/// `known` values, each with the path it is written to in a run's folder.
fn parse_templates(
    s: &mut StudySection,
    study_dir: &Path,
    known: &[String],
) -> Result<Vec<TemplateFile>> {
    let is_known = |n: &str| known.iter().any(|k| k == n);
    let mut templates = Vec::new();
    for (i, source) in s
        .strings("templates")?
        .unwrap_or_default()
        .iter()
        .enumerate()
    {
        let key = format!("templates[{i}]");
        let source_path = relative_to(study_dir, source);
        let text = std::fs::read_to_string(&source_path)
            .map_err(|e| s.error(&key, format!("cannot read {}: {e}", source_path.display())))?;
        let template = Template::parse(&text)
            .map_err(|e| s.error(&key, format!("{}: {e}", source_path.display())))?;
        if let Some((name, line)) = template.unknown_names(is_known).into_iter().next() {
            return Err(s
                .error(
                    &key,
                    format!(
                        "{} line {line}: unknown name `{name}` (known: {})",
                        source_path.display(),
                        known.join(", ")
                    ),
                )
                .into());
        }
        let target = if Path::new(source).is_absolute() {
            source_path
                .file_name()
                .map_or_else(|| source.clone(), |n| n.to_string_lossy().into_owned())
        } else {
            source.clone()
        };
        if Path::new(&target)
            .components()
            .any(|c| matches!(c, std::path::Component::ParentDir))
        {
            return Err(s
                .error(
                    &key,
                    "a template must lie in or below the study's folder (no `..`)",
                )
                .into());
        }
        templates.push(TemplateFile { target, template });
    }
    Ok(templates)
}

/// `model.outputs`: at least one name, all non-empty and distinct.
fn parse_output_names(s: &mut StudySection) -> Result<Vec<String>> {
    let outputs = s.strings("outputs")?.ok_or_else(|| {
        s.error(
            "outputs",
            "missing: the names of the model's outputs, e.g. [\"f\"]",
        )
    })?;
    if outputs.is_empty() {
        return Err(s.error("outputs", "at least one output is needed").into());
    }
    for (i, o) in outputs.iter().enumerate() {
        if o.trim().is_empty() || outputs[..i].contains(o) {
            return Err(s
                .error(
                    &format!("outputs[{i}]"),
                    "output names must be non-empty and distinct",
                )
                .into());
        }
    }
    Ok(outputs)
}

/// `model.env`: the environment variables set for the model, numbers and booleans as text.
fn parse_env(s: &mut StudySection) -> Result<Vec<(String, String)>> {
    let mut env = Vec::new();
    if let Some(t) = s.sub_table("env")? {
        for (k, v) in t {
            let value = match v {
                toml::Value::String(x) => x.clone(),
                toml::Value::Integer(x) => x.to_string(),
                toml::Value::Float(x) => x.to_string(),
                toml::Value::Boolean(x) => x.to_string(),
                _ => {
                    return Err(s
                        .error(&format!("env.{k}"), "expected a string or number")
                        .into());
                }
            };
            env.push((k.clone(), value));
        }
    }
    Ok(env)
}

fn parse_decoder(table: &toml::Table, outputs: &[String], file: &str) -> Result<DecoderSpec> {
    let mut s = StudySection::new(table, "model.output", file);
    let out_file = s.string("file")?.ok_or_else(|| {
        s.error(
            "file",
            "missing: the output file, relative to the run directory",
        )
    })?;
    let format = s
        .string("format")?
        .ok_or_else(|| s.error("format", "missing (\"json\", \"csv\" or \"regex\")"))?;
    let format = match format.as_str() {
        "json" if s.has("array") => {
            if s.has("keys") {
                return Err(s.error(
                    "array",
                    "give either `array` (one array holds every output) or `keys` (a pointer per output)",
                ).into());
            }
            let pointer = s.string("array")?.unwrap_or_default();
            let pointer = if pointer.starts_with('/') {
                pointer
            } else {
                format!("/{pointer}")
            };
            DecoderFormat::JsonArray { pointer }
        }
        "json" => {
            let pointers = match s.sub_table("keys")? {
                Some(keys) => outputs
                    .iter()
                    .map(|o| match keys.get(o) {
                        Some(toml::Value::String(p)) if p.starts_with('/') => Ok(p.clone()),
                        Some(toml::Value::String(p)) => Ok(format!("/{p}")),
                        Some(_) => Err(s.error(
                            &format!("keys.{o}"),
                            "expected a JSON pointer string such as \"/a/0/b\"",
                        )),
                        None => Ok(format!("/{o}")),
                    })
                    .collect::<iuq_study_file::Result<Vec<_>>>()?,
                None => outputs.iter().map(|o| format!("/{o}")).collect(),
            };
            DecoderFormat::Json { pointers }
        }
        "csv" => {
            let column = s.string("column")?;
            let row =
                match s.value("row") {
                    None => CsvRow::Last,
                    Some(toml::Value::String(r)) if r == "last" => CsvRow::Last,
                    Some(toml::Value::String(r)) if r == "first" => CsvRow::First,
                    Some(toml::Value::Integer(i)) if *i >= 0 => CsvRow::Index(*i as usize),
                    Some(other) => {
                        return Err(s.error(
                        "row",
                        format!("expected \"first\", \"last\" or a row index ≥ 0, found `{other}`"),
                    ).into());
                    }
                };
            match column {
                Some(column) => DecoderFormat::CsvColumn { column },
                None => DecoderFormat::CsvColumns { row },
            }
        }
        "regex" => {
            let patterns = match (s.string("pattern")?, s.sub_table("patterns")?) {
                (Some(p), None) => {
                    let re = regex::Regex::new(&p).map_err(|e| s.error("pattern", e.to_string()))?;
                    for o in outputs {
                        if re.capture_names().flatten().all(|n| n != o) {
                            return Err(s.error("pattern", format!("no named group `(?P<{o}>…)` for output `{o}`")).into());
                        }
                    }
                    vec![p; outputs.len()]
                }
                (None, Some(t)) => outputs
                    .iter()
                    .map(|o| match t.get(o) {
                        Some(toml::Value::String(p)) => Ok(p.clone()),
                        _ => Err(s.error(&format!("patterns.{o}"), "missing: a regular expression whose first group is the value")),
                    })
                    .collect::<iuq_study_file::Result<Vec<_>>>()?,
                _ => return Err(s.error("pattern", "give either `pattern` (named groups per output) or `patterns = { output = 'regex' }`").into()),
            };
            DecoderFormat::Regex { patterns }
        }
        other => {
            return Err(s
                .error(
                    "format",
                    format!("unknown format `{other}` (\"json\", \"csv\" or \"regex\")"),
                )
                .into());
        }
    };
    s.finish_with_hint(
        "file, format, keys or array (json), column and row (csv), pattern or patterns (regex)",
    )?;
    let spec = DecoderSpec {
        file: out_file,
        format,
    };
    OutputDecoder::new(spec.clone(), outputs.to_vec())
        .map_err(|r| CampaignError::study(file, "model.output", r))?;
    Ok(spec)
}

fn parse_design(table: &toml::Table, file: &str, study_dir: &Path) -> Result<StudyDesign> {
    let mut s = StudySection::new(table, "design", file);
    let kind = s.string("kind")?.unwrap_or_else(|| "lhs".into());
    let seed = match s.value("seed") {
        None => 0,
        Some(toml::Value::Integer(i)) if *i >= 0 => *i as u64,
        Some(other) => {
            return Err(s
                .error("seed", format!("expected an integer ≥ 0, found `{other}`"))
                .into());
        }
    };
    let spec = match kind.as_str() {
        "lhs" | "sobol" => {
            let n = s
                .count("n", 1)?
                .ok_or_else(|| s.error("n", "missing: the number of points"))?;
            if kind == "lhs" {
                StudyDesign::Lhs { n, seed }
            } else {
                StudyDesign::Sobol { n, seed }
            }
        }
        "file" => {
            let p = s.string("file")?.ok_or_else(|| {
                s.error("file", "missing: a CSV file with one column per parameter")
            })?;
            StudyDesign::File {
                path: relative_to(study_dir, &p),
            }
        }
        other => {
            return Err(s
                .error(
                    "kind",
                    format!("unknown design `{other}` (\"lhs\", \"sobol\" or \"file\")"),
                )
                .into());
        }
    };
    s.finish_with_hint("kind, n, seed, file")?;
    Ok(spec)
}

fn parse_executor(
    table: &toml::Table,
    file: &str,
    study_dir: &Path,
    stem: &str,
) -> Result<ExecutorSpec> {
    let mut s = StudySection::new(table, "executor", file);
    let kind = match s.string("kind")?.as_deref() {
        None | Some("local") => ExecutorKind::Local,
        Some("slurm") => ExecutorKind::Slurm,
        Some("hyperqueue") => ExecutorKind::Hyperqueue,
        Some(other) => {
            return Err(s
                .error(
                    "kind",
                    format!("unknown executor `{other}` (\"local\", \"slurm\" or \"hyperqueue\")"),
                )
                .into());
        }
    };
    let max_parallel = s.count("max_parallel", 1)?;
    let directory = relative_to(
        study_dir,
        &s.string("directory")?
            .unwrap_or_else(|| format!("{stem}.campaign")),
    );
    let mut retry = RetryPolicy::default();
    if let Some(t) = s.sub_table("retry")? {
        let mut r = StudySection::new(t, "executor.retry", file);
        if let Some(m) = r.count("max_attempts", 1)? {
            retry.max_attempts = m as u32;
        }
        if let Some(on) = r.strings("on")? {
            retry.retry_on = on
                .iter()
                .enumerate()
                .map(|(i, k)| {
                    OutcomeKind::from_name(k)
                        .filter(|k| *k != OutcomeKind::Succeeded)
                        .ok_or_else(|| {
                            r.error(
                                &format!("on[{i}]"),
                                format!(
                                    "unknown outcome `{k}` (one of {})",
                                    OutcomeKind::ALL[1..]
                                        .iter()
                                        .map(|k| k.as_str())
                                        .collect::<Vec<_>>()
                                        .join(", ")
                                ),
                            )
                        })
                })
                .collect::<iuq_study_file::Result<Vec<_>>>()?;
        }
        r.finish_with_hint("max_attempts, on")?;
    }
    let poll_interval = s.duration("poll_interval")?.unwrap_or(5.0).max(0.01);
    let array_chunk = s.count("array_chunk", 1)?.unwrap_or(1000);
    let mut submit_args = s.strings("sbatch_args")?.unwrap_or_default();
    submit_args.extend(s.strings("submit_args")?.unwrap_or_default());
    let hq = s.string("hq")?;
    let worker = s.strings("worker")?;
    if worker.as_ref().is_some_and(Vec::is_empty) {
        return Err(s.error("worker", "must name a program").into());
    }
    s.finish_with_hint("kind, max_parallel, directory, retry, poll_interval, array_chunk, sbatch_args, submit_args, hq, worker")?;
    Ok(ExecutorSpec {
        kind,
        max_parallel,
        directory,
        retry,
        poll_interval,
        array_chunk,
        submit_args,
        hq,
        worker,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const STUDY: &str = r#"
name = "fake"
[parameters]
x = { uniform = [0, 1] }
stress = { uniform = [1, 10] }
[model]
kind = "command"
command = ["sim", "--steps={{ steps }}", "{{x}}"]
derived = { steps = "ceil(100 / stress)", half = "steps / 2" }
outputs = ["f"]
output = { file = "result.json", format = "json" }
timeout = "1m30s"
[design]
kind = "lhs"
n = 20
seed = 3
[executor]
kind = "local"
max_parallel = 2
retry = { max_attempts = 2, on = ["lost", "timeout"] }
"#;

    fn parse(text: &str) -> Result<CampaignStudy> {
        CampaignStudy::parse(text, Path::new("/tmp/study.toml"))
    }

    #[test]
    fn a_valid_study_is_read() {
        let s = parse(STUDY).unwrap();
        assert_eq!(s.model.timeout, Some(90.0));
        assert_eq!(s.model.derived.len(), 2);
        assert_eq!(s.design, Some(StudyDesign::Lhs { n: 20, seed: 3 }));
        assert_eq!(s.executor.max_parallel, Some(2));
        assert_eq!(s.executor.directory, PathBuf::from("/tmp/study.campaign"));
        assert_eq!(
            s.executor.retry.retry_on,
            vec![OutcomeKind::Lost, OutcomeKind::Timeout]
        );
        assert_eq!(
            s.model.template_names(),
            vec!["x", "stress", "steps", "half", "run_id"]
        );
        assert_eq!(s.hash.len(), 64);
    }

    #[test]
    fn errors_name_file_key_and_reason() {
        let cases = [
            (
                STUDY.replace("{{x}}", "{{ y }}"),
                "model.command[2]",
                "unknown name `y`",
            ),
            (
                STUDY.replace("ceil(100 / stress)", "ceil(100 / strss)"),
                "model.derived.steps",
                "",
            ),
            (
                STUDY.replace("timeout = \"1m30s\"", "timeout = \"soon\""),
                "model.timeout",
                "",
            ),
            (
                STUDY.replace("format = \"json\"", "format = \"xml\""),
                "model.output.format",
                "unknown format",
            ),
            (
                STUDY.replace("outputs = [\"f\"]", ""),
                "model.outputs",
                "missing",
            ),
            (
                STUDY.replace("kind = \"local\"", "kind = \"pbs\""),
                "executor.kind",
                "unknown executor",
            ),
            (
                STUDY.replace("\"timeout\"]", "\"whatever\"]"),
                "executor.retry.on[1]",
                "unknown outcome",
            ),
            (STUDY.replace("n = 20", "n = 0"), "design.n", ""),
            (
                STUDY.replace("max_parallel = 2", "max_paralel = 2"),
                "executor.max_paralel",
                "unknown key",
            ),
            (
                STUDY.replace("kind = \"command\"", "kind = \"expression\""),
                "model.kind",
                "",
            ),
            (
                STUDY.replace("[design]", "[desing]"),
                "desing",
                "unknown section",
            ),
            (
                STUDY.replace("uniform = [0, 1]", "uniform = [1, 0]"),
                "parameters.x",
                "",
            ),
        ];
        for (text, key, reason) in cases {
            let e = parse(&text).unwrap_err();
            assert!(e.is_bad_input());
            let m = e.to_string();
            assert!(
                m.starts_with("/tmp/study.toml: key `") && m.contains(key) && m.contains(reason),
                "{m}"
            );
        }
    }
}
