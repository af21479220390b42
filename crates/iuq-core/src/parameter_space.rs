//! Parameter spaces: ordered, named parameters with independent priors.

use rand::Rng;
use serde::{Deserialize, Serialize};

use crate::error::{CoreError, Result};
use crate::prior::Prior;

/// One named parameter and its prior.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Parameter {
    /// The name used in study files, expressions and outputs (e.g. `kLink`).
    pub name: String,
    /// Its prior distribution.
    pub prior: Prior,
}

/// An ordered set of parameters with independent priors: the joint prior density is the
/// product of the marginals.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParameterSpace {
    parameters: Vec<Parameter>,
}

impl ParameterSpace {
    /// Build a space, checking that it is non-empty, names are unique and valid identifiers,
    /// and every prior is proper.
    pub fn new(parameters: Vec<Parameter>) -> Result<Self> {
        if parameters.is_empty() {
            return Err(CoreError::InvalidParameterSpace(
                "at least one parameter is needed".into(),
            ));
        }
        for (i, p) in parameters.iter().enumerate() {
            let valid_identifier = p
                .name
                .chars()
                .next()
                .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
                && p.name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_');
            if !valid_identifier {
                return Err(CoreError::InvalidParameterSpace(format!(
                    "parameter name `{}` must start with a letter or `_` and hold only letters, digits and `_`",
                    p.name
                )));
            }
            if parameters[..i].iter().any(|q| q.name == p.name) {
                return Err(CoreError::InvalidParameterSpace(format!(
                    "parameter `{}` is defined twice",
                    p.name
                )));
            }
            p.prior.validate(&p.name)?;
        }
        Ok(Self { parameters })
    }

    /// The parameters in order.
    pub fn parameters(&self) -> &[Parameter] {
        &self.parameters
    }

    /// Number of parameters.
    pub fn dimension(&self) -> usize {
        self.parameters.len()
    }

    /// Parameter names in order.
    pub fn names(&self) -> Vec<String> {
        self.parameters.iter().map(|p| p.name.clone()).collect()
    }

    /// Index of the parameter called `name`.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.parameters.iter().position(|p| p.name == name)
    }

    fn check_dimension(&self, x: &[f64]) -> Result<()> {
        if x.len() != self.dimension() {
            return Err(CoreError::DimensionMismatch {
                expected: self.dimension(),
                actual: x.len(),
            });
        }
        Ok(())
    }

    /// True when every coordinate lies in its prior's support.
    pub fn in_support(&self, x: &[f64]) -> bool {
        x.len() == self.dimension()
            && self
                .parameters
                .iter()
                .zip(x)
                .all(|(p, &v)| p.prior.in_support(v))
    }

    /// Joint log prior density Σ_i ln π_i(x_i); −∞ outside the support.
    pub fn log_prior(&self, x: &[f64]) -> Result<f64> {
        self.check_dimension(x)?;
        Ok(self
            .parameters
            .iter()
            .zip(x)
            .map(|(p, &v)| p.prior.log_density(v))
            .sum())
    }

    /// One joint draw from the prior.
    pub fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> Vec<f64> {
        self.parameters
            .iter()
            .map(|p| p.prior.sample(rng))
            .collect()
    }

    /// Map a point of the unit cube through each marginal quantile function, so that a
    /// space-filling design on \[0,1\]^d becomes one distributed as the prior.
    pub fn from_unit_cube(&self, u: &[f64]) -> Result<Vec<f64>> {
        self.check_dimension(u)?;
        Ok(self
            .parameters
            .iter()
            .zip(u)
            .map(|(p, &v)| p.prior.quantile(v))
            .collect())
    }

    /// Finite ranges holding each prior's bulk (the support where bounded).
    pub fn ranges(&self) -> Vec<(f64, f64)> {
        self.parameters
            .iter()
            .map(|p| p.prior.plotting_range())
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::random::stream;

    fn rbc_space() -> ParameterSpace {
        ParameterSpace::new(vec![
            Parameter {
                name: "kLink".into(),
                prior: Prior::Uniform(10.0, 300.0),
            },
            Parameter {
                name: "kBend".into(),
                prior: Prior::Uniform(50.0, 400.0),
            },
            Parameter {
                name: "viscosityRatio".into(),
                prior: Prior::Uniform(1.0, 15.0),
            },
        ])
        .unwrap()
    }

    #[test]
    fn joint_log_prior_is_the_sum_of_marginals() {
        let s = rbc_space();
        let lp = s.log_prior(&[100.0, 100.0, 5.0]).unwrap();
        let expected = -(290.0f64.ln() + 350.0f64.ln() + 14.0f64.ln());
        assert!((lp - expected).abs() < 1e-12);
        assert_eq!(s.log_prior(&[5.0, 100.0, 5.0]).unwrap(), f64::NEG_INFINITY);
        assert!(s.log_prior(&[1.0]).is_err());
    }

    #[test]
    fn duplicate_and_invalid_names_are_rejected() {
        let p = |n: &str| Parameter {
            name: n.into(),
            prior: Prior::Uniform(0.0, 1.0),
        };
        assert!(ParameterSpace::new(vec![p("a"), p("a")]).is_err());
        assert!(ParameterSpace::new(vec![p("1a")]).is_err());
        assert!(ParameterSpace::new(vec![p("a b")]).is_err());
        assert!(ParameterSpace::new(vec![]).is_err());
    }

    #[test]
    fn samples_are_in_support_and_unit_cube_maps_to_ranges() {
        let s = rbc_space();
        let mut rng = stream(3, 0, 0);
        for _ in 0..1000 {
            assert!(s.in_support(&s.sample(&mut rng)));
        }
        let x = s.from_unit_cube(&[0.0, 0.5, 1.0]).unwrap();
        assert_eq!(x, vec![10.0, 225.0, 15.0]);
    }
}
