//! `rbss-codegen`: generate the kernel crates of robot models.
//!
//! ```text
//! rbss-codegen [--freeze] [--out DIR] MODEL.toml...   write generated/NAME (or DIR) for each model
//! rbss-codegen --all                                  every models/*.toml
//! rbss-codegen --check [--all | MODEL.toml...]        fail if a generated crate is out of date
//! ```
//! Progress and figures go to stderr.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use rbss_codegen::{Options, generate, stale_files, write_crate};

fn usage() -> ExitCode {
    eprintln!(
        "usage: rbss-codegen [--freeze] [--kinematics-only] [--check] [--out DIR] (--all | MODEL.toml...)\n\
         \n  --all      every models/*.toml (run from the workspace root)\
         \n  --check    regenerate in memory and fail if generated/NAME differs\
         \n  --freeze   fold parameter values into the kernels\
         \n  --kinematics-only   emit no dynamics kernels (M, psi, energies)\
         \n  --out DIR  write the crate to DIR instead of generated/NAME (one model only)"
    );
    ExitCode::from(2)
}

fn main() -> ExitCode {
    let mut opts = Options::default();
    let mut check = false;
    let mut all = false;
    let mut out: Option<PathBuf> = None;
    let mut models: Vec<String> = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--freeze" => opts.freeze = true,
            "--kinematics-only" => opts.kinematics_only = true,
            "--check" => check = true,
            "--all" => all = true,
            "--out" => match args.next() {
                Some(d) => out = Some(PathBuf::from(d)),
                None => return usage(),
            },
            "-h" | "--help" => {
                usage();
                return ExitCode::SUCCESS;
            }
            s if s.starts_with('-') => {
                eprintln!("rbss-codegen: unknown option `{s}`");
                return usage();
            }
            _ => models.push(a),
        }
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
                eprintln!(
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
        let source = match std::fs::read_to_string(model) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("{model}: error: cannot read the model file: {e}");
                failed = true;
                continue;
            }
        };
        let generated = match generate(model, &source, &opts, &mut |s| {
            eprintln!("rbss-codegen: {s}")
        }) {
            Ok(g) => g,
            Err(e) => {
                eprintln!("{e}");
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
                eprintln!("rbss-codegen: {} is up to date", dir.display());
            } else {
                for p in &stale {
                    eprintln!("rbss-codegen: {} is out of date", p.display());
                }
                eprintln!(
                    "generated/{} is out of date: run `cargo run --release -p rbss-codegen -- {model}`",
                    generated.name
                );
                failed = true;
            }
            continue;
        }
        if let Err(e) = write_crate(&dir, &generated) {
            eprintln!("{e}");
            failed = true;
            continue;
        }
        let r = &generated.report;
        eprintln!(
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
            eprintln!(
                "rbss-codegen:   {:<12} {:>6}  nnz {:>4}  {}",
                k.name, k.shape, k.nonzeros, k.ops
            );
        }
    }
    if failed {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}
