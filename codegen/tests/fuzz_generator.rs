//! A deterministic fuzzer of the generator (`rbss_codegen::generate`): parse -> derive ->
//! assemble -> emit -> format, where `fuzz_parser` stops after the parser.
//!
//! It starts from real models and replaces 1 to 3 of their expressions (a centre of mass, a
//! parameter's value, a solid's size or density, a transform's argument) with random
//! expressions of the model language: the model's parameters and coordinates, pi, small and
//! extreme numbers (`10^400`, `10^-400`, `2^1024`, `1e38`), the four operations and powers,
//! `sin`, `cos`, `tan`, `sqrt` (and of constants `atan2 hypot asin acos abs exp ln`), nested to
//! depth 3, and pose steps (`rpy`, `quat`, `axis_angle`, `pose`, `inverse`) beside a
//! transform's own steps (folded with them). Every case that parses must then generate
//! without a panic: the kernels, or a typed error (`Error::Model`, rendered). A finite
//! expression with an overflowing constant (`com = ["l1 / 10^400", 0, 0]`) panicked the
//! generator before the parser refused it.
//!
//! ```text
//! cargo test --release -p rbss-codegen --test fuzz_generator                      # CI: 400 cases
//! RBSS_FUZZ_CASES=100000 cargo test --release -p rbss-codegen --test fuzz_generator -- --nocapture
//! RBSS_FUZZ_SEED=7 ...                                                            # another stream
//! ```
//!
//! Generation never touches symbolica (only the reference derivation does), so this runs on
//! several threads. A failing case is written to `$TMPDIR/rbss-fuzz-gen-PID/failure-CASE.toml`.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::time::Instant;

use common::Rng;
use rbss_codegen::{Error, Options, generate};

mod common;

/// Cases in CI (a few seconds in release); `RBSS_FUZZ_CASES` overrides.
const DEFAULT_CASES: u64 = 400;
const MODELS: &[&str] = &["models/five_bar.toml", "models/planar_3rrr.toml"];

const NUMBERS: &[&str] = &[
    "0", "1", "2", "3", "0.5", "1/3", "1e38", "1e-38", "10^400", "10^-400", "2^1024", "2^-1075",
    "0.1", "180", "pi", "pi / 2",
];

/// A random expression over `names` (parameters, and coordinates where allowed).
fn expr(rng: &mut Rng, names: &[String], depth: usize) -> String {
    if depth == 0 || rng.below(3) == 0 {
        return if !names.is_empty() && rng.below(2) == 0 {
            names[rng.below(names.len())].clone()
        } else {
            rng.pick(NUMBERS).to_string()
        };
    }
    let a = expr(rng, names, depth - 1);
    match rng.below(10) {
        0 => format!("{a} + {}", expr(rng, names, depth - 1)),
        1 => format!("{a} - {}", expr(rng, names, depth - 1)),
        2 => format!("({a}) * ({})", expr(rng, names, depth - 1)),
        3 => format!("({a}) / ({})", expr(rng, names, depth - 1)),
        4 => format!(
            "({a})^{}",
            *rng.pick(&["2", "3", "-1", "0.5", "400", "-400"])
        ),
        5 => format!("-({a})"),
        6 => format!("{}({a})", *rng.pick(&["sin", "cos", "tan", "sqrt"])),
        // The constant-only functions: their argument is made of numbers alone (a coordinate
        // or parameter in it is either refused or a run-time constant).
        7 => {
            let c = expr(rng, &[], depth - 1);
            match rng.below(4) {
                0 => format!("atan2({c}, {})", expr(rng, &[], depth - 1)),
                1 => format!("hypot({c}, {})", expr(rng, &[], depth - 1)),
                _ => format!("{}({c})", *rng.pick(&["asin", "acos", "abs", "exp", "ln"])),
            }
        }
        _ => format!("({a})"),
    }
}

/// A random pose step (a table in `transforms`): rpy, quat, axis_angle, pose or the inverse of
/// elementary steps, with random constant expressions (and coordinates in rpy).
fn pose_step(rng: &mut Rng, params: &[String], with_coords: &[String]) -> String {
    let c = |rng: &mut Rng| format!("\"{}\"", expr(rng, params, 2));
    match rng.below(5) {
        0 => format!(
            "{{ rpy = [{}, {}, \"{}\"] }}",
            c(rng),
            c(rng),
            expr(rng, with_coords, 2)
        ),
        1 => format!(
            "{{ quat = [{}, {}, {}, {}] }}",
            c(rng),
            c(rng),
            c(rng),
            c(rng)
        ),
        2 => format!(
            "{{ axis_angle = [{}, {}, {}, {}], unit = \"deg\" }}",
            c(rng),
            c(rng),
            c(rng),
            c(rng)
        ),
        3 => format!(
            "{{ pose = {{ xyz = [{}, 0, {}], quat = [1, {}, 0, 0] }} }}",
            c(rng),
            c(rng),
            c(rng)
        ),
        _ => format!(
            "{{ inverse = [\"Rx({})\", {{ rpy = [{}, 0, 0] }}, \"Tz({})\"] }}",
            expr(rng, params, 2),
            c(rng),
            expr(rng, params, 2)
        ),
    }
}

/// The names `key = { ... }` of a model's `[parameters]` and `{ name = "..." }` of its
/// coordinates.
fn names(src: &str) -> (Vec<String>, Vec<String>) {
    let mut params = Vec::new();
    let mut coords = Vec::new();
    let mut in_params = false;
    for line in src.lines() {
        let t = line.trim();
        if t.starts_with('[') {
            in_params = t == "[parameters]";
            continue;
        }
        if in_params && let Some((k, _)) = t.split_once('=') {
            let k = k.trim();
            if !k.is_empty() && !k.starts_with('#') {
                params.push(k.to_string());
            }
        }
        if let Some(rest) = t.strip_prefix("{ name = \"")
            && let Some((n, _)) = rest.split_once('"')
        {
            coords.push(n.to_string());
        }
    }
    (params, coords)
}

/// Replaces one expression of the model text with a random one; `None` when the chosen line
/// has nothing to replace.
fn mutate(src: &str, rng: &mut Rng, params: &[String], coords: &[String]) -> Option<String> {
    let lines: Vec<&str> = src.lines().collect();
    let targets: Vec<usize> = (0..lines.len())
        .filter(|&i| {
            let t = lines[i].trim_start();
            t.starts_with("com = [")
                || t.starts_with("transforms = [")
                || t.starts_with("solid = {")
                || t.contains("value = ")
        })
        .collect();
    let i = targets[rng.below(targets.len())];
    let line = lines[i];
    let t = line.trim_start();
    let with_coords: Vec<String> = params.iter().chain(coords).cloned().collect();
    let new = if t.starts_with("com = [") {
        let mut items = ["0".to_string(), "0".to_string(), "0".to_string()];
        items[rng.below(3)] = format!("\"{}\"", expr(rng, params, 3));
        format!("com = [{}]", items.join(", "))
    } else if t.starts_with("transforms = [") {
        let step = *rng.pick(&["Tx", "Ty", "Tz", "Rx", "Ry", "Rz"]);
        // Keep the line's own steps (its coordinates stay in use), add one: elementary, or a
        // pose step (constant runs fold in the derivation).
        let inner = t.trim_start_matches("transforms = [").trim_end_matches(']');
        if rng.below(2) == 0 {
            let pose = pose_step(rng, params, &with_coords);
            format!(
                "transforms = [{pose}, {inner}, {}]",
                pose_step(rng, params, &with_coords)
            )
        } else {
            format!(
                "transforms = [{inner}, \"{step}({})\"]",
                expr(rng, &with_coords, 3)
            )
        }
    } else if t.starts_with("solid = {") {
        let e = expr(rng, params, 2);
        if let Some(p) = t.find("density = ") {
            let rest = &t[p + "density = ".len()..];
            let end = rest.find([',', ' ', '}']).unwrap_or(rest.len());
            format!("{}density = \"{e}\"{}", &t[..p], &rest[end..])
        } else {
            return None;
        }
    } else {
        let p = line.find("value = ")?;
        let rest = &line[p + "value = ".len()..];
        let end = rest.find([',', ' ', '}']).unwrap_or(rest.len());
        // Parameters are constants: numbers and pi only.
        let e = expr(rng, &[], 2);
        return Some(
            lines[..i]
                .iter()
                .copied()
                .chain(std::iter::once(
                    format!("{}value = \"{e}\"{}", &line[..p], &rest[end..]).as_str(),
                ))
                .chain(lines[i + 1..].iter().copied())
                .collect::<Vec<_>>()
                .join("\n"),
        );
    };
    let indent = &line[..line.len() - t.len()];
    let mut out: Vec<String> = lines.iter().map(|l| l.to_string()).collect();
    out[i] = format!("{indent}{new}");
    Some(out.join("\n"))
}

fn env_u64(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

#[test]
fn fuzz_generator() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let cases = env_u64("RBSS_FUZZ_CASES", DEFAULT_CASES);
    let seed = env_u64("RBSS_FUZZ_SEED", 1);
    let sources: Vec<(String, String, Vec<String>, Vec<String>)> = MODELS
        .iter()
        .map(|m| {
            let src = std::fs::read_to_string(root.join(m)).unwrap();
            let (p, c) = names(&src);
            assert!(
                !p.is_empty() && !c.is_empty(),
                "{m}: no parameters or coordinates"
            );
            (m.to_string(), src, p, c)
        })
        .collect();
    // Panics are caught and counted; keep their messages off the test output.
    std::panic::set_hook(Box::new(|_| {}));
    let t0 = Instant::now();
    let next = AtomicU64::new(0);
    let (generated, refused, unparsed) = (
        AtomicUsize::new(0),
        AtomicUsize::new(0),
        AtomicUsize::new(0),
    );
    let failures = std::sync::Mutex::new(Vec::new());
    let threads = std::thread::available_parallelism().map_or(2, |n| n.get().min(4));
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| {
                loop {
                    let case = next.fetch_add(1, Ordering::Relaxed);
                    if case >= cases {
                        break;
                    }
                    let mut rng = Rng::new(seed.wrapping_mul(1_000_003).wrapping_add(case));
                    let (path, src, params, coords) = &sources[rng.below(sources.len())];
                    let mut text = src.clone();
                    for _ in 0..1 + rng.below(3) {
                        if let Some(t) = mutate(&text, &mut rng, params, coords) {
                            text = t;
                        }
                    }
                    let shown = format!("{path} (case {case})");
                    if rbss_codegen::parse::parse_model(&shown, &text).is_err() {
                        unparsed.fetch_add(1, Ordering::Relaxed);
                        continue;
                    }
                    let run = catch_unwind(AssertUnwindSafe(|| {
                        generate(&shown, &text, &Options::default(), &mut |_| {})
                    }));
                    match run {
                        Ok(Ok(_)) => {
                            generated.fetch_add(1, Ordering::Relaxed);
                        }
                        Ok(Err(Error::Model(d))) => {
                            assert!(d.render().contains(": error: "), "{}", d.render());
                            refused.fetch_add(1, Ordering::Relaxed);
                        }
                        Ok(Err(e)) => panic!("case {case}: unexpected error {e}"),
                        Err(p) => {
                            let msg = p
                                .downcast_ref::<String>()
                                .cloned()
                                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                                .unwrap_or_default();
                            let dir = std::env::temp_dir()
                                .join(format!("rbss-fuzz-gen-{}", std::process::id()));
                            let _ = std::fs::create_dir_all(&dir);
                            let file = dir.join(format!("failure-{case}.toml"));
                            let _ = std::fs::write(&file, &text);
                            failures.lock().unwrap().push(format!(
                                "case {case} ({path}): panic: {msg}\n  written to {}",
                                file.display()
                            ));
                        }
                    }
                }
            });
        }
    });
    let _ = std::panic::take_hook();
    let failures = failures.into_inner().unwrap();
    let summary = format!(
        "{cases} cases (seed {seed}) in {:.1} s: {} generated, {} refused with a model error, \
         {} not parsed, {} panics",
        t0.elapsed().as_secs_f64(),
        generated.into_inner(),
        refused.into_inner(),
        unparsed.into_inner(),
        failures.len()
    );
    println!("{summary}");
    assert!(
        failures.is_empty(),
        "{summary}:\n{}",
        failures
            .iter()
            .take(10)
            .cloned()
            .collect::<Vec<_>>()
            .join("\n")
    );
}
