//! An empty output path (`--out "$DIR"` with `DIR` unset) is an error, never the current
//! directory: each command runs in an empty scratch directory, which must stay empty.

use std::process::Command;

/// Runs `rbss ARGS` in an empty directory; returns (success, stderr, files left there).
fn run_in_empty_dir(args: &[&str]) -> (bool, String, Vec<String>) {
    let tmp = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_rbss"))
        .args(args)
        .current_dir(tmp.path())
        .output()
        .unwrap();
    let left = std::fs::read_dir(tmp.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
        left,
    )
}

#[test]
fn every_output_path_refuses_the_empty_string() {
    let cases: &[&[&str]] = &[
        &["paper", "--out", ""],
        &["roundtrip", "--model", "five_bar", "--out", ""],
        &["roundtrip", "--model", "five_bar", "--out", "  "],
        &[
            "inverse-dynamics",
            "--model",
            "stewart_6ups",
            "--samples",
            "3",
            "--csv",
            "",
        ],
    ];
    for args in cases {
        let (ok, stderr, left) = run_in_empty_dir(args);
        assert!(!ok, "{args:?} succeeded");
        assert!(
            stderr.contains("an empty path names no file or directory"),
            "{args:?}: {stderr}"
        );
        assert!(left.is_empty(), "{args:?} wrote {left:?}");
    }
}

/// The library functions behind the commands refuse it too (no argument parser in between).
#[test]
fn the_library_refuses_the_empty_directory() {
    let e = rbss::create_output_dir(std::path::Path::new("")).unwrap_err();
    assert!(e.contains("an empty path"), "{e}");
}
