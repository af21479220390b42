//! Files that readers see whole or not at all: written to a temporary name in the same folder,
//! then renamed over the target.

use std::io::Write;
use std::path::Path;

use crate::error::{CampaignError, Result};

/// Write `contents` to `path` atomically. With `durable`, the data is flushed to disk (fsync of
/// the file and its folder) before the call returns, so it survives a power failure; without,
/// it survives any crash of the writing process.
pub fn write_atomically(path: &Path, contents: &[u8], durable: bool) -> Result<()> {
    let directory = path.parent().unwrap_or_else(|| Path::new("."));
    let name = path
        .file_name()
        .map_or_else(|| "file".into(), |n| n.to_string_lossy().into_owned());
    let temporary = directory.join(format!(".{name}.tmp-{}", std::process::id()));
    let result = (|| -> std::io::Result<()> {
        let mut file = std::fs::File::create(&temporary)?;
        file.write_all(contents)?;
        if durable {
            file.sync_all()?;
        }
        std::fs::rename(&temporary, path)?;
        if durable {
            if let Ok(dir) = std::fs::File::open(directory) {
                let _ = dir.sync_all();
            }
        }
        Ok(())
    })();
    result.map_err(|e| {
        let _ = std::fs::remove_file(&temporary);
        CampaignError::io(path, e)
    })
}
