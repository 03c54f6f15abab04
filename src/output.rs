//! The output files of one command, committed together.
//!
//! Each file is written to a temporary beside it, named uniquely per process and write
//! (`.NAME.PID-K.partial`), so that concurrent runs into one directory never share one; the
//! temporaries become the real names only in [`Outputs::commit`], after every file of the run
//! was written. A failure before the commit (an error, a full disk) leaves the old set of
//! files as it was and removes the temporaries (on drop). The commit checks first that every
//! destination can be replaced by a file (a directory in the way cannot), then renames them one
//! after another: a set of renames is not atomic, but each rename is, and a process killed among
//! them leaves some files new and some old, each whole, and at most the not yet renamed
//! temporaries.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Per-process counter of temporary names (with the pid, unique on the machine).
static COUNTER: AtomicUsize = AtomicUsize::new(0);

/// The files of one run, written to temporaries and renamed together by [`Outputs::commit`];
/// dropped uncommitted, it removes its temporaries.
#[derive(Default)]
pub struct Outputs {
    /// (temporary, destination), in the order they were created.
    files: Vec<(PathBuf, PathBuf)>,
}

impl Outputs {
    pub fn new() -> Self {
        Self::default()
    }

    /// Creates the temporary that becomes `path` on commit, and returns it open for writing.
    pub fn create(&mut self, path: &Path) -> Result<File, String> {
        let name = path
            .file_name()
            .ok_or_else(|| format!("{}: names no file", path.display()))?;
        let tmp = path.with_file_name(format!(
            ".{}.{}-{}.partial",
            name.to_string_lossy(),
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        let file =
            File::create_new(&tmp).map_err(|e| format!("{}: cannot write: {e}", path.display()))?;
        self.files.push((tmp, path.to_path_buf()));
        Ok(file)
    }

    /// Renames every temporary to its destination; on an error nothing is renamed (when the
    /// checks catch it) and the temporaries are removed.
    pub fn commit(mut self) -> Result<(), String> {
        for (_, dest) in &self.files {
            if dest.is_dir() {
                return Err(format!(
                    "{}: cannot write: a directory is in the way (nothing written)",
                    dest.display()
                ));
            }
        }
        let files = std::mem::take(&mut self.files);
        for (k, (tmp, dest)) in files.iter().enumerate() {
            if let Err(e) = std::fs::rename(tmp, dest) {
                self.files = files[k..].to_vec();
                let done = files[..k]
                    .iter()
                    .map(|(_, d)| d.display().to_string())
                    .collect::<Vec<_>>();
                return Err(if done.is_empty() {
                    format!("{}: cannot write: {e} (nothing written)", dest.display())
                } else {
                    format!(
                        "{}: cannot write: {e} (already written: {})",
                        dest.display(),
                        done.join(", ")
                    )
                });
            }
        }
        Ok(())
    }
}

impl Drop for Outputs {
    fn drop(&mut self) {
        for (tmp, _) in &self.files {
            let _ = std::fs::remove_file(tmp);
        }
    }
}

/// Writes one file through [`Outputs`]: `write` fills it, then it replaces `path`.
pub fn write_file(
    path: &Path,
    write: impl FnOnce(&mut File) -> Result<(), String>,
) -> Result<(), String> {
    let mut out = Outputs::new();
    let mut f = out.create(path)?;
    write(&mut f)?;
    drop(f);
    out.commit()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn entries(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn commit_renames_all_and_drop_removes_all() {
        let tmp = tempfile::tempdir().unwrap();
        let (a, b) = (tmp.path().join("a.csv"), tmp.path().join("b.png"));
        std::fs::write(&a, "old a").unwrap();
        std::fs::write(&b, "old b").unwrap();
        {
            let mut out = Outputs::new();
            out.create(&a).unwrap().write_all(b"new a").unwrap();
            out.create(&b).unwrap().write_all(b"new b").unwrap();
            // Dropped before the commit: a failure of the run.
        }
        assert_eq!(entries(tmp.path()), ["a.csv", "b.png"]);
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "old a");
        let mut out = Outputs::new();
        out.create(&a).unwrap().write_all(b"new a").unwrap();
        out.create(&b).unwrap().write_all(b"new b").unwrap();
        out.commit().unwrap();
        assert_eq!(entries(tmp.path()), ["a.csv", "b.png"]);
        assert_eq!(std::fs::read_to_string(&b).unwrap(), "new b");
    }

    #[test]
    fn a_directory_in_the_way_commits_nothing() {
        let tmp = tempfile::tempdir().unwrap();
        let (a, b) = (tmp.path().join("a.csv"), tmp.path().join("b.png"));
        std::fs::write(&a, "old a").unwrap();
        std::fs::create_dir(&b).unwrap();
        let mut out = Outputs::new();
        out.create(&a).unwrap().write_all(b"new a").unwrap();
        out.create(&b).unwrap().write_all(b"new b").unwrap();
        let e = out.commit().unwrap_err();
        assert!(e.contains("a directory is in the way"), "{e}");
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "old a");
        assert_eq!(entries(tmp.path()), ["a.csv", "b.png"]);
    }
}
