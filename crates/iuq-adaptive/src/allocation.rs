//! How a round's runs are shared among run groups: by each group's part of the surrogate error.
//!
//! A study whose model runs at one abscissa at a time has one run group, and one GP, per datum.
//! Its GPs do not need runs alike: at a low shear stress a GP that already predicts the posterior
//! region to 10⁻⁴ gains nothing from four more runs, while at a stress where the model's runs
//! scatter (a chaotic quantity of interest) the GP's mean is known only to σ_noise/√(runs
//! nearby) and each run buys little. What the runs are for is to bring the surrogate error ε of
//! the posterior moments ([`crate::moment_error`]) below the tolerance. With ε_g the error that
//! group g's GPs alone leave (the same measure with only their likelihood terms), and the GPs'
//! errors independent, ε² ≈ Σ_g ε_g²: group g's share of the round's runs follows its share of
//! ε², relative to the largest,
//!
//! n_g = ⌈batch · ε_g² / max_h ε_h²⌉,
//!
//! so the group that holds the most of the error gets the full `batch`, and one whose error is a
//! third of that gets a ninth of it (at least one run, where its error is not zero). This is the
//! greedy form of allocating evaluations to the output whose surrogate uncertainty most affects
//! the posterior, as in the multi-output sequential designs of Sürer, Plumlee and Wild (2023).

/// The most runs each of the groups with surrogate errors `group_errors` (ε_g, posterior stds)
/// gets in a round of at most `batch` runs per group: ⌈batch·ε_g²/max ε²⌉. When an error is not
/// a finite number, or every error is zero, nothing is known of their ratios and every group
/// gets `batch`.
pub fn group_batches(batch: usize, group_errors: &[f64]) -> Vec<usize> {
    let largest = group_errors.iter().map(|e| e.abs()).fold(0.0, f64::max);
    if largest == 0.0 || group_errors.iter().any(|e| !e.is_finite()) {
        return vec![batch; group_errors.len()];
    }
    group_errors
        .iter()
        .map(|e| {
            let share = (e.abs() / largest).powi(2);
            ((batch as f64 * share).ceil() as usize).min(batch)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_group_with_the_largest_error_gets_the_whole_batch() {
        // Shares of ε²: 1, 1/4, 1/9, 1/100, 0.
        let batches = group_batches(8, &[0.15, 0.075, 0.05, 0.015, 0.0]);
        assert_eq!(batches, vec![8, 2, 1, 1, 0]);
    }

    #[test]
    fn unknown_or_zero_errors_leave_every_group_its_batch() {
        assert_eq!(group_batches(4, &[0.0, 0.0]), vec![4, 4]);
        assert!(group_batches(4, &[]).is_empty());
        assert_eq!(group_batches(4, &[f64::NAN, 0.1]), vec![4, 4]);
        assert_eq!(group_batches(4, &[f64::INFINITY, 0.1]), vec![4, 4]);
    }

    #[test]
    fn equal_errors_share_alike() {
        assert_eq!(group_batches(4, &[0.2, 0.2, 0.2]), vec![4, 4, 4]);
    }
}
