//! What the report contains, section by section and in reading order: for each section its
//! figures (drawn here, SVG and PNG), its tables and its explanatory text.

use std::path::Path;

use crate::charts::cell_portraits::{CellShapesChart, ElongationTraceChart};
use crate::charts::convergence::ConvergenceChart;
use crate::charts::corner::CornerChart;
use crate::charts::data_fit::DataFitChart;
use crate::charts::failure_map::{self, FailureMapChart};
use crate::charts::gp_diagnostics::GpDiagnosticsChart;
use crate::charts::map_error::MapErrorChart;
use crate::charts::model_posterior::{LogWeightsChart, MapRunsChart};
use crate::charts::posterior_check::{self, PosteriorCheckChart};
use crate::charts::sampler_stages::{self, SamplerStagesChart};
use crate::charts::sensitivity::{DISPLAY_RANGE, SensitivityChart};
use crate::charts::violins::ViolinChart;
use crate::derived::DerivedResults;
use crate::error::Result;
use crate::figure::{Chart, FigureInfo, RenderedFigure, render_png, render_svg};
use crate::files::write_atomic;
use crate::input::{Convergence, StudyReport};
use crate::report_tables as build;
use crate::tables::Table;

/// One section of the report.
pub(crate) struct Section {
    /// HTML anchor.
    pub id: &'static str,
    /// Heading.
    pub title: &'static str,
    /// A sentence or two on what the section shows.
    pub text: String,
    /// Figures, drawn.
    pub figures: Vec<RenderedFigure>,
    /// Tables shown in the page.
    pub tables: Vec<Table>,
    /// Tables only offered as downloads (too long to show).
    pub downloads: Vec<Table>,
}

impl Section {
    fn new(id: &'static str, title: &'static str, text: impl Into<String>) -> Self {
        Self {
            id,
            title,
            text: text.into(),
            figures: Vec::new(),
            tables: Vec::new(),
            downloads: Vec::new(),
        }
    }
}

/// A figure to draw: file stem, title, caption, pixel size and the tables holding its numbers.
struct FigureSpec<'a> {
    name: &'a str,
    title: &'a str,
    caption: String,
    size: (u32, u32),
    tables: &'a [&'a str],
}

/// Draws `chart` as `figures_dir/NAME.svg` and `NAME.png` (atomically) and returns it with its
/// SVG text for the page.
fn figure(spec: FigureSpec, chart: &impl Chart, figures_dir: &Path) -> Result<RenderedFigure> {
    let (width, height) = spec.size;
    let svg = render_svg(spec.name, width, height, chart)?;
    write_atomic(
        &figures_dir.join(format!("{}.svg", spec.name)),
        svg.as_bytes(),
    )?;
    render_png(
        spec.name,
        width,
        height,
        chart,
        &figures_dir.join(format!("{}.png", spec.name)),
    )?;
    Ok(RenderedFigure {
        info: FigureInfo {
            name: spec.name.to_string(),
            title: spec.title.to_string(),
            caption: spec.caption,
            svg: format!("figures/{}.svg", spec.name),
            png: format!("figures/{}.png", spec.name),
            width,
            height,
            tables: spec.tables.iter().map(|t| t.to_string()).collect(),
        },
        svg,
    })
}

/// A file-name-safe lower-case form of `text`.
fn slug(text: &str) -> String {
    let mut slug = String::new();
    for c in text.chars() {
        if c.is_ascii_alphanumeric() {
            slug.push(c.to_ascii_lowercase());
        } else if !slug.ends_with('_') {
            slug.push('_');
        }
    }
    slug.trim_matches('_').to_string()
}

/// What every section is built from: the validated report, what was derived from it, and where
/// the figures go.
#[derive(Clone, Copy)]
struct SectionContext<'a> {
    report: &'a StudyReport,
    derived: &'a DerivedResults,
    figures_dir: &'a Path,
}

/// Builds every section of a validated report, drawing its figures into `figures_dir`, in the
/// order the report shows them; a section without its data is left out.
pub(crate) fn build_sections(
    report: &StudyReport,
    derived: &DerivedResults,
    figures_dir: &Path,
) -> Result<Vec<Section>> {
    let c = SectionContext {
        report,
        derived,
        figures_dir,
    };
    let has_posteriors = !report.posteriors.is_empty();
    let mut sections = vec![data_fit_section(&c)?];
    if has_posteriors {
        sections.push(posterior_section(&c));
    }
    if !report.sensitivity.is_empty() {
        sections.push(sensitivity_section(&c)?);
    }
    if has_posteriors {
        sections.extend(posterior_figure_sections(&c)?);
    }
    if !report.gp_diagnostics.is_empty() {
        sections.push(surrogate_section(&c)?);
    }
    if report.posteriors.iter().any(|p| !p.stages.is_empty()) {
        sections.push(sampler_section(&c)?);
    }
    if let Some(convergence) = &report.convergence {
        sections.push(convergence_section(convergence, figures_dir)?);
    }
    if let Some(check) = &report.posterior_check {
        sections.push(posterior_check_section(&c, check)?);
    }
    if let Some(m) = &report.model_posterior {
        sections.push(model_posterior_section(&c, m)?);
    }
    if let Some(portraits) = &report.cell_portraits {
        sections.push(cell_shapes_section(&c, portraits)?);
    }
    if !report.two_fidelity.is_empty() {
        let mut section = Section::new(
            "two-fidelity",
            "Two fidelities",
            "The surrogate of the expensive model as ρ·(a GP of the cheap model) + a GP discrepancy δ per data point, the cheap model used where it explains at least half of the expensive runs' variance and predicts them better (leave-one-out) than their own GP; and the runs of each model.",
        );
        section.tables.push(build::two_fidelity(report));
        sections.push(section);
    }
    if !report.two_fidelity_components.is_empty() {
        let mut section = Section::new(
            "two-fidelity",
            "Two fidelities",
            "The surrogate of the expensive model's curve on the principal components of both models' curves, each component's coefficient as ρ_k·(a GP of the cheap model's) + a GP discrepancy δ_k, the cheap model used where it explains at least half of the expensive runs' coefficient variance and predicts them better (leave-one-out) than their own GP; and the runs of each model.",
        );
        section.tables.push(build::two_fidelity_components(report));
        sections.push(section);
    }
    // Shown with the failure map, or else with the run statistics.
    let mut runs_per_point =
        (!report.runs_per_point.is_empty()).then(|| build::runs_per_point(report));
    if !report.failure_map.is_empty() {
        let mut section = failure_map_section(&c)?;
        section.tables.extend(runs_per_point.take());
        sections.push(section);
    }
    sections.push(runs_section(&c, runs_per_point));
    Ok(sections)
}

/// The measurements with the calibrated model's MAP curve and band.
fn data_fit_section(c: &SectionContext<'_>) -> Result<Section> {
    let SectionContext {
        report,
        derived,
        figures_dir,
    } = *c;
    let has_posteriors = !report.posteriors.is_empty();
    let y = &report.data.y_label;
    let mut fit = Section::new(
        "data-fit",
        "Measurements and calibrated model",
        if has_posteriors {
            "The measurements with their standard deviations, and for each source the model output at the MAP estimate and the central 95 % band of the output propagated through the posterior."
        } else {
            "The measurements with their standard deviations (no posterior was computed)."
        },
    );
    fit.figures.push(figure(
        FigureSpec {
            name: "data_fit",
            title: "Measurements and calibrated model",
            caption: format!(
                "{y} against {}: measurements (black, ± one std), MAP curve (line) and central 95 % band of the propagated output (shaded) for each source.",
                report.data.x_label
            ),
            size: (920, 600),
            tables: &["propagated"],
        },
        &DataFitChart {
            data: &report.data,
            derived,
            map_runs: report
                .posterior_check
                .iter()
                .flat_map(|c| &c.points)
                .filter_map(|p| p.map_model.map(|(y, s)| (p.x, y, s)))
                .collect(),
        },
        figures_dir,
    )?);
    fit.tables.push(build::propagated(report, derived));
    Ok(fit)
}

/// The posterior summary tables and the samples to download.
fn posterior_section(c: &SectionContext<'_>) -> Section {
    let report = c.report;
    let derived = c.derived;
    let mut posterior = Section::new(
        "posterior",
        "Posterior summary",
        "Maximum a posteriori estimate, mean, standard deviation and the 5 % and 95 % quantiles of each parameter, one column group per source.",
    );
    posterior.tables.push(build::posterior_summary(report));
    posterior
        .tables
        .push(build::posterior_evidence(report, derived));
    let mut used = Vec::new();
    for (s, p) in report.posteriors.iter().enumerate() {
        let mut name = format!("posterior_samples_{}", slug(&p.source));
        if used.contains(&name) {
            name = format!("{name}_{s}");
        }
        used.push(name.clone());
        posterior
            .downloads
            .push(build::posterior_samples(report, s, name));
    }
    posterior
}

/// Sobol' indices per output.
fn sensitivity_section(c: &SectionContext<'_>) -> Result<Section> {
    let SectionContext {
        report,
        figures_dir,
        ..
    } = *c;
    let chart = SensitivityChart::new(report);
    let mut section = Section::new(
        "sensitivity",
        "Sensitivity",
        "Sobol' indices of each output: the first-order index S1 is the share of the output variance due to the parameter alone, the total index ST includes all its interactions.",
    );
    section.figures.push(figure(
        FigureSpec {
            name: "sensitivity",
            title: "Sobol' indices per output",
            caption: format!(
                "First-order (solid) and total (light) Sobol' indices per parameter with their confidence intervals; sources side by side in each group. An estimate whose interval is wider than the index's whole range [0, 1] says nothing and is not drawn: a grey question mark stands in its place. The axis stops at {} and {}: bars or intervals beyond are cut and marked with an arrowhead (the table gives their values).",
                DISPLAY_RANGE.0, DISPLAY_RANGE.1
            ),
            size: chart.size(),
            tables: &["sensitivity"],
        },
        &chart,
        figures_dir,
    )?);
    section.tables.push(build::sensitivity(report));
    Ok(section)
}

/// The corner plot, the propagated output's violins and the MAP's error.
fn posterior_figure_sections(c: &SectionContext<'_>) -> Result<Vec<Section>> {
    let SectionContext {
        report,
        derived,
        figures_dir,
    } = *c;
    let y = &report.data.y_label;
    let mut sections = Vec::new();
    let chart = CornerChart::new(report);
    let mut section = Section::new(
        "corner",
        "Posterior densities",
        "Marginal and pairwise posterior densities (Gaussian kernel density estimates, Scott's rule) of the final posterior samples.",
    );
    section.figures.push(figure(
        FigureSpec {
            name: "corner",
            title: "Posterior marginals and pairwise densities",
            caption: "Diagonal: 1-D marginal densities, with the MAP estimate as a thin vertical line. Below: contours enclosing 68 % (thick) and 95 % (thin) of the 2-D density, MAP marked ×. Sources overlaid in their colours.".to_string(),
            size: chart.size(),
            tables: &[],
        },
        &chart,
        figures_dir,
    )?);
    sections.push(section);

    let chart = ViolinChart::new(report)?;
    let mut section = Section::new(
        "propagation",
        "Propagated uncertainty",
        format!(
            "The distribution of the model output ({y}) over the posterior at each stress, with the measurements and the MAP curves."
        ),
    );
    let split = if report.posteriors.len() == 2 {
        " With two sources each violin is split: the first source on the left, the second on the right."
    } else {
        ""
    };
    section.figures.push(figure(
        FigureSpec {
            name: "violins",
            title: "Propagated output per stress",
            caption: format!("Violins: kernel density of the output at the posterior samples, mirrored around each stress.{split} Black: measurements ± one std; lines: MAP curves."),
            size: (920, 600),
            tables: &["propagated"],
        },
        &chart,
        figures_dir,
    )?);
    sections.push(section);

    let mut section = Section::new(
        "map-error",
        "Error of the MAP prediction",
        "Absolute difference between the MAP prediction and the measurement at each stress, compared with the measurement's standard deviation.",
    );
    section.figures.push(figure(
        FigureSpec {
            name: "map_error",
            title: "Absolute error of the MAP prediction",
            caption: "Bars: |MAP prediction − measurement| per source; black dash: the measurement's standard deviation.".to_string(),
            size: (920, 460),
            tables: &["map_error"],
        },
        &MapErrorChart { data: &report.data, derived },
        figures_dir,
    )?);
    section.tables.push(build::map_error(report, derived));
    sections.push(section);
    Ok(sections)
}

/// Each output's GP against test runs.
fn surrogate_section(c: &SectionContext<'_>) -> Result<Section> {
    let SectionContext {
        report,
        figures_dir,
        ..
    } = *c;
    let chart = GpDiagnosticsChart {
        diagnostics: &report.gp_diagnostics,
    };
    let mut section = Section::new(
        "surrogate",
        "Surrogate quality",
        "Each output's Gaussian process against model runs it was not trained on. Q² = 1 − Σ(y − ŷ)² / Σ(y − ȳ)²: 1 is a perfect prediction.",
    );
    section.figures.push(figure(
        FigureSpec {
            name: "gp_diagnostics",
            title: "GP prediction against simulation",
            caption: "GP predictive mean against the simulated output on the independent test set, with ± 2 predictive std whiskers and the identity line; Q² on the test set in each title.".to_string(),
            size: chart.size(),
            tables: &["gp_quality", "gp_hyperparameters"],
        },
        &chart,
        figures_dir,
    )?);
    section.tables.push(build::gp_quality(report));
    section.tables.push(build::gp_hyperparameters(report));
    Ok(section)
}

/// BASIS's diagnostics per stage.
fn sampler_section(c: &SectionContext<'_>) -> Result<Section> {
    let SectionContext {
        report,
        figures_dir,
        ..
    } = *c;
    let mut section = Section::new(
        "sampler",
        "Sampler diagnostics",
        "Per stage of the BASIS sampler: the annealing exponent (1 at the posterior), the coefficient of variation of the plausibility weights, the acceptance rate of the Markov chains and the running log-evidence estimate.",
    );
    section.figures.push(figure(
        FigureSpec {
            name: "sampler_stages",
            title: "Sampler diagnostics per stage",
            caption: "Annealing exponent, CV of the weights, acceptance rate and log evidence against the stage, one line per source.".to_string(),
            size: sampler_stages::SIZE,
            tables: &["sampler_stages"],
        },
        &SamplerStagesChart {
            posteriors: &report.posteriors,
        },
        figures_dir,
    )?);
    section.tables.push(build::sampler_stages(report));
    Ok(section)
}

/// The model run at the posterior beside the surrogate.
fn posterior_check_section(
    c: &SectionContext<'_>,
    check: &crate::input::PosteriorCheckReport,
) -> Result<Section> {
    let SectionContext {
        report,
        figures_dir,
        ..
    } = *c;
    let mut section = Section::new(
        "posterior-check",
        "The model at the posterior",
        format!(
            "The model itself run at the MAP of the {} posterior and at {} of its samples, at every data point, beside the surrogate's prediction at the same parameters: the surrogate checked where the calibration relies on it. RMSE is the root mean square of model − surrogate over these runs; within 2σ the share of runs within two stds of the surrogate: its predictive std for a new run as the likelihood uses it (latent function and the GP's noise), with the run's own frame std and the check's resolution (a tenth of the datum's likelihood std by default).{}",
            check.source,
            check.samples,
            if check.test.is_empty() {
                String::new()
            } else {
                format!(" {}", check.test)
            }
        ),
    );
    section.figures.push(figure(
        FigureSpec {
            name: "posterior_check",
            title: "Model − surrogate at the posterior",
            caption: format!(
                "Model output minus surrogate mean at every data point ({}): posterior samples (blue), the MAP (red), twice the surrogate's median predictive std (grey band), and at each sample twice its own predictive std with the run's frame std (grey line): a sample beyond its line is outside 2σ. The MAP runs also appear in the first figure.",
                report.data.x_label
            ),
            size: posterior_check::SIZE,
            tables: &["posterior_check"],
        },
        &PosteriorCheckChart {
            check,
            x_label: &report.data.x_label,
        },
        figures_dir,
    )?);
    section.tables.push(build::posterior_check(report, check));
    Ok(section)
}

/// The model's own posterior beside the surrogate's.
fn model_posterior_section(
    c: &SectionContext<'_>,
    m: &crate::input::ModelPosteriorReport,
) -> Result<Section> {
    let SectionContext {
        report,
        figures_dir,
        ..
    } = *c;
    let mut section = Section::new(
        "model-posterior",
        "The model's own posterior",
        format!(
            "The {model}'s posterior obtained from the {surrogate}'s: {samples} members of the {surrogate} posterior run through the {model} ({runs} model runs in all), weighted by the ratio of the {model}'s likelihood to the {surrogate}'s in importance stages, each certified when the Pareto-smoothed k̂ of its weights (Vehtari et al. 2024) is below min(1 − 1/log₁₀ S, 0.7) (and, for a reproducible {model}'s step to the {model}'s posterior, when no parameter's weighted std exceeds the members' own by more than 1.2: the std ratio, since k̂ underestimates the tail of a proposal narrower than the target); where one stage does not hold, delayed-acceptance moves screened by the {surrogate} and confirmed by the {model} bridge to the next.{probe}{corrected} {stop}. Relative differences are (model − surrogate)/|surrogate|; MCSE is the Monte Carlo standard error of the model posterior's mean and std.{paired}{noisy}",
            paired = if m.paired {
                format!(
                    " The means and stds are paired with the {surrogate} posterior: its samples' moments plus the shift the weights give the members' (a control variate whose error vanishes as the weights become equal), so their MCSE counts the {surrogate} posterior's own sampling error and the shift's.",
                    surrogate = m.surrogate_source
                )
            } else {
                String::new()
            },
            noisy = if m.pseudo_marginal {
                noisy_caveat(m)
            } else {
                String::new()
            },
            model = m.model_source,
            surrogate = m.surrogate_source,
            samples = first_batch(m),
            runs = m.model_runs,
            stop = sentence_case(&m.stop),
            corrected = if m.pseudo_marginal {
                mismatch_sentence(m)
            } else {
                correction_sentence(m)
            },
            probe = probe_sentence(m),
        ),
    );
    section.tables.push(build::model_posterior_comparison(m));
    section.figures.push(figure(
        FigureSpec {
            name: "model_posterior_map_runs",
            title: "The model at both MAPs",
            caption: format!(
                "The {} run at the MAP of the {} posterior (crosses) and at the MAP of its own posterior (dots), beside the measurements (± one std); the table gives the absolute errors.",
                m.model_source, m.surrogate_source
            ),
            size: (920, 520),
            tables: &["model_posterior_map_runs"],
        },
        &MapRunsChart {
            report: m,
            data: &report.data,
        },
        figures_dir,
    )?);
    section
        .tables
        .push(build::model_posterior_map_runs(report, m));
    section.figures.push(figure(
        FigureSpec {
            name: "model_posterior_weights",
            title: "Importance log-weights",
            caption: if first_batch(m) < m.samples {
                "Histogram of the log-weights of both batches' members whose model run succeeded, weighed as one sample of the even mixture of the surrogate's posterior and the second batch's (the corrected or the tempered surrogate's), (ℓ model − ℓ surrogate) − ln ½(1 + e^(g − ln c)) with g the log of the second posterior's ratio to the first: a long right tail means a few members carry the estimate (k̂ measures it).".to_string()
            } else {
                "Histogram of the final step's log-weights Δβ·(ℓ model − ℓ surrogate) of the members whose model run succeeded (the last stage's; where the method stopped uncertified, the rest of the way to β = 1 in one step): a long right tail means a few members carry the estimate (k̂ measures it).".to_string()
            },
            size: (920, 460),
            tables: &["model_posterior_stages"],
        },
        &LogWeightsChart { report: m },
        figures_dir,
    )?);
    section.tables.push(build::model_posterior_stages(m));
    Ok(section)
}

/// The cell's shapes and elongation traces at the MAP.
fn cell_shapes_section(
    c: &SectionContext<'_>,
    portraits: &crate::input::CellPortraits,
) -> Result<Section> {
    let SectionContext { figures_dir, .. } = *c;
    let mut section = Section::new(
        "cell-shapes",
        "The cell at the MAP",
        format!(
            "The cell model run at {} at every stress: the final shape in the shear plane, whose contour (per bin along the flow, the outermost vertices across it) the elongation index is measured on with its fitted ellipse, and from the side; and the elongation index through the whole run, from the cell at rest to the end of the measuring window (shaded), whose frames give the measured value{}.",
            portraits.source,
            portraits
                .compared
                .as_ref()
                .map_or(String::new(), |c| format!(
                    ", beside the same runs at {}",
                    c.source
                ))
        ),
    );
    let chart = CellShapesChart { portraits };
    section.figures.push(figure(
        FigureSpec {
            name: "cell_shapes",
            title: "The cell's shape at every stress",
            caption: "Each panel: the last frame's contour in the shear plane (orange dots; flow to the right, gradient up) with its fitted ellipse (black), and below it the same shape seen from the side (blue; flow to the right, vorticity up). Lengths in µm, centred on the cell's centroid; every panel at the same scale.".to_string(),
            size: chart.size(),
            tables: &[],
        },
        &chart,
        figures_dir,
    )?);
    section.figures.push(figure(
        FigureSpec {
            name: "elongation_trace",
            title: "Elongation index against strain",
            caption: match &portraits.compared {
                Some(compared) => format!(
                    "The elongation index of the shear-plane contour through each run (one colour per stress, darker for higher stress): solid, the cell at {}; dashed, at {}. Shaded, the measuring window whose frames give the run's value.",
                    portraits.source, compared.source
                ),
                None => "The elongation index of the shear-plane contour through each run (one line per stress, darker for higher stress); shaded, the measuring window whose frames give the run's value.".to_string(),
            },
            size: (920, 520),
            tables: &[],
        },
        &ElongationTraceChart { portraits },
        figures_dir,
    )?);
    Ok(section)
}

/// Where the model fails, per run group.
fn failure_map_section(c: &SectionContext<'_>) -> Result<Section> {
    let SectionContext {
        report,
        figures_dir,
        ..
    } = *c;
    let chart = FailureMapChart {
        panels: &report.failure_map,
    };
    let mut section = Section::new(
        "failure-map",
        "Where the model fails",
        "The model runs in the plane of two parameters, one panel per run group with failed runs: which runs failed, where the adaptive design placed its runs, and the failure classifier's probability of failure.",
    );
    let shown = report.failure_map.len().min(failure_map::MAX_PANELS);
    let left_out = if shown < report.failure_map.len() {
        format!(
            " Only the first {shown} of {} panels are shown (report.json holds all).",
            report.failure_map.len()
        )
    } else {
        String::new()
    };
    section.figures.push(figure(
        FigureSpec {
            name: "failure_map",
            title: "Where the model fails",
            caption: format!(
                "Runs of each group: initial and test designs as hollow circles, adaptive runs filled, failed runs as crosses; shaded red, the failure classifier's probability of failure (the darker, the likelier), with the other parameters at their posterior means.{left_out}"
            ),
            size: chart.size(),
            tables: &[],
        },
        &chart,
        figures_dir,
    )?);
    Ok(section)
}

/// The run statistics, with the runs per data point where no failure map shows them.
fn runs_section(c: &SectionContext<'_>, runs_per_point: Option<Table>) -> Section {
    let (report, derived) = (c.report, c.derived);
    let mut runs = Section::new(
        "runs",
        "Run statistics",
        "Model runs of the study, failed runs by reason, and the wall time of each pipeline stage.",
    );
    runs.tables.push(build::run_counts(report, derived));
    if !report.run_statistics.failures_by_reason.is_empty() {
        runs.tables.push(build::failures_by_reason(report));
    }
    runs.tables.extend(runs_per_point);
    runs.tables.push(build::stage_times(report, derived));
    runs
}

/// Members of the first batch: all of them, or half when both batches of a correction are the
/// population (the second batch has as many).
fn first_batch(m: &crate::input::ModelPosteriorReport) -> usize {
    if m.both_batches || m.proposal_mismatch.as_ref().is_some_and(|t| t.corrected) {
        m.samples / 2
    } else {
        m.samples
    }
}

/// How a reproducible model's first batch corrected the surrogate, or why it did not.
fn correction_sentence(m: &crate::input::ModelPosteriorReport) -> String {
    let surrogate = &m.surrogate_source;
    let refused = if m.corrections_refused.is_empty() {
        String::new()
    } else {
        format!(
            " (first tried and refused: {})",
            m.corrections_refused.join("; ")
        )
    };
    if m.corrections > 0 {
        let how = if m.correction_moment_matched {
            "towards the moments of the batch's importance weights (a Gaussian log-ratio, stds widened 1.2 times)"
        } else {
            "by a quadratic fit of the difference of the two log-likelihoods"
        };
        let then = if m.both_batches {
            format!(
                " Both batches, weighed as one sample of the mixture of the {surrogate}'s posterior and the corrected one, held: they are the estimate ({} members, no bridge).",
                m.samples
            )
        } else {
            " Both batches together did not hold, so the stages went on from the corrected batch."
                .to_string()
        };
        format!(
            " The first batch's weights did not hold in one stage, so the {surrogate} was corrected {how}{refused} and a new batch drawn from the corrected {surrogate}'s posterior.{then}"
        )
    } else if let Some(reason) = &m.correction_not_made {
        format!(
            " The first batch's weights did not hold in one stage, and no correction of the {surrogate} was made: {reason}."
        )
    } else {
        String::new()
    }
}

/// `text` with its first letter in upper case (a status phrase opening a sentence).
fn sentence_case(text: &str) -> String {
    let mut chars = text.chars();
    chars
        .next()
        .map(|first| first.to_uppercase().collect::<String>() + chars.as_str())
        .unwrap_or_default()
}

/// What the test of a noisy model's first batch found and what followed.
/// What a noisy likelihood's estimate does not say: its MCSE counts the weights' spread, not
/// how each member's weight was itself drawn, and its MAP is a lucky run.
fn noisy_caveat(m: &crate::input::ModelPosteriorReport) -> String {
    format!(
        " With a noisy likelihood the MCSE is computed from the weights as drawn: where the {model}'s run-to-run spread is large against the data's std it can understate the spread of a std (about 1.5 times on a test problem whose spread is twice the data's std), and the {model} posterior's MAP is the member whose run landed best, not a maximum of the likelihood averaged over the noise.",
        model = m.model_source
    )
}

fn mismatch_sentence(m: &crate::input::ModelPosteriorReport) -> String {
    let (model, surrogate) = (&m.model_source, &m.surrogate_source);
    let not_made = m
        .correction_not_made
        .as_ref()
        .map(|reason| {
            format!(" The {model}'s runs asked for a correction of the {surrogate}, but {reason}: the one step stands.")
        })
        .unwrap_or_default();
    let Some(t) = &m.proposal_mismatch else {
        return match (m.correction_defensive_normal, m.correction_tempering) {
            (true, _) | (false, Some(_)) => {
                format!(" The one step's k̂ did not hold.{}", defensive_sentence(m))
            }
            _ => not_made,
        };
    };
    let found = format!(
        "the first batch's importance-weighted mean lies {:.2} posterior stds from the {surrogate}'s and its spread's divergence is {:.3} (a permutation test of the weights over the members: p = {:.3})",
        t.mean_shift, t.spread_divergence, t.p_value
    );
    if t.corrected {
        let why = if t.p_value < t.level {
            "beyond what the weights' noise explains"
        } else {
            "within the weights' noise, but the one step's k̂ did not hold"
        };
        match m.correction_defensive_normal || m.correction_tempering.is_some() {
            true => format!(
                " Measured on the {model}'s runs, {found}: {why}.{}",
                defensive_sentence(m)
            ),
            false => format!(
                " Measured on the {model}'s runs, {found}: {why}. So the {surrogate} was corrected towards the weighted moments (stds widened {:.1} times) and a second batch of {batch} drawn from the corrected {surrogate}'s posterior; both batches are weighed as one sample of the two posteriors' even mixture, so that {samples} members carry the estimate.",
                t.widening,
                batch = m.samples / 2,
                samples = m.samples
            ),
        }
    } else {
        if not_made.is_empty() {
            format!(" Measured on the {model}'s runs, {found}: no correction.")
        } else {
            format!(" Measured on the {model}'s runs, {found}.{not_made}")
        }
    }
}

/// The defensive batch (from a normal fitted to the weights, or from the surrogate's posterior
/// tempered), and the corrections refused before it.
fn defensive_sentence(m: &crate::input::ModelPosteriorReport) -> String {
    let surrogate = &m.surrogate_source;
    let refused = if m.corrections_refused.is_empty() {
        String::new()
    } else {
        format!(
            " The correction towards the weighted moments was refused ({}).",
            m.corrections_refused.join("; ")
        )
    };
    let from = match m.correction_tempering {
        Some(beta) if !m.correction_defensive_normal => format!(
            "the {surrogate}'s posterior tempered at β = {beta:.3} (π·L^β: the {surrogate}'s own shape, about {:.1} times as wide, with no fit to extrapolate)",
            beta.recip().sqrt()
        ),
        _ => "a normal at the first batch's importance-weighted mean with twice its weighted second moment (at least √2 times as wide as the weights' estimate of the target, and not multiplied by the surrogate's posterior, whose tail the refused correction raised)".to_string(),
    };
    format!(
        "{refused} So a defensive second batch of {} was drawn from {from}; both batches are weighed as one sample of the even mixture of the {surrogate}'s posterior and that proposal, so that {} members carry the estimate.",
        m.samples / 2,
        m.samples
    )
}

/// What the reproducibility probe found, as a sentence of the model posterior's section.
fn probe_sentence(m: &crate::input::ModelPosteriorReport) -> String {
    let model = &m.model_source;
    let nudge = "Rerun with every parameter moved by a billionth of its range";
    let one_step = "the weights are those of one importance step (pseudo-marginal: unbiased, with no fit of the log-likelihoods' difference and no bridge, whose fits and Metropolis ratios assume a reproducible likelihood), certified by k̂";
    let replicated = if m.replicates > 1 {
        format!(
            "; each irregular datum was measured by {} runs (the member's own and {} nudged by multiples of a billionth), their likelihoods averaged",
            m.replicates,
            m.replicates - 1
        )
    } else {
        String::new()
    };
    match (
        m.probe_pairs,
        m.irregular_outputs.is_empty(),
        m.pseudo_marginal,
    ) {
        (0, _, false) => String::new(),
        (0, _, true) => {
            format!(" The study declares the {model}'s likelihood noisy: {one_step}{replicated}.")
        }
        (pairs, true, false) => {
            format!(" {nudge}, {pairs} members' outputs repeated: the {model} is reproducible.")
        }
        (pairs, true, true) => format!(
            " {nudge}, {pairs} members' outputs repeated, but the study declares the {model}'s likelihood noisy: {one_step}{replicated}."
        ),
        (pairs, false, pseudo_marginal) => format!(
            " {nudge}, {pairs} members' outputs did not repeat at {}: there the {model} is irregular (chaotic or stochastic), a run's likelihood is one draw of its average over that irregular part, and {}.",
            m.irregular_outputs.join(", "),
            if pseudo_marginal {
                format!("{one_step}{replicated}")
            } else {
                "the study nevertheless treats the likelihood as reproducible (`noisy = false`)"
                    .to_string()
            }
        ),
    }
}

/// The convergence section: the stopping rule and its outcome, and, when there were rounds, the
/// figure of the posterior and the surrogate's uncertainty per round with the rounds' table.
fn convergence_section(convergence: &Convergence, figures_dir: &Path) -> Result<Section> {
    let rounds = convergence.rounds.len();
    let outcome = if convergence.converged {
        format!(
            "The rule was met after {rounds} round{}.",
            if rounds == 1 { "" } else { "s" }
        )
    } else {
        format!(
            "The rule was not met in {rounds} round{}.",
            if rounds == 1 { "" } else { "s" }
        )
    };
    let mut section = Section::new(
        "convergence",
        "Convergence of the adaptive design",
        format!(
            "Round by round, the adaptive design adds model runs where the surrogate is least certain of the likelihood and recomputes the posterior. Stopping rule: {}. {outcome} Stopped because: {}.{}",
            convergence.criterion.trim_end_matches('.'),
            convergence.stop_reason.trim_end_matches('.'),
            convergence
                .retrained_checks
                .iter()
                .map(|c| format!(" {c}"))
                .collect::<String>()
        ),
    );
    if rounds > 0 {
        let chart = ConvergenceChart { convergence };
        section.figures.push(figure(
            FigureSpec {
                name: "convergence",
                title: "Convergence of the adaptive design",
                caption: "Posterior mean (line) and ± 1 std band of each parameter, and, on a logarithmic axis, the surrogate's std of the log-likelihood averaged over the posterior (nats) and how far the surrogate's error could move a posterior mean or std (posterior stds; the stopping rule's measure), against the model runs the round's posterior was computed from, one marker per round (their spacing: the runs each round added).".to_string(),
                size: chart.size(),
                tables: &["adaptive_rounds"],
            },
            &chart,
            figures_dir,
        )?);
        section.tables.push(build::adaptive_rounds(convergence));
    }
    Ok(section)
}

#[cfg(test)]
mod tests {
    use super::slug;

    #[test]
    fn slugs_are_file_name_safe() {
        assert_eq!(slug("GP surrogate"), "gp_surrogate");
        assert_eq!(slug("cell model (HemoCell)"), "cell_model_hemocell");
    }
}
