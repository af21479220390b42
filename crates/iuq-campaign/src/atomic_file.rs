//! Files that readers see whole or not at all (a worker's status and result, a job's manifest
//! and script), written with iuq's one atomic writer (`iuq_atomic_file`); errors name the file.

use std::path::Path;

use iuq_atomic_file::Durability;

use crate::error::{CampaignError, Result};

/// Write `contents` to `path` atomically. With `durable`, the data is flushed to disk (fsync of
/// the file and its folder) before the call returns, so it survives a power failure; without,
/// it survives any crash of the writing process.
pub fn write_atomically(path: &Path, contents: &[u8], durable: bool) -> Result<()> {
    let durability = if durable {
        Durability::Durable
    } else {
        Durability::Atomic
    };
    iuq_atomic_file::write_atomically(path, contents, durability)
        .map_err(|e| CampaignError::io(path, e))
}
