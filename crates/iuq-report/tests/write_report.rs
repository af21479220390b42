//! End-to-end tests of `write_report` on a small synthetic study: the files it writes, their
//! formats, the agreement of the page's numbers with `report.json`, and the rejection of bad
//! input without touching an existing page.

mod synthetic;

use std::path::{Path, PathBuf};

use iuq_report::{ReportDocument, ReportError, format_number, write_report};
use serde_json::Value;

/// Three stresses, 200 samples, both sources.
fn small_report() -> iuq_report::StudyReport {
    synthetic::synthetic_report(&[0.64, 1.99, 6.19], 2, 200, 42)
}

/// A fresh, empty directory for one test, removed when dropped.
struct Scratch(PathBuf);

impl std::ops::Deref for Scratch {
    type Target = Path;

    fn deref(&self) -> &Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn fresh_dir(name: &str) -> Scratch {
    let dir = std::env::temp_dir().join(format!("iuq-report-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    Scratch(dir)
}

const FIGURES: [&str; 12] = [
    "data_fit",
    "sensitivity",
    "corner",
    "violins",
    "map_error",
    "gp_diagnostics",
    "sampler_stages",
    "posterior_check",
    "model_posterior_map_runs",
    "model_posterior_weights",
    "cell_shapes",
    "elongation_trace",
];

const TABLES: [&str; 17] = [
    "propagated",
    "posterior_summary",
    "posterior_evidence",
    "posterior_samples_gp_surrogate",
    "posterior_samples_cell_model",
    "sensitivity",
    "map_error",
    "gp_quality",
    "gp_hyperparameters",
    "sampler_stages",
    "run_counts",
    "failures_by_reason",
    "stage_times",
    "posterior_check",
    "model_posterior",
    "model_posterior_stages",
    "model_posterior_map_runs",
];

fn read_document(dir: &Path) -> (ReportDocument, Value) {
    let text = std::fs::read_to_string(dir.join("report.json")).unwrap();
    (
        serde_json::from_str(&text).unwrap(),
        serde_json::from_str(&text).unwrap(),
    )
}

/// No temporary file is left anywhere under `dir`.
fn assert_no_temporaries(dir: &Path) {
    for sub in [dir.to_path_buf(), dir.join("figures"), dir.join("tables")] {
        let Ok(entries) = std::fs::read_dir(&sub) else {
            continue;
        };
        for entry in entries {
            let name = entry.unwrap().file_name().to_string_lossy().into_owned();
            assert!(
                !name.starts_with('.'),
                "temporary file left: {}",
                sub.join(name).display()
            );
        }
    }
}

#[test]
fn writes_every_figure_table_and_page() {
    let dir = fresh_dir("files");
    let report = small_report();
    let files = write_report(&report, &dir).unwrap();
    for name in FIGURES {
        for extension in ["svg", "png"] {
            let path = dir.join("figures").join(format!("{name}.{extension}"));
            assert!(path.is_file(), "missing {}", path.display());
            assert!(files.figures.contains(&path));
        }
    }
    for name in TABLES {
        for extension in ["csv", "json"] {
            let path = dir.join("tables").join(format!("{name}.{extension}"));
            assert!(path.is_file(), "missing {}", path.display());
            assert!(files.tables.contains(&path));
        }
    }
    assert_eq!(files.figures.len(), 2 * FIGURES.len());
    assert_eq!(files.tables.len(), 2 * TABLES.len());
    assert!(files.html.is_file() && files.json.is_file());
    let (document, _) = read_document(&dir);
    assert!(
        document.report == report,
        "report.json does not round-trip the input"
    );
    assert_eq!(document.figures.len(), FIGURES.len());
    assert_no_temporaries(&dir);
}

/// Every figure of the report in `dir` is an SVG and a PNG of the declared size, not empty.
fn assert_figures_well_formed(dir: &Path) {
    let (document, _) = read_document(dir);
    for figure in &document.figures {
        let svg = std::fs::read_to_string(dir.join(&figure.svg)).unwrap();
        assert!(
            svg.starts_with("<svg"),
            "{} does not start with <svg",
            figure.svg
        );
        assert!(svg.trim_end().ends_with("</svg>"));
        assert!(svg.len() > 5_000, "{} is nearly empty", figure.svg);
        assert!(svg.contains("<text"), "{} has no text", figure.svg);
        assert!(svg.contains(&format!("width=\"{}\"", figure.width)));
        // No tick reads a floating-point residue (3.469e-18 where an axis crosses zero).
        for residue in ["e-15", "e-16", "e-17", "e-18", "e-19"] {
            assert!(
                !svg.contains(residue),
                "{} has a tick {residue}",
                figure.svg
            );
        }

        let png = std::fs::read(dir.join(&figure.png)).unwrap();
        assert_eq!(
            &png[..8],
            b"\x89PNG\r\n\x1a\n",
            "{} is not a PNG",
            figure.png
        );
        assert_eq!(&png[12..16], b"IHDR");
        let width = u32::from_be_bytes([png[16], png[17], png[18], png[19]]);
        let height = u32::from_be_bytes([png[20], png[21], png[22], png[23]]);
        assert_eq!(
            (width, height),
            (figure.width, figure.height),
            "{}",
            figure.png
        );
        assert!(png.len() > 10_000, "{} is nearly empty", figure.png);
    }
}

#[test]
fn figures_are_svg_and_png_of_the_declared_size() {
    let dir = fresh_dir("formats");
    write_report(&small_report(), &dir).unwrap();
    assert_figures_well_formed(&dir);
}

/// Every `<td … data-value="V" data-pointer="P">TEXT</td>` of the page.
fn numeric_cells(html: &str) -> Vec<(f64, String, String)> {
    let mut cells = Vec::new();
    let mut rest = html;
    while let Some(start) = rest.find("data-value=\"") {
        rest = &rest[start + "data-value=\"".len()..];
        let end = rest.find('"').unwrap();
        let value: f64 = rest[..end].parse().unwrap();
        rest = &rest[end..];
        let pointer_start = rest.find("data-pointer=\"").unwrap() + "data-pointer=\"".len();
        rest = &rest[pointer_start..];
        let pointer_end = rest.find('"').unwrap();
        let pointer = rest[..pointer_end].to_string();
        let text_start = rest.find('>').unwrap() + 1;
        let text_end = rest.find("</td>").unwrap();
        cells.push((value, pointer, rest[text_start..text_end].to_string()));
        rest = &rest[text_end..];
    }
    cells
}

/// Every number in the tables of the page in `dir` equals the number its pointer names in
/// `report.json` and is displayed by `format_number`.
fn assert_numbers_match_report_json(dir: &Path) {
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    let (_, json) = read_document(dir);
    let cells = numeric_cells(&html);
    assert!(cells.len() > 100, "only {} numeric cells", cells.len());
    for (value, pointer, text) in &cells {
        let json_value = json
            .pointer(pointer)
            .and_then(Value::as_f64)
            .unwrap_or_else(|| panic!("{pointer} is not a number in report.json"));
        assert_eq!(*value, json_value, "at {pointer}");
        assert_eq!(text, &format_number(*value), "display of {pointer}");
    }
    // Every numeric cell of the page's tables is among them: no number escapes the check.
    let plain_numeric_cells = html.matches("<td class=\"num\">").count();
    let empty_cells = html.matches("<td class=\"num\">–</td>").count();
    assert_eq!(plain_numeric_cells, empty_cells);
}

#[test]
fn html_numbers_equal_report_json_numbers() {
    let dir = fresh_dir("numbers");
    write_report(&small_report(), &dir).unwrap();
    assert_numbers_match_report_json(&dir);
}

#[test]
fn the_page_is_self_contained() {
    let dir = fresh_dir("self-contained");
    write_report(&small_report(), &dir).unwrap();
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    for forbidden in [
        "<script",
        "<link",
        " src=",
        "url(",
        "@import",
        "href=\"http",
    ] {
        assert!(!html.contains(forbidden), "page contains {forbidden}");
    }
    // Sections in the order of the report.
    let order = [
        "data-fit",
        "posterior",
        "sensitivity",
        "corner",
        "propagation",
        "map-error",
        "surrogate",
        "sampler",
        "posterior-check",
        "runs",
    ];
    let positions: Vec<usize> = order
        .iter()
        .map(|id| {
            html.find(&format!("<section id=\"{id}\">"))
                .unwrap_or_else(|| panic!("no section {id}"))
        })
        .collect();
    assert!(positions.windows(2).all(|w| w[0] < w[1]));
    // The noisy model's correction is stated with the test that called for it.
    let text = html.replace("&#39;", "'");
    assert!(text.contains(
        "the first batch's importance-weighted mean lies 0.42 posterior stds from the GP surrogate's and its spread's divergence is 0.061 (a permutation test of the weights over the members: p = 0.002): beyond what the weights' noise explains."
    ));
    assert!(text.contains("a second batch of 100 drawn from the corrected GP surrogate's posterior; both batches are weighed as one sample of the two posteriors' even mixture, so that 200 members carry the estimate"));
    assert!(text.contains("100 members of the GP surrogate posterior run through the cell model"));
    assert!(text.contains("Histogram of the log-weights of both batches"));
    // The status opens a sentence.
    assert!(
        text.contains(" Certified: every stage's k̂ is below its threshold."),
        "{text}"
    );
    assert_eq!(html.matches("<svg").count(), FIGURES.len());
    for name in FIGURES {
        assert!(html.contains(&format!("href=\"figures/{name}.png\"")));
    }
}

#[test]
fn a_noisy_models_refused_correction_is_said_without_a_contradiction() {
    let mut report = small_report();
    {
        let m = report.model_posterior.as_mut().unwrap();
        m.corrections = 0;
        m.both_batches = false;
        m.proposal_mismatch.as_mut().unwrap().corrected = false;
        m.correction_not_made = Some(
            "the moment-matched correction's posterior keeps 2 % of its population inside the range of viscosityRatio over the batch it was fitted on (at least 50 % needed)".into(),
        );
    }
    let dir = fresh_dir("noisy-refused");
    write_report(&report, &dir).unwrap();
    let text = std::fs::read_to_string(dir.join("report.html"))
        .unwrap()
        .replace("&#39;", "'");
    assert!(text.contains("(a permutation test of the weights over the members: p = 0.002). The cell model's runs asked for a correction of the GP surrogate, but the moment-matched correction's posterior keeps 2 % of its population inside the range of viscosityRatio over the batch it was fitted on (at least 50 % needed): the one step stands."), "{text}");
    assert!(!text.contains("no correction."), "{text}");
    assert!(
        text.contains("With a noisy likelihood the MCSE is computed from the weights as drawn"),
        "{text}"
    );
}

#[test]
fn a_noisy_models_defensive_batch_is_said_with_the_refused_correction() {
    let mut report = small_report();
    {
        let m = report.model_posterior.as_mut().unwrap();
        m.corrections = 1;
        m.both_batches = true;
        m.proposal_mismatch.as_mut().unwrap().corrected = true;
        m.correction_tempering = Some(0.25);
        m.corrections_refused = vec![
            "the moment-matched correction: its posterior keeps 2 % of its population inside the range of viscosityRatio over the batch it was fitted on (at least 50 % needed)".into(),
        ];
    }
    let samples = report.model_posterior.as_ref().unwrap().samples;
    let dir = fresh_dir("noisy-defensive");
    write_report(&report, &dir).unwrap();
    let text = std::fs::read_to_string(dir.join("report.html"))
        .unwrap()
        .replace("&#39;", "'");
    assert!(text.contains(&format!("The correction towards the weighted moments was refused (the moment-matched correction: its posterior keeps 2 % of its population inside the range of viscosityRatio over the batch it was fitted on (at least 50 % needed)). So a defensive second batch of {} was drawn from the GP surrogate's posterior tempered at β = 0.250 (π·L^β: the GP surrogate's own shape, about 2.0 times as wide, with no fit to extrapolate); both batches are weighed as one sample of the even mixture of the GP surrogate's posterior and that proposal, so that {samples} members carry the estimate.", samples / 2)), "{text}");
    assert!(
        !text.contains("corrected towards the weighted moments (stds"),
        "{text}"
    );
    assert!(!text.contains("the one step stands"), "{text}");

    // The defensive normal, tried before the tempered posterior.
    {
        let m = report.model_posterior.as_mut().unwrap();
        m.correction_tempering = None;
        m.correction_defensive_normal = true;
    }
    let dir = fresh_dir("noisy-defensive-normal");
    write_report(&report, &dir).unwrap();
    let text = std::fs::read_to_string(dir.join("report.html"))
        .unwrap()
        .replace("&#39;", "'");
    assert!(text.contains(&format!("So a defensive second batch of {} was drawn from a normal at the first batch's importance-weighted mean with twice its weighted second moment (at least √2 times as wide as the weights' estimate of the target, and not multiplied by the surrogate's posterior, whose tail the refused correction raised); both batches are weighed", samples / 2)), "{text}");
    assert!(!text.contains("tempered at"), "{text}");
}

#[test]
fn a_reproducible_models_correction_says_which_fit_and_what_was_refused() {
    let mut report = small_report();
    {
        let m = report.model_posterior.as_mut().unwrap();
        m.pseudo_marginal = false;
        m.proposal_mismatch = None;
        m.corrections = 1;
        m.correction_moment_matched = true;
        m.corrections_refused =
            vec!["the least-squares fit of r: its posterior keeps 0 % of its population inside the range of kLink over the batch it was fitted on (at least 50 % needed)".into()];
    }
    let dir = fresh_dir("smooth-correction");
    write_report(&report, &dir).unwrap();
    let text = std::fs::read_to_string(dir.join("report.html"))
        .unwrap()
        .replace("&#39;", "'");
    assert!(text.contains("so the GP surrogate was corrected towards the moments of the batch's importance weights (a Gaussian log-ratio, stds widened 1.2 times) (first tried and refused: the least-squares fit of r: its posterior keeps 0 % of its population inside the range of kLink"), "{text}");
    assert!(!text.contains("With a noisy likelihood"), "{text}");

    let m = report.model_posterior.as_mut().unwrap();
    m.corrections = 0;
    m.corrections_refused.clear();
    m.correction_not_made = Some(
        "both corrections' posteriors lie outside the batch; the stages go on from the first batch"
            .into(),
    );
    let dir = fresh_dir("smooth-no-correction");
    write_report(&report, &dir).unwrap();
    let text = std::fs::read_to_string(dir.join("report.html"))
        .unwrap()
        .replace("&#39;", "'");
    assert!(text.contains("The first batch's weights did not hold in one stage, and no correction of the GP surrogate was made: both corrections' posteriors lie outside the batch; the stages go on from the first batch."));
    // Without a bridge the weights' chart says nothing of ancestors; after one, how many the
    // members descend from.
    assert!(!text.contains("ancestors)"), "{text}");
    report.model_posterior.as_mut().unwrap().ancestors = 143;
    let dir = fresh_dir("smooth-bridged");
    write_report(&report, &dir).unwrap();
    let text = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(text.contains("; 143 ancestors)"), "{text}");
}

#[test]
fn the_model_posteriors_tables_hold_the_map_runs_errors_and_no_ratio_to_zero() {
    let mut report = small_report();
    {
        let m = report.model_posterior.as_mut().unwrap();
        m.parameters[0].surrogate.1 = 0.0;
        m.parameters[0].relative_difference.1 = None;
        m.map_runs[1].at_model_map = None;
        m.map_runs[1].absolute_error.1 = None;
    }
    let dir = fresh_dir("model-posterior-tables");
    write_report(&report, &dir).unwrap();
    let table = |name: &str| -> Value {
        serde_json::from_str(
            &std::fs::read_to_string(dir.join(format!("tables/{name}.json"))).unwrap(),
        )
        .unwrap()
    };
    let m = report.model_posterior.as_ref().unwrap();
    let compared = table("model_posterior");
    // The relative difference to a surrogate mean of 0 is undefined: "–", not inf or NaN.
    let key = "relative difference mean";
    assert_eq!(compared["rows"][0][key], "–", "{compared}");
    let expected = m.parameters[1].relative_difference.1;
    assert_eq!(compared["rows"][1][key].as_f64(), expected);
    let runs = table("model_posterior_map_runs");
    let error_key = |source: &str| format!("at the {source} MAP |error|");
    for (j, p) in m.map_runs.iter().enumerate() {
        let row = &runs["rows"][j];
        // Each absolute error is |run − datum|, a number in the table (so also in report.json).
        let at_s = p.at_surrogate_map.unwrap();
        assert_eq!(
            row[error_key(&m.surrogate_source)].as_f64(),
            Some((at_s - p.datum.0).abs()),
            "{row}"
        );
        let at_model = row[error_key(&m.model_source)].clone();
        match p.at_model_map {
            Some(at_m) => assert_eq!(at_model.as_f64(), Some((at_m - p.datum.0).abs())),
            None => assert_eq!(at_model, "–", "{row}"),
        }
    }
    assert_numbers_match_report_json(&dir);
}

#[test]
fn runs_not_made_are_counted_apart_from_the_failure_fraction() {
    let mut report = small_report();
    let dir = fresh_dir("all-made");
    write_report(&report, &dir).unwrap();
    let counts = std::fs::read_to_string(dir.join("tables/run_counts.csv")).unwrap();
    assert!(
        counts.contains("failed (fraction of those made),0.05"),
        "{counts}"
    );
    assert!(!counts.contains("not run"), "{counts}");
    // 30 runs left pending (say, a batch abandoned when the method changed): counted apart, and
    // the failure fraction stays that of the runs made (6 of 114 + 6).
    report.run_statistics.runs = 150;
    let dir = fresh_dir("some-not-made");
    write_report(&report, &dir).unwrap();
    let counts = std::fs::read_to_string(dir.join("tables/run_counts.csv")).unwrap();
    assert!(
        counts.contains("not run (pending or cancelled),30"),
        "{counts}"
    );
    assert!(
        counts.contains("failed (fraction of those made),0.05"),
        "{counts}"
    );
}

#[test]
fn empty_posteriors_and_sensitivity_omit_their_sections() {
    let dir = fresh_dir("omitted");
    let mut report = small_report();
    report.posteriors.clear();
    report.sensitivity.clear();
    write_report(&report, &dir).unwrap();
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    for id in [
        "posterior",
        "sensitivity",
        "corner",
        "propagation",
        "map-error",
        "sampler",
    ] {
        assert!(
            !html.contains(&format!("<section id=\"{id}\">")),
            "section {id} present"
        );
    }
    assert!(html.contains("<section id=\"data-fit\">"));
    assert!(html.contains("<section id=\"surrogate\">"));
    assert!(dir.join("figures/data_fit.png").is_file());
    assert!(!dir.join("figures/corner.svg").exists());
}

#[test]
fn a_single_source_renders() {
    let dir = fresh_dir("single");
    let report = synthetic::synthetic_report(&[0.64, 1.99, 6.19], 1, 200, 3);
    write_report(&report, &dir).unwrap();
    assert!(dir.join("figures/violins.png").is_file());
}

#[test]
fn a_posterior_without_sampler_stages_has_no_line_and_no_legend_entry() {
    // The model's posterior reweighted from the surrogate's has no BASIS stages.
    let mut report = small_report();
    report.posteriors[1].stages.clear();
    let dir = fresh_dir("stageless");
    write_report(&report, &dir).unwrap();
    let svg = std::fs::read_to_string(dir.join("figures/sampler_stages.svg")).unwrap();
    assert!(svg.contains(">\nGP surrogate\n</text>"), "{svg}");
    assert!(
        !svg.contains(">\ncell model\n</text>"),
        "a legend entry without a line"
    );
    let corner = std::fs::read_to_string(dir.join("figures/corner.svg")).unwrap();
    assert!(
        corner.contains(">\ncell model\n</text>"),
        "the corner plot still shows both"
    );
}

/// A report at the control values `xs` (a general model's abscissae, e.g. times) renders: every
/// figure well formed, the data-fit and violin figures written as SVG and PNG, their x tick
/// labels on the linear axis the values call for.
fn assert_renders_at(name: &str, xs: &[f64], expected_labels: &[&str]) {
    let dir = fresh_dir(name);
    let mut report = synthetic::synthetic_report(xs, 2, 200, 11);
    report.data.x_label = "time t (s)".to_string();
    let files = write_report(&report, &dir).unwrap();
    assert_figures_well_formed(&dir);
    for figure in ["data_fit", "violins"] {
        for extension in ["svg", "png"] {
            let path = dir.join("figures").join(format!("{figure}.{extension}"));
            assert!(path.is_file(), "missing {}", path.display());
            assert!(files.figures.contains(&path));
        }
        let svg = std::fs::read_to_string(dir.join(format!("figures/{figure}.svg"))).unwrap();
        for label in expected_labels {
            assert!(
                svg.contains(&format!(">\n{label}\n</text>")),
                "{figure}.svg has no tick label {label}"
            );
        }
    }
}

#[test]
fn control_values_from_zero_render_on_a_linear_axis() {
    let times: Vec<f64> = [0.0, 0.5]
        .into_iter()
        .chain((1..=10).map(f64::from))
        .collect();
    assert_renders_at("times", &times, &["0", "2", "4", "6", "8", "10"]);
}

#[test]
fn negative_control_values_render_on_a_linear_axis() {
    // Within the toy model's domain (it has poles at −1 and near −2).
    let xs = [-0.8, -0.6, -0.4, -0.2, 0.0, 0.3, 0.4];
    assert_renders_at("negative", &xs, &["-0.8", "-0.4", "0", "0.2", "0.4"]);
}

/// Writing `bad` into a directory holding a good report fails with an invalid-input error
/// naming `field`, and leaves the good page untouched.
fn assert_rejected(name: &str, bad: iuq_report::StudyReport, field: &str) {
    let dir = fresh_dir(name);
    write_report(&small_report(), &dir).unwrap();
    let before = std::fs::read(dir.join("report.html")).unwrap();
    match write_report(&bad, &dir) {
        Err(ReportError::InvalidInput { field: f, reason }) => {
            assert!(
                f.contains(field),
                "error names `{f}` ({reason}), expected `{field}`"
            );
        }
        other => panic!("expected an invalid-input error, got {other:?}"),
    }
    assert_eq!(std::fs::read(dir.join("report.html")).unwrap(), before);
    assert_no_temporaries(&dir);

    // Into an empty directory: no page at all.
    let empty = fresh_dir(&format!("{name}-empty"));
    assert!(write_report(&bad, &empty).is_err());
    assert!(!empty.join("report.html").exists());
    assert!(!empty.join("report.json").exists());
}

#[test]
fn mismatched_lengths_are_rejected() {
    let mut bad = small_report();
    bad.data.y.pop();
    assert_rejected("short-y", bad, "data.y");

    let mut bad = small_report();
    bad.posteriors[1].propagated.pop();
    assert_rejected("short-propagated", bad, "posteriors[1].propagated");

    let mut bad = small_report();
    bad.posteriors[0].samples[17].pop();
    assert_rejected("short-sample", bad, "posteriors[0].samples[17]");

    let mut bad = small_report();
    bad.gp_diagnostics[2].predicted_std.push(0.1);
    assert_rejected("long-std", bad, "gp_diagnostics[2].predicted_std");
}

#[test]
fn non_finite_values_and_empty_samples_are_rejected() {
    let mut bad = small_report();
    bad.posteriors[0].samples[5][1] = f64::NAN;
    assert_rejected("nan-sample", bad, "posteriors[0].samples[5][1]");

    let mut bad = small_report();
    bad.posteriors[1].samples.clear();
    assert_rejected("no-samples", bad, "posteriors[1].samples");

    let mut bad = small_report();
    bad.data.x[0] = f64::NAN;
    assert_rejected("nan-control", bad, "data.x[0]");

    let mut bad = small_report();
    bad.posteriors[0].propagated[1].samples[3] = f64::INFINITY;
    assert_rejected(
        "infinite-output",
        bad,
        "posteriors[0].propagated[1].samples[3]",
    );
}

/// The small report with an adaptive design's results: 3 rounds, 2 failure-map panels (the
/// second without a probability grid) and the runs per data point.
fn adaptive_report() -> iuq_report::StudyReport {
    let mut report = small_report();
    synthetic::add_adaptive_results(&mut report, 3, 2, 5);
    report
}

/// Position of `<section id="ID">` in `html`.
fn section_position(html: &str, id: &str) -> usize {
    html.find(&format!("<section id=\"{id}\">"))
        .unwrap_or_else(|| panic!("no section {id}"))
}

#[test]
fn adaptive_results_get_their_sections_figures_and_tables() {
    let dir = fresh_dir("adaptive");
    let report = adaptive_report();
    let files = write_report(&report, &dir).unwrap();
    let html = std::fs::read_to_string(&files.html).unwrap();
    assert!(html.contains("Convergence of the adaptive design"));
    assert!(html.contains("Where the model fails"));
    for name in ["convergence", "failure_map"] {
        for extension in ["svg", "png"] {
            let path = dir.join("figures").join(format!("{name}.{extension}"));
            assert!(path.is_file(), "missing {}", path.display());
            assert!(files.figures.contains(&path));
        }
    }
    for name in ["adaptive_rounds", "runs_per_point"] {
        for extension in ["csv", "json"] {
            let path = dir.join("tables").join(format!("{name}.{extension}"));
            assert!(path.is_file(), "missing {}", path.display());
            assert!(files.tables.contains(&path));
        }
    }
    // After the sampler, before the run statistics; the runs per point with the failure map.
    let order =
        ["sampler", "convergence", "failure-map", "runs"].map(|id| section_position(&html, id));
    assert!(order.windows(2).all(|w| w[0] < w[1]));
    let table = html.find("id=\"table-runs_per_point\"").unwrap();
    assert!(order[2] < table && table < order[3]);

    let rounds = std::fs::read_to_string(dir.join("tables/adaptive_rounds.csv")).unwrap();
    let mut lines = rounds.lines();
    assert_eq!(
        lines.next().unwrap(),
        "round,runs,new runs,shift (posterior stds),sampler noise (posterior stds),\
         surrogate error (posterior stds),log-likelihood std (nats),extrapolated share,\
         sampler disagreement (posterior stds),mixing level,\
         kLink mean,kLink std,kBend mean,kBend std,sigma_m mean,sigma_m std"
    );
    assert_eq!(lines.count(), 3);
    let first = report.convergence.as_ref().unwrap().rounds[0].clone();
    assert!(rounds.contains(&format!(
        "\n1,40,12,,,{},{},",
        first.surrogate_error.unwrap(),
        first.log_likelihood_std
    )));

    let (document, _) = read_document(&dir);
    assert!(document.report == report, "report.json does not round-trip");
    assert_eq!(document.figures.len(), FIGURES.len() + 2);
    assert_figures_well_formed(&dir);
    assert_numbers_match_report_json(&dir);
    assert_no_temporaries(&dir);
}

#[test]
fn a_report_without_adaptive_results_has_neither_section() {
    let dir = fresh_dir("no-adaptive");
    write_report(&small_report(), &dir).unwrap();
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    for id in ["convergence", "failure-map"] {
        assert!(!html.contains(&format!("<section id=\"{id}\">")));
    }
    assert!(!html.contains("Convergence of the adaptive design"));
    assert!(!html.contains("Where the model fails"));
    for name in ["convergence", "failure_map"] {
        assert!(!dir.join(format!("figures/{name}.svg")).exists());
    }
    for name in ["adaptive_rounds", "runs_per_point"] {
        assert!(!dir.join(format!("tables/{name}.csv")).exists());
    }
}

#[test]
fn runs_per_point_without_a_failure_map_join_the_run_statistics() {
    let dir = fresh_dir("runs-per-point");
    let mut report = adaptive_report();
    report.failure_map.clear();
    write_report(&report, &dir).unwrap();
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(!html.contains("<section id=\"failure-map\">"));
    let table = html.find("id=\"table-runs_per_point\"").unwrap();
    assert!(section_position(&html, "runs") < table);
    assert!(dir.join("tables/runs_per_point.csv").is_file());
    assert!(!dir.join("figures/failure_map.svg").exists());
}

#[test]
fn a_convergence_without_rounds_has_text_but_no_figure() {
    let dir = fresh_dir("no-rounds");
    let mut report = adaptive_report();
    report.convergence.as_mut().unwrap().rounds.clear();
    report.convergence.as_mut().unwrap().converged = false;
    write_report(&report, &dir).unwrap();
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(html.contains("<section id=\"convergence\">"));
    assert!(html.contains("The rule was not met in 0 rounds."));
    assert!(!dir.join("figures/convergence.svg").exists());
    assert!(!dir.join("tables/adaptive_rounds.csv").exists());
}

#[test]
fn only_the_first_eight_failure_panels_are_drawn() {
    let dir = fresh_dir("nine-panels");
    let mut report = small_report();
    synthetic::add_adaptive_results(&mut report, 2, 9, 11);
    write_report(&report, &dir).unwrap();
    let (document, _) = read_document(&dir);
    let figure = document
        .figures
        .iter()
        .find(|f| f.name == "failure_map")
        .unwrap();
    assert!(figure.caption.contains("Only the first 8 of 9 panels"));
    let svg = std::fs::read_to_string(dir.join(&figure.svg)).unwrap();
    assert_eq!(svg.matches("runs at ").count(), 8);
}

#[test]
fn invalid_adaptive_results_are_rejected() {
    let mut bad = adaptive_report();
    bad.convergence.as_mut().unwrap().rounds[1].mean.pop();
    assert_rejected("short-mean", bad, "convergence.rounds[1].mean");

    let mut bad = adaptive_report();
    bad.convergence.as_mut().unwrap().rounds[2].std[0] = -1.0;
    assert_rejected("negative-std", bad, "convergence.rounds[2].std[0]");

    let mut bad = adaptive_report();
    bad.convergence.as_mut().unwrap().rounds[0].extrapolation_share = 1.5;
    assert_rejected(
        "share-above-one",
        bad,
        "convergence.rounds[0].extrapolation_share",
    );

    let mut bad = adaptive_report();
    bad.failure_map[0].failure_probability[7] = 1.2;
    assert_rejected(
        "probability-above-one",
        bad,
        "failure_map[0].failure_probability[7]",
    );

    let mut bad = adaptive_report();
    bad.failure_map[0].failure_probability.pop();
    assert_rejected("short-grid", bad, "failure_map[0].failure_probability");

    let mut bad = adaptive_report();
    bad.failure_map[1].failed.pop();
    assert_rejected("short-failed", bad, "failure_map[1].failed");

    let mut bad = adaptive_report();
    bad.failure_map[1].bounds.2 = bad.failure_map[1].bounds.3;
    assert_rejected("empty-bounds", bad, "failure_map[1].bounds");

    let mut bad = adaptive_report();
    bad.runs_per_point[2].x = f64::NAN;
    assert_rejected("nan-point", bad, "runs_per_point[2].x");
}
