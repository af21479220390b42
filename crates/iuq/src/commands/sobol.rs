//! `iuq sobol STUDY`: Sobol' indices of a study's model over its priors.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use serde_json::{Map, Value, json};

use iuq_sensitivity::{IntervalMethod, SensitivityOptions, analyse};
use iuq_study::study::Study;

use crate::input_error::{BadInput, input_error};
use crate::report_output::{emit, short};

/// Arguments of `iuq sobol`.
#[derive(Debug, Args)]
pub struct SobolArgs {
    /// The study file (TOML) with a `[model]` (expression, rbc-shear or umbridge).
    pub study: PathBuf,
    /// Base points N of the Saltelli design (N(d + 2) evaluations per design); default from the
    /// study's `[sensitivity] n`, else 1024.
    #[arg(long)]
    pub n: Option<usize>,
    /// Seed of the scrambling and bootstrap (default from the study, else 0).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Confidence intervals from R independent scramblings instead of the bootstrap.
    #[arg(long)]
    pub replicates: Option<usize>,
    /// Bootstrap resamples (default 100).
    #[arg(long)]
    pub resamples: Option<usize>,
    /// Confidence level of the intervals (default 0.95).
    #[arg(long)]
    pub confidence: Option<f64>,
}

/// Run `iuq sobol`.
pub fn run(args: &SobolArgs, json: bool) -> Result<()> {
    let study = Study::load(&args.study)?;
    let model = study.model()?;
    let section = &study.sensitivity;
    let n = args.n.or(section.n).unwrap_or(1024);
    if n < 2 {
        return Err(input_error(format!(
            "--n: at least 2 base points are needed, got {n}"
        )));
    }
    let confidence = args.confidence.or(section.confidence).unwrap_or(0.95);
    if !(confidence > 0.0 && confidence < 1.0) {
        return Err(input_error(format!(
            "--confidence: {confidence} must lie strictly between 0 and 1"
        )));
    }
    let interval = match args.replicates.or(section.replicates) {
        Some(count) if count < 2 => {
            return Err(input_error(format!(
                "--replicates: at least 2 are needed, got {count}"
            )));
        }
        Some(count) => IntervalMethod::Replicates { count },
        None => {
            let resamples = args.resamples.or(section.resamples).unwrap_or(100);
            if resamples < 2 {
                return Err(input_error(format!(
                    "--resamples: at least 2 are needed, got {resamples}"
                )));
            }
            IntervalMethod::Bootstrap { resamples }
        }
    };
    let options = SensitivityOptions {
        base_points: n,
        seed: args.seed.or(section.seed).unwrap_or(0),
        interval,
        confidence_level: confidence,
        ..Default::default()
    }
    .check()
    .bad_input(|| format!("{}", args.study.display()))?;
    let start = std::time::Instant::now();
    let report = analyse(&model, &study.space, &options)
        .bad_input(|| format!("{}", args.study.display()))?;
    let by_name = |values: &[f64]| -> Value {
        Value::Object(
            report
                .inputs
                .iter()
                .zip(values)
                .map(|(k, v)| (k.clone(), json!(v)))
                .collect::<Map<_, _>>(),
        )
    };
    let mut outputs = Map::new();
    for o in &report.outputs {
        outputs.insert(
            o.output.clone(),
            json!({
                "S1": by_name(&o.first_order),
                "ST": by_name(&o.total),
                "S1_conf": by_name(&o.first_order_conf),
                "ST_conf": by_name(&o.total_conf),
                "variance": o.variance,
            }),
        );
    }
    let value = json!({
        "study": study.name,
        "outputs": outputs,
        "evaluations": report.evaluations,
        "failed_evaluations": report.failed_evaluations,
        "dropped_groups": report.dropped_groups,
        "failure_handling": report.failure_handling(),
        "failure_reasons": report.failure_reasons,
        "base_points": n,
        "seconds": start.elapsed().as_secs_f64(),
        "interval": match &options.interval {
            IntervalMethod::Bootstrap { resamples } => json!({"method": "bootstrap", "resamples": resamples, "confidence": confidence}),
            IntervalMethod::Replicates { count } => json!({"method": "replicates", "count": count, "confidence": confidence}),
        },
    });
    emit(json, &value, || {
        let mut text = format!(
            "Sobol' indices of `{}` ({} evaluations; {})\n",
            study.name,
            report.evaluations,
            report.failure_handling()
        );
        for o in &report.outputs {
            text.push_str(&format!(
                "\noutput {}\n{:<16} {:>22} {:>22}\n",
                o.output, "input", "S1 ± conf", "ST ± conf"
            ));
            for (i, name) in report.inputs.iter().enumerate() {
                text.push_str(&format!(
                    "{:<16} {:>22} {:>22}\n",
                    name,
                    format!(
                        "{} ± {}",
                        short(o.first_order[i]),
                        short(o.first_order_conf[i])
                    ),
                    format!("{} ± {}", short(o.total[i]), short(o.total_conf[i]))
                ));
            }
        }
        text
    });
    Ok(())
}
