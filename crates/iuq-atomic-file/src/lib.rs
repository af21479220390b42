//! Files that readers see whole or not at all, for every crate of iuq that writes results: the
//! contents go to a hidden temporary name in the target's own folder (so the final rename stays
//! on one file system and is atomic on POSIX), then the temporary file is renamed over the
//! target. A reader — a person, a coordinator polling a worker's status, a resumed study — sees
//! the old file or the new one, never a half-written one; a failed write leaves no temporary
//! file behind.
//!
//! Errors are the `std::io::Error` of the failing step; callers name the file in their own
//! error type.
//!
//! ```
//! use iuq_atomic_file::{Durability, write_atomically};
//!
//! let dir = std::env::temp_dir().join(format!("iuq-atomic-file-doc-{}", std::process::id()));
//! std::fs::create_dir_all(&dir)?;
//! let path = dir.join("summary.json");
//! write_atomically(&path, b"{\"runs\": 1}", Durability::Atomic)?;
//! write_atomically(&path, b"{\"runs\": 2}", Durability::Durable)?;
//! assert_eq!(std::fs::read_to_string(&path)?, "{\"runs\": 2}");
//! // Nothing but the file itself is left in the folder.
//! assert_eq!(std::fs::read_dir(&dir)?.count(), 1);
//! std::fs::remove_dir_all(&dir)?;
//! # Ok::<(), std::io::Error>(())
//! ```

#![warn(missing_docs)]
// No panic reachable from user input: a library reports every failure in its error type.
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

use std::io::Write;
use std::path::{Path, PathBuf};

/// Whether a write must survive a power failure, or only a crash of the writing process.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Durability {
    /// The data and the rename are flushed to disk (fsync of the file and of its folder) before
    /// the call returns: for records another machine or a later session relies on.
    Durable,
    /// Atomic against a crash of this process; the kernel writes the data back when it likes.
    Atomic,
}

/// The final component of `path` as text (`file` when there is none).
fn file_name(path: &Path) -> String {
    path.file_name()
        .map_or_else(|| "file".into(), |n| n.to_string_lossy().into_owned())
}

/// A hidden temporary name beside `path`, unique to this process: `.<name>.tmp-<pid>`, with
/// `.<extension>` appended when given (for writers that choose a format by the extension).
pub fn temporary_path(path: &Path, extension: Option<&str>) -> PathBuf {
    let mut name = format!(".{}.tmp-{}", file_name(path), std::process::id());
    if let Some(extension) = extension {
        name.push('.');
        name.push_str(extension);
    }
    path.with_file_name(name)
}

/// Rename the finished `temporary` file over `path`; on failure the temporary file is removed.
pub fn replace(temporary: &Path, path: &Path) -> std::io::Result<()> {
    std::fs::rename(temporary, path).inspect_err(|_| {
        let _ = std::fs::remove_file(temporary);
    })
}

/// Write `contents` to `path` atomically (see the crate), flushed to disk first when
/// `durability` is [`Durability::Durable`].
pub fn write_atomically(
    path: &Path,
    contents: &[u8],
    durability: Durability,
) -> std::io::Result<()> {
    let temporary = temporary_path(path, None);
    let durable = durability == Durability::Durable;
    let written = (|| -> std::io::Result<()> {
        let mut file = std::fs::File::create(&temporary)?;
        file.write_all(contents)?;
        if durable {
            file.sync_all()?;
        }
        Ok(())
    })();
    if let Err(error) = written {
        let _ = std::fs::remove_file(&temporary);
        return Err(error);
    }
    replace(&temporary, path)?;
    if durable {
        let directory = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        if let Ok(folder) = std::fs::File::open(directory) {
            let _ = folder.sync_all();
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("iuq-atomic-file-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn temporary_names_are_hidden_beside_the_target() {
        let t = temporary_path(Path::new("/a/b/report.html"), None);
        assert_eq!(t.parent(), Some(Path::new("/a/b")));
        let name = t.file_name().unwrap().to_string_lossy().into_owned();
        assert_eq!(name, format!(".report.html.tmp-{}", std::process::id()));
        let png = temporary_path(Path::new("fig.png"), Some("png"));
        assert!(png.to_string_lossy().ends_with(".png"));
    }

    #[test]
    fn a_write_replaces_the_whole_file_and_leaves_nothing_else() {
        let dir = scratch("replace");
        let path = dir.join("status.json");
        for durability in [Durability::Atomic, Durability::Durable] {
            write_atomically(&path, b"first, longer contents", durability).unwrap();
            write_atomically(&path, b"second", durability).unwrap();
            assert_eq!(std::fs::read(&path).unwrap(), b"second");
        }
        let names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, ["status.json"]);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_failed_write_keeps_the_old_file_and_no_temporary() {
        let dir = scratch("fail");
        let path = dir.join("result.json");
        write_atomically(&path, b"old", Durability::Atomic).unwrap();
        // Renaming a file over a non-empty folder fails.
        let folder = dir.join("folder");
        std::fs::create_dir_all(folder.join("inside")).unwrap();
        assert!(write_atomically(&folder, b"new", Durability::Atomic).is_err());
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
        let mut names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        names.sort();
        assert_eq!(names, ["folder", "result.json"]);
        // A missing folder: nothing is created.
        assert!(write_atomically(&dir.join("missing/x.json"), b"x", Durability::Atomic).is_err());
        assert!(!dir.join("missing").exists());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
