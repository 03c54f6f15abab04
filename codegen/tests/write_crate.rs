//! Writing a generated crate to disk (`rbss_codegen::write_crate`, through `rbss-codegen
//! --out`): whole crates only, even with concurrent writers of two models on one directory;
//! no temporaries left; the user's own files kept; the runtime found from wherever the crate
//! is written.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn codegen(model: &str, out: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rbss-codegen"))
        .current_dir(root())
        .arg("--out")
        .arg(out)
        .arg(model)
        .output()
        .expect("cannot start rbss-codegen")
}

fn codegen_ok(model: &str, out: &Path) {
    let run = codegen(model, out);
    assert!(
        run.status.success(),
        "rbss-codegen --out {} {model}: {}\n{}",
        out.display(),
        run.status,
        String::from_utf8_lossy(&run.stderr)
    );
}

/// Every file under `dir` (relative path -> bytes).
fn tree(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    fn walk(base: &Path, dir: &Path, out: &mut BTreeMap<PathBuf, Vec<u8>>) {
        for e in std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(base, &p, out);
            } else {
                let rel = p.strip_prefix(base).unwrap().to_path_buf();
                out.insert(rel, std::fs::read(&p).unwrap());
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// 4 processes at once on one `--out` directory, two writing `five_bar` and two
/// `five_bar_turned` (different module files: `src/five_bar.rs`, `src/five_bar_turned.rs`),
/// for several rounds: after every round the directory is exactly one model's crate (as a
/// single run writes it) plus the user's file, and nothing else is left beside it but the lock.
#[test]
fn concurrent_writers_leave_one_whole_crate() {
    const ROUNDS: usize = 12;
    const PROCESSES: usize = 4;
    let models = ["models/five_bar.toml", "models/five_bar_turned.toml"];
    let tmp = tempfile::tempdir().unwrap();
    // References and the shared directory at the same depth: the same runtime path.
    let refs: Vec<_> = models
        .iter()
        .enumerate()
        .map(|(k, m)| {
            let dir = tmp.path().join(format!("ref{k}")).join("crate");
            codegen_ok(m, &dir);
            tree(&dir)
        })
        .collect();
    assert_ne!(refs[0], refs[1]);
    let parent = tmp.path().join("shared");
    let dir = parent.join("crate");
    codegen_ok(models[0], &dir);
    std::fs::write(dir.join("NOTES.md"), "the user's own file\n").unwrap();

    for round in 0..ROUNDS {
        let handles: Vec<_> = (0..PROCESSES)
            .map(|k| {
                let dir = dir.clone();
                // Which model each process writes turns with the round.
                let model = models[(k + round) % 2];
                std::thread::spawn(move || (model, codegen(model, &dir)))
            })
            .collect();
        for h in handles {
            let (model, run) = h.join().unwrap();
            assert!(
                run.status.success(),
                "round {round}: rbss-codegen {model}: {}\n{}",
                run.status,
                String::from_utf8_lossy(&run.stderr)
            );
        }
        let mut now = tree(&dir);
        assert_eq!(
            now.remove(Path::new("NOTES.md")).as_deref(),
            Some(&b"the user's own file\n"[..]),
            "round {round}: the user's file was lost"
        );
        assert!(
            refs.contains(&now),
            "round {round}: the crate is not one model's: files {:?}",
            now.keys().collect::<Vec<_>>()
        );
        assert_eq!(
            names(&parent),
            [".crate.rbss-lock", "crate"],
            "round {round}: temporaries left beside the crate"
        );
    }
    println!("{ROUNDS} rounds of {PROCESSES} concurrent writers: one whole crate after each");
}

/// Regenerating another model into a directory: the old model's module goes (it would mix two
/// models), the user's files stay (a `target/` and `Cargo.lock` from building in place, a
/// hand-written module); an unchanged crate is not rewritten (cargo would rebuild it).
#[test]
fn regeneration_drops_the_old_model_and_keeps_the_users_files() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("crate");
    codegen_ok("models/five_bar.toml", &dir);
    std::fs::create_dir_all(dir.join("target/release")).unwrap();
    std::fs::write(dir.join("target/release/artefact"), "built").unwrap();
    std::fs::write(dir.join("Cargo.lock"), "# lock").unwrap();
    std::fs::write(dir.join("src/helper.rs"), "// mine\n").unwrap();
    // What versions before the whole-directory swap left on a kill.
    std::fs::write(dir.join("src/lib.rbss-tmp"), "half").unwrap();

    let module = dir.join("src/five_bar.rs");
    let before = std::fs::metadata(&module).unwrap().modified().unwrap();
    std::thread::sleep(std::time::Duration::from_millis(20));
    codegen_ok("models/five_bar.toml", &dir);
    // The stale temporary made the crate differ: rewritten, but the module, unchanged, keeps
    // its modification time.
    assert!(!dir.join("src/lib.rbss-tmp").exists());
    assert_eq!(
        std::fs::metadata(&module).unwrap().modified().unwrap(),
        before
    );

    codegen_ok("models/five_bar_turned.toml", &dir);
    let files: Vec<_> = tree(&dir).into_keys().collect();
    let expected: Vec<PathBuf> = [
        "Cargo.lock",
        "Cargo.toml",
        "rbss-manifest.toml",
        "src/five_bar_turned.rs",
        "src/helper.rs",
        "src/lib.rs",
        "target/release/artefact",
    ]
    .iter()
    .map(PathBuf::from)
    .collect();
    assert_eq!(files, expected);
    assert_eq!(names(tmp.path()), [".crate.rbss-lock", "crate"]);
}

/// A target that is a file: refused, the file untouched, no temporaries.
#[test]
fn a_file_in_place_of_the_directory_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("crate");
    std::fs::write(&dir, "not a directory").unwrap();
    let run = codegen("models/five_bar.toml", &dir);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("is not a directory"), "{stderr}");
    assert_eq!(std::fs::read_to_string(&dir).unwrap(), "not a directory");
    assert_eq!(names(tmp.path()), [".crate.rbss-lock", "crate"]);
}

/// `--out DIR` anywhere: the crate's `rbss-runtime` path leads to this workspace's runtime
/// (it was `../../runtime`, right only two levels below the workspace), relative or absolute,
/// from a relative or an absolute DIR.
#[test]
fn the_runtime_path_is_right_wherever_the_crate_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    let runtime = root().join("runtime").canonicalize().unwrap();
    // Relative to the workspace root, where the command runs.
    let inside = PathBuf::from(format!("target/rbss-out-test-{}", std::process::id()));
    let cases = [
        tmp.path().join("a/b/c/crate"),
        tmp.path().join("crate"),
        inside.join("deep/er/crate"),
    ];
    for out in &cases {
        codegen_ok("models/five_bar.toml", out);
        let dir = &root().join(out);
        let manifest = std::fs::read_to_string(dir.join("Cargo.toml")).unwrap();
        let line = manifest
            .lines()
            .find(|l| l.starts_with("rbss-runtime = { path = \""))
            .unwrap_or_else(|| panic!("no rbss-runtime dependency in\n{manifest}"));
        let path = line
            .trim_start_matches("rbss-runtime = { path = \"")
            .trim_end_matches("\" }");
        let resolved = dir.join(path).canonicalize();
        assert_eq!(
            resolved.as_ref().ok(),
            Some(&runtime),
            "{}: `{path}` does not lead to the runtime",
            dir.display()
        );
        assert!(dir.join(path).join("Cargo.toml").exists());
    }
    let _ = std::fs::remove_dir_all(root().join(&inside));
    // The default place, generated/NAME, keeps its `../../runtime`.
    let run = Command::new(env!("CARGO_BIN_EXE_rbss-codegen"))
        .current_dir(root())
        .args(["--check", "models/five_bar.toml"])
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
}
