//! The Markdown tables of BENCHMARKS.md's "Scenes" from `bench/scenes/run.sh`'s results
//! (`results.tsv` and the generator's reports `gen_VARIANT.txt` in its work directory).
//!
//! `cargo run --release --example scene_table -- [DIR]` (default `target/scene-bench`).

use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::{Path, PathBuf};

/// The jobs of the scene benchmark: key, title, the solver timed.
const JOBS: [(&str, &str, &str); 3] = [
    ("ik", "1 kHz IK", "inverse_kinematics"),
    (
        "id",
        "inverse dynamics along a path",
        "inverse_dynamics_full",
    ),
    ("sim", "full simulation", "simulator_step"),
];

type Row = HashMap<String, String>;

fn read(path: &Path) -> Result<String, String> {
    std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))
}

/// The rows of `results.tsv`, by column name.
fn rows(dir: &Path) -> Result<Vec<Row>, String> {
    let text = read(&dir.join("results.tsv"))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines
        .next()
        .ok_or("results.tsv is empty")?
        .split('\t')
        .collect();
    Ok(lines
        .filter(|l| !l.is_empty())
        .map(|l| {
            header
                .iter()
                .map(|h| h.to_string())
                .zip(l.split('\t').map(String::from))
                .collect()
        })
        .collect())
}

/// Kernel -> (mul, add, div, fn) from the generator's report of one variant: the lines
/// `rbss-codegen:   NAME ... A mul, B add, C div, D fn`.
fn ops(dir: &Path, variant: &str) -> Result<BTreeMap<String, [u64; 4]>, String> {
    let text = read(&dir.join(format!("gen_{variant}.txt")))?;
    let mut out = BTreeMap::new();
    for line in text.lines() {
        let Some(rest) = line.strip_prefix("rbss-codegen:") else {
            continue;
        };
        if rest.trim_start().starts_with('[') {
            continue;
        }
        let Some(name) = rest.split_whitespace().next() else {
            continue;
        };
        let Some(at) = rest.find(" mul, ") else {
            continue;
        };
        let nums: Vec<u64> = rest[..at]
            .rsplit(' ')
            .next()
            .into_iter()
            .chain(
                rest[at..]
                    .split(", ")
                    .skip(1)
                    .map(|s| s.split(' ').next().unwrap_or("")),
            )
            .filter_map(|s| s.trim().parse().ok())
            .collect();
        if let [m, a, d, f] = nums[..] {
            out.insert(name.to_string(), [m, a, d, f]);
        }
    }
    Ok(out)
}

fn find<'a>(rows: &'a [Row], variant: &str, job: &str, name: &str) -> Option<&'a Row> {
    rows.iter()
        .find(|r| r["variant"] == variant && r["job"] == job && r["name"] == name)
}

fn ns(r: &Row) -> f64 {
    r["ns"].parse().unwrap_or(f64::NAN)
}

fn main() -> Result<(), String> {
    let dir = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or("target/scene-bench".into()),
    );
    let rows = rows(&dir)?;
    for robot in ["stewart_6ups", "five_bar"] {
        println!("\n#### {robot}\n");
        println!(
            "| scene (job) | crate | kernels | gen. s | lines | compile s (wall / CPU) | binary bytes | solver ns/call |"
        );
        println!("|---|---|---|---:|---:|---:|---:|---:|");
        for (job, title, solver) in JOBS {
            for (suffix, kind) in [
                ("full", "full model"),
                ("frozen", "scene, frozen"),
                ("rt", "scene, run-time params"),
            ] {
                let variant = if suffix == "full" {
                    format!("{robot}_full")
                } else {
                    format!("{robot}_{job}_{suffix}")
                };
                let r = find(&rows, &variant, job, &format!("solver/{solver}"))
                    .ok_or_else(|| format!("no solver/{solver} row for {variant} ({job})"))?;
                let o = ops(&dir, &variant)?;
                let kernels = if suffix == "full" {
                    format!("all {}", o.len())
                } else {
                    o.keys().cloned().collect::<Vec<_>>().join(", ")
                };
                println!(
                    "| {title} (`{solver}`) | {kind} | {kernels} | {} | {} | {} / {} | {} | {:.0} |",
                    r["gen_s"],
                    r["lines"],
                    r["compile_wall_s"],
                    r["compile_cpu_s"],
                    r["binary_bytes"],
                    ns(r)
                );
            }
        }
        println!();
        println!(
            "| kernel | ops run-time params (mul, add, div, fn) | ops frozen | ns run-time | ns frozen |"
        );
        println!("|---|---|---|---:|---:|");
        let mut seen = HashSet::new();
        for (job, _, _) in JOBS {
            let (rt_v, fr_v) = (format!("{robot}_{job}_rt"), format!("{robot}_{job}_frozen"));
            let (rt, fr) = (ops(&dir, &rt_v)?, ops(&dir, &fr_v)?);
            for r in rows.iter().filter(|r| r["variant"] == rt_v) {
                let Some(name) = r["name"].strip_prefix("kernel/") else {
                    continue;
                };
                if !seen.insert(name.to_string()) {
                    continue;
                }
                let f = find(&rows, &fr_v, job, &r["name"])
                    .ok_or_else(|| format!("no {} row for {fr_v}", r["name"]))?;
                let fmt = |o: Option<&[u64; 4]>| match o {
                    Some(o) => format!(
                        "{} ({})",
                        o.map(|v| v.to_string()).join(", "),
                        o.iter().sum::<u64>()
                    ),
                    None => "?".into(),
                };
                println!(
                    "| `{name}` | {} | {} | {:.1} | {:.1} |",
                    fmt(rt.get(name)),
                    fmt(fr.get(name)),
                    ns(r),
                    ns(f)
                );
            }
        }
    }
    Ok(())
}
