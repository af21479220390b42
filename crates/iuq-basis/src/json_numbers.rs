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
