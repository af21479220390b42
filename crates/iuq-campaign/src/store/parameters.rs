//! A run's parameter vector as the store keeps it: its exact key (identical vectors share one
//! run) and its stored text.

/// The key identifying a parameter vector exactly: the bits of each value (with -0 as 0).
pub fn parameter_key(point: &[f64]) -> String {
    point
        .iter()
        .map(|v| format!("{:016x}", if *v == 0.0 { 0u64 } else { v.to_bits() }))
        .collect::<Vec<_>>()
        .join(",")
}

/// A run's parameters as the store holds them (a JSON array; `null` reads as NaN). Text that is
/// no such array is a corrupt store, an error of the row (column `column` of the query), never an
/// empty parameter vector that a model would then be run with.
pub(super) fn decode_parameters(text: &str, column: usize) -> rusqlite::Result<Vec<f64>> {
    serde_json::from_str::<Vec<Option<f64>>>(text)
        .map(|v| v.into_iter().map(|x| x.unwrap_or(f64::NAN)).collect())
        .map_err(|e| {
            rusqlite::Error::FromSqlConversionFailure(
                column,
                rusqlite::types::Type::Text,
                format!("run parameters `{text}` are not a JSON array of numbers: {e}").into(),
            )
        })
}

pub(super) fn encode_parameters(point: &[f64]) -> String {
    // Shortest round-trip form; parameters are finite (checked when designs are added).
    serde_json::to_string(point).unwrap_or_else(|_| "[]".into())
}
