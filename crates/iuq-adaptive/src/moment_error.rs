//! How far the surrogate's own uncertainty can move the posterior moments: the convergence
//! measure that asks the question a user asks ("would more runs change my answer?").
//!
//! The surrogate posterior is the population {θ_i} with weights w_i (Σ w_i = 1) under the
//! log-likelihood ℓ = Σ_t ℓ_t of the GP means m_t. Were the model's true outputs m_t + δm_t,
//! with δm_t the GP's error, the log-likelihood would change by
//! δℓ(θ) ≈ Σ_t a_t(θ)·δm_t(θ), a_t = ∂ℓ_t/∂m_t = (y_t − m_t)/s_t² (first order, s_t² held fixed),
//! and reweighting the same population moves each moment to first order by its posterior
//! covariance with δℓ:
//!
//! δμ_k ≈ Σ_i w_i (θ_ik − μ_k) δℓ_i,  δσ_k ≈ Σ_i w_i ((θ_ik − μ_k)² − σ_k²) δℓ_i / (2σ_k),
//! δ ln Z ≈ Σ_i w_i δℓ_i.
//!
//! With δm_t ~ GP(0, C_t) (the latent posterior covariance of data point t's GP, independent
//! over t), each is a Gaussian of variance Σ_t gᵀ diag(a_t) C_t diag(a_t) g for its weight vector
//! g ([`linearised_moment_error`]). Where the GPs are unsure of a tail of the posterior that
//! linearisation fails (a sample of weight 10⁻⁴ whose log-likelihood may be 5 nats off moves
//! the first-order std by many posterior stds, the reweighting by a bounded amount), so the
//! engine draws instead: [`sampled_moment_error`] draws the GPs' errors jointly over the samples
//! and reweights the population by the exact change of each Gaussian likelihood term from the one
//! the population was sampled under to the one the model's true outputs would give,
//!
//! δℓ_t = [−(r_t − δm_t)²/(2s_t²) − ½ ln s_t²] − [−r_t²/(2c_t²) − ½ ln c_t²].
//!
//! s_t² is the term's variance once the GP's error is gone (data, modelling error and the runs'
//! own scatter); c_t² the variance the population was sampled under. A surrogate likelihood that
//! counts the GP's predictive std as computational error (the study's convention) has
//! c_t² = s_t² + (its share of) v_t, the GP's latent variance: where the GP is unsure the surrogate
//! likelihood is broad, and a tail sample it keeps for that reason loses weight when the truth is
//! known unless the truth fits the datum. Taking c_t = s_t there instead credits such a sample
//! with the whole misfit r²/(2s²) as if it had been sampled with it: on the healthy red-cell study
//! two posterior samples of weight 1/16000 at 4.24 Pa (GP mean 0.15 below the datum, latent std
//! 0.05–0.065, s 0.015–0.02) then gain 20–30 nats in a typical draw, and ε read 3.2 posterior stds
//! where the exact change gives 0.15. The moments' change over the draws is summarised by the
//! 68.3 % quantile of its absolute value, the std for a zero-centred Gaussian change that also
//! counts a change every draw makes alike (with c_t > s_t the tails lose weight in every draw):
//! where a tail the GPs are unsure of takes over the population in one draw of sixty, that draw
//! says where runs are needed (the acquisition goes there), not how far the moments typically
//! stand from the truth, and a std over the draws would follow it from round to round (0.09 to
//! 4.5 posterior stds on the TBHP red-cell study). Unlike the mean spread of the log-likelihood
//! ([`crate::convergence`]'s u), this measure does not count an error the surrogate makes alike
//! over the whole posterior (it moves ln Z, not the posterior), and it is in the units of the
//! convergence tolerance, posterior stds. It is the
//! form of the "posterior moment uncertainty due to the surrogate" that Sinsbeck and
//! Nowak (2017) and GPry (El Gammal et al. 2023) estimate by sampling GP realisations.

use iuq_core::weighted_statistics::quantile_sorted;

use crate::error::{AdaptiveError, Result};

/// P(|Z| ≤ 1) for a standard normal Z: the quantile of |change| that equals the std of a
/// zero-centred Gaussian change.
const ONE_SIGMA_COVERAGE: f64 = 0.682_689_492_137_085_9;

/// One data point's part: the residual y_t − m_t, the likelihood variance s_t² once the GP's
/// error is gone and the variance c_t² the population was sampled under, at each sample, and the
/// GP's latent posterior covariance C_t between the samples.
#[derive(Debug, Clone, Copy)]
pub struct MomentTerm<'a> {
    /// r_t(θ_i) = y_t − m_t(θ_i), one per sample.
    pub residual: &'a [f64],
    /// s_t²(θ_i), the term's total variance without the GP's latent variance, one per sample.
    pub variance: &'a [f64],
    /// c_t²(θ_i), the term's variance in the likelihood the samples were drawn from: `variance`
    /// plus whatever share of the GP's predictive variance that likelihood counts as
    /// computational error.
    pub sampled_variance: &'a [f64],
    /// C_t(θ_i, θ_j), a symmetric matrix over the samples.
    pub covariance: &'a [Vec<f64>],
}

/// The surrogate's first-order error on the posterior moments.
#[derive(Debug, Clone, PartialEq)]
pub struct MomentError {
    /// Std of δμ_k / σ_k per parameter.
    pub mean: Vec<f64>,
    /// Std of δσ_k / σ_k per parameter.
    pub std: Vec<f64>,
    /// Std of δ ln Z (nats).
    pub log_evidence: f64,
}

impl MomentError {
    /// The largest error of a mean or std over the parameters, in posterior stds (0 for none).
    pub fn largest(&self) -> f64 {
        self.mean
            .iter()
            .chain(&self.std)
            .map(|v| if v.is_nan() { f64::INFINITY } else { *v })
            .fold(0.0, f64::max)
    }
}

/// Checks the shapes and returns the normalised weights.
fn checked_weights(
    samples: &[Vec<f64>],
    weights: &[f64],
    terms: &[MomentTerm<'_>],
) -> Result<Vec<f64>> {
    checked_weights_with(samples, weights, terms, true)
}

/// [`checked_weights`], the terms' covariances checked only when `covariances` (a reduced
/// basis's terms carry none: its components do).
fn checked_weights_with(
    samples: &[Vec<f64>],
    weights: &[f64],
    terms: &[MomentTerm<'_>],
    covariances: bool,
) -> Result<Vec<f64>> {
    let n = samples.len();
    let Some(first) = samples.first() else {
        return Err(AdaptiveError::InvalidParameter {
            what: "posterior samples",
            reason: "none given".into(),
        });
    };
    let d = first.len();
    let mismatch = |what: &'static str, actual: usize, expected: usize| {
        Err(AdaptiveError::LengthMismatch {
            what,
            expected,
            actual,
        })
    };
    if weights.len() != n {
        return mismatch("weights vs. samples", weights.len(), n);
    }
    if let Some(s) = samples.iter().find(|s| s.len() != d) {
        return mismatch("sample dimensions", s.len(), d);
    }
    for t in terms {
        if t.residual.len() != n {
            return mismatch("residuals vs. samples", t.residual.len(), n);
        }
        if t.variance.len() != n {
            return mismatch("variances vs. samples", t.variance.len(), n);
        }
        if t.sampled_variance.len() != n {
            return mismatch("sampled variances vs. samples", t.sampled_variance.len(), n);
        }
        if !covariances {
            continue;
        }
        if t.covariance.len() != n {
            return mismatch("covariance rows vs. samples", t.covariance.len(), n);
        }
        if let Some(row) = t.covariance.iter().find(|r| r.len() != n) {
            return mismatch("covariance columns vs. samples", row.len(), n);
        }
    }
    let total: f64 = weights.iter().sum();
    if !(total.is_finite() && total > 0.0) {
        return Err(AdaptiveError::InvalidParameter {
            what: "sample weights",
            reason: format!("their sum {total} must be positive and finite"),
        });
    }
    Ok(weights.iter().map(|v| v / total).collect())
}

/// The first-order std of the posterior moments under the surrogate's error (see the module
/// doc), with s_t² held fixed at `variance` (the change c_t² → s_t² does not enter; see
/// [`sampled_moment_error`]): `samples[i]` is θ_i (every sampled parameter), `weights[i]` its weight (normalised
/// here), `terms` one per data point.
///
/// # Errors
/// No samples, lengths that do not match, or non-positive total weight.
pub fn linearised_moment_error(
    samples: &[Vec<f64>],
    weights: &[f64],
    terms: &[MomentTerm<'_>],
) -> Result<MomentError> {
    let w = checked_weights(samples, weights, terms)?;
    let d = samples[0].len();
    let sensitivities: Vec<Vec<f64>> = terms
        .iter()
        .map(|t| {
            t.residual
                .iter()
                .zip(t.variance)
                .map(|(r, s2)| r / s2)
                .collect()
        })
        .collect();
    // Var[Σ_i g_i δℓ_i] = Σ_t (g∘a_t)ᵀ C_t (g∘a_t).
    let variance = |g: &[f64]| -> f64 {
        terms
            .iter()
            .zip(&sensitivities)
            .map(|(t, a)| {
                let u: Vec<f64> = g.iter().zip(a).map(|(g, a)| g * a).collect();
                t.covariance
                    .iter()
                    .zip(&u)
                    .map(|(row, ui)| ui * row.iter().zip(&u).map(|(c, uj)| c * uj).sum::<f64>())
                    .sum::<f64>()
            })
            .sum::<f64>()
            .max(0.0)
    };
    let mut error = MomentError {
        mean: Vec::with_capacity(d),
        std: Vec::with_capacity(d),
        log_evidence: variance(&w).sqrt(),
    };
    for k in 0..d {
        let mean: f64 = samples.iter().zip(&w).map(|(s, w)| w * s[k]).sum();
        let var: f64 = samples
            .iter()
            .zip(&w)
            .map(|(s, w)| w * (s[k] - mean).powi(2))
            .sum();
        let sd = var.sqrt();
        if sd == 0.0 {
            error.mean.push(0.0);
            error.std.push(0.0);
            continue;
        }
        let g: Vec<f64> = samples
            .iter()
            .zip(&w)
            .map(|(s, w)| w * (s[k] - mean))
            .collect();
        let h: Vec<f64> = samples
            .iter()
            .zip(&w)
            .map(|(s, w)| w * ((s[k] - mean).powi(2) - var) / (2.0 * sd))
            .collect();
        error.mean.push(variance(&g).sqrt() / sd);
        error.std.push(variance(&h).sqrt() / sd);
    }
    Ok(error)
}

/// The weighted mean and std of every parameter and ln Σ_i w_i e^{δℓ_i} (w normalised).
fn reweighted_moments(samples: &[Vec<f64>], w: &[f64], dl: &[f64]) -> (Vec<f64>, Vec<f64>, f64) {
    let shift = dl.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let v: Vec<f64> = w
        .iter()
        .zip(dl)
        .map(|(w, d)| w * (d - shift).exp())
        .collect();
    let z: f64 = v.iter().sum();
    let d = samples[0].len();
    let mut mean = vec![0.0; d];
    let mut std = vec![0.0; d];
    for k in 0..d {
        let m = samples.iter().zip(&v).map(|(s, v)| v * s[k]).sum::<f64>() / z;
        let var = samples
            .iter()
            .zip(&v)
            .map(|(s, v)| v * (s[k] - m).powi(2))
            .sum::<f64>()
            / z;
        mean[k] = m;
        std[k] = var.sqrt();
    }
    (mean, std, z.ln() + shift)
}

/// The lower Cholesky factor of a covariance matrix, with the smallest jitter (relative to the
/// mean diagonal, from 10⁻¹⁰ up by factors of 100) that makes it positive definite: near-copies
/// among the samples make C singular.
fn cholesky_with_jitter(c: &[Vec<f64>]) -> Result<Vec<Vec<f64>>> {
    use faer::dyn_stack::{MemBuffer, MemStack};
    use faer::linalg::cholesky::llt;
    use faer::{MatMut, Par};
    let n = c.len();
    let mean_diagonal = (0..n).map(|i| c[i][i].max(0.0)).sum::<f64>() / n.max(1) as f64;
    if mean_diagonal == 0.0 {
        return Ok(vec![vec![0.0; n]; n]);
    }
    // faer's blocked factorisation, sequential (the result does not depend on the thread count).
    let mut buffer = MemBuffer::new(llt::factor::cholesky_in_place_scratch::<f64>(
        n,
        Par::Seq,
        Default::default(),
    ));
    let mut a = vec![0.0; n * n];
    let mut jitter = 1e-10 * mean_diagonal;
    for _ in 0..6 {
        for j in 0..n {
            for i in j..n {
                a[j * n + i] = c[i][j];
            }
            a[j * n + j] += jitter;
        }
        let factored = llt::factor::cholesky_in_place(
            MatMut::from_column_major_slice_mut(&mut a, n, n),
            Default::default(),
            Par::Seq,
            MemStack::new(&mut buffer),
            Default::default(),
        );
        let pivots_ok = (0..n).all(|i| {
            let v = a[i * n + i];
            v.is_finite() && v > 0.0
        });
        if factored.is_err() || !pivots_ok {
            jitter *= 100.0;
            continue;
        }
        return Ok((0..n)
            .map(|i| {
                let mut row = vec![0.0; n];
                for (j, v) in row.iter_mut().enumerate().take(i + 1) {
                    *v = a[j * n + i];
                }
                row
            })
            .collect());
    }
    Err(AdaptiveError::InvalidParameter {
        what: "GP covariance over the samples",
        reason: "not positive semi-definite even with a jitter of 10⁻² of its mean diagonal".into(),
    })
}

/// The typical change (68.3 % quantile of its absolute value) of the posterior moments over
/// `draws` joint draws of the GPs' errors (see the module doc), each population reweighted by the
/// exact change of the Gaussian likelihood terms from the sampled to the true one;
/// `seed` makes it reproducible. `samples[i]` is θ_i (every sampled parameter), `weights[i]` its
/// weight (normalised here), `terms` one per data point.
///
/// # Errors
/// No samples, lengths that do not match, non-positive total weight, fewer than 2 draws, or a
/// covariance that is not positive semi-definite.
pub fn sampled_moment_error(
    samples: &[Vec<f64>],
    weights: &[f64],
    terms: &[MomentTerm<'_>],
    draws: usize,
    seed: u64,
) -> Result<MomentError> {
    let w = checked_weights(samples, weights, terms)?;
    check_draws(draws)?;
    let factors = factorise(terms)?;
    Ok(drawn_moment_error(
        samples, &w, terms, &factors, draws, seed,
    ))
}

/// [`sampled_moment_error`] of all `terms` together and of each group of them (`groups`, ranges
/// of term indices), every one from the same `seed`, with each covariance factorised once: the
/// error of the whole surrogate and the part each run group's GPs leave alone.
///
/// # Errors
/// As [`sampled_moment_error`], or a group that is not a range of the terms.
pub fn sampled_moment_errors_by_group(
    samples: &[Vec<f64>],
    weights: &[f64],
    terms: &[MomentTerm<'_>],
    groups: &[std::ops::Range<usize>],
    draws: usize,
    seed: u64,
) -> Result<(MomentError, Vec<MomentError>)> {
    let w = checked_weights(samples, weights, terms)?;
    check_draws(draws)?;
    if let Some(g) = groups
        .iter()
        .find(|g| g.start > g.end || g.end > terms.len())
    {
        return Err(AdaptiveError::InvalidParameter {
            what: "group of likelihood terms",
            reason: format!("{g:?} is not a range of the {} terms", terms.len()),
        });
    }
    let factors = factorise(terms)?;
    let all = drawn_moment_error(samples, &w, terms, &factors, draws, seed);
    let per_group = groups
        .iter()
        .map(|g| {
            drawn_moment_error(
                samples,
                &w,
                &terms[g.clone()],
                &factors[g.clone()],
                draws,
                seed,
            )
        })
        .collect();
    Ok((all, per_group))
}

/// The error of a reduced-basis surrogate: the components' latent posterior covariances over
/// the samples (independent GPs) and, per likelihood term t, its loadings a_tk on them, so that
/// δm_t = Σ_k a_tk δc_k: the outputs' errors are correlated through the components.
#[derive(Debug, Clone, Copy)]
pub struct ComponentErrors<'a> {
    /// C_k(θ_i, θ_j), one symmetric matrix per component.
    pub covariances: &'a [Vec<Vec<f64>>],
    /// a_tk, one row per term (in the order of the terms), one column per component.
    pub loadings: &'a [Vec<f64>],
}

/// [`sampled_moment_errors_by_group`] for a reduced basis: the draws are of the components'
/// errors, mapped to the outputs by their loadings (the terms' own `covariance` is not read and
/// may be empty). Each component's covariance is factorised once; every group's error uses the
/// same draws of all components.
///
/// # Errors
/// As [`sampled_moment_errors_by_group`], or loadings that do not match the terms and
/// components.
pub fn sampled_moment_errors_by_group_from_components(
    samples: &[Vec<f64>],
    weights: &[f64],
    terms: &[MomentTerm<'_>],
    components: ComponentErrors<'_>,
    groups: &[std::ops::Range<usize>],
    draws: usize,
    seed: u64,
) -> Result<(MomentError, Vec<MomentError>)> {
    let w = checked_weights_with(samples, weights, terms, false)?;
    check_draws(draws)?;
    let n = samples.len();
    let q = components.covariances.len();
    if components.loadings.len() != terms.len() {
        return Err(AdaptiveError::LengthMismatch {
            what: "loadings vs. terms",
            expected: terms.len(),
            actual: components.loadings.len(),
        });
    }
    if let Some(row) = components.loadings.iter().find(|r| r.len() != q) {
        return Err(AdaptiveError::LengthMismatch {
            what: "loadings vs. components",
            expected: q,
            actual: row.len(),
        });
    }
    for c in components.covariances {
        if c.len() != n || c.iter().any(|r| r.len() != n) {
            return Err(AdaptiveError::LengthMismatch {
                what: "component covariance vs. samples",
                expected: n,
                actual: c.len(),
            });
        }
    }
    if let Some(g) = groups
        .iter()
        .find(|g| g.start > g.end || g.end > terms.len())
    {
        return Err(AdaptiveError::InvalidParameter {
            what: "group of likelihood terms",
            reason: format!("{g:?} is not a range of the {} terms", terms.len()),
        });
    }
    let factors = components
        .covariances
        .iter()
        .map(|c| cholesky_with_jitter(c))
        .collect::<Result<Vec<_>>>()?;
    // The components' draws are the same for the whole surrogate and for every group.
    let drawn = factor_draws(&factors, samples.len(), draws, seed);
    let all = drawn_component_error(samples, &w, terms, components.loadings, &drawn);
    let per_group = groups
        .iter()
        .map(|g| {
            drawn_component_error(
                samples,
                &w,
                &terms[g.clone()],
                &components.loadings[g.clone()],
                &drawn,
            )
        })
        .collect();
    Ok((all, per_group))
}

fn check_draws(draws: usize) -> Result<()> {
    if draws < 2 {
        return Err(AdaptiveError::InvalidParameter {
            what: "draws of the GP error",
            reason: format!("{draws} is fewer than 2"),
        });
    }
    Ok(())
}

/// The Cholesky factor of each term's covariance.
fn factorise(terms: &[MomentTerm<'_>]) -> Result<Vec<Vec<Vec<f64>>>> {
    terms
        .iter()
        .map(|t| cholesky_with_jitter(t.covariance))
        .collect()
}

/// The draws of [`sampled_moment_error`] with normalised weights `w` and the terms' factors.
fn drawn_moment_error(
    samples: &[Vec<f64>],
    w: &[f64],
    terms: &[MomentTerm<'_>],
    factors: &[Vec<Vec<f64>>],
    draws: usize,
    seed: u64,
) -> MomentError {
    let errors = factor_draws(factors, samples.len(), draws, seed);
    drawn_moment_error_with(samples, w, terms, &errors)
}

/// e[draw][source][i] = (L_source z)_i, z standard normal drawn in the order draw, source, i from
/// `seed`: the joint draws of independent Gaussian errors with the Cholesky factors `factors`
/// (rows; lower-triangular). All draws of one source are one sequential matrix product.
fn factor_draws(
    factors: &[Vec<Vec<f64>>],
    n: usize,
    draws: usize,
    seed: u64,
) -> Vec<Vec<Vec<f64>>> {
    use faer::linalg::matmul::matmul;
    use faer::{Accum, Mat, MatRef, Par};
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(seed);
    let sources = factors.len();
    // z of each source, n × draws, column-major.
    let mut z = vec![vec![0.0; n * draws]; sources];
    for d in 0..draws {
        for zs in z.iter_mut() {
            for v in &mut zs[d * n..(d + 1) * n] {
                *v = StandardNormal.sample(&mut rng);
            }
        }
    }
    let mut errors = vec![vec![vec![0.0; n]; sources]; draws];
    let mut product = Mat::<f64>::zeros(n, draws);
    for (source, l) in factors.iter().enumerate() {
        let lower = Mat::<f64>::from_fn(n, n, |i, j| if j <= i { l[i][j] } else { 0.0 });
        matmul(
            product.as_mut(),
            Accum::Replace,
            lower.as_ref(),
            MatRef::from_column_major_slice(&z[source], n, draws),
            1.0,
            Par::Seq,
        );
        for (d, per_draw) in errors.iter_mut().enumerate() {
            for (i, v) in per_draw[source].iter_mut().enumerate() {
                *v = product[(i, d)];
            }
        }
    }
    errors
}

/// The draws of a reduced basis: the components' errors `components[draw][k][i]`
/// ([`factor_draws`]), every output's error δm_t = Σ_k a_tk δc_k.
fn drawn_component_error(
    samples: &[Vec<f64>],
    w: &[f64],
    terms: &[MomentTerm<'_>],
    loadings: &[Vec<f64>],
    components: &[Vec<Vec<f64>>],
) -> MomentError {
    let n = samples.len();
    let errors: Vec<Vec<Vec<f64>>> = components
        .iter()
        .map(|dc| {
            loadings
                .iter()
                .map(|a| {
                    (0..n)
                        .map(|i| a.iter().zip(dc).map(|(a, c)| a * c[i]).sum())
                        .collect()
                })
                .collect()
        })
        .collect();
    drawn_moment_error_with(samples, w, terms, &errors)
}

/// The reweighting of every draw: `errors[draw][t][i]` is the error of term t at sample i in
/// one joint draw.
fn drawn_moment_error_with(
    samples: &[Vec<f64>],
    w: &[f64],
    terms: &[MomentTerm<'_>],
    errors: &[Vec<Vec<f64>>],
) -> MomentError {
    let n = samples.len();
    let d = samples[0].len();
    let draws = errors.len();
    let (mean0, std0, log_z0) = reweighted_moments(samples, w, &vec![0.0; n]);
    let mut changes: Vec<Vec<f64>> = Vec::with_capacity(draws);
    for dm in errors {
        let mut dl = vec![0.0; n];
        for (t, errors) in terms.iter().zip(dm) {
            for i in 0..n {
                let (r, s2, c2) = (t.residual[i], t.variance[i], t.sampled_variance[i]);
                let e = errors[i];
                dl[i] += r * r / (2.0 * c2) - (r - e) * (r - e) / (2.0 * s2) + 0.5 * (c2 / s2).ln();
            }
        }
        let (mean, std, log_z) = reweighted_moments(samples, w, &dl);
        let mut row = Vec::with_capacity(2 * d + 1);
        for k in 0..d {
            let scale = if std0[k] > 0.0 { std0[k] } else { 1.0 };
            row.push((mean[k] - mean0[k]) / scale);
            row.push((std[k] - std0[k]) / scale);
        }
        row.push(log_z - log_z0);
        changes.push(row);
    }
    let spread = |c: usize| -> f64 {
        let mut column: Vec<f64> = changes.iter().map(|r| r[c].abs()).collect();
        if column.iter().any(|v| v.is_nan()) {
            return f64::NAN;
        }
        column.sort_by(f64::total_cmp);
        quantile_sorted(&column, ONE_SIGMA_COVERAGE)
    };
    MomentError {
        mean: (0..d).map(|k| spread(2 * k)).collect(),
        std: (0..d).map(|k| spread(2 * k + 1)).collect(),
        log_evidence: spread(2 * d),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};
    use rand_xoshiro::Xoshiro256PlusPlus;

    /// The weighted mean and std of parameter 0 and ln Σ w_i e^{δℓ_i}.
    fn reweighted(samples: &[Vec<f64>], w: &[f64], dl: &[f64]) -> (f64, f64, f64) {
        let v: Vec<f64> = w.iter().zip(dl).map(|(w, d)| w * d.exp()).collect();
        let z: f64 = v.iter().sum();
        let mean = samples.iter().zip(&v).map(|(s, v)| v * s[0]).sum::<f64>() / z;
        let var = samples
            .iter()
            .zip(&v)
            .map(|(s, v)| v * (s[0] - mean).powi(2))
            .sum::<f64>()
            / z;
        (mean, var.sqrt(), z.ln())
    }

    /// The first-order stds against the moments of the reweighted population under 4000 draws
    /// of a small GP error (δℓ of std ≈ 0.02: the linear regime), with a smooth squared-
    /// exponential covariance over 60 samples of a skewed posterior. The Monte Carlo std of a
    /// std estimated from 4000 draws is 1.1 %; the second-order terms at this size are below
    /// 1 %: 4 % covers both.
    #[test]
    fn the_first_order_error_matches_reweighting_under_gp_draws() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(7);
        let n = 60;
        let samples: Vec<Vec<f64>> = (0..n)
            .map(|i| {
                let x = i as f64 / (n - 1) as f64;
                vec![x * x, 1.0 - x]
            })
            .collect();
        let w: Vec<f64> = (0..n).map(|i| 1.0 + (i % 7) as f64).collect();
        let total: f64 = w.iter().sum();
        let w: Vec<f64> = w.iter().map(|v| v / total).collect();
        // Residuals r_i with s² = 1: the sensitivity a_i = r_i.
        let a: Vec<f64> = (0..n).map(|i| 0.5 - i as f64 / n as f64).collect();
        let ones = vec![1.0; n];
        let scale = 1e-3;
        let cov: Vec<Vec<f64>> = (0..n)
            .map(|i| {
                (0..n)
                    .map(|j| {
                        let (x, y) = (samples[i][1], samples[j][1]);
                        scale * (-(x - y).powi(2) / (2.0 * 0.2 * 0.2)).exp()
                    })
                    .collect()
            })
            .collect();
        let term = MomentTerm {
            residual: &a,
            variance: &ones,
            sampled_variance: &ones,
            covariance: &cov,
        };
        let error = linearised_moment_error(&samples, &w, &[term]).unwrap();
        // The engine's sampled form agrees in this linear regime (within its own draw error: the
        // half 16–84 % range of 2000 Gaussian draws has a relative std of 2.2 %; 7 % is three).
        let sampled = sampled_moment_error(&samples, &w, &[term], 2000, 3).unwrap();
        for (a, b) in [
            (error.mean[0], sampled.mean[0]),
            (error.std[0], sampled.std[0]),
            (error.log_evidence, sampled.log_evidence),
        ] {
            assert!((a / b - 1.0).abs() < 0.07, "linearised {a} vs sampled {b}");
        }
        // Draws δm = L z with C = L Lᵀ (Cholesky with a little jitter).
        let mut l = vec![vec![0.0; n]; n];
        for i in 0..n {
            for j in 0..=i {
                let s: f64 = (0..j).map(|k| l[i][k] * l[j][k]).sum();
                if i == j {
                    l[i][i] = (cov[i][i] + 1e-12 - s).sqrt();
                } else {
                    l[i][j] = (cov[i][j] - s) / l[j][j];
                }
            }
        }
        let (m0, s0, _) = reweighted(&samples, &w, &vec![0.0; n]);
        let draws = 4000;
        let (mut dm, mut ds, mut dz) = (Vec::new(), Vec::new(), Vec::new());
        for _ in 0..draws {
            let z: Vec<f64> = (0..n).map(|_| StandardNormal.sample(&mut rng)).collect();
            let dl: Vec<f64> = (0..n)
                .map(|i| a[i] * (0..=i).map(|k| l[i][k] * z[k]).sum::<f64>())
                .collect();
            let (m, s, lz) = reweighted(&samples, &w, &dl);
            dm.push((m - m0) / s0);
            ds.push((s - s0) / s0);
            dz.push(lz);
        }
        let sd = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
        };
        for (formula, sampled) in [
            (error.mean[0], sd(&dm)),
            (error.std[0], sd(&ds)),
            (error.log_evidence, sd(&dz)),
        ] {
            assert!(
                (formula / sampled - 1.0).abs() < 0.04,
                "formula {formula} vs reweighting {sampled}"
            );
        }
        assert_eq!(
            error.largest(),
            error.mean[0]
                .max(error.std[0])
                .max(error.mean[1])
                .max(error.std[1])
        );
    }

    /// An error the surrogate makes alike everywhere (perfectly correlated, equal sensitivity)
    /// moves ln Z but not the posterior.
    #[test]
    fn a_uniform_error_moves_the_evidence_not_the_moments() {
        let samples: Vec<Vec<f64>> = (0..10).map(|i| vec![i as f64]).collect();
        let w = vec![1.0; 10];
        let a = vec![2.0; 10];
        let ones = vec![1.0; 10];
        let cov = vec![vec![0.01; 10]; 10];
        let term = MomentTerm {
            residual: &a,
            variance: &ones,
            sampled_variance: &ones,
            covariance: &cov,
        };
        let error = linearised_moment_error(&samples, &w, &[term]).unwrap();
        assert!(error.largest() < 1e-12, "{error:?}");
        assert!((error.log_evidence - 0.2).abs() < 1e-12);
        let sampled = sampled_moment_error(&samples, &w, &[term], 200, 1).unwrap();
        // Only the jitter that keeps the factorisation positive definite (10⁻¹⁰ of the
        // diagonal, so draws of 10⁻⁶ that differ per sample) moves the moments.
        assert!(sampled.largest() < 1e-5, "{sampled:?}");
    }

    /// A tail sample whose likelihood the GP is very unsure of: linearisation says the std could
    /// move by tens of posterior stds; reweighting the population cannot move the mean farther
    /// than the tail sample itself, (3 − 0.45)/0.29 ≈ 9 posterior stds, nor the std beyond that
    /// of an even split between the tail and the rest, (1.28 − 0.29)/0.29 ≈ 3.4.
    #[test]
    fn an_unsure_tail_is_bounded_when_drawn() {
        let mut samples: Vec<Vec<f64>> = (0..999).map(|i| vec![(i % 10) as f64 / 10.0]).collect();
        samples.push(vec![3.0]);
        let w = vec![1.0; 1000];
        let ones = vec![1.0; 1000];
        let mut residual = vec![0.0; 1000];
        residual[999] = -30.0;
        let mut cov = vec![vec![0.0; 1000]; 1000];
        for (i, row) in cov.iter_mut().enumerate() {
            row[i] = if i == 999 { 900.0 } else { 1e-6 };
        }
        let term = MomentTerm {
            residual: &residual,
            variance: &ones,
            sampled_variance: &ones,
            covariance: &cov,
        };
        let linear = linearised_moment_error(&samples, &w, &[term]).unwrap();
        let sampled = sampled_moment_error(&samples, &w, &[term], 400, 2).unwrap();
        assert!(linear.std[0] > 20.0, "{linear:?}");
        assert!(sampled.mean[0] < 9.0 && sampled.std[0] < 3.4, "{sampled:?}");
    }

    /// With no GP error left to draw (C = 0) the change is the deterministic one from the
    /// likelihood the population was sampled under (variance c² = s² + v(θ), broad where the GP
    /// was unsure) to the true one (s²): the measure is exactly the difference of the two
    /// posteriors' moments, computed here on the grid directly from their densities.
    #[test]
    fn a_broad_sampled_likelihood_is_replaced_by_the_true_one() {
        let n = 201;
        let samples: Vec<Vec<f64>> = (0..n).map(|i| vec![i as f64 / (n - 1) as f64]).collect();
        let residual: Vec<f64> = samples.iter().map(|s| -s[0]).collect();
        let s2 = vec![0.01; n];
        let c2: Vec<f64> = samples.iter().map(|s| 0.01 + 0.05 * s[0] * s[0]).collect();
        let density = |v: &[f64]| -> Vec<f64> {
            residual
                .iter()
                .zip(v)
                .map(|(r, v)| (-r * r / (2.0 * v)).exp() / v.sqrt())
                .collect()
        };
        let moments = |p: &[f64]| -> (f64, f64, f64) {
            let z: f64 = p.iter().sum();
            let m = samples.iter().zip(p).map(|(s, p)| p * s[0]).sum::<f64>() / z;
            let v = samples
                .iter()
                .zip(p)
                .map(|(s, p)| p * (s[0] - m).powi(2))
                .sum::<f64>()
                / z;
            (m, v.sqrt(), z)
        };
        let sampled = density(&c2);
        let truth = density(&s2);
        let (m_c, s_c, z_c) = moments(&sampled);
        let (m_s, s_s, z_s) = moments(&truth);
        let cov = vec![vec![0.0; n]; n];
        let term = MomentTerm {
            residual: &residual,
            variance: &s2,
            sampled_variance: &c2,
            covariance: &cov,
        };
        let error = sampled_moment_error(&samples, &sampled, &[term], 8, 1).unwrap();
        let expected = [
            (error.mean[0], (m_s - m_c).abs() / s_c),
            (error.std[0], (s_s - s_c).abs() / s_c),
            (error.log_evidence, (z_s / z_c).ln().abs()),
        ];
        for (got, want) in expected {
            assert!(want > 0.01, "the test needs a visible change: {want}");
            assert!((got - want).abs() < 1e-9 * want, "{got} vs {want}");
        }
    }

    /// The red-cell case that made the engine report ε ≈ 3 on a settled posterior: one tail
    /// sample of weight 10⁻³ where the GP's mean misses the datum by 0.15 with a latent std of
    /// 0.063, against s = 0.02. Sampled under c² = s² + v, its weight grows by at most
    /// e^{r²/(2c²)}·c/s ≈ 43 and only in the draws where the truth fits the datum; credited with
    /// the whole misfit r²/(2s²) = 28 nats (c = s) it takes over the population in most draws.
    #[test]
    fn a_tail_sampled_under_the_gp_variance_does_not_take_over() {
        let n = 1000;
        let mut samples: Vec<Vec<f64>> = (0..n - 1).map(|i| vec![(i % 10) as f64 / 10.0]).collect();
        samples.push(vec![3.0]);
        let w = vec![1.0; n];
        let mut residual = vec![0.0; n];
        residual[n - 1] = 0.15;
        let s2 = vec![0.0004; n];
        let mut c2 = s2.clone();
        c2[n - 1] += 0.004;
        let mut cov = vec![vec![0.0; n]; n];
        for (i, row) in cov.iter_mut().enumerate() {
            row[i] = if i == n - 1 { 0.004 } else { 1e-12 };
        }
        let exact = MomentTerm {
            residual: &residual,
            variance: &s2,
            sampled_variance: &c2,
            covariance: &cov,
        };
        let error = sampled_moment_error(&samples, &w, &[exact], 400, 5).unwrap();
        assert!(error.largest() < 0.05, "{error:?}");
        let fixed = MomentTerm {
            sampled_variance: &s2,
            ..exact
        };
        let error = sampled_moment_error(&samples, &w, &[fixed], 400, 5).unwrap();
        assert!(error.largest() > 1.0, "{error:?}");
    }

    /// The grouped form factorises each covariance once and gives, bit for bit, what separate
    /// calls give for all terms and for each group.
    #[test]
    fn the_factor_reconstructs_the_covariance_and_a_singular_one_gets_a_jitter() {
        let n = 40;
        let c: Vec<Vec<f64>> = (0..n)
            .map(|i| {
                (0..n)
                    .map(|j| (-((i as f64 - j as f64) / 6.0).powi(2)).exp())
                    .collect()
            })
            .collect();
        let l = cholesky_with_jitter(&c).unwrap();
        let mean_diagonal = 1.0;
        for i in 0..n {
            assert!(l[i][i + 1..].iter().all(|v| *v == 0.0));
            for j in 0..n {
                let product: f64 = (0..n).map(|k| l[i][k] * l[j][k]).sum();
                // A squared-exponential covariance this smooth is singular to rounding: the
                // factor is of C + jitter·I with a jitter of at most 1e-6 of its diagonal.
                assert!(
                    (product - c[i][j]).abs() < 1e-6 * mean_diagonal + 1e-12,
                    "({i}, {j}): {product} vs {}",
                    c[i][j]
                );
            }
        }
        // Rank one: only a jitter makes it factorisable.
        let rank_one = vec![vec![1.0; 5]; 5];
        let l = cholesky_with_jitter(&rank_one).unwrap();
        assert!(l.iter().enumerate().all(|(i, r)| r[i] > 0.0));
        // Indefinite (eigenvalues 4 and −2): no jitter up to its mean diagonal helps.
        assert!(cholesky_with_jitter(&[vec![1.0, 3.0], vec![3.0, 1.0]]).is_err());
    }

    #[test]
    fn grouped_errors_equal_separate_calls() {
        let n = 30;
        let samples: Vec<Vec<f64>> = (0..n).map(|i| vec![i as f64 / n as f64]).collect();
        let w = vec![1.0; n];
        let ones = vec![1.0; n];
        let residuals: Vec<Vec<f64>> = (0..3)
            .map(|t| {
                (0..n)
                    .map(|i| (i as f64 - 10.0 * t as f64) / n as f64)
                    .collect()
            })
            .collect();
        let cov: Vec<Vec<f64>> = (0..n)
            .map(|i| {
                (0..n)
                    .map(|j| 0.01 * (-((i as f64 - j as f64) / 8.0).powi(2)).exp())
                    .collect()
            })
            .collect();
        let terms: Vec<MomentTerm<'_>> = residuals
            .iter()
            .map(|r| MomentTerm {
                residual: r,
                variance: &ones,
                sampled_variance: &ones,
                covariance: &cov,
            })
            .collect();
        let groups = [0..1, 1..3];
        let (all, per_group) =
            sampled_moment_errors_by_group(&samples, &w, &terms, &groups, 20, 9).unwrap();
        assert_eq!(
            all,
            sampled_moment_error(&samples, &w, &terms, 20, 9).unwrap()
        );
        for (g, error) in groups.iter().zip(&per_group) {
            let alone = sampled_moment_error(&samples, &w, &terms[g.clone()], 20, 9).unwrap();
            assert_eq!(*error, alone);
        }
        let beyond = vec![std::ops::Range { start: 2, end: 4 }];
        assert!(sampled_moment_errors_by_group(&samples, &w, &terms, &beyond, 20, 9).is_err());

        // A reduced basis whose components are the outputs themselves (identity loadings) draws
        // the same errors as independent outputs: the same result, bit for bit, for all terms.
        let covariances = vec![cov.clone(), cov.clone(), cov.clone()];
        let identity: Vec<Vec<f64>> = (0..3)
            .map(|t| (0..3).map(|k| if t == k { 1.0 } else { 0.0 }).collect())
            .collect();
        let components = ComponentErrors {
            covariances: &covariances,
            loadings: &identity,
        };
        let (from_components, _) = sampled_moment_errors_by_group_from_components(
            &samples, &w, &terms, components, &groups, 20, 9,
        )
        .unwrap();
        assert_eq!(from_components, all);
        // One component shared by all three outputs: their errors move together, so the
        // moments move more than with independent errors of the same size.
        let shared = vec![cov.clone()];
        let ones_loading = vec![vec![1.0]; 3];
        let (together, _) = sampled_moment_errors_by_group_from_components(
            &samples,
            &w,
            &terms,
            ComponentErrors {
                covariances: &shared,
                loadings: &ones_loading,
            },
            &groups,
            20,
            9,
        )
        .unwrap();
        assert!(together.largest() > 0.0 && together.largest().is_finite());
        let bad = vec![vec![1.0, 0.0]; 3];
        assert!(
            sampled_moment_errors_by_group_from_components(
                &samples,
                &w,
                &terms,
                ComponentErrors {
                    covariances: &shared,
                    loadings: &bad,
                },
                &groups,
                20,
                9,
            )
            .is_err()
        );
    }

    #[test]
    fn mismatched_inputs_are_errors() {
        let samples = vec![vec![1.0], vec![2.0]];
        let cov = vec![vec![1.0, 0.0], vec![0.0, 1.0]];
        let term = MomentTerm {
            residual: &[1.0, 1.0],
            variance: &[1.0, 1.0],
            sampled_variance: &[1.0, 1.0],
            covariance: &cov,
        };
        assert!(linearised_moment_error(&[], &[], &[]).is_err());
        assert!(linearised_moment_error(&samples, &[1.0], &[term]).is_err());
        assert!(linearised_moment_error(&samples, &[0.0, 0.0], &[term]).is_err());
        assert!(sampled_moment_error(&samples, &[1.0, 1.0], &[term], 1, 0).is_err());
        let short = MomentTerm {
            residual: &[1.0],
            variance: &[1.0, 1.0],
            sampled_variance: &[1.0, 1.0],
            covariance: &cov,
        };
        assert!(sampled_moment_error(&samples, &[1.0, 1.0], &[short], 10, 0).is_err());
        let short_sampled = MomentTerm {
            residual: &[1.0, 1.0],
            variance: &[1.0, 1.0],
            sampled_variance: &[1.0],
            covariance: &cov,
        };
        assert!(sampled_moment_error(&samples, &[1.0, 1.0], &[short_sampled], 10, 0).is_err());
    }
}
