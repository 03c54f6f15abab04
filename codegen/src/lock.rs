//! The machine-wide lock that serialises every use of symbolica.
//!
//! Unlicensed, symbolica allows one symbolica thread per user on the machine: a second
//! process that touches it aborts. Cargo runs build scripts in parallel, and tests may run
//! codegen concurrently, so codegen takes an exclusive file lock before its first symbolica
//! call and holds it until the process is done with symbolica. A second process then waits.
//!
//! "Done with symbolica" means the end of the process: symbolica's own per-user permit (a
//! lock file in its per-user lock directory) is taken by the first thread that calls it and
//! kept until that thread exits, which for `rbss-codegen`, a build script or the main thread
//! of any program is the end of the process. Releasing this lock earlier (say when
//! [`crate::generate`] returns) would let a waiting codegen start symbolica while this
//! process still holds the permit, and symbolica would abort it (found by
//! `codegen/tests/concurrent.rs`). So once taken, the lock stays with the process; its file
//! descriptor is closed, and the lock released, when the process exits.

use std::fs::{File, OpenOptions};
use std::io;
use std::path::PathBuf;
use std::sync::Mutex;

/// The lock file, once this process holds it (never released before the process exits).
static HELD: Mutex<Option<File>> = Mutex::new(None);

/// Proof that this process holds the lock (for the rest of its life; see the module
/// documentation).
pub struct SymbolicaLock {
    _private: (),
}

/// The lock file: `$RBSS_LOCK_FILE`, or `rbss-codegen-symbolica.lock` in the temp directory.
pub fn lock_path() -> PathBuf {
    std::env::var_os("RBSS_LOCK_FILE")
        .map(PathBuf::from)
        .unwrap_or_else(|| std::env::temp_dir().join("rbss-codegen-symbolica.lock"))
}

impl SymbolicaLock {
    /// Blocks until this process holds the lock (at once if it already does). `on_wait` is
    /// called once if another process holds it first.
    pub fn acquire(on_wait: impl FnOnce(&std::path::Path)) -> io::Result<SymbolicaLock> {
        let mut held = HELD.lock().unwrap_or_else(|e| e.into_inner());
        if held.is_none() {
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
            *held = Some(file);
        }
        Ok(SymbolicaLock { _private: () })
    }
}
