//! The documentation stays short, timeless and linked: README.md at most 15 KB with no
//! timestamp, date, issue number or commit hash (those belong in BENCHMARKS.md, beside the
//! figures they date), BENCHMARKS.md at most 40 KB, and every relative link of the README, of
//! BENCHMARKS.md and of the documents under docs/, bench/, models/ and scenes/ resolving to a file (and,
//! into a Markdown file, to one of its headings).

use std::path::{Path, PathBuf};

const README_MAX: usize = 15 * 1024;
const BENCHMARKS_MAX: usize = 40 * 1024;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn read(rel: &str) -> String {
    std::fs::read_to_string(root().join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

fn is_word(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// Timestamps such as `07:45 UTC`.
fn timestamps(text: &str) -> Vec<String> {
    let b: Vec<char> = text.chars().collect();
    let mut found = Vec::new();
    for w in b.windows(9) {
        let d = |k: usize| w[k].is_ascii_digit();
        if d(0) && d(1) && w[2] == ':' && d(3) && d(4) && w[5..] == [' ', 'U', 'T', 'C'] {
            found.push(w.iter().collect());
        }
    }
    found
}

/// Dates such as `2026-11-26`.
fn dates(text: &str) -> Vec<String> {
    let b: Vec<char> = text.chars().collect();
    let mut found = Vec::new();
    for w in b.windows(10) {
        let d = |k: usize| w[k].is_ascii_digit();
        let dashes = w[4] == '-' && w[7] == '-';
        if w[0] == '2' && w[1] == '0' && d(2) && d(3) && dashes && d(5) && d(6) && d(8) && d(9) {
            found.push(w.iter().collect());
        }
    }
    found
}

/// Issue and pull-request references: `issue 19`, `issues 8 and 9`, `#19`, `/issues/19`,
/// `/pull/19`.
fn issue_refs(text: &str) -> Vec<String> {
    let lower = text.to_lowercase();
    let b: Vec<char> = lower.chars().collect();
    let digit_at = |i: usize| i < b.len() && b[i].is_ascii_digit();
    let number_end = |mut i: usize| {
        while digit_at(i) {
            i += 1;
        }
        i
    };
    let mut found = Vec::new();
    for i in 0..b.len() {
        let starts = |s: &str| b[i..].iter().take(s.chars().count()).copied().eq(s.chars());
        let before_ok = i == 0 || !is_word(b[i - 1]);
        for word in ["issue ", "issues ", "/issues/", "/pull/", "pr "] {
            let n = word.chars().count();
            if (before_ok || word.starts_with('/')) && starts(word) && digit_at(i + n) {
                found.push(b[i..number_end(i + n)].iter().collect());
            }
        }
        if b[i] == '#' && before_ok && digit_at(i + 1) {
            found.push(b[i..number_end(i + 1)].iter().collect());
        }
    }
    found
}

/// Commit hashes: 7 to 40 hexadecimal characters between non-word characters, with at least
/// one digit and one letter.
fn hashes(text: &str) -> Vec<String> {
    text.split(|c: char| !is_word(c))
        .filter(|t| {
            (7..=40).contains(&t.len())
                && t.chars().all(|c| c.is_ascii_hexdigit())
                && t.chars().any(|c| c.is_ascii_digit())
                && t.chars().any(|c| c.is_ascii_alphabetic())
        })
        .map(str::to_string)
        .collect()
}

/// The text outside fenced code blocks.
fn prose(text: &str) -> String {
    let mut out = String::new();
    let mut fenced = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if !fenced {
            out.push_str(line);
            out.push('\n');
        }
    }
    out
}

/// GitHub's anchor of a heading: lower case, only letters, digits, `-`, `_` and spaces kept,
/// spaces as `-`; a repeated heading gets `-1`, `-2`, ...
fn anchors(markdown: &str) -> Vec<String> {
    let mut seen: Vec<String> = Vec::new();
    let mut out = Vec::new();
    for line in prose(markdown).lines() {
        let hashes = line.chars().take_while(|&c| c == '#').count();
        if !(1..=6).contains(&hashes) || !line[hashes..].starts_with(' ') {
            continue;
        }
        let slug: String = line[hashes..]
            .trim()
            .to_lowercase()
            .chars()
            .filter(|&c| is_word(c) || c == '-' || c == ' ')
            .map(|c| if c == ' ' { '-' } else { c })
            .collect();
        let n = seen.iter().filter(|s| **s == slug).count();
        seen.push(slug.clone());
        out.push(if n == 0 { slug } else { format!("{slug}-{n}") });
    }
    out
}

/// The targets of the Markdown links `[text](target)` outside code blocks.
fn link_targets(markdown: &str) -> Vec<String> {
    let text = prose(markdown);
    let mut out = Vec::new();
    let mut rest = text.as_str();
    while let Some(at) = rest.find("](") {
        let after = &rest[at + 2..];
        let end = after.find([')', ' ', '\n']).unwrap_or(after.len());
        out.push(after[..end].to_string());
        rest = &after[end..];
    }
    out
}

/// Every relative link of `rel` that does not resolve, with the reason.
fn broken_links(rel: &str) -> Vec<String> {
    let file = root().join(rel);
    let dir = file.parent().unwrap();
    let mut broken = Vec::new();
    for target in link_targets(&read(rel)) {
        if target.contains("://") || target.starts_with("mailto:") {
            continue;
        }
        let (path, anchor) = match target.split_once('#') {
            Some((p, a)) => (p, Some(a)),
            None => (target.as_str(), None),
        };
        let resolved: PathBuf = if path.is_empty() {
            file.clone()
        } else {
            dir.join(path)
        };
        if !resolved.exists() {
            broken.push(format!("{rel}: `{target}`: no such file"));
            continue;
        }
        if let Some(anchor) = anchor
            && resolved.extension().is_some_and(|x| x == "md")
        {
            let text = std::fs::read_to_string(&resolved).unwrap();
            if !anchors(&text).iter().any(|a| a == anchor) {
                broken.push(format!("{rel}: `{target}`: no such heading"));
            }
        }
    }
    broken
}

/// README.md, BENCHMARKS.md and the Markdown files of docs/, bench/, models/ and scenes/.
fn documents() -> Vec<String> {
    let mut docs = vec!["README.md".to_string(), "BENCHMARKS.md".to_string()];
    for dir in ["docs", "bench", "bench/peers", "models", "scenes"] {
        let Ok(rd) = std::fs::read_dir(root().join(dir)) else {
            continue;
        };
        let mut found: Vec<String> = rd
            .flatten()
            .map(|e| e.path())
            .filter(|p| p.is_file() && p.extension().is_some_and(|x| x == "md"))
            .map(|p| format!("{dir}/{}", p.file_name().unwrap().to_string_lossy()))
            .collect();
        found.sort();
        docs.extend(found);
    }
    docs
}

#[test]
fn readme_is_short_and_timeless() {
    let readme = read("README.md");
    let mut problems = Vec::new();
    if readme.len() > README_MAX {
        problems.push(format!(
            "README.md is {} bytes, over {README_MAX}: move detail to docs/",
            readme.len()
        ));
    }
    for (what, found) in [
        ("a timestamp", timestamps(&readme)),
        ("a date", dates(&readme)),
        ("an issue reference", issue_refs(&readme)),
        ("a commit hash", hashes(&readme)),
    ] {
        for f in found {
            problems.push(format!(
                "README.md has {what}, `{f}`: dated facts go to BENCHMARKS.md"
            ));
        }
    }
    for command in [
        "cargo run --release -- paper --out paper-out",
        "cargo test --release --workspace --features rbss/full",
    ] {
        if !readme.contains(command) {
            problems.push(format!("README.md lost the command `{command}`"));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

#[test]
fn benchmarks_is_short() {
    let len = read("BENCHMARKS.md").len();
    assert!(
        len <= BENCHMARKS_MAX,
        "BENCHMARKS.md is {len} bytes, over {BENCHMARKS_MAX}: move superseded passes to \
         docs/benchmarks-history.md"
    );
}

#[test]
fn relative_links_resolve() {
    let docs = documents();
    assert!(docs.iter().any(|d| d == "docs/model-format.md"), "{docs:?}");
    let broken: Vec<String> = docs.iter().flat_map(|d| broken_links(d)).collect();
    assert!(broken.is_empty(), "{}", broken.join("\n"));
}

/// The repository paths a document names in code spans outside code blocks (`runtime/src/lib.rs`, `bench/`): those
/// with a `/` that end in a file extension or a `/`, less placeholders (`NAME`, `DIR`,
/// `my_robot`), globs, absolute paths and build output (`target/`, `bench/peers/build/`).
fn named_paths(markdown: &str) -> Vec<String> {
    let exts = [
        "rs", "md", "toml", "sh", "py", "c", "h", "cpp", "hpp", "csv", "png", "xml", "urdf", "sdf",
        "txt", "json",
    ];
    let mut out = Vec::new();
    let text = prose(markdown);
    let spans = text.lines().flat_map(|l| l.split('`').skip(1).step_by(2));
    for span in spans {
        if span.contains(char::is_whitespace) || !span.contains('/') {
            continue;
        }
        let skip = ["/", "$", "~", ".", "target/", "bench/peers/build/", "http"];
        let placeholder = ["*", "NAME", "DIR", "my_", "{", "::"];
        if skip.iter().any(|p| span.starts_with(p)) || placeholder.iter().any(|p| span.contains(p))
        {
            continue;
        }
        let ext = span.rsplit_once('.').map(|(_, e)| e);
        if span.ends_with('/') || ext.is_some_and(|e| exts.contains(&e)) {
            out.push(span.to_string());
        }
    }
    out
}

#[test]
fn benchmarks_name_existing_paths() {
    let mut missing = Vec::new();
    for doc in ["BENCHMARKS.md", "bench/README.md"] {
        for path in named_paths(&read(doc)) {
            if !root().join(&path).exists() {
                missing.push(format!("{doc}: `{path}` does not exist"));
            }
        }
    }
    assert!(missing.is_empty(), "{}", missing.join("\n"));
}

/// The checks catch what they are for (and nothing in ordinary text).
#[test]
fn the_checks_find_what_they_look_for() {
    assert_eq!(timestamps("measured 07:45 UTC today"), ["07:45 UTC"]);
    assert!(timestamps("a ratio of 3:1, 12:30 local").is_empty());
    assert_eq!(dates("on 2026-11-26, at"), ["2026-11-26"]);
    assert!(dates("models 2026-11 and 1e-10-2").is_empty());
    assert_eq!(issue_refs("see issue 19 and #35."), ["issue 19", "#35"]);
    assert_eq!(issue_refs("github.com/o/r/issues/4"), ["/issues/4"]);
    assert!(issue_refs("an issue with #![no_std], the tissue 3").is_empty());
    assert_eq!(
        hashes("at `d3971df`, main at b899505."),
        ["d3971df", "b899505"]
    );
    assert!(hashes("1e-10 f64 deadbeef 1234567 sha256 0.131").is_empty());
    assert_eq!(
        anchors("# A\n## The paper's round trip\n```\n# not\n```\n## A\n## `--model-file`: x"),
        ["a", "the-papers-round-trip", "a-1", "--model-file-x"]
    );
    assert_eq!(
        named_paths("`runtime/src/lib.rs`, `bench/`, `rbss/full`, `generated/NAME/src/lib.rs`"),
        ["runtime/src/lib.rs", "bench/"]
    );
    assert_eq!(
        link_targets("[a](x.md#y) `[b](z)`\n```\n[c](no)\n```\n[d](https://e)"),
        ["x.md#y", "z", "https://e"]
    );
}
