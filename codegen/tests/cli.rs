//! The `rbss-codegen` command's arguments: what it refuses before writing anything.

use std::path::Path;
use std::process::Command;

/// `--out ""` (an unset shell variable) is an error: before, the crate was written into the
/// current directory, and in the workspace root its Cargo.toml and src/lib.rs replaced the
/// project's own. The sentinel manifest in the working directory must survive untouched.
#[test]
fn an_empty_out_directory_is_refused() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let model = root.join("models/five_bar.toml");
    let tmpdir = tempfile::tempdir().unwrap();
    let manifest = tmpdir.path().join("Cargo.toml");
    std::fs::write(&manifest, "# the project's own manifest\n").unwrap();
    for out in ["", " "] {
        let run = Command::new(env!("CARGO_BIN_EXE_rbss-codegen"))
            .arg("--out")
            .arg(out)
            .arg(&model)
            .current_dir(tmpdir.path())
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{stderr}");
        assert!(
            stderr.contains("an empty path names no directory"),
            "{stderr}"
        );
        assert_eq!(
            std::fs::read_to_string(&manifest).unwrap(),
            "# the project's own manifest\n"
        );
        assert!(!tmpdir.path().join("src").exists());
    }
}

/// A closed pipe on stdout and stderr (`rbss-codegen ... 2>&1 | head -c1` once `head` exits):
/// the progress messages are dropped, the crate is still written, the exit status is 0 (it
/// was a panic, exit 101, at the first message, before anything was written).
#[test]
fn a_closed_output_pipe_does_not_stop_the_generation() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let tmpdir = tempfile::tempdir().unwrap();
    let out = tmpdir.path().join("crate");
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let status = Command::new(env!("CARGO_BIN_EXE_rbss-codegen"))
        .current_dir(&root)
        .arg("--out")
        .arg(&out)
        .arg("models/five_bar.toml")
        .stdout(writer.try_clone().unwrap())
        .stderr(writer)
        .status()
        .unwrap();
    assert_eq!(status.code(), Some(0), "{status}");
    assert!(out.join("src/five_bar.rs").is_file());
}
