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
