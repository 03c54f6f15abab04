//! Model file (TOML) -> validated [`Model`], collecting every error with its exact position.
//!
//! The TOML text is parsed by `toml::de::DeTable::parse`, which keeps the byte span of every
//! key and value; this module then walks the document itself so that it can report *all* the
//! semantic errors of a file at once, each at the key, value or expression token it is about.
//! A TOML syntax error stops there (no tree exists to walk).
//!
//! # File format
//!
//! The reference with an example per construct is `docs/model-format.md`; in brief:
//!
//! ```toml
//! coordinates = [                 # top-level key: must come before the first [table] header
//!   { name = "d1", unit = "m", home = 0.9 },     # unit: "m", "rad" or "deg" (home converted)
//! ]
//!
//! [robot]
//! name = "stewart_6ups"           # snake_case, the generated crate's name
//! description = "..."             # optional
//! gravity = [0, 0, -9.81]         # parameter expressions
//! actuated = ["d1"]               # coordinates q
//! outputs = ["x"]                 # task coordinates, one per degree of freedom (may share an
//!                                 # actuated coordinate: one in no loop must); or a task
//!                                 # frame: [{ frame = "tool0", pose = "xyz-rpy" }] (`task_frames`)
//!
//! [parameters]                    # in order: a value may use only parameters above it
//! r0 = { value = 0.489, unit = "m", doc = "..." }
//! rho = 7800
//! alpha1 = { value = -15, unit = "deg" }   # stored as -15 * (pi / 180)
//!
//! [[body]]
//! name = "leg1_lower"
//! parent = "world"                # optional; "world" or a body defined above
//! transforms = ["Rz(alpha1)", "Tx(r0)", ["x", "y", "z", 0, 0, 0, 1, 2, 3, 4, 5, 6]]
//! mass = "m"                      # with `inertia`, or instead of both: `solid`
//! com = [0, 0, 0.25]              # optional, body frame
//! inertia = [1, 1, 1, 0, 0, 0]    # [Ixx, Iyy, Izz, Ixy, Ixz, Iyz] about the com, body axes
//! solid = { shape = "cylinder", radius = 0.05, length = 0.5, density = "rho" }
//!
//! [[loop]]
//! name = "leg1"
//! a = { body = "leg1_upper" }
//! b = { body = "platform", transforms = ["Rz(beta1)", "Tx(rp)"] }
//! components = ["x", "y", "z"]    # optional
//! ```
//!
//! Decisions beyond the basics:
//!
//! - Repetition (`repeat.rs`): an entry of `coordinates`, `[parameters]`, `[[body]]` or
//!   `[[loop]]` with `count = N`, and `[[leg]]` groups (`count`, `[[leg.body]]`,
//!   `[[leg.loop]]`), expand before the walk into N entries with `{i}` replaced by 1..N.
//! - Joints by name (`joints.rs`): `{ revolute = "q", axis = "z" }`, `prismatic`,
//!   `universal = ["a", "b"]`, `spherical = ["a", "b", "c"]` in `transforms`, lowered to the
//!   elementary steps.
//! - `inertia` is positive semidefinite (a thin rod); `M` of the robot is checked at the
//!   assembled home by the generator (`assemble::check_mass`).
//! - `inertia` entries `Ixy, Ixz, Iyz` are the off-diagonal *entries of the inertia matrix*
//!   (`I_xy = -∫ x y dm`), as in URDF and MuJoCo's `fullinertia`.
//! - Solids (homogeneous, centred on the centre of mass, which still comes from `com`):
//!   `cylinder` (`radius`, `length`, `axis` `z` unless given), `box` (`size = [a, b, c]`
//!   along `x, y, z`), each with either `density` or `mass`; `rod` (a thin rod along `axis`,
//!   `z` unless given: `length` and `mass`, `m L^2 / 12` across, 0 about the axis).
//! - A coordinate unit is `m`, `rad` or `deg`; `home` is optional (default 0) and may be a
//!   parameter expression.
//! - Names of parameters, coordinates, bodies and loops are identifiers that are not Rust
//!   keywords (they become Rust names); `pi` and the function names are reserved.
//! - Every coordinate must be used by at least one transform (otherwise the mass matrix and
//!   the constraint Jacobian would have a zero column).
//! - A unary minus directly in front of a number literal is folded into the number.

use std::collections::HashMap;
use std::ops::Range;

use toml::Spanned;
use toml::de::{DeTable, DeValue};

use crate::diagnostics::{Diagnostic, Diagnostics};
use crate::model::{
    Attachment, Axis, Body, Coordinate, Expr, Func, JointForces, Loop, LoopKind, MassProps, Model,
    Parameter, Pos, Side, Step,
};

mod bodies;
mod cx;
mod expr;
mod inertia;
mod joints;
mod loops;
mod names;
mod poses;
mod repeat;
mod sections;
mod structure;
mod task_frames;
mod walker;
mod warnings;

#[cfg(test)]
mod tests;

use cx::*;
use expr::*;
pub(crate) use names::scene_name_conflict;
use names::*;
use repeat::*;
use walker::*;

type Value<'a> = Spanned<DeValue<'a>>;
type Span = Range<usize>;

/// Parses and validates a model file. `path` is only used in messages.
pub fn parse_model(path: &str, source: &str) -> Result<Model, Diagnostics> {
    parse_model_with_warnings(path, source).0
}

/// [`parse_model`], and the model's warnings (render them with
/// [`Diagnostics::render_warnings`]; empty when there are none or the model has errors).
pub fn parse_model_with_warnings(
    path: &str,
    source: &str,
) -> (Result<Model, Diagnostics>, Diagnostics) {
    let no_warnings = || Diagnostics::new(path, source, Vec::new());
    let doc = match DeTable::parse(source) {
        Ok(doc) => doc,
        Err(e) => {
            let cx = Cx::new(source);
            let errors = Diagnostics::new(path, source, vec![toml_error(&cx, &e)]);
            return (Err(errors), no_warnings());
        }
    };
    // A model file that names a source (`urdf = "..."`): the source imported, then merged
    // (crate::import::merge); every position stays the model file's.
    let resolved = match crate::import::merge::source_key(doc.get_ref()) {
        None => None,
        Some(key) => match crate::import::merge::resolve(path, source, doc.get_ref(), key) {
            Ok(r) => Some(r),
            Err(d) => return (Err(d), no_warnings()),
        },
    };
    let text = resolved.as_ref().map_or(source, |r| r.text.as_str());
    let merged;
    let doc_root = match &resolved {
        None => doc.get_ref(),
        Some(r) => match crate::import::merge::merged(doc.get_ref(), text, r.start) {
            Ok(m) => {
                merged = m;
                &merged
            }
            Err(e) => {
                let d = Diagnostic::new(
                    Pos { line: 1, col: 1 },
                    1,
                    format!("internal error: the imported model is not TOML: {e}"),
                    "",
                );
                return (Err(Diagnostics::new(path, text, vec![d])), no_warnings());
            }
        },
    };
    // An imported model's errors and warnings at the source's elements (crate::import::merge::SourceMap).
    let relocated = |d: Diagnostics| match &resolved {
        Some(r) => r.map.relocate(d, text),
        None => d,
    };
    let mut p = Parser::new(text);
    p.imported_from = resolved.as_ref().map_or(usize::MAX, |r| r.start);
    let root = p.expand(doc_root);
    let model = p.model(&root);
    match model {
        Some(mut model) if p.cx.diags.is_empty() => {
            p.collect_warnings(&model);
            let mut warnings = std::mem::take(&mut p.warnings);
            if let Some(r) = &resolved {
                warnings.extend(r.warnings.iter().cloned());
                model.import = Some(crate::model::Import {
                    source: r.source.clone(),
                    model_len: source.len(),
                    text: r.text.clone(),
                    map: r.map.clone(),
                });
            }
            (Ok(model), relocated(Diagnostics::new(path, text, warnings)))
        }
        _ => {
            let mut items = p.once_per_template();
            if items.is_empty() {
                // Cannot happen: every `None` comes with an error. Stay total anyway.
                items.push(Diagnostic::new(
                    Pos { line: 1, col: 1 },
                    1,
                    "internal error: incomplete model",
                    "",
                ));
            }
            (
                Err(relocated(Diagnostics::new(path, text, items))),
                no_warnings(),
            )
        }
    }
}

/// Reads and parses a model file. An unreadable file is reported as one error at 1:1; a file
/// that is not UTF-8 at the first invalid byte.
pub fn parse_model_file(path: &std::path::Path) -> Result<Model, Diagnostics> {
    let source = crate::source::read_source(path)?;
    parse_model(&path.display().to_string(), &source)
}

fn toml_error(cx: &Cx<'_>, e: &toml::de::Error) -> Diagnostic {
    let span = e.span().unwrap_or(0..0);
    let text = e.message().trim();
    let first = text.lines().next().unwrap_or("").trim();
    let (mut message, label) = match first.split_once(", expected ") {
        Some((m, exp)) => (m.to_string(), format!("expected {exp}")),
        None => (first.to_string(), String::new()),
    };
    if message == "duplicate key" {
        let key = cx.text(&span);
        if !key.is_empty() && !key.contains('\n') && key.chars().count() <= 60 {
            message = format!("duplicate key `{key}`");
        }
    }
    if message.is_empty() {
        message = "invalid TOML".to_string();
    }
    Diagnostic::new(
        cx.pos(span.start),
        cx.len(&span),
        format!("TOML syntax: {message}"),
        label,
    )
}
