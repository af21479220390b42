//! The one reader of a study file's sections, for every crate that reads study files.
//!
//! A [`StudySection`] reads the keys of one TOML table with their types checked; every error
//! names the file, the whole key (`surrogate.adaptive.batch`) and the reason
//! ([`StudyFileError`], exit code 2 in the command line). It remembers which keys it was
//! asked for, so that [`StudySection::finish`] reports a key it never read — a misspelling —
//! as unknown, listing the keys it knows.

use std::sync::LazyLock;

use toml::{Table, Value};

use crate::duration::{check_duration, parse_duration};
use crate::error::{Result, StudyFileError};

/// The largest count a study may give (2³¹ − 1): sizes, samples, runs and steps beyond it would
/// overflow the products made of them or ask for more memory than any machine has.
pub const MAX_COUNT: usize = (1 << 31) - 1;

static EMPTY: LazyLock<Table> = LazyLock::new(Table::new);

/// Reads the keys of one section of a study file (see the module documentation).
#[derive(Debug, Clone)]
pub struct StudySection<'a> {
    table: &'a Table,
    prefix: String,
    file: &'a str,
    known: Vec<String>,
}

impl<'a> StudySection<'a> {
    /// The section `prefix` (`model`, `surrogate.adaptive`) of `file`, held in `table`.
    pub fn new(table: &'a Table, prefix: impl Into<String>, file: &'a str) -> Self {
        Self {
            table,
            prefix: prefix.into(),
            file,
            known: Vec::new(),
        }
    }

    /// A section that may be absent from the file: an absent one reads as empty.
    pub fn optional(table: Option<&'a Table>, prefix: impl Into<String>, file: &'a str) -> Self {
        Self::new(table.unwrap_or(&EMPTY), prefix, file)
    }

    /// The section held in `value`, which must be a table (`example` shows one in the error).
    pub fn of_value(
        value: &'a Value,
        prefix: impl Into<String>,
        file: &'a str,
        example: &str,
    ) -> Result<Self> {
        let prefix = prefix.into();
        match value {
            Value::Table(table) => Ok(Self::new(table, prefix, file)),
            other => Err(StudyFileError::key(
                file,
                prefix,
                format!("expected a table such as {example}, found `{other}`"),
            )),
        }
    }

    /// The study file.
    pub fn file(&self) -> &'a str {
        self.file
    }

    /// The whole name of `key` in this section (`surrogate.adaptive.batch`).
    pub fn full_key(&self, key: &str) -> String {
        if self.prefix.is_empty() {
            key.to_string()
        } else {
            format!("{}.{key}", self.prefix)
        }
    }

    /// An error about `key` of this section.
    pub fn error(&self, key: &str, reason: impl Into<String>) -> StudyFileError {
        StudyFileError::key(self.file, self.full_key(key), reason)
    }

    /// An error about the section as a whole.
    pub fn section_error(&self, reason: impl Into<String>) -> StudyFileError {
        StudyFileError::key(self.file, self.prefix.clone(), reason)
    }

    /// The table itself (keys not read through the section are not checked by `finish`).
    pub fn table(&self) -> &'a Table {
        self.table
    }

    /// Whether the section has `key` (without reading it).
    pub fn has(&self, key: &str) -> bool {
        self.table.contains_key(key)
    }

    /// Mark `keys` as known without reading them (read elsewhere, or only in some cases).
    pub fn allow(&mut self, keys: &[&str]) {
        for key in keys {
            self.mark(key);
        }
    }

    fn mark(&mut self, key: &str) {
        if !self.known.iter().any(|k| k == key) {
            self.known.push(key.to_string());
        }
    }

    /// The value of `key`, of any type.
    pub fn value(&mut self, key: &str) -> Option<&'a Value> {
        self.mark(key);
        self.table.get(key)
    }

    /// A string.
    pub fn string(&mut self, key: &str) -> Result<Option<String>> {
        match self.value(key) {
            None => Ok(None),
            Some(Value::String(s)) => Ok(Some(s.clone())),
            Some(other) => Err(self.error(key, format!("expected a string, found `{other}`"))),
        }
    }

    /// One of `options`.
    pub fn choice(&mut self, key: &str, options: &[&'static str]) -> Result<Option<&'static str>> {
        let Some(word) = self.string(key)? else {
            return Ok(None);
        };
        options
            .iter()
            .find(|o| **o == word)
            .copied()
            .map(Some)
            .ok_or_else(|| {
                self.error(
                    key,
                    format!("unknown value `{word}` (one of {})", options.join(", ")),
                )
            })
    }

    /// A boolean.
    pub fn boolean(&mut self, key: &str) -> Result<Option<bool>> {
        match self.value(key) {
            None => Ok(None),
            Some(Value::Boolean(b)) => Ok(Some(*b)),
            Some(other) => Err(self.error(key, format!("expected true or false, found `{other}`"))),
        }
    }

    /// An integer of at least `min` and at most [`MAX_COUNT`].
    pub fn count(&mut self, key: &str, min: usize) -> Result<Option<usize>> {
        match self.value(key) {
            None => Ok(None),
            Some(Value::Integer(i)) if *i > MAX_COUNT as i64 => Err(self.error(
                key,
                format!("{i} is too large (a count is at most {MAX_COUNT})"),
            )),
            Some(Value::Integer(i)) if *i >= 0 && *i as u64 >= min as u64 => usize::try_from(*i)
                .map(Some)
                .map_err(|_| self.error(key, format!("{i} is too large"))),
            Some(other) => Err(self.error(
                key,
                format!("expected an integer of at least {min}, found `{other}`"),
            )),
        }
    }

    /// An integer from `min` to `max` (a count whose cost grows with it beyond reason sooner
    /// than [`MAX_COUNT`]).
    pub fn count_in(&mut self, key: &str, min: usize, max: usize) -> Result<Option<usize>> {
        match self.count(key, min)? {
            Some(v) if v > max => Err(self.error(key, format!("{v} is too large (at most {max})"))),
            v => Ok(v),
        }
    }

    /// A non-negative integer that may use all 64 bits (a seed).
    pub fn seed(&mut self, key: &str) -> Result<Option<u64>> {
        match self.value(key) {
            None => Ok(None),
            Some(Value::Integer(i)) if *i >= 0 => Ok(Some(*i as u64)),
            Some(other) => Err(self.error(
                key,
                format!("expected a non-negative integer, found `{other}`"),
            )),
        }
    }

    /// A finite number (an integer reads as a number).
    pub fn number(&mut self, key: &str) -> Result<Option<f64>> {
        match self.value(key) {
            None => Ok(None),
            Some(v) => number_of(v)
                .map(Some)
                .ok_or_else(|| self.error(key, format!("expected a number, found `{v}`"))),
        }
    }

    /// A finite number greater than zero.
    pub fn positive(&mut self, key: &str) -> Result<Option<f64>> {
        match self.number(key)? {
            Some(x) if x <= 0.0 => {
                Err(self.error(key, format!("expected a positive number, found `{x}`")))
            }
            other => Ok(other),
        }
    }

    /// An array of finite numbers.
    pub fn numbers(&mut self, key: &str) -> Result<Option<Vec<f64>>> {
        self.array(key, "number", number_of)
    }

    /// An array of strings.
    pub fn strings(&mut self, key: &str) -> Result<Option<Vec<String>>> {
        self.array(key, "string", |v| v.as_str().map(str::to_string))
    }

    /// An array whose items `convert` reads (`None`: not a `what`).
    fn array<T>(
        &mut self,
        key: &str,
        what: &str,
        convert: impl Fn(&Value) -> Option<T>,
    ) -> Result<Option<Vec<T>>> {
        match self.value(key) {
            None => Ok(None),
            Some(Value::Array(items)) => items
                .iter()
                .enumerate()
                .map(|(i, v)| {
                    convert(v).ok_or_else(|| {
                        self.error(
                            &format!("{key}[{i}]"),
                            format!("expected a {what}, found `{v}`"),
                        )
                    })
                })
                .collect::<Result<Vec<_>>>()
                .map(Some),
            Some(other) => Err(self.error(
                key,
                format!("expected an array of {what}s, found `{other}`"),
            )),
        }
    }

    /// A duration in seconds: a number, or a string such as `"1h 30m"`.
    pub fn duration(&mut self, key: &str) -> Result<Option<f64>> {
        match self.value(key) {
            None => Ok(None),
            Some(Value::String(s)) => parse_duration(s).map(Some).map_err(|r| self.error(key, r)),
            Some(Value::Integer(i)) if *i >= 0 => check_duration(*i as f64)
                .map(Some)
                .map_err(|r| self.error(key, r)),
            Some(Value::Float(f)) if f.is_finite() && *f >= 0.0 => {
                check_duration(*f).map(Some).map_err(|r| self.error(key, r))
            }
            Some(other) => Err(self.error(
                key,
                format!("expected a duration such as \"30m\", found `{other}`"),
            )),
        }
    }

    /// A table, as it is.
    pub fn sub_table(&mut self, key: &str) -> Result<Option<&'a Table>> {
        match self.value(key) {
            None => Ok(None),
            Some(Value::Table(t)) => Ok(Some(t)),
            Some(other) => Err(self.error(key, format!("expected a table, found `{other}`"))),
        }
    }

    /// A table read as a section of its own (`example` shows one in the error).
    pub fn section(&mut self, key: &str, example: &str) -> Result<Option<StudySection<'a>>> {
        let full = self.full_key(key);
        let file = self.file;
        self.value(key)
            .map(|v| StudySection::of_value(v, full, file, example))
            .transpose()
    }

    /// Fail on a key the section was never asked for, listing the keys it knows.
    pub fn finish(&self) -> Result<()> {
        match self
            .table
            .keys()
            .find(|k| !self.known.iter().any(|known| known == *k))
        {
            Some(key) => Err(self.error(
                key,
                format!("unknown key (expected one of {})", self.known.join(", ")),
            )),
            None => Ok(()),
        }
    }

    /// [`StudySection::finish`] with the known keys described by `hint`.
    pub fn finish_with_hint(&self, hint: &str) -> Result<()> {
        match self
            .table
            .keys()
            .find(|k| !self.known.iter().any(|known| known == *k))
        {
            Some(key) => Err(self.error(key, format!("unknown key ({hint})"))),
            None => Ok(()),
        }
    }
}

/// A finite number, from a float or an integer.
fn number_of(value: &Value) -> Option<f64> {
    value
        .as_float()
        .or_else(|| value.as_integer().map(|i| i as f64))
        .filter(|x| x.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(text: &str) -> Table {
        text.parse().unwrap()
    }

    #[test]
    fn values_are_read_with_their_types_and_errors_name_file_and_whole_key() {
        let t = table(
            "n = 4\nx = 2\ny = 0.5\nword = \"lhs\"\nflag = true\nxs = [1, 2.5]\nnames = [\"a\"]\nwait = \"1m 30s\"\ninner = { seed = 3 }\n",
        );
        let mut s = StudySection::new(&t, "surrogate", "s.toml");
        assert_eq!(s.count("n", 1).unwrap(), Some(4));
        assert_eq!(s.number("x").unwrap(), Some(2.0));
        assert_eq!(s.positive("y").unwrap(), Some(0.5));
        assert_eq!(s.choice("word", &["lhs", "sobol"]).unwrap(), Some("lhs"));
        assert_eq!(s.boolean("flag").unwrap(), Some(true));
        assert_eq!(s.numbers("xs").unwrap(), Some(vec![1.0, 2.5]));
        assert_eq!(s.strings("names").unwrap(), Some(vec!["a".to_string()]));
        assert_eq!(s.duration("wait").unwrap(), Some(90.0));
        let mut inner = s.section("inner", "{ seed = 1 }").unwrap().unwrap();
        assert_eq!(inner.seed("seed").unwrap(), Some(3));
        inner.finish().unwrap();
        assert_eq!(s.count("absent", 1).unwrap(), None);
        s.finish().unwrap();

        let message = |e: StudyFileError| e.to_string();
        let mut s = StudySection::new(&t, "surrogate", "s.toml");
        assert_eq!(
            message(s.count("n", 5).unwrap_err()),
            "s.toml: key `surrogate.n`: expected an integer of at least 5, found `4`"
        );
        assert!(message(s.choice("word", &["sobol"]).unwrap_err()).contains("`surrogate.word`"));
        assert!(message(s.positive("word").unwrap_err()).contains("expected a number"));
        assert!(message(s.boolean("n").unwrap_err()).contains("`surrogate.n`"));
        assert!(message(s.numbers("names").unwrap_err()).contains("`surrogate.names[0]`"));
        let mut inner = s.section("inner", "{ seed = 1 }").unwrap().unwrap();
        assert!(message(inner.string("seed").unwrap_err()).contains("`surrogate.inner.seed`"));
        assert!(message(s.section("n", "{ seed = 1 }").unwrap_err()).contains("{ seed = 1 }"));
        assert_eq!(
            s.error("n", "why"),
            StudyFileError::key("s.toml", "surrogate.n", "why")
        );
    }

    #[test]
    fn a_key_never_asked_for_is_unknown_and_the_known_ones_are_listed() {
        let t = table("batch = 2\nbacth = 3\n");
        let mut s = StudySection::new(&t, "surrogate.adaptive", "s.toml");
        s.count("batch", 1).unwrap();
        s.allow(&["max_runs"]);
        assert_eq!(
            s.finish().unwrap_err().to_string(),
            "s.toml: key `surrogate.adaptive.bacth`: unknown key (expected one of batch, max_runs)"
        );
        let absent = StudySection::optional(None, "sampler", "s.toml");
        absent.finish().unwrap();
    }
}
