//! The output files of one command, committed together.
//!
//! Each file is written to a temporary beside it, named uniquely per process and write
//! (`.NAME.PID-K.partial`), so that concurrent runs into one directory never share one; the
//! temporaries become the real names only in [`Outputs::commit`], after every file of the run
//! was written. A failure before the commit (an error, a full disk) leaves the old set of
//! files as it was and removes the temporaries (on drop). The commit checks first that every
//! destination can be replaced by a file (a directory in the way cannot), then, holding a lock
//! on the directory (`flock` on the directory itself: no lock file), flushes the temporaries,
//! writes a journal (`.rbss-commit.PID`: the renames to do), renames them one after another
//! and removes the journal. So two runs into one directory never interleave their renames
//! (one run's CSV beside another's PNG); a run killed among its renames leaves its journal, and
//! the next commit into the directory finishes those renames first (the set becomes whole)
//! and removes the temporaries of processes that are gone.

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

    /// Renames every temporary to its destination, under the directory's lock (see the module
    /// documentation); on an error nothing is renamed (when the checks catch it) and the
    /// temporaries are removed.
    pub fn commit(mut self) -> Result<(), String> {
        for (_, dest) in &self.files {
            if dest.is_dir() {
                return Err(format!(
                    "{}: cannot write: a directory is in the way (nothing written)",
                    dest.display()
                ));
            }
        }
        // The directories of the files (usually one), each locked and recovered, in order.
        let mut dirs: Vec<PathBuf> = self.files.iter().map(|(_, d)| parent_dir(d)).collect();
        dirs.sort();
        dirs.dedup();
        let mut locks = Vec::new();
        for d in &dirs {
            if let Ok(f) = File::open(d)
                && f.lock().is_ok()
            {
                locks.push(f);
            }
            recover(d);
        }
        // The journal: the renames to finish should this process die among them.
        let journal = (dirs.len() == 1 && self.files.len() > 1)
            .then(|| dirs[0].join(format!(".rbss-commit.{}", std::process::id())));
        if let Some(j) = &journal {
            let mut text = String::new();
            for (tmp, dest) in &self.files {
                // Flushed before the journal names them: a journal never names a torn file.
                if let Ok(f) = File::open(tmp) {
                    let _ = f.sync_all();
                }
                let name = |p: &Path| p.file_name().map(|n| n.to_string_lossy().into_owned());
                if let (Some(t), Some(d)) = (name(tmp), name(dest)) {
                    text.push_str(&format!("{t}\t{d}\n"));
                }
            }
            let written = File::create(j).and_then(|mut f| {
                std::io::Write::write_all(&mut f, text.as_bytes())?;
                f.sync_all()
            });
            if let Err(e) = written {
                let _ = std::fs::remove_file(j);
                return Err(format!(
                    "{}: cannot write: {e} (nothing written)",
                    j.display()
                ));
            }
        }
        let files = std::mem::take(&mut self.files);
        let result = self.rename_all(&files);
        if let Some(j) = &journal {
            let _ = std::fs::remove_file(j);
        }
        for d in &dirs {
            if let Ok(f) = File::open(d) {
                let _ = f.sync_all();
            }
        }
        drop(locks);
        result
    }

    fn rename_all(&mut self, files: &[(PathBuf, PathBuf)]) -> Result<(), String> {
        let pause = std::env::var("RBSS_TEST_COMMIT_PAUSE_MS")
            .ok()
            .and_then(|v| v.parse::<u64>().ok());
        for (k, (tmp, dest)) in files.iter().enumerate() {
            if k > 0
                && let Some(ms) = pause
            {
                pause_between_renames(ms);
            }
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

/// The test hook `RBSS_TEST_COMMIT_PAUSE_MS`: a pause between the renames of a commit, so that a test can kill a run among them (tests/empty_out.rs).
fn pause_between_renames(ms: u64) {
    std::thread::sleep(std::time::Duration::from_millis(ms));
}

/// The directory a file is written in (`.` for a bare name).
fn parent_dir(p: &Path) -> PathBuf {
    match p.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Under the directory's lock: finishes the commits of runs killed among their renames (their
/// journals), and removes the temporaries of processes that are gone.
fn recover(dir: &Path) {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return;
    };
    let names: Vec<String> = rd
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    for name in &names {
        let Some(pid) = name.strip_prefix(".rbss-commit.") else {
            continue;
        };
        if pid.parse::<u32>().is_ok_and(alive) {
            continue;
        }
        let journal = dir.join(name);
        if let Ok(text) = std::fs::read_to_string(&journal) {
            for line in text.lines() {
                if let Some((t, d)) = line.split_once('\t') {
                    let tmp = dir.join(t);
                    if tmp.is_file() {
                        let _ = std::fs::rename(&tmp, dir.join(d));
                    }
                }
            }
        }
        let _ = std::fs::remove_file(&journal);
    }
    for name in &names {
        // `.NAME.PID-K.partial`
        let Some(stem) = name.strip_suffix(".partial") else {
            continue;
        };
        let pid = stem
            .rsplit('.')
            .next()
            .and_then(|pk| pk.split('-').next())
            .and_then(|p| p.parse::<u32>().ok());
        if let Some(pid) = pid
            && !alive(pid)
        {
            let _ = std::fs::remove_file(dir.join(name));
        }
    }
}

/// Whether the process `pid` runs (Linux: `/proc/PID`; elsewhere assumed, so nothing of a
/// live process is ever removed).
fn alive(pid: u32) -> bool {
    if pid == std::process::id() {
        return true;
    }
    let proc = Path::new("/proc");
    if !proc.join("self").exists() {
        return true;
    }
    proc.join(pid.to_string()).exists()
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
