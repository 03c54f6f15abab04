//! A model file that names a source (`urdf = "..."`, `mjcf`, `sdf`) merged with the model the
//! source imports to.
//!
//! The parser reads one text: the model file as written, then the imported model (as
//! [`super::Imported::render`] writes it, commented with the source's elements and lines). Both
//! are parsed apart and merged as documents, so every position in the model file is the one the
//! user wrote, and an error in the imported part quotes the imported line with its source's
//! element and line. The model file adds and overrides:
//!
//! - `coordinates`, `[[body]]`, `[[loop]]`: an entry whose `name` is an imported entry's sets or
//!   replaces keys of it (a coordinate's `home`, a body's `mass = "m2"` kept as a parameter, a
//!   loop's `components`), in its place; other entries are added after the imported ones;
//! - `[robot]`, `[parameters]`, `[frames]`: keys added, or replacing the imported ones;
//! - `[[leg]]`: added after the imported bodies and loops.

use std::path::Path;

use toml::Spanned;
use toml::de::{DeArray, DeTable, DeValue};

use super::{Format, Imported, Renames, SourceFile, ident, import_renamed};
use crate::diagnostics::{Diagnostic, Diagnostics, Place};
pub use crate::source::SourceMap;

type Value<'a> = Spanned<DeValue<'a>>;

/// What [`resolve`] found: the merged text, where the imported part starts, the source.
pub struct Resolved {
    /// The model file, a separator line, the imported model.
    pub text: String,
    /// Byte offset of the imported model in `text`.
    pub start: usize,
    pub source: SourceFile,
    /// The source's warnings, as the model file's (at the source key).
    pub warnings: Vec<Diagnostic>,
    /// Where the merged text's lines come from.
    pub map: SourceMap,
}

/// The model file's source key (`urdf`, `mjcf`, `sdf`), if it has one: the format, the path as
/// written, and the span of the value.
pub fn source_key(root: &DeTable<'_>) -> Option<(Format, String, std::ops::Range<usize>)> {
    root.iter().find_map(|(k, v)| {
        let f = Format::from_key(k.get_ref())?;
        let path = v.get_ref().as_str().unwrap_or("").to_string();
        Some((f, path, v.span()))
    })
}

/// Imports the source a model file names. `model_path` is the model file's path as shown;
/// the source's path is relative to the model file's directory. An error in the source is
/// reported in the source's own terms (its file, line and column).
pub fn resolve(
    model_path: &str,
    source: &str,
    root: &DeTable<'_>,
    key: (Format, String, std::ops::Range<usize>),
) -> Result<Resolved, Diagnostics> {
    let (format, rel, span) = key;
    let model_diag = |msg: String, label: &str| {
        let pos = crate::source::pos_of(source, span.start);
        let len = source.get(span.clone()).map_or(1, |s| s.chars().count());
        Diagnostics::new(
            model_path,
            source,
            vec![Diagnostic::new(pos, len, msg, label)],
        )
    };
    if rel.trim().is_empty() {
        return Err(model_diag(
            format!("`{}` names no file", format.key()),
            "a path relative to this model file",
        ));
    }
    let dir = Path::new(model_path).parent().unwrap_or(Path::new(""));
    let path = dir.join(&rel);
    let shown = path.display().to_string().replace('\\', "/");
    if !path.is_file() {
        return Err(model_diag(
            format!("cannot read `{shown}`: no such file"),
            "the path is relative to this model file",
        ));
    }
    let (mut renames, spans) = renames_of(model_path, source, root)?;
    let imported = import_renamed(&path, &shown, format, &mut renames);
    // The renames' own mistakes, at their entries in the model file, before the source's errors
    // (a rename onto a name the source already uses would otherwise surface as a duplicate there);
    // names the source lacks only when it imported (else its names may be incomplete).
    let mistakes = rename_mistakes(&renames, &spans, &shown, imported.is_ok(), |span| {
        (
            crate::source::pos_of(source, span.start),
            source.get(span.clone()).map_or(1, |s| s.chars().count()),
        )
    });
    if !mistakes.is_empty() {
        return Err(Diagnostics::new(model_path, source, mistakes));
    }
    let (imported, warnings) = imported?;
    let (text, start, lines) = combined(source, &imported);
    let map = SourceMap {
        model_len: source.len(),
        first_line: text[..start].matches('\n').count() + 1,
        lines,
        key: (
            crate::source::pos_of(source, span.start),
            source.get(span.clone()).map_or(1, |s| s.chars().count()),
        ),
    };
    let warnings = warnings
        .items
        .iter()
        .map(|w| {
            let mut d = model_diag(
                format!("{shown}:{}:{}: {}", w.pos.line, w.pos.col, w.message),
                &w.label,
            )
            .items
            .remove(0);
            d.help = w.help.clone();
            d
        })
        .collect();
    Ok(Resolved {
        text,
        start,
        source: imported.source.clone().unwrap_or(SourceFile {
            path: shown,
            sha256: String::new(),
        }),
        warnings,
        map,
    })
}

/// What is wrong with the model file's renames once the source's names are known: a name the
/// source does not have (with the nearest names as help; only when `complete`, the source's
/// names all read), and a new name another joint (body) of the source already has: each at its
/// `[rename]` entry (`at` gives the position and length of an entry's span).
fn rename_mistakes(
    renames: &Renames,
    spans: &[Vec<std::ops::Range<usize>>; 2],
    shown: &str,
    complete: bool,
    at: impl Fn(&std::ops::Range<usize>) -> (crate::diagnostics::Pos, usize),
) -> Vec<Diagnostic> {
    let mut out = Vec::new();
    for ((kind, list, seen), spans) in [
        ("joint", &renames.joints, &renames.seen_joints),
        ("body", &renames.bodies, &renames.seen_bodies),
    ]
    .into_iter()
    .zip(spans)
    {
        for ((from, to), span) in list.iter().zip(spans) {
            let (pos, len) = at(span);
            if !seen.contains(from) {
                if !complete {
                    continue;
                }
                let mut d = Diagnostic::new(
                    pos,
                    len,
                    format!("{shown} has no {kind} `{from}`"),
                    "not renamed",
                );
                d.help = crate::diagnostics::suggest(from, seen.iter().map(|s| (s.as_str(), None)))
                    .or_else(|| {
                        (!seen.is_empty()).then(|| {
                            let names: Vec<&str> =
                                seen.iter().take(12).map(String::as_str).collect();
                            format!("its {kind} names: {}", names.join(", "))
                        })
                    });
                out.push(d);
                continue;
            }
            // Another of the source's names that ends up as `to` (kept, or mapped to it).
            let taken = seen
                .iter()
                .find(|s| *s != from && !list.iter().any(|(f, _)| f == *s) && ident(s) == *to);
            if let Some(other) = taken {
                let mut d = Diagnostic::new(
                    pos,
                    len,
                    format!(
                        "{kind} `{from}` cannot be renamed `{to}`: {shown}'s {kind} `{other}` has that name"
                    ),
                    "a name already taken",
                );
                d.help = Some(format!(
                    "choose another name, or rename `{other}` too (`{other} = \"...\"`)"
                ));
                out.push(d);
            }
        }
    }
    out
}

/// The model file's `[rename]`: `joints = { SOURCE_NAME = "new_name" }` and `bodies = {...}`
/// (URDF and SDF links, MJCF bodies), with the span of each key; every mistake in it at once.
#[allow(clippy::type_complexity)]
fn renames_of(
    model_path: &str,
    source: &str,
    root: &DeTable<'_>,
) -> Result<(Renames, [Vec<std::ops::Range<usize>>; 2]), Diagnostics> {
    let mut renames = Renames::default();
    let mut spans: [Vec<std::ops::Range<usize>>; 2] = [Vec::new(), Vec::new()];
    let mut errors = Vec::new();
    let mut error = |span: std::ops::Range<usize>, msg: String, label: &str| {
        errors.push(Diagnostic::new(
            crate::source::pos_of(source, span.start),
            source
                .get(span)
                .map_or(1, |s| s.lines().next().unwrap_or("").chars().count()),
            msg,
            label,
        ));
    };
    let Some(r) = root.iter().find(|(k, _)| k.get_ref().as_ref() == RENAME) else {
        return Ok((renames, spans));
    };
    let Some(table) = r.1.get_ref().as_table() else {
        error(
            r.1.span(),
            "`rename` must be a table".into(),
            "expected `[rename]`",
        );
        return Err(Diagnostics::new(model_path, source, errors));
    };
    for (k, v) in table.iter() {
        let which = match k.get_ref().as_ref() {
            "joints" => 0,
            "bodies" => 1,
            other => {
                error(
                    k.span(),
                    format!("unknown key `{other}` in `[rename]`"),
                    "expected `joints` or `bodies`",
                );
                continue;
            }
        };
        let Some(names) = v.get_ref().as_table() else {
            error(
                v.span(),
                format!("`rename.{}` must be a table", k.get_ref()),
                "expected `{ source_name = \"new_name\" }`",
            );
            continue;
        };
        for (from, to) in names.iter() {
            let Some(new) = to.get_ref().as_str() else {
                error(
                    to.span(),
                    "a new name must be a string".into(),
                    "expected a string",
                );
                continue;
            };
            if ident(new) != new {
                error(
                    to.span(),
                    format!("`{new}` cannot name a joint or body"),
                    "not an identifier, or a reserved word",
                );
                continue;
            }
            let list = if which == 0 {
                &mut renames.joints
            } else {
                &mut renames.bodies
            };
            if let Some((first, _)) = list.iter().find(|(_, n)| n == new) {
                error(
                    to.span(),
                    format!(
                        "`{first}` and `{}` are both renamed `{new}`",
                        from.get_ref()
                    ),
                    "a second name for the same identifier",
                );
                continue;
            }
            list.push((from.get_ref().to_string(), new.to_string()));
            spans[which].push(from.span());
        }
    }
    if errors.is_empty() {
        Ok((renames, spans))
    } else {
        Err(Diagnostics::new(model_path, source, errors))
    }
}

/// The model file's table of renames of the source's names.
pub const RENAME: &str = "rename";

/// The model file, then a separator comment, then the imported model; the imported lines
/// with their places.
#[allow(clippy::type_complexity)]
fn combined(source: &str, imported: &Imported) -> (String, usize, Vec<(String, Option<Place>)>) {
    let mut text = source.to_string();
    if !text.ends_with('\n') {
        text.push('\n');
    }
    text.push_str("# ---- imported ----\n");
    let start = text.len();
    let (rendered, places) = imported.render_mapped();
    text.push_str(&rendered);
    let lines = rendered.lines().map(str::to_string).zip(places).collect();
    (text, start, lines)
}

/// The document of the merged text: the model file's (`overlay`, the source key removed) merged
/// with the imported one, parsed from `text[start..]` (spans moved to `text`).
pub fn merged<'a>(
    overlay: &DeTable<'a>,
    text: &'a str,
    start: usize,
) -> Result<DeTable<'a>, String> {
    let imported = DeTable::parse(&text[start..]).map_err(|e| e.to_string())?;
    let imported = shift_table(imported.get_ref(), start);
    let mut out = imported;
    for (k, v) in overlay.iter() {
        let key = k.get_ref().as_ref();
        if Format::from_key(key).is_some() || key == RENAME {
            continue;
        }
        let existing = out
            .iter()
            .find(|(ik, _)| ik.get_ref().as_ref() == key)
            .map(|(ik, iv)| (ik.clone(), iv.clone()));
        let merged = match (key, existing) {
            (_, None) => v.clone(),
            ("coordinates" | "body" | "loop", Some((_, iv))) => merge_by_name(&iv, v),
            ("leg", Some((_, iv))) => concat(&iv, v),
            (_, Some((_, iv))) => merge_tables(&iv, v, v.span()),
        };
        // The key as the model file wrote it, when it wrote one.
        out.remove(key);
        out.insert(k.clone(), merged);
    }
    Ok(out)
}

fn shift_table<'a>(t: &DeTable<'a>, by: usize) -> DeTable<'a> {
    let mut out = DeTable::new();
    for (k, v) in t.iter() {
        let ks = k.span();
        out.insert(
            Spanned::new(ks.start + by..ks.end + by, k.get_ref().clone()),
            shift(v, by),
        );
    }
    out
}

fn shift<'a>(v: &Value<'a>, by: usize) -> Value<'a> {
    let s = v.span();
    let span = s.start + by..s.end + by;
    let inner = match v.get_ref() {
        DeValue::Array(a) => DeValue::Array(a.iter().map(|x| shift(x, by)).collect()),
        DeValue::Table(t) => DeValue::Table(shift_table(t, by)),
        other => other.clone(),
    };
    Spanned::new(span, inner)
}

fn name_of<'v>(v: &'v Value<'_>) -> Option<&'v str> {
    v.get_ref()
        .as_table()?
        .iter()
        .find(|(k, _)| k.get_ref().as_ref() == "name")
        .and_then(|(_, n)| n.get_ref().as_str())
}

/// Imported entries (coordinates, bodies, loops), with the model file's entries of the same
/// name merged into them (in their place) and its others after them.
fn merge_by_name<'a>(imported: &Value<'a>, overlay: &Value<'a>) -> Value<'a> {
    let (DeValue::Array(ia), DeValue::Array(oa)) = (imported.get_ref(), overlay.get_ref()) else {
        // Not an array in the model file: the parser reports it there.
        return overlay.clone();
    };
    let mut out: DeArray<'a> = ia.clone();
    for o in oa.iter() {
        let hit = name_of(o).and_then(|n| out.iter().position(|i| name_of(i) == Some(n)));
        match hit {
            Some(i) => {
                let m = merge_tables(&out[i], o, out[i].span());
                out.as_mut()[i] = m;
            }
            None => out.push(o.clone()),
        }
    }
    Spanned::new(overlay.span(), DeValue::Array(out))
}

/// The imported entries, then the model file's.
fn concat<'a>(imported: &Value<'a>, overlay: &Value<'a>) -> Value<'a> {
    match (imported.get_ref(), overlay.get_ref()) {
        (DeValue::Array(ia), DeValue::Array(oa)) => {
            let mut out = ia.clone();
            for o in oa.iter() {
                out.push(o.clone());
            }
            Spanned::new(overlay.span(), DeValue::Array(out))
        }
        _ => overlay.clone(),
    }
}

/// The imported table with the model file's keys added or replacing its own.
fn merge_tables<'a>(
    imported: &Value<'a>,
    overlay: &Value<'a>,
    span: std::ops::Range<usize>,
) -> Value<'a> {
    let (DeValue::Table(it), DeValue::Table(ot)) = (imported.get_ref(), overlay.get_ref()) else {
        return overlay.clone();
    };
    let mut out = it.clone();
    for (k, v) in ot.iter() {
        out.remove(k.get_ref().as_ref());
        out.insert(k.clone(), v.clone());
    }
    Spanned::new(span, DeValue::Table(out))
}
