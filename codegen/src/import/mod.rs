//! Robot descriptions in other formats (URDF, MJCF, SDF) -> rbss model text.
//!
//! Each importer reads its XML with `roxmltree` (byte positions, so every error points into the
//! source file; DTDs refused, so no entity is ever expanded) and writes a [`Imported`]: the
//! coordinates, bodies, loops and robot keys of an rbss model, each with the source element it
//! came from. [`Imported::render`] writes it as a model file (TOML, commented with the source's
//! elements and lines): what `rbss-codegen import FILE --out models/NAME.toml` writes, and what a
//! model file with `urdf = "..."` (or `mjcf`, `sdf`) is merged with ([`merge`]).
//!
//! Numbers are copied as written in the source (exact decimals, as a hand-written model has
//! them); numbers the importer computes (an inertia turned into the body's axes, a quaternion
//! from Euler angles) are written in shortest round-trip form.

use std::path::Path;

use crate::diagnostics::{Diagnostic, Diagnostics, Place};
use crate::model::Pos;
pub use crate::model::SourceFile;

pub(crate) mod geom;
pub mod merge;
mod mesh;
mod mjcf;
mod sdf;
mod urdf;
mod xml;

pub use mjcf::mesh_path;

/// The source formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    Urdf,
    Mjcf,
    Sdf,
}

impl Format {
    /// The model-file key naming a source of this format.
    pub fn key(self) -> &'static str {
        match self {
            Format::Urdf => "urdf",
            Format::Mjcf => "mjcf",
            Format::Sdf => "sdf",
        }
    }

    /// The format of a model-file key.
    pub fn from_key(key: &str) -> Option<Format> {
        match key {
            "urdf" => Some(Format::Urdf),
            "mjcf" => Some(Format::Mjcf),
            "sdf" => Some(Format::Sdf),
            _ => None,
        }
    }

    /// The format of a file, by its extension (`.urdf`, `.xml`/`.mjcf`, `.sdf`).
    pub fn from_path(path: &Path) -> Option<Format> {
        match path.extension()?.to_str()? {
            "urdf" => Some(Format::Urdf),
            "xml" | "mjcf" => Some(Format::Mjcf),
            "sdf" => Some(Format::Sdf),
            _ => None,
        }
    }
}

/// Where in the source an imported item comes from, for the comments of the written model.
#[derive(Debug, Clone, Default)]
pub struct Origin {
    /// `<joint name="q2">` (short).
    pub element: String,
    /// The file (as shown) and line.
    pub at: String,
    /// The element's tag in its file: where an error of the imported entry is reported.
    pub place: Option<Place>,
}

/// One coordinate: a joint's variable.
#[derive(Debug, Clone, Default)]
pub struct Coord {
    pub name: String,
    /// `"rad"`, `"m"` or `"1"` (a quaternion's component).
    pub unit: &'static str,
    pub home: Option<String>,
    pub stiffness: Option<String>,
    pub rest: Option<String>,
    pub damping: Option<String>,
    pub armature: Option<String>,
    /// An actuated coordinate's gear ratio (MJCF's actuator `gear`), when not 1.
    pub gear: Option<String>,
    pub origin: Origin,
}

/// One body (a link): its parent and steps, its mass properties.
#[derive(Debug, Clone, Default)]
pub struct BodyOut {
    pub name: String,
    pub parent: String,
    /// The steps, each as TOML (`"Rz(q)"` quoted, `{ pose = { ... } }`).
    pub transforms: Vec<String>,
    /// `mass`, `com`, `inertia` (numbers as TOML), when the body has mass.
    pub mass: Option<(String, [String; 3], [String; 6])>,
    pub origin: Origin,
    /// Keys whose source element is another than the origin's (`transforms` from a joint,
    /// `inertia` from an `<inertia>`).
    pub places: Vec<(&'static str, Place)>,
}

/// One loop, as its TOML keys (`name` first).
#[derive(Debug, Clone, Default)]
pub struct LoopOut {
    pub keys: Vec<(&'static str, String)>,
    pub origin: Origin,
}

/// What an importer read: an rbss model without what the source cannot say.
#[derive(Debug, Clone, Default)]
pub struct Imported {
    pub format: Option<Format>,
    /// The source as shown, and its hash (with included files').
    pub source: Option<SourceFile>,
    /// `[robot] name` (snake_case).
    pub name: String,
    pub description: String,
    /// `[robot] gravity`, as TOML numbers.
    pub gravity: [String; 3],
    /// `[robot] actuated`.
    pub actuated: Vec<String>,
    pub coordinates: Vec<Coord>,
    pub bodies: Vec<BodyOut>,
    pub loops: Vec<LoopOut>,
    /// Notes written at the top of the model (what was ignored).
    pub notes: Vec<String>,
    /// The source's root element (`<robot>`, `<mujoco>`, `<model>`): the place of `[robot]`'s
    /// imported keys.
    pub root: Option<Place>,
}

/// A text of lines, each with the place in a source it comes from.
#[derive(Default)]
struct Lines {
    text: String,
    places: Vec<Option<Place>>,
}

impl Lines {
    fn push(&mut self, line: &str, place: Option<&Place>) {
        self.text.push_str(line);
        self.text.push('\n');
        self.places.push(place.cloned());
    }
}

/// Limits on untrusted XML: the file's size, its number of nodes and its depth.
pub const MAX_BYTES: usize = 16 << 20;
pub const MAX_NODES: u32 = 1_000_000;
pub const MAX_DEPTH: usize = 256;

/// Names of the source's joints and bodies (links) the model file renames (`[rename]`), by the
/// source's name; and, filled by the import, every name the source has.
#[derive(Debug, Clone, Default)]
pub struct Renames {
    pub joints: Vec<(String, String)>,
    pub bodies: Vec<(String, String)>,
    /// The source's joint and body names (as the source writes them), in the order read.
    pub seen_joints: Vec<String>,
    pub seen_bodies: Vec<String>,
}

impl Renames {
    fn joint(&mut self, name: &str) -> String {
        if !self.seen_joints.iter().any(|s| s == name) {
            self.seen_joints.push(name.to_string());
        }
        match self.joints.iter().find(|(k, _)| k == name) {
            Some((_, to)) => to.clone(),
            None => ident(name),
        }
    }

    fn body(&mut self, name: &str) -> String {
        if !self.seen_bodies.iter().any(|s| s == name) {
            self.seen_bodies.push(name.to_string());
        }
        match self.bodies.iter().find(|(k, _)| k == name) {
            Some((_, to)) => to.clone(),
            None => ident(name),
        }
    }
}

/// Reads and imports a source file. `shown` is its path as messages show it. Errors (all of
/// them) point into the source; the warnings are rendered apart (the model still imports).
pub fn import_file(
    path: &Path,
    shown: &str,
    format: Format,
) -> Result<(Imported, Diagnostics), Diagnostics> {
    import_renamed(path, shown, format, &mut Renames::default())
}

/// [`import_file`], with the joints and bodies `renames` names renamed (a note each in the
/// written model); `renames` gets the source's names.
pub fn import_renamed(
    path: &Path,
    shown: &str,
    format: Format,
    renames: &mut Renames,
) -> Result<(Imported, Diagnostics), Diagnostics> {
    let text = read_xml(path, shown)?;
    // MJCF's `<include>`s: every file read (and checked) before the walk.
    let includes = match format {
        Format::Mjcf => mjcf::includes(path, shown, &text)?,
        Format::Sdf => sdf::includes(path, shown, &text)?,
        _ => Vec::new(),
    };
    let mut cx = xml::Cx::new(shown, &text);
    cx.renames = std::mem::take(renames);
    for (_, p, t) in &includes {
        cx.add_file(p, t);
    }
    let doc = cx.parse()?;
    let mut docs = Vec::new();
    for k in 1..=includes.len() {
        docs.push(cx.parse_file(k)?);
    }
    let imported = match format {
        Format::Urdf => urdf::import(&mut cx, &doc),
        Format::Mjcf => {
            let roots: Vec<(&str, roxmltree::Node<'_, '_>)> = includes
                .iter()
                .zip(&docs)
                .map(|((key, _, _), d)| (key.as_str(), d.root_element()))
                .collect();
            mjcf::import(
                &mut cx,
                &doc,
                &roots,
                path.parent().unwrap_or(Path::new("")),
            )
        }
        Format::Sdf => {
            let roots: Vec<(&str, roxmltree::Node<'_, '_>)> = includes
                .iter()
                .zip(&docs)
                .map(|((key, _, _), d)| (key.as_str(), d.root_element()))
                .collect();
            sdf::import(&mut cx, &doc, &roots)
        }
    };
    let extra: Vec<String> = cx.included().iter().map(|t| t.to_string()).collect();
    *renames = std::mem::take(&mut cx.renames);
    let (errors, warnings) = cx.finish();
    if let Some(errors) = errors {
        return Err(errors);
    }
    let mut imported = imported.ok_or_else(|| {
        Diagnostics::new(
            shown,
            text.clone(),
            vec![Diagnostic::new(
                Pos { line: 1, col: 1 },
                1,
                "internal error: incomplete import",
                "",
            )],
        )
    })?;
    // Included files' warnings, as notes of the written model.
    for w in warnings.iter().skip(1) {
        for d in &w.items {
            imported.notes.push(format!(
                "{}:{}:{}: warning: {}",
                w.path, d.pos.line, d.pos.col, d.message
            ));
        }
    }
    let warnings = warnings
        .into_iter()
        .next()
        .unwrap_or_else(|| Diagnostics::new(shown, text.clone(), Vec::new()));
    for (kind, list, seen) in [
        ("joint", &renames.joints, &renames.seen_joints),
        ("body", &renames.bodies, &renames.seen_bodies),
    ] {
        for (from, to) in list.iter().filter(|(f, _)| seen.contains(f)) {
            imported.notes.push(format!(
                "{kind} `{from}` of {shown} is `{to}` here (the model file's `[rename]`)"
            ));
        }
    }
    imported.format = Some(format);
    let mut hashed = text.replace("\r\n", "\n");
    for included in &extra {
        hashed.push_str(&included.replace("\r\n", "\n"));
    }
    imported.source = Some(SourceFile {
        path: shown.to_string(),
        sha256: sha256_hex(hashed.as_bytes()),
    });
    Ok((imported, warnings))
}

/// The files an SDF source's `<include>`s name (transitively, each `<uri>` resolved as the
/// importer resolves it), for the cache key of a model file that names the source: a file that
/// cannot be read is left out (the import reports it).
pub fn sdf_included_files(path: &Path, text: &str) -> Vec<std::path::PathBuf> {
    sdf::included_files(path, text)
}

/// The text of an XML file, or a located error (unreadable, too large, not UTF-8).
pub(crate) fn read_xml(path: &Path, shown: &str) -> Result<String, Diagnostics> {
    let at_start = |msg: String| {
        Diagnostics::new(
            shown,
            String::new(),
            vec![Diagnostic::new(Pos { line: 1, col: 1 }, 1, msg, "")],
        )
    };
    match std::fs::metadata(path) {
        Ok(m) if m.len() > MAX_BYTES as u64 => {
            return Err(at_start(format!(
                "`{shown}` is {} bytes, more than the {} bytes a robot description may have",
                m.len(),
                MAX_BYTES
            )));
        }
        _ => {}
    }
    crate::source::read_source(path)
}

impl Imported {
    /// The model file: `coordinates`, `[robot]`, `[[body]]`, `[[loop]]`, commented with the
    /// source's elements and lines.
    pub fn render(&self) -> String {
        self.render_with(false)
    }

    /// [`Imported::render`]; with `every_line`, every line of a body or loop names its source
    /// element (the text a model file is merged with: an error the model's checks find there,
    /// an inertia, is located in the source too).
    pub fn render_with(&self, every_line: bool) -> String {
        self.render_lines(every_line).text
    }

    /// The text a model file is merged with ([`Imported::render_with`], every line commented),
    /// and for each of its lines the place in the source it comes from.
    pub fn render_mapped(&self) -> (String, Vec<Option<Place>>) {
        let l = self.render_lines(true);
        (l.text, l.places)
    }

    fn render_lines(&self, every_line: bool) -> Lines {
        let mut s = Lines::default();
        if let Some(src) = &self.source {
            s.push(
                &format!(
                    "# Imported by rbss-codegen from {} (sha256 {}).",
                    src.path, src.sha256
                ),
                None,
            );
        }
        for n in &self.notes {
            s.push(&format!("# note: {n}"), None);
        }
        s.push("", None);
        s.push("coordinates = [", None);
        for c in &self.coordinates {
            let mut keys = format!("name = {}, unit = \"{}\"", quote(&c.name), c.unit);
            for (k, v) in [
                ("home", &c.home),
                ("stiffness", &c.stiffness),
                ("rest", &c.rest),
                ("damping", &c.damping),
                ("armature", &c.armature),
                ("gear", &c.gear),
            ] {
                if let Some(v) = v {
                    keys.push_str(&format!(", {k} = {v}"));
                }
            }
            s.push(
                &format!("  {{ {keys} }},{}", comment(&c.origin)),
                c.origin.place.as_ref(),
            );
        }
        s.push("]", None);
        s.push("", None);
        let root = self.root.as_ref();
        s.push("[robot]", root);
        s.push(&format!("name = {}", quote(&self.name)), root);
        if !self.description.is_empty() {
            s.push(&format!("description = {}", quote(&self.description)), root);
        }
        s.push(&format!("gravity = [{}]", self.gravity.join(", ")), root);
        let names: Vec<String> = self.actuated.iter().map(|a| quote(a)).collect();
        s.push(&format!("actuated = [{}]", names.join(", ")), root);
        for b in &self.bodies {
            let (head, c) = lines_comment(&b.origin, every_line);
            let at = |key: &str| {
                b.places
                    .iter()
                    .find(|(k, _)| *k == key)
                    .map(|(_, p)| p)
                    .or(b.origin.place.as_ref())
            };
            s.push("", None);
            s.push(&format!("[[body]]{head}"), b.origin.place.as_ref());
            s.push(&format!("name = {}{c}", quote(&b.name)), at("name"));
            if b.parent != "world" {
                s.push(&format!("parent = {}{c}", quote(&b.parent)), at("parent"));
            }
            s.push(
                &format!("transforms = [{}]{c}", b.transforms.join(", ")),
                at("transforms"),
            );
            if let Some((m, com, inertia)) = &b.mass {
                s.push(&format!("mass = {m}{c}"), at("mass"));
                s.push(&format!("com = [{}]{c}", com.join(", ")), at("com"));
                s.push(
                    &format!("inertia = [{}]{c}", inertia.join(", ")),
                    at("inertia"),
                );
            }
        }
        for l in &self.loops {
            let (head, c) = lines_comment(&l.origin, every_line);
            s.push("", None);
            s.push(&format!("[[loop]]{head}"), l.origin.place.as_ref());
            for (k, v) in &l.keys {
                s.push(&format!("{k} = {v}{c}"), l.origin.place.as_ref());
            }
        }
        s
    }
}

/// The comment of an entry's header line and of its other lines.
fn lines_comment(o: &Origin, every_line: bool) -> (String, String) {
    let c = comment(o);
    let rest = if every_line { c.clone() } else { String::new() };
    (c, rest)
}

fn comment(o: &Origin) -> String {
    if o.element.is_empty() {
        String::new()
    } else {
        format!("  # {} {}", o.element, o.at)
    }
}

/// A TOML basic string.
pub(crate) fn quote(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if c.is_control() => out.push_str(&format!("\\u{:04X}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// A number as TOML: as written when it is a plain decimal, else in shortest round-trip form.
pub(crate) fn number(text: &str, value: f64) -> String {
    let plain = {
        let t = text.strip_prefix('-').unwrap_or(text);
        let (mant, exp) = match t.find(['e', 'E']) {
            Some(i) => (&t[..i], Some(&t[i + 1..])),
            None => (t, None),
        };
        let (int, frac) = match mant.split_once('.') {
            Some((a, b)) => (a, Some(b)),
            None => (mant, None),
        };
        let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
        let int_ok = digits(int) && (int == "0" || !int.starts_with('0'));
        let exp_ok = exp.is_none_or(|e| digits(e.strip_prefix(['+', '-']).unwrap_or(e)));
        int_ok && frac.is_none_or(digits) && exp_ok
    };
    if plain { text.to_string() } else { fnum(value) }
}

/// An f64 in shortest round-trip form, as TOML (a float or an integer).
pub(crate) fn fnum(v: f64) -> String {
    let v = if v == 0.0 { 0.0 } else { v };
    format!("{v:?}")
}

/// A name as an rbss identifier: characters other than letters, digits and `_` become `_`; a
/// leading digit gets a `_` in front; a Rust keyword, `pi` or a function's name (`static`,
/// `sin`) gets a `_` behind (`static_`). The written model's comments keep the source's name.
pub(crate) fn ident(name: &str) -> String {
    let mut s: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if s.is_empty() || s.starts_with(|c: char| c.is_ascii_digit()) {
        s.insert(0, '_');
    }
    if crate::model::RUST_KEYWORDS.contains(&s.as_str())
        || s == "pi"
        || crate::model::Func::NAMES.contains(&s.as_str())
    {
        s.push('_');
    }
    s
}

/// sha256 of `bytes`, in hex.
pub(crate) fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// The steps of a joint of `kind` (`"revolute"` or `"prismatic"`) moving coordinate `q` along
/// the unit axis `axis` of the frame reached so far: the named joint about a coordinate axis,
/// else a turn taking z onto the axis, the joint about z, and that turn undone. `q` may also be
/// an expression of a coordinate (MJCF's `ref`: `"q - 0.5"`), written as elementary steps.
pub(crate) fn joint_steps(kind: &str, q: &str, axis: [f64; 3]) -> Vec<String> {
    let (rot, tr) = ("R", "T");
    let letter = if kind == "revolute" { rot } else { tr };
    let named = ident(q) == q;
    match geom::coordinate_axis(axis) {
        Some((k, s)) if !named => {
            let a = ["x", "y", "z"][k];
            let sign = if s > 0.0 { "" } else { "-" };
            vec![quote(&format!("{letter}{a}({sign}({q}))"))]
        }
        None if !named => {
            let t = geom::z_onto(axis);
            let aa = format!("{{ axis_angle = [{}] }}", t.map(fnum).join(", "));
            vec![
                aa.clone(),
                quote(&format!("{letter}z({q})")),
                format!("{{ inverse = [{aa}] }}"),
            ]
        }
        Some((k, s)) => {
            let a = ["x", "y", "z"][k];
            if s > 0.0 {
                if a == "z" {
                    vec![format!("{{ {kind} = {} }}", quote(q))]
                } else {
                    vec![format!("{{ {kind} = {}, axis = \"{a}\" }}", quote(q))]
                }
            } else {
                vec![quote(&format!("{letter}{a}(-{q})"))]
            }
        }
        None => {
            let t = geom::z_onto(axis);
            let aa = format!("{{ axis_angle = [{}] }}", t.map(fnum).join(", "));
            vec![
                aa.clone(),
                format!("{{ {kind} = {} }}", quote(q)),
                format!("{{ inverse = [{aa}] }}"),
            ]
        }
    }
}

/// A free joint (a floating base) named `name`: its seven coordinates `{name}_x`, `_y`, `_z`
/// (m, the position in the axes of the frame reached so far) and `{name}_qw`, `_qx`, `_qy`,
/// `_qz` (the orientation's quaternion, home `(1, 0, 0, 0)`), none actuated, and the step
/// `{ free = [...] }`.
pub(crate) fn free_joint(name: &str, origin: &Origin) -> (Vec<Coord>, String) {
    let parts = ["x", "y", "z", "qw", "qx", "qy", "qz"];
    let coords: Vec<Coord> = parts
        .iter()
        .enumerate()
        .map(|(i, p)| Coord {
            name: format!("{name}_{p}"),
            unit: if i < 3 { "m" } else { "1" },
            home: (i == 3).then(|| "1".to_string()),
            origin: origin.clone(),
            ..Coord::default()
        })
        .collect();
    let names: Vec<String> = coords.iter().map(|c| quote(&c.name)).collect();
    (coords, format!("{{ free = [{}] }}", names.join(", ")))
}

/// A `pose` step, or nothing when both parts are zero. `xyz` and `rot` (`rpy = [...]`,
/// `quat = [...]`) as TOML.
pub(crate) fn pose_step(xyz: Option<String>, rot: Option<String>) -> Option<String> {
    let mut keys = Vec::new();
    if let Some(x) = xyz {
        keys.push(format!("xyz = [{x}]"));
    }
    if let Some(r) = rot {
        keys.push(r);
    }
    (!keys.is_empty()).then(|| format!("{{ pose = {{ {} }} }}", keys.join(", ")))
}

/// Numbers as a TOML list's items (`0, 0, 0.089159`), `None` when all are zero.
pub(crate) fn nonzero_list(v: &[(String, f64)]) -> Option<String> {
    v.iter().any(|(_, x)| *x != 0.0).then(|| {
        v.iter()
            .map(|(t, x)| number(t, *x))
            .collect::<Vec<_>>()
            .join(", ")
    })
}

/// The unit vector of `v`, `None` when it is zero.
pub(crate) fn unit(v: [f64; 3]) -> Option<[f64; 3]> {
    let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    (n > 0.0 && n.is_finite()).then(|| v.map(|x| x / n))
}
