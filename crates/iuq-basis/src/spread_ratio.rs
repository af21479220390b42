//! How much wider an importance step's target is than its proposal, parameter by parameter.
//!
//! Importance weights from a proposal narrower than the target have a tail that k̂ of a few
//! hundred draws underestimates: for Gaussians whose stds stand at σ_q = σ_p/ρ the weights
//! behave as exp(a·z²) with tail index k = 1 − 1/ρ² (0.75 for a proposal half as wide), and
//! such a tail decays so slowly that k̂ at 300 draws often lies far below its threshold while
//! the weighted std comes out 20–30 % narrow (docs/methods.md §5b, "What the certificate
//! covers"). The weighted std itself shows the narrowness that k̂ misses: it exceeds the
//! proposal's std (the members' unweighted std, an equally weighted sample of the proposal) by
//! the factor the weights can reach, understated but plainly above 1 (1.4 where ρ = 2, 300
//! members). With a proposal as wide as the target, or shifted but as wide, the ratio stays at
//! 1 within its sampling spread (about 0.05 at 300 members); with a wider one, below 1.
//!
//! A mixture of batches (a first batch and a corrected one, weighed together) has the tails of
//! its widest component, so its spread in a parameter is the largest of its batches' stds: a
//! narrow first batch beside a corrected batch as wide as the target is not a narrow proposal.

/// The spread ratio above which a step's target counts as wider than its proposal:
/// [`crate::model_posterior`](mod@crate::model_posterior) then corrects the surrogate (for a
/// reproducible model or a noisy one), does not weigh both batches as the estimate, and halves
/// a stage's step to β = 1 (shorter steps are followed by a bridge), as where k̂ does not hold. At 1.2 a Gaussian target is
/// at least ρ ≈ 1.2 times as wide (k ≥ 0.3; the estimate understates ρ), four times the
/// ratio's sampling spread at 300 members above 1.
pub const WIDER_THAN_PROPOSAL: f64 = 1.2;

/// The parameter whose weighted std (weights `exp(log_weights)`, normalised) most exceeds the
/// proposal's std, and that ratio. `points` are `batches` consecutive batches of equal size,
/// each a sample of one component of the proposal; the proposal's std of a parameter is the
/// largest of the batches' unweighted stds. `None` for fewer than two points a batch, a size not
/// divisible into `batches`, no finite weight, or no parameter that varies over the points.
pub fn widest_spread_ratio(
    points: &[Vec<f64>],
    log_weights: &[f64],
    batches: usize,
) -> Option<(usize, f64)> {
    let d = points.first()?.len();
    if batches == 0
        || points.len() % batches != 0
        || points.len() / batches < 2
        || log_weights.len() != points.len()
    {
        return None;
    }
    let size = points.len() / batches;
    let w = crate::pareto_smoothing::normalised_weights(log_weights);
    let total: f64 = w.iter().sum();
    if total == 0.0 {
        return None;
    }
    let variance = |batch: &[Vec<f64>], k: usize| {
        let n = batch.len() as f64;
        let mean = batch.iter().map(|p| p[k]).sum::<f64>() / n;
        batch.iter().map(|p| (p[k] - mean).powi(2)).sum::<f64>() / n
    };
    (0..d)
        .filter_map(|k| {
            let spread = points
                .chunks(size)
                .map(|batch| variance(batch, k))
                .fold(0.0, f64::max);
            let weighted_mean = points.iter().zip(&w).map(|(p, w)| w * p[k]).sum::<f64>() / total;
            let weighted = points
                .iter()
                .zip(&w)
                .map(|(p, w)| w * (p[k] - weighted_mean).powi(2))
                .sum::<f64>()
                / total;
            (spread > 0.0).then(|| (k, (weighted / spread).sqrt()))
        })
        .max_by(|a, b| a.1.total_cmp(&b.1))
}

/// Whether the step whose log-weights over `points` (`batches` batches, as for
/// [`widest_spread_ratio`]) are `log_weights` keeps its target within [`WIDER_THAN_PROPOSAL`] of
/// the proposal's spread in every parameter (also when the ratio cannot be computed: nothing to
/// judge).
pub fn within_proposal_spread(points: &[Vec<f64>], log_weights: &[f64], batches: usize) -> bool {
    widest_spread_ratio(points, log_weights, batches)
        .is_none_or(|(_, ratio)| ratio <= WIDER_THAN_PROPOSAL)
}

#[cfg(test)]
mod tests {
    use super::*;
    use iuq_core::random::stream;
    use rand_distr::{Distribution, StandardNormal};

    fn draws(n: usize, std: &[f64], seed: u64) -> Vec<Vec<f64>> {
        let mut rng = stream(seed, 1, 0);
        (0..n)
            .map(|_| {
                std.iter()
                    .map(|s| {
                        let z: f64 = StandardNormal.sample(&mut rng);
                        s * z
                    })
                    .collect::<Vec<f64>>()
            })
            .collect()
    }

    /// ln N(x; shift, 1) − ln N(x; 0, σ_q²) per parameter, summed.
    fn log_weights(points: &[Vec<f64>], std: &[f64], shift: f64) -> Vec<f64> {
        points
            .iter()
            .map(|p| {
                p.iter()
                    .zip(std)
                    .map(|(x, s)| -0.5 * (x - shift).powi(2) + 0.5 * (x / s).powi(2))
                    .sum()
            })
            .collect()
    }

    #[test]
    fn a_proposal_half_as_wide_is_flagged_and_a_wider_or_shifted_one_is_not() {
        // Target N(0, I) in 4-D, 300 members. A proposal half as wide in x2: on every one of 20
        // seeds the ratio of x2 exceeds the bound (exact ρ = 2). A proposal 1.3 times as wide,
        // or as wide and shifted by 0.3: the ratio stays at or below 1 plus 4 sampling spreads
        // (the ratio of two stds over 300 members of moderately uneven weights: about 0.05).
        for seed in 0..20 {
            let narrow = [1.0, 1.0, 0.5, 1.0];
            let points = draws(300, &narrow, seed);
            let (k, ratio) = widest_spread_ratio(&points, &log_weights(&points, &narrow, 0.0), 1)
                .expect("a ratio");
            assert_eq!(k, 2, "seed {seed}");
            assert!(ratio > WIDER_THAN_PROPOSAL, "seed {seed}: {ratio}");
            let wide = [1.3; 4];
            let points = draws(300, &wide, seed);
            assert!(within_proposal_spread(
                &points,
                &log_weights(&points, &wide, 0.0),
                1
            ));
            let same = [1.0; 4];
            let points = draws(300, &same, seed);
            let (_, ratio) = widest_spread_ratio(&points, &log_weights(&points, &same, 0.3), 1)
                .expect("a ratio");
            assert!(ratio < 1.0 + 4.0 * 0.05, "seed {seed}: {ratio}");
        }
    }

    #[test]
    fn failed_members_weigh_nothing_and_degenerate_input_has_no_ratio() {
        let points = vec![vec![0.0], vec![1.0], vec![2.0], vec![3.0]];
        // The two failed members (weight 0) leave {1, 2}: std 0.5 against 1.118.
        let lw = [f64::NEG_INFINITY, 0.0, 0.0, f64::NEG_INFINITY];
        let (_, ratio) = widest_spread_ratio(&points, &lw, 1).expect("a ratio");
        assert!((ratio - 0.5 / 1.25f64.sqrt()).abs() < 1e-12);
        assert_eq!(
            widest_spread_ratio(&points, &[f64::NEG_INFINITY; 4], 1),
            None
        );
        assert_eq!(widest_spread_ratio(&points[..1], &[0.0], 1), None);
        assert_eq!(widest_spread_ratio(&points, &[0.0; 4], 3), None);
        assert_eq!(
            widest_spread_ratio(&[vec![1.0], vec![1.0]], &[0.0, 0.0], 1),
            None
        );
        assert!(within_proposal_spread(
            &[vec![1.0], vec![1.0]],
            &[0.0, 0.0],
            1
        ));
    }

    #[test]
    fn a_mixtures_spread_is_its_widest_batchs() {
        // Two batches: {0, 1} (std 0.5) and {0, 4} (std 2). Equal weights: the weighted std over
        // all four (1.639) against the wider batch's 2.
        let points = vec![vec![0.0], vec![1.0], vec![0.0], vec![4.0]];
        let (_, ratio) = widest_spread_ratio(&points, &[0.0; 4], 2).expect("a ratio");
        let pooled = (43.0f64 / 16.0).sqrt();
        assert!((ratio - pooled / 2.0).abs() < 1e-12, "{ratio}");
        let (_, alone) = widest_spread_ratio(&points, &[0.0; 4], 1).expect("a ratio");
        assert!((alone - 1.0).abs() < 1e-12);
    }
}
