//! The fitted Gaussian process: training data, scalers, hyper-parameters and the Cholesky
//! factor of K, from which predictions, leave-one-out residuals and the likelihood follow.

use crate::bounds::Bounds;
use crate::data::{ColumnMajor, validate_points, validate_values};
use crate::diagnostics::{FitDiagnostics, FitWarning};
use crate::error::{GpError, Result};
use crate::forward_substitution::PackedFactor;
use crate::kernel::{Hyperparameters, Kernel, LengthScales, Variance};
use crate::log_marginal_likelihood::LmlWorkspace;
use crate::scaling::{InputScaling, OutputScaling};
use crate::validation::{LeaveOneOut, closed_form_leave_one_out};

/// A Gaussian process conditioned on training data, with the hyper-parameters fitted by
/// [`GaussianProcess::fit`] (or given, [`GaussianProcess::with_hyperparameters`]).
///
/// The GP works on scaled inputs x̃ and standardised outputs ỹ ([`InputScaling`],
/// [`OutputScaling`]); its hyper-parameters are in those units; predictions are returned in
/// the original units. It stores the factor L of K = c·R + (σ² + jitter)·I (packed for the
/// variance kernel) and α = K⁻¹ỹ.
#[derive(Debug, Clone)]
pub struct GaussianProcess {
    pub(crate) kernel: Kernel,
    pub(crate) hyperparameters: Hyperparameters,
    pub(crate) jitter: f64,
    pub(crate) input_scaling: InputScaling,
    pub(crate) output_scaling: OutputScaling,
    pub(crate) training_inputs: Vec<Vec<f64>>,
    pub(crate) training_outputs: Vec<f64>,
    /// Scaled training inputs, column-major.
    pub(crate) x: ColumnMajor,
    /// α = K⁻¹ỹ.
    pub(crate) alpha: Vec<f64>,
    /// L packed for the variance kernel of [`crate::forward_substitution`].
    pub(crate) packed_factor: PackedFactor,
    pub(crate) log_marginal_likelihood: f64,
    pub(crate) leave_one_out: LeaveOneOut,
    pub(crate) diagnostics: FitDiagnostics,
}

/// Training data validated, scaled and laid out for the kernel loops.
pub(crate) struct Prepared {
    pub input_scaling: InputScaling,
    pub output_scaling: OutputScaling,
    pub x: ColumnMajor,
    pub y: Vec<f64>,
    pub warnings: Vec<FitWarning>,
}

/// The covariance a GP is assembled with: the kernel variant, its hyper-parameters and the
/// jitter added to K's diagonal.
pub(crate) struct Covariance {
    pub kernel: Kernel,
    pub hyperparameters: Hyperparameters,
    pub jitter: f64,
}

/// Validates the training set and applies the scalings chosen in `options`.
pub(crate) fn prepare(
    x: &[Vec<f64>],
    y: &[f64],
    scale_inputs: bool,
    standardize_outputs: bool,
) -> Result<Prepared> {
    let d = validate_points(x, "training point", None)?;
    if x.len() < 2 {
        return Err(GpError::TooFewPoints {
            required: 2,
            actual: x.len(),
        });
    }
    if y.len() != x.len() {
        return Err(GpError::LengthMismatch {
            what: "outputs vs. training points",
            expected: x.len(),
            actual: y.len(),
        });
    }
    validate_values(y, "output")?;
    let input_scaling = if scale_inputs {
        InputScaling::unit_cube(x, d)
    } else {
        InputScaling::identity(d)
    };
    let output_scaling = if standardize_outputs {
        OutputScaling::standardize(y)
    } else {
        OutputScaling::identity()
    };
    prepare_with(x, y, input_scaling, output_scaling)
}

/// Lays out the training set under given scalings (validated data).
pub(crate) fn prepare_with(
    x: &[Vec<f64>],
    y: &[f64],
    input_scaling: InputScaling,
    output_scaling: OutputScaling,
) -> Result<Prepared> {
    let d = input_scaling.dimension();
    let mut warnings: Vec<FitWarning> = InputScaling::constant_inputs(x, d)
        .into_iter()
        .map(|input| FitWarning::ConstantInput { input })
        .collect();
    if y.iter().all(|v| *v == y[0]) {
        warnings.push(FitWarning::ConstantOutput);
    }
    let cols = ColumnMajor::from_rows(x, d, |k, v| input_scaling.apply(k, v));
    let ys: Vec<f64> = y.iter().map(|&v| output_scaling.apply(v)).collect();
    validate_values(&cols.values, "scaled training input")?;
    validate_values(&ys, "standardised output")?;
    Ok(Prepared {
        input_scaling,
        output_scaling,
        x: cols,
        y: ys,
        warnings,
    })
}

/// Warnings for hyper-parameters within 10 % of a bound (|ln(v/bound)| ≤ 0.1).
pub(crate) fn bound_warnings(
    kernel: &Kernel,
    h: &Hyperparameters,
    bounds: &Bounds,
) -> Vec<FitWarning> {
    let near = |v: f64, b: f64| (v.ln() - b.ln()).abs() <= 0.1;
    let mut out = Vec::new();
    for (k, &l) in h.length_scales.iter().enumerate() {
        let input = match kernel.length_scales {
            LengthScales::Ard => Some(k),
            LengthScales::Isotropic => None,
        };
        if near(l, bounds.length_scale[0]) {
            out.push(FitWarning::LengthScaleAtLowerBound { input, value: l });
        } else if near(l, bounds.length_scale[1]) {
            out.push(FitWarning::LengthScaleAtUpperBound { input, value: l });
        }
    }
    if kernel.signal_variance == Variance::Estimated
        && (near(h.signal_variance, bounds.signal_variance[0])
            || near(h.signal_variance, bounds.signal_variance[1]))
    {
        out.push(FitWarning::SignalVarianceAtBound {
            value: h.signal_variance,
        });
    }
    if kernel.noise_variance == Variance::Estimated
        && near(h.noise_variance, bounds.noise_variance[1])
    {
        out.push(FitWarning::NoiseAtUpperBound {
            value: h.noise_variance,
        });
    }
    out
}

impl GaussianProcess {
    /// Factorises K for `covariance` and builds the GP with its leave-one-out diagnostics
    /// (a Q² at or below `min_leave_one_out_q2` adds a warning).
    pub(crate) fn assemble(
        x: &[Vec<f64>],
        y: &[f64],
        prepared: Prepared,
        covariance: Covariance,
        min_leave_one_out_q2: f64,
        mut diagnostics: FitDiagnostics,
    ) -> Result<Self> {
        let Covariance {
            kernel,
            hyperparameters: h,
            jitter,
        } = covariance;
        let n = prepared.x.n;
        let mut ws = LmlWorkspace::new(n);
        ws.factorize(&prepared.x, &h, jitter)?;
        let lml = ws.solve(&prepared.y);
        if !lml.is_finite() {
            return Err(GpError::NotPositiveDefinite { pivot: 0 });
        }
        ws.invert();
        let leave_one_out = closed_form_leave_one_out(
            ws.alpha(),
            &ws.inverse_diagonal(),
            y,
            &prepared.output_scaling,
        );
        let mut warnings = prepared.warnings;
        warnings.append(&mut diagnostics.warnings);
        if let Some(q2) = leave_one_out.q2
            && q2 <= min_leave_one_out_q2
        {
            warnings.push(FitWarning::LowLeaveOneOutQ2 {
                q2,
                threshold: min_leave_one_out_q2,
            });
        }
        diagnostics.warnings = warnings;
        diagnostics.leave_one_out_q2 = leave_one_out.q2;
        let (cholesky, alpha) = ws.into_factor();
        let packed_factor = PackedFactor::new(&cholesky, n);
        Ok(Self {
            kernel,
            hyperparameters: h,
            jitter,
            input_scaling: prepared.input_scaling,
            output_scaling: prepared.output_scaling,
            training_inputs: x.to_vec(),
            training_outputs: y.to_vec(),
            x: prepared.x,
            alpha,
            packed_factor,
            log_marginal_likelihood: lml,
            leave_one_out,
            diagnostics,
        })
    }

    /// The kernel variant.
    pub fn kernel(&self) -> &Kernel {
        &self.kernel
    }

    /// The hyper-parameters (in the scaled units the GP works in).
    pub fn hyperparameters(&self) -> &Hyperparameters {
        &self.hyperparameters
    }

    /// θ = (ln c, ln l…, ln σ²) of the fitted hyper-parameters (fixed entries left out).
    pub fn theta(&self) -> Vec<f64> {
        self.kernel.theta(&self.hyperparameters)
    }

    /// The length scales in the units of the original inputs: l_k·r_k (r_k the input range
    /// used for scaling; the isotropic scale is expanded per input).
    pub fn length_scales_in_input_units(&self) -> Vec<f64> {
        (0..self.dimension())
            .map(|k| {
                let l = if self.hyperparameters.length_scales.len() == 1 {
                    self.hyperparameters.length_scales[0]
                } else {
                    self.hyperparameters.length_scales[k]
                };
                l * self.input_scaling.range[k]
            })
            .collect()
    }

    /// The jitter added to the diagonal of K.
    pub fn jitter(&self) -> f64 {
        self.jitter
    }

    /// The input scaling x̃ = (x − a)/r.
    pub fn input_scaling(&self) -> &InputScaling {
        &self.input_scaling
    }

    /// The output scaling ỹ = (y − ȳ)/s.
    pub fn output_scaling(&self) -> &OutputScaling {
        &self.output_scaling
    }

    /// The training inputs (original units).
    pub fn training_inputs(&self) -> &[Vec<f64>] {
        &self.training_inputs
    }

    /// The training outputs (original units).
    pub fn training_outputs(&self) -> &[f64] {
        &self.training_outputs
    }

    /// Number of inputs d.
    pub fn dimension(&self) -> usize {
        self.x.d
    }

    /// Number of training points n.
    pub fn n_training(&self) -> usize {
        self.x.n
    }

    /// The log marginal likelihood of the standardised data at the hyper-parameters (the
    /// quantity maximised; with standardisation on, it equals scikit-learn's
    /// `log_marginal_likelihood_value_` with `normalize_y=True`).
    pub fn log_marginal_likelihood(&self) -> f64 {
        self.log_marginal_likelihood
    }

    /// Warnings, leave-one-out Q2 and the multi-start runs.
    pub fn diagnostics(&self) -> &FitDiagnostics {
        &self.diagnostics
    }
}
