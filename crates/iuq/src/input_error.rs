//! Bad input versus failed work: the two ways a command can fail, and their exit codes.
//!
//! Every error caused by what the user gave (a flag, a file, a key in a study file) is wrapped
//! in [`InputError`] with a message naming the file, key and reason; `main` maps it to exit
//! code 2. Any other error is a failure of the work (exit code 1).

use std::fmt;

/// Exit code of a successful command.
pub const EXIT_SUCCESS: i32 = 0;
/// Exit code of a command whose work failed.
pub const EXIT_FAILURE: i32 = 1;
/// Exit code of a command given bad input.
pub const EXIT_BAD_INPUT: i32 = 2;

/// An error caused by the user's input.
#[derive(Debug)]
pub struct InputError(pub String);

impl fmt::Display for InputError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for InputError {}

/// Build an input error as an `anyhow::Error`.
pub fn input_error(message: impl Into<String>) -> anyhow::Error {
    anyhow::Error::new(InputError(message.into()))
}

/// True when the error (or one in its chain) is an [`InputError`].
pub fn is_input_error(error: &anyhow::Error) -> bool {
    error
        .chain()
        .any(|e| e.downcast_ref::<InputError>().is_some())
}

/// Extension to mark any error as an input error with a context message, e.g.
/// `parse(text).bad_input(|| format!("{path}: ..."))`.
pub trait BadInput<T> {
    /// Convert the error into an [`InputError`] whose message is `context: error`.
    fn bad_input<F: FnOnce() -> String>(self, context: F) -> anyhow::Result<T>;
}

impl<T, E: fmt::Display> BadInput<T> for Result<T, E> {
    fn bad_input<F: FnOnce() -> String>(self, context: F) -> anyhow::Result<T> {
        self.map_err(|e| input_error(format!("{}: {e}", context())))
    }
}
