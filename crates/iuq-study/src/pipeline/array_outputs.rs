//! Array outputs of a command model: one declaration maps a run's array to the data rows.
//!
//! ```toml
//! [model]
//! kind = "command"
//! command = ["./model", "--curve"]
//! output = { file = "result.json", format = "json", array = "/T" }   # or
//! output = { file = "out.csv", format = "csv", column = "T" }
//! ```
//!
//! Without `outputs`, the model has as many outputs as a run answers for (one per data row for
//! a whole-curve model, one with `model.abscissa`), named `T[0]`, `T[1]`, … after the array's last
//! pointer token or the column; element j is compared with data row j (in file order, after
//! `x_range`). A run whose array has another length is not a model failure but a study that
//! declares the wrong shape: the pipeline stops with an input error naming the file and key
//! ([`array_length_error`]).

use toml::{Table, Value};

use crate::error::{Result, StudyError, input_error};

/// The key that declares the array (`model.output.array` or `model.output.column`), when the
/// `[model]` table gives no `outputs` and declares one.
fn array_key(model: &Table) -> Option<(&'static str, String)> {
    if model.contains_key("outputs") {
        return None;
    }
    let output = model.get("output")?.as_table()?;
    if let Some(pointer) = output.get("array").and_then(Value::as_str) {
        let base = pointer
            .rsplit('/')
            .find(|token| !token.is_empty())
            .unwrap_or("y");
        return Some(("array", base.replace("~1", "/").replace("~0", "~")));
    }
    let is_csv = output.get("format").and_then(Value::as_str) == Some("csv");
    let column = output.get("column").and_then(Value::as_str)?;
    is_csv.then(|| ("column", column.to_string()))
}

/// `model` with `outputs` named after its array, `count` of them, when it declares an array and
/// no `outputs`; unchanged otherwise.
pub(super) fn with_array_outputs(mut model: Table, count: usize) -> Table {
    if let Some((_, base)) = array_key(&model) {
        let names = (0..count)
            .map(|j| Value::String(format!("{base}[{j}]")))
            .collect();
        model.insert("outputs".into(), Value::Array(names));
    }
    model
}

/// The input error of a run whose array had the wrong length (its `reason` holds
/// [`iuq_campaign::decoder::ARRAY_LENGTH_MISMATCH`]): the study file and the key that declares the
/// array, the reason, and what the length must be.
pub(super) fn array_length_error(
    file: &str,
    model: &Table,
    reason: &str,
    expected: &str,
) -> StudyError {
    let key = match array_key(model) {
        Some((key, _)) => format!("model.output.{key}"),
        None => "model.outputs".to_string(),
    };
    input_error(format!(
        "{file}: key `{key}`: {reason}; expected {expected}"
    ))
}

/// Whether a failed run's reason is an array of the wrong length.
pub(super) fn is_length_mismatch(reason: &str) -> bool {
    reason.contains(iuq_campaign::decoder::ARRAY_LENGTH_MISMATCH)
}

/// Fail with [`array_length_error`] when any outcome is an array of the wrong length.
pub(super) fn check_lengths(
    file: &str,
    model: Option<&Table>,
    outcomes: &[iuq_core::Outcome],
    expected: &str,
) -> Result<()> {
    let Some(model) = model else {
        return Ok(());
    };
    for outcome in outcomes {
        if let Err(failure) = outcome
            && is_length_mismatch(&failure.reason)
        {
            return Err(array_length_error(file, model, &failure.reason, expected));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(text: &str) -> Table {
        text.parse().unwrap()
    }

    #[test]
    fn outputs_are_named_after_the_array_or_column() {
        let json = table(
            "kind = \"command\"\noutput = { file = \"r.json\", format = \"json\", array = \"/curve/T\" }",
        );
        let named = with_array_outputs(json, 3);
        assert_eq!(
            named["outputs"],
            Value::Array(vec!["T[0]".into(), "T[1]".into(), "T[2]".into()])
        );
        let csv = table("output = { file = \"o.csv\", format = \"csv\", column = \"el\" }");
        let named = with_array_outputs(csv, 2);
        assert_eq!(
            named["outputs"],
            Value::Array(vec!["el[0]".into(), "el[1]".into()])
        );
        // Given outputs stay as they are.
        let given = table(
            "outputs = [\"a\"]\noutput = { file = \"r.json\", format = \"json\", array = \"/T\" }",
        );
        assert_eq!(with_array_outputs(given.clone(), 5), given);
        // No array: nothing to name.
        let plain = table("output = { file = \"r.json\", format = \"json\" }");
        assert!(!with_array_outputs(plain, 2).contains_key("outputs"));
    }

    #[test]
    fn a_wrong_length_names_the_file_and_the_key() {
        let json = table("output = { file = \"r.json\", format = \"json\", array = \"/T\" }");
        let e = array_length_error("s.toml", &json, "array length mismatch: …", "8");
        assert!(e.is_bad_input());
        let m = e.to_string();
        assert!(
            m.contains("s.toml") && m.contains("model.output.array"),
            "{m}"
        );
        assert!(is_length_mismatch(&format!(
            "output file `r.json`: {}: the array at `/T` has 7 values for 8 outputs",
            iuq_campaign::decoder::ARRAY_LENGTH_MISMATCH
        )));
    }
}
