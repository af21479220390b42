//! The prediction-error likelihood of a model against data (docs/methods.md §4; Wu et al. 2017,
//! section 2).
//!
//! Data D = {ŷ_j}, j = 1..N_ŷ, and a model q(θ_m) with one output per data point (output j ↔
//! data point j, by order). The parameters θ = (θ_m, σ_m) are the model's parameters followed by
//! the homoscedastic modelling error σ_m (named [`MODELLING_ERROR_NAME`]) when it is estimated.
//! ŷ = q(θ_m) + ε, ε ~ N(0, Σ), Σ diagonal,
//!
//! Σ_jj = σ_d,j² + c_j + σ_m²·ŷ_j²,
//!
//! with σ_d,j the measurement error of observation j (switchable), c_j the computational term
//! ([`ComputationalError`]) and σ_m the modelling error, relative to the data. Then
//!
//! ln f(D | θ) = −½ Σ_j [ r_j²/Σ_jj + ln(2π Σ_jj) ],  r = ŷ − q(θ_m).
//!
//! A failed model run, a non-finite output or a non-positive variance makes the point a failure
//! (ln f = −∞ for the sampler, counted with its reason).

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use iuq_core::{EvaluationFailure, Model, Outcome, Parameter, ParameterSpace, Prior};

use crate::error::{BasisError, Result};
use crate::gaussian_screen::GaussianScreen;
use crate::likelihood::{LogLikelihood, PointLogLikelihood};

/// The name of the modelling-error parameter appended to the model's parameters.
pub const MODELLING_ERROR_NAME: &str = "sigma_m";

/// The prior of the modelling error σ_m in the red-cell study and in [`ErrorModel::default`]:
/// U(0.001, 0.1). A study file has no modelling error unless it names a prior.
pub const DEFAULT_MODELLING_ERROR_PRIOR: Prior = Prior::Uniform(0.001, 0.1);

/// ln(2π).
const LN_2PI: f64 = 1.837_877_066_409_345_5;

/// How the model's computational standard deviation s_j (the spread of a simulator's measuring
/// window, or a surrogate's predictive std — [`iuq_core::Evaluation::computational_std`]) enters
/// the variance Σ_jj. When the model reports no std, the term is zero.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ComputationalError {
    /// The paper's form (the red-cell study's): the computational error is relative,
    /// σ_c,j = s_j/|q_j|, and enters as σ_c,j²·ŷ_j² = (s_j·ŷ_j/q_j)². Undefined (a failure) where
    /// q_j = 0 and s_j > 0.
    Relative,
    /// The study's original code: the absolute std multiplied by the datum, s_j²·ŷ_j².
    AbsoluteTimesData,
    /// The absolute std as a variance of its own, s_j² (the dimensionally plain form, and the
    /// default of a study: a surrogate's predictive variance adds to the data's as it is).
    #[default]
    Absolute,
    /// Ignore the model's computational std.
    None,
}

impl ComputationalError {
    /// The name used in study files (`computational_error = "relative"`).
    pub fn name(self) -> &'static str {
        match self {
            ComputationalError::Relative => "relative",
            ComputationalError::AbsoluteTimesData => "absolute-times-data",
            ComputationalError::Absolute => "absolute",
            ComputationalError::None => "none",
        }
    }

    /// Every convention, for parsing and messages.
    pub const ALL: [ComputationalError; 4] = [
        ComputationalError::Relative,
        ComputationalError::AbsoluteTimesData,
        ComputationalError::Absolute,
        ComputationalError::None,
    ];

    /// The convention called `name`, if any.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|c| c.name() == name)
    }

    /// The variance term c_j for model output `q`, its std `s` and datum `y`: (s·y/q)² for
    /// [`Relative`](Self::Relative), (s·y)², s² or 0 for the others.
    #[inline]
    pub fn variance(self, q: f64, s: f64, y: f64) -> std::result::Result<f64, EvaluationFailure> {
        Ok(match self {
            ComputationalError::Relative => {
                if s == 0.0 {
                    0.0
                } else if q == 0.0 {
                    return Err(EvaluationFailure::new(
                        "relative computational error undefined: model output is 0",
                    ));
                } else {
                    (s * y / q).powi(2)
                }
            }
            ComputationalError::AbsoluteTimesData => (s * y).powi(2),
            ComputationalError::Absolute => s * s,
            ComputationalError::None => 0.0,
        })
    }
}

/// Observations ŷ_j with optional measurement standard deviations σ_d,j.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Observations {
    /// The data ŷ_j, in the order of the model's outputs.
    pub values: Vec<f64>,
    /// The measurement error σ_d,j of each datum (e.g. the `y_err` column), if known.
    pub measurement_std: Option<Vec<f64>>,
}

impl Observations {
    /// Check that there is data, every value is finite and every σ_d,j finite and ≥ 0.
    pub fn validate(&self) -> Result<()> {
        if self.values.is_empty() {
            return Err(BasisError::InvalidData("no observations".into()));
        }
        if let Some(j) = self.values.iter().position(|v| !v.is_finite()) {
            return Err(BasisError::InvalidData(format!(
                "observation {j} is not finite ({})",
                self.values[j]
            )));
        }
        if let Some(s) = &self.measurement_std {
            if s.len() != self.values.len() {
                return Err(BasisError::InvalidData(format!(
                    "{} observations but {} measurement errors",
                    self.values.len(),
                    s.len()
                )));
            }
            if let Some(j) = s.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
                return Err(BasisError::InvalidData(format!(
                    "measurement error {j} must be finite and non-negative, got {}",
                    s[j]
                )));
            }
        }
        Ok(())
    }
}

/// Which error terms enter Σ (docs/methods.md §4).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ErrorModel {
    /// Use the measurement errors σ_d,j of the data (default true; ignored when the data has
    /// none).
    pub measurement_error: bool,
    /// How the model's computational std enters (default [`ComputationalError::Relative`]).
    pub computational_error: ComputationalError,
    /// The prior of the modelling error σ_m, estimated with the model parameters; `None`
    /// leaves it out (default U(0.001, 0.1)).
    pub modelling_error: Option<Prior>,
}

impl ErrorModel {
    /// ln f of one datum: −½[(ŷ − q)²/Σ + ln(2πΣ)], Σ = σ_d² + c(q, s, ŷ) + σ_m²·ŷ², with σ_d
    /// the datum's measurement std (used when [`ErrorModel::measurement_error`] is set), s the
    /// model's computational std of that output and σ_m the modelling error (0 when not
    /// estimated). A non-positive or non-finite Σ is a failure naming datum `j`.
    pub fn datum_log_likelihood(
        &self,
        j: usize,
        y: f64,
        measurement_std: Option<f64>,
        q: f64,
        s: f64,
        sigma_m: f64,
    ) -> std::result::Result<f64, EvaluationFailure> {
        Ok(-0.5 * self.datum_deviance(j, y, measurement_std, q, s, sigma_m)?)
    }

    /// −2 ln f of one datum, (ŷ − q)²/Σ + ln(2πΣ) (summed over the data before the factor −½,
    /// as the likelihood always has, so that its values do not change in the last bit).
    fn datum_deviance(
        &self,
        j: usize,
        y: f64,
        measurement_std: Option<f64>,
        q: f64,
        s: f64,
        sigma_m: f64,
    ) -> std::result::Result<f64, EvaluationFailure> {
        let variance = self.datum_variance(j, y, measurement_std, q, s, sigma_m)?;
        Ok(deviance(y - q, variance, variance.ln()))
    }

    /// Σ_jj of one datum (see [`ErrorModel::datum_log_likelihood`]); a non-positive or
    /// non-finite Σ is a failure naming datum `j`.
    #[inline]
    fn datum_variance(
        &self,
        j: usize,
        y: f64,
        measurement_std: Option<f64>,
        q: f64,
        s: f64,
        sigma_m: f64,
    ) -> std::result::Result<f64, EvaluationFailure> {
        let sd = if self.measurement_error {
            measurement_std.unwrap_or(0.0)
        } else {
            0.0
        };
        let variance =
            sd * sd + self.computational_error.variance(q, s, y)? + sigma_m * sigma_m * y * y;
        if !(variance > 0.0 && variance.is_finite()) {
            return Err(EvaluationFailure::new(format!(
                "variance of observation {j} is {variance} (no positive error term)"
            )));
        }
        Ok(variance)
    }
}

/// −2 ln f of one datum from its residual r, its variance Σ and ln Σ: r²/Σ + ln 2π + ln Σ.
#[inline]
fn deviance(r: f64, variance: f64, log_variance: f64) -> f64 {
    r * r / variance + LN_2PI + log_variance
}

/// ln Σ_jj of one point of a batch, reused for every other point whose Σ_jj is the same number:
/// a screen's surrogate (the GPs' means, a variance that does not depend on θ) or a model without
/// computational stds gives every point the same variances, and their logarithm was most of a
/// likelihood evaluation on a 200-point curve. The same input gives the same `ln`, so the
/// likelihood does not change in the last bit.
#[derive(Debug, Default)]
struct VarianceLogs {
    variance: Vec<f64>,
    log: Vec<f64>,
}

impl VarianceLogs {
    /// ln `variance`, from the memo where datum `j`'s variance there is bitwise the same.
    #[inline]
    fn log(&self, j: usize, variance: f64) -> f64 {
        match self.variance.get(j) {
            Some(v) if v.to_bits() == variance.to_bits() => self.log[j],
            _ => variance.ln(),
        }
    }
}

/// The red-cell study's error model (Wu et al. 2017): measurement error, the relative computational
/// error and σ_m ~ U(0.001, 0.1). A study file's default is plainer: no modelling error and the
/// absolute computational error (`iuq-study`'s `[likelihood]` reader).
impl Default for ErrorModel {
    fn default() -> Self {
        Self {
            measurement_error: true,
            computational_error: ComputationalError::Relative,
            modelling_error: Some(DEFAULT_MODELLING_ERROR_PRIOR),
        }
    }
}

/// The prediction-error likelihood of a [`Model`] against [`Observations`].
///
/// Parameters: the model's inputs in order, then σ_m when [`ErrorModel::modelling_error`] is
/// set. Each batch of parameter vectors is one [`Model::evaluate_batch`] call.
#[derive(Debug, Clone)]
pub struct PredictionErrorLikelihood<M> {
    model: M,
    observations: Observations,
    errors: ErrorModel,
    /// The screen's likelihood as a quadratic form, where the model's screen is affine
    /// ([`crate::gaussian_screen`]); built at the first screened batch.
    screen: std::sync::OnceLock<Option<GaussianScreen>>,
}

impl<M: Model> PredictionErrorLikelihood<M> {
    /// Build the likelihood, checking the data, that the model has one output per datum, and
    /// that Σ cannot be identically zero (some error term must be present).
    pub fn new(model: M, observations: Observations, errors: ErrorModel) -> Result<Self> {
        observations.validate()?;
        if model.output_dimension() != observations.values.len() {
            return Err(BasisError::InvalidData(format!(
                "the model has {} outputs but there are {} observations (output j is compared with observation j)",
                model.output_dimension(),
                observations.values.len()
            )));
        }
        if let Some(prior) = errors.modelling_error {
            prior.validate(MODELLING_ERROR_NAME)?;
            let (lo, _) = prior.support();
            if lo < 0.0 {
                return Err(BasisError::InvalidLikelihood(format!(
                    "the prior of {MODELLING_ERROR_NAME} must not allow negative values (support starts at {lo})"
                )));
            }
        }
        if model
            .input_names()
            .iter()
            .any(|n| n == MODELLING_ERROR_NAME)
            && errors.modelling_error.is_some()
        {
            return Err(BasisError::InvalidLikelihood(format!(
                "a model parameter is called `{MODELLING_ERROR_NAME}`, the name of the modelling error"
            )));
        }
        let has_measurement = errors.measurement_error
            && observations
                .measurement_std
                .as_ref()
                .is_some_and(|s| s.iter().all(|v| *v > 0.0));
        if !has_measurement
            && errors.modelling_error.is_none()
            && errors.computational_error == ComputationalError::None
        {
            return Err(BasisError::InvalidLikelihood(
                "no error term: give positive measurement errors, a modelling error or a computational error".into(),
            ));
        }
        Ok(Self {
            model,
            observations,
            errors,
            screen: std::sync::OnceLock::new(),
        })
    }

    /// The model.
    pub fn model(&self) -> &M {
        &self.model
    }

    /// The observations.
    pub fn observations(&self) -> &Observations {
        &self.observations
    }

    /// The error terms.
    pub fn errors(&self) -> &ErrorModel {
        &self.errors
    }

    /// The sampled parameter space: `model_space` (whose names must be the model's inputs, in
    /// order) followed by σ_m with its prior when the modelling error is estimated.
    pub fn parameter_space(&self, model_space: &ParameterSpace) -> Result<ParameterSpace> {
        if model_space.names() != self.model.input_names() {
            return Err(BasisError::InvalidLikelihood(format!(
                "the parameters ({}) are not the model's inputs ({})",
                model_space.names().join(", "),
                self.model.input_names().join(", ")
            )));
        }
        let mut parameters = model_space.parameters().to_vec();
        if let Some(prior) = self.errors.modelling_error {
            parameters.push(Parameter {
                name: MODELLING_ERROR_NAME.into(),
                prior,
            });
        }
        Ok(ParameterSpace::new(parameters)?)
    }

    /// ln f(D | θ) from one model outcome and σ_m (0 when not estimated).
    pub fn log_likelihood_of(&self, outcome: &Outcome, sigma_m: f64) -> PointLogLikelihood {
        self.log_likelihood_with(outcome, sigma_m, &VarianceLogs::default())
    }

    /// Each datum's residual ŷ_j − q_j and Σ_jj under one outcome and σ_m, after checking that
    /// the outcome is a finite evaluation with one output per datum.
    fn data_terms<'a>(
        &'a self,
        outcome: &'a Outcome,
        sigma_m: f64,
    ) -> std::result::Result<
        impl Iterator<Item = std::result::Result<(f64, f64), EvaluationFailure>> + 'a,
        EvaluationFailure,
    > {
        let evaluation = outcome.as_ref().map_err(Clone::clone)?;
        let y = &self.observations.values;
        if evaluation.outputs.len() != y.len() {
            return Err(EvaluationFailure::new(format!(
                "model returned {} outputs, expected {}",
                evaluation.outputs.len(),
                y.len()
            )));
        }
        if !evaluation.is_finite() {
            return Err(EvaluationFailure::new("model returned a non-finite output"));
        }
        let measurement = self.observations.measurement_std.as_deref();
        let stds = evaluation.computational_std.as_deref();
        Ok(y.iter()
            .zip(&evaluation.outputs)
            .enumerate()
            .map(move |(j, (&yj, &qj))| {
                let sc = stds.and_then(|s| s.get(j)).copied().unwrap_or(0.0);
                let variance = self.errors.datum_variance(
                    j,
                    yj,
                    measurement.map(|s| s[j]),
                    qj,
                    sc,
                    sigma_m,
                )?;
                Ok((yj - qj, variance))
            }))
    }

    /// The variances of the data under one outcome and σ_m, with their logarithms (empty where
    /// the outcome gives no likelihood).
    fn variance_logs(&self, outcome: &Outcome, sigma_m: f64) -> VarianceLogs {
        let Ok(terms) = self.data_terms(outcome, sigma_m) else {
            return VarianceLogs::default();
        };
        let variance: Option<Vec<f64>> = terms.map(|t| t.ok().map(|(_, v)| v)).collect();
        let Some(variance) = variance else {
            return VarianceLogs::default();
        };
        let log = variance.iter().map(|v| v.ln()).collect();
        VarianceLogs { variance, log }
    }

    /// [`PredictionErrorLikelihood::log_likelihood_of`] with the logarithms of `memo`'s variances.
    fn log_likelihood_with(
        &self,
        outcome: &Outcome,
        sigma_m: f64,
        memo: &VarianceLogs,
    ) -> PointLogLikelihood {
        let mut sum = 0.0;
        for (j, term) in self.data_terms(outcome, sigma_m)?.enumerate() {
            let (residual, variance) = term?;
            sum += deviance(residual, variance, memo.log(j, variance));
        }
        Ok(-0.5 * sum)
    }
}

impl<M: Model> LogLikelihood for PredictionErrorLikelihood<M> {
    fn parameter_count(&self) -> usize {
        self.model.input_dimension() + usize::from(self.errors.modelling_error.is_some())
    }

    fn log_likelihood_batch(&self, points: &[Vec<f64>]) -> Result<Vec<PointLogLikelihood>> {
        let model_points = self.model_points(points)?;
        let outcomes = self.model.evaluate_batch(&model_points);
        self.of_outcomes(points, outcomes)
    }

    /// The same likelihood of the model's screen ([`iuq_core::Model::screening_batch`]), as a
    /// quadratic form in the screen's coefficients where the screen is affine and the variances
    /// do not depend on θ ([`crate::gaussian_screen`]).
    fn screening_log_likelihood_batch(
        &self,
        points: &[Vec<f64>],
    ) -> Option<Result<Vec<PointLogLikelihood>>> {
        let model_points = match self.model_points(points) {
            Ok(m) => m,
            Err(e) => return Some(Err(e)),
        };
        if let Some(affine) = self.model.affine_screening() {
            let screen = self.screen.get_or_init(|| {
                let affine = affine.affine_screen();
                let variances = self.screen_variances(&affine)?;
                GaussianScreen::new(&affine, &self.observations.values, &variances)
            });
            if let Some(screen) = screen {
                return Some(self.of_coefficients(screen, affine, points, &model_points));
            }
        }
        let outcomes = self.model.screening_batch(&model_points)?;
        Some(self.of_outcomes(points, outcomes))
    }
}

impl<M: Model> PredictionErrorLikelihood<M> {
    /// The model's inputs of every point (σ_m, when estimated, left off), after checking the
    /// points' length.
    fn model_points(&self, points: &[Vec<f64>]) -> Result<Vec<Vec<f64>>> {
        let n_model = self.model.input_dimension();
        let expected = self.parameter_count();
        if let Some(p) = points.iter().find(|p| p.len() != expected) {
            return Err(BasisError::InvalidLikelihood(format!(
                "expected {expected} parameters, got a point with {}",
                p.len()
            )));
        }
        Ok(points.iter().map(|p| p[..n_model].to_vec()).collect())
    }

    /// Σ_jj of the affine screen `screen`'s outputs where they do not depend on θ: no estimated
    /// modelling error and a computational error that does not scale with q (`None` otherwise,
    /// or where a datum's variance is not positive).
    fn screen_variances(&self, screen: &iuq_core::affine_screen::AffineScreen) -> Option<Vec<f64>> {
        if self.errors.modelling_error.is_some()
            || self.errors.computational_error == ComputationalError::Relative
            || screen.outputs() != self.observations.values.len()
            || screen.stds.len() != screen.outputs()
        {
            return None;
        }
        let measurement = self.observations.measurement_std.as_deref();
        self.observations
            .values
            .iter()
            .enumerate()
            .map(|(j, &y)| {
                self.errors
                    .datum_variance(
                        j,
                        y,
                        measurement.map(|s| s[j]),
                        screen.offset[j],
                        screen.stds[j],
                        0.0,
                    )
                    .ok()
            })
            .collect()
    }

    /// ln f of the affine screen at every point, from its coefficients there.
    fn of_coefficients(
        &self,
        screen: &GaussianScreen,
        affine: &dyn iuq_core::affine_screen::AffineScreening,
        points: &[Vec<f64>],
        model_points: &[Vec<f64>],
    ) -> Result<Vec<PointLogLikelihood>> {
        let coefficients = affine
            .screening_coefficients(model_points)
            .map_err(|e| match e {
                iuq_core::CoreError::ModelInput(reason) => BasisError::ModelInput(reason),
                e => BasisError::ModelBatch(e.to_string()),
            })?;
        if coefficients.len() != points.len() {
            return Err(BasisError::ModelBatch(format!(
                "the model's screen returned {} outcomes for {} points",
                coefficients.len(),
                points.len()
            )));
        }
        Ok(coefficients
            .par_iter()
            .with_min_len(64)
            .map(|c| {
                c.as_ref()
                    .map_err(Clone::clone)
                    .and_then(|c| screen.log_likelihood(c))
            })
            .collect())
    }

    /// ln f at every point from the model's outcomes there.
    fn of_outcomes(
        &self,
        points: &[Vec<f64>],
        outcomes: iuq_core::Result<Vec<iuq_core::Outcome>>,
    ) -> Result<Vec<PointLogLikelihood>> {
        let n_model = self.model.input_dimension();
        let outcomes = outcomes.map_err(|e| match e {
            iuq_core::CoreError::ModelInput(reason) => BasisError::ModelInput(reason),
            e => BasisError::ModelBatch(e.to_string()),
        })?;
        if outcomes.len() != points.len() {
            return Err(BasisError::ModelBatch(format!(
                "the model returned {} outcomes for {} points",
                outcomes.len(),
                points.len()
            )));
        }
        let estimated = self.errors.modelling_error.is_some();
        let sigma_m = |p: &[f64]| if estimated { p[n_model] } else { 0.0 };
        let memo = points
            .first()
            .zip(outcomes.first())
            .map(|(p, outcome)| self.variance_logs(outcome, sigma_m(p)))
            .unwrap_or_default();
        Ok(points
            .par_iter()
            .zip(outcomes.par_iter())
            .with_min_len(64)
            .map(|(p, outcome)| self.log_likelihood_with(outcome, sigma_m(p), &memo))
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use iuq_core::{Evaluation, ExpressionModel};

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    /// A model returning fixed outputs and stds, whatever its input.
    struct Fixed(Vec<String>, Vec<String>, Outcome);
    impl Model for Fixed {
        fn input_names(&self) -> &[String] {
            &self.0
        }
        fn output_names(&self) -> &[String] {
            &self.1
        }
        fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
            Ok(points.iter().map(|_| self.2.clone()).collect())
        }
    }

    fn fixed(q: Vec<f64>, s: Option<Vec<f64>>) -> Fixed {
        let outputs = (0..q.len()).map(|j| format!("y{j}")).collect();
        let e = match s {
            Some(s) => Evaluation::with_std(q, s),
            None => Evaluation::new(q),
        };
        Fixed(names(&["k"]), outputs, Ok(e))
    }

    /// Outputs (k, 2k) with computational stds that depend on k only above 0.5: below, every
    /// point of a batch has the same variances, above each its own.
    struct Varying(Vec<String>, Vec<String>);
    impl Model for Varying {
        fn input_names(&self) -> &[String] {
            &self.0
        }
        fn output_names(&self) -> &[String] {
            &self.1
        }
        fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
            Ok(points
                .iter()
                .map(|p| {
                    let k = p[0];
                    let s = if k > 0.5 { 0.1 * k } else { 0.05 };
                    if k > 0.9 {
                        Err(EvaluationFailure::new("fails above 0.9"))
                    } else {
                        Ok(Evaluation::with_std(vec![k, 2.0 * k], vec![s, s]))
                    }
                })
                .collect())
        }
    }

    #[test]
    fn a_batch_reuses_equal_variances_logarithms_without_changing_a_bit() {
        let observations = Observations {
            values: vec![0.3, 0.5],
            measurement_std: Some(vec![0.01, 0.02]),
        };
        for modelling_error in [None, Some(DEFAULT_MODELLING_ERROR_PRIOR)] {
            let errors = ErrorModel {
                measurement_error: true,
                computational_error: ComputationalError::Absolute,
                modelling_error,
            };
            let model = Varying(names(&["k"]), names(&["a", "b"]));
            let likelihood =
                PredictionErrorLikelihood::new(model, observations.clone(), errors).unwrap();
            let points: Vec<Vec<f64>> = (0..200)
                .map(|i| {
                    let k = i as f64 / 199.0;
                    if modelling_error.is_some() {
                        vec![k, 0.01 + 0.001 * (i % 7) as f64]
                    } else {
                        vec![k]
                    }
                })
                .collect();
            let batch = likelihood.log_likelihood_batch(&points).unwrap();
            for (p, got) in points.iter().zip(&batch) {
                let outcome = &likelihood
                    .model()
                    .evaluate_batch(&[p[..1].to_vec()])
                    .unwrap()[0];
                let sigma_m = p.get(1).copied().unwrap_or(0.0);
                let alone = likelihood.log_likelihood_of(outcome, sigma_m);
                match (got, alone) {
                    (Ok(a), Ok(b)) => assert_eq!(a.to_bits(), b.to_bits(), "at {p:?}"),
                    (Err(_), Err(_)) => {}
                    (a, b) => panic!("at {p:?}: {a:?} vs {b:?}"),
                }
            }
            assert!(batch.iter().filter(|v| v.is_err()).count() > 0);
        }
    }

    #[test]
    fn matches_the_formula_for_every_computational_convention() {
        let y = vec![0.3, 0.5];
        let sd = vec![0.01, 0.02];
        let q = vec![0.28, 0.55];
        let s = vec![0.004, 0.006];
        let sigma_m = 0.05;
        let obs = Observations {
            values: y.clone(),
            measurement_std: Some(sd.clone()),
        };
        for convention in ComputationalError::ALL {
            let l = PredictionErrorLikelihood::new(
                fixed(q.clone(), Some(s.clone())),
                obs.clone(),
                ErrorModel {
                    computational_error: convention,
                    ..Default::default()
                },
            )
            .unwrap();
            let got = l.log_likelihood_batch(&[vec![1.0, sigma_m]]).unwrap()[0]
                .clone()
                .unwrap();
            let mut expected = 0.0;
            for j in 0..2 {
                let c = match convention {
                    ComputationalError::Relative => (s[j] / q[j] * y[j]).powi(2),
                    ComputationalError::AbsoluteTimesData => (s[j] * y[j]).powi(2),
                    ComputationalError::Absolute => s[j] * s[j],
                    ComputationalError::None => 0.0,
                };
                let v = sd[j] * sd[j] + c + (sigma_m * y[j]).powi(2);
                expected +=
                    -0.5 * ((y[j] - q[j]).powi(2) / v + (2.0 * std::f64::consts::PI * v).ln());
            }
            assert!((got - expected).abs() < 1e-12, "{convention:?}");
            assert_eq!(
                ComputationalError::from_name(convention.name()),
                Some(convention)
            );
        }
    }

    #[test]
    fn measurement_error_can_be_switched_off_and_sigma_m_left_out() {
        let obs = Observations {
            values: vec![1.0],
            measurement_std: Some(vec![0.1]),
        };
        let l = PredictionErrorLikelihood::new(
            fixed(vec![1.2], None),
            obs.clone(),
            ErrorModel {
                measurement_error: true,
                computational_error: ComputationalError::None,
                modelling_error: None,
            },
        )
        .unwrap();
        assert_eq!(l.parameter_count(), 1);
        let v = l.log_likelihood_batch(&[vec![0.0]]).unwrap()[0]
            .clone()
            .unwrap();
        let expected = -0.5 * (0.04 / 0.01 + (2.0 * std::f64::consts::PI * 0.01).ln());
        assert!((v - expected).abs() < 1e-12);
        // no error term at all is rejected up front
        assert!(
            PredictionErrorLikelihood::new(
                fixed(vec![1.2], None),
                obs,
                ErrorModel {
                    measurement_error: false,
                    computational_error: ComputationalError::None,
                    modelling_error: None,
                },
            )
            .is_err()
        );
    }

    #[test]
    fn failures_and_zero_variances_are_point_failures() {
        let obs = Observations {
            values: vec![1.0],
            measurement_std: None,
        };
        let failing = Fixed(
            names(&["k"]),
            names(&["y"]),
            Err(EvaluationFailure::new("mesh broke")),
        );
        let l =
            PredictionErrorLikelihood::new(failing, obs.clone(), ErrorModel::default()).unwrap();
        let v = l.log_likelihood_batch(&[vec![0.0, 0.01]]).unwrap();
        assert_eq!(v[0].clone().unwrap_err().reason, "mesh broke");
        // relative computational error at q = 0 is undefined
        let l = PredictionErrorLikelihood::new(
            fixed(vec![0.0], Some(vec![0.1])),
            obs.clone(),
            ErrorModel::default(),
        )
        .unwrap();
        assert!(l.log_likelihood_batch(&[vec![0.0, 0.01]]).unwrap()[0].is_err());
        // σ_m = 0 and nothing else: zero variance
        let l = PredictionErrorLikelihood::new(
            fixed(vec![1.0], None),
            obs,
            ErrorModel {
                modelling_error: Some(Prior::Uniform(0.0, 0.1)),
                ..Default::default()
            },
        )
        .unwrap();
        assert!(l.log_likelihood_batch(&[vec![0.0, 0.0]]).unwrap()[0].is_err());
    }

    #[test]
    fn parameter_space_appends_sigma_m_and_checks_names() {
        let model = ExpressionModel::new(
            names(&["a", "b"]),
            &[("y1".into(), "a".into()), ("y2".into(), "a + b".into())],
        )
        .unwrap();
        let obs = Observations {
            values: vec![1.0, 2.0],
            measurement_std: None,
        };
        let l = PredictionErrorLikelihood::new(model, obs.clone(), ErrorModel::default()).unwrap();
        let space = ParameterSpace::new(vec![
            Parameter {
                name: "a".into(),
                prior: Prior::Uniform(0.0, 1.0),
            },
            Parameter {
                name: "b".into(),
                prior: Prior::Uniform(0.0, 1.0),
            },
        ])
        .unwrap();
        let full = l.parameter_space(&space).unwrap();
        assert_eq!(full.names(), names(&["a", "b", "sigma_m"]));
        let wrong = ParameterSpace::new(vec![Parameter {
            name: "a".into(),
            prior: Prior::Uniform(0.0, 1.0),
        }])
        .unwrap();
        assert!(l.parameter_space(&wrong).is_err());
        // output count must match the data
        let model = ExpressionModel::new(names(&["a"]), &[("y".into(), "a".into())]).unwrap();
        assert!(PredictionErrorLikelihood::new(model, obs, ErrorModel::default()).is_err());
        // bad data
        let bad = Observations {
            values: vec![f64::NAN],
            measurement_std: None,
        };
        assert!(bad.validate().is_err());
        let bad = Observations {
            values: vec![1.0],
            measurement_std: Some(vec![-1.0]),
        };
        assert!(bad.validate().is_err());
    }

    /// A model whose screen is affine: coefficients (a, b²) through fixed loadings, three
    /// outputs with fixed stds.
    struct Affine(
        Vec<String>,
        Vec<String>,
        iuq_core::affine_screen::AffineScreen,
    );
    impl Model for Affine {
        fn input_names(&self) -> &[String] {
            &self.0
        }
        fn output_names(&self) -> &[String] {
            &self.1
        }
        fn evaluate_batch(&self, points: &[Vec<f64>]) -> iuq_core::Result<Vec<Outcome>> {
            self.screening_batch(points).unwrap()
        }
        fn screening_batch(&self, points: &[Vec<f64>]) -> Option<iuq_core::Result<Vec<Outcome>>> {
            Some(Ok(points
                .iter()
                .map(|p| {
                    Ok(Evaluation::with_std(
                        self.2.outputs_of(&[p[0], p[1] * p[1]]),
                        self.2.stds.clone(),
                    ))
                })
                .collect()))
        }
        fn affine_screening(&self) -> Option<&dyn iuq_core::affine_screen::AffineScreening> {
            Some(self)
        }
    }
    impl iuq_core::affine_screen::AffineScreening for Affine {
        fn affine_screen(&self) -> iuq_core::affine_screen::AffineScreen {
            self.2.clone()
        }
        fn screening_coefficients(
            &self,
            points: &[Vec<f64>],
        ) -> iuq_core::Result<Vec<iuq_core::affine_screen::CoefficientOutcome>> {
            Ok(points.iter().map(|p| Ok(vec![p[0], p[1] * p[1]])).collect())
        }
    }

    /// The screen's likelihood through the quadratic form equals the term-by-term likelihood of
    /// the screen's outcomes (to 1e-12 relative) where the variances do not depend on θ, and is
    /// the term-by-term one itself where they do (the relative computational error).
    #[test]
    fn an_affine_screen_gives_the_screens_likelihood() {
        let model = || {
            Affine(
                names(&["a", "b"]),
                names(&["y0", "y1", "y2"]),
                iuq_core::affine_screen::AffineScreen {
                    offset: vec![1.0, 2.0, 0.5],
                    loadings: vec![1.0, 0.5, -0.3, 0.2, 1.5, 0.7],
                    stds: vec![0.05, 0.1, 0.02],
                },
            )
        };
        let observations = Observations {
            values: vec![1.3, 2.9, 0.4],
            measurement_std: Some(vec![0.1, 0.2, 0.15]),
        };
        let points: Vec<Vec<f64>> = (0..50)
            .map(|i| vec![-1.0 + 0.04 * i as f64, 0.5 + 0.02 * i as f64])
            .collect();
        for (convention, form) in [
            (ComputationalError::Absolute, true),
            (ComputationalError::None, true),
            (ComputationalError::Relative, false),
        ] {
            let errors = ErrorModel {
                measurement_error: true,
                computational_error: convention,
                modelling_error: None,
            };
            let likelihood =
                PredictionErrorLikelihood::new(model(), observations.clone(), errors).unwrap();
            let screened = likelihood
                .screening_log_likelihood_batch(&points)
                .unwrap()
                .unwrap();
            let terms = likelihood
                .of_outcomes(
                    &points,
                    likelihood.model().screening_batch(&points).unwrap(),
                )
                .unwrap();
            for (p, (a, b)) in points.iter().zip(screened.iter().zip(&terms)) {
                let (a, b) = (*a.as_ref().unwrap(), *b.as_ref().unwrap());
                if form {
                    assert!(
                        (a - b).abs() <= 1e-12 * b.abs().max(1.0),
                        "{convention:?} at {p:?}: {a} vs {b}"
                    );
                } else {
                    assert_eq!(a.to_bits(), b.to_bits(), "{convention:?} at {p:?}");
                }
            }
            assert_eq!(
                likelihood.screen.get().is_some_and(Option::is_some),
                form,
                "{convention:?}"
            );
        }
    }
}
