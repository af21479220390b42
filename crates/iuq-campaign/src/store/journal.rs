//! The journal mode a store's file system allows: a WAL on local disks, the rollback journal on
//! network and cluster file systems.

use std::path::Path;

use serde::Serialize;

/// The journal mode chosen for the store's file system.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum JournalMode {
    /// Write-ahead log (local disks).
    Wal,
    /// Rollback journal (network file systems).
    Delete,
}

/// True when `path` lies on a network or cluster file system (by `statfs` magic number), where
/// SQLite's WAL mode is unsafe.
pub fn is_network_file_system(path: &Path) -> bool {
    use std::os::unix::ffi::OsStrExt;
    let Ok(c) = std::ffi::CString::new(path.as_os_str().as_bytes()) else {
        return false;
    };
    // SAFETY: statfs writes into the zeroed struct we own; the path is NUL-terminated.
    let magic = unsafe {
        let mut s: libc::statfs = std::mem::zeroed();
        if libc::statfs(c.as_ptr(), &mut s) != 0 {
            return false;
        }
        s.f_type as u64 & 0xffff_ffff
    };
    const NETWORK: [u64; 13] = [
        0x6969,      // NFS
        0x517B,      // SMB
        0xFF53_4D42, // CIFS
        0xFE53_4D42, // SMB2
        0x0BD0_0BD0, // Lustre
        0x4750_4653, // GPFS
        0x1983_0326, // BeeGFS
        0x00C3_6400, // Ceph
        0x0102_1997, // 9p
        0x5346_414F, // AFS
        0xAAD7_AAEA, // PanFS
        0x6573_5546, // FUSE (sshfs, …)
        0x0102_1994, // tmpfs is local; listed here only as a guard below
    ];
    magic != 0x0102_1994 && NETWORK.contains(&magic)
}
