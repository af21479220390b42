//! Monte Carlo standard errors of a weighted population whose members share ancestors.
//!
//! After a bridge the model posterior's population is a resample-move population: members are
//! copies of resampled ancestors moved by a few MCMC steps, and copies of one ancestor are
//! correlated. The self-normalised importance-sampling error √(Σ w̄²(h − μ)²), which treats every
//! member as independent, then understates the spread. Chan & Lai (2013, "A general theory of
//! particle filters in hidden Markov models and some applications", Ann. Statist. 41(6)) and
//! Lee & Whiteley (2018, "Variance estimation in the particle filter", Biometrika 105(3)) group
//! the members by their ancestor in the first generation (their "Eve") and sum within groups:
//!
//! MCSE(μ)² = Σ_e (Σ_{i: E_i = e} w̄_i (h_i − μ))²,
//!
//! consistent for the sequential Monte Carlo estimate's variance. Without resampling every member
//! is its own ancestor and this is the independent formula. It needs ancestors that are not
//! all one: with one Eve left the estimate collapses to 0 (Lee & Whiteley's degeneracy), so the
//! number of distinct ancestors is reported beside it.

/// Standard errors of every parameter's weighted mean and std under ancestral grouping.
#[derive(Debug, Clone, PartialEq)]
pub struct AncestralErrors {
    /// MCSE of each mean, √(Σ_e (Σ_{i∈e} w̄_i (θ_ik − μ_k))²).
    pub mean: Vec<f64>,
    /// MCSE of each std by the delta method, √(Σ_e (Σ_{i∈e} w̄_i ((θ_ik − μ_k)² − σ_k²))²)/(2σ_k)
    /// (0 where σ_k is 0).
    pub std: Vec<f64>,
    /// Distinct ancestors among the members with a positive weight.
    pub ancestors: usize,
}

/// The errors of the weighted means `mean` and stds `std` of `theta` under normalised `weights`,
/// members grouped by `ancestor` (any labels; members with equal labels share an ancestor).
pub fn ancestral_errors(
    theta: &[Vec<f64>],
    weights: &[f64],
    ancestor: &[usize],
    mean: &[f64],
    std: &[f64],
) -> AncestralErrors {
    let d = mean.len();
    let mut order: Vec<usize> = (0..theta.len()).collect();
    order.sort_by_key(|&i| ancestor[i]);
    let mut sum_mean = vec![0.0; d];
    let mut sum_var = vec![0.0; d];
    let (mut group_mean, mut group_var) = (vec![0.0; d], vec![0.0; d]);
    let mut ancestors = 0;
    let mut weighted_in_group = false;
    for (position, &i) in order.iter().enumerate() {
        for k in 0..d {
            let deviation = theta[i][k] - mean[k];
            group_mean[k] += weights[i] * deviation;
            group_var[k] += weights[i] * (deviation * deviation - std[k] * std[k]);
        }
        weighted_in_group |= weights[i] > 0.0;
        let last_of_group = order
            .get(position + 1)
            .is_none_or(|&next| ancestor[next] != ancestor[i]);
        if last_of_group {
            for k in 0..d {
                sum_mean[k] += group_mean[k] * group_mean[k];
                sum_var[k] += group_var[k] * group_var[k];
            }
            group_mean.fill(0.0);
            group_var.fill(0.0);
            ancestors += usize::from(weighted_in_group);
            weighted_in_group = false;
        }
    }
    AncestralErrors {
        mean: sum_mean.iter().map(|v| v.sqrt()).collect(),
        std: sum_var
            .iter()
            .zip(std)
            .map(|(v, s)| if *s > 0.0 { v.sqrt() / (2.0 * s) } else { 0.0 })
            .collect(),
        ancestors,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn own_ancestors_give_the_independent_formula_and_copies_add_up() {
        let theta: Vec<Vec<f64>> = [0.0, 1.0, 3.0, -2.0].iter().map(|&v| vec![v]).collect();
        let w = [0.1, 0.2, 0.3, 0.4];
        let mean: f64 = theta.iter().zip(&w).map(|(t, w)| w * t[0]).sum();
        let var: f64 = theta
            .iter()
            .zip(&w)
            .map(|(t, w)| w * (t[0] - mean).powi(2))
            .sum();
        let std = var.sqrt();
        let own = ancestral_errors(&theta, &w, &[0, 1, 2, 3], &[mean], &[std]);
        let independent: f64 = theta
            .iter()
            .zip(&w)
            .map(|(t, w)| (w * (t[0] - mean)).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!((own.mean[0] - independent).abs() < 1e-15);
        assert_eq!(own.ancestors, 4);
        // Members 0 and 2 copies of one ancestor, 1 and 3 of another: their terms add before
        // squaring.
        let shared = ancestral_errors(&theta, &w, &[7, 5, 7, 5], &[mean], &[std]);
        let a = 0.1 * (0.0 - mean) + 0.3 * (3.0 - mean);
        let b = 0.2 * (1.0 - mean) + 0.4 * (-2.0 - mean);
        assert!((shared.mean[0] - (a * a + b * b).sqrt()).abs() < 1e-15);
        let va = 0.1 * ((0.0 - mean).powi(2) - var) + 0.3 * ((3.0 - mean).powi(2) - var);
        let vb = 0.2 * ((1.0 - mean).powi(2) - var) + 0.4 * ((-2.0 - mean).powi(2) - var);
        assert!((shared.std[0] - (va * va + vb * vb).sqrt() / (2.0 * std)).abs() < 1e-15);
        assert_eq!(shared.ancestors, 2);
        // A zero-weight group does not count as an ancestor.
        let w0 = [0.25, 0.0, 0.75, 0.0];
        assert_eq!(
            ancestral_errors(&theta, &w0, &[7, 5, 7, 5], &[mean], &[std]).ancestors,
            1
        );
    }
}
