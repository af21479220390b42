//! The report's tables, built from the study's results and the derived quantities. Every
//! numeric cell points at its value in `report.json` (`/report/…` for input, `/derived/…` for
//! computed values).

use crate::charts::sensitivity::informative;
use crate::derived::DerivedResults;
use crate::input::{
    Convergence, DataSeries, ModelPosteriorReport, PosteriorCheckReport, StudyReport,
};
use crate::tables::{Cell, Column, Table};

/// The leading columns of the tables per data point: the abscissa, the measurement, its std.
fn data_columns(data: &DataSeries) -> Vec<Column> {
    vec![
        Column::plain(data.x_label.clone()),
        Column::plain("data"),
        Column::plain("data std"),
    ]
}

/// The cells of [`data_columns`] for data point `i`, pointing into `report.json`.
fn data_cells(data: &DataSeries, i: usize) -> Vec<Cell> {
    vec![
        Cell::number(data.x[i], format!("/report/data/x/{i}")),
        Cell::number(data.y[i], format!("/report/data/y/{i}")),
        Cell::number(data.y_err[i], format!("/report/data/y_err/{i}")),
    ]
}

/// Propagated output at each data point: measurement, and per source MAP, mean and 95 % band.
pub(crate) fn propagated(report: &StudyReport, derived: &DerivedResults) -> Table {
    let data = &report.data;
    let mut columns = data_columns(data);
    for prediction in &derived.predictions {
        for header in ["MAP", "mean", "2.5 %", "97.5 %"] {
            columns.push(Column::grouped(prediction.source.clone(), header));
        }
    }
    let rows = (0..data.x.len())
        .map(|i| {
            let mut row = data_cells(data, i);
            for (s, prediction) in derived.predictions.iter().enumerate() {
                let point = &prediction.points[i];
                let at = |field: &str| format!("/derived/predictions/{s}/points/{i}/{field}");
                row.push(Cell::number(point.map_prediction, at("map_prediction")));
                row.push(Cell::number(point.mean, at("mean")));
                row.push(Cell::number(point.q025, at("q025")));
                row.push(Cell::number(point.q975, at("q975")));
            }
            row
        })
        .collect();
    Table {
        name: "propagated".into(),
        title: "Propagated output at the data points".into(),
        columns,
        rows,
    }
}

/// Posterior summary: MAP, mean, std, 5 % and 95 % quantiles per parameter, one column group
/// per source.
pub(crate) fn posterior_summary(report: &StudyReport) -> Table {
    let mut columns = vec![Column::plain("parameter")];
    for posterior in &report.posteriors {
        for header in ["MAP", "mean", "std", "5 %", "95 %"] {
            columns.push(Column::grouped(posterior.source.clone(), header));
        }
    }
    let rows = report
        .parameters
        .iter()
        .enumerate()
        .map(|(p, name)| {
            let mut row = vec![Cell::text(name.clone())];
            for (s, posterior) in report.posteriors.iter().enumerate() {
                let summary = &posterior.summary[p];
                let at = |field: &str| format!("/report/posteriors/{s}/summary/{p}/{field}");
                row.push(Cell::number(summary.map, at("map")));
                row.push(Cell::number(summary.mean, at("mean")));
                row.push(Cell::number(summary.std, at("std")));
                row.push(Cell::number(summary.q05, at("q05")));
                row.push(Cell::number(summary.q95, at("q95")));
            }
            row
        })
        .collect();
    Table {
        name: "posterior_summary".into(),
        title: "Posterior summary".into(),
        columns,
        rows,
    }
}

/// Per source: number of posterior samples and log evidence.
pub(crate) fn posterior_evidence(report: &StudyReport, derived: &DerivedResults) -> Table {
    Table {
        name: "posterior_evidence".into(),
        title: "Posterior samples and evidence".into(),
        columns: vec![
            Column::plain("source"),
            Column::plain("samples"),
            Column::plain("log evidence"),
        ],
        rows: report
            .posteriors
            .iter()
            .enumerate()
            .map(|(s, posterior)| {
                vec![
                    Cell::text(posterior.source.clone()),
                    Cell::count(
                        derived.posterior_sample_counts[s],
                        format!("/derived/posterior_sample_counts/{s}"),
                    ),
                    Cell::number(
                        posterior.log_evidence,
                        format!("/report/posteriors/{s}/log_evidence"),
                    ),
                ]
            })
            .collect(),
    }
}

/// The posterior samples of source `s`, one column per parameter (a download, not shown).
pub(crate) fn posterior_samples(report: &StudyReport, s: usize, name: String) -> Table {
    let posterior = &report.posteriors[s];
    Table {
        name,
        title: format!("Posterior samples: {}", posterior.source),
        columns: report.parameters.iter().map(Column::plain).collect(),
        rows: posterior
            .samples
            .iter()
            .enumerate()
            .map(|(k, row)| {
                row.iter()
                    .enumerate()
                    .map(|(p, &v)| {
                        Cell::number(v, format!("/report/posteriors/{s}/samples/{k}/{p}"))
                    })
                    .collect()
            })
            .collect(),
    }
}

/// Sobol' indices in long form: one row per output, source and parameter.
pub(crate) fn sensitivity(report: &StudyReport) -> Table {
    let columns = [
        "output",
        "x",
        "source",
        "parameter",
        "S1",
        "S1 low",
        "S1 high",
        "ST",
        "ST low",
        "ST high",
        "informative",
    ]
    .map(Column::plain)
    .to_vec();
    let mut rows = Vec::new();
    for (r, result) in report.sensitivity.iter().enumerate() {
        for (k, index) in result.indices.iter().enumerate() {
            let at = |field: &str| format!("/report/sensitivity/{r}/indices/{k}/{field}");
            rows.push(vec![
                Cell::text(result.output_label.clone()),
                Cell::number(result.x, format!("/report/sensitivity/{r}/x")),
                Cell::text(result.source.clone()),
                Cell::text(index.parameter.clone()),
                Cell::number(index.first_order, at("first_order")),
                Cell::number(index.first_order_low, at("first_order_low")),
                Cell::number(index.first_order_high, at("first_order_high")),
                Cell::number(index.total, at("total")),
                Cell::number(index.total_low, at("total_low")),
                Cell::number(index.total_high, at("total_high")),
                Cell::text(
                    match (
                        informative(index.first_order_low, index.first_order_high),
                        informative(index.total_low, index.total_high),
                    ) {
                        (true, true) => "yes",
                        (false, false) => "no: intervals wider than [0, 1]",
                        (true, false) => "S1 only: ST's interval wider than [0, 1]",
                        (false, true) => "ST only: S1's interval wider than [0, 1]",
                    },
                ),
            ]);
        }
    }
    Table {
        name: "sensitivity".into(),
        title: "Sobol' indices".into(),
        columns,
        rows,
    }
}

/// Absolute error of each source's MAP prediction at each data point, also in units of the
/// measurement std.
pub(crate) fn map_error(report: &StudyReport, derived: &DerivedResults) -> Table {
    let data = &report.data;
    let mut columns = data_columns(data);
    for prediction in &derived.predictions {
        for header in ["MAP", "|MAP − data|", "|MAP − data| / std"] {
            columns.push(Column::grouped(prediction.source.clone(), header));
        }
    }
    let rows = (0..data.x.len())
        .map(|i| {
            let mut row = data_cells(data, i);
            for (s, prediction) in derived.predictions.iter().enumerate() {
                let point = &prediction.points[i];
                let at = |field: &str| format!("/derived/predictions/{s}/points/{i}/{field}");
                row.push(Cell::number(point.map_prediction, at("map_prediction")));
                row.push(Cell::number(point.absolute_error, at("absolute_error")));
                row.push(match point.error_in_data_std {
                    Some(value) => Cell::number(value, at("error_in_data_std")),
                    None => Cell::Empty,
                });
            }
            row
        })
        .collect();
    Table {
        name: "map_error".into(),
        title: "Error of the MAP prediction".into(),
        columns,
        rows,
    }
}

/// Q² on the test set and leave-one-out Q² per output.
pub(crate) fn gp_quality(report: &StudyReport) -> Table {
    Table {
        name: "gp_quality".into(),
        title: "Surrogate quality".into(),
        columns: ["output", "x", "Q² (test set)", "Q² (leave-one-out)"]
            .map(Column::plain)
            .to_vec(),
        rows: report
            .gp_diagnostics
            .iter()
            .enumerate()
            .map(|(g, d)| {
                vec![
                    Cell::text(d.output_label.clone()),
                    Cell::number(d.x, format!("/report/gp_diagnostics/{g}/x")),
                    Cell::number(d.q2, format!("/report/gp_diagnostics/{g}/q2")),
                    Cell::number(d.loo_q2, format!("/report/gp_diagnostics/{g}/loo_q2")),
                ]
            })
            .collect(),
    }
}

/// Fitted hyper-parameters per output, one column per hyper-parameter name (empty where an
/// output's GP lacks it).
pub(crate) fn gp_hyperparameters(report: &StudyReport) -> Table {
    let mut names: Vec<&str> = Vec::new();
    for diagnostic in &report.gp_diagnostics {
        for (name, _) in &diagnostic.hyperparameters {
            if !names.contains(&name.as_str()) {
                names.push(name);
            }
        }
    }
    let mut columns = vec![Column::plain("output")];
    columns.extend(names.iter().map(|n| Column::plain(*n)));
    let rows = report
        .gp_diagnostics
        .iter()
        .enumerate()
        .map(|(g, d)| {
            let mut row = vec![Cell::text(d.output_label.clone())];
            for name in &names {
                row.push(
                    match d.hyperparameters.iter().position(|(n, _)| n == name) {
                        Some(h) => Cell::number(
                            d.hyperparameters[h].1,
                            format!("/report/gp_diagnostics/{g}/hyperparameters/{h}/1"),
                        ),
                        None => Cell::Empty,
                    },
                );
            }
            row
        })
        .collect();
    Table {
        name: "gp_hyperparameters".into(),
        title: "GP hyper-parameters".into(),
        columns,
        rows,
    }
}

/// The sampler's stages of every source.
pub(crate) fn sampler_stages(report: &StudyReport) -> Table {
    let columns = [
        "source",
        "stage",
        "annealing exponent",
        "CV",
        "acceptance",
        "log evidence",
        "evaluations",
        "seconds",
    ]
    .map(Column::plain)
    .to_vec();
    let mut rows = Vec::new();
    for (s, posterior) in report.posteriors.iter().enumerate() {
        for (k, stage) in posterior.stages.iter().enumerate() {
            let at = |field: &str| format!("/report/posteriors/{s}/stages/{k}/{field}");
            rows.push(vec![
                Cell::text(posterior.source.clone()),
                Cell::count(stage.stage, at("stage")),
                Cell::number(stage.annealing_exponent, at("annealing_exponent")),
                Cell::number(stage.cv, at("cv")),
                Cell::number(stage.acceptance, at("acceptance")),
                Cell::number(stage.log_evidence, at("log_evidence")),
                Cell::count(stage.evaluations, at("evaluations")),
                Cell::number(stage.seconds, at("seconds")),
            ]);
        }
    }
    Table {
        name: "sampler_stages".into(),
        title: "Sampler stages".into(),
        columns,
        rows,
    }
}

/// Counts of model runs.
pub(crate) fn run_counts(report: &StudyReport, derived: &DerivedResults) -> Table {
    let stats = &report.run_statistics;
    let mut rows = vec![
        vec![
            Cell::text("total"),
            Cell::count(stats.runs, "/report/run_statistics/runs"),
        ],
        vec![
            Cell::text("succeeded"),
            Cell::count(stats.succeeded, "/report/run_statistics/succeeded"),
        ],
        vec![
            Cell::text("failed"),
            Cell::count(stats.failed, "/report/run_statistics/failed"),
        ],
        vec![
            Cell::text("failed (fraction of those made)"),
            Cell::number(derived.failure_fraction, "/derived/failure_fraction"),
        ],
    ];
    if derived.not_run > 0 {
        rows.push(vec![
            Cell::text("not run (pending or cancelled)"),
            Cell::count(derived.not_run, "/derived/not_run"),
        ]);
    }
    Table {
        name: "run_counts".into(),
        title: "Model runs".into(),
        columns: vec![Column::plain("runs"), Column::plain("count")],
        rows,
    }
}

/// Failed runs per reason.
pub(crate) fn failures_by_reason(report: &StudyReport) -> Table {
    Table {
        name: "failures_by_reason".into(),
        title: "Failed runs by reason".into(),
        columns: vec![Column::plain("reason"), Column::plain("runs")],
        rows: report
            .run_statistics
            .failures_by_reason
            .iter()
            .enumerate()
            .map(|(k, (reason, count))| {
                vec![
                    Cell::text(reason.clone()),
                    Cell::count(
                        *count,
                        format!("/report/run_statistics/failures_by_reason/{k}/1"),
                    ),
                ]
            })
            .collect(),
    }
}

/// Wall time per pipeline stage, and the total.
pub(crate) fn stage_times(report: &StudyReport, derived: &DerivedResults) -> Table {
    let mut rows: Vec<Vec<Cell>> = report
        .run_statistics
        .stage_seconds
        .iter()
        .enumerate()
        .map(|(k, (stage, seconds))| {
            vec![
                Cell::text(stage.clone()),
                Cell::number(
                    *seconds,
                    format!("/report/run_statistics/stage_seconds/{k}/1"),
                ),
            ]
        })
        .collect();
    rows.push(vec![
        Cell::text("total"),
        Cell::number(derived.total_stage_seconds, "/derived/total_stage_seconds"),
    ]);
    Table {
        name: "stage_times".into(),
        title: "Wall time per pipeline stage".into(),
        columns: vec![Column::plain("stage"), Column::plain("seconds")],
        rows,
    }
}

/// The adaptive engine's rounds: runs, shift, sampler noise, surrogate error, the surrogate's
/// log-likelihood std, the extrapolated share, the check of the sampler and its mixing level,
/// then the posterior mean and std of each parameter (one column group per
/// parameter).
pub(crate) fn adaptive_rounds(convergence: &Convergence) -> Table {
    let parameters = &convergence.parameters;
    let mut columns = [
        "round",
        "runs",
        "new runs",
        "shift (posterior stds)",
        "sampler noise (posterior stds)",
        "surrogate error (posterior stds)",
        "log-likelihood std (nats)",
        "extrapolated share",
        "sampler disagreement (posterior stds)",
        "mixing level",
    ]
    .map(Column::plain)
    .to_vec();
    for name in parameters {
        columns.push(Column::grouped(name.clone(), "mean"));
        columns.push(Column::grouped(name.clone(), "std"));
    }
    let rows = convergence
        .rounds
        .iter()
        .enumerate()
        .map(|(i, round)| {
            let at = |field: &str| format!("/report/convergence/rounds/{i}/{field}");
            let mut row = vec![
                Cell::count(round.round, at("round")),
                Cell::count(round.runs, at("runs")),
                Cell::count(round.new_runs, at("new_runs")),
                match round.shift {
                    Some(shift) => Cell::number(shift, at("shift")),
                    None => Cell::Empty,
                },
                match round.shift_noise {
                    Some(noise) => Cell::number(noise, at("shift_noise")),
                    None => Cell::Empty,
                },
                match round.surrogate_error {
                    Some(error) => Cell::number(error, at("surrogate_error")),
                    None => Cell::Empty,
                },
                Cell::number(round.log_likelihood_std, at("log_likelihood_std")),
                Cell::number(round.extrapolation_share, at("extrapolation_share")),
                match round.sampler_disagreement {
                    Some(d) => Cell::number(d, at("sampler_disagreement")),
                    None => Cell::Empty,
                },
                Cell::count(round.mixing_level as usize, at("mixing_level")),
            ];
            for p in 0..parameters.len() {
                row.push(Cell::number(round.mean[p], at(&format!("mean/{p}"))));
                row.push(Cell::number(round.std[p], at(&format!("std/{p}"))));
            }
            row
        })
        .collect();
    Table {
        name: "adaptive_rounds".into(),
        title: "Rounds of the adaptive design".into(),
        columns,
        rows,
    }
}

/// Model runs informing each data point: all of them, those the adaptive engine placed and
/// those that failed.
pub(crate) fn runs_per_point(report: &StudyReport) -> Table {
    let columns = vec![
        Column::plain(report.data.x_label.clone()),
        Column::plain("runs"),
        Column::plain("adaptive"),
        Column::plain("failed"),
    ];
    let rows = report
        .runs_per_point
        .iter()
        .enumerate()
        .map(|(i, point)| {
            let at = |field: &str| format!("/report/runs_per_point/{i}/{field}");
            vec![
                Cell::number(point.x, at("x")),
                Cell::count(point.runs, at("runs")),
                Cell::count(point.adaptive, at("adaptive")),
                Cell::count(point.failed, at("failed")),
            ]
        })
        .collect();
    Table {
        name: "runs_per_point".into(),
        title: "Model runs per data point".into(),
        columns,
        rows,
    }
}

/// The two-fidelity emulator per data point: ρ, whether the cheap model is used, the share of
/// the expensive runs it explains, the discrepancy's scale, and the runs of each fidelity.
pub(crate) fn two_fidelity(report: &StudyReport) -> Table {
    let columns = vec![
        Column::plain(report.data.x_label.clone()),
        Column::plain("ρ"),
        Column::plain("cheap model used"),
        Column::plain("explained share"),
        Column::plain("discrepancy std"),
        Column::plain("expensive runs"),
        Column::plain("cheap runs"),
    ];
    let rows = report
        .two_fidelity
        .iter()
        .enumerate()
        .map(|(i, point)| {
            let at = |field: &str| format!("/report/two_fidelity/{i}/{field}");
            vec![
                Cell::number(point.x, at("x")),
                Cell::number(point.rho, at("rho")),
                Cell::text(if point.uses_low_fidelity { "yes" } else { "no" }),
                Cell::number(point.explained_share, at("explained_share")),
                Cell::number(point.discrepancy_std, at("discrepancy_std")),
                Cell::count(point.expensive_runs, at("expensive_runs")),
                Cell::count(point.cheap_runs, at("cheap_runs")),
            ]
        })
        .collect();
    Table {
        name: "two_fidelity".into(),
        title: "Two fidelities per data point".into(),
        columns,
        rows,
    }
}

/// The reduced basis of two fidelities per principal component: the share of the runs it
/// explains, ρ_k, whether the cheap model is used, the share of the expensive runs'
/// coefficient it explains, the discrepancy's scale, and the runs of each fidelity.
pub(crate) fn two_fidelity_components(report: &StudyReport) -> Table {
    let columns = vec![
        Column::plain("component"),
        Column::plain("share of the runs' variance"),
        Column::plain("ρ"),
        Column::plain("cheap model used"),
        Column::plain("explained share"),
        Column::plain("discrepancy std"),
        Column::plain("expensive runs"),
        Column::plain("cheap runs"),
    ];
    let rows = report
        .two_fidelity_components
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let at = |field: &str| format!("/report/two_fidelity_components/{i}/{field}");
            vec![
                Cell::count(c.component, at("component")),
                Cell::number(c.explained_variance, at("explained_variance")),
                Cell::number(c.rho, at("rho")),
                Cell::text(if c.uses_low_fidelity { "yes" } else { "no" }),
                Cell::number(c.explained_share, at("explained_share")),
                Cell::number(c.discrepancy_std, at("discrepancy_std")),
                Cell::count(c.expensive_runs, at("expensive_runs")),
                Cell::count(c.cheap_runs, at("cheap_runs")),
            ]
        })
        .collect();
    Table {
        name: "two_fidelity_components".into(),
        title: "Two fidelities per principal component".into(),
        columns,
        rows,
    }
}

/// The posterior check per data point: the model and the surrogate at the MAP, the RMSE and
/// coverage over the checked runs, failures, and the model's diagnostic.
pub(crate) fn posterior_check(report: &StudyReport, check: &PosteriorCheckReport) -> Table {
    let diagnostic = check.diagnostic.clone();
    let mut names = vec![
        report.data.x_label.clone(),
        "model at MAP".to_string(),
        "model std".to_string(),
        "surrogate at MAP".to_string(),
        "surrogate std".to_string(),
        "RMSE".to_string(),
        "within 2σ".to_string(),
        "runs".to_string(),
        "failed".to_string(),
    ];
    if let Some(d) = &diagnostic {
        names.push(format!("median |{d}|"));
        names.push(format!("largest |{d}|"));
    }
    let columns = names.into_iter().map(Column::plain).collect();
    let mut rows = Vec::new();
    for (i, p) in check.points.iter().enumerate() {
        let at = |field: &str| format!("/report/posterior_check/points/{i}/{field}");
        let runs = p.model.len() + usize::from(p.map_model.is_some()) + p.failed;
        let mut row = vec![
            Cell::number(p.x, at("x")),
            p.map_model.map_or_else(
                || Cell::text("failed"),
                |(v, _)| Cell::number(v, at("map_model/0")),
            ),
            p.map_model.map_or_else(
                || Cell::text("–"),
                |(_, s)| Cell::number(s, at("map_model/1")),
            ),
            Cell::number(p.map_surrogate.0, at("map_surrogate/0")),
            Cell::number(p.map_surrogate.1, at("map_surrogate/1")),
            Cell::number(p.rmse, at("rmse")),
            Cell::number(p.within_two_std, at("within_two_std")),
            Cell::text(runs.to_string()),
            Cell::text(p.failed.to_string()),
        ];
        if diagnostic.is_some() {
            for (value, field) in [
                (p.diagnostic_median_abs, "diagnostic_median_abs"),
                (p.diagnostic_largest_abs, "diagnostic_largest_abs"),
            ] {
                row.push(value.map_or_else(|| Cell::text("–"), |v| Cell::number(v, at(field))));
            }
        }
        rows.push(row);
    }
    Table {
        name: "posterior_check".into(),
        title: "The model at the posterior, beside the surrogate".into(),
        columns,
        rows,
    }
}

/// Table 2 of a study with both posteriors: MAP, mean and std of each parameter from the
/// surrogate and from the model, with the relative differences and the model posterior's Monte
/// Carlo standard errors.
pub(crate) fn model_posterior_comparison(m: &ModelPosteriorReport) -> Table {
    let mut columns = vec![Column::plain("parameter")];
    for group in [&m.surrogate_source, &m.model_source] {
        for header in ["MAP", "mean", "std"] {
            columns.push(Column::grouped(group.clone(), header));
        }
    }
    for header in ["MAP", "mean", "std"] {
        columns.push(Column::grouped("relative difference", header));
    }
    for header in ["MCSE mean", "MCSE std"] {
        columns.push(Column::grouped(m.model_source.clone(), header));
    }
    let rows = m
        .parameters
        .iter()
        .enumerate()
        .map(|(p, c)| {
            let at = |field: &str| format!("/report/model_posterior/parameters/{p}/{field}");
            vec![
                Cell::text(c.name.clone()),
                Cell::number(c.surrogate.0, at("surrogate/0")),
                Cell::number(c.surrogate.1, at("surrogate/1")),
                Cell::number(c.surrogate.2, at("surrogate/2")),
                Cell::number(c.model.0, at("model/0")),
                Cell::number(c.model.1, at("model/1")),
                Cell::number(c.model.2, at("model/2")),
                Cell::optional(c.relative_difference.0, at("relative_difference/0")),
                Cell::optional(c.relative_difference.1, at("relative_difference/1")),
                Cell::optional(c.relative_difference.2, at("relative_difference/2")),
                Cell::number(c.mcse.0, at("mcse/0")),
                Cell::number(c.mcse.1, at("mcse/1")),
            ]
        })
        .collect();
    Table {
        name: "model_posterior".into(),
        title: "The surrogate's and the model's posterior".into(),
        columns,
        rows,
    }
}

/// The model posterior's stages: exponent, CV, k̂, the spread ratio, ESS, model evaluations and
/// the bridges' acceptance rates.
pub(crate) fn model_posterior_stages(m: &ModelPosteriorReport) -> Table {
    let columns = [
        "stage",
        "β",
        "CV",
        "k̂",
        "std ratio",
        "ESS",
        "model evaluations",
        "surrogate acceptance",
        "model acceptance",
    ]
    .into_iter()
    .map(Column::plain)
    .collect();
    let rows = m
        .stages
        .iter()
        .enumerate()
        .map(|(k, s)| {
            let at = |field: &str| format!("/report/model_posterior/stages/{k}/{field}");
            let mut row = vec![
                Cell::count(s.stage, at("stage")),
                Cell::number(s.beta, at("beta")),
                Cell::number(s.cv, at("cv")),
                Cell::number(s.pareto_k, at("pareto_k")),
                Cell::number(s.spread_ratio, at("spread_ratio")),
                Cell::number(s.effective_sample_size, at("effective_sample_size")),
                Cell::count(s.model_evaluations, at("model_evaluations")),
            ];
            match s.acceptance {
                Some((a, b)) => {
                    row.push(Cell::number(a, at("acceptance/0")));
                    row.push(Cell::number(b, at("acceptance/1")));
                }
                None => {
                    row.push(Cell::text("–"));
                    row.push(Cell::text("–"));
                }
            }
            row
        })
        .collect();
    Table {
        name: "model_posterior_stages".into(),
        title: "Stages of the model posterior".into(),
        columns,
        rows,
    }
}

/// The model run at both MAPs at every data point, with the absolute errors against the
/// measurement.
pub(crate) fn model_posterior_map_runs(report: &StudyReport, m: &ModelPosteriorReport) -> Table {
    let columns = vec![
        Column::plain(report.data.x_label.clone()),
        Column::plain("measurement"),
        Column::plain("std"),
        Column::grouped(format!("at the {} MAP", m.surrogate_source), "model"),
        Column::grouped(format!("at the {} MAP", m.surrogate_source), "|error|"),
        Column::grouped(format!("at the {} MAP", m.model_source), "model"),
        Column::grouped(format!("at the {} MAP", m.model_source), "|error|"),
    ];
    let rows = m
        .map_runs
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let at = |field: &str| format!("/report/model_posterior/map_runs/{i}/{field}");
            let mut row = vec![
                Cell::number(p.x, at("x")),
                Cell::number(p.datum.0, at("datum/0")),
                Cell::number(p.datum.1, at("datum/1")),
            ];
            for (value, error, field, error_field) in [
                (
                    p.at_surrogate_map,
                    p.absolute_error.0,
                    "at_surrogate_map",
                    "absolute_error/0",
                ),
                (
                    p.at_model_map,
                    p.absolute_error.1,
                    "at_model_map",
                    "absolute_error/1",
                ),
            ] {
                match value.zip(error) {
                    Some((v, e)) => {
                        row.push(Cell::number(v, at(field)));
                        row.push(Cell::number(e, at(error_field)));
                    }
                    None => {
                        row.push(Cell::text("failed"));
                        row.push(Cell::text("–"));
                    }
                }
            }
            row
        })
        .collect();
    Table {
        name: "model_posterior_map_runs".into(),
        title: "The model at both MAPs".into(),
        columns,
        rows,
    }
}
