//! Posterior summaries of a final (equally weighted) population (docs/methods.md §6): the
//! MAP among the samples, mean, standard deviation, quantiles, and 1-D and 2-D Gaussian KDE
//! marginals (scipy's `gaussian_kde` conventions, through [`iuq_core::GaussianKde`]).

use serde::{Deserialize, Serialize};

use iuq_core::GaussianKde;
use iuq_core::weighted_statistics::weighted_quantiles;

use crate::error::{BasisError, Result};
use crate::sampler::BasisState;

/// Quantile probabilities reported by default: 2.5, 5, 25, 50, 75, 95 and 97.5 %.
pub const DEFAULT_PROBABILITIES: [f64; 7] = [0.025, 0.05, 0.25, 0.5, 0.75, 0.95, 0.975];

/// Summary statistics of posterior samples.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PosteriorSummary {
    /// Parameter names, in order.
    pub names: Vec<String>,
    /// The maximum a posteriori sample: the member with the largest ll + lp.
    pub map: Vec<f64>,
    /// Index of the MAP member in the population.
    pub map_index: usize,
    /// ln f(D|θ) at the MAP.
    pub map_log_likelihood: f64,
    /// ln π(θ) at the MAP.
    pub map_log_prior: f64,
    /// Posterior mean of each parameter.
    pub mean: Vec<f64>,
    /// Posterior standard deviation of each parameter (population std, ddof = 0, as
    /// `numpy.std`).
    pub std: Vec<f64>,
    /// The probabilities of [`quantiles`](Self::quantiles).
    pub probabilities: Vec<f64>,
    /// `quantiles[k][q]`: quantile `probabilities[q]` of parameter k (Hazen's definition,
    /// [`weighted_quantiles`] with equal weights).
    pub quantiles: Vec<Vec<f64>>,
}

impl PosteriorSummary {
    /// Summarise equally weighted `samples` with their log-likelihoods and log-priors.
    pub fn new(
        names: &[String],
        samples: &[Vec<f64>],
        log_likelihood: &[f64],
        log_prior: &[f64],
        probabilities: &[f64],
    ) -> Result<Self> {
        let n = samples.len();
        let d = names.len();
        if n == 0 {
            return Err(BasisError::InvalidData("no samples to summarise".into()));
        }
        if log_likelihood.len() != n || log_prior.len() != n {
            return Err(BasisError::InvalidData(format!(
                "{n} samples but {} log-likelihoods and {} log-priors",
                log_likelihood.len(),
                log_prior.len()
            )));
        }
        if let Some(i) = samples.iter().position(|x| x.len() != d) {
            return Err(BasisError::InvalidData(format!(
                "sample {i} does not have {d} values"
            )));
        }
        let mut map_index = None;
        let mut best = f64::NEG_INFINITY;
        for i in 0..n {
            let v = log_likelihood[i] + log_prior[i];
            if v.is_finite() && (map_index.is_none() || v > best) {
                best = v;
                map_index = Some(i);
            }
        }
        let map_index = map_index.ok_or_else(|| {
            BasisError::InvalidData("no sample has a finite log-posterior".into())
        })?;
        let mut mean = vec![0.0; d];
        for x in samples {
            for (m, v) in mean.iter_mut().zip(x) {
                *m += v;
            }
        }
        for m in &mut mean {
            *m /= n as f64;
        }
        let mut std = vec![0.0; d];
        for x in samples {
            for ((s, v), m) in std.iter_mut().zip(x).zip(&mean) {
                *s += (v - m).powi(2);
            }
        }
        for s in &mut std {
            *s = (*s / n as f64).sqrt();
        }
        let ones = vec![1.0; n];
        let quantiles = (0..d)
            .map(|k| {
                let column: Vec<f64> = samples.iter().map(|x| x[k]).collect();
                weighted_quantiles(&column, &ones, probabilities)
            })
            .collect::<iuq_core::Result<Vec<_>>>()?;
        Ok(Self {
            names: names.to_vec(),
            map: samples[map_index].clone(),
            map_index,
            map_log_likelihood: log_likelihood[map_index],
            map_log_prior: log_prior[map_index],
            mean,
            std,
            probabilities: probabilities.to_vec(),
            quantiles,
        })
    }

    /// Summarise the population of a state with [`DEFAULT_PROBABILITIES`].
    pub fn from_state(state: &BasisState) -> Result<Self> {
        Self::new(
            &state.parameter_names,
            &state.samples,
            &state.log_likelihood,
            &state.log_prior,
            &DEFAULT_PROBABILITIES,
        )
    }
}

/// A 1-D KDE marginal on a regular grid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Marginal1d {
    /// The parameter's name.
    pub parameter: String,
    /// Grid points.
    pub grid: Vec<f64>,
    /// Density at each grid point.
    pub density: Vec<f64>,
}

/// A 2-D KDE marginal on a regular grid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Marginal2d {
    /// The parameter along x.
    pub x_parameter: String,
    /// The parameter along y.
    pub y_parameter: String,
    /// Grid along x.
    pub xs: Vec<f64>,
    /// Grid along y.
    pub ys: Vec<f64>,
    /// `density[j][i]` at `(xs[i], ys[j])` (rows along y, as an image).
    pub density: Vec<Vec<f64>>,
}

fn column(samples: &[Vec<f64>], k: usize) -> Result<Vec<f64>> {
    samples
        .iter()
        .map(|x| {
            x.get(k)
                .copied()
                .ok_or_else(|| BasisError::InvalidData(format!("a sample has no coordinate {k}")))
        })
        .collect()
}

fn grid(lo: f64, hi: f64, points: usize) -> Vec<f64> {
    if points == 1 {
        return vec![0.5 * (lo + hi)];
    }
    (0..points)
        .map(|i| lo + (hi - lo) * i as f64 / (points - 1) as f64)
        .collect()
}

/// The grid range of a marginal: `range` if given, else the sample range widened by three
/// kernel standard deviations on each side.
fn default_range(values: &[f64], kernel_variance: f64, range: Option<(f64, f64)>) -> (f64, f64) {
    if let Some(r) = range {
        return r;
    }
    let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let pad = 3.0 * kernel_variance.sqrt();
    (lo - pad, hi + pad)
}

fn check_grid(points: usize, range: Option<(f64, f64)>) -> Result<()> {
    if points == 0 {
        return Err(BasisError::InvalidData(
            "a marginal needs grid points".into(),
        ));
    }
    if let Some((lo, hi)) = range {
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(BasisError::InvalidData(format!(
                "marginal range [{lo}, {hi}] must be finite and increasing"
            )));
        }
    }
    Ok(())
}

/// The default grid range of parameter `k`'s marginal: the sample range widened by three
/// kernel standard deviations (Scott's rule) on each side. Clip it to the prior support for
/// plots of bounded parameters.
pub fn marginal_range(samples: &[Vec<f64>], k: usize) -> Result<(f64, f64)> {
    let values = column(samples, k)?;
    let data: Vec<Vec<f64>> = values.iter().map(|&v| vec![v]).collect();
    let kde = GaussianKde::new(&data, None)?;
    Ok(default_range(&values, kde.covariance()[0][0], None))
}

/// The 1-D KDE marginal of parameter `k` (named `name`) of equally weighted `samples`, on
/// `points` grid points over `range` (default: the sample range ± 3 kernel std).
pub fn marginal_1d(
    samples: &[Vec<f64>],
    k: usize,
    name: &str,
    points: usize,
    range: Option<(f64, f64)>,
) -> Result<Marginal1d> {
    check_grid(points, range)?;
    let values = column(samples, k)?;
    let data: Vec<Vec<f64>> = values.iter().map(|&v| vec![v]).collect();
    let kde = GaussianKde::new(&data, None)?;
    let (lo, hi) = default_range(&values, kde.covariance()[0][0], range);
    let grid = grid(lo, hi, points);
    let density = kde.evaluate_1d(&grid)?;
    Ok(Marginal1d {
        parameter: name.to_string(),
        grid,
        density,
    })
}

/// The 2-D KDE marginal of parameters `a` (x) and `b` (y) of equally weighted `samples`, on a
/// `points`×`points` grid over `ranges` (default: each sample range ± 3 kernel std).
pub fn marginal_2d(
    samples: &[Vec<f64>],
    (a, b): (usize, usize),
    (name_a, name_b): (&str, &str),
    points: usize,
    ranges: Option<((f64, f64), (f64, f64))>,
) -> Result<Marginal2d> {
    check_grid(points, ranges.map(|r| r.0))?;
    check_grid(points, ranges.map(|r| r.1))?;
    let xa = column(samples, a)?;
    let xb = column(samples, b)?;
    let data: Vec<Vec<f64>> = xa.iter().zip(&xb).map(|(&u, &v)| vec![u, v]).collect();
    let kde = GaussianKde::new(&data, None)?;
    let h = kde.covariance();
    let (ra, rb) = match ranges {
        Some((ra, rb)) => (ra, rb),
        None => (
            default_range(&xa, h[0][0], None),
            default_range(&xb, h[1][1], None),
        ),
    };
    let xs = grid(ra.0, ra.1, points);
    let ys = grid(rb.0, rb.1, points);
    let density = kde.evaluate_grid_2d(&xs, &ys)?;
    Ok(Marginal2d {
        x_parameter: name_a.to_string(),
        y_parameter: name_b.to_string(),
        xs,
        ys,
        density,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_statistics_and_map() {
        let names = vec!["a".to_string(), "b".to_string()];
        let samples = vec![
            vec![1.0, 10.0],
            vec![2.0, 20.0],
            vec![3.0, 30.0],
            vec![4.0, 40.0],
        ];
        let ll = [-3.0, -1.0, -2.0, f64::NEG_INFINITY];
        let lp = [0.0, -0.5, 0.0, 0.0];
        let s = PosteriorSummary::new(&names, &samples, &ll, &lp, &[0.5]).unwrap();
        assert_eq!(s.map_index, 1);
        assert_eq!(s.map, vec![2.0, 20.0]);
        assert_eq!(s.mean, vec![2.5, 25.0]);
        // numpy.std([1, 2, 3, 4]) = 1.118033988749895
        assert!((s.std[0] - 1.118_033_988_749_895).abs() < 1e-15);
        assert_eq!(s.quantiles[1], vec![25.0]);
        assert!(PosteriorSummary::new(&names, &samples, &ll[..2], &lp, &[0.5]).is_err());
    }

    #[test]
    fn marginals_integrate_to_one() {
        let samples: Vec<Vec<f64>> = (0..400)
            .map(|i| {
                let t = i as f64 / 400.0;
                vec![(t * 37.0).sin(), (t * 11.0).cos() + t]
            })
            .collect();
        let m = marginal_1d(&samples, 0, "a", 400, None).unwrap();
        let dx = m.grid[1] - m.grid[0];
        let mass: f64 = m.density.iter().sum::<f64>() * dx;
        assert!((mass - 1.0).abs() < 1e-3, "{mass}");
        let m2 = marginal_2d(&samples, (0, 1), ("a", "b"), 120, None).unwrap();
        let cell = (m2.xs[1] - m2.xs[0]) * (m2.ys[1] - m2.ys[0]);
        let mass: f64 = m2.density.iter().flatten().sum::<f64>() * cell;
        assert!((mass - 1.0).abs() < 5e-3, "{mass}");
        assert!(marginal_1d(&samples, 5, "z", 10, None).is_err());
        let (lo, hi) = marginal_range(&samples, 0).unwrap();
        assert_eq!((lo, hi), (m.grid[0], m.grid[399]));
        assert!(marginal_1d(&samples, 0, "a", 10, Some((1.0, 0.0))).is_err());
    }
}
