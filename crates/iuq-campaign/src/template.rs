//! `{{ name }}` templates: input files and command arguments filled with the values of one run.
//!
//! A placeholder is `{{`, optional spaces, a name (letters, digits, `_`; not starting with a
//! digit), optional spaces, `}}`. Names are the study's parameters, its derived values and
//! `run_id`. Everything else is copied unchanged; `{{{{` is no escape, so a template that needs a
//! literal `{{` must not be a template. Templates are parsed when the study is loaded, so an
//! unknown name is reported before any run starts.

use serde::{Deserialize, Serialize};

/// One piece of a parsed template.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Segment {
    /// Text copied unchanged.
    Literal(String),
    /// A placeholder, replaced by the value of the named quantity.
    Placeholder {
        /// The name inside the braces.
        name: String,
        /// The 1-based line of the placeholder in the template (for error messages).
        line: usize,
    },
}

/// A parsed template.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Template {
    segments: Vec<Segment>,
}

/// Why a template does not parse: the 1-based line and the reason.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TemplateSyntaxError {
    /// The line of the offending `{{`.
    pub line: usize,
    /// What is wrong.
    pub reason: String,
}

impl std::fmt::Display for TemplateSyntaxError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "line {}: {}", self.line, self.reason)
    }
}

fn is_name(name: &str) -> bool {
    name.chars()
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

impl Template {
    /// Parse template text.
    pub fn parse(text: &str) -> Result<Self, TemplateSyntaxError> {
        let mut segments = Vec::new();
        let mut rest = text;
        let mut line = 1;
        while let Some(start) = rest.find("{{") {
            let literal = &rest[..start];
            line += literal.matches('\n').count();
            if !literal.is_empty() {
                segments.push(Segment::Literal(literal.to_string()));
            }
            let after = &rest[start + 2..];
            let end = after.find("}}").ok_or_else(|| TemplateSyntaxError {
                line,
                reason: "`{{` without a closing `}}`".into(),
            })?;
            let inner = &after[..end];
            let name = inner.trim();
            if !is_name(name) {
                return Err(TemplateSyntaxError {
                    line,
                    reason: format!(
                        "`{{{{{inner}}}}}` does not hold a name (letters, digits and `_`)"
                    ),
                });
            }
            segments.push(Segment::Placeholder {
                name: name.to_string(),
                line,
            });
            line += inner.matches('\n').count();
            rest = &after[end + 2..];
        }
        if !rest.is_empty() {
            segments.push(Segment::Literal(rest.to_string()));
        }
        Ok(Self { segments })
    }

    /// The segments in order.
    pub fn segments(&self) -> &[Segment] {
        &self.segments
    }

    /// Placeholders whose name `known` rejects, as `(name, line)`.
    pub fn unknown_names(&self, known: impl Fn(&str) -> bool) -> Vec<(String, usize)> {
        self.segments
            .iter()
            .filter_map(|s| match s {
                Segment::Placeholder { name, line } if !known(name) => Some((name.clone(), *line)),
                _ => None,
            })
            .collect()
    }

    /// True when the template holds at least one placeholder.
    pub fn has_placeholders(&self) -> bool {
        self.segments
            .iter()
            .any(|s| matches!(s, Segment::Placeholder { .. }))
    }

    /// Fill the placeholders with `value(name)`; a name it does not know is left as written.
    pub fn render(&self, value: impl Fn(&str) -> Option<String>) -> String {
        let mut out = String::new();
        for segment in &self.segments {
            match segment {
                Segment::Literal(text) => out.push_str(text),
                Segment::Placeholder { name, .. } => match value(name) {
                    Some(v) => out.push_str(&v),
                    None => {
                        out.push_str("{{ ");
                        out.push_str(name);
                        out.push_str(" }}");
                    }
                },
            }
        }
        out
    }
}

/// Format a value for a template or `params.json`-free text: integral values of magnitude below
/// 2^53 without a decimal point (`37`, so that step counts are integers), others in the shortest
/// form that reads back to the same `f64` (`0.1`, `1e-7`).
pub fn format_value(v: f64) -> String {
    if v.is_finite() && v == v.trunc() && v.abs() < 9.007_199_254_740_992e15 {
        format!("{}", v as i64)
    } else {
        format!("{v:?}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn placeholders_are_filled_and_lines_counted() {
        let t = Template::parse("a={{x}}\nb = {{ steps }} {{y}}\n").unwrap();
        let rendered = t.render(|n| match n {
            "x" => Some(format_value(0.25)),
            "steps" => Some(format_value(37.0)),
            _ => None,
        });
        assert_eq!(rendered, "a=0.25\nb = 37 {{ y }}\n");
        assert_eq!(
            t.unknown_names(|n| n == "x" || n == "steps"),
            vec![("y".to_string(), 2)]
        );
    }

    #[test]
    fn bad_templates_name_the_line() {
        let e = Template::parse("ok\n{{ x").unwrap_err();
        assert_eq!(e.line, 2);
        let e = Template::parse("{{ 1x }}").unwrap_err();
        assert!(e.reason.contains("name"));
        assert!(Template::parse("no placeholders } {").is_ok());
    }

    #[test]
    fn values_are_formatted_for_input_files() {
        assert_eq!(format_value(3.0), "3");
        assert_eq!(format_value(-2.0), "-2");
        assert_eq!(format_value(0.1), "0.1");
        assert_eq!(format_value(1e-7), "1e-7");
        assert_eq!(format_value(1e300), "1e300");
        assert_eq!(format_value(f64::NAN), "NaN");
    }
}
