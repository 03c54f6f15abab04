//! `rbss-codegen`: generate the kernel crates of robot models.
//!
//! ```text
//! rbss-codegen [--freeze] [--out DIR] MODEL.toml...   write generated/NAME (or DIR) for each model
//! rbss-codegen --all                                  every models/*.toml
//! rbss-codegen --check [--all | MODEL.toml...]        fail if a generated crate is out of date
//! rbss-codegen --scene SCENE.toml --out DIR           write the crate of a scene (scenes/*.toml) to DIR
//! rbss-codegen import FILE [--out MODEL.toml]         a URDF, MJCF or SDF file as a model file (stdout without --out)
//! ```
//! Progress and figures go to stderr; nothing goes to stdout. A closed stderr (`2>&1 | head`)
//! does not stop the run: the messages are dropped and the crates still written.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use rbss_codegen::{
    Options, generate, generate_scene, generate_with_runtime, scene, stale_files, write_crate,
};

/// `eprintln!` that ignores a failed write (a closed pipe) instead of panicking.
macro_rules! say {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr().lock(), $($t)*);
    }};
}

fn usage() -> ExitCode {
    say!(
        "usage: rbss-codegen [--freeze] [--kinematics-only] [--no-derivatives] [--check] [--out DIR] (--all | MODEL.toml...)\n\
         \n       rbss-codegen --scene SCENE.toml --out DIR\n\
         \n       rbss-codegen import FILE.urdf|FILE.xml|FILE.sdf [--out MODEL.toml]\n\
         \n  --all      every models/*.toml (run from the workspace root)\
         \n  --check    regenerate in memory and fail if generated/NAME differs\
         \n  --freeze   fold parameter values into the kernels\
         \n  --kinematics-only   emit no dynamics kernels (M, psi, energies)\
         \n  --no-derivatives    emit no derivative kernel (dynamics_derivatives)\
         \n  --out DIR  write the crate to DIR instead of generated/NAME (one model only)\
         \n  --scene SCENE.toml  generate only what the scene's tasks need (see scenes/README.md)"
    );
    ExitCode::from(2)
}

fn main() -> ExitCode {
    let mut opts = Options::default();
    let mut check = false;
    let mut all = false;
    let mut out: Option<PathBuf> = None;
    let mut models: Vec<String> = Vec::new();
    let mut scene_file: Option<String> = None;
    let mut args = std::env::args().skip(1).peekable();
    if args.peek().is_some_and(|a| a == "import") {
        args.next();
        return run_import(args.collect());
    }
    while let Some(a) = args.next() {
        match a.as_str() {
            "--scene" => match args.next() {
                Some(f) => scene_file = Some(f),
                None => return usage(),
            },
            "--freeze" => opts.freeze = true,
            "--kinematics-only" => opts.kinematics_only = true,
            "--no-derivatives" => opts.no_derivatives = true,
            "--check" => check = true,
            "--all" => all = true,
            "--out" => match args.next() {
                // An empty DIR (an unset shell variable) would mean the current directory: in the
                // workspace root, the crate's Cargo.toml and src/lib.rs would replace the
                // project's own.
                Some(d) if d.trim().is_empty() => {
                    say!(
                        "rbss-codegen: --out: an empty path names no directory (an unset shell \
                         variable?): give the directory to write the crate to"
                    );
                    return ExitCode::from(2);
                }
                Some(d) => out = Some(PathBuf::from(d)),
                None => return usage(),
            },
            "-h" | "--help" => {
                usage();
                return ExitCode::SUCCESS;
            }
            s if s.starts_with('-') => {
                say!("rbss-codegen: unknown option `{s}`");
                return usage();
            }
            _ => models.push(a),
        }
    }
    if let Some(file) = scene_file {
        if all || check || opts != Options::default() || !models.is_empty() {
            say!(
                "rbss-codegen: --scene takes no model, --all, --check or options (the scene file says it all)"
            );
            return usage();
        }
        let Some(out) = out else {
            say!("rbss-codegen: --scene needs --out DIR");
            return usage();
        };
        return run_scene(&file, &out);
    }
    if all {
        match std::fs::read_dir("models") {
            Ok(rd) => {
                let mut found: Vec<String> = rd
                    .filter_map(|e| e.ok())
                    .map(|e| e.path())
                    .filter(|p| p.extension().is_some_and(|x| x == "toml"))
                    .map(|p| p.to_string_lossy().replace('\\', "/"))
                    .collect();
                found.sort();
                models.extend(found);
            }
            Err(e) => {
                say!(
                    "rbss-codegen: error: cannot read `models/` ({e}); run from the workspace root"
                );
                return ExitCode::FAILURE;
            }
        }
    }
    if models.is_empty() || (out.is_some() && models.len() != 1) {
        return usage();
    }

    let mut failed = false;
    for model in &models {
        let t0 = Instant::now();
        let source = match rbss_codegen::source::read_source(Path::new(model)) {
            Ok(s) => s,
            Err(d) => {
                // Unreadable, or not UTF-8 (located at the first invalid byte).
                say!("{}", d.render());
                failed = true;
                continue;
            }
        };
        let mut progress = |s: &str| say!("rbss-codegen: {s}");
        // `generated/NAME` depends on `../../runtime`, this workspace's layout; a crate written
        // elsewhere on the runtime where it is from there.
        let generated = match &out {
            Some(dir) => {
                generate_with_runtime(model, &source, &opts, &runtime_dep_for(dir), &mut progress)
            }
            None => generate(model, &source, &opts, &mut progress),
        };
        let generated = match generated {
            Ok(g) => g,
            Err(e) => {
                say!("{e}");
                failed = true;
                continue;
            }
        };
        let dir = out
            .clone()
            .unwrap_or_else(|| Path::new("generated").join(&generated.name));
        if check {
            let stale = stale_files(&dir, &generated);
            if stale.is_empty() {
                say!("rbss-codegen: {} is up to date", dir.display());
            } else {
                for p in &stale {
                    say!("rbss-codegen: {} is out of date", p.display());
                }
                say!(
                    "generated/{} is out of date: run `cargo run --release -p rbss-codegen -- {model}`",
                    generated.name
                );
                failed = true;
            }
            continue;
        }
        if let Err(e) = write_crate(&dir, &generated) {
            say!("{e}");
            failed = true;
            continue;
        }
        let r = &generated.report;
        say!(
            "rbss-codegen: wrote {} ({} lines; n = {}, m = {}) in {:.2} s: parse {:.3} s, derive {:.3} s, emit {:.3} s, format {:.3} s",
            dir.display(),
            r.lines,
            r.n,
            r.m,
            t0.elapsed().as_secs_f64(),
            r.parse_time.as_secs_f64(),
            r.derive_time.as_secs_f64(),
            r.emit_time.as_secs_f64(),
            r.format_time.as_secs_f64()
        );
        for k in &r.kernels {
            say!(
                "rbss-codegen:   {:<12} {:>6}  nnz {:>4}  {}",
                k.name,
                k.shape,
                k.nonzeros,
                k.ops
            );
        }
    }
    if failed {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}

/// `--scene FILE --out DIR`: the crate of one scene, depending on this workspace's runtime.
fn run_scene(file: &str, out: &Path) -> ExitCode {
    let t0 = Instant::now();
    let scene = match scene::read_scene(file) {
        Ok(s) => s,
        Err(d) => {
            say!("{}", d.to_string().trim_end());
            return ExitCode::FAILURE;
        }
    };
    let runtime_dep = runtime_dep_for(out);
    let generated = match generate_scene(&scene, &runtime_dep, &mut |s| say!("rbss-codegen: {s}")) {
        Ok(g) => g,
        Err(e) => {
            say!("{}", e.to_string().trim_end());
            return ExitCode::FAILURE;
        }
    };
    if let Err(e) = write_crate(out, &generated) {
        say!("{e}");
        return ExitCode::FAILURE;
    }
    let r = &generated.report;
    say!(
        "rbss-codegen: wrote {} (scene {}: {}; {} lines) in {:.3} s",
        out.display(),
        scene.name,
        scene.summary(),
        r.lines,
        t0.elapsed().as_secs_f64()
    );
    for k in &r.kernels {
        say!(
            "rbss-codegen:   {:<24} {:>6}  nnz {:>4}  {}",
            k.name,
            k.shape,
            k.nonzeros,
            k.ops
        );
    }
    ExitCode::SUCCESS
}

/// Where a crate written to `out` finds this workspace's runtime: the path from `out` (which
/// need not exist yet) to `runtime/`, both made absolute and free of symbolic links, or the
/// runtime's absolute path when either cannot be resolved (the binary moved away from its
/// sources).
fn runtime_dep_for(out: &Path) -> String {
    let runtime = Path::new(env!("CARGO_MANIFEST_DIR")).join("../runtime");
    match (absolute_dir(out), runtime.canonicalize()) {
        // Sharing no more than the root, a relative path says less than the absolute one.
        (Some(from), Ok(to)) if from.components().nth(1) == to.components().nth(1) => {
            relative_path(&from, &to)
        }
        (_, Ok(to)) => to.to_string_lossy().replace('\\', "/"),
        _ => runtime.to_string_lossy().replace('\\', "/"),
    }
}

/// `dir` made absolute and symlink-free: its deepest existing ancestor canonicalised, with the
/// components that do not exist yet appended (`None` for a `..` among those).
fn absolute_dir(dir: &Path) -> Option<PathBuf> {
    let mut missing = Vec::new();
    let mut cur = if dir.is_absolute() {
        dir.to_path_buf()
    } else {
        std::env::current_dir().ok()?.join(dir)
    };
    loop {
        if let Ok(c) = cur.canonicalize() {
            let mut out = c;
            for part in missing.iter().rev() {
                out.push(part);
            }
            return Some(out);
        }
        match cur.file_name() {
            Some(n) => missing.push(n.to_os_string()),
            None => return None,
        }
        if !cur.pop() {
            return None;
        }
    }
}

/// The path of `to` relative to the directory `from` (both absolute), with `/` separators.
fn relative_path(from: &Path, to: &Path) -> String {
    let a: Vec<_> = from.components().collect();
    let b: Vec<_> = to.components().collect();
    let common = a.iter().zip(&b).take_while(|(x, y)| x == y).count();
    let mut parts: Vec<String> = vec!["..".to_string(); a.len() - common];
    parts.extend(
        b[common..]
            .iter()
            .map(|c| c.as_os_str().to_string_lossy().into_owned()),
    );
    if parts.is_empty() {
        ".".to_string()
    } else {
        parts.join("/")
    }
}

/// `rbss-codegen import FILE [--out MODEL.toml]`: the source as a model file, commented with its
/// elements and lines. Nothing is written when the source has errors.
fn run_import(args: Vec<String>) -> ExitCode {
    let (file, out) = match args.as_slice() {
        [f] => (f, None),
        [f, o, d] | [o, d, f] if o == "--out" && !d.trim().is_empty() => (f, Some(d)),
        _ => return usage(),
    };
    let path = Path::new(file);
    let Some(format) = rbss_codegen::import::Format::from_path(path) else {
        say!(
            "rbss-codegen: import: `{file}`: the format is told by the extension: .urdf, .xml or .mjcf (MJCF), .sdf"
        );
        return ExitCode::from(2);
    };
    let shown = file.replace('\\', "/");
    let (imported, warnings) = match rbss_codegen::import::import_file(path, &shown, format) {
        Ok(x) => x,
        Err(d) => {
            say!("{}", d.render());
            return ExitCode::FAILURE;
        }
    };
    if !warnings.items.is_empty() {
        say!("{}", warnings.render_warnings());
    }
    let text = imported.render();
    match out {
        None => {
            use std::io::Write as _;
            let _ = std::io::stdout().lock().write_all(text.as_bytes());
        }
        Some(o) => {
            // Written next to its place, then renamed: never a half-written model file.
            let tmp = PathBuf::from(format!("{o}.tmp"));
            if let Err(e) = std::fs::write(&tmp, &text).and_then(|_| std::fs::rename(&tmp, o)) {
                let _ = std::fs::remove_file(&tmp);
                say!("rbss-codegen: error: cannot write `{o}`: {e}");
                return ExitCode::FAILURE;
            }
            say!(
                "rbss-codegen: wrote {o} ({} coordinates, {} bodies, {} loops): add `outputs` (and the loops a tree cannot say), then generate it",
                imported.coordinates.len(),
                imported.bodies.len(),
                imported.loops.len()
            );
        }
    }
    ExitCode::SUCCESS
}
