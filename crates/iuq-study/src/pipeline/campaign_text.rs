//! The text of the campaign study a pipeline writes for its model runs (the study's own model,
//! or the cell model's runs).

use toml::{Table, Value};

use crate::error::{Result, StudyError};
use crate::study::Study;

/// The campaign text of `study`'s runs: its name, a description `"<what> of the study <file>
/// (written by iuq pipeline; do not edit)"`, its parameters followed by `extra` (the abscissa,
/// with a prior that covers the data's; the campaign needs a prior for every input, and never
/// samples it), the `[model]` table `model`, and the study's `[executor]`.
pub(super) fn campaign_text(
    study: &Study,
    what: &str,
    extra: Option<(String, Value)>,
    model: Table,
) -> Result<String> {
    let mut parameters = Table::new();
    for p in study.space.parameters() {
        let prior = Value::try_from(p.prior).map_err(|e| {
            StudyError::failure(format!("cannot write the prior of `{}`: {e}", p.name))
                .with_source(e)
        })?;
        parameters.insert(p.name.clone(), prior);
    }
    if let Some((name, prior)) = extra {
        parameters.insert(name, prior);
    }
    let mut root = Table::new();
    root.insert("name".into(), Value::String(study.name.clone()));
    root.insert(
        "description".into(),
        Value::String(format!(
            "{what} of the study {} (written by iuq pipeline; do not edit)",
            // The file name only: the same study called by another path keeps one text.
            study.path.file_name().map_or_else(
                || study.path.display().to_string(),
                |n| n.to_string_lossy().into_owned()
            )
        )),
    );
    root.insert("parameters".into(), Value::Table(parameters));
    root.insert("model".into(), Value::Table(model));
    if let Some(executor) = &study.executor {
        root.insert("executor".into(), Value::Table(executor.clone()));
    }
    toml::to_string(&root).map_err(|e| {
        StudyError::failure(format!("cannot write the campaign study: {e}")).with_source(e)
    })
}
