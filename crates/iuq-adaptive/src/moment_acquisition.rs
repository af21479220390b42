//! A batch of new runs chosen to shrink the surrogate's error on the posterior moments — the
//! quantity the stopping rule measures ([`crate::moment_error`]).
//!
//! To first order, were the model's outputs the GP means plus the GPs' error δm_t, a posterior
//! moment (mean or std of a parameter, in posterior stds) would move by
//!
//! δM = Σ_t Σ_i u_{M,t,i} δm_t(θ_i),  u_{M,t,i} = g_{M,i} · a_t(θ_i),  a_t = (y_t − m_t)/s_t²,
//!
//! over the candidates θ_i (the distinct posterior samples), with g_{M,i} = w_i (θ_ik − μ_k)/σ_k
//! for the mean of parameter k and w_i ((θ_ik − μ_k)² − σ_k²)/(2σ_k²) for its std, w_i the
//! posterior mass candidate i stands for (its copies in the population). With δm_t ~ GP(0, C_t),
//! Var\[δM\] = Σ_t u_{M,t}ᵀ C_t u_{M,t}. A run at θ_c, taken by the next round's GP with its noise
//! σ_t², lowers C_t by C_t[·, c] C_t[c, ·]/(C_t[c, c] + σ_t²), so it lowers Var\[δM\] by
//!
//! Δ_M(c) = Σ_t (u_{M,t}ᵀ C_t[·, c])² / (C_t[c, c] + σ_t²),
//!
//! and a candidate's score is p_answer(c) · Σ_M Δ_M(c): the reduction of the summed squared
//! first-order error of every posterior mean and std. The batch is picked greedily, each pick's
//! run conditioned into every C_t before the next (the kriging believer of [`crate::batch`]).
//!
//! Unlike the density-weighted variance of the log-likelihood ([`crate::acquisition`]) this
//! weighs a candidate by the posterior mass it stands for and by how far it sits from the
//! posterior mean, not by the square of its density: a tail the GPs are unsure of, which moves
//! the moments far more per unit of mass than the bulk, draws runs as the stopping rule sees it.
//! On the healthy red-cell study with HemoCell's orientation four samples of the 4.24 Pa tail
//! (Λ 13–14, kLink 30–34, GP latent std 0.05–0.065) held most of that stress's error (0.14
//! posterior stds with them, 0.055 without), and the density-weighted acquisition sent no run
//! there in rounds 5–22 (no 4.24 Pa run after round 4 has Λ > 12.2). It is the integrated
//! variance reduction of Sürer, Plumlee & Wild (2023) with the posterior moments, rather than the
//! likelihood, as the integrand's target.

use iuq_gp::OutputPredictor;

use crate::batch::{LikelihoodTerm, Selection, greedy_selection};
use crate::error::{AdaptiveError, Result};

/// The posterior's first-order moment sensitivities g_M (one row per moment: the mean, then the
/// std, of each parameter with a non-zero spread) over candidates `theta` of mass `mass`.
fn moment_sensitivities(theta: &[Vec<f64>], mass: &[f64]) -> Vec<Vec<f64>> {
    let total: f64 = mass.iter().sum();
    let w: Vec<f64> = mass.iter().map(|m| m / total).collect();
    let d = theta.first().map_or(0, Vec::len);
    let mut rows = Vec::with_capacity(2 * d);
    for k in 0..d {
        let mean: f64 = theta.iter().zip(&w).map(|(t, w)| w * t[k]).sum();
        let var: f64 = theta
            .iter()
            .zip(&w)
            .map(|(t, w)| w * (t[k] - mean).powi(2))
            .sum();
        if var.is_nan() || var <= 0.0 {
            continue;
        }
        let sd = var.sqrt();
        rows.push(
            theta
                .iter()
                .zip(&w)
                .map(|(t, w)| w * (t[k] - mean) / sd)
                .collect(),
        );
        rows.push(
            theta
                .iter()
                .zip(&w)
                .map(|(t, w)| w * ((t[k] - mean).powi(2) - var) / (2.0 * var))
                .collect(),
        );
    }
    rows
}

/// One likelihood term's state during the greedy selection: its latent covariance over the
/// candidates, conditioned on the picks so far, P = U C (one row per moment), and its noise.
struct TermState {
    covariance: Vec<Vec<f64>>,
    projected: Vec<Vec<f64>>,
    noise: f64,
}

impl TermState {
    /// The state of an emulated quantity f with latent covariance C over the candidates and
    /// first-order sensitivity `a` = ∂ℓ/∂f at each candidate.
    fn new(
        gp: &dyn OutputPredictor,
        a: &[f64],
        candidates: &[Vec<f64>],
        sensitivities: &[Vec<f64>],
    ) -> Result<Self> {
        let prediction = gp.predict(candidates)?;
        let noise = gp.run_noise_variance(&prediction);
        let covariance = gp.posterior_covariance(candidates, candidates)?;
        let m = candidates.len();
        let projected = sensitivities
            .iter()
            .map(|g| {
                let u: Vec<f64> = g.iter().zip(a).map(|(g, a)| g * a).collect();
                let mut p = vec![0.0; m];
                for (ui, row) in u.iter().zip(&covariance) {
                    if *ui != 0.0 {
                        for (pc, c) in p.iter_mut().zip(row) {
                            *pc += ui * c;
                        }
                    }
                }
                p
            })
            .collect();
        Ok(Self {
            covariance,
            projected,
            noise,
        })
    }

    /// Σ_M P[M][c]² / (C[c][c] + σ²).
    fn reduction(&self, c: usize) -> f64 {
        let d = self.covariance[c][c].max(0.0) + self.noise;
        if d.is_nan() || d <= 0.0 {
            return 0.0;
        }
        self.projected.iter().map(|p| p[c] * p[c]).sum::<f64>() / d
    }

    /// Condition on a run at candidate `c`.
    fn condition(&mut self, c: usize) {
        let d = self.covariance[c][c].max(0.0) + self.noise;
        if d.is_nan() || d <= 0.0 {
            return;
        }
        let column: Vec<f64> = self.covariance.iter().map(|row| row[c]).collect();
        for (row, ci) in self.covariance.iter_mut().zip(&column) {
            let f = ci / d;
            if f != 0.0 {
                for (v, cj) in row.iter_mut().zip(&column) {
                    *v -= f * cj;
                }
            }
        }
        for p in &mut self.projected {
            let f = p[c] / d;
            for (v, cj) in p.iter_mut().zip(&column) {
                *v -= f * cj;
            }
        }
    }
}

/// The checks both selections make of the candidates' data, and the empty selection when there
/// is nothing to choose (no candidate, no term, no mass).
fn empty_selection(
    m: usize,
    no_terms: bool,
    sampled: &[Vec<f64>],
    mass: &[f64],
    answer: &[f64],
    min_score: f64,
) -> Result<Option<Selection>> {
    for (what, len) in [
        ("sampled parameters vs. candidates", sampled.len()),
        ("masses vs. candidates", mass.len()),
        ("answer probabilities vs. candidates", answer.len()),
    ] {
        if len != m {
            return Err(AdaptiveError::LengthMismatch {
                what,
                expected: m,
                actual: len,
            });
        }
    }
    if let Some(bad) = mass.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
        return Err(AdaptiveError::InvalidParameter {
            what: "candidate mass",
            reason: format!("{bad} must be finite and non-negative"),
        });
    }
    if min_score.is_nan() || min_score < 0.0 {
        return Err(AdaptiveError::InvalidParameter {
            what: "minimum score",
            reason: format!("{min_score} must be non-negative"),
        });
    }
    let total_mass: f64 = mass.iter().sum();
    if m == 0 || no_terms || total_mass <= 0.0 {
        return Ok(Some(Selection {
            indices: Vec::new(),
            scores: Vec::new(),
            initial_scores: vec![0.0; m],
        }));
    }
    Ok(None)
}

/// Pick up to `batch` of `candidates` (the GPs' inputs, original units) greedily by the
/// reduction of the posterior moments' first-order error they bring (module docs), stopping when
/// the best remaining score is at most `min_score`. `sampled[i]` is candidate i's every sampled
/// parameter (θ, then σ_m where sampled: the moments whose error counts), `mass[i]` ≥ 0 the
/// posterior mass it stands for (its copies in the population), `answer[i]` the probability that
/// the model answers there. Ties go to the lower index, so the selection is deterministic.
///
/// # Errors
/// Lengths that differ from the number of candidates, a negative or non-finite mass, a
/// negative `min_score`, or a GP that cannot be evaluated at the candidates.
pub fn select_batch_for_moments(
    terms: &[LikelihoodTerm<'_>],
    candidates: &[Vec<f64>],
    sampled: &[Vec<f64>],
    mass: &[f64],
    answer: &[f64],
    batch: usize,
    min_score: f64,
) -> Result<Selection> {
    let m = candidates.len();
    if let Some(term) = terms.iter().find(|t| t.total_variance.len() != m) {
        return Err(AdaptiveError::LengthMismatch {
            what: "total variances vs. candidates",
            expected: m,
            actual: term.total_variance.len(),
        });
    }
    if let Some(empty) = empty_selection(m, terms.is_empty(), sampled, mass, answer, min_score)? {
        return Ok(empty);
    }
    let sources = terms
        .iter()
        .map(|term| {
            let prediction = term.gp.predict(candidates)?;
            let a = prediction
                .mean
                .iter()
                .zip(&term.total_variance)
                .map(|(m, s2)| {
                    if *s2 > 0.0 && s2.is_finite() {
                        (term.datum - m) / s2
                    } else {
                        0.0
                    }
                })
                .collect();
            Ok(SensitivityTerm { gp: term.gp, a })
        })
        .collect::<Result<Vec<_>>>()?;
    select_batch_for_moments_by_sensitivity(
        &sources, candidates, sampled, mass, answer, batch, min_score,
    )
}

/// One emulated quantity f (a model output, or a component of a reduced basis) and the
/// first-order sensitivity a = ∂ℓ/∂f of the log-likelihood to it at each candidate: for an
/// output, (y − m)/s²; for component k of a reduced basis, Σ_t a_t·a_tk over the outputs t it
/// loads on, so that δℓ = Σ_k a_k δc_k.
#[derive(Clone)]
pub struct SensitivityTerm<'a> {
    /// The emulator of f.
    pub gp: &'a dyn OutputPredictor,
    /// ∂ℓ/∂f at each candidate.
    pub a: Vec<f64>,
}

/// [`select_batch_for_moments`] on quantities given with their sensitivities: the same score
/// Σ_M Δ_M(c), each term's u_{M,i} = g_{M,i}·a_i.
///
/// # Errors
/// As [`select_batch_for_moments`].
pub fn select_batch_for_moments_by_sensitivity(
    terms: &[SensitivityTerm<'_>],
    candidates: &[Vec<f64>],
    sampled: &[Vec<f64>],
    mass: &[f64],
    answer: &[f64],
    batch: usize,
    min_score: f64,
) -> Result<Selection> {
    let m = candidates.len();
    if let Some(term) = terms.iter().find(|t| t.a.len() != m) {
        return Err(AdaptiveError::LengthMismatch {
            what: "sensitivities vs. candidates",
            expected: m,
            actual: term.a.len(),
        });
    }
    if let Some(empty) = empty_selection(m, terms.is_empty(), sampled, mass, answer, min_score)? {
        return Ok(empty);
    }
    let sensitivities = moment_sensitivities(sampled, mass);
    let mut states = terms
        .iter()
        .map(|t| TermState::new(t.gp, &t.a, candidates, &sensitivities))
        .collect::<Result<Vec<_>>>()?;
    let score = |states: &[TermState], c: usize| -> f64 {
        answer[c] * states.iter().map(|s| s.reduction(c)).sum::<f64>()
    };
    let initial_scores: Vec<f64> = (0..m).map(|c| score(&states, c)).collect();
    greedy_selection(initial_scores, batch, min_score, |pick, chosen, scores| {
        for state in &mut states {
            state.condition(pick);
        }
        for (c, s) in scores.iter_mut().enumerate() {
            *s = if chosen[c] { 0.0 } else { score(&states, c) };
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::batch::select_batch;
    use crate::moment_error::{MomentTerm, linearised_moment_error};
    use iuq_gp::{FitOptions, GaussianProcess};

    /// A GP of f(x) = x² from runs on [0.3, 0.7] (the posterior's bulk): sure there, unsure
    /// towards 1.
    fn bulk_gp() -> GaussianProcess {
        let x: Vec<Vec<f64>> = (0..7).map(|i| vec![0.3 + 0.4 * i as f64 / 6.0]).collect();
        let y: Vec<f64> = x.iter().map(|p| p[0] * p[0]).collect();
        GaussianProcess::fit(&x, &y, &FitOptions::default().check().unwrap()).unwrap()
    }

    /// Σ_M Var\[δM\] by the crate's independent first-order form, for latent covariance `c`.
    fn summed_variance(
        theta: &[Vec<f64>],
        mass: &[f64],
        datum: f64,
        mean: &[f64],
        s2: &[f64],
        c: &[Vec<f64>],
    ) -> f64 {
        let total: f64 = mass.iter().sum();
        let w: Vec<f64> = mass.iter().map(|m| m / total).collect();
        let r: Vec<f64> = mean.iter().map(|m| datum - m).collect();
        let e = linearised_moment_error(
            theta,
            &w,
            &[MomentTerm {
                residual: &r,
                variance: s2,
                sampled_variance: s2,
                covariance: c,
            }],
        )
        .unwrap();
        e.mean.iter().chain(&e.std).map(|v| v * v).sum()
    }

    #[test]
    fn a_picks_score_is_the_drop_of_the_first_order_moment_error() {
        let gp = bulk_gp();
        let theta: Vec<Vec<f64>> = (0..25).map(|i| vec![0.2 + 0.03 * i as f64]).collect();
        let mass: Vec<f64> = theta
            .iter()
            .map(|t| (-((t[0] - 0.5) / 0.15).powi(2)).exp())
            .collect();
        let datum = 0.3;
        let s2 = vec![0.002; theta.len()];
        let term = LikelihoodTerm {
            gp: &gp,
            datum,
            total_variance: s2.clone(),
        };
        let answer = vec![1.0; theta.len()];
        let selection =
            select_batch_for_moments(&[term], &theta, &theta, &mass, &answer, 2, 0.0).unwrap();
        let prediction = gp.predict(&theta).unwrap();
        let s = gp.output_scaling().std;
        let noise = prediction.noise_variance + gp.jitter() * s * s;
        let c = gp.posterior_covariance(&theta, &theta).unwrap();
        let before = summed_variance(&theta, &mass, datum, &prediction.mean, &s2, &c);
        // Conditioned on a run at the first pick, with the GP's noise.
        let p = selection.indices[0];
        let d = c[p][p] + noise;
        let after: Vec<Vec<f64>> = (0..theta.len())
            .map(|i| {
                (0..theta.len())
                    .map(|j| c[i][j] - c[i][p] * c[p][j] / d)
                    .collect()
            })
            .collect();
        let dropped = before - summed_variance(&theta, &mass, datum, &prediction.mean, &s2, &after);
        assert!(
            (selection.scores[0] - dropped).abs() <= 1e-9 * dropped.abs().max(1e-300),
            "{} vs {dropped}",
            selection.scores[0]
        );
        // The pick is the best of every candidate's own drop.
        for (i, score) in selection.initial_scores.iter().enumerate() {
            assert!(*score <= selection.scores[0] * (1.0 + 1e-12), "{i}");
        }
        // The second pick's score is the drop from the conditioned state.
        let q = selection.indices[1];
        assert_ne!(p, q);
        let d2 = after[q][q] + noise;
        let twice: Vec<Vec<f64>> = (0..theta.len())
            .map(|i| {
                (0..theta.len())
                    .map(|j| after[i][j] - after[i][q] * after[q][j] / d2)
                    .collect()
            })
            .collect();
        let dropped2 = summed_variance(&theta, &mass, datum, &prediction.mean, &s2, &after)
            - summed_variance(&theta, &mass, datum, &prediction.mean, &s2, &twice);
        assert!(
            (selection.scores[1] - dropped2).abs() <= 1e-8 * dropped2.abs(),
            "{} vs {dropped2}",
            selection.scores[1]
        );
    }

    #[test]
    fn an_unsure_tail_draws_the_run_that_the_density_weight_keeps_away() {
        let gp = bulk_gp();
        // The bulk: 40 samples in [0.35, 0.65], where the GP has runs; the tail: 2 samples at
        // 0.97 and 0.98, one mass each, where it has none and its mean is off the datum.
        let mut theta: Vec<Vec<f64>> = (0..40)
            .map(|i| vec![0.35 + 0.3 * i as f64 / 39.0])
            .collect();
        theta.push(vec![0.97]);
        theta.push(vec![0.98]);
        let mass = vec![1.0; theta.len()];
        let datum = 0.25;
        let s2 = vec![0.01; theta.len()];
        let term = || LikelihoodTerm {
            gp: &gp,
            datum,
            total_variance: s2.clone(),
        };
        let answer = vec![1.0; theta.len()];
        let moments =
            select_batch_for_moments(&[term()], &theta, &theta, &mass, &answer, 1, 0.0).unwrap();
        assert!(moments.indices[0] >= 40, "{:?}", moments.indices);
        // The density-weighted acquisition: the tail's likelihood is e^{-(0.25-0.95)²/0.02}
        // of the bulk's, squared.
        let prediction = gp.predict(&theta).unwrap();
        let log_density: Vec<f64> = prediction
            .mean
            .iter()
            .map(|m| -(datum - m).powi(2) / (2.0 * 0.01))
            .collect();
        let weights = crate::acquisition::likelihood_weights(&log_density, &answer);
        let density = select_batch(&[term()], &theta, &weights, 1, 0.0).unwrap();
        assert!(density.indices[0] < 40, "{:?}", density.indices);
    }

    #[test]
    fn mismatched_inputs_are_errors() {
        let gp = bulk_gp();
        let theta = vec![vec![0.5], vec![0.6]];
        let term = LikelihoodTerm {
            gp: &gp,
            datum: 0.3,
            total_variance: vec![0.01; 2],
        };
        let ok = [1.0, 1.0];
        assert!(
            select_batch_for_moments(
                std::slice::from_ref(&term),
                &theta,
                &theta,
                &ok[..1],
                &ok,
                1,
                0.0
            )
            .is_err()
        );
        assert!(
            select_batch_for_moments(
                std::slice::from_ref(&term),
                &theta,
                &theta,
                &[1.0, -1.0],
                &ok,
                1,
                0.0
            )
            .is_err()
        );
        assert!(select_batch_for_moments(&[term], &theta, &theta, &ok, &ok, 1, -1.0).is_err());
    }
}
