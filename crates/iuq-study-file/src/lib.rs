//! The study file's reader for iuq, the one every crate that reads a study file uses.
//!
//! | module | what |
//! |---|---|
//! | [`section`] | [`StudySection`]: the keys of one TOML table read with their types checked; every error names the file and the whole key, and a key never read is reported as unknown |
//! | [`duration`] | durations a study may name (`"1h30m"`, seconds), with their bound |
//! | [`error`] | the crate's error type [`StudyFileError`] |
//!
//! # Example
//!
//! A section reads its keys with their types; an error names the file and the whole key, and
//! [`StudySection::finish`] reports a key that was never read (a misspelling) as unknown.
//!
//! ```
//! use iuq_study_file::StudySection;
//!
//! let root: toml::Table = "[executor]\nmax_parallel = 4\ntimeout = \"1h30m\"\nretires = 2\n"
//!     .parse()?;
//! let table = root["executor"].as_table().unwrap();
//! let mut executor = StudySection::new(table, "executor", "study.toml");
//! assert_eq!(executor.count("max_parallel", 1)?, Some(4));
//! assert_eq!(executor.duration("timeout")?, Some(5400.0));
//! assert_eq!(executor.count("poll", 1)?, None);
//! assert_eq!(
//!     executor.count("max_parallel", 8).unwrap_err().to_string(),
//!     "study.toml: key `executor.max_parallel`: expected an integer of at least 8, found `4`"
//! );
//! assert_eq!(
//!     executor.finish().unwrap_err().to_string(),
//!     "study.toml: key `executor.retires`: unknown key \
//!      (expected one of max_parallel, timeout, poll)"
//! );
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]
// No panic reachable from user input: a library reports every failure in its error type.
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

pub mod duration;
pub mod error;
pub mod section;

pub use duration::{MAX_DURATION_SECONDS, check_duration, parse_duration};
pub use error::{Result, StudyFileError};
pub use section::{MAX_COUNT, StudySection};
