//! Concurrent code generation, as cargo runs build scripts: four `rbss-codegen` processes
//! started at once on `models/five_bar.toml`, each writing to its own `--out` directory.
//!
//! Code generation does not use symbolica (only the reference derivation in
//! `rbss_codegen::expanded` does, behind the machine-wide lock), so nothing serialises the four:
//! they must all exit 0, none aborted (unlicensed symbolica aborts a second concurrent user with
//! SIGABRT: this is what would catch generation reaching symbolica again), and all write the
//! same bytes.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

const PROCESSES: usize = 4;
/// Generous for a shared 2-core machine (one generation takes ~10 ms).
const TIMEOUT: Duration = Duration::from_secs(300);

/// One child's stderr lines with the time (since the start) at which each was read.
type Lines = Arc<Mutex<Vec<(f64, String)>>>;

fn spawn(root: &Path, out: &Path, t0: Instant) -> (Child, Lines, std::thread::JoinHandle<()>) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_rbss-codegen"))
        .current_dir(root)
        .args(["--out", out.to_str().unwrap(), "models/five_bar.toml"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
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
fn four_codegens_at_once_agree() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let tmpdir = tempfile::tempdir().unwrap();
    let tmp = tmpdir.path();

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
            panic!("rbss-codegen did not finish in {} s", TIMEOUT.as_secs());
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

    // 1. Every process succeeded; none was aborted.
    for (k, status) in statuses.iter().enumerate() {
        let status = status.unwrap();
        #[cfg(unix)]
        {
            use std::os::unix::process::ExitStatusExt;
            assert!(
                status.signal().is_none(),
                "rbss-codegen #{k} was killed by signal {:?} (SIGABRT = 6: symbolica refused a second \
                 concurrent user: did generation start using symbolica?); its stderr:\n{}",
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

    println!("{PROCESSES} rbss-codegen processes at once in {elapsed:.2} s");
}
