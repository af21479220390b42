//! Numbers that plain JSON cannot hold, as a checkpoint writes them: the [`BasisState`]'s
//! log-likelihoods keep −∞ (a failed member) as `null`.
//!
//! [`BasisState`]: crate::BasisState

/// Serde helper for log-likelihood vectors: −∞ (a failed member) is written as `null`, which
/// plain JSON numbers cannot hold, and read back as −∞.
pub mod negative_infinity_as_null {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    /// Write −∞ (and any other non-finite value) as `null`.
    pub fn serialize<S: Serializer>(values: &[f64], serializer: S) -> Result<S::Ok, S::Error> {
        let v: Vec<Option<f64>> = values
            .iter()
            .map(|&x| if x.is_finite() { Some(x) } else { None })
            .collect();
        v.serialize(serializer)
    }

    /// Read `null` as −∞.
    pub fn deserialize<'de, D: Deserializer<'de>>(deserializer: D) -> Result<Vec<f64>, D::Error> {
        let v: Vec<Option<f64>> = Vec::deserialize(deserializer)?;
        Ok(v.into_iter()
            .map(|x| x.unwrap_or(f64::NEG_INFINITY))
            .collect())
    }
}

/// Serde helper for a statistic that may be +∞ (a k̂ where the weights are nearly equal and no
/// tail can be fitted): plain JSON writes it as `null`, read back here as +∞.
pub mod infinity_from_null {
    use serde::{Deserialize, Deserializer};

    /// Read `null` as +∞.
    pub fn deserialize<'de, D: Deserializer<'de>>(deserializer: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(deserializer)?.unwrap_or(f64::INFINITY))
    }
}

#[cfg(test)]
mod tests {
    #[derive(serde::Serialize, serde::Deserialize, PartialEq, Debug)]
    struct Statistic {
        #[serde(deserialize_with = "super::infinity_from_null::deserialize")]
        pareto_k: f64,
    }

    #[test]
    fn an_infinite_statistic_reads_back() {
        for value in [f64::INFINITY, 0.41] {
            let text = serde_json::to_string(&Statistic { pareto_k: value }).unwrap();
            let back: Statistic = serde_json::from_str(&text).unwrap();
            assert_eq!(back.pareto_k, value, "{text}");
        }
    }
}
