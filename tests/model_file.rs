//! `--model-file` (src/model_file.rs): a model file's robot generated, compiled into a library,
//! cached and loaded, through the command. One test, in order, on one cache (a temporary
//! directory; cargo builds in this workspace's target directory, so the runtime and its
//! dependencies are compiled once): a fresh cache builds, the next run loads, an edited model
//! is rebuilt (its answer checked against the five-bar's closed-form inverse kinematics), `rbss
//! list --model-file` lists the cached robot as `rbss list` does the compiled-in one, a
//! corrupt library or stamp is rebuilt, and a missing toolchain or a bad model file is a clear
//! error. With the studies, a second test runs `rbss bench` on a model file (the library's
//! studies variant).

use std::path::{Path, PathBuf};
use std::process::Command;

/// `target/`: where cargo builds the cache's libraries (the directory of this build).
fn target_dir() -> PathBuf {
    Path::new(env!("CARGO_BIN_EXE_rbss"))
        .parent()
        .and_then(Path::parent)
        .unwrap()
        .to_path_buf()
}

/// Runs `rbss args` with the cache in `cache`; (success, stdout, stderr).
fn rbss(cache: &Path, args: &[&str], env: &[(&str, &str)]) -> (bool, String, String) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_rbss"));
    cmd.args(args)
        .env("RBSS_CACHE", cache)
        .env("RBSS_CACHE_TARGET", target_dir())
        .env_remove("RBSS_CODEGEN");
    for (k, v) in env {
        cmd.env(k, v);
    }
    let out = cmd.output().unwrap();
    (
        out.status.success(),
        String::from_utf8(out.stdout).unwrap(),
        String::from_utf8(out.stderr).unwrap(),
    )
}

/// `th1` of `rbss ik --json` output.
fn th1(stdout: &str) -> f64 {
    let v: serde_json::Value = serde_json::from_str(stdout).unwrap();
    v["coordinates"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["name"] == "th1")
        .unwrap()["value"]
        .as_f64()
        .unwrap()
}

/// The five-bar's left elbow angle at the effector position `p` (models/five_bar.toml's
/// header): `th1 = atan2(P - B1) + acos((l1² + D² - l2²) / (2 l1 D))`, `B1 = (-b, 0)`.
fn th1_closed_form(p: [f64; 2], b: f64, l1: f64, l2: f64) -> f64 {
    let (dx, dy) = (p[0] + b, p[1]);
    let d = dx.hypot(dy);
    dy.atan2(dx) + ((l1 * l1 + d * d - l2 * l2) / (2.0 * l1 * d)).acos()
}

/// The cache's entries (`robots/KEY/`).
fn entries(cache: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(cache.join("robots"))
        .map(|rd| {
            rd.flatten()
                .map(|e| e.path())
                .filter(|p| p.is_dir())
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

#[test]
fn fresh_cached_stale_and_corrupt_cache() {
    let tmp = tempfile::Builder::new()
        .prefix("rbss-model-file-")
        .tempdir()
        .unwrap();
    let cache = tmp.path().join("cache");
    let model = tmp.path().join("five_bar.toml");
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let source = std::fs::read_to_string(root.join("models/five_bar.toml")).unwrap();
    std::fs::write(&model, &source).unwrap();
    let model_arg = model.to_str().unwrap();
    let ik = [
        "ik",
        "--model-file",
        model_arg,
        "--pose",
        "0.05,0.32",
        "--json",
    ];

    // Fresh: generated and compiled; the same answer as the robot compiled into the command.
    let (ok, fresh, stderr) = rbss(&cache, &ik, &[]);
    assert!(ok, "{stderr}");
    assert!(stderr.contains("compiling robot `five_bar`"), "{stderr}");
    let (ok, builtin, stderr_b) = rbss(
        &cache,
        &["ik", "--model", "five_bar", "--pose", "0.05,0.32", "--json"],
        &[],
    );
    assert!(ok, "{stderr_b}");
    assert_eq!(
        fresh, builtin,
        "the library and the compiled-in robot differ"
    );
    assert_eq!(entries(&cache).len(), 1);

    // Cached: loaded, not compiled; the same answer. Another subcommand through the same
    // library (forward kinematics back from the inverse's actuated values).
    let (ok, cached, stderr) = rbss(&cache, &ik, &[]);
    assert!(ok, "{stderr}");
    assert!(!stderr.contains("compiling"), "{stderr}");
    assert_eq!(cached, fresh);
    let (ok, fk, stderr) = rbss(
        &cache,
        &[
            "fk",
            "--model-file",
            model_arg,
            "--q",
            "1.665079729680785,1.0375962841620",
        ],
        &[],
    );
    assert!(ok, "{stderr}");
    assert!(!stderr.contains("compiling"), "{stderr}");
    assert!(fk.contains("x        =     0.050000"), "{fk}");
    // `rbss list --model-file`: the robot's description, as `rbss list --model` gives the
    // compiled-in one (text and JSON).
    for json in [false, true] {
        let flag: &[&str] = if json { &["--json"] } else { &[] };
        let (ok, listed, stderr) = rbss(
            &cache,
            &[&["list", "--model-file", model_arg], flag].concat(),
            &[],
        );
        assert!(ok, "{stderr}");
        assert!(!stderr.contains("compiling"), "{stderr}");
        let (ok, builtin, stderr) = rbss(
            &cache,
            &[&["list", "--model", "five_bar"], flag].concat(),
            &[],
        );
        assert!(ok, "{stderr}");
        assert_eq!(listed, builtin);
    }
    let (ok, listed, _) = rbss(&cache, &["list", "--model-file", model_arg], &[]);
    assert!(ok);
    assert!(listed.contains("left: 0 x, 1 y"), "{listed}");

    // The subcommands so far ran in the plain library: the robot without its derivative
    // kernel, behind the command alone (its only C symbols: the command's entry and the ABI
    // version the loader checks).
    let plain = entries(&cache).remove(0);
    let robot_lib = std::fs::read_to_string(plain.join("robot-lib.rs")).unwrap();
    assert!(robot_lib.contains("without_derivatives"), "{robot_lib}");
    let library = plain.join(format!(
        "{}robot{}",
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    ));
    // SAFETY: a library the command built from these sources; only symbols are looked up.
    let lib = unsafe { libloading::Library::new(&library) }.unwrap();
    for (symbol, exported) in [
        ("rbss_command", true),
        ("rbss_abi_version", true),
        ("rbss_forward_dynamics", false),
        ("rbss_forward_dynamics_derivatives", false),
    ] {
        // SAFETY: looked up, never called.
        let found = unsafe { lib.get::<unsafe extern "C" fn()>(symbol.as_bytes()) }.is_ok();
        assert_eq!(found, exported, "{symbol} in {}", library.display());
    }
    drop(lib);

    // `rbss linearize --model-file` (issue 36): through the library, the JSON of the
    // compiled-in robot (A, B, the full derivatives), in both coordinates; a state off the
    // constraints refused alike. Its first run builds the model's full library (with the
    // derivative kernel and the C ABI): a second entry, which `id-derivatives` then uses too.
    let m = rbss_runtime::Model::new(five_bar::FiveBar::default());
    let mut d = rbss_runtime::Data::new(&m);
    rbss_runtime::inverse_velocity(&m, &mut d, &[0.2, -0.1]).unwrap();
    let state = tmp.path().join("state.json");
    let json = |x: &[f64]| {
        serde_json::json!({"X": x, "Xdot": d.xdot.to_vec(), "U": [0.05, -0.02]}).to_string()
    };
    std::fs::write(&state, json(&d.x)).unwrap();
    let state_arg = state.to_str().unwrap();
    for coordinates in ["outputs", "actuated"] {
        let run = |robot: [&str; 2]| {
            rbss(
                &cache,
                &[
                    "linearize",
                    robot[0],
                    robot[1],
                    "--state",
                    state_arg,
                    "--coordinates",
                    coordinates,
                ],
                &[],
            )
        };
        let (ok, from_file, stderr) = run(["--model-file", model_arg]);
        assert!(ok, "{stderr}");
        assert_eq!(
            stderr.contains("compiling robot `five_bar`"),
            coordinates == "outputs",
            "{stderr}"
        );
        let (ok, builtin, stderr) = run(["--model", "five_bar"]);
        assert!(ok, "{stderr}");
        assert_eq!(from_file, builtin, "linearize --coordinates {coordinates}");
        let v: serde_json::Value = serde_json::from_str(&from_file).unwrap();
        assert_eq!(v["A"].as_array().unwrap().len(), 4, "A is 2d x 2d, d = 2");
    }
    let mut off = d.x;
    off[4] += 0.01;
    std::fs::write(&state, json(&off)).unwrap();
    let (ok, _, from_file) = rbss(
        &cache,
        &["linearize", "--model-file", model_arg, "--state", state_arg],
        &[],
    );
    assert!(!ok);
    let (_, _, builtin) = rbss(
        &cache,
        &["linearize", "--model", "five_bar", "--state", state_arg],
        &[],
    );
    assert!(from_file.contains("not consistent"), "{from_file}");
    assert_eq!(from_file, builtin);

    // `rbss id-derivatives --model-file`: the compiled-in robot's JSON (U, lambda, the six
    // matrices) at a motion with an acceleration.
    let motion = tmp.path().join("motion.json");
    let xddot: Vec<f64> = (0..d.x.len()).map(|i| 0.3 - 0.1 * i as f64).collect();
    std::fs::write(
        &motion,
        serde_json::json!({"X": d.x.to_vec(), "Xdot": d.xdot.to_vec(), "Xddot": xddot}).to_string(),
    )
    .unwrap();
    let motion_arg = motion.to_str().unwrap();
    let run = |robot: [&str; 2]| {
        rbss(
            &cache,
            &["id-derivatives", robot[0], robot[1], "--state", motion_arg],
            &[],
        )
    };
    let (ok, from_file, stderr) = run(["--model-file", model_arg]);
    assert!(ok, "{stderr}");
    assert!(!stderr.contains("compiling"), "{stderr}");
    assert_eq!(entries(&cache).len(), 2, "the plain and the full library");
    let (ok, builtin, stderr) = run(["--model", "five_bar"]);
    assert!(ok, "{stderr}");
    assert_eq!(from_file, builtin, "id-derivatives");
    let v: serde_json::Value = serde_json::from_str(&from_file).unwrap();
    assert_eq!(v["dU_dXddot"].as_array().unwrap().len(), 2, "k rows");

    // Stale: the model edited (l2 0.25 -> 0.26): a new entry, whose answer is the closed
    // form's for the new length (and differs from the old one's).
    let edited = source.replace("l2 = { value = 0.25,", "l2 = { value = 0.26,");
    assert_ne!(edited, source);
    std::fs::write(&model, &edited).unwrap();
    let (ok, stale, stderr) = rbss(&cache, &ik, &[]);
    assert!(ok, "{stderr}");
    assert!(stderr.contains("compiling robot `five_bar`"), "{stderr}");
    let want_old = th1_closed_form([0.05, 0.32], 0.15, 0.2, 0.25);
    let want_new = th1_closed_form([0.05, 0.32], 0.15, 0.2, 0.26);
    assert!(
        (th1(&fresh) - want_old).abs() < 1e-9,
        "{} vs {want_old}",
        th1(&fresh)
    );
    assert!(
        (th1(&stale) - want_new).abs() < 1e-9,
        "{} vs {want_new}",
        th1(&stale)
    );
    assert!((want_new - want_old).abs() > 1e-3);
    let all = entries(&cache);
    assert_eq!(
        all.len(),
        3,
        "the first model's two libraries, the edit's: {all:?}"
    );

    // Corrupt: the current entry's library truncated, then its stamp naming another key:
    // each is rebuilt with a message, never a crash.
    let current = all
        .iter()
        .find(|e| {
            std::fs::read_to_string(e.join("robot/rbss-manifest.toml"))
                .unwrap()
                .contains(&format!(
                    "model_sha256 = \"{}\"",
                    sha256_hex(edited.as_bytes())
                ))
        })
        .expect("the edited model's entry")
        .clone();
    let lib = std::fs::read_dir(&current)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| {
            p.file_name()
                .unwrap()
                .to_string_lossy()
                .starts_with(std::env::consts::DLL_PREFIX)
        })
        .unwrap();
    std::fs::write(&lib, b"not a library").unwrap();
    let (ok, again, stderr) = rbss(&cache, &ik, &[]);
    assert!(ok, "{stderr}");
    assert!(
        stderr.contains("unusable") && stderr.contains("rebuilding"),
        "{stderr}"
    );
    assert_eq!(again, stale);
    // Truncated to 1 MiB (what a crash during the copy can leave; before, every run died of
    // SIGBUS when the library was mapped): its size is not the stamp's, so it is rebuilt.
    let full_len = std::fs::metadata(&lib).unwrap().len();
    assert!(full_len > 1 << 20, "{full_len}");
    std::fs::OpenOptions::new()
        .write(true)
        .open(&lib)
        .unwrap()
        .set_len(1 << 20)
        .unwrap();
    let (ok, again, stderr) = rbss(&cache, &ik, &[]);
    assert!(ok, "{stderr}");
    assert!(
        stderr.contains("its stamp says") && stderr.contains("rebuilding"),
        "{stderr}"
    );
    assert_eq!(again, stale);
    // The same size, other bytes: its SHA-256 is not the stamp's.
    let mut bytes = std::fs::read(&lib).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x55;
    std::fs::write(&lib, &bytes).unwrap();
    let (ok, again, stderr) = rbss(&cache, &ik, &[]);
    assert!(ok, "{stderr}");
    assert!(
        stderr.contains("SHA-256") && stderr.contains("rebuilding"),
        "{stderr}"
    );
    assert_eq!(again, stale);
    let stamp = std::fs::read_to_string(current.join("ok")).unwrap();
    let key = current.file_name().unwrap().to_str().unwrap();
    std::fs::write(
        current.join("ok"),
        stamp.replace(key, "0123456789abcdef0123456789abcdef"),
    )
    .unwrap();
    let (ok, again, stderr) = rbss(&cache, &ik, &[]);
    assert!(ok, "{stderr}");
    assert!(
        stderr.contains("another key") && stderr.contains("rebuilding"),
        "{stderr}"
    );
    assert_eq!(again, stale);

    // Warm, the cache serves without a toolchain (the library is verified, not rebuilt) ...
    let (ok, warm, stderr) = rbss(
        &cache,
        &ik,
        &[
            ("CARGO", "/nonexistent/cargo"),
            ("RUSTC", "/nonexistent/rustc"),
        ],
    );
    assert!(ok, "{stderr}");
    assert_eq!(warm, stale);
    assert!(stderr.contains("using the cached library"), "{stderr}");
    // ... and read-only (no lock file written), unless the tests run as root.
    let robots = cache.join("robots");
    let mode = |m: u32| {
        use std::os::unix::fs::PermissionsExt as _;
        std::fs::set_permissions(&robots, std::fs::Permissions::from_mode(m)).unwrap();
    };
    let locks_before = std::fs::read_dir(&robots).unwrap().flatten().count();
    mode(0o555);
    let (ok, ro, stderr) = rbss(&cache, &ik, &[]);
    mode(0o755);
    assert!(ok, "read-only cache: {stderr}");
    assert_eq!(ro, stale);
    assert_eq!(
        std::fs::read_dir(&robots).unwrap().flatten().count(),
        locks_before
    );

    // `rbss cache list`: the three entries, the robot's name, the model file; pruning to the
    // current entry's size removes the least recently used (the first model's two) first,
    // never a stamp-less build.
    let (ok, listed, stderr) = rbss(&cache, &["cache", "list"], &[]);
    assert!(ok, "{stderr}");
    assert_eq!(listed.matches(" five_bar ").count(), 3, "{listed}");
    assert!(listed.contains(model_arg), "{listed}");
    assert!(listed.contains("3 entries"), "{listed}");
    let (ok, pruned, stderr) = rbss(
        &cache,
        &[
            "cache",
            "prune",
            "--max-size",
            &dir_size(&current).to_string(),
        ],
        &[],
    );
    assert!(ok, "{stderr}");
    assert!(pruned.contains("2 entries removed"), "{pruned}");
    let left = entries(&cache);
    assert_eq!(left, vec![current.clone()], "{pruned}");
    // The remaining entry still serves, from the cache.
    let (ok, again, stderr) = rbss(&cache, &ik, &[]);
    assert!(ok && !stderr.contains("compiling"), "{stderr}");
    assert_eq!(again, stale);

    // No toolchain: a clear error, exit status 1.
    let other = tmp.path().join("cache2");
    let (ok, _, stderr) = rbss(&other, &ik, &[("CARGO", "/nonexistent/cargo")]);
    assert!(!ok);
    assert!(
        stderr.contains("rbss: error: cannot run cargo `/nonexistent/cargo`")
            && stderr.contains("needs a Rust toolchain"),
        "{stderr}"
    );

    // A bad model file: the generator's diagnostic (file, line, column), nothing cached.
    std::fs::write(
        &model,
        source.replace("l2 = { value = 0.25,", "l2 = { value = ,"),
    )
    .unwrap();
    let (ok, _, stderr) = rbss(&cache, &ik, &[]);
    assert!(!ok);
    assert!(
        stderr.contains(&format!("{model_arg}:43:")),
        "no file:line: in {stderr}"
    );
    assert_eq!(entries(&cache).len(), 1);
}

/// Runs `rbss args` in `cwd` with the cache in `cache` (and `env`); (success, stdout, stderr).
fn rbss_in(
    cache: &Path,
    cwd: &Path,
    args: &[&str],
    env: &[(&str, &str)],
) -> (bool, String, String) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_rbss"));
    cmd.args(args)
        .current_dir(cwd)
        .env("RBSS_CACHE", cache)
        .env("RBSS_CACHE_TARGET", target_dir())
        .env_remove("RBSS_CODEGEN");
    for (k, v) in env {
        cmd.env(k, v);
    }
    let out = cmd.output().unwrap();
    (
        out.status.success(),
        String::from_utf8(out.stdout).unwrap(),
        String::from_utf8(out.stderr).unwrap(),
    )
}

/// Every number of the attributes `names` in an XML text multiplied by 10 (masses, inertias,
/// densities: the robot's mass matrix and gravity forces become 10 times the old ones).
fn scale_attributes(xml: &str, names: &[&str]) -> String {
    let mut out = xml.to_string();
    for name in names {
        let pat = format!(" {name}=\"");
        let mut from = 0;
        while let Some(i) = out[from..].find(&pat) {
            let start = from + i + pat.len();
            let end = start + out[start..].find('"').unwrap();
            let scaled: Vec<String> = out[start..end]
                .split_whitespace()
                .map(|v| format!("{:?}", v.parse::<f64>().unwrap() * 10.0))
                .collect();
            let scaled = scaled.join(" ");
            out.replace_range(start..end, &scaled);
            from = start + scaled.len();
        }
    }
    assert_ne!(out, xml);
    out
}

/// `M` and `psi` of `rbss eval --model-file MODEL` at the state `x` (zero rates), run in `cwd`.
fn mass_and_psi(cache: &Path, cwd: &Path, model: &str, x: &[f64]) -> (Vec<f64>, Vec<f64>, String) {
    let states = cwd.join("states.json");
    std::fs::write(
        &states,
        serde_json::json!({"states": [{"X": x, "Xdot": vec![0.0; x.len()]}]}).to_string(),
    )
    .unwrap();
    let (ok, stdout, stderr) = rbss_in(
        cache,
        cwd,
        &[
            "eval",
            "--model-file",
            model,
            "--states",
            states.to_str().unwrap(),
        ],
        &[],
    );
    assert!(ok, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let m = v["states"][0]["M"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|r| r.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()))
        .collect();
    let psi = v["states"][0]["psi"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    (m, psi, stderr)
}

/// `a` is 10 `b`, entry by entry (to 1e-9 of the largest entry).
fn assert_ten_times(what: &str, a: &[f64], b: &[f64]) {
    assert_eq!(a.len(), b.len());
    let scale = b.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    assert!(scale > 0.0);
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(
            (x - 10.0 * y).abs() <= 1e-9 * 10.0 * scale,
            "{what}[{i}]: {x} is not 10 x {y}"
        );
    }
}

/// The files a model includes are in the key (issue 37, finding 1): an MJCF model whose
/// bodies are in an `<include>`d file, the same relative path run from two directories with
/// different includes, the include edited, and an include edited while the robot is being
/// generated. With every mass and inertia of the include 10 times larger, `M` and `psi`
/// (gravity only, at rest) must be 10 times the first ones; before, each run after the first
/// got the first directory's robot.
#[test]
fn mjcf_include_edits_and_two_directories() {
    let tmp = tempfile::Builder::new()
        .prefix("rbss-model-file-mjcf-")
        .tempdir()
        .unwrap();
    let cache = tmp.path().join("cache");
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("codegen/tests/import");
    let bodies = std::fs::read_to_string(src.join("four_bar_bodies.xml")).unwrap();
    let heavy = scale_attributes(&bodies, &["mass", "diaginertia", "density"]);
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    for (dir, body_text) in [(&a, &bodies), (&b, &heavy)] {
        std::fs::create_dir_all(dir).unwrap();
        for f in ["four_bar_split.toml", "four_bar_split.xml"] {
            std::fs::copy(src.join(f), dir.join(f)).unwrap();
        }
        std::fs::write(dir.join("four_bar_bodies.xml"), body_text).unwrap();
    }
    // The second source has a sensor, which the importer skips with a warning: the first run
    // (the one that generates) shows it, at the sensor's line.
    let with_sensor = std::fs::read_to_string(b.join("four_bar_split.xml"))
        .unwrap()
        .replace(
            "</mujoco>",
            "  <sensor>\n    <jointpos joint=\"th1\"/>\n  </sensor>\n</mujoco>",
        );
    std::fs::write(b.join("four_bar_split.xml"), &with_sensor).unwrap();
    let sensor_line = with_sensor
        .lines()
        .position(|l| l.contains("<sensor>"))
        .unwrap()
        + 1;
    let x = [0.2, -0.1, 0.1];
    let model = "four_bar_split.toml";
    let (m1, psi1, stderr) = mass_and_psi(&cache, &a, model, &x);
    assert!(stderr.contains("compiling robot"), "{stderr}");
    assert!(!stderr.contains("warning"), "{stderr}");
    // The same relative path in another directory: another robot.
    let (m2, psi2, stderr) = mass_and_psi(&cache, &b, model, &x);
    assert!(stderr.contains("compiling robot"), "{stderr}");
    let warning = stderr
        .lines()
        .find(|l| l.contains(": warning: "))
        .unwrap_or_else(|| panic!("no warning: {stderr}"));
    assert!(
        warning.contains(&format!("four_bar_split.xml:{sensor_line}:"))
            && warning.ends_with("sensors are skipped"),
        "{warning}"
    );
    assert_ten_times("M", &m2, &m1);
    assert_ten_times("psi", &psi2, &psi1);
    // Cached: the first directory's robot again, not compiled.
    let (m1_again, _, stderr) = mass_and_psi(&cache, &a, model, &x);
    assert!(!stderr.contains("compiling"), "{stderr}");
    assert_eq!(m1_again, m1);

    // The include edited while the robot is generated (a generator that edits it first): an
    // error, nothing cached; the next run builds the edited robot.
    // (`RBSS_CODEGEN`: a generator command run instead of the one in rbss.)
    let real = Path::new(env!("CARGO_BIN_EXE_rbss")).with_file_name("rbss-codegen");
    assert!(
        real.is_file(),
        "{} is missing: build it with `cargo build --release -p rbss-codegen`",
        real.display()
    );
    let wrapper = tmp.path().join("codegen-that-edits.sh");
    std::fs::write(
        &wrapper,
        format!(
            "#!/bin/sh\ncp '{}' '{}'\nexec '{}' \"$@\"\n",
            b.join("four_bar_bodies.xml").display(),
            a.join("four_bar_bodies.xml").display(),
            real.display()
        ),
    )
    .unwrap();
    {
        use std::os::unix::fs::PermissionsExt as _;
        std::fs::set_permissions(&wrapper, std::fs::Permissions::from_mode(0o755)).unwrap();
    }
    std::fs::write(
        a.join("four_bar_bodies.xml"),
        bodies.replace("<!--", "<!-- edited:"),
    )
    .unwrap();
    let before = entries(&cache).len();
    let states = a.join("states.json");
    let (ok, _, stderr) = rbss_in(
        &cache,
        &a,
        &[
            "eval",
            "--model-file",
            model,
            "--states",
            states.to_str().unwrap(),
        ],
        &[("RBSS_CODEGEN", wrapper.to_str().unwrap())],
    );
    assert!(!ok);
    assert!(
        stderr.contains("changed while it was being compiled"),
        "{stderr}"
    );
    assert_eq!(entries(&cache).len(), before);
    // The include is now the heavy one: its robot.
    let (m3, psi3, stderr) = mass_and_psi(&cache, &a, model, &x);
    assert!(stderr.contains("compiling robot"), "{stderr}");
    assert_ten_times("M", &m3, &m1);
    assert_ten_times("psi", &psi3, &psi1);
}

/// A model with `urdf = "..."`: the URDF's masses and inertias edited (10 times), `M` must
/// be 10 times the old one (before, the old library stayed).
#[test]
fn urdf_source_edit() {
    let tmp = tempfile::Builder::new()
        .prefix("rbss-model-file-urdf-")
        .tempdir()
        .unwrap();
    let cache = tmp.path().join("cache");
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("codegen/tests/import");
    for f in ["ur5.toml", "ur5.urdf"] {
        std::fs::copy(src.join(f), tmp.path().join(f)).unwrap();
    }
    let x = [
        0.2,
        -1.3,
        1.5,
        -1.8,
        -1.57,
        0.3,
        -0.5615701059437073,
        -0.2252727516909624,
        0.34124203713702866,
        -3.113927766653958,
        0.009389622415266129,
        1.470937846115427,
    ];
    let model = tmp.path().join("ur5.toml");
    let model = model.to_str().unwrap();
    let (m1, psi1, stderr) = mass_and_psi(&cache, tmp.path(), model, &x);
    assert!(stderr.contains("compiling robot"), "{stderr}");
    let urdf = std::fs::read_to_string(src.join("ur5.urdf")).unwrap();
    let heavy = scale_attributes(&urdf, &["value", "ixx", "ixy", "ixz", "iyy", "iyz", "izz"]);
    std::fs::write(tmp.path().join("ur5.urdf"), heavy).unwrap();
    let (m2, psi2, stderr) = mass_and_psi(&cache, tmp.path(), model, &x);
    assert!(stderr.contains("compiling robot"), "{stderr}");
    assert_ten_times("M", &m2, &m1);
    assert_ten_times("psi", &psi2, &psi1);
}

/// The bytes of the files under `p`.
fn dir_size(p: &Path) -> u64 {
    std::fs::read_dir(p)
        .unwrap()
        .flatten()
        .map(|e| {
            if e.file_type().unwrap().is_dir() {
                dir_size(&e.path())
            } else {
                e.metadata().unwrap().len()
            }
        })
        .sum()
}

/// SHA-256 in hex (the manifest's `model_sha256`), by `sha256sum`'s algorithm in the sha2
/// crate the command uses.
fn sha256_hex(data: &[u8]) -> String {
    use sha2::Digest as _;
    sha2::Sha256::digest(data)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// `rbss bench --model-file` (the studies variant of the library, built on its first use):
/// the 6-UPS model file's solver table has the rows and kernel calls of the compiled-in
/// robot's, and its work-precision sweep along its default trajectory file
/// (models/trajectories/stewart_6ups.toml) is the compiled-in robot's along the same file
/// (every column but the times identical) and TraekP's, the compiled-in default, to rounding.
#[cfg(feature = "studies")]
#[test]
fn bench_with_a_model_file() {
    let tmp = tempfile::Builder::new()
        .prefix("rbss-model-file-bench-")
        .tempdir()
        .unwrap();
    let cache = tmp.path().join("cache");
    let model = tmp.path().join("stewart_6ups.toml");
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    std::fs::copy(root.join("models/stewart_6ups.toml"), &model).unwrap();
    let model_arg = model.to_str().unwrap();
    let out = |name: &str| tmp.path().join(name).to_str().unwrap().to_string();
    let run = |args: &[&str]| {
        let (ok, stdout, stderr) = rbss(&cache, args, &[]);
        assert!(ok, "rbss {args:?}: {stderr}");
        (stdout, stderr)
    };

    // The solver table: built with the studies, then the same rows and kernel calls.
    let solvers = |robot: [&str; 2], dir: &str| {
        let (stdout, stderr) = run(&[
            "bench",
            "solvers",
            robot[0],
            robot[1],
            "--batches",
            "3",
            "--out",
            dir,
        ]);
        let csv = std::fs::read_to_string(Path::new(dir).join("solvers.csv")).unwrap();
        let rows: Vec<(String, String)> = csv
            .lines()
            .skip(1)
            .map(|l| {
                let f: Vec<&str> = l.split(',').collect();
                assert_eq!(f.len(), 5, "{l}");
                (f[0].to_string(), f[4].to_string())
            })
            .collect();
        for (name, _) in &rows {
            assert!(
                stdout.contains(&format!("| stewart_6ups | {name} |")),
                "{stdout}"
            );
        }
        (rows, stderr)
    };
    let (from_file, stderr) = solvers(["--model-file", model_arg], &out("s1"));
    assert!(
        stderr.contains("compiling robot `stewart_6ups` with the studies"),
        "{stderr}"
    );
    let (builtin, _) = solvers(["--model", "stewart_6ups"], &out("s2"));
    assert_eq!(from_file.len(), 9);
    assert_eq!(from_file, builtin);
    assert_eq!(entries(&cache).len(), 1);

    // Work-precision: from the cached studies library.
    type Rows = Vec<std::collections::BTreeMap<String, String>>;
    let sweep = |args: &[&str], dir: &str| -> Rows {
        let mut all = vec!["bench", "work-precision"];
        all.extend_from_slice(args);
        all.extend_from_slice(&["--quick", "--repeats", "1", "--out", dir]);
        let (stdout, stderr) = run(&all);
        assert!(!stderr.contains("compiling"), "{stderr}");
        assert!(
            stdout.contains("stewart_6ups round trip, 24 runs (0 failed)"),
            "{stdout}"
        );
        let csv = std::fs::read_to_string(Path::new(dir).join("work_precision.csv")).unwrap();
        let mut lines = csv.lines();
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        lines
            .map(|l| {
                header
                    .iter()
                    .zip(l.split(','))
                    .map(|(h, v)| (h.to_string(), v.to_string()))
                    .collect()
            })
            .collect()
    };
    let file = sweep(&["--model-file", model_arg], &out("w1"));
    let along_file = sweep(
        &[
            "--model",
            "stewart_6ups",
            "--trajectory",
            root.join("models/trajectories/stewart_6ups.toml")
                .to_str()
                .unwrap(),
        ],
        &out("w2"),
    );
    let traek = sweep(&["--model", "stewart_6ups"], &out("w3"));
    assert_eq!(file.len(), 24);
    assert_eq!((along_file.len(), traek.len()), (24, 24));
    for ((f, a), t) in file.iter().zip(&along_file).zip(&traek) {
        // The same kernels, trajectory and solvers: the same numbers (the times aside).
        for (k, v) in f {
            if !k.starts_with("time") {
                assert_eq!(v, &a[k], "{k}: {f:?} vs {a:?}");
            }
        }
        // TraekP in closed form against the same motion as expressions (`0.1*cos(2*pi*t)*
        // sin(2*pi*t)` for `0.05 sin(4 w t)`, ...): the same steps, the errors equal to
        // rounding (measured: relative differences up to 7e-5 of errors of 1e-11 m and
        // more; the energy balance, whose smallest values are 4e-10 J, up to 6e-3).
        for k in [
            "method",
            "stabilization",
            "parameter",
            "status",
            "steps",
            "rejected",
        ] {
            assert_eq!(f[k], t[k], "{k}: {f:?} vs {t:?}");
        }
        assert_eq!(f["rhs_evaluations"], t["rhs_evaluations"]);
        let num = |r: &std::collections::BTreeMap<String, String>, k: &str| -> f64 {
            r[k].parse().unwrap()
        };
        // Plus the position solves' own tolerance (`SolverOptions::tol_f`, 1e-12 m or rad):
        // the projection steps stop anywhere within it, so two runs' errors may differ by that
        // much whatever their size (measured with the QR-based projection: 2.6e-13 m on errors
        // of 1.5e-10 m).
        let tol_f = rbss_runtime::SolverOptions::default().tol_f;
        for (k, rel, floor) in [
            ("position_error_m", 1e-3, tol_f),
            ("rotation_error_rad", 1e-3, tol_f),
            ("output_error", 1e-3, tol_f),
            ("energy_error_j", 5e-2, 0.0),
        ] {
            let (a, b) = (num(f, k), num(t, k));
            assert!(
                a > 0.0 && (a - b).abs() <= rel * b + floor,
                "{} {} {}: {k} {a:e} (model file) vs {b:e} (TraekP)",
                f["method"],
                f["stabilization"],
                f["parameter"]
            );
        }
        // The precision axis: the translations (x, y, z) and the rotations are told apart by
        // the model file's units, as TraekP's are.
        assert_eq!(
            num(f, "output_error"),
            num(f, "position_error_m").max(num(f, "rotation_error_rad"))
        );
    }
    assert_eq!(entries(&cache).len(), 1, "one entry: the studies variant");
}

/// An entry (`dir`) with a library of `bytes` and its stamp, as a build writes them.
fn fake_entry(dir: &Path, bytes: &[u8]) {
    std::fs::write(dir.join(rbss::model_file::entry_library_file()), bytes).unwrap();
    std::fs::write(
        dir.join("ok"),
        format!(
            "key = \"k\"\nmodel_key = \"m\"\nlibrary_size = {}\nlibrary_sha256 = \"{}\"\n\
             rbss = \"0\"\nabi = {}\nname = \"r\"\nmodel = \"m.toml\"\n",
            bytes.len(),
            sha256_hex(bytes),
            rbss::model_file::ABI_VERSION
        ),
    )
    .unwrap();
}

/// The library is hashed once per state of the file (issue 37: a warm run hashed the 18 MB
/// library every time, 0.17 s of its 0.27 s): a load after a verified one does not hash it again
/// (`verified` records its metadata); a change of its bytes that keeps its size and its
/// modification time (set back as `touch -d` does) is still hashed again, and refused; a
/// truncated library is refused by its size.
#[test]
fn the_library_is_hashed_once_per_state_of_the_file() {
    use rbss::model_file::verify_entry;
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let bytes: Vec<u8> = (0..100_000u32).map(|i| (i * 7919 % 251) as u8).collect();
    fake_entry(dir, &bytes);
    assert!(verify_entry(dir, "k").unwrap(), "the first load hashes");
    assert!(dir.join("verified").is_file());
    assert!(!verify_entry(dir, "k").unwrap(), "the second does not");
    assert!(!verify_entry(dir, "k").unwrap());
    assert_eq!(
        verify_entry(dir, "l").unwrap_err(),
        "its stamp names another key"
    );

    // One byte flipped in place, the size and the modification time set back.
    let lib = dir.join(rbss::model_file::entry_library_file());
    let mtime = std::fs::metadata(&lib).unwrap().modified().unwrap();
    let mut flipped = bytes.clone();
    flipped[50_000] ^= 0x55;
    std::thread::sleep(std::time::Duration::from_millis(20));
    std::fs::write(&lib, &flipped).unwrap();
    std::fs::File::options()
        .append(true)
        .open(&lib)
        .unwrap()
        .set_modified(mtime)
        .unwrap();
    assert_eq!(std::fs::metadata(&lib).unwrap().modified().unwrap(), mtime);
    assert_eq!(std::fs::metadata(&lib).unwrap().len(), bytes.len() as u64);
    let e = verify_entry(dir, "k").unwrap_err();
    assert!(e.contains("its SHA-256 is not its stamp's"), "{e}");

    // Truncated: refused by its size.
    std::fs::write(&lib, &bytes[..1000]).unwrap();
    let e = verify_entry(dir, "k").unwrap_err();
    assert!(e.contains("1000 bytes, its stamp says 100000"), "{e}");

    // The right bytes again: hashed (the record is of another state of the file), then not.
    std::fs::write(&lib, &bytes).unwrap();
    assert!(verify_entry(dir, "k").unwrap());
    assert!(!verify_entry(dir, "k").unwrap());
    // A record naming another SHA-256 than the stamp's is not trusted.
    let record = std::fs::read_to_string(dir.join("verified")).unwrap();
    let other = record.replace(&sha256_hex(&bytes), &"0".repeat(64));
    assert_ne!(other, record);
    std::fs::write(dir.join("verified"), other).unwrap();
    assert!(verify_entry(dir, "k").unwrap());
    assert!(!verify_entry(dir, "k").unwrap());
}

/// An SDF source's `<include>`d files are in the key, as MJCF's are: the included arm's mass
/// and inertia made ten times heavier, the robot is compiled again and its M and psi are ten
/// times the first (a key without the included file would serve the first robot from the cache).
#[test]
fn sdf_include_edits_are_in_the_key() {
    let tmp = tempfile::Builder::new()
        .prefix("rbss-model-file-sdf-")
        .tempdir()
        .unwrap();
    let cache = tmp.path().join("cache");
    let dir = tmp.path().join("robot");
    std::fs::create_dir_all(dir.join("parts")).unwrap();
    let arm = |k: f64| {
        format!(
            "<sdf version=\"1.9\"><model name=\"arm\"><link name=\"upper\"><inertial>\
             <pose>0.1 0 0 0 0 0</pose><mass>{}</mass><inertia><ixx>{}</ixx><iyy>{}</iyy>\
             <izz>{}</izz></inertia></inertial></link></model></sdf>",
            k,
            0.001 * k,
            0.002 * k,
            0.003 * k
        )
    };
    std::fs::write(dir.join("parts/arm.sdf"), arm(1.0)).unwrap();
    std::fs::write(
        dir.join("robot.sdf"),
        "<sdf version=\"1.9\"><model name=\"robot\"><include><uri>parts/arm.sdf</uri></include>\
         <joint name=\"q\" type=\"revolute\"><parent>world</parent><child>arm::upper</child>\
         <axis><xyz>0 1 0</xyz></axis></joint></model></sdf>",
    )
    .unwrap();
    std::fs::write(dir.join("robot.toml"), "sdf = \"robot.sdf\"\n").unwrap();
    let x = [0.3];
    let (m1, psi1, stderr) = mass_and_psi(&cache, &dir, "robot.toml", &x);
    assert!(stderr.contains("compiling robot"), "{stderr}");
    std::fs::write(dir.join("parts/arm.sdf"), arm(10.0)).unwrap();
    let (m2, psi2, stderr) = mass_and_psi(&cache, &dir, "robot.toml", &x);
    assert!(stderr.contains("compiling robot"), "{stderr}");
    assert_ten_times("M", &m2, &m1);
    assert_ten_times("psi", &psi2, &psi1);
}
