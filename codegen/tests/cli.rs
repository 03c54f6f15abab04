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

/// A model file that is not UTF-8 is reported at the line and column of the first invalid byte
/// (it was `cannot read the model file: stream did not contain valid UTF-8`, no location), and a
/// 2 MB line is quoted around the error's column only (it was echoed whole) (issue 23).
#[test]
fn bad_bytes_are_located_and_long_lines_are_cut() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let model = std::fs::read(root.join("models/five_bar.toml")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let run = |file: &Path| {
        let out = Command::new(env!("CARGO_BIN_EXE_rbss-codegen"))
            .arg(file)
            .arg("--out")
            .arg(dir.path().join("out"))
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(1), "{out:?}");
        String::from_utf8(out.stderr).unwrap()
    };

    // Invalid bytes on the first line after 300 valid bytes.
    let mut bytes = model[..300].to_vec();
    let line = bytes.iter().filter(|&&b| b == b'\n').count() + 1;
    let col = bytes.len() - bytes.iter().rposition(|&b| b == b'\n').unwrap();
    bytes.extend_from_slice(b"\xff\xfe bad\n");
    bytes.extend_from_slice(&model[300..]);
    let file = dir.path().join("bad.toml");
    std::fs::write(&file, &bytes).unwrap();
    let stderr = run(&file);
    let head = format!(
        "{}:{line}:{col}: error: the model file is not valid UTF-8",
        file.display()
    );
    assert!(stderr.starts_with(&head), "{head} in {stderr}");

    // A 2 MB line: the error stays short and still points at the column.
    let text = String::from_utf8(model).unwrap().replacen(
        "name = \"five_bar\"",
        &format!("name = \"five_bar\" {}", "x".repeat(2_000_000)),
        1,
    );
    let file = dir.path().join("long.toml");
    std::fs::write(&file, text).unwrap();
    let stderr = run(&file);
    assert!(stderr.len() < 1000, "{} bytes of error", stderr.len());
    assert!(
        stderr.contains("TOML syntax") && stderr.contains("xxx..."),
        "{stderr}"
    );
}
