//! Checks of a [`StudyReport`] before anything is drawn or written: consistent lengths, enough
//! samples, finite values. Every failure names the offending field.

use crate::error::{ReportError, Result};
use crate::input::{
    Convergence, DataSeries, FailureMapPanel, GpDiagnostic, PosteriorCheckReport, PosteriorResult,
    RunsAtPoint, StudyReport,
};

/// Checks that `report` can be rendered: returns the first problem found.
pub(crate) fn validate(report: &StudyReport) -> Result<()> {
    validate_data(&report.data)?;
    if !report.posteriors.is_empty() && report.parameters.is_empty() {
        return Err(ReportError::invalid(
            "parameters",
            "posteriors are given but no parameter names",
        ));
    }
    for (s, posterior) in report.posteriors.iter().enumerate() {
        validate_posterior(report, posterior, &format!("posteriors[{s}]"))?;
        if report.posteriors[..s]
            .iter()
            .any(|other| other.source == posterior.source)
        {
            return Err(ReportError::invalid(
                format!("posteriors[{s}].source"),
                format!("source `{}` appears twice", posterior.source),
            ));
        }
    }
    for (r, result) in report.sensitivity.iter().enumerate() {
        let field = format!("sensitivity[{r}]");
        finite(&format!("{field}.x"), result.x)?;
        if result.indices.is_empty() {
            return Err(ReportError::invalid(
                format!("{field}.indices"),
                "no indices",
            ));
        }
        for (i, index) in result.indices.iter().enumerate() {
            let f = format!("{field}.indices[{i}]");
            finite(&format!("{f}.first_order"), index.first_order)?;
            finite(&format!("{f}.first_order_low"), index.first_order_low)?;
            finite(&format!("{f}.first_order_high"), index.first_order_high)?;
            finite(&format!("{f}.total"), index.total)?;
            finite(&format!("{f}.total_low"), index.total_low)?;
            finite(&format!("{f}.total_high"), index.total_high)?;
        }
    }
    for (g, diagnostic) in report.gp_diagnostics.iter().enumerate() {
        validate_gp(diagnostic, &format!("gp_diagnostics[{g}]"))?;
    }
    let stats = &report.run_statistics;
    if stats.succeeded + stats.failed > stats.runs {
        return Err(ReportError::invalid(
            "run_statistics",
            format!(
                "{} succeeded + {} failed exceed {} runs",
                stats.succeeded, stats.failed, stats.runs
            ),
        ));
    }
    for (i, (stage, seconds)) in stats.stage_seconds.iter().enumerate() {
        if !seconds.is_finite() || *seconds < 0.0 {
            return Err(ReportError::invalid(
                format!("run_statistics.stage_seconds[{i}]"),
                format!(
                    "stage `{stage}` has wall time {seconds}, not a finite non-negative number"
                ),
            ));
        }
    }
    if let Some(convergence) = &report.convergence {
        validate_convergence(convergence)?;
    }
    for (k, panel) in report.failure_map.iter().enumerate() {
        validate_failure_panel(panel, &format!("failure_map[{k}]"))?;
    }
    validate_runs_per_point(&report.runs_per_point)?;
    if let Some(check) = &report.posterior_check {
        validate_posterior_check(check)?;
    }
    Ok(())
}

/// Checks the posterior check: paired model and surrogate values, finite numbers, non-negative
/// stds.
fn validate_posterior_check(check: &PosteriorCheckReport) -> Result<()> {
    for (i, p) in check.points.iter().enumerate() {
        let f = format!("posterior_check.points[{i}]");
        finite(&format!("{f}.x"), p.x)?;
        let n = p.model.len();
        same_length(
            &format!("{f}.surrogate"),
            p.surrogate.len(),
            &format!("{f}.model"),
            n,
        )?;
        same_length(
            &format!("{f}.surrogate_std"),
            p.surrogate_std.len(),
            &format!("{f}.model"),
            n,
        )?;
        same_length(
            &format!("{f}.model_std"),
            p.model_std.len(),
            &format!("{f}.model"),
            n,
        )?;
        for (k, v) in p.model.iter().chain(&p.surrogate).enumerate() {
            finite(&format!("{f}.values[{k}]"), *v)?;
        }
        for (k, v) in p.surrogate_std.iter().chain(&p.model_std).enumerate() {
            non_negative(&format!("{f}.stds[{k}]"), *v)?;
        }
        finite(&format!("{f}.map_surrogate"), p.map_surrogate.0)?;
        non_negative(&format!("{f}.map_surrogate"), p.map_surrogate.1)?;
        if let Some((value, std)) = p.map_model {
            finite(&format!("{f}.map_model"), value)?;
            non_negative(&format!("{f}.map_model"), std)?;
        }
    }
    Ok(())
}

/// Checks the adaptive engine's rounds: one mean and std per parameter, finite values,
/// non-negative stds and shifts, shares in [0, 1].
fn validate_convergence(convergence: &Convergence) -> Result<()> {
    let d = convergence.parameters.len();
    for (i, round) in convergence.rounds.iter().enumerate() {
        let f = format!("convergence.rounds[{i}]");
        let parameters = "convergence.parameters";
        same_length(&format!("{f}.mean"), round.mean.len(), parameters, d)?;
        same_length(&format!("{f}.std"), round.std.len(), parameters, d)?;
        for (p, &mean) in round.mean.iter().enumerate() {
            finite(&format!("{f}.mean[{p}]"), mean)?;
        }
        for (p, &std) in round.std.iter().enumerate() {
            non_negative(&format!("{f}.std[{p}]"), std)?;
        }
        if let Some(shift) = round.shift {
            non_negative(&format!("{f}.shift"), shift)?;
        }
        if let Some(noise) = round.shift_noise {
            non_negative(&format!("{f}.shift_noise"), noise)?;
        }
        if let Some(error) = round.surrogate_error {
            non_negative(&format!("{f}.surrogate_error"), error)?;
        }
        non_negative(&format!("{f}.log_likelihood_std"), round.log_likelihood_std)?;
        probability(
            &format!("{f}.extrapolation_share"),
            round.extrapolation_share,
        )?;
    }
    Ok(())
}

/// Checks one failure-map panel: one flag of each kind per run, finite coordinates, a
/// non-empty plotting range, and a probability grid that is empty or complete with values in
/// [0, 1].
fn validate_failure_panel(panel: &FailureMapPanel, field: &str) -> Result<()> {
    let points = format!("{field}.points");
    let n = panel.points.len();
    same_length(&format!("{field}.failed"), panel.failed.len(), &points, n)?;
    same_length(
        &format!("{field}.adaptive"),
        panel.adaptive.len(),
        &points,
        n,
    )?;
    for (i, &(x, y)) in panel.points.iter().enumerate() {
        finite(&format!("{points}[{i}].0"), x)?;
        finite(&format!("{points}[{i}].1"), y)?;
    }
    let (x_low, x_high, y_low, y_high) = panel.bounds;
    for (name, low, high) in [("x", x_low, x_high), ("y", y_low, y_high)] {
        let f = format!("{field}.bounds");
        finite(&f, low)?;
        finite(&f, high)?;
        if low >= high {
            return Err(ReportError::invalid(
                f,
                format!("the {name} range [{low}, {high}] is empty"),
            ));
        }
    }
    if !panel.failure_probability.is_empty() {
        let (columns, rows) = panel.grid_size;
        let cells = columns.saturating_mul(rows);
        let probabilities = format!("{field}.failure_probability");
        if panel.failure_probability.len() != cells {
            return Err(ReportError::invalid(
                probabilities,
                format!(
                    "has {} entries but grid_size {columns} × {rows} needs {cells}",
                    panel.failure_probability.len()
                ),
            ));
        }
        for (i, &p) in panel.failure_probability.iter().enumerate() {
            probability(&format!("{probabilities}[{i}]"), p)?;
        }
    }
    Ok(())
}

/// Checks the runs per data point: finite control values, adaptive and failed runs among the
/// runs.
fn validate_runs_per_point(rows: &[RunsAtPoint]) -> Result<()> {
    for (i, row) in rows.iter().enumerate() {
        let f = format!("runs_per_point[{i}]");
        finite(&format!("{f}.x"), row.x)?;
        for (name, count) in [("adaptive", row.adaptive), ("failed", row.failed)] {
            if count > row.runs {
                return Err(ReportError::invalid(
                    format!("{f}.{name}"),
                    format!("{count} exceed the point's {} runs", row.runs),
                ));
            }
        }
    }
    Ok(())
}

/// Checks the measurements: equal lengths, finite values (any sign of x: the figures choose a
/// logarithmic or linear x axis from the data), non-negative errors.
fn validate_data(data: &DataSeries) -> Result<()> {
    let n = data.x.len();
    if n == 0 {
        return Err(ReportError::invalid("data.x", "no data points"));
    }
    same_length("data.y", data.y.len(), "data.x", n)?;
    same_length("data.y_err", data.y_err.len(), "data.x", n)?;
    for i in 0..n {
        finite(&format!("data.x[{i}]"), data.x[i])?;
        finite(&format!("data.y[{i}]"), data.y[i])?;
        finite(&format!("data.y_err[{i}]"), data.y_err[i])?;
        if data.y_err[i] < 0.0 {
            return Err(ReportError::invalid(
                format!("data.y_err[{i}]"),
                format!("{} is negative", data.y_err[i]),
            ));
        }
    }
    Ok(())
}

/// Checks one posterior against the parameters and the data.
fn validate_posterior(
    report: &StudyReport,
    posterior: &PosteriorResult,
    field: &str,
) -> Result<()> {
    let d = report.parameters.len();
    same_length(
        &format!("{field}.summary"),
        posterior.summary.len(),
        "parameters",
        d,
    )?;
    for (p, summary) in posterior.summary.iter().enumerate() {
        let f = format!("{field}.summary[{p}]");
        if summary.name != report.parameters[p] {
            return Err(ReportError::invalid(
                format!("{f}.name"),
                format!(
                    "`{}` does not match parameter {p} `{}`",
                    summary.name, report.parameters[p]
                ),
            ));
        }
        for (name, value) in [
            ("map", summary.map),
            ("mean", summary.mean),
            ("std", summary.std),
            ("q05", summary.q05),
            ("q50", summary.q50),
            ("q95", summary.q95),
        ] {
            finite(&format!("{f}.{name}"), value)?;
        }
    }
    finite(&format!("{field}.log_evidence"), posterior.log_evidence)?;
    if posterior.samples.len() < 2 {
        return Err(ReportError::invalid(
            format!("{field}.samples"),
            format!(
                "{} samples; the density plots need at least two",
                posterior.samples.len()
            ),
        ));
    }
    for (i, row) in posterior.samples.iter().enumerate() {
        let f = format!("{field}.samples[{i}]");
        same_length(&f, row.len(), "parameters", d)?;
        for (j, value) in row.iter().enumerate() {
            finite(&format!("{f}[{j}]"), *value)?;
        }
    }
    for (i, stage) in posterior.stages.iter().enumerate() {
        let f = format!("{field}.stages[{i}]");
        finite(&format!("{f}.annealing_exponent"), stage.annealing_exponent)?;
        finite(&format!("{f}.cv"), stage.cv)?;
        finite(&format!("{f}.acceptance"), stage.acceptance)?;
        finite(&format!("{f}.log_evidence"), stage.log_evidence)?;
        finite(&format!("{f}.seconds"), stage.seconds)?;
    }
    let data = &report.data;
    same_length(
        &format!("{field}.propagated"),
        posterior.propagated.len(),
        "data.x",
        data.x.len(),
    )?;
    for (i, output) in posterior.propagated.iter().enumerate() {
        let f = format!("{field}.propagated[{i}]");
        let tolerance = 1e-9 * data.x[i].abs().max(1.0);
        let same_x = (output.x - data.x[i]).abs() <= tolerance;
        if !same_x {
            return Err(ReportError::invalid(
                format!("{f}.x"),
                format!("{} does not match data.x[{i}] = {}", output.x, data.x[i]),
            ));
        }
        finite(&format!("{f}.map_prediction"), output.map_prediction)?;
        if output.samples.is_empty() {
            return Err(ReportError::invalid(
                format!("{f}.samples"),
                "no propagated samples",
            ));
        }
        for (j, value) in output.samples.iter().enumerate() {
            finite(&format!("{f}.samples[{j}]"), *value)?;
        }
    }
    Ok(())
}

/// Checks one GP diagnostic: equal lengths, finite values, non-negative stds.
fn validate_gp(diagnostic: &GpDiagnostic, field: &str) -> Result<()> {
    finite(&format!("{field}.x"), diagnostic.x)?;
    finite(&format!("{field}.q2"), diagnostic.q2)?;
    finite(&format!("{field}.loo_q2"), diagnostic.loo_q2)?;
    let n = diagnostic.simulated.len();
    if n == 0 {
        return Err(ReportError::invalid(
            format!("{field}.simulated"),
            "no test points",
        ));
    }
    let simulated = format!("{field}.simulated");
    same_length(
        &format!("{field}.predicted"),
        diagnostic.predicted.len(),
        &simulated,
        n,
    )?;
    same_length(
        &format!("{field}.predicted_std"),
        diagnostic.predicted_std.len(),
        &simulated,
        n,
    )?;
    for i in 0..n {
        finite(&format!("{field}.simulated[{i}]"), diagnostic.simulated[i])?;
        finite(&format!("{field}.predicted[{i}]"), diagnostic.predicted[i])?;
        let std = diagnostic.predicted_std[i];
        if !std.is_finite() || std < 0.0 {
            return Err(ReportError::invalid(
                format!("{field}.predicted_std[{i}]"),
                format!("{std} is not a finite non-negative number"),
            ));
        }
    }
    for (i, (name, value)) in diagnostic.hyperparameters.iter().enumerate() {
        finite(&format!("{field}.hyperparameters[{i}] ({name})"), *value)?;
    }
    Ok(())
}

/// An error unless `value` is finite.
fn finite(field: &str, value: f64) -> Result<()> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(ReportError::invalid(
            field,
            format!("{value} is not finite"),
        ))
    }
}

/// An error unless `value` is finite and not negative.
fn non_negative(field: &str, value: f64) -> Result<()> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(ReportError::invalid(
            field,
            format!("{value} is not a finite non-negative number"),
        ))
    }
}

/// An error unless `value` lies in [0, 1].
fn probability(field: &str, value: f64) -> Result<()> {
    if (0.0..=1.0).contains(&value) {
        Ok(())
    } else {
        Err(ReportError::invalid(
            field,
            format!("{value} is not in [0, 1]"),
        ))
    }
}

/// An error unless `len` equals `expected`, the length of `reference`.
fn same_length(field: &str, len: usize, reference: &str, expected: usize) -> Result<()> {
    if len == expected {
        Ok(())
    } else {
        Err(ReportError::invalid(
            field,
            format!("has {len} entries but {reference} has {expected}"),
        ))
    }
}
