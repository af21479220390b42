//! A second, cheaper model of the same outputs (`[low_fidelity]`): the surrogate of the study's
//! model becomes a two-fidelity emulator (`iuq_gp::MultiFidelityGp` per data point: the
//! expensive output as ρ·(the cheap model's GP) + a GP discrepancy δ, one δ in (θ, abscissa)
//! shared by the data points of a model run once per point where that predicts better,
//! `iuq_gp::shared_discrepancy`), and every adaptive round chooses, for each run it wants,
//! which model to run there.
//!
//! ```toml
//! [low_fidelity]
//! kind = "expression"            # any model kind of [model], with the same outputs
//! outputs = { y = "a * exp(-k * t)" }
//! design = { n = 40, seed = 3 }  # its initial design, beside the high fidelity's own points
//! max_runs = 400                 # its budget (default 10 × [surrogate] adaptive.max_runs)
//! cost_ratio = 100               # a high-fidelity run's cost in low-fidelity runs
//! ```
//!
//! **Runs.** The cheap model runs as a campaign of its own in `low-fidelity/` inside the study's
//! campaign directory (its own store, so kill -9 safe and resumable as the study's; the same
//! executor). Its initial design is the high fidelity's initial points (nested designs let δ
//! see the cheap model's value at every expensive run) plus a maximin Latin hypercube of
//! `design.n` points (default 4 × the high fidelity's initial runs).
//!
//! **Allocation** (per round, after the engine chose where it wants runs, on the two-fidelity
//! surrogate): at a chosen θ the surrogate's latent variance of output j splits into
//! v_L,j = ρ_j²·σ²_L,j(θ), which a cheap run there removes, and v_δ,j = σ²_δ,j(θ), which only an
//! expensive run removes. Summed over the run's outputs in units of the data's variance
//! (V_L, V_δ), a cheap run removes V_L for cost 1 and an expensive one (with a cheap run at the
//! same θ, keeping the designs nested) V_L + V_δ for cost r + 1, r the cost ratio: the cheap run
//! alone is chosen when it removes more per unit cost, V_L·(r + 1) > V_L + V_δ, i.e. V_L·r > V_δ
//! (the greedy variance-reduction-per-cost rule of multi-fidelity Bayesian optimisation;
//! Kandasamy et al. 2016, Song et al. 2019). r is `cost_ratio`, else the ratio of the two
//! stores' median run times, else 10. The rounds' stopping rule is the engine's, on the
//! posterior of the two-fidelity surrogate of the expensive model; `--model-posterior` then
//! runs the expensive model only.
//!
//! Each round's allocation is recorded in the study's store (a derived result), so a rerun
//! replays it whatever the run times measured on the new machine.

use std::sync::Mutex;

use serde_json::json;
use toml::{Table, Value};

use iuq_doe::{LhsMethod, latin_hypercube};
use iuq_gp::{MultiFidelityBank, MultiFidelityGp, ReducedBasis};
use iuq_study_file::StudySection;

use super::events::Events;
use super::model_runs::{ModelRuns, RunRequests};
use super::run_groups::{Curves, GroupRuns, OutputRuns, RunOrigin};
use crate::error::{Result, StudyError, input_error};
use crate::likelihood_section::DataLikelihood;
use crate::study::Study;

/// The cost ratio assumed before either store has timed a run and none is declared.
pub const DEFAULT_COST_RATIO: f64 = 10.0;

/// The low fidelity's initial design by default: this many times the high fidelity's.
pub const DESIGN_FACTOR: usize = 4;

/// Its run budget by default: this many times the high fidelity's `max_runs`.
pub const BUDGET_FACTOR: usize = 10;

/// `[low_fidelity]`'s own keys (the others are its model's).
const OWN_KEYS: [&str; 3] = ["design", "max_runs", "cost_ratio"];

/// The keys of `[low_fidelity]` that are not its model's.
#[derive(Debug, Clone, PartialEq)]
pub struct LowFidelitySettings {
    /// Points of its Latin hypercube (beside the high fidelity's initial points).
    pub design_runs: usize,
    /// Seed of that hypercube.
    pub design_seed: u64,
    /// The most low-fidelity runs.
    pub max_runs: usize,
    /// A high-fidelity run's cost in low-fidelity runs, where declared.
    pub cost_ratio: Option<f64>,
}

/// The study's `[low_fidelity]`, if any: its own keys and the study as it would read with the
/// cheap model as its `[model]` (its campaign in `low-fidelity/` of the study's campaign
/// directory). An error names the study file and the `low_fidelity.` key.
pub fn low_fidelity_study(
    study: &Study,
    high_initial_runs: usize,
    high_max_runs: usize,
    training_seed: u64,
) -> Result<Option<(Study, LowFidelitySettings)>> {
    let Some(table) = &study.low_fidelity else {
        return Ok(None);
    };
    let file = study.path.display().to_string();
    let mut own = Table::new();
    let mut model = table.clone();
    for key in OWN_KEYS {
        if let Some(v) = model.remove(key) {
            own.insert(key.into(), v);
        }
    }
    let mut s = StudySection::new(&own, "low_fidelity", &file);
    let (design_runs, design_seed) = match s.sub_table("design")? {
        Some(t) => {
            let mut d = StudySection::new(t, "low_fidelity.design", &file);
            let n = d.count("n", 0)?;
            let seed = d.seed("seed")?;
            d.finish()?;
            (n, seed)
        }
        None => (None, None),
    };
    let max_runs = s.count("max_runs", 1)?;
    let cost_ratio = s.positive("cost_ratio")?;
    s.finish()?;
    let settings = LowFidelitySettings {
        design_runs: design_runs.unwrap_or(DESIGN_FACTOR * high_initial_runs),
        design_seed: design_seed.unwrap_or(training_seed.wrapping_add(1000)),
        max_runs: max_runs.unwrap_or(BUDGET_FACTOR * high_max_runs),
        cost_ratio,
    };
    let text = std::fs::read_to_string(&study.path)
        .map_err(|e| input_error(format!("{file}: cannot read: {e}")).with_source(e))?;
    let mut root: Table = text
        .parse()
        .map_err(|e| input_error(format!("{file}: {e}")).with_source(e))?;
    root.remove("low_fidelity");
    root.insert("model".into(), Value::Table(model));
    root.insert(
        "name".into(),
        Value::String(format!("{}-low-fidelity", study.name)),
    );
    let mut executor = study.executor.clone().unwrap_or_default();
    let stem = study
        .path
        .file_stem()
        .map_or_else(|| "study".to_string(), |s| s.to_string_lossy().into_owned());
    let directory = executor
        .get("directory")
        .and_then(Value::as_str)
        .map_or_else(|| format!("{stem}.campaign"), str::to_string);
    executor.insert(
        "directory".into(),
        Value::String(format!("{directory}/low-fidelity")),
    );
    root.insert("executor".into(), Value::Table(executor));
    let text = toml::to_string(&root).map_err(|e| {
        StudyError::failure(format!("cannot write the low-fidelity study: {e}")).with_source(e)
    })?;
    let low = Study::parse(&text, &study.path).map_err(|e| match e {
        StudyError::BadInput(_) => e.map_message(|m| {
            m.replace("key `model.", "key `low_fidelity.")
                .replace("key `model`", "key `low_fidelity`")
                .replace("section `[model]`", "section `[low_fidelity]`")
        }),
        other => other,
    })?;
    Ok(Some((low, settings)))
}

/// Data point j's latent variance at θ split by fidelity: (what a cheap run there would
/// remove, what only an expensive run removes); `super::emulator::Emulator::fidelity_variances`.
pub(super) type FidelitySplit<'a> = &'a dyn Fn(usize, &[f64]) -> Result<(f64, f64)>;

/// The cheap model's runs, their campaign and its settings.
pub struct LowFidelity {
    /// The cheap model as a campaign.
    pub runs: ModelRuns,
    /// `[low_fidelity]`'s own keys.
    pub settings: LowFidelitySettings,
    groups: Mutex<Vec<GroupRuns>>,
}

/// A round's runs of each fidelity.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Allocation {
    /// Runs of the study's model.
    pub high: RunRequests,
    /// Runs of the cheap model.
    pub low: RunRequests,
}

impl LowFidelity {
    /// Open the cheap model's campaign (`low_study` and `settings` from
    /// [`low_fidelity_study`]); its outputs must map onto the data as the study's model's do.
    pub(super) fn open(
        low_study: &Study,
        settings: LowFidelitySettings,
        data: &DataLikelihood,
        max_parallel: Option<usize>,
        callable: Option<iuq_campaign::SharedModel>,
        events: &Events,
    ) -> Result<Self> {
        let runs = ModelRuns::open(
            low_study,
            data,
            max_parallel,
            callable,
            events,
            events.campaign_progress("low-fidelity runs"),
        )
        .map_err(|e| match e {
            StudyError::BadInput(_) => e.map_message(|m| {
                m.replace("key `model.", "key `low_fidelity.")
                    .replace("key `model`", "key `low_fidelity`")
            }),
            other => other,
        })?;
        let groups = vec![GroupRuns::default(); runs.groups()];
        Ok(Self {
            runs,
            settings,
            groups: Mutex::new(groups),
        })
    }

    fn groups(&self) -> Result<std::sync::MutexGuard<'_, Vec<GroupRuns>>> {
        self.groups
            .lock()
            .map_err(|_| StudyError::failure("the low-fidelity runs' lock is poisoned"))
    }

    /// The cheap model's group and position of data point `j`.
    fn locate(&self, j: usize) -> (usize, usize) {
        (0..self.runs.groups())
            .find_map(|g| {
                let r = self.runs.group_outputs(g);
                r.contains(&j).then(|| (g, j - r.start))
            })
            .unwrap_or((0, j))
    }

    /// The cheap runs of the groups holding the outputs of the study's run group `g`: one
    /// request per such group at `theta`.
    fn requests_for(&self, high: &ModelRuns, g: usize, theta: &[f64]) -> RunRequests {
        let mut groups: Vec<usize> = high.group_outputs(g).map(|j| self.locate(j).0).collect();
        groups.dedup();
        groups.into_iter().map(|l| (l, theta.to_vec())).collect()
    }

    /// The initial runs: at every initial point of the study's model (nested), then the Latin
    /// hypercube of `design.n` points in every group.
    pub(super) fn initial_runs(
        &self,
        study: &Study,
        high: &ModelRuns,
        high_groups: &[GroupRuns],
        maximin_candidates: usize,
    ) -> Result<()> {
        let mut requests: RunRequests = Vec::new();
        for (g, group) in high_groups.iter().enumerate() {
            for (theta, origin) in group.points.iter().zip(&group.origins) {
                if *origin == RunOrigin::Initial {
                    for r in self.requests_for(high, g, theta) {
                        if !requests.contains(&r) {
                            requests.push(r);
                        }
                    }
                }
            }
        }
        let space = &study.space;
        if self.settings.design_runs > 0 {
            let unit = latin_hypercube(
                self.settings.design_runs,
                space.dimension(),
                LhsMethod::Maximin {
                    candidates: maximin_candidates,
                },
                self.settings.design_seed,
            )?;
            let points: Vec<Vec<f64>> = unit
                .iter()
                .map(|u| space.from_unit_cube(u).map_err(StudyError::from))
                .collect::<Result<_>>()?;
            for g in 0..self.runs.groups() {
                requests.extend(points.iter().map(|p| (g, p.clone())));
            }
        }
        let outcomes = self.runs.run(Some("low-fidelity-initial"), &requests)?;
        self.add(RunOrigin::Initial, requests, outcomes)
    }

    fn add(
        &self,
        origin: RunOrigin,
        requests: RunRequests,
        outcomes: Vec<iuq_core::Outcome>,
    ) -> Result<()> {
        let mut groups = self.groups()?;
        for ((g, theta), outcome) in requests.into_iter().zip(outcomes) {
            groups[g].extend(origin, vec![theta], vec![outcome]);
        }
        Ok(())
    }

    /// The successful runs of a whole-curve cheap model (one run group): θ and every output.
    pub(super) fn training_curves(&self) -> Result<Curves> {
        match self.groups()?.as_slice() {
            [group] => Ok(group.training_curves()),
            groups => Err(StudyError::failure(format!(
                "a reduced basis of two fidelities needs a whole-curve cheap model (one run group), not {} run groups",
                groups.len()
            ))),
        }
    }

    /// The successful runs of data point `j`.
    pub(super) fn training(&self, j: usize) -> Result<OutputRuns> {
        let (g, k) = self.locate(j);
        Ok(self.groups()?[g].training(k))
    }

    /// Runs made so far.
    pub fn runs_made(&self) -> Result<usize> {
        Ok(self.groups()?.iter().map(GroupRuns::len).sum())
    }

    /// Every run (θ and outcome) of every group, for the round's fingerprint.
    pub(super) fn fingerprint_text(&self) -> Result<String> {
        let groups = self.groups()?;
        Ok(groups
            .iter()
            .enumerate()
            .map(|(g, group)| {
                format!(
                    "low fidelity group {g} points {:?} outcomes {:?}\n",
                    group.points, group.outcomes
                )
            })
            .collect())
    }

    /// r: `cost_ratio`, else the stores' median run times' ratio, else [`DEFAULT_COST_RATIO`].
    pub(super) fn cost_ratio(&self, high: &ModelRuns) -> Result<f64> {
        if let Some(r) = self.settings.cost_ratio {
            return Ok(r);
        }
        let high_seconds = high.campaign().median_run_seconds()?;
        let low_seconds = self.runs.campaign().median_run_seconds()?;
        Ok(match (high_seconds, low_seconds) {
            (Some(h), Some(l)) if h > 0.0 && l > 0.0 => (h / l).max(1.0),
            _ => DEFAULT_COST_RATIO,
        })
    }

    /// Split the runs the engine wants (`requests`, of the study's model) by the rule of the
    /// module docs: cheap runs alone where they remove more variance per unit cost, else the
    /// expensive run with a cheap one at the same θ; within `low_budget` cheap runs.
    pub(super) fn allocate(
        &self,
        fidelity_variances: FidelitySplit<'_>,
        high: &ModelRuns,
        data_variance: &dyn Fn(usize) -> f64,
        requests: RunRequests,
        cost_ratio: f64,
    ) -> Result<Allocation> {
        let mut budget = self.settings.max_runs.saturating_sub(self.runs_made()?);
        let groups = self.groups()?;
        let has_run = |r: &(usize, Vec<f64>)| groups[r.0].points.contains(&r.1);
        let mut allocation = Allocation::default();
        for (g, theta) in requests {
            let (mut v_low, mut v_delta) = (0.0, 0.0);
            for j in high.group_outputs(g) {
                let (low, delta) = fidelity_variances(j, &theta)?;
                let tau = data_variance(j);
                v_low += low / tau;
                v_delta += delta / tau;
            }
            let cheap: RunRequests = self
                .requests_for(high, g, &theta)
                .into_iter()
                .filter(|r| !has_run(r) && !allocation.low.contains(r))
                .collect();
            let cheap_alone = v_low * cost_ratio > v_delta;
            if cheap_alone && !cheap.is_empty() && cheap.len() <= budget {
                budget -= cheap.len();
                allocation.low.extend(cheap);
                continue;
            }
            if cheap.len() <= budget {
                budget -= cheap.len();
                allocation.low.extend(cheap);
            }
            allocation.high.push((g, theta));
        }
        Ok(allocation)
    }

    /// Run the cheap runs of round `round` (design `adaptive-round-<round>` of its store).
    pub(super) fn run_round(&self, round: usize, requests: RunRequests) -> Result<()> {
        if requests.is_empty() {
            return Ok(());
        }
        let outcomes = self
            .runs
            .run(Some(&format!("adaptive-round-{round}")), &requests)?;
        self.add(RunOrigin::Adaptive { round }, requests, outcomes)
    }
}

/// The key under which round `round`'s allocation is recorded in the study's store.
pub(super) fn allocation_key(round: usize) -> String {
    format!("two-fidelity-round-{round}")
}

/// Per data point, ρ, whether both fidelities are used and the two leave-one-out densities
/// (`two-fidelity.json`).
pub(super) fn two_fidelity_summary(bank: &MultiFidelityBank) -> serde_json::Value {
    json!({ "outputs": two_fidelity_entries("output", bank.output_names().iter().cloned().zip(bank.gps())) })
}

/// Per component of a reduced basis of two fidelities, as [`two_fidelity_summary`] per data
/// point (`two-fidelity.json`); components of one fidelity are left out.
pub(super) fn two_fidelity_basis_summary(basis: &ReducedBasis) -> serde_json::Value {
    let components = basis
        .component_gps()
        .iter()
        .enumerate()
        .filter_map(|(k, c)| c.two_fidelity().map(|gp| (format!("{}", k + 1), gp)));
    json!({ "components": two_fidelity_entries("component", components) })
}

/// One entry per named two-fidelity GP: its name under `key`, ρ, its use of the cheap model,
/// the share it explains, both leave-one-out densities and the discrepancy's std.
fn two_fidelity_entries<'a>(
    key: &str,
    gps: impl Iterator<Item = (String, &'a MultiFidelityGp)>,
) -> Vec<serde_json::Value> {
    gps.map(|(name, gp)| {
        let (two, one) = gp.loo_log_densities();
        json!({
            key: name,
            "rho": gp.rho(),
            "uses_low_fidelity": gp.uses_low_fidelity(),
            "explained_share": gp.explained_share(),
            "loo_log_density_two_fidelities": two,
            "loo_log_density_high_fidelity_alone": one,
            "discrepancy_std": gp.discrepancy_std(),
            "shared_discrepancy": gp.shared_point().is_some(),
        })
    })
    .collect()
}

/// One line on how much the cheap model helps.
pub(super) fn two_fidelity_message(bank: &MultiFidelityBank) -> String {
    helped_line(bank.gps().iter(), "data points")
}

/// One line on how much the cheap model helps a reduced basis of two fidelities.
pub(super) fn two_fidelity_basis_message(basis: &ReducedBasis) -> String {
    let gps = basis
        .component_gps()
        .iter()
        .filter_map(|c| c.two_fidelity());
    helped_line(gps, "principal components")
}

/// "two fidelities: the cheap model helps u of n `what` (ρ …)", or with one discrepancy shared
/// across the data points "… n of n data points through one discrepancy in (θ, abscissa)
/// (ρ …)".
fn helped_line<'a>(gps: impl Iterator<Item = &'a MultiFidelityGp> + Clone, what: &str) -> String {
    let used = gps.clone().filter(|g| g.uses_low_fidelity()).count();
    let n = gps.clone().count();
    if gps.clone().any(|g| g.shared_point().is_some()) {
        let rho = gps.clone().next().map_or(0.0, |g| g.rho());
        return format!(
            "two fidelities: the cheap model helps {used} of {n} {what} through one discrepancy in (θ, abscissa) (ρ {rho:.3})"
        );
    }
    let rhos: Vec<String> = gps.clone().map(|g| format!("{:.3}", g.rho())).collect();
    format!(
        "two fidelities: the cheap model helps {used} of {n} {what} (ρ {})",
        rhos.join(", ")
    )
}
