//! The disk budget of a run's output folder, and the one place a full disk is recognised.
//!
//! Policy (DESIGN.md, "Disk budget"): the folder's usage is measured by walking it, not tracked
//! incrementally, so files from an earlier run (a resumed one) count too. Every large write is
//! checked before it starts:
//! - a snapshot must leave room for one more checkpoint of the pool's full capacity plus a small
//!   reserve for the CSV and PNG files, so the run can always stop with a fresh checkpoint;
//! - a checkpoint first deletes checkpoints beyond the `keep` newest, then, if it still does not
//!   fit, every checkpoint but the newest; if it still does not fit the run stops.
//!
//! When a snapshot does not fit, [`DiskFullPolicy`] says whether the run stops (the default,
//! after writing a checkpoint) or deletes its oldest snapshots.

use serde::Deserialize;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

/// What a run does when its next snapshot would not fit the disk budget.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum DiskFullPolicy {
    /// Write a checkpoint and stop, saying how to resume with a larger budget.
    #[default]
    Stop,
    /// Delete the oldest snapshots (never the newest) to make room, and go on.
    PruneSnapshots,
}

/// Bytes kept free for the CSV, PVD and PNG files an output rewrites.
pub const SMALL_FILE_RESERVE: u64 = 4 << 20;

/// Total size of the regular files under `dir` (0 if it does not exist).
pub fn usage(dir: &Path) -> u64 {
    let Ok(rd) = std::fs::read_dir(dir) else { return 0 };
    rd.flatten()
        .map(|e| match e.metadata() {
            Ok(m) if m.is_dir() => usage(&e.path()),
            Ok(m) => m.len(),
            Err(_) => 0,
        })
        .sum()
}

/// Whether an I/O error means the disk (or the test's simulated disk) is full.
pub fn is_disk_full(e: &std::io::Error) -> bool {
    e.raw_os_error() == Some(ENOSPC) || e.kind() == std::io::ErrorKind::StorageFull
}

const ENOSPC: i32 = 28;

/// Fault injection for the tests: with `STRAND_FAULT_ENOSPC_AFTER=N` in the environment, large
/// output writes (checkpoints and snapshots) fail with ENOSPC once N bytes have gone through
/// them, exactly as a disk that fills up would. Lets the tests prove that a full disk stops a
/// run cleanly without needing a small filesystem (mounting a tmpfs needs root).
pub fn fault_check(bytes: u64) -> std::io::Result<()> {
    static WRITTEN: AtomicU64 = AtomicU64::new(0);
    static LIMIT: std::sync::OnceLock<Option<u64>> = std::sync::OnceLock::new();
    let limit = *LIMIT.get_or_init(|| std::env::var("STRAND_FAULT_ENOSPC_AFTER").ok().and_then(|v| v.parse().ok()));
    let Some(limit) = limit else { return Ok(()) };
    let before = WRITTEN.fetch_add(bytes, Ordering::Relaxed);
    if before + bytes > limit {
        return Err(std::io::Error::from_raw_os_error(ENOSPC));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn usage_counts_nested_files() {
        let d = tempfile::tempdir().unwrap();
        std::fs::write(d.path().join("a"), [0u8; 100]).unwrap();
        std::fs::create_dir(d.path().join("sub")).unwrap();
        std::fs::write(d.path().join("sub/b"), [0u8; 28]).unwrap();
        assert_eq!(usage(d.path()), 128);
        assert_eq!(usage(&d.path().join("missing")), 0);
    }

    #[test]
    fn enospc_is_disk_full() {
        assert!(is_disk_full(&std::io::Error::from_raw_os_error(ENOSPC)));
        assert!(!is_disk_full(&std::io::Error::from_raw_os_error(2)));
    }
}
