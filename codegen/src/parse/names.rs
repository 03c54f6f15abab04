//! Names: suggestions, identifiers, reserved words, snake_case.

use super::*;

// Names

/// Levenshtein distance, `None` when either string is too long to bother.
pub(super) fn edit_distance(a: &str, b: &str) -> Option<usize> {
    let a: Vec<char> = a.chars().collect();
    let b: Vec<char> = b.chars().collect();
    if a.len() > 64 || b.len() > 64 {
        return None;
    }
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    let mut cur = vec![0; b.len() + 1];
    for i in 1..=a.len() {
        cur[0] = i;
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            cur[j] = (prev[j] + 1).min(cur[j - 1] + 1).min(prev[j - 1] + cost);
        }
        std::mem::swap(&mut prev, &mut cur);
    }
    Some(prev[b.len()])
}

/// `did you mean `x` (line N)?` for the closest candidate within edit distance 2.
pub(super) fn suggest<'c>(
    name: &str,
    candidates: impl IntoIterator<Item = (&'c str, Option<usize>)>,
) -> Option<String> {
    let mut best: Option<(usize, &str, Option<usize>)> = None;
    for (cand, line) in candidates {
        if cand == name || cand.is_empty() {
            continue;
        }
        let Some(d) = edit_distance(name, cand) else {
            continue;
        };
        let close = d <= 2 && d < name.chars().count().max(cand.chars().count());
        // A difference in case only is the closest match of all.
        let d = if name.to_lowercase() == cand.to_lowercase() {
            0
        } else {
            d
        };
        if (close || d == 0) && best.is_none_or(|(bd, _, _)| d < bd) {
            best = Some((d, cand, line));
        }
    }
    best.map(|(_, cand, line)| match line {
        Some(l) => format!("did you mean `{cand}` (line {l})?"),
        None => format!("did you mean `{cand}`?"),
    })
}

pub(super) fn is_identifier(s: &str) -> bool {
    let mut chars = s.chars();
    matches!(chars.next(), Some(c) if c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

pub(super) const RUST_KEYWORDS: &[&str] = &[
    "as", "async", "await", "break", "const", "continue", "crate", "dyn", "else", "enum", "extern",
    "false", "fn", "for", "gen", "if", "impl", "in", "let", "loop", "match", "mod", "move", "mut",
    "pub", "ref", "return", "self", "Self", "static", "struct", "super", "trait", "true", "type",
    "unsafe", "use", "where", "while", "abstract", "become", "box", "do", "final", "macro",
    "override", "priv", "try", "typeof", "unsized", "virtual", "yield", "_",
];

pub(super) const FUNCS: &[(&str, Func)] = &[
    ("sin", Func::Sin),
    ("cos", Func::Cos),
    ("tan", Func::Tan),
    ("sqrt", Func::Sqrt),
];
pub(super) const FUNC_NAMES: &[&str] = &["sin", "cos", "tan", "sqrt"];
pub(super) const STEP_NAMES: &[&str] = &["Rx", "Ry", "Rz", "Tx", "Ty", "Tz"];

pub(super) fn is_snake_case(s: &str) -> bool {
    !s.is_empty()
        && s.starts_with(|c: char| c.is_ascii_lowercase())
        && s.chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
        && !s.ends_with('_')
        && !s.contains("__")
}

/// A snake_case spelling of `s` (for the help of a bad robot name).
pub(super) fn to_snake_case(s: &str) -> String {
    let mut out = String::new();
    let chars: Vec<char> = s.chars().collect();
    for (i, &c) in chars.iter().enumerate() {
        if c.is_ascii_uppercase() {
            let prev_lower =
                i > 0 && (chars[i - 1].is_ascii_lowercase() || chars[i - 1].is_ascii_digit());
            let next_lower = chars.get(i + 1).is_some_and(|n| n.is_ascii_lowercase());
            let prev_upper = i > 0 && chars[i - 1].is_ascii_uppercase();
            if prev_lower || (prev_upper && next_lower) {
                out.push('_');
            }
            out.push(c.to_ascii_lowercase());
        } else if c.is_ascii_alphanumeric() {
            out.push(c);
        } else {
            out.push('_');
        }
    }
    let mut parts: Vec<&str> = out.split('_').filter(|p| !p.is_empty()).collect();
    while parts
        .first()
        .is_some_and(|p| p.starts_with(|c: char| c.is_ascii_digit()))
    {
        parts.remove(0);
    }
    parts.join("_")
}
