//! Bad input versus failed work: the two ways a command can fail, and their exit codes.
//!
//! Every error caused by what the user gave (a flag, a file, a key in a study file) is an
//! [`iuq_study::StudyError::BadInput`] with a message naming the file, key and reason, whether it
//! comes from the study layer or from a verb's own flags ([`input_error`]); `main` maps it to
//! exit code 2. Any other error is a failure of the work (exit code 1). A `StudyError` keeps the
//! typed error it came from as its source; its message already names that error, so [`message`]
//! does not print it twice.

use iuq_study::StudyError;

/// Mark any error as an input error with a context message, e.g.
/// `parse(text).bad_input(|| format!("{path}: ..."))` (the study layer's extension).
pub use iuq_study::BadInput;

/// Exit code of a successful command.
pub const EXIT_SUCCESS: i32 = 0;
/// Exit code of a command whose work failed.
pub const EXIT_FAILURE: i32 = 1;
/// Exit code of a command given bad input.
pub const EXIT_BAD_INPUT: i32 = 2;

/// Build an input error as an `anyhow::Error`.
pub fn input_error(message: impl Into<String>) -> anyhow::Error {
    anyhow::Error::new(iuq_study::input_error(message))
}

/// True when the first [`StudyError`] in the error's chain is a [`StudyError::BadInput`] (the
/// errors a `StudyError` keeps as its sources do not decide its kind).
pub fn is_input_error(error: &anyhow::Error) -> bool {
    error
        .chain()
        .find_map(|e| e.downcast_ref::<StudyError>())
        .is_some_and(StudyError::is_bad_input)
}

/// The message `main` prints: the error's text and its sources', each after `: ` (as `{:#}`
/// prints it), up to the first [`StudyError`], whose message already holds its sources' texts.
pub fn message(error: &anyhow::Error) -> String {
    iuq_study::error::chain_message(&**error)
}
