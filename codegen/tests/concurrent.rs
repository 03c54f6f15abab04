//! Concurrent code generation, as cargo runs build scripts: four `rbss-codegen` processes
//! started at once on `models/five_bar.toml`, each writing to its own `--out` directory.
//!
//! Unlicensed, symbolica allows one symbolica thread per user on the machine and aborts
//! (SIGABRT) a second one, so this test passes only if the machine-wide lock
//! (`rbss_codegen::lock`) serialises the four: all exit 0, all write the same bytes, at least
//! three of them report waiting for the lock, and their symbolica phases (from the first
//! progress line after taking the lock to the last one before releasing it) do not overlap.
//!
//! The children use the *default* lock path (this test does not set `RBSS_LOCK_FILE`; an
//! `RBSS_LOCK_FILE` already in the environment is inherited, as every other codegen would see
//! it). A test-private lock file would serialise the four children among themselves only: a
//! codegen running at the same time elsewhere on the machine (`tests/regenerate.rs` and
//! `tests/ui_derive.rs` in another `cargo test`, another engineer's `rbss-codegen`, a build
//! script) holds the default lock, not the private one, and one of the two would abort. With
//! the default path they simply wait for each other, which is what the test is meant to show.
//! The cost: the test waits while another codegen holds the lock.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

const PROCESSES: usize = 4;
/// Generous: another codegen on the machine (the 6-UPS takes minutes) may hold the lock first.
const TIMEOUT: Duration = Duration::from_secs(1800);

/// One child's stderr lines with the time (since the start) at which each was read.
type Lines = Arc<Mutex<Vec<(f64, String)>>>;

fn spawn(root: &Path, out: &Path, t0: Instant) -> (Child, Lines, std::thread::JoinHandle<()>) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_rbss-codegen"))
        .current_dir(root)
        .args(["--out", out.to_str().unwrap(), "models/five_bar.toml"])
        .stdin(Stdio::null())
        .stdout(Stdio::null()) // symbolica's banner
        .stderr(Stdio::piped())
        .spawn()
        .expect("cannot start rbss-codegen");
    let lines: Lines = Arc::new(Mutex::new(Vec::new()));
    let stderr = child.stderr.take().unwrap();
    let sink = Arc::clone(&lines);
    let reader = std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines() {
            let Ok(line) = line else { break };
            sink.lock()
                .unwrap()
                .push((t0.elapsed().as_secs_f64(), line));
        }
    });
    (child, lines, reader)
}

fn files(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    for rel in ["Cargo.toml", "src/lib.rs", "src/five_bar.rs"] {
        let p = dir.join(rel);
        let bytes = std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        out.push((PathBuf::from(rel), bytes));
    }
    out
}

#[test]
fn four_codegens_at_once_wait_for_each_other() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let tmp = std::env::temp_dir().join(format!("rbss-concurrent-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    std::fs::create_dir_all(&tmp).unwrap();
    let lock = rbss_codegen::lock::lock_path();

    let t0 = Instant::now();
    let mut children: Vec<_> = (0..PROCESSES)
        .map(|k| spawn(&root, &tmp.join(format!("out{k}")), t0))
        .collect();

    // Wait for all, killing the rest (our own children only) on timeout.
    let mut statuses = [None; PROCESSES];
    while statuses.iter().any(|s| s.is_none()) {
        for (k, (child, _, _)) in children.iter_mut().enumerate() {
            if statuses[k].is_none() {
                statuses[k] = child.try_wait().unwrap();
            }
        }
        if t0.elapsed() > TIMEOUT {
            for (child, _, _) in children.iter_mut() {
                let _ = child.kill();
                let _ = child.wait();
            }
            panic!(
                "rbss-codegen did not finish in {} s (is another codegen holding {}?)",
                TIMEOUT.as_secs(),
                lock.display()
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let elapsed = t0.elapsed().as_secs_f64();
    let mut logs = Vec::new();
    for (_, lines, reader) in children {
        reader.join().unwrap();
        logs.push(Arc::try_unwrap(lines).unwrap().into_inner().unwrap());
    }
    let show = |k: usize| -> String {
        logs[k]
            .iter()
            .map(|(t, l)| format!("  [{t:8.3} s] {l}\n"))
            .collect()
    };

    // 1. Every process succeeded; none was aborted by symbolica.
    for (k, status) in statuses.iter().enumerate() {
        let status = status.unwrap();
        #[cfg(unix)]
        {
            use std::os::unix::process::ExitStatusExt;
            assert!(
                status.signal().is_none(),
                "rbss-codegen #{k} was killed by signal {:?} (SIGABRT = 6: symbolica refused a second \
                 concurrent user, the lock did not serialise them); its stderr:\n{}",
                status.signal(),
                show(k)
            );
        }
        assert!(
            status.success(),
            "rbss-codegen #{k} failed ({status}); its stderr:\n{}",
            show(k)
        );
    }

    // 2. The same bytes from every process.
    let first = files(&tmp.join("out0"));
    for k in 1..PROCESSES {
        let other = files(&tmp.join(format!("out{k}")));
        for ((p, a), (_, b)) in first.iter().zip(&other) {
            assert!(a == b, "{} differs between process 0 and {k}", p.display());
        }
    }

    // 3. The lock serialised them: all but the first waited for it ...
    let waiting = format!("waiting for the symbolica lock {}", lock.display());
    let waited = logs
        .iter()
        .filter(|log| log.iter().any(|(_, l)| l.contains(&waiting)))
        .count();
    // ... and their symbolica phases do not overlap. The phase runs from the first progress line
    // printed with the lock held (`[five_bar] frames`) to the last (`[five_bar] formatting`).
    // Lines are timestamped when this process reads them, so allow 50 ms of pipe latency.
    let mut phases: Vec<(f64, f64, usize)> = Vec::new();
    for (k, log) in logs.iter().enumerate() {
        let at = |needle: &str| {
            log.iter()
                .find(|(_, l)| l.contains(needle))
                .map(|(t, _)| *t)
                .unwrap_or_else(|| panic!("no `{needle}` line from #{k}:\n{}", show(k)))
        };
        phases.push((at("[five_bar] frames"), at("[five_bar] formatting"), k));
    }
    phases.sort_by(|a, b| a.0.total_cmp(&b.0));
    println!(
        "{PROCESSES} rbss-codegen processes in {elapsed:.2} s; {waited} waited for {}; symbolica phases:",
        lock.display()
    );
    for (start, end, k) in &phases {
        println!("  #{k}: {start:8.3} s .. {end:8.3} s");
    }
    assert!(
        waited >= PROCESSES - 1,
        "only {waited} of {PROCESSES} processes waited for the lock; stderr:\n{}",
        (0..PROCESSES).map(show).collect::<Vec<_>>().join("\n")
    );
    for w in phases.windows(2) {
        assert!(
            w[1].0 > w[0].1 - 0.05,
            "the symbolica phases of #{} ({:.3}..{:.3} s) and #{} ({:.3}..{:.3} s) overlap",
            w[0].2,
            w[0].0,
            w[0].1,
            w[1].2,
            w[1].0,
            w[1].1
        );
    }
    let _ = std::fs::remove_dir_all(&tmp);
}
