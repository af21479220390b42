//! A bank of GPs, one per output column, sharing the inputs: the surrogate of a multi-output
//! model, usable wherever a [`Model`] is.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use iuq_core::model::{Evaluation, EvaluationFailure, Model, Outcome};

use crate::data::validate_points;
use crate::error::{GpError, Result};
use crate::fit::{CheckedFitOptions, fit_with_stream};
use crate::gaussian_process::GaussianProcess;
use crate::prediction::{BLOCK, Prediction};

/// Which predictive standard deviation a bank reports as the computational std.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PredictiveStd {
    /// √(var_f + σ²): the std of a new model run, noise included (scikit-learn's
    /// `predict(return_std=True)` with a `WhiteKernel`, which the study used). Default.
    #[default]
    WithNoise,
    /// √var_f: the std of the latent (noise-free) function.
    Latent,
}

impl PredictiveStd {
    /// The part of a GP's noise variance `noise_variance` (in output units) that this
    /// convention adds to the latent variance: all of it, or none.
    pub fn added_noise_variance(self, noise_variance: f64) -> f64 {
        match self {
            PredictiveStd::WithNoise => noise_variance,
            PredictiveStd::Latent => 0.0,
        }
    }

    /// The variance whose square root a bank reports as the computational std at each point of
    /// `prediction`: var_f + σ², or var_f.
    pub fn variance(self, prediction: &Prediction) -> Vec<f64> {
        let noise = self.added_noise_variance(prediction.noise_variance);
        prediction.variance.iter().map(|v| v + noise).collect()
    }
}

/// One GP per output, all on the same inputs. Implements [`Model`]: a batch of points gives,
/// per point, the posterior means of every output and their predictive stds as the
/// computational std.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(try_from = "SavedBank", into = "SavedBank")]
pub struct GpBank {
    input_names: Vec<String>,
    output_names: Vec<String>,
    gps: Vec<GaussianProcess>,
    predictive_std: PredictiveStd,
}

/// The value of a GP file's `format` field: every GP file of iuq (`iuq gp fit`, the pipeline's
/// `gp-bank.json`, the Python package's `save`) is a bank, of one output or many.
pub const BANK_FORMAT: &str = "iuq-gp-bank";
/// The version of the bank layout written by this crate.
pub const BANK_FORMAT_VERSION: u32 = 1;

#[derive(Clone, Serialize, Deserialize)]
struct SavedBank {
    format: String,
    version: u32,
    input_names: Vec<String>,
    output_names: Vec<String>,
    predictive_std: PredictiveStd,
    gps: Vec<GaussianProcess>,
}

impl From<GpBank> for SavedBank {
    fn from(b: GpBank) -> Self {
        Self {
            format: BANK_FORMAT.to_string(),
            version: BANK_FORMAT_VERSION,
            input_names: b.input_names,
            output_names: b.output_names,
            predictive_std: b.predictive_std,
            gps: b.gps,
        }
    }
}

impl TryFrom<SavedBank> for GpBank {
    /// The reason, which [`GpBank::from_json_str`] wraps once as a persistence error.
    type Error = String;
    fn try_from(s: SavedBank) -> std::result::Result<Self, String> {
        if s.format != BANK_FORMAT || s.version != BANK_FORMAT_VERSION {
            return Err(format!(
                "format `{}` version {} is not a GP file (`{BANK_FORMAT}` version {BANK_FORMAT_VERSION})",
                s.format, s.version
            ));
        }
        GpBank::new(s.input_names, s.output_names, s.gps)
            .map(|b| b.with_predictive_std(s.predictive_std))
            .map_err(|e| e.to_string())
    }
}

impl GpBank {
    /// A bank from fitted GPs, one per output name, each on `input_names.len()` inputs.
    ///
    /// # Errors
    /// No outputs, a count of GPs different from the outputs, or a GP whose dimension differs
    /// from the number of inputs.
    pub fn new(
        input_names: Vec<String>,
        output_names: Vec<String>,
        gps: Vec<GaussianProcess>,
    ) -> Result<Self> {
        if output_names.is_empty() {
            return Err(GpError::InvalidParameter {
                what: "GP bank",
                reason: "needs at least one output".into(),
            });
        }
        if gps.len() != output_names.len() {
            return Err(GpError::LengthMismatch {
                what: "GPs vs. output names",
                expected: output_names.len(),
                actual: gps.len(),
            });
        }
        if let Some(gp) = gps.iter().find(|gp| gp.dimension() != input_names.len()) {
            return Err(GpError::LengthMismatch {
                what: "GP inputs vs. input names",
                expected: input_names.len(),
                actual: gp.dimension(),
            });
        }
        Ok(Self {
            input_names,
            output_names,
            gps,
            predictive_std: PredictiveStd::default(),
        })
    }

    /// Fits one GP per output column: `outputs[j][i]` is output j at point `x[i]`. Outputs
    /// are fitted in parallel; output j draws its multi-start design from the keyed stream
    /// `(options.seed, GP_MULTI_START, j)`.
    ///
    /// # Errors
    /// As [`GpBank::new`] and [`crate::fit()`] (the first failing output is reported).
    pub fn fit(
        input_names: Vec<String>,
        output_names: Vec<String>,
        x: &[Vec<f64>],
        outputs: &[Vec<f64>],
        options: &CheckedFitOptions,
    ) -> Result<Self> {
        if outputs.len() != output_names.len() {
            return Err(GpError::LengthMismatch {
                what: "output columns vs. output names",
                expected: output_names.len(),
                actual: outputs.len(),
            });
        }
        let d = validate_points(x, "training point", None)?;
        if d != input_names.len() {
            return Err(GpError::LengthMismatch {
                what: "training point dimension vs. input names",
                expected: input_names.len(),
                actual: d,
            });
        }
        let gps = outputs
            .par_iter()
            .enumerate()
            .map(|(j, y)| fit_with_stream(x, y, options, j as u64, None))
            .collect::<Result<Vec<_>>>()?;
        Self::new(input_names, output_names, gps)
    }

    /// The same bank reporting the given predictive std.
    pub fn with_predictive_std(mut self, predictive_std: PredictiveStd) -> Self {
        self.predictive_std = predictive_std;
        self
    }

    /// Which predictive std the bank reports.
    pub fn predictive_std(&self) -> PredictiveStd {
        self.predictive_std
    }

    /// The GPs, in output order.
    pub fn gps(&self) -> &[GaussianProcess] {
        &self.gps
    }

    /// Predictions of every output at `points` (one [`Prediction`] per output).
    ///
    /// # Errors
    /// A point of the wrong dimension or with a non-finite coordinate.
    pub fn predict(&self, points: &[Vec<f64>]) -> Result<Vec<Prediction>> {
        self.gps.iter().map(|gp| gp.predict(points)).collect()
    }

    /// The bank as a JSON document (GPs as in [`GaussianProcess::to_json_string`]).
    ///
    /// # Errors
    /// Only if serialisation fails.
    pub fn to_json_string(&self) -> Result<String> {
        serde_json::to_string(self).map_err(|e| GpError::Persistence(e.to_string()))
    }

    /// A bank from a JSON document written by [`GpBank::to_json_string`].
    ///
    /// # Errors
    /// Malformed JSON or any error of [`GaussianProcess::from_json_str`] or [`GpBank::new`].
    pub fn from_json_str(json: &str) -> Result<Self> {
        serde_json::from_str(json).map_err(|e| GpError::Persistence(e.to_string()))
    }
}

impl GpBank {
    /// Means and reported stds of every output at validated points: one parallel loop over
    /// (output, block of [`BLOCK`] points), so that all cores share the work of all GPs
    /// whatever the batch size; each block is computed sequentially, so the results do not
    /// depend on the number of threads.
    fn predict_valid(&self, points: &[Vec<f64>]) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
        let m = points.len();
        let mut means = vec![vec![0.0; m]; self.gps.len()];
        let mut stds = vec![vec![0.0; m]; self.gps.len()];
        let mut tasks = Vec::with_capacity(self.gps.len() * m.div_ceil(BLOCK));
        for ((gp, mean), std) in self.gps.iter().zip(&mut means).zip(&mut stds) {
            for ((mc, sc), pc) in mean
                .chunks_mut(BLOCK)
                .zip(std.chunks_mut(BLOCK))
                .zip(points.chunks(BLOCK))
            {
                tasks.push((gp, mc, sc, pc));
            }
        }
        tasks.into_par_iter().for_each(|(gp, mc, sc, pc)| {
            gp.predict_block(pc, mc, Some(&mut *sc));
            let s = gp.output_scaling.std;
            let noise = self
                .predictive_std
                .added_noise_variance(s * s * gp.hyperparameters.noise_variance);
            for v in sc.iter_mut() {
                *v = (*v + noise).sqrt();
            }
        });
        (means, stds)
    }
}

impl Model for GpBank {
    fn input_names(&self) -> &[String] {
        &self.input_names
    }

    fn output_names(&self) -> &[String] {
        &self.output_names
    }

    /// Per point: the means of every output, with the predictive stds as computational std.
    /// A point of the wrong dimension or with a non-finite coordinate is a per-point failure.
    fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
        Ok(self.outcomes(points, |valid| self.predict_valid(valid)))
    }

    /// Per point: the means of every output, with the noise part of the predictive std alone
    /// (the std a prediction has where the latent variance is zero): the screen of
    /// delayed-acceptance moves, O(n·d) per point and output instead of O(n²). Fails exactly
    /// where [`GpBank::evaluate_batch`] does.
    fn screening_batch(&self, points: &[Vec<f64>]) -> Option<iuq_core::Result<Vec<Outcome>>> {
        Some(Ok(self.outcomes(points, |valid| self.screen_valid(valid))))
    }
}

impl GpBank {
    /// One outcome per point from `predict`'s (means, stds) per output at the valid points; a
    /// point of the wrong dimension or with a non-finite coordinate is a per-point failure.
    fn outcomes(
        &self,
        points: &[Vec<f64>],
        predict: impl FnOnce(&[Vec<f64>]) -> (Vec<Vec<f64>>, Vec<Vec<f64>>),
    ) -> Vec<Outcome> {
        let d = self.input_names.len();
        let invalid: Vec<Option<String>> = points
            .iter()
            .map(|p| {
                if p.len() != d {
                    Some(format!("expected {d} inputs, got {}", p.len()))
                } else if p.iter().any(|v| !v.is_finite()) {
                    Some("non-finite input".to_string())
                } else {
                    None
                }
            })
            .collect();
        let valid: Vec<Vec<f64>> = points
            .iter()
            .zip(&invalid)
            .filter(|(_, e)| e.is_none())
            .map(|(p, _)| p.clone())
            .collect();
        let (means, stds) = predict(&valid);
        let mut next = 0;
        invalid
            .into_iter()
            .map(|e| match e {
                Some(reason) => Err(EvaluationFailure::new(reason)),
                None => {
                    let i = next;
                    next += 1;
                    Ok(Evaluation::with_std(
                        means.iter().map(|m| m[i]).collect(),
                        stds.iter().map(|s| s[i]).collect(),
                    ))
                }
            })
            .collect()
    }

    /// Means and noise-only stds of every output at validated points, in the blocks of
    /// [`GpBank::predict_valid`] without the variances.
    fn screen_valid(&self, points: &[Vec<f64>]) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
        let m = points.len();
        let mut means = vec![vec![0.0; m]; self.gps.len()];
        let mut tasks = Vec::with_capacity(self.gps.len() * m.div_ceil(BLOCK));
        for (gp, mean) in self.gps.iter().zip(&mut means) {
            for (mc, pc) in mean.chunks_mut(BLOCK).zip(points.chunks(BLOCK)) {
                tasks.push((gp, mc, pc));
            }
        }
        tasks
            .into_par_iter()
            .for_each(|(gp, mc, pc)| gp.predict_block(pc, mc, None));
        let stds = self
            .gps
            .iter()
            .map(|gp| {
                let s = gp.output_scaling.std;
                let noise = self
                    .predictive_std
                    .added_noise_variance(s * s * gp.hyperparameters.noise_variance);
                vec![noise.sqrt(); m]
            })
            .collect();
        (means, stds)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::FitOptions;
    use crate::test_data::spec_data;

    fn names(prefix: &str, n: usize) -> Vec<String> {
        (1..=n).map(|i| format!("{prefix}{i}")).collect()
    }

    fn bank() -> (GpBank, Vec<Vec<f64>>, Vec<Vec<f64>>) {
        let (x, y) = spec_data();
        let x = x[..40].to_vec();
        let y1 = y[..40].to_vec();
        let y2: Vec<f64> = x.iter().map(|p| p[0] * p[1] + 0.3 * p[2]).collect();
        let opts = FitOptions {
            n_restarts: 3,
            ..Default::default()
        };
        let outputs = vec![y1, y2];
        let b = GpBank::fit(
            names("x", 3),
            names("y", 2),
            &x,
            &outputs,
            &opts.check().unwrap(),
        )
        .unwrap();
        (b, x, outputs)
    }

    #[test]
    fn bank_is_a_model_matching_its_gps() {
        let (b, x, outputs) = bank();
        assert_eq!(b.input_dimension(), 3);
        assert_eq!(b.output_dimension(), 2);
        let pts = vec![
            vec![0.2, 0.3, 0.4],
            vec![0.5, 0.1],
            vec![0.9, 0.8, 0.1],
            vec![f64::NAN, 0.0, 0.0],
        ];
        let out = b.evaluate_batch(&pts).unwrap();
        assert_eq!(out.len(), 4);
        assert!(out[1].is_err() && out[3].is_err());
        for (i, p) in [(0, &pts[0]), (2, &pts[2])] {
            let e = out[i].as_ref().unwrap();
            for (j, gp) in b.gps().iter().enumerate() {
                let single = gp.predict(std::slice::from_ref(p)).unwrap();
                assert_eq!(e.outputs[j], single.mean[0]);
                let (a, b) = (
                    e.computational_std.as_ref().unwrap()[j],
                    single.std_with_noise()[0],
                );
                assert!((a - b).abs() <= 1e-5 * b, "{a} vs {b}");
            }
        }
        // Each output's GP reproduces its training data well.
        for (j, gp) in b.gps().iter().enumerate() {
            assert!(gp.q2(&x, &outputs[j]).unwrap() > 0.99);
        }
        let latent = b.clone().with_predictive_std(PredictiveStd::Latent);
        let e = latent.evaluate_batch(&pts[..1]).unwrap();
        let p = b.gps()[0].predict(&pts[..1]).unwrap();
        let a = e[0].as_ref().unwrap().computational_std.as_ref().unwrap()[0];
        assert!((a - p.std()[0]).abs() <= 1e-5 * a);
        assert!(
            a < b.evaluate_batch(&pts[..1]).unwrap()[0]
                .as_ref()
                .unwrap()
                .computational_std
                .as_ref()
                .unwrap()[0]
        );
    }

    /// The screen of delayed acceptance: the same means, failing at the same points, with the
    /// noise part of the std alone (the std the full prediction has where its latent variance
    /// vanishes: at most the full std, and √(s²σ²) exactly).
    #[test]
    fn the_screen_has_the_means_and_the_noise_std() {
        let (b, _, _) = bank();
        let pts = vec![
            vec![0.2, 0.3, 0.4],
            vec![0.5, 0.1],
            vec![0.9, 0.8, 0.1],
            vec![f64::NAN, 0.0, 0.0],
        ];
        let full = b.evaluate_batch(&pts).unwrap();
        let screen = b.screening_batch(&pts).unwrap().unwrap();
        for (f, s) in full.iter().zip(&screen) {
            assert_eq!(f.is_ok(), s.is_ok());
            let (Ok(f), Ok(s)) = (f, s) else { continue };
            assert_eq!(f.outputs, s.outputs);
            for (j, gp) in b.gps().iter().enumerate() {
                let noise = gp.predict(&pts[..1]).unwrap().noise_variance.sqrt();
                let screened = s.computational_std.as_ref().unwrap()[j];
                assert_eq!(screened, noise);
                assert!(screened <= f.computational_std.as_ref().unwrap()[j]);
            }
        }
    }

    #[test]
    fn results_do_not_depend_on_threads_or_batch() {
        let (b, _, _) = bank();
        let pts: Vec<Vec<f64>> = (0..(2 * BLOCK + 19))
            .map(|i| {
                let t = (i as f64 + 0.5) / (2 * BLOCK + 19) as f64;
                vec![t, (5.0 * t).fract(), (11.0 * t).fract()]
            })
            .collect();
        let with = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| b.evaluate_batch(&pts).unwrap())
        };
        let one = with(1);
        assert_eq!(one, with(2));
        assert_eq!(one, with(3));
        for i in [0, 7, 8, BLOCK, 2 * BLOCK + 18] {
            assert_eq!(b.evaluate_batch(&pts[i..=i]).unwrap()[0], one[i], "{i}");
        }
    }

    #[test]
    fn bank_roundtrip_and_bad_input() {
        let (b, x, outputs) = bank();
        let json = b.to_json_string().unwrap();
        let back = GpBank::from_json_str(&json).unwrap();
        // The file names its format; another format or version is refused, naming both.
        assert!(
            json.starts_with(r#"{"format":"iuq-gp-bank","version":1,"#),
            "{}",
            &json[..60]
        );
        for (from, to) in [
            (r#""format":"iuq-gp-bank""#, r#""format":"iuq-gp""#),
            (r#""version":1"#, r#""version":2"#),
        ] {
            let message = GpBank::from_json_str(&json.replacen(from, to, 1))
                .unwrap_err()
                .to_string();
            assert!(message.contains("is not a GP file"), "{message}");
        }
        let pts = vec![vec![0.2, 0.3, 0.4], vec![0.7, 0.1, 0.5]];
        assert_eq!(
            b.evaluate_batch(&pts).unwrap(),
            back.evaluate_batch(&pts).unwrap()
        );
        assert!(
            GpBank::fit(
                names("x", 2),
                names("y", 2),
                &x,
                &outputs,
                &FitOptions::default().check().unwrap()
            )
            .is_err()
        );
        assert!(
            GpBank::fit(
                names("x", 3),
                names("y", 3),
                &x,
                &outputs,
                &FitOptions::default().check().unwrap()
            )
            .is_err()
        );
        assert!(GpBank::new(names("x", 3), vec![], vec![]).is_err());
    }
}
