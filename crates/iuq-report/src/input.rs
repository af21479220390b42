//! The report's input: everything a calibration study produced that the report shows.
//!
//! `iuq pipeline` fills these structures and hands them to [`crate::write_report`]; they are
//! also written verbatim into `report.json`, so every number in the report can be traced back.

use serde::{Deserialize, Serialize};

/// A whole calibration study's results, as the report shows them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StudyReport {
    /// Title of the report, e.g. "RBC calibration — healthy cells".
    pub title: String,
    /// The study's name (the `name` key of the study file).
    pub study_name: String,
    /// Key/value lines shown in the header: iuq version, command, seed, date, study file hash.
    pub provenance: Vec<(String, String)>,
    /// Names of the calibrated parameters, in sample-column order: the model parameters, then
    /// `sigma_m` when the study has a modelling error. A unit may follow in brackets.
    pub parameters: Vec<String>,
    /// The measurements the model was calibrated on.
    pub data: DataSeries,
    /// One posterior per source ("GP surrogate", optionally "cell model"); empty omits the
    /// posterior sections.
    pub posteriors: Vec<PosteriorResult>,
    /// Sobol' indices per output and per source ("model runs", "surrogate"); empty omits the
    /// sensitivity section.
    pub sensitivity: Vec<SensitivityResult>,
    /// Quality of the Gaussian-process surrogate, one entry per output; empty omits the section.
    pub gp_diagnostics: Vec<GpDiagnostic>,
    /// Counts of model runs and wall time per pipeline stage.
    pub run_statistics: RunStatistics,
    /// The adaptive engine's rounds; `None` (a one-shot design) omits the convergence section.
    #[serde(default)]
    pub convergence: Option<Convergence>,
    /// The runs in the plane of two parameters, successes and failures, one panel per run group
    /// that had a failure; empty omits the failure map.
    #[serde(default)]
    pub failure_map: Vec<FailureMapPanel>,
    /// Model runs per data point (per run group); empty omits the table.
    #[serde(default)]
    pub runs_per_point: Vec<RunsAtPoint>,
    /// The model run at the posterior beside the surrogate; `None` omits the section.
    #[serde(default)]
    pub posterior_check: Option<PosteriorCheckReport>,
    /// The model's own posterior from the surrogate's (Table 2 of a study with both columns,
    /// the importance weights' diagnostics, the model at both MAPs); `None` omits the section.
    #[serde(default)]
    pub model_posterior: Option<ModelPosteriorReport>,
    /// The cell at a MAP at every stress, in pictures (cell-model studies); `None` omits them.
    #[serde(default)]
    pub cell_portraits: Option<CellPortraits>,
    /// Per data point, how the cheap model of a two-fidelity study helps the surrogate; empty
    /// (one fidelity) omits the section.
    #[serde(default)]
    pub two_fidelity: Vec<TwoFidelityPoint>,
    /// Per principal component of a reduced basis of two fidelities, how the cheap model helps
    /// it; empty (one fidelity, or a GP per data point) omits the table.
    #[serde(default)]
    pub two_fidelity_components: Vec<TwoFidelityComponent>,
}

/// One principal component's two-fidelity emulator in a reduced basis of two fidelities:
/// c_k = ρ_k·c_L,k + δ_k.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TwoFidelityComponent {
    /// The component's rank (1: the one explaining most of the runs' variance).
    pub component: usize,
    /// The share of the runs' variance the component explains.
    pub explained_variance: f64,
    /// ρ_k, the scale of the cheap model's coefficient in the expensive one's.
    pub rho: f64,
    /// Whether the emulator uses the cheap model for this component.
    pub uses_low_fidelity: bool,
    /// The share of the expensive runs' coefficient variance ρ_k·(cheap coefficient) explains.
    pub explained_share: f64,
    /// The discrepancy δ_k's output scale.
    pub discrepancy_std: f64,
    /// Successful expensive runs (whole curves) the basis was fitted to.
    pub expensive_runs: usize,
    /// Successful cheap runs.
    pub cheap_runs: usize,
}

/// One data point's two-fidelity emulator: f_H = ρ·f_L + δ.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TwoFidelityPoint {
    /// The data point's control value.
    pub x: f64,
    /// ρ, the scale of the cheap model in the expensive one.
    pub rho: f64,
    /// Whether the emulator uses the cheap model here (else the expensive runs alone).
    pub uses_low_fidelity: bool,
    /// The share of the expensive runs' variance ρ·(cheap model) explains.
    pub explained_share: f64,
    /// The discrepancy δ's output scale (its training residuals' std).
    pub discrepancy_std: f64,
    /// Successful expensive runs informing the point.
    pub expensive_runs: usize,
    /// Successful cheap runs informing it.
    pub cheap_runs: usize,
}

/// The cell model run at a MAP at every stress, told in pictures: its final shape in the shear
/// plane with the fitted ellipse and from the side, and its elongation index against strain
/// through the whole run with the measuring window.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CellPortraits {
    /// Whose MAP, e.g. "the cell model posterior's MAP".
    pub source: String,
    /// One per stress, in increasing stress.
    pub portraits: Vec<CellPortrait>,
    /// The cell run at the other MAP (the surrogate posterior's), drawn beside these in the
    /// elongation-against-strain figure; `None` where it was not run.
    #[serde(default)]
    pub compared: Option<ComparedTraces>,
}

/// The elongation index through the runs at a second point, to set beside a
/// [`CellPortraits`]' own (the published study's Fig. 8 runs the model at both MAPs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ComparedTraces {
    /// Whose MAP, e.g. "the GP surrogate posterior's MAP".
    pub source: String,
    /// One per stress, in the order of the portraits.
    pub traces: Vec<ElongationTrace>,
}

/// One run's elongation index against strain.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ElongationTrace {
    /// The shear stress in Pa.
    pub x: f64,
    /// The run's elongation index over the measuring window, and its std.
    pub elongation_index: (f64, f64),
    /// (strain, elongation index) through the run.
    pub trace: Vec<(f64, f64)>,
}

/// One stress of [`CellPortraits`] (lengths in µm, centred on the shape's centroid).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CellPortrait {
    /// The shear stress in Pa.
    pub x: f64,
    /// The run's elongation index over the measuring window, and its std.
    pub elongation_index: (f64, f64),
    /// (strain, elongation index) through the run.
    pub trace: Vec<(f64, f64)>,
    /// The measuring window in strain (start, end).
    pub window: (f64, f64),
    /// The final shape's contour in the shear plane (flow, gradient).
    pub outline: Vec<[f64; 2]>,
    /// Its fitted ellipse: centre x, centre y, semi-major, semi-minor, angle (radians).
    pub ellipse: [f64; 5],
    /// The final shape's contour from the side (flow, vorticity).
    pub side: Vec<[f64; 2]>,
}

/// The model's own posterior beside the surrogate's: the published study's Table 2 layout (MAP,
/// mean and std from each, with their relative differences), how far the importance weights
/// can be trusted, and the model run at both MAPs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelPosteriorReport {
    /// The surrogate's source name, e.g. "GP surrogate".
    pub surrogate_source: String,
    /// The model's source name, e.g. "cell model".
    pub model_source: String,
    /// Every stage's k̂ below its threshold and the posterior reached.
    pub certified: bool,
    /// Why the method stopped, in words.
    pub stop: String,
    /// The population's size S.
    pub samples: usize,
    /// k̂ of the final weights.
    pub pareto_k: f64,
    /// Its threshold min(1 − 1/log₁₀ S, 0.7).
    pub pareto_k_threshold: f64,
    /// Effective sample size of the final weights.
    pub effective_sample_size: f64,
    /// Distinct ancestors of the weighted members (fewer than `samples` after a bridge's
    /// resampling; the standard errors are grouped by them).
    #[serde(default)]
    pub ancestors: usize,
    /// Model runs the method asked for (stored runs included).
    pub model_runs: usize,
    /// Failed model evaluations.
    pub failures: usize,
    /// Times the surrogate was corrected by a fit of the model–surrogate difference before the
    /// stages (each a batch of `samples` evaluations).
    #[serde(default)]
    pub corrections: usize,
    /// Members rerun with their parameters nudged by a billionth of their ranges to see whether
    /// the model's outputs repeat (0: no probe).
    #[serde(default)]
    pub probe_pairs: usize,
    /// The outputs that did not repeat (irregular: a chaotic or stochastic model).
    #[serde(default)]
    pub irregular_outputs: Vec<String>,
    /// The likelihood was taken as a noisy estimate: one importance step, certified by k̂.
    #[serde(default)]
    pub pseudo_marginal: bool,
    /// For a noisy likelihood, the test of the first batch's weights for a surrogate posterior
    /// off the model's (`None`: not made).
    #[serde(default)]
    pub proposal_mismatch: Option<MismatchTest>,
    /// Why a correction that was wanted was not made (a noisy likelihood: the test or k̂ asked
    /// for one; a reproducible one: every candidate's posterior lay mostly outside the batch).
    #[serde(default)]
    pub correction_not_made: Option<String>,
    /// Whether the correction made was the moment-matched one (else a least-squares fit, or a
    /// defensive batch).
    #[serde(default)]
    pub correction_moment_matched: bool,
    /// For a noisy model's defensive batch: the tempering β of the surrogate's posterior it was
    /// drawn from (π·L_s^β).
    #[serde(default)]
    pub correction_tempering: Option<f64>,
    /// For a noisy model's defensive batch drawn from a normal fitted to the first batch's
    /// weights (its weighted mean, twice its weighted second moment).
    #[serde(default)]
    pub correction_defensive_normal: bool,
    /// Whether the population is both batches of a correction, weighed as one sample of the
    /// mixture of the two posteriors (else, after a correction, the corrected batch's stages).
    #[serde(default)]
    pub both_batches: bool,
    /// Whether the moments are paired with the surrogate's posterior (its population's mean
    /// plus the weights' shift of the members' mean, a control variate), so that their MCSE
    /// counts the surrogate posterior's own sampling error and the shift's.
    #[serde(default)]
    pub paired: bool,
    /// Corrections tried and refused before the one made, each with its reason.
    #[serde(default)]
    pub corrections_refused: Vec<String>,
    /// Runs per member at each irregular data point (their likelihoods averaged; 1: none
    /// repeated).
    #[serde(default = "one")]
    pub replicates: usize,
    /// One row per parameter.
    pub parameters: Vec<ComparedParameter>,
    /// The final stage's log-weights Δβ·(ℓ_model − ℓ_surrogate) of the members whose model run
    /// succeeded (their histogram); after a noisy model's correction, the mixture weights of
    /// both batches.
    pub log_weights: Vec<f64>,
    /// The stages.
    pub stages: Vec<ModelPosteriorStageRow>,
    /// The model at both MAPs, one entry per data point.
    pub map_runs: Vec<MapRunsAtPoint>,
}

/// The permutation test of a noisy model's first batch: how far its importance-weighted
/// moments lie from the surrogate posterior's, against the weights' noise.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MismatchTest {
    /// Mahalanobis distance of the weighted mean from the surrogate posterior's.
    pub mean_shift: f64,
    /// Kullback–Leibler divergence of the weighted covariance from the surrogate posterior's.
    pub spread_divergence: f64,
    /// Bonferroni p-value of the two permutation tests.
    pub p_value: f64,
    /// The level below which the surrogate is called off.
    pub level: f64,
    /// The factor by which a correction widens the weighted stds.
    pub widening: f64,
    /// Whether a second batch followed (the moment-matched correction's, or a defensive one
    /// from the surrogate's posterior tempered), both weighed as one mixture sample.
    pub corrected: bool,
}

/// One parameter in the surrogate's and the model's posterior.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ComparedParameter {
    /// The parameter's name.
    pub name: String,
    /// MAP, mean and std of the surrogate's posterior.
    pub surrogate: (f64, f64, f64),
    /// MAP, mean and std of the model's posterior.
    pub model: (f64, f64, f64),
    /// (model − surrogate)/|surrogate| of MAP, mean and std; `None` ("–" in the table) where
    /// the surrogate's is 0.
    pub relative_difference: (Option<f64>, Option<f64>, Option<f64>),
    /// Monte Carlo standard errors of the model posterior's mean and std.
    pub mcse: (f64, f64),
}

/// One stage of the model posterior.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelPosteriorStageRow {
    /// 1, 2, …
    pub stage: usize,
    /// The tempering exponent after it.
    pub beta: f64,
    /// CV of its weights.
    pub cv: f64,
    /// k̂ of its weights.
    pub pareto_k: f64,
    /// ESS of its weights.
    pub effective_sample_size: f64,
    /// Model evaluations before its weights.
    pub model_evaluations: usize,
    /// Acceptance of the bridge's surrogate and model steps (none for the first stage).
    pub acceptance: Option<(f64, f64)>,
    /// The widest ratio of its weighted std to the members' own over the parameters (above 1.2
    /// a step to β = 1 is not certified; 0 where it could not be computed).
    #[serde(default)]
    pub spread_ratio: f64,
}

/// The model run at both MAPs at one data point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MapRunsAtPoint {
    /// The data point's control value.
    pub x: f64,
    /// The measurement and its std.
    pub datum: (f64, f64),
    /// The model at the surrogate posterior's MAP (`None`: the run failed).
    pub at_surrogate_map: Option<f64>,
    /// The model at the model posterior's MAP.
    pub at_model_map: Option<f64>,
    /// |run − datum| at the surrogate's MAP and at the model's (`None` where the run failed).
    #[serde(default)]
    pub absolute_error: (Option<f64>, Option<f64>),
}

impl MapRunsAtPoint {
    /// Both MAP runs at the data point `x` with the measurement `datum` (value, std), their
    /// absolute errors computed.
    pub fn new(
        x: f64,
        datum: (f64, f64),
        at_surrogate_map: Option<f64>,
        at_model_map: Option<f64>,
    ) -> Self {
        let error = |run: Option<f64>| run.map(|v| (v - datum.0).abs());
        Self {
            x,
            datum,
            at_surrogate_map,
            at_model_map,
            absolute_error: (error(at_surrogate_map), error(at_model_map)),
        }
    }
}

/// The model itself run at the MAP of the surrogate's posterior and at posterior samples, beside
/// the surrogate's prediction at the same parameters: the surrogate checked where the
/// calibration relies on it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PosteriorCheckReport {
    /// The posterior whose MAP and samples were run, e.g. "GP surrogate".
    pub source: String,
    /// The posterior samples run besides the MAP.
    pub samples: usize,
    /// Name of the model's diagnostic shown per run, e.g. "EL drift over the window"; `None`
    /// when the model has none.
    pub diagnostic: Option<String>,
    /// One entry per data point.
    pub points: Vec<CheckedPoint>,
    /// The check's test in words: its rule, and whether and where it failed (empty: not given).
    #[serde(default)]
    pub test: String,
}

/// The posterior check at one data point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CheckedPoint {
    /// The data point's control value.
    pub x: f64,
    /// The model's output at the MAP and its computational std; `None` when the run failed.
    pub map_model: Option<(f64, f64)>,
    /// The surrogate's mean and predictive std at the MAP.
    pub map_surrogate: (f64, f64),
    /// The model's outputs at the posterior samples whose runs succeeded.
    pub model: Vec<f64>,
    /// The surrogate's means at the same samples.
    pub surrogate: Vec<f64>,
    /// The surrogate's predictive stds there.
    pub surrogate_std: Vec<f64>,
    /// The runs' computational stds.
    pub model_std: Vec<f64>,
    /// The model's diagnostic at each successful run, the MAP's first (empty without one).
    pub diagnostic: Vec<f64>,
    /// The median of the diagnostic's absolute values (`None` without one).
    pub diagnostic_median_abs: Option<f64>,
    /// The largest of them.
    pub diagnostic_largest_abs: Option<f64>,
    /// Runs that failed (MAP and samples).
    pub failed: usize,
    /// Root mean square of model − surrogate over the successful runs, MAP included.
    pub rmse: f64,
    /// Share of those runs within two predictive stds (surrogate and computational) of the
    /// surrogate.
    pub within_two_std: f64,
}

/// How the adaptive engine converged: one entry per round.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Convergence {
    /// The stopping rule in words, e.g. "posterior means and stds move < 0.1 std between rounds
    /// and the surrogate's log-likelihood std over the posterior < 0.2".
    pub criterion: String,
    /// Whether the rule was met.
    pub converged: bool,
    /// Why the loop stopped.
    pub stop_reason: String,
    /// The sampled parameters (columns of `mean` and `std`).
    pub parameters: Vec<String>,
    /// The rounds, in order.
    pub rounds: Vec<ConvergenceRound>,
    /// Each posterior check that failed its test after the engine had stopped, in words: its
    /// runs became training runs and the rounds went on.
    #[serde(default)]
    pub retrained_checks: Vec<String>,
}

/// One round of the adaptive engine.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ConvergenceRound {
    /// Round number, from 1.
    pub round: usize,
    /// Model runs made before the round's new runs.
    pub runs: usize,
    /// New runs chosen in the round.
    pub new_runs: usize,
    /// Posterior mean per parameter.
    pub mean: Vec<f64>,
    /// Posterior std per parameter.
    pub std: Vec<f64>,
    /// Largest shift of a mean or std since the previous round beyond the sampler's noise, in
    /// posterior stds (`None` in the first round).
    pub shift: Option<f64>,
    /// The sampler's noise on the shift (twice the Monte Carlo error of the difference), in
    /// posterior stds (`None` in the first round or where unknown).
    #[serde(default)]
    pub shift_noise: Option<f64>,
    /// How far the surrogate's error could move a posterior mean or std, in posterior stds
    /// (`None` where not computed).
    #[serde(default)]
    pub surrogate_error: Option<f64>,
    /// The surrogate's std of the log-likelihood averaged over the posterior (nats).
    pub log_likelihood_std: f64,
    /// Share of the posterior farther than one length scale from every training run.
    pub extrapolation_share: f64,
    /// How much harder than the study's sampler the round's chains mixed (0: as set).
    #[serde(default)]
    pub mixing_level: u32,
    /// The check of the sampler: the largest difference of a posterior mean or std between the
    /// replicates that mixed harder and the others, beyond the noise, in posterior stds (`None`
    /// where not made).
    #[serde(default)]
    pub sampler_disagreement: Option<f64>,
}

/// The runs of one run group in the plane of two parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FailureMapPanel {
    /// The panel's title, e.g. "runs at 9.04 Pa".
    pub label: String,
    /// The parameter on the horizontal axis.
    pub x_parameter: String,
    /// The parameter on the vertical axis.
    pub y_parameter: String,
    /// Axis ranges (the priors' plotting ranges): (x_low, x_high, y_low, y_high).
    pub bounds: (f64, f64, f64, f64),
    /// One entry per run: its two coordinates.
    pub points: Vec<(f64, f64)>,
    /// Whether each run failed.
    pub failed: Vec<bool>,
    /// Whether each run was placed by the adaptive engine (else the initial or test design).
    pub adaptive: Vec<bool>,
    /// The failure classifier's probability of failure on a regular grid over `bounds` (the
    /// other parameters at their posterior means), row-major with `grid_size.0` columns in x
    /// and `grid_size.1` rows in y; empty when no run of the group failed.
    pub failure_probability: Vec<f64>,
    /// (columns, rows) of the grid.
    pub grid_size: (usize, usize),
}

/// Model runs at one data point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunsAtPoint {
    /// The data point's control value.
    pub x: f64,
    /// Runs informing it (initial, test and adaptive).
    pub runs: usize,
    /// Of which the adaptive engine placed.
    pub adaptive: usize,
    /// Of which failed.
    pub failed: usize,
}

/// The measurements: one output `y` with its measurement std `y_err` at each control value `x`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DataSeries {
    /// Label of the control variable with its unit, e.g. "shear stress (Pa)".
    pub x_label: String,
    /// Label of the measured output with its unit, e.g. "elongation index EL (–)".
    pub y_label: String,
    /// Control values, any finite numbers (times from 0, negative values, …). Figures draw them
    /// on a logarithmic axis when all are positive and span a ratio of at least 4, on a linear
    /// axis otherwise.
    pub x: Vec<f64>,
    /// Measured values.
    pub y: Vec<f64>,
    /// Measurement standard deviations (non-negative).
    pub y_err: Vec<f64>,
}

/// The posterior of one source (the GP surrogate or the cell model itself).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PosteriorResult {
    /// The source's name, e.g. "GP surrogate" or "cell model"; also picks its colour.
    pub source: String,
    /// Summary statistics, one entry per parameter, in the order of [`StudyReport::parameters`].
    pub summary: Vec<ParameterSummary>,
    /// The final estimate of the log evidence (log marginal likelihood).
    pub log_evidence: f64,
    /// Final equally weighted posterior samples: one row per sample, columns as
    /// [`StudyReport::parameters`].
    pub samples: Vec<Vec<f64>>,
    /// The sampler's per-stage diagnostics.
    pub stages: Vec<SamplerStage>,
    /// The model output propagated through the posterior, one entry per data point (in the
    /// order of [`DataSeries::x`]).
    pub propagated: Vec<PropagatedOutput>,
}

/// Posterior summary of one parameter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParameterSummary {
    /// The parameter's name.
    pub name: String,
    /// Maximum a posteriori estimate (the sample of highest posterior density).
    pub map: f64,
    /// Posterior mean.
    pub mean: f64,
    /// Posterior standard deviation.
    pub std: f64,
    /// 5 % quantile.
    pub q05: f64,
    /// Median.
    pub q50: f64,
    /// 95 % quantile.
    pub q95: f64,
}

/// Diagnostics of one BASIS stage (tempering step).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SamplerStage {
    /// Stage number, 0 for the prior samples.
    pub stage: usize,
    /// Annealing (tempering) exponent of the likelihood at this stage, in [0, 1].
    pub annealing_exponent: f64,
    /// Coefficient of variation of the plausibility weights.
    pub cv: f64,
    /// Acceptance rate of the stage's Markov chains.
    pub acceptance: f64,
    /// Running estimate of the log evidence after this stage.
    pub log_evidence: f64,
    /// Model (or surrogate) evaluations in this stage.
    pub evaluations: usize,
    /// Wall time of the stage in seconds.
    pub seconds: f64,
}

/// The model output at one data point, propagated through the posterior.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PropagatedOutput {
    /// The control value (equal to the matching [`DataSeries::x`]).
    pub x: f64,
    /// Model output at each posterior sample.
    pub samples: Vec<f64>,
    /// Model output at the MAP estimate.
    pub map_prediction: f64,
}

/// Sobol' indices of one output, estimated from one source.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SensitivityResult {
    /// The output's label, e.g. "EL at 1.36 Pa".
    pub output_label: String,
    /// The output's control value (shear stress); outputs with equal `x` share a panel.
    pub x: f64,
    /// Where the indices come from: "model runs" or "surrogate".
    pub source: String,
    /// One entry per parameter.
    pub indices: Vec<SensitivityIndex>,
}

/// First-order and total Sobol' indices of one parameter with their confidence intervals.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SensitivityIndex {
    /// The parameter's name.
    pub parameter: String,
    /// First-order index S1.
    pub first_order: f64,
    /// Lower end of the S1 confidence interval.
    pub first_order_low: f64,
    /// Upper end of the S1 confidence interval.
    pub first_order_high: f64,
    /// Total index ST.
    pub total: f64,
    /// Lower end of the ST confidence interval.
    pub total_low: f64,
    /// Upper end of the ST confidence interval.
    pub total_high: f64,
}

/// Quality of the Gaussian process of one output.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GpDiagnostic {
    /// The output's label, e.g. "EL at 1.36 Pa".
    pub output_label: String,
    /// The output's control value (shear stress).
    pub x: f64,
    /// Q² on the independent test set.
    pub q2: f64,
    /// Leave-one-out Q² on the training set.
    pub loo_q2: f64,
    /// Simulated outputs of the test set.
    pub simulated: Vec<f64>,
    /// GP predictive means at the test points.
    pub predicted: Vec<f64>,
    /// GP predictive standard deviations at the test points.
    pub predicted_std: Vec<f64>,
    /// Fitted hyper-parameters as (name, value) pairs.
    pub hyperparameters: Vec<(String, f64)>,
}

/// Counts of model runs and wall time per pipeline stage.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RunStatistics {
    /// Model runs attempted.
    pub runs: usize,
    /// Runs that produced an output.
    pub succeeded: usize,
    /// Runs that failed.
    pub failed: usize,
    /// Failed runs per reason, e.g. ("timeout", 3).
    pub failures_by_reason: Vec<(String, usize)>,
    /// Wall time of each pipeline stage in seconds, e.g. ("design", 0.2).
    pub stage_seconds: Vec<(String, f64)>,
}

/// The default of [`ModelPosteriorReport::replicates`].
fn one() -> usize {
    1
}
