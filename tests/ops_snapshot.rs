//! The operation counts of every generated kernel (the "Cost after CSE" line of its doc
//! comment) against the snapshot `tests/snapshots/ops.txt`, so that a codegen change that
//! makes the kernels cheaper or dearer shows up in review.
//!
//! `RBSS_BLESS=1 cargo test --release --test ops_snapshot` rewrites the snapshot.

use std::collections::BTreeMap;
use std::path::Path;

/// `robot/kernel` -> `"134 mul, 93 add, 0 div, 15 fn"`, from every `generated/*/src/*.rs`.
fn current_ops(root: &Path) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    let mut robots: Vec<_> = std::fs::read_dir(root.join("generated"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_dir())
        .collect();
    robots.sort();
    for dir in robots {
        let robot = dir.file_name().unwrap().to_string_lossy().to_string();
        let module = dir.join("src").join(format!("{robot}.rs"));
        let Ok(text) = std::fs::read_to_string(&module) else {
            continue;
        };
        let mut cost: Option<String> = None;
        for line in text.lines() {
            let line = line.trim();
            if let Some(c) = line.strip_prefix("/// Cost after CSE: ") {
                cost = Some(c.trim_end_matches('.').to_string());
            } else if let Some(rest) = line.strip_prefix("pub fn ")
                && let Some(c) = cost.take()
            {
                let name: String = rest
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect();
                out.insert(format!("{robot}/{name}"), c);
            } else if !line.starts_with("///") && !line.starts_with("#[") {
                cost = None;
            }
        }
    }
    out
}

fn parse(text: &str) -> BTreeMap<String, String> {
    text.lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .filter_map(|l| l.split_once(": "))
        .map(|(k, v)| (k.trim().to_string(), v.trim().to_string()))
        .collect()
}

/// Total operations of a cost line: mul + add + div + fn.
fn total(cost: &str) -> u64 {
    cost.split(',')
        .filter_map(|p| p.split_whitespace().next()?.parse::<u64>().ok())
        .sum()
}

#[test]
fn generated_kernel_op_counts_match_the_snapshot() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let path = root.join("tests/snapshots/ops.txt");
    let now = current_ops(root);
    assert!(
        now.contains_key("stewart_6ups/mass_matrix") && now.contains_key("five_bar/psi"),
        "found the generated kernels' cost lines: {now:?}"
    );
    if std::env::var_os("RBSS_BLESS").is_some_and(|v| v == "1") {
        let mut text = String::from(
            "# Operation counts of the generated kernels (\"Cost after CSE\" in generated/*/src),\n\
             # checked by tests/ops_snapshot.rs; RBSS_BLESS=1 cargo test --release --test ops_snapshot\n\
             # rewrites this file.\n",
        );
        for (k, v) in &now {
            text.push_str(&format!("{k}: {v}\n"));
        }
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, text).unwrap();
        return;
    }
    let snap = parse(&std::fs::read_to_string(&path).unwrap_or_default());
    let mut diffs = Vec::new();
    for (k, v) in &now {
        match snap.get(k) {
            None => diffs.push(format!("  new kernel {k}: {v}")),
            Some(s) if s != v => {
                let (a, b) = (total(s), total(v));
                let how = if b > a { "WORSE" } else { "better" };
                diffs.push(format!("  {k}: {s} -> {v} ({how}: {a} -> {b} ops)"));
            }
            _ => {}
        }
    }
    for k in snap.keys().filter(|k| !now.contains_key(*k)) {
        diffs.push(format!("  kernel gone: {k}"));
    }
    assert!(
        diffs.is_empty(),
        "generated op counts differ from tests/snapshots/ops.txt:\n{}\n\
         run `RBSS_BLESS=1 cargo test --release --test ops_snapshot` to accept them",
        diffs.join("\n")
    );
}
