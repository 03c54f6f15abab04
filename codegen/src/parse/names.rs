//! Names: suggestions, identifiers, reserved words, snake_case.

use super::*;

// Names

pub(super) use crate::diagnostics::{edit_distance, suggest};

pub(super) fn is_identifier(s: &str) -> bool {
    let mut chars = s.chars();
    matches!(chars.next(), Some(c) if c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

pub(super) use crate::model::RUST_KEYWORDS;

/// Robot names the generated crate cannot hold, with the reason: its module is `src/NAME.rs`,
/// and its robot type `CamelName` must not clash with the other types of the module (each
/// found by compiling the crate generated with that name).
pub(super) const RESERVED_ROBOT_NAMES: &[(&str, &str)] = &[
    (
        "lib",
        "`src/lib.rs` would be both the crate root and the kernels",
    ),
    (
        "main",
        "`src/main.rs` would make the crate a binary whose `main` is missing",
    ),
    (
        "params",
        "the robot's type `Params` would clash with the parameters' struct",
    ),
    (
        "structure",
        "the robot's type `Structure` would clash with the runtime's",
    ),
    (
        "kernels",
        "the robot's type `Kernels` would clash with the runtime's trait",
    ),
    (
        "ik_block",
        "the robot's type `IkBlock` would clash with the runtime's",
    ),
    (
        "default",
        "the robot's type `Default` would hide the trait `Default`",
    ),
    (
        "rbss",
        "the crate `rbss` (the command's library) is a dependency of the robot's library",
    ),
    (
        "rbss_ffi",
        "the crate `rbss-ffi` (the C ABI) is a dependency of the robot's library",
    ),
    (
        "rbss_runtime",
        "the crate `rbss-runtime` is a dependency of the generated crate",
    ),
    (
        "std",
        "`std` is the standard library's crate: the generated code names it",
    ),
    (
        "core",
        "`core` is the standard library's crate: the generated code names it",
    ),
    (
        "alloc",
        "`alloc` is the standard library's crate: the generated code names it",
    ),
];

/// Why `name` cannot name a scene's crate (its module is `src/NAME.rs`, declared `mod NAME;`),
/// or `None`. The robot type of a scene's crate is named after the model, so only the layout
/// and the keywords matter here.
pub(crate) fn scene_name_conflict(name: &str) -> Option<String> {
    if RUST_KEYWORDS.contains(&name) {
        return Some(format!(
            "`{name}` is a Rust keyword: `mod {name};` cannot declare it"
        ));
    }
    RESERVED_ROBOT_NAMES
        .iter()
        .find(|(n, _)| *n == name && matches!(name, "lib" | "main"))
        .map(|(_, why)| why.to_string())
}

pub(super) const FUNC_NAMES: &[&str] = &Func::NAMES;
/// The functions whose argument may depend on the coordinates (the derivation differentiates
/// them); the others take constants: numbers and parameters.
pub(super) const COORD_FUNCS: &[Func] = &[Func::Sin, Func::Cos, Func::Tan, Func::Sqrt];
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
