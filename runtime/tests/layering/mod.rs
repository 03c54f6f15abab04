//! The import checker behind the layers tests (`runtime/tests/layers.rs`,
//! `codegen/tests/layers.rs`, `tests/layers.rs`): every `crate::`, `super::` and child-module
//! path in the code of a crate's src/**.rs (comments and `#[cfg(test)]` modules left out) is an
//! import of the module it names, and an import may only go to the same or a lower layer, with
//! no cycle among the modules.
//!
//! Imports through the crate root (`crate::forward_dynamics`, a re-export of lib.rs) are
//! refused too, unless a layer names the root (`""`): they hide which module is used. A parent's `pub use child::X` is an import of
//! the child, so a child must name a sibling's item by the sibling (`super::report::X`), not
//! through the parent's re-export.

// Each test crate that includes this file uses all of it.
#![allow(dead_code)]

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Path, PathBuf};

/// The layers, lowest first, each a name and its modules (by their first path segment): a
/// module may import modules of its own layer or of lower ones.
pub type Layers<'a> = &'a [(&'a str, &'a [&'a str])];

/// One import: the line that holds it.
#[derive(Debug, Clone)]
pub struct Site {
    file: String,
    line: usize,
    text: String,
}

fn rank(layers: Layers, module: &str) -> Option<usize> {
    let top = module.split("::").next().unwrap_or("");
    layers.iter().position(|(_, ms)| ms.contains(&top))
}

fn rs_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.expect("directory entry").path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            rs_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

/// `algorithm/forward_dynamics/mod.rs` -> `algorithm::forward_dynamics`; lib.rs -> "".
fn module_of(rel: &Path) -> String {
    let mut parts: Vec<String> = rel
        .iter()
        .map(|s| s.to_string_lossy().into_owned())
        .collect();
    let last = parts.pop().unwrap_or_default();
    let stem = last.trim_end_matches(".rs");
    if stem != "mod" && stem != "lib" {
        parts.push(stem.to_string());
    }
    parts.join("::")
}

fn parent(module: &str) -> String {
    match module.rfind("::") {
        Some(i) => module[..i].to_string(),
        None => String::new(),
    }
}

/// The code of a file, line by line: `//` comments blanked, and nothing from a `#[cfg(test)]`
/// on (the unit tests at the end of a file).
fn code_lines(src: &str) -> Vec<String> {
    let mut out = Vec::new();
    for line in src.lines() {
        if line.trim_start().starts_with("#[cfg(test)]") {
            break;
        }
        let mut code = String::new();
        let mut in_str = false;
        let mut prev = ' ';
        let mut chars = line.chars().peekable();
        while let Some(c) = chars.next() {
            if !in_str && c == '/' && chars.peek() == Some(&'/') {
                break;
            }
            if c == '"' && prev != '\\' {
                in_str = !in_str;
            }
            // Blank string contents: a path in a message is no import.
            code.push(if in_str && c != '"' { ' ' } else { c });
            prev = c;
        }
        out.push(code);
    }
    out
}

fn is_ident(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// The paths of a `use` tree (or a plain path) starting at `s` (just after `prefix::`): each
/// as its segments, with `{a::b, c}` groups expanded.
fn paths_from(s: &[char], i: &mut usize, prefix: Vec<String>, out: &mut Vec<Vec<String>>) {
    let mut segs = prefix;
    loop {
        while *i < s.len() && s[*i].is_whitespace() {
            *i += 1;
        }
        if *i < s.len() && s[*i] == '{' {
            *i += 1;
            loop {
                while *i < s.len() && (s[*i].is_whitespace() || s[*i] == ',') {
                    *i += 1;
                }
                if *i >= s.len() || s[*i] == '}' {
                    *i += 1;
                    return;
                }
                paths_from(s, i, segs.clone(), out);
            }
        }
        let start = *i;
        while *i < s.len() && is_ident(s[*i]) {
            *i += 1;
        }
        if *i > start {
            segs.push(s[start..*i].iter().collect());
        }
        if *i + 1 < s.len() && s[*i] == ':' && s[*i + 1] == ':' {
            *i += 2;
            continue;
        }
        // Skip ` as name`, generic arguments and the like up to the end of this element.
        let mut depth = 0_i32;
        while *i < s.len() {
            match s[*i] {
                '<' | '(' | '[' => depth += 1,
                '>' | ')' | ']' if depth > 0 => depth -= 1,
                ',' | '}' | ';' if depth == 0 => break,
                c if depth == 0 && !is_ident(c) && !c.is_whitespace() => break,
                _ => {}
            }
            *i += 1;
        }
        out.push(segs);
        return;
    }
}

/// Resolves a path to the longest prefix that is a module.
fn resolve(base: &str, segs: &[String], modules: &BTreeSet<String>) -> String {
    let mut m = base.to_string();
    for s in segs {
        let next = if m.is_empty() {
            s.clone()
        } else {
            format!("{m}::{s}")
        };
        if modules.contains(&next) {
            m = next;
        } else {
            break;
        }
    }
    m
}

/// Every import of `module` (file `rel`): the module it names and where.
fn imports(module: &str, rel: &str, src: &str, modules: &BTreeSet<String>) -> Vec<(String, Site)> {
    let children: Vec<String> = modules
        .iter()
        .filter(|m| parent(m) == module && !m.is_empty())
        .map(|m| m.rsplit("::").next().unwrap_or("").to_string())
        .collect();
    let mut out = Vec::new();
    // A `use` may span lines: scan the whole code with line numbers per character.
    let lines = code_lines(src);
    let mut text: Vec<char> = Vec::new();
    let mut line_of: Vec<usize> = Vec::new();
    for (n, l) in lines.iter().enumerate() {
        for c in l.chars().chain(std::iter::once('\n')) {
            text.push(c);
            line_of.push(n);
        }
    }
    let mut i = 0;
    while i < text.len() {
        let before = if i == 0 { ' ' } else { text[i - 1] };
        if is_ident(before) || (before == ':' && !(i >= 2 && text[i - 2] == '$')) {
            i += 1;
            continue;
        }
        let rest: String = text[i..(i + 64).min(text.len())].iter().collect();
        let start = i;
        let (base, skip) = if rest.starts_with("crate::") {
            (String::new(), "crate::".len())
        } else if rest.starts_with("super::") {
            let mut base = parent(module);
            let mut skip = "super::".len();
            while rest[skip..].starts_with("super::") {
                base = parent(&base);
                skip += "super::".len();
            }
            (base, skip)
        } else if rest.starts_with("self::") {
            (module.to_string(), "self::".len())
        } else if let Some(c) = children
            .iter()
            .find(|c| rest.starts_with(&format!("{c}::")))
        {
            let _ = c;
            (module.to_string(), 0)
        } else {
            i += 1;
            continue;
        };
        i += skip;
        let mut paths = Vec::new();
        paths_from(&text, &mut i, Vec::new(), &mut paths);
        let line = line_of[start];
        for p in paths {
            let target = resolve(&base, &p, modules);
            if target != module {
                let site = Site {
                    file: rel.to_string(),
                    line: line + 1,
                    text: src.lines().nth(line).unwrap_or("").trim().to_string(),
                };
                out.push((target, site));
            }
        }
        i = i.max(start + 1);
    }
    out
}

/// The strongly connected components of more than one module (Tarjan).
fn cycles(graph: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    struct St<'a> {
        g: &'a BTreeMap<String, BTreeSet<String>>,
        index: BTreeMap<String, usize>,
        low: BTreeMap<String, usize>,
        stack: Vec<String>,
        on: BTreeSet<String>,
        next: usize,
        out: Vec<Vec<String>>,
    }
    fn visit(st: &mut St, v: &str) {
        st.index.insert(v.to_string(), st.next);
        st.low.insert(v.to_string(), st.next);
        st.next += 1;
        st.stack.push(v.to_string());
        st.on.insert(v.to_string());
        let succ: Vec<String> = st.g.get(v).into_iter().flatten().cloned().collect();
        for w in succ {
            if !st.index.contains_key(&w) {
                visit(st, &w);
                let lw = st.low[&w];
                let lv = st.low.get_mut(v).unwrap();
                *lv = (*lv).min(lw);
            } else if st.on.contains(&w) {
                let iw = st.index[&w];
                let lv = st.low.get_mut(v).unwrap();
                *lv = (*lv).min(iw);
            }
        }
        if st.low[v] == st.index[v] {
            let mut comp = Vec::new();
            while let Some(w) = st.stack.pop() {
                st.on.remove(&w);
                let done = w == v;
                comp.push(w);
                if done {
                    break;
                }
            }
            if comp.len() > 1 {
                comp.sort();
                st.out.push(comp);
            }
        }
    }
    let mut st = St {
        g: graph,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on: BTreeSet::new(),
        next: 0,
        out: Vec::new(),
    };
    for v in graph.keys() {
        if !st.index.contains_key(v) {
            visit(&mut st, v);
        }
    }
    st.out
}

/// The import graph of the sources under `src`: module -> module -> the lines.
pub type Graph = BTreeMap<String, BTreeMap<String, Vec<Site>>>;

pub fn graph_of(src: &Path) -> Graph {
    let mut files = Vec::new();
    rs_files(src, &mut files);
    let modules: BTreeSet<String> = files
        .iter()
        .map(|f| module_of(f.strip_prefix(src).unwrap()))
        .collect();
    let mut graph = Graph::new();
    for f in &files {
        let rel = f.strip_prefix(src).unwrap();
        let module = module_of(rel);
        if module.is_empty() {
            continue; // lib.rs: the module list and the public re-exports
        }
        let text = fs::read_to_string(f).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        let entry = graph.entry(module.clone()).or_default();
        for (target, site) in imports(&module, &rel.display().to_string(), &text, &modules) {
            let sites = entry.entry(target).or_default();
            if !sites
                .iter()
                .any(|s| s.line == site.line && s.file == site.file)
            {
                sites.push(site);
            }
        }
    }
    graph
}

/// The graph of the top-level modules: a module's submodules are one node with it (their
/// imports of each other dropped), for a crate whose module directories keep the parent and
/// children pattern (`super::` helpers of a `mod.rs` that calls its children): only the
/// imports between top-level modules are then held to the layers and to no cycle.
pub fn top_level(graph: &Graph) -> Graph {
    let top = |m: &str| m.split("::").next().unwrap_or("").to_string();
    let mut out = Graph::new();
    for (from, edges) in graph {
        let entry = out.entry(top(from)).or_default();
        for (to, sites) in edges {
            if top(to) == top(from) && !to.is_empty() {
                continue;
            }
            entry
                .entry(top(to))
                .or_default()
                .extend(sites.iter().cloned());
        }
    }
    out
}

/// What is wrong with the graph: imports through the root, against the layers, in a cycle.
/// `test` names the file that holds `layers`, for the message of a module without a layer.
pub fn violations(graph: &Graph, layers: Layers, test: &str) -> Vec<String> {
    let mut bad = Vec::new();
    let show = |sites: &[Site]| -> String {
        sites
            .iter()
            .map(|s| format!("\n    {}:{}: {}", s.file, s.line, s.text))
            .collect()
    };
    for (from, edges) in graph {
        let Some(rf) = rank(layers, from) else {
            bad.push(format!(
                "module `{from}` has no layer (add it to LAYERS in {test} and to the crate docs)"
            ));
            continue;
        };
        for (to, sites) in edges {
            // The crate root is a module like the others only where a layer names it (`""`):
            // a crate whose lib.rs holds helpers and `#[macro_export]` macros.
            if to.is_empty() && rank(layers, "").is_none() {
                bad.push(format!(
                    "`{from}` imports through the crate root (name the module):{}",
                    show(sites)
                ));
                continue;
            }
            match rank(layers, to) {
                Some(rt) if rt > rf => bad.push(format!(
                    "`{from}` ({}) imports `{to}` ({}), a higher layer:{}",
                    layers[rf].0,
                    layers[rt].0,
                    show(sites)
                )),
                Some(_) => {}
                None => bad.push(format!("`{from}` imports `{to}`, which has no layer")),
            }
        }
    }
    let simple: BTreeMap<String, BTreeSet<String>> = graph
        .iter()
        .map(|(m, e)| {
            (
                m.clone(),
                e.keys().filter(|t| !t.is_empty()).cloned().collect(),
            )
        })
        .collect();
    for comp in cycles(&simple) {
        let mut msg = format!("import cycle among {}:", comp.join(", "));
        for m in &comp {
            for (to, sites) in &graph[m] {
                if comp.contains(to) {
                    msg.push_str(&format!("\n  `{m}` -> `{to}`:{}", show(sites)));
                }
            }
        }
        bad.push(msg);
    }
    bad
}
