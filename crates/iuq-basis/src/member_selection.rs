//! Which members of a population a model-posterior batch runs: a draw without replacement that
//! is nested in its sample size.
//!
//! The members are the first `amount` positions of a Fisher–Yates shuffle of `0..length`
//! (Knuth 1997, Algorithm 3.4.2P, stopped after `amount` swaps): position i takes the index at
//! a uniform position j ∈ [i, length). The draws for positions `0..amount` do not depend on
//! `amount`, so the selection for S members is contained in the one for any S' > S under the
//! same random stream: a user who raises `samples` (a smaller MCSE, a k̂ that did not hold)
//! keeps every model run already made for the smaller batch, which the campaign store then
//! reuses. Each draw `random_range(i..length)` is on `u32`, as in `rand`'s own partial
//! shuffle (`rand::seq::index::sample` takes it for most sizes, e.g. 200 of 10,000), so the
//! batches recorded before this module existed are drawn again exactly.

use rand::Rng;

/// `amount` distinct indices of `0..length`, uniformly without replacement, in ascending order,
/// nested in `amount` for a given random stream (module docs). `amount` is capped at `length`.
pub fn nested_selection<R: Rng + ?Sized>(rng: &mut R, length: usize, amount: usize) -> Vec<usize> {
    let amount = amount.min(length);
    let mut indices: Vec<usize> = (0..length).collect();
    for i in 0..amount {
        let j = if length <= u32::MAX as usize {
            rng.random_range(i as u32..length as u32) as usize
        } else {
            rng.random_range(i..length)
        };
        indices.swap(i, j);
    }
    indices.truncate(amount);
    indices.sort_unstable();
    indices
}

#[cfg(test)]
mod tests {
    use super::*;
    use iuq_core::random::stream;
    use std::collections::BTreeSet;

    #[test]
    fn a_larger_selection_contains_every_smaller_one() {
        for (length, seed) in [(40, 1), (2_000, 7), (10_000, 3)] {
            let mut previous: BTreeSet<usize> = BTreeSet::new();
            for amount in [1, 5, 11, 12, 30, 40, 163, 200, 300, 2_000] {
                let chosen = nested_selection(&mut stream(seed, 9, 0), length, amount);
                assert_eq!(chosen.len(), amount.min(length));
                let set: BTreeSet<usize> = chosen.iter().copied().collect();
                assert_eq!(set.len(), chosen.len(), "distinct");
                assert!(chosen.windows(2).all(|w| w[0] < w[1]), "ascending");
                assert!(previous.is_subset(&set), "{length}, {amount}");
                previous = set;
            }
        }
    }

    #[test]
    fn the_batches_drawn_by_rand_partial_shuffle_are_drawn_again() {
        // The red-cell studies' batches (200 of 10,000) and the examples' sizes were drawn by
        // `rand::seq::index::sample`, which takes its partial shuffle there; their stored runs
        // stay the batches' runs only if the same members come out.
        for (length, amount) in [
            (10_000, 200),
            (10_000, 300),
            (2_000, 50),
            (2_000, 100),
            (500, 40),
        ] {
            let mut old = rand::seq::index::sample(&mut stream(1, 9, 0), length, amount).into_vec();
            old.sort_unstable();
            assert_eq!(nested_selection(&mut stream(1, 9, 0), length, amount), old);
        }
    }

    #[test]
    fn raising_samples_keeps_the_first_batch_members() {
        use crate::model_posterior::{ModelPosteriorSettings, selected_members};
        let with = |samples| ModelPosteriorSettings {
            samples,
            seed: 4,
            ..Default::default()
        };
        let small = selected_members(10_000, &with(200));
        let large = selected_members(10_000, &with(300));
        assert_eq!(large.len(), 300);
        assert!(small.iter().all(|i| large.binary_search(i).is_ok()));
    }

    #[test]
    fn every_index_is_equally_likely() {
        // 3 of 6, 20,000 draws: each index is chosen with probability 1/2; the count's std is
        // √(20,000 · ¼) ≈ 71, so 5 std is ±354 (a chance below 1e-5 per index).
        let mut counts = [0usize; 6];
        let mut rng = stream(5, 9, 0);
        for _ in 0..20_000 {
            for i in nested_selection(&mut rng, 6, 3) {
                counts[i] += 1;
            }
        }
        for c in counts {
            assert!((c as f64 - 10_000.0).abs() < 354.0, "{counts:?}");
        }
    }
}
