//! The tidy export of a campaign: one row per run with its status, parameters, outputs (and
//! output stds where known), attempts, outcome kind and failure reason; as CSV or JSON.

use serde_json::{Value, json};

use crate::error::{CampaignError, Result};
use crate::store::{CampaignStore, ExportRow};

/// The rows of the export.
pub fn export_rows(store: &CampaignStore) -> Result<Vec<ExportRow>> {
    store.export_rows()
}

/// Tidy CSV: `run_id, status, <parameters>, <outputs>, <output>_std…, attempts, outcome, reason`
/// (empty cells where a run has no value).
pub fn export_csv(
    rows: &[ExportRow],
    parameters: &[String],
    outputs: &[String],
) -> Result<Vec<u8>> {
    let with_std = rows.iter().any(|r| r.std.is_some());
    let mut w = csv::Writer::from_writer(Vec::new());
    let mut header: Vec<String> = vec!["run_id".into(), "status".into()];
    header.extend(parameters.iter().cloned());
    header.extend(outputs.iter().cloned());
    if with_std {
        header.extend(outputs.iter().map(|o| format!("{o}_std")));
    }
    header.extend(["attempts".into(), "outcome".into(), "reason".into()]);
    let err = |e: csv::Error| CampaignError::Format {
        path: "export".into(),
        reason: e.to_string(),
    };
    w.write_record(&header).map_err(err)?;
    for r in rows {
        let mut record = vec![r.run_id.to_string(), r.status.clone()];
        record.extend(r.parameters.iter().map(|v| format!("{v:?}")));
        for k in 0..outputs.len() {
            record.push(
                r.outputs
                    .get(k)
                    .map_or_else(String::new, |v| format!("{v:?}")),
            );
        }
        if with_std {
            for k in 0..outputs.len() {
                record.push(
                    r.std
                        .as_ref()
                        .and_then(|s| s.get(k))
                        .map_or_else(String::new, |v| format!("{v:?}")),
                );
            }
        }
        record.push(r.attempts.to_string());
        record.push(r.kind.clone().unwrap_or_default());
        record.push(r.reason.clone().unwrap_or_default());
        w.write_record(&record).map_err(err)?;
    }
    w.into_inner().map_err(|e| CampaignError::Format {
        path: "export".into(),
        reason: e.to_string(),
    })
}

/// Tidy JSON: an array of objects with the same fields as the CSV (parameters and outputs by name).
pub fn export_json(rows: &[ExportRow], parameters: &[String], outputs: &[String]) -> Value {
    Value::Array(
        rows.iter()
            .map(|r| {
                let mut o = serde_json::Map::new();
                o.insert("run_id".into(), json!(r.run_id));
                o.insert("status".into(), json!(r.status));
                for (name, v) in parameters.iter().zip(&r.parameters) {
                    o.insert(name.clone(), json!(v));
                }
                for (k, name) in outputs.iter().enumerate() {
                    o.insert(
                        name.clone(),
                        r.outputs.get(k).map_or(Value::Null, |v| json!(v)),
                    );
                    if let Some(s) = r.std.as_ref().and_then(|s| s.get(k)) {
                        o.insert(format!("{name}_std"), json!(s));
                    }
                }
                o.insert("attempts".into(), json!(r.attempts));
                o.insert("outcome".into(), json!(r.kind));
                o.insert("reason".into(), json!(r.reason));
                Value::Object(o)
            })
            .collect(),
    )
}
