//! Atomic file output: every file of the report is written under a temporary name in its
//! final directory and renamed, so a reader never sees a half-written file.

use std::path::Path;

use crate::error::{ReportError, Result};

/// Writes `contents` to `path` atomically, with iuq's one atomic writer (`iuq_atomic_file`).
pub(crate) fn write_atomic(path: &Path, contents: &[u8]) -> Result<()> {
    iuq_atomic_file::write_atomically(path, contents, iuq_atomic_file::Durability::Atomic).map_err(
        |source| ReportError::Io {
            path: path.to_path_buf(),
            source,
        },
    )
}

/// Creates `dir` and its parents.
pub(crate) fn create_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|source| ReportError::Io {
        path: dir.to_path_buf(),
        source,
    })
}
