//! Quantities the report computes from the study's results (prediction bands, errors of the MAP
//! curves, totals), kept in `report.json` beside the input so every table number is there.

use serde::{Deserialize, Serialize};

use crate::input::StudyReport;
use crate::statistics::{mean, quantile_sorted};

/// Lower probability of the central 95 % prediction band.
pub(crate) const BAND_LOW: f64 = 0.025;
/// Upper probability of the central 95 % prediction band.
pub(crate) const BAND_HIGH: f64 = 0.975;

/// Everything the report derives from a [`StudyReport`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DerivedResults {
    /// Predictions of each posterior source at the data points.
    pub predictions: Vec<SourcePredictions>,
    /// Number of posterior samples of each source, in the order of the posteriors.
    pub posterior_sample_counts: Vec<usize>,
    /// Sum of the wall times of all pipeline stages, in seconds.
    pub total_stage_seconds: f64,
    /// Share of failed runs among the runs made, succeeded or failed (0 when there were none).
    pub failure_fraction: f64,
    /// Runs in the campaign store neither succeeded nor failed: pending, abandoned or cancelled
    /// (a model posterior's batch left when its method changed, say).
    #[serde(default)]
    pub not_run: usize,
}

/// One posterior source's predictions at every data point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SourcePredictions {
    /// The source's name.
    pub source: String,
    /// One entry per data point, in data order.
    pub points: Vec<PredictionPoint>,
}

/// The propagated output at one data point compared with the measurement.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PredictionPoint {
    /// The control value.
    pub x: f64,
    /// The measured value.
    pub data: f64,
    /// The measurement std.
    pub data_err: f64,
    /// Model output at the MAP estimate.
    pub map_prediction: f64,
    /// Mean of the propagated output.
    pub mean: f64,
    /// 2.5 % quantile of the propagated output.
    pub q025: f64,
    /// 97.5 % quantile of the propagated output.
    pub q975: f64,
    /// |MAP prediction − data|.
    pub absolute_error: f64,
    /// |MAP prediction − data| / measurement std; `None` where the std is zero.
    pub error_in_data_std: Option<f64>,
}

impl DerivedResults {
    /// Computes the derived results of a validated report.
    pub(crate) fn compute(report: &StudyReport) -> Self {
        let data = &report.data;
        let predictions = report
            .posteriors
            .iter()
            .map(|posterior| SourcePredictions {
                source: posterior.source.clone(),
                points: posterior
                    .propagated
                    .iter()
                    .enumerate()
                    .map(|(i, output)| {
                        let mut sorted = output.samples.clone();
                        sorted.sort_by(f64::total_cmp);
                        let absolute_error = (output.map_prediction - data.y[i]).abs();
                        PredictionPoint {
                            x: data.x[i],
                            data: data.y[i],
                            data_err: data.y_err[i],
                            map_prediction: output.map_prediction,
                            mean: mean(&sorted),
                            q025: quantile_sorted(&sorted, BAND_LOW),
                            q975: quantile_sorted(&sorted, BAND_HIGH),
                            absolute_error,
                            error_in_data_std: (data.y_err[i] > 0.0)
                                .then(|| absolute_error / data.y_err[i]),
                        }
                    })
                    .collect(),
            })
            .collect();
        let stats = &report.run_statistics;
        Self {
            predictions,
            posterior_sample_counts: report.posteriors.iter().map(|p| p.samples.len()).collect(),
            total_stage_seconds: stats.stage_seconds.iter().map(|(_, s)| s).sum(),
            failure_fraction: if stats.succeeded + stats.failed > 0 {
                stats.failed as f64 / (stats.succeeded + stats.failed) as f64
            } else {
                0.0
            },
            not_run: stats.runs.saturating_sub(stats.succeeded + stats.failed),
        }
    }
}
