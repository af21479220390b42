//! Atomic file output: every file of the report is written under a temporary name in its
//! final directory and renamed, so a reader never sees a half-written file.

use std::path::{Path, PathBuf};

use crate::error::{ReportError, Result};

/// A temporary name beside `path`: hidden, with the process id, in the same directory so the
/// final rename stays on one file system.
pub(crate) fn temporary_path(path: &Path) -> PathBuf {
    path.with_file_name(format!(".{}.tmp-{}", file_name(path), std::process::id()))
}

/// [`temporary_path`] ending in `.extension`, for writers that choose a format by extension.
pub(crate) fn temporary_path_with_extension(path: &Path, extension: &str) -> PathBuf {
    path.with_file_name(format!(
        ".{}.tmp-{}.{extension}",
        file_name(path),
        std::process::id()
    ))
}

/// The final component of `path` as text.
fn file_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "file".to_string())
}

/// Writes `contents` to `path` atomically (temporary file, then rename).
pub(crate) fn write_atomic(path: &Path, contents: &[u8]) -> Result<()> {
    let temporary = temporary_path(path);
    let io_error = |source| ReportError::Io {
        path: path.to_path_buf(),
        source,
    };
    std::fs::write(&temporary, contents).map_err(io_error)?;
    std::fs::rename(&temporary, path).map_err(|source| {
        let _ = std::fs::remove_file(&temporary);
        io_error(source)
    })
}

/// Creates `dir` and its parents.
pub(crate) fn create_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|source| ReportError::Io {
        path: dir.to_path_buf(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temporary_names_stay_in_the_directory() {
        let t = temporary_path(Path::new("/a/b/report.html"));
        assert_eq!(t.parent(), Some(Path::new("/a/b")));
        assert!(
            t.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with(".report.html.tmp-"))
        );
    }
}
