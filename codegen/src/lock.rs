//! The machine-wide lock that serialises every use of symbolica.
//!
//! Unlicensed, symbolica allows one symbolica thread per user on the machine: a second
//! process that touches it aborts. Cargo runs build scripts in parallel, and tests may run
//! codegen concurrently, so codegen takes an exclusive file lock before its first symbolica
//! call and holds it until the process is done with symbolica. A second process then waits.

use std::fs::{File, OpenOptions};
use std::io;
use std::path::PathBuf;

/// Holds the lock while alive.
pub struct SymbolicaLock {
    _file: File,
}

/// The lock file: `$RBSS_LOCK_FILE`, or `rbss-codegen-symbolica.lock` in the temp directory.
pub fn lock_path() -> PathBuf {
    std::env::var_os("RBSS_LOCK_FILE")
        .map(PathBuf::from)
        .unwrap_or_else(|| std::env::temp_dir().join("rbss-codegen-symbolica.lock"))
}

impl SymbolicaLock {
    /// Blocks until this process holds the lock. `on_wait` is called once if another process
    /// holds it first.
    pub fn acquire(on_wait: impl FnOnce(&std::path::Path)) -> io::Result<SymbolicaLock> {
        let path = lock_path();
        let file = OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&path)?;
        match file.try_lock() {
            Ok(()) => {}
            Err(std::fs::TryLockError::WouldBlock) => {
                on_wait(&path);
                file.lock()?;
            }
            Err(std::fs::TryLockError::Error(e)) => return Err(e),
        }
        Ok(SymbolicaLock { _file: file })
    }
}
