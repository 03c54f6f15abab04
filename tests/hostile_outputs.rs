//! The `rbss` command against hostile conditions (issue 23): concurrent runs into one output
//! directory, outputs that cannot be written, absurd sample counts, a closed stdout. Each a
//! typed error or a quiet end, never a panic (exit 101), never a half-written set of files.

use std::path::Path;
use std::process::{Command, Output, Stdio};

fn rbss(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rbss"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdin(Stdio::null())
        .output()
        .expect("cannot start rbss")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Names in `dir`, sorted.
fn entries(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

fn no_partials(dir: &Path) {
    let left: Vec<_> = entries(dir)
        .into_iter()
        .filter(|n| n.contains("partial"))
        .collect();
    assert!(left.is_empty(), "temporaries left: {left:?}");
}

/// 8 `rbss roundtrip` at once into one `--out`: before, their temporaries had one name
/// (`roundtrip.csv.partial`), one run renamed another's away and 1-5 of 8 failed with "cannot
/// write: No such file or directory". Now all succeed and leave exactly the two files.
#[test]
fn eight_concurrent_roundtrips_into_one_directory() {
    const RUNS: usize = 8;
    const ROUNDS: usize = 5;
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let out_s = out.to_str().unwrap().to_string();
    for round in 0..ROUNDS {
        let handles: Vec<_> = (0..RUNS)
            .map(|_| {
                let out_s = out_s.clone();
                std::thread::spawn(move || {
                    rbss(&["roundtrip", "--model", "five_bar", "--out", &out_s])
                })
            })
            .collect();
        let mut failed = Vec::new();
        for (k, h) in handles.into_iter().enumerate() {
            let o = h.join().unwrap();
            if !o.status.success() {
                failed.push(format!("run {k}: {}: {}", o.status, stderr(&o)));
            }
        }
        assert!(
            failed.is_empty(),
            "round {round}: {} of {RUNS} failed:\n{}",
            failed.len(),
            failed.join("\n")
        );
        assert_eq!(entries(&out), ["roundtrip.csv", "roundtrip.png"]);
    }
    println!("{ROUNDS} rounds of {RUNS} concurrent roundtrips: all succeeded");
}

/// A run that cannot write one of its files (a directory where `roundtrip.png` goes) writes
/// none: the old `roundtrip.csv` stays, and no temporary is left. Before, the CSV was
/// replaced and a `roundtrip.partial.png` left.
#[test]
fn a_failed_roundtrip_keeps_the_old_files_and_leaves_no_temporaries() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path();
    std::fs::write(out.join("roundtrip.csv"), "the previous run's\n").unwrap();
    std::fs::create_dir(out.join("roundtrip.png")).unwrap();
    let o = rbss(&[
        "roundtrip",
        "--model",
        "five_bar",
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("roundtrip.png: cannot write: a directory is in the way"),
        "{err}"
    );
    assert_eq!(
        std::fs::read_to_string(out.join("roundtrip.csv")).unwrap(),
        "the previous run's\n"
    );
    no_partials(out);
    assert_eq!(entries(out), ["roundtrip.csv", "roundtrip.png"]);
}

/// `rbss inverse-dynamics --csv DIR` (a directory): an error naming it, no temporary left.
#[test]
fn inverse_dynamics_into_a_directory_leaves_no_temporary() {
    let tmp = tempfile::tempdir().unwrap();
    let csv = tmp.path().join("u.csv");
    std::fs::create_dir(&csv).unwrap();
    let o = rbss(&[
        "inverse-dynamics",
        "--model",
        "stewart_6ups",
        "--samples",
        "3",
        "--csv",
        csv.to_str().unwrap(),
    ]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("u.csv: cannot write"), "{err}");
    no_partials(tmp.path());
    assert_eq!(entries(tmp.path()), ["u.csv"]);
}

/// `--samples 18446744073709551615` (u64::MAX): a clear error before any work, not a panic
/// on the allocation (capacity overflow, exit 101); nothing written.
#[test]
fn absurd_sample_counts_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let csv = tmp.path().join("u.csv");
    let paper_out = tmp.path().join("paper");
    let big = u64::MAX.to_string();
    let over = (rbss::trajectory::MAX_SAMPLES + 1).to_string();
    for samples in [big.as_str(), over.as_str()] {
        for args in [
            vec![
                "inverse-dynamics",
                "--model",
                "stewart_6ups",
                "--samples",
                samples,
                "--csv",
                csv.to_str().unwrap(),
            ],
            vec![
                "paper",
                "--samples",
                samples,
                "--out",
                paper_out.to_str().unwrap(),
            ],
        ] {
            let o = rbss(&args);
            let err = stderr(&o);
            assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
            assert!(
                err.contains(&format!("--samples {samples}: at most 1000000")),
                "{args:?}: {err}"
            );
        }
    }
    assert!(entries(tmp.path()).is_empty());
}

/// Commands that print results, with stdout a pipe nobody reads (`rbss list | head -c1` once
/// `head` has exited): a quiet end with status 0, not a panic (exit 101, "failed printing to
/// stdout: Broken pipe").
#[test]
fn a_closed_stdout_ends_quietly() {
    let tmp = tempfile::tempdir().unwrap();
    let states = tmp.path().join("states.json");
    let home = five_bar::STRUCTURE.home.to_vec();
    let xdot = vec![0.0; home.len()];
    std::fs::write(
        &states,
        serde_json::json!({"states": [{"X": home, "Xdot": xdot}]}).to_string(),
    )
    .unwrap();
    let cases: [&[&str]; 4] = [
        &["list"],
        &["ik", "--model", "five_bar", "--pose", "0.05,0.32"],
        &["fk", "--model", "five_bar", "--q", "2.0,1.2"],
        &[
            "eval",
            "--model",
            "five_bar",
            "--states",
            states.to_str().unwrap(),
        ],
    ];
    for args in cases {
        // The command's output must be there to write: check it first with a live pipe.
        let live = rbss(args);
        assert!(
            live.status.success() && !live.stdout.is_empty(),
            "{args:?}: {}",
            stderr(&live)
        );
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let o = Command::new(env!("CARGO_BIN_EXE_rbss"))
            .args(args)
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .stdin(Stdio::null())
            .stdout(writer)
            .stderr(Stdio::piped())
            .output()
            .unwrap();
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(0), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
}

/// A study that prints its table as it goes (`rbss bench solvers`), with a closed stdout: the
/// table is dropped, the run completes and writes its CSV, status 0 (it panicked, exit 101).
#[cfg(feature = "studies")]
#[test]
fn a_study_with_a_closed_stdout_still_writes_its_files() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let o = Command::new(env!("CARGO_BIN_EXE_rbss"))
        .args([
            "bench",
            "solvers",
            "--model",
            "five_bar",
            "--batches",
            "1",
            "--out",
        ])
        .arg(&out)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdin(Stdio::null())
        .stdout(writer)
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(0), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(entries(&out), ["solvers.csv"]);
}

/// A study's files are committed together too: `rbss stress fk` with a directory where
/// `fk_rates.png` goes writes none of fk.md, fk_rates.csv, fk_iterations.csv (before, those
/// three were written and the run failed at the figure).
#[cfg(feature = "studies")]
#[test]
fn a_failed_study_writes_none_of_its_files() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path();
    std::fs::create_dir(out.join("fk_rates.png")).unwrap();
    let o = rbss(&[
        "stress",
        "fk",
        "--samples",
        "20",
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("a directory is in the way"), "{err}");
    assert_eq!(entries(out), ["fk_rates.png"]);
}
