//! Both batches of a corrected model posterior weighed as one sample: the first batch drawn from
//! the surrogate's posterior q, the second from the corrected surrogate's q_c ∝ q·e^g.
//!
//! Their union is a sample of the mixture ½q + ½q_c, and the deterministic-mixture (balance
//! heuristic) weights of multiple importance sampling (Veach & Guibas 1995; Owen & Zhou 2000)
//!
//! w = L_m·π / (½q + ½q_c) ∝ exp(r − ln(½(1 + e^{g − ln c}))), r = ℓ_m − ℓ_s, c = Z_c/Z_s,
//!
//! make it one importance sample of the model's posterior: no run is wasted, and the weights'
//! second moment is never more than twice what the better of the two proposals alone would give
//! — a correction that overshot (too narrow along some axis, so that its own batch's weights
//! have a heavy tail) is covered by the first batch there, and the first batch's few heavy
//! weights (what called for the correction) are shared with the second. c is estimated by
//! bridge sampling between the two surrogate populations (Meng & Wong 1996; no model runs).
//! A noisy model's estimate is always this ([`crate::pseudo_marginal`]); a reproducible
//! model's is this when its k̂ holds, and the stages from the corrected batch otherwise
//! ([`crate::model_posterior`](mod@crate::model_posterior)).

use crate::model_posterior::members::{Members, log_ratios};
use crate::pareto_smoothing::log_sum_exp;

/// ln(e^a + e^b) without overflow.
pub(crate) fn log_add_exp(a: f64, b: f64) -> f64 {
    let m = a.max(b);
    if m == f64::NEG_INFINITY {
        return m;
    }
    m + ((a - m).exp() + (b - m).exp()).ln()
}

/// ln(Z_c/Z_s) for q_c ∝ q·e^g from g at draws of q (`on_q`) and of q_c (`on_corrected`): the
/// optimal bridge sampling estimate of Meng & Wong (1996, eq. 4.1), iterated from the
/// importance estimate ln mean_q e^g to a fixed point. Unlike that importance estimate, which
/// samples q_c from the narrower q exactly where a correction widens it (its variance is
/// infinite once an axis of q_c is √2 times q's), the bridge weighs both sides.
pub(crate) fn log_normalising_ratio(on_q: &[f64], on_corrected: &[f64]) -> f64 {
    let (n_q, n_c) = (on_q.len() as f64, on_corrected.len() as f64);
    let (ln_s_c, ln_s_q) = ((n_c / (n_q + n_c)).ln(), (n_q / (n_q + n_c)).ln());
    let log_mean = |values: &mut dyn Iterator<Item = f64>, n: f64| -> f64 {
        log_sum_exp(&values.collect::<Vec<f64>>()) - n.ln()
    };
    let mut rho = log_mean(&mut on_q.iter().copied(), n_q);
    for _ in 0..1000 {
        // (1/n_q) Σ_q e^g/(s_c e^g + s_q e^ρ) over (1/n_c) Σ_c 1/(s_c e^g + s_q e^ρ).
        let numerator = log_mean(
            &mut on_q
                .iter()
                .map(|&g| g - log_add_exp(ln_s_c + g, ln_s_q + rho)),
            n_q,
        );
        let denominator = log_mean(
            &mut on_corrected
                .iter()
                .map(|&g| -log_add_exp(ln_s_c + g, ln_s_q + rho)),
            n_c,
        );
        let next = numerator - denominator;
        let converged = (next - rho).abs() < 1e-12;
        rho = next;
        if converged || !rho.is_finite() {
            break;
        }
    }
    rho
}

/// The first batch (from q) followed by the second (from q_c), `surrogate` the uncorrected ℓ_s
/// of both, and their mixture log-weights r − ln(½(1 + e^{g − ln c})) (module docs); `g` is
/// called with a member's θ and its uncorrected ℓ_s (a tempered q_c's g is a function of ℓ_s,
/// [`crate::defensive_tempering`]).
pub(crate) fn mixture_of_batches(
    mut first: Members,
    second: Members,
    g: &dyn Fn(&[f64], f64, f64) -> f64,
    log_c: f64,
) -> (Members, Vec<f64>) {
    // The even mixture ½q + ½q_c, and the spread ratio of both batches, need equal batches.
    debug_assert_eq!(first.theta.len(), second.theta.len());
    first.theta.extend(second.theta);
    first.surrogate.extend(second.surrogate);
    first.model.extend(second.model);
    first.prior.extend(second.prior);
    let raw = log_ratios(&first.model, &first.surrogate)
        .into_iter()
        .zip(first.theta.iter().zip(&first.surrogate).zip(&first.prior))
        .map(|(r, ((x, &ls), &lp))| r - (log_add_exp(0.0, g(x, ls, lp) - log_c) - 2f64.ln()))
        .collect();
    (first, raw)
}

#[cfg(test)]
mod tests {
    use super::*;
    use iuq_core::random::stream;
    use rand_distr::{Distribution, StandardNormal};

    #[test]
    fn bridge_sampling_gives_the_ratio_of_normalising_constants() {
        // q = N(0, 1), q_c ∝ q·e^g with g = x²·(1/2 − 1/(2·2.25)): q_c = N(0, 1.5²) up to its
        // constant, Z_c/Z_s = 1.5. The importance estimate from q alone has infinite variance
        // here (q_c's std is above √2 times q's); the bridge is within 0.02 with 20,000 draws
        // each.
        let a = 0.5 - 1.0 / (2.0 * 2.25);
        let mut rng = stream(1, 9, 0);
        let on_q: Vec<f64> = (0..20_000)
            .map(|_| {
                let z: f64 = StandardNormal.sample(&mut rng);
                a * z * z
            })
            .collect();
        let on_corrected: Vec<f64> = (0..20_000)
            .map(|_| {
                let z: f64 = StandardNormal.sample(&mut rng);
                a * (1.5 * z).powi(2)
            })
            .collect();
        let rho = log_normalising_ratio(&on_q, &on_corrected);
        assert!((rho - 1.5f64.ln()).abs() < 0.02, "{rho}");
    }

    #[test]
    fn the_mixture_weights_are_the_target_over_the_mixture_density() {
        // q = N(0, 1), q_c = N(0, 1.5²) (g as above, c = 1.5), target ∝ N(0, 1.2²) with
        // ℓ_m − ℓ_s = ln N(x; 0, 1.2²) − ln N(x; 0, 1): exp(raw) must equal
        // N(x; 0, 1.2²)/(½N(x; 0, 1) + ½N(x; 0, 1.5²)) up to one constant.
        let a = 0.5 - 1.0 / (2.0 * 2.25);
        let g = |x: &[f64], _: f64, _: f64| a * x[0] * x[0];
        let normal = |x: f64, s: f64| (-0.5 * (x / s).powi(2)).exp() / s;
        let points = [-2.0, -0.5, 0.0, 0.7, 1.9, 3.1];
        let members = |xs: &[f64]| Members {
            theta: xs.iter().map(|&x| vec![x]).collect(),
            surrogate: xs.iter().map(|&x| normal(x, 1.0).ln()).collect(),
            model: xs.iter().map(|&x| normal(x, 1.2).ln()).collect(),
            prior: vec![0.0; xs.len()],
        };
        let (all, raw) = mixture_of_batches(
            members(&points[..3]),
            members(&points[3..]),
            &g,
            1.5f64.ln(),
        );
        assert_eq!(all.theta.len(), 6);
        let ratio: Vec<f64> = points
            .iter()
            .zip(&raw)
            .map(|(&x, r)| {
                let exact = normal(x, 1.2) / (0.5 * normal(x, 1.0) + 0.5 * normal(x, 1.5));
                r.exp() / exact
            })
            .collect();
        for v in &ratio {
            assert!((v / ratio[0] - 1.0).abs() < 1e-12, "{ratio:?}");
        }
    }
}
