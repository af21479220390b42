//! A batch of new runs: greedy maximisation of the acquisition with "kriging believer" updates.
//!
//! The score of candidate x is a(x) = w(x) · Σ_t Var[ℓ_t(x)] over the likelihood terms t (one per
//! datum whose GP the run would inform), with w the candidate's weight: the probability that the
//! model answers there times (L(x)/L_max)², see [`crate::acquisition`]. After each pick s,
//! every GP is conditioned on a run at s as if it had returned the predicted mean (Ginsbourger,
//! Le Riche & Carraro 2010): the means stay, and the variances drop by
//! cov(x, s | picks so far)²/(var(s | picks so far) + σ²_noise), computed exactly from the
//! GP's posterior covariance by sequential conditioning. Candidates near a pick lose their
//! score, so a batch spreads over the region where the posterior is uncertain instead of
//! repeating one point; the batch is as good as its runs' values are predictable, and the next
//! round refits on what they really returned.

use iuq_gp::OutputPredictor;

use crate::acquisition::log_likelihood_variance;
use crate::error::{AdaptiveError, Result};

/// One Gaussian log-likelihood term that the surrogate predicts: the emulator of the model
/// output (its GP, or an output of a reduced basis) that is compared with `datum`.
#[derive(Clone)]
pub struct LikelihoodTerm<'a> {
    /// The emulator of the model output.
    pub gp: &'a dyn OutputPredictor,
    /// The datum the output is compared with.
    pub datum: f64,
    /// The total data variance s² (measurement plus modelling error) at each candidate: it
    /// depends on the candidate's modelling error σ_m when that is sampled.
    pub total_variance: Vec<f64>,
}

/// The chosen candidates.
#[derive(Debug, Clone, PartialEq)]
pub struct Selection {
    /// Indices of the chosen candidates, in the order they were picked.
    pub indices: Vec<usize>,
    /// The score of each pick when it was picked (after conditioning on the earlier picks).
    pub scores: Vec<f64>,
    /// Every candidate's score before any pick.
    pub initial_scores: Vec<f64>,
}

fn score(
    terms: &[LikelihoodTerm<'_>],
    means: &[Vec<f64>],
    variances: &[Vec<f64>],
    weights: &[f64],
    i: usize,
) -> f64 {
    let total: f64 = terms
        .iter()
        .enumerate()
        .map(|(t, term)| {
            log_likelihood_variance(
                term.datum,
                means[t][i],
                variances[t][i],
                term.total_variance[i],
            )
        })
        .sum();
    weights[i] * total
}

/// The covariance columns of the components several outputs share, computed for one pick.
struct ComponentColumns<'a> {
    components: &'a [iuq_gp::ComponentGp],
    columns: Vec<Vec<Vec<f64>>>,
}

/// Pick up to `batch` of `candidates` (original parameter units), greedily by score, stopping
/// early when the best remaining score is below `min_score` (the surrogate is already sure
/// enough everywhere else). `weights[i]` ≥ 0 multiplies candidate i's score: the probability
/// that the model gives an answer there times its likelihood relative to the best candidate's
/// ([`crate::acquisition::likelihood_weights`]). Ties go to the lower index, so the
/// selection is deterministic.
///
/// # Errors
/// Lengths that differ from the number of candidates, a negative `min_score`, or a GP that
/// cannot be evaluated at the candidates.
pub fn select_batch(
    terms: &[LikelihoodTerm<'_>],
    candidates: &[Vec<f64>],
    weights: &[f64],
    batch: usize,
    min_score: f64,
) -> Result<Selection> {
    let m = candidates.len();
    if weights.len() != m {
        return Err(AdaptiveError::LengthMismatch {
            what: "weights vs. candidates",
            expected: m,
            actual: weights.len(),
        });
    }
    if let Some(term) = terms.iter().find(|t| t.total_variance.len() != m) {
        return Err(AdaptiveError::LengthMismatch {
            what: "total variances vs. candidates",
            expected: m,
            actual: term.total_variance.len(),
        });
    }
    if min_score.is_nan() || min_score < 0.0 {
        return Err(AdaptiveError::InvalidParameter {
            what: "minimum score",
            reason: format!("{min_score} must be non-negative"),
        });
    }
    if m == 0 || terms.is_empty() {
        return Ok(Selection {
            indices: Vec::new(),
            scores: Vec::new(),
            initial_scores: vec![0.0; m],
        });
    }
    let mut means = Vec::with_capacity(terms.len());
    let mut variances = Vec::with_capacity(terms.len());
    let mut noise = Vec::with_capacity(terms.len());
    for term in terms {
        let prediction = term.gp.predict(candidates)?;
        // The next round's GP takes the run with its fitted noise σ² (plus the jitter), so the
        // run lowers its latent variance by cov²/(var + σ²), not as an exact value would: where
        // a model's output is rough on a scale the kernel cannot represent (the cell model's
        // elongation at 9.04 Pa, chaotic in its parameters) a run tells the latent mean little,
        // and the batch keeps its runs where the posterior needs that mean rather than spreading
        // them as if each settled its neighbourhood.
        noise.push(term.gp.run_noise_variance(&prediction));
        means.push(prediction.mean);
        variances.push(prediction.variance);
    }
    let initial_scores: Vec<f64> = (0..m)
        .map(|i| score(terms, &means, &variances, weights, i))
        .collect();
    // Per term: the conditioned covariance columns of the picks so far, and their denominators.
    let mut columns: Vec<Vec<Vec<f64>>> = vec![Vec::new(); terms.len()];
    let mut denominators: Vec<Vec<f64>> = vec![Vec::new(); terms.len()];
    greedy_selection(initial_scores, batch, min_score, |pick, chosen, scores| {
        let s = std::slice::from_ref(&candidates[pick]);
        // The covariance columns of the components that outputs share (a reduced basis), each
        // computed once per pick rather than once per output.
        let mut shared: Option<ComponentColumns<'_>> = None;
        for (t, term) in terms.iter().enumerate() {
            let covariance = match term.gp.shared_components() {
                Some(components) => {
                    let known = shared
                        .as_ref()
                        .is_some_and(|c| std::ptr::eq(c.components, components.components));
                    if !known {
                        let columns = components
                            .components
                            .iter()
                            .map(|gp| gp.posterior_covariance(candidates, s))
                            .collect::<iuq_gp::Result<Vec<_>>>()?;
                        shared = Some(ComponentColumns {
                            components: components.components,
                            columns,
                        });
                    }
                    let columns = shared.as_ref().map_or(&[][..], |c| c.columns.as_slice());
                    components.combine(columns)
                }
                None => term.gp.posterior_covariance(candidates, s)?,
            };
            let prior: Vec<f64> = covariance.into_iter().map(|row| row[0]).collect();
            // Condition on the earlier picks: c_k(x, s) = c(x, s) − Σ_j c_j(x)·c_j(s)/d_j.
            let mut column = prior;
            for (previous, d) in columns[t].iter().zip(&denominators[t]) {
                let at_pick = previous[pick] / d;
                for (c, p) in column.iter_mut().zip(previous) {
                    *c -= p * at_pick;
                }
            }
            let d = column[pick].max(0.0) + noise[t];
            if d > 0.0 {
                for (v, c) in variances[t].iter_mut().zip(&column) {
                    *v = (*v - c * c / d).max(0.0);
                }
                columns[t].push(column);
                denominators[t].push(d);
            } else {
                variances[t][pick] = 0.0;
            }
        }
        for i in 0..m {
            scores[i] = if chosen[i] {
                0.0
            } else {
                score(terms, &means, &variances, weights, i)
            };
        }
        Ok(())
    })
}

/// The greedy loop of both acquisitions: pick the best-scoring candidate not yet chosen (ties to
/// the lower index), while its score is positive and above `min_score`, `batch` at most; after
/// every pick but the last, `after_pick(pick, chosen, scores)` conditions on it and rescores.
pub(crate) fn greedy_selection(
    initial_scores: Vec<f64>,
    batch: usize,
    min_score: f64,
    mut after_pick: impl FnMut(usize, &[bool], &mut [f64]) -> Result<()>,
) -> Result<Selection> {
    let mut scores = initial_scores.clone();
    let mut chosen = vec![false; scores.len()];
    let mut selection = Selection {
        indices: Vec::new(),
        scores: Vec::new(),
        initial_scores,
    };
    while selection.indices.len() < batch {
        let mut best: Option<(usize, f64)> = None;
        for (i, &s) in scores.iter().enumerate() {
            if !chosen[i] && s.is_finite() && best.is_none_or(|(_, b)| s > b) {
                best = Some((i, s));
            }
        }
        let Some((pick, best_score)) = best else {
            break;
        };
        if best_score <= min_score || best_score <= 0.0 {
            break;
        }
        chosen[pick] = true;
        selection.indices.push(pick);
        selection.scores.push(best_score);
        if selection.indices.len() == batch {
            break;
        }
        after_pick(pick, &chosen, &mut scores)?;
    }
    Ok(selection)
}

#[cfg(test)]
mod tests {
    use super::*;
    use iuq_gp::{FitOptions, GaussianProcess};

    /// A GP of f(x) = sin(3x) from runs on [0, 0.3] ∪ [0.7, 1]: unsure in the gap.
    fn gap_gp() -> GaussianProcess {
        let x: Vec<Vec<f64>> = (0..8)
            .map(|i| {
                let t = i as f64 / 7.0;
                vec![if t < 0.5 { 0.6 * t } else { 0.4 + 0.6 * t }]
            })
            .collect();
        let y: Vec<f64> = x.iter().map(|p| (3.0 * p[0]).sin()).collect();
        GaussianProcess::fit(&x, &y, &FitOptions::default().check().unwrap()).unwrap()
    }

    #[test]
    fn picks_go_where_the_gp_is_unsure_and_spread_out() {
        let gp = gap_gp();
        // Candidates where a posterior for the datum sin(1.5) ± 0.3 lies: sin(3x) within 0.3 of
        // it, x ∈ [0.27, 0.78] (training runs at 0.26 and 0.74).
        let datum = (3.0f64 * 0.5).sin();
        let candidates: Vec<Vec<f64>> = (0..1001)
            .map(|i| vec![i as f64 / 1000.0])
            .filter(|x| ((3.0 * x[0]).sin() - datum).abs() < 0.3)
            .collect();
        let term = LikelihoodTerm {
            gp: &gp,
            datum,
            total_variance: vec![0.01; candidates.len()],
        };
        let p = vec![1.0; candidates.len()];
        let selection = select_batch(&[term], &candidates, &p, 3, 0.0).unwrap();
        assert_eq!(selection.indices.len(), 3);
        let xs: Vec<f64> = selection
            .indices
            .iter()
            .map(|&i| candidates[i][0])
            .collect();
        // The first two picks lie between runs (0.334 in the gap, 0.789 midway between the runs
        // at 0.743 and 0.829), away from each other.
        let runs = gp.training_inputs();
        for x in &xs[..2] {
            let nearest = runs
                .iter()
                .map(|r| (r[0] - x).abs())
                .fold(f64::MAX, f64::min);
            assert!(nearest > 0.035, "{xs:?}");
        }
        assert!((xs[0] - xs[1]).abs() >= 0.2, "{xs:?}");
        // Scores fall as the batch fills: each pick explains part of the others' uncertainty.
        assert!(selection.scores.windows(2).all(|w| w[1] <= w[0]));
    }

    /// A run of an output that scatters (40 runs of x + 0.3·N(0, 1): the GP's fitted noise is
    /// of that size, its latent variance between the runs much smaller) tells the latent mean
    /// little: the next round's GP takes it with that noise, so each pick's score stays above
    /// 80 % of its first value — the batch is as worth making as its first run. Taken as exact
    /// (the noise left out), the first picks would leave the fourth a quarter of its score.
    #[test]
    fn runs_of_a_scattering_output_barely_explain_each_other() {
        let mut state: u64 = 11;
        let mut normal = || {
            // Box–Muller on a small LCG: reproducible noise without another dependency.
            let mut uniform = || {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
            };
            let (a, b) = (uniform(), uniform());
            (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
        };
        let x: Vec<Vec<f64>> = (0..40).map(|i| vec![i as f64 / 39.0]).collect();
        let y: Vec<f64> = x.iter().map(|p| p[0] + 0.3 * normal()).collect();
        let gp = GaussianProcess::fit(&x, &y, &FitOptions::default().check().unwrap()).unwrap();
        let noise = gp.predict(&[vec![0.5]]).unwrap().noise_variance;
        assert!(
            noise > 0.05,
            "the fit sees the scatter: noise variance {noise}"
        );
        let candidates: Vec<Vec<f64>> = (0..21).map(|i| vec![0.4 + 0.01 * i as f64]).collect();
        let term = LikelihoodTerm {
            gp: &gp,
            datum: 0.8,
            total_variance: vec![0.1; candidates.len()],
        };
        let p = vec![1.0; candidates.len()];
        let selection = select_batch(&[term], &candidates, &p, 4, 0.0).unwrap();
        assert_eq!(selection.indices.len(), 4);
        for (&i, &score) in selection.indices.iter().zip(&selection.scores) {
            let first = selection.initial_scores[i];
            assert!(
                score > 0.8 * first,
                "score {score} after picks, {first} before"
            );
        }
    }

    #[test]
    fn no_pick_where_the_model_gives_no_answer() {
        let gp = gap_gp();
        let candidates: Vec<Vec<f64>> = (0..101).map(|i| vec![i as f64 / 100.0]).collect();
        let term = LikelihoodTerm {
            gp: &gp,
            datum: 1.0,
            total_variance: vec![0.01; candidates.len()],
        };
        // The model fails on [0.4, 0.6].
        let p: Vec<f64> = candidates
            .iter()
            .map(|c| {
                if (0.4..=0.6).contains(&c[0]) {
                    0.0
                } else {
                    1.0
                }
            })
            .collect();
        let selection = select_batch(&[term], &candidates, &p, 4, 0.0).unwrap();
        for &i in &selection.indices {
            assert!(!(0.4..=0.6).contains(&candidates[i][0]));
        }
    }

    #[test]
    fn a_high_minimum_score_stops_the_batch_and_sizes_are_checked() {
        let gp = gap_gp();
        let candidates: Vec<Vec<f64>> = (0..11).map(|i| vec![i as f64 / 10.0]).collect();
        let term = LikelihoodTerm {
            gp: &gp,
            datum: 0.5,
            total_variance: vec![1.0; candidates.len()],
        };
        let p = vec![1.0; candidates.len()];
        let none = select_batch(std::slice::from_ref(&term), &candidates, &p, 5, 1e6).unwrap();
        assert!(none.indices.is_empty());
        assert!(select_batch(std::slice::from_ref(&term), &candidates, &p[..3], 5, 0.0).is_err());
        assert!(select_batch(&[term], &candidates, &p, 5, -1.0).is_err());
    }
}

#[cfg(test)]
mod clustered {
    use super::*;
    use iuq_gp::{FitOptions, GaussianProcess};

    /// Candidates clustered far inside the GP's length scales (a sharp posterior): after a pick,
    /// its neighbours are explained and the next pick is not one of them.
    #[test]
    fn picks_in_a_tight_cluster_are_spread() {
        let x: Vec<Vec<f64>> = (0..10)
            .map(|i| {
                let t = i as f64 / 9.0;
                vec![0.05 + 0.3 * t, 60.0 + 40.0 * ((7.0 * t) % 1.0)]
            })
            .collect();
        let y: Vec<f64> = x
            .iter()
            .map(|p| 20.0 + (p[1] - 20.0) * (-p[0] * 3.0f64).exp())
            .collect();
        let gp = GaussianProcess::fit(&x, &y, &FitOptions::default().check().unwrap()).unwrap();
        let candidates: Vec<Vec<f64>> = (0..400)
            .map(|i| {
                let a = (i % 20) as f64 / 19.0 - 0.5;
                let b = (i / 20) as f64 / 19.0 - 0.5;
                vec![0.30 + 0.03 * a, 88.0 + 3.0 * b]
            })
            .collect();
        let datum = 20.0 + 68.0 * (-0.9f64).exp();
        let term = LikelihoodTerm {
            gp: &gp,
            datum,
            total_variance: vec![0.64; candidates.len()],
        };
        let w = vec![1.0; candidates.len()];
        let s = select_batch(&[term], &candidates, &w, 3, 0.0).unwrap();
        let picks: Vec<&Vec<f64>> = s.indices.iter().map(|&i| &candidates[i]).collect();
        for a in 0..picks.len() {
            for b in a + 1..picks.len() {
                let dk = (picks[a][0] - picks[b][0]) / 0.03;
                let dt = (picks[a][1] - picks[b][1]) / 3.0;
                assert!(dk.hypot(dt) > 0.2, "{picks:?}");
            }
        }
    }

    /// An output of a reduced basis hidden behind a predictor that does not say it shares the
    /// components: the batch computes its covariances output by output.
    struct Unshared<'a>(iuq_gp::ReducedBasisOutput<'a>);
    impl OutputPredictor for Unshared<'_> {
        fn predict(&self, points: &[Vec<f64>]) -> iuq_gp::Result<iuq_gp::Prediction> {
            self.0.predict(points)
        }
        fn posterior_covariance(
            &self,
            a: &[Vec<f64>],
            b: &[Vec<f64>],
        ) -> iuq_gp::Result<Vec<Vec<f64>>> {
            self.0.posterior_covariance(a, b)
        }
        fn run_noise_variance(&self, prediction: &iuq_gp::Prediction) -> f64 {
            self.0.run_noise_variance(prediction)
        }
    }

    /// The outputs of a reduced basis share their components' covariance columns: the batch
    /// picks the same candidates with the same scores, bit for bit, as computing every output's
    /// covariance on its own.
    #[test]
    fn shared_component_columns_pick_as_per_output_columns() {
        let xs: Vec<f64> = (0..30).map(|i| 0.2 * i as f64).collect();
        let runs: Vec<Vec<f64>> = (0..12)
            .map(|i| {
                let u = (i as f64 + 0.5) / 12.0;
                vec![1.0 + u, 0.2 + 0.6 * ((i * 5) % 12) as f64 / 12.0]
            })
            .collect();
        let curves: Vec<Vec<f64>> = runs
            .iter()
            .map(|t| xs.iter().map(|x| t[0] * (-t[1] * x).exp()).collect())
            .collect();
        let names = |p: &str, n: usize| (0..n).map(|j| format!("{p}{j}")).collect::<Vec<_>>();
        let basis = iuq_gp::ReducedBasis::fit(
            names("t", 2),
            names("y", 30),
            &runs,
            &curves,
            &iuq_gp::ReducedBasisOptions::default(),
        )
        .unwrap();
        let candidates: Vec<Vec<f64>> = (0..40)
            .map(|i| vec![1.0 + (i % 8) as f64 / 8.0, 0.2 + 0.6 * (i / 8) as f64 / 5.0])
            .collect();
        let outputs: Vec<iuq_gp::ReducedBasisOutput<'_>> = (0..30)
            .map(|output| iuq_gp::ReducedBasisOutput {
                basis: &basis,
                output,
            })
            .collect();
        let hidden: Vec<Unshared<'_>> = outputs.iter().map(|o| Unshared(*o)).collect();
        let data: Vec<f64> = xs.iter().map(|x| 1.5 * (-0.5 * x).exp()).collect();
        fn terms<'a>(
            gps: Vec<&'a dyn OutputPredictor>,
            data: &[f64],
            m: usize,
        ) -> Vec<LikelihoodTerm<'a>> {
            gps.into_iter()
                .zip(data)
                .map(|(gp, &datum)| LikelihoodTerm {
                    gp,
                    datum,
                    total_variance: vec![1e-4; m],
                })
                .collect()
        }
        let weights = vec![1.0; candidates.len()];
        let select = |gps: Vec<&dyn OutputPredictor>| {
            select_batch(
                &terms(gps, &data, candidates.len()),
                &candidates,
                &weights,
                4,
                0.0,
            )
            .unwrap()
        };
        let shared = select(outputs.iter().map(|o| o as &dyn OutputPredictor).collect());
        let alone = select(hidden.iter().map(|o| o as &dyn OutputPredictor).collect());
        assert_eq!(shared.indices.len(), 4);
        assert_eq!(shared.indices, alone.indices);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&shared.scores), bits(&alone.scores));
    }
}
