//! SDF (1.6 and later) -> [`Imported`].
//!
//! | SDF | rbss |
//! |---|---|
//! | `<link>` with `<pose relative_to>` (the model's frame by default) | a `[[body]]`: its pose relative to its parent link, `inverse(parent's pose) * its pose`, folded at generation |
//! | `<joint type="revolute\|continuous\|prismatic">` that brings a link into the tree | a coordinate: the child's steps go to the joint's frame (`<pose>`, the child's frame by default), move about `<axis><xyz>`, and back |
//! | `<joint type="ball">` in the tree | three coordinates `NAME_x`, `NAME_y`, `NAME_z` (`Rx Ry Rz` about the joint's origin) |
//! | `<joint type="universal\|revolute2">` in the tree | two coordinates `NAME_1`, `NAME_2`: the turn about `<axis>`, then about `<axis2>` as turned by the first (SDFormat: "two revolute joints connected in series", both axes in the joint's frame), i.e. `J R(axis, q1) R(axis2, q2) J⁻¹`; parallel axes refused |
//! | `<joint type="screw">` in the tree | one coordinate, the angle `q` about `<axis>`, and the translation along it: `<screw_thread_pitch>` p (m per revolution, right-handed positive) `p q / (2 pi)`, else the deprecated `<thread_pitch>` t (rad/m, left-handed positive) `-q / t` ([`screw_lead`]) |
//! | `<axis><xyz expressed_in>`, `<axis2>` | the vector turned from the named frame into the joint's (SDF 1.6's `<use_parent_model_frame>true`: the model's frame) |
//! | `<joint type="fixed">` in the tree | the child's steps only |
//! | a joint whose child is already in the tree | a loop at the joint's frame: `ball` (ball), `hinge` (revolute, about the axis), `weld` (fixed) |
//! | a `prismatic`, `universal`, `revolute2` or `screw` joint whose child is already in the tree (no loop kind is such a joint) | it brings the child in (its coordinates), and the joint that brought it in closes the loop instead (as above); refused when that joint is not revolute, ball or fixed, or when the loop hangs below the child (a note says which joint closes) |
//! | `<joint type="gearbox">` (`<gearbox_ratio>` r, `<gearbox_reference_body>` R, `<axis>`, `<axis2>`) | a `coupling` loop named after the joint: SDFormat's `theta_2 = -r theta_1`, `theta_1` the parent link's angle against R about `<axis>`, `theta_2` the child's about `<axis2>`, i.e. `q2 = -r s1 s2 q1` between the revolute joints of the tree that join parent and child to R (`s = ±1`: the joint's axis along or against the gearbox's, the joint from R to the link or back); `q2` is not actuated |
//! | `<frame>` | a frame `relative_to` may name |
//! | `<include>` (`<uri>`: a path, `file://`, `model://NAME` in [`MODEL_PATH_VARS`]' directories and the file's; `<name>`, `<pose>`) | the included file's `<model>` as a nested model in its place ([`includes`], [`register_includes`]) |
//! | a nested `<model>` (any depth) | its links, joints and frames, scoped: `inner::link` from outside, `link` inside, `__model__` its own frame ([`scope_of`], [`resolve`]); its `<pose>` relative to the model around it |
//! | `<inertial>` (`<pose>`, `<mass>`, `<inertia>`) | `mass`, `com`, `inertia` (in the link's axes) |
//! | `<axis><dynamics>` `damping`, `spring_stiffness`, `spring_reference` | `damping`, `stiffness`, `rest` (`friction` ignored, with a warning) |
//! | `<world><gravity>` | `gravity` |
//!
//! | a `<link>` that is the child of no joint (the model's root: a floating base) | a free joint `LINK_free`: 7 coordinates `LINK_free_x`, `_y`, `_z`, `LINK_free_qw`, `_qx`, `_qy`, `_qz` that move the link from its pose as written (home: zero and `(1, 0, 0, 0)`) |
//!
//! Refused: a prismatic, universal, revolute2 or screw joint closing a loop that no other joint
//! of it can close; a gearbox whose links are not turned against its reference body by revolute
//! joints of the tree about its axes; an `<include>` whose `<uri>` names no local file.

use std::cell::RefCell;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

use roxmltree::{Document, Node};

use super::geom::{self, Mat};
use super::xml::{Cx, child, element};
use super::{
    BodyOut, Coord, Imported, LoopOut, Origin, fnum, ident, joint_steps, number, quote, unit,
};
use crate::diagnostics::Place;

/// A frame in the model's frame: as steps (exact, folded at generation) and as numbers.
#[derive(Clone)]
struct Abs {
    steps: Vec<String>,
    p: [f64; 3],
    r: Mat,
}

const IDENTITY: Mat = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

fn origin_abs() -> Abs {
    Abs {
        steps: Vec::new(),
        p: [0.0; 3],
        r: IDENTITY,
    }
}

/// Joints no loop kind expresses: one that closes a loop brings its child into the tree instead,
/// and the joint that brought the child in closes the loop ([`tree`]).
const CUT_ELSEWHERE: [&str; 4] = ["prismatic", "universal", "revolute2", "screw"];

struct Frames<'a, 'i> {
    /// Scoped name (`inner::link`) -> a `<link>`, `<joint>`, `<frame>` or nested `<model>`.
    nodes: HashMap<String, Node<'a, 'i>>,
    done: HashMap<String, Option<Abs>>,
    visiting: Vec<String>,
}

/// An `<include>` and the `<model>` of the file it names.
type Included<'a, 'i> = (Node<'a, 'i>, Node<'a, 'i>);

thread_local! {
    /// The included files being imported, by their text's address: the scope the `<include>` is
    /// written in (`"arm::"`) and the included model's name there (`<include><name>`, else the
    /// model's own).
    static INCLUDED: RefCell<HashMap<usize, (String, String)>> = RefCell::new(HashMap::new());
}

/// The included file's scope and name of an element's document, if it is an included one.
fn included_as(n: Node<'_, '_>) -> Option<(String, String)> {
    let key = n.document().input_text().as_ptr() as usize;
    INCLUDED.with(|m| m.borrow().get(&key).cloned())
}

/// Whether `n` is the `<model>` of an included file.
fn is_included_root(n: Node<'_, '_>) -> bool {
    n.tag_name().name() == "model"
        && n.parent_element()
            .is_none_or(|o| o.tag_name().name() != "model")
        && included_as(n).is_some()
}

/// The environment variables whose directories `model://NAME` is searched in, in order (then the
/// including file's directory): libsdformat's `SDF_PATH`, Gazebo's `GZ_SIM_RESOURCE_PATH` (and
/// `IGN_GAZEBO_RESOURCE_PATH` before it), Gazebo classic's `GAZEBO_MODEL_PATH`.
pub(crate) const MODEL_PATH_VARS: [&str; 4] = [
    "SDF_PATH",
    "GZ_SIM_RESOURCE_PATH",
    "IGN_GAZEBO_RESOURCE_PATH",
    "GAZEBO_MODEL_PATH",
];

/// The file an `<include>`'s `<uri>` names, from a file in `dir`: a path (relative to `dir`),
/// `file://PATH`, or `model://NAME[/...]` searched in the directories of [`MODEL_PATH_VARS`]
/// and `dir`. A directory is a model's: the file its `model.config`'s `<sdf>` names, else
/// `model.sdf`. Else the places looked at (none for a URI that is no local file).
fn resolve_uri(uri: &str, dir: &Path) -> Result<PathBuf, Vec<PathBuf>> {
    let uri = uri.trim();
    let candidates: Vec<PathBuf> = if let Some(rest) = uri.strip_prefix("model://") {
        let mut dirs: Vec<PathBuf> = Vec::new();
        for var in MODEL_PATH_VARS {
            if let Some(v) = std::env::var_os(var) {
                dirs.extend(std::env::split_paths(&v).filter(|d| !d.as_os_str().is_empty()));
            }
        }
        dirs.push(dir.to_path_buf());
        dirs.iter().map(|d| d.join(rest)).collect()
    } else if let Some(rest) = uri.strip_prefix("file://") {
        vec![dir.join(rest)]
    } else if uri.contains("://") {
        return Err(Vec::new());
    } else {
        vec![dir.join(uri)]
    };
    for c in &candidates {
        if c.is_file() {
            return Ok(c.clone());
        }
        if c.is_dir() {
            let named = std::fs::read_to_string(c.join("model.config"))
                .ok()
                .and_then(|t| {
                    Document::parse(&t).ok().and_then(|d| {
                        d.descendants()
                            .find(|n| n.has_tag_name("sdf"))
                            .and_then(|n| n.text())
                            .map(|t| c.join(t.trim()))
                    })
                });
            for f in named.into_iter().chain([c.join("model.sdf")]) {
                if f.is_file() {
                    return Ok(f);
                }
            }
        }
    }
    Err(candidates)
}

/// The `<include>` elements of an SDF text and their `<uri>`s, with the element's offset.
fn include_uris(text: &str) -> Vec<(usize, String)> {
    let opts = roxmltree::ParsingOptions {
        allow_dtd: false,
        nodes_limit: super::MAX_NODES,
        ..Default::default()
    };
    let Ok(doc) = Document::parse_with_options(text, opts) else {
        return Vec::new();
    };
    doc.descendants()
        .filter(|n| n.is_element() && n.tag_name().name() == "include")
        .map(|n| {
            let uri = child(n, "uri").and_then(|u| u.text()).unwrap_or("");
            (n.range().start, uri.trim().to_string())
        })
        .collect()
}

/// Every file an SDF source includes, transitively (those that resolve and read).
pub(super) fn included_files(path: &Path, text: &str) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = Vec::new();
    let mut queue = vec![(path.to_path_buf(), text.to_string())];
    let mut i = 0;
    while i < queue.len() && out.len() < MAX_INCLUDES {
        let (from, t) = queue[i].clone();
        i += 1;
        let dir = from.parent().unwrap_or(Path::new("")).to_path_buf();
        for (_, uri) in include_uris(&t) {
            if let Ok(p) = resolve_uri(&uri, &dir)
                && out.len() < MAX_INCLUDES
                && let Ok(b) = std::fs::read_to_string(&p)
            {
                out.push(p.clone());
                queue.push((p, b));
            }
        }
    }
    out
}

/// At most this many included files (each inclusion counts: a model included twice is read
/// twice, as two models).
const MAX_INCLUDES: usize = 64;

/// The files the source's `<include>`s name, transitively, each inclusion once, in breadth-first
/// order: `(key, path as shown, text)`, the key the including file's shown path and the
/// `<include>`'s byte offset. A `<uri>` that resolves to no file is an error at it that names the
/// places looked at; a file that includes itself (through others) is refused.
pub(super) fn includes(
    path: &Path,
    shown: &str,
    text: &str,
) -> Result<Vec<(String, String, String)>, crate::diagnostics::Diagnostics> {
    let mut out: Vec<(String, String, String)> = Vec::new();
    // (path, shown, text, the files including it)
    let mut queue: Vec<(PathBuf, String, String, Vec<PathBuf>)> = vec![(
        path.to_path_buf(),
        shown.to_string(),
        text.to_string(),
        Vec::new(),
    )];
    let mut i = 0;
    while i < queue.len() {
        let (from, from_shown, from_text, chain) = queue[i].clone();
        i += 1;
        let uris = include_uris(&from_text);
        if uris.is_empty() {
            continue;
        }
        let doc = Document::parse_with_options(
            &from_text,
            roxmltree::ParsingOptions {
                allow_dtd: false,
                nodes_limit: super::MAX_NODES,
                ..Default::default()
            },
        )
        .ok();
        let Some(doc) = doc else { continue };
        let mut cx = Cx::new(&from_shown, &from_text);
        let dir = from.parent().unwrap_or(Path::new("")).to_path_buf();
        for inc in doc
            .descendants()
            .filter(|n| n.is_element() && n.tag_name().name() == "include")
        {
            let Some(u) = child(inc, "uri") else {
                cx.error(&cx.tag(inc), "the `<include>` has no `<uri>`", "", "");
                continue;
            };
            let uri = u.text().unwrap_or("").trim();
            let at = u.first_child().map_or_else(|| cx.tag(u), |c| c.range());
            let p = match resolve_uri(uri, &dir) {
                Ok(p) => p,
                Err(looked) => {
                    let places: Vec<String> =
                        looked.iter().map(|p| p.display().to_string()).collect();
                    cx.error(
                        &at,
                        format!("cannot resolve `{uri}`"),
                        if places.is_empty() {
                            "not a local file"
                        } else {
                            "no such file or model directory"
                        },
                        &if places.is_empty() {
                            "only local files are read: a path (relative to this file), \
                             `file://PATH` or `model://NAME`"
                                .to_string()
                        } else {
                            format!(
                                "looked at {}{}",
                                places.join(", "),
                                if uri.starts_with("model://") {
                                    " (`model://` is searched in the directories of SDF_PATH, \
                                     GZ_SIM_RESOURCE_PATH, IGN_GAZEBO_RESOURCE_PATH, \
                                     GAZEBO_MODEL_PATH, then this file's)"
                                } else {
                                    ""
                                }
                            )
                        },
                    );
                    continue;
                }
            };
            let same = |a: &Path, b: &Path| {
                a == b
                    || a.canonicalize()
                        .is_ok_and(|x| b.canonicalize().is_ok_and(|y| x == y))
            };
            if same(&p, &from) || chain.iter().any(|c| same(&p, c.as_path())) {
                cx.error(
                    &at,
                    format!("`{uri}` includes the file that includes it"),
                    "an endless inclusion",
                    "",
                );
                continue;
            }
            if out.len() >= MAX_INCLUDES {
                cx.error(&at, "more than 64 included models", "", "");
                break;
            }
            let p_shown = p.display().to_string().replace('\\', "/");
            match super::read_xml(&p, &p_shown) {
                Ok(t) => {
                    let mut up = chain.clone();
                    up.push(from.clone());
                    queue.push((p.clone(), p_shown.clone(), t.clone(), up));
                    out.push((format!("{from_shown}@{}", inc.range().start), p_shown, t));
                }
                Err(e) => {
                    let why = e.items.first().map_or(String::new(), |d| d.message.clone());
                    cx.error(&at, format!("cannot include `{p_shown}`: {why}"), "", "");
                }
            }
        }
        if let (Some(errors), _) = cx.finish() {
            return Err(errors);
        }
    }
    Ok(out)
}

/// The `<include>`s of `model` and of the models in it, each with the `<model>` of its file
/// (registered in [`INCLUDED`] with its scope and name, outer ones first).
fn register_includes<'a, 'i>(
    cx: &mut Cx<'_>,
    model: Node<'a, 'i>,
    roots: &[(&str, Node<'a, 'i>)],
    out: &mut Vec<Included<'a, 'i>>,
) {
    for n in model.children().filter(|n| n.is_element()) {
        match n.tag_name().name() {
            "model" => register_includes(cx, n, roots, out),
            "include" => {
                let key = format!("{}@{}", cx.path_of(n), n.range().start);
                let Some(&(_, root)) = roots.iter().find(|(k, _)| *k == key) else {
                    continue;
                };
                let m = child(root, "model")
                    .or_else(|| child(root, "world").and_then(|w| child(w, "model")));
                let Some(m) = m else {
                    cx.error(&cx.tag(n), "the included file has no `<model>`", "", "");
                    continue;
                };
                if let Some(pf) = child(n, "placement_frame") {
                    cx.error(
                        &cx.tag(pf),
                        "`<placement_frame>` is not supported",
                        "not read",
                        "give the `<include>`'s `<pose>` of the model's frame",
                    );
                }
                let name = child(n, "name")
                    .and_then(|e| e.text())
                    .map(str::trim)
                    .or(m.attribute("name"))
                    .unwrap_or("")
                    .to_string();
                let key = m.document().input_text().as_ptr() as usize;
                let scope = scope_of(n);
                INCLUDED.with(|r| r.borrow_mut().insert(key, (scope, name)));
                out.push((n, m));
                register_includes(cx, m, roots, out);
            }
            _ => {}
        }
    }
}

pub(super) fn import<'a, 'i>(
    cx: &mut Cx<'_>,
    doc: &'a Document<'i>,
    roots: &[(&str, Node<'a, 'i>)],
) -> Option<Imported> {
    INCLUDED.with(|r| r.borrow_mut().clear());
    let out = import_model(cx, doc, roots);
    INCLUDED.with(|r| r.borrow_mut().clear());
    out
}

fn import_model<'a, 'i>(
    cx: &mut Cx<'_>,
    doc: &'a Document<'i>,
    roots: &[(&str, Node<'a, 'i>)],
) -> Option<Imported> {
    let root = doc.root_element();
    if root.tag_name().name() != "sdf" {
        cx.error(
            &cx.tag(root),
            format!(
                "an SDF file's root element is `<sdf>`, not `<{}>`",
                root.tag_name().name()
            ),
            "expected `<sdf>`",
            "",
        );
        return None;
    }
    if let Some(v) = root.attribute("version") {
        let old = v
            .split('.')
            .next()
            .and_then(|m| m.parse::<u32>().ok())
            .zip(v.split('.').nth(1).and_then(|m| m.parse::<u32>().ok()));
        if old.is_some_and(|(a, b)| (a, b) < (1, 6)) {
            cx.error(
                &cx.attr_range(root, "version"),
                format!("SDF {v} is older than 1.6"),
                "1.6 or later",
                "convert it with `gz sdf -p`",
            );
        }
    }
    let world = child(root, "world");
    let model = child(root, "model").or_else(|| world.and_then(|w| child(w, "model")));
    let Some(model) = model else {
        cx.error(&cx.tag(root), "the SDF file has no `<model>`", "", "");
        return None;
    };
    let mut out = Imported {
        name: ident(&model.attribute("name").unwrap_or("robot").to_lowercase()),
        description: format!("imported from {}", cx.path),
        gravity: ["0".into(), "0".into(), "-9.81".into()],
        root: Some(cx.place(model)),
        ..Imported::default()
    };
    if let Some(g) = world
        .and_then(|w| child(w, "gravity"))
        .and_then(|g| cx.text_numbers(g, 3))
    {
        out.gravity = [0, 1, 2].map(|k| number(&g[k].0, g[k].1));
    }
    let mut inc = Vec::new();
    register_includes(cx, model, roots, &mut inc);
    let links = nested(model, "link", &inc);
    let joints = nested(model, "joint", &inc);
    let mut frames = frames(cx, model, &links, &joints, &inc);
    let (tree, closing, floating) = tree(cx, &links, &joints, &mut out);
    for &l in &floating {
        free_root(cx, &mut frames, l, &mut out);
    }
    bodies(cx, &mut frames, &links, &tree, &mut out);
    loops(cx, &mut frames, &closing, &mut out);
    gearboxes(cx, &mut frames, &links, &joints, &tree, &mut out);
    Some(out)
}

/// The links, joints and frames by name (one namespace).
fn frames<'a, 'i>(
    cx: &mut Cx<'_>,
    model: Node<'a, 'i>,
    links: &[Node<'a, 'i>],
    joints: &[Node<'a, 'i>],
    inc: &[Included<'a, 'i>],
) -> Frames<'a, 'i> {
    let mut frames = Frames {
        nodes: HashMap::new(),
        done: HashMap::new(),
        visiting: Vec::new(),
    };
    for n in links
        .iter()
        .chain(joints)
        .chain(nested(model, "frame", inc).iter())
        .chain(nested(model, "model", inc).iter())
    {
        let Some(local) = cx.required(*n, "name") else {
            continue;
        };
        let name = qname(*n);
        // An included model is placed by the `<include>`'s `<pose>` when it has one.
        let placed = match inc.iter().find(|(_, m)| m == n) {
            Some((i, _)) if child(*i, "pose").is_some() => *i,
            _ => *n,
        };
        if frames.nodes.insert(name.clone(), placed).is_some()
            || local == "world"
            || local == "__model__"
        {
            cx.error(
                &cx.attr_range(*n, "name"),
                format!("frame name `{name}` is taken"),
                "",
                "links, joints and frames share one namespace",
            );
        }
    }

    frames
}

/// The elements `tag` of `model` and of the models nested in it (SDFormat 1.8: `<model>` in a
/// `<model>`) or included (`<include>`: the included file's `<model>` in its place), in the
/// file's order.
fn nested<'a, 'i>(model: Node<'a, 'i>, tag: &str, inc: &[Included<'a, 'i>]) -> Vec<Node<'a, 'i>> {
    let mut out = Vec::new();
    for n in model.children().filter(|n| n.is_element()) {
        let inner = match n.tag_name().name() {
            "model" => Some(n),
            "include" => inc.iter().find(|(i, _)| *i == n).map(|(_, m)| *m),
            _ => None,
        };
        if n.tag_name().name() == tag {
            out.push(n);
        }
        if let Some(m) = inner {
            if tag == "model" && m != n {
                out.push(m);
            }
            out.extend(nested(m, tag, inc));
        }
    }
    out
}

/// The scope an element is written in: the names of the models nested in the imported one
/// around it, each followed by `::` (`""` in the imported model itself).
fn scope_of(n: Node<'_, '_>) -> String {
    if is_included_root(n) {
        return included_as(n).map(|(scope, _)| scope).unwrap_or_default();
    }
    let mut names = Vec::new();
    let mut base = String::new();
    let mut up = n.parent_element();
    while let Some(m) = up {
        let outer = m.parent_element();
        if m.tag_name().name() == "model" {
            if outer.is_none_or(|o| o.tag_name().name() != "model") {
                // The file's model: the imported one, or an included one (named by its include).
                if let Some((scope, name)) = included_as(m) {
                    names.push(name);
                    base = scope;
                }
                break;
            }
            names.push(m.attribute("name").unwrap_or("").to_string());
        }
        up = outer;
    }
    let inner: String = names.iter().rev().map(|s| format!("{s}::")).collect();
    format!("{base}{inner}")
}

/// An element's scoped name: `inner::link` for a link of the nested model `inner`.
fn qname(n: Node<'_, '_>) -> String {
    if is_included_root(n) {
        let (scope, name) = included_as(n).unwrap_or_default();
        return format!("{scope}{name}");
    }
    format!("{}{}", scope_of(n), n.attribute("name").unwrap_or(""))
}

/// A frame name written in element `n`'s scope, scoped: SDFormat's names are relative to the
/// model they are written in (`inner::link` from outside `inner`, `link` inside it); `world` is
/// the world, `__model__` the model the element is written in.
fn resolve(n: Node<'_, '_>, name: &str) -> String {
    let scope = scope_of(n);
    match name {
        "world" => "world".into(),
        "__model__" if scope.is_empty() => "__model__".into(),
        "__model__" => scope.trim_end_matches("::").to_string(),
        _ => format!("{scope}{name}"),
    }
}

/// The help of an unknown name written in a nested model: names there are its own.
fn scope_help(n: Node<'_, '_>, scoped: &str) -> String {
    let scope = scope_of(n);
    if scope.is_empty() {
        String::new()
    } else {
        format!(
            "written in model `{}`, this names `{scoped}`: a nested model's names are its own \
             (SDFormat's scopes; a model reaches into a nested one with `model::name`, not out)",
            scope.trim_end_matches("::")
        )
    }
}

/// A joint's parent and child link, scoped.
fn ends(j: Node<'_, '_>) -> (String, String) {
    let get = |t: &str| {
        resolve(
            j,
            child(j, t)
                .and_then(|e| e.text())
                .map(str::trim)
                .unwrap_or(""),
        )
    };
    (get("parent"), get("child"))
}

/// A link no joint has as its child: a floating base, moved by a free joint from its pose as
/// written.
fn free_root<'a, 'i>(
    cx: &mut Cx<'_>,
    frames: &mut Frames<'a, 'i>,
    l: Node<'a, 'i>,
    out: &mut Imported,
) {
    let name = qname(l);
    let Some(abs) = abs_of(cx, frames, &name) else {
        return;
    };
    let origin = cx.origin(l);
    let body = cx.body_name(&name);
    let (coords, step) = super::free_joint(&format!("{body}_free"), &origin);
    out.coordinates.extend(coords);
    let mut transforms = abs.steps.clone();
    transforms.push(step);
    out.bodies.push(BodyOut {
        name: body,
        parent: "world".into(),
        transforms,
        mass: child(l, "inertial").and_then(|i| inertial(cx, i)),
        origin,
        places: inertial_places(cx, l),
    });
}

/// The tree: from the world and from the links no joint has as its child (floating bases),
/// each joint whose parent is in it brings its child in; a joint whose child is already in
/// closes a loop. A prismatic joint that would close a loop brings its child in instead, and the
/// joint that brought the child in closes the loop (the model language has no prismatic loop;
/// where the loop is cut does not change the mechanism). `gearbox` joints are constraints
/// between two joints' angles, not joints of the tree ([`gearboxes`]). The tree's joints with
/// every parent before its children, the closing joints and the floating links; a link or
/// joint not tied to the world is reported.
#[allow(clippy::type_complexity)]
fn tree<'a, 'i>(
    cx: &mut Cx<'_>,
    links: &[Node<'a, 'i>],
    all_joints: &[Node<'a, 'i>],
    out: &mut Imported,
) -> (Vec<Node<'a, 'i>>, Vec<Node<'a, 'i>>, Vec<Node<'a, 'i>>) {
    for &j in all_joints {
        for t in ["parent", "child"] {
            match child(j, t) {
                None => cx.error(
                    &cx.tag(j),
                    format!("joint has no `<{t}>`"),
                    &format!("`<{t}>LINK</{t}>` missing"),
                    "",
                ),
                Some(e) => {
                    let l = e.text().unwrap_or("").trim();
                    let scoped = resolve(j, l);
                    if scoped != "world" && !links.iter().any(|k| qname(*k) == scoped) {
                        cx.error(
                            &e.first_child().map_or_else(|| cx.tag(e), |c| c.range()),
                            format!("unknown link `{l}`"),
                            "no `<link>` of this name",
                            &scope_help(j, &scoped),
                        );
                    }
                }
            }
        }
    }
    let joints: Vec<Node<'a, 'i>> = all_joints
        .iter()
        .copied()
        .filter(|j| j.attribute("type") != Some("gearbox"))
        .collect();
    // Link -> the joint that brought it into the tree (`None`: the world, a floating base).
    let mut in_tree: HashMap<String, Option<Node<'_, '_>>> = HashMap::new();
    in_tree.insert("world".into(), None);
    let floating: Vec<Node<'_, '_>> = links
        .iter()
        .copied()
        .filter(|l| {
            let name = qname(*l);
            !joints.iter().any(|&j| ends(j).1 == name)
        })
        .collect();
    for l in &floating {
        in_tree.insert(qname(*l), None);
    }
    let mut tree = Vec::new();
    let mut closing = Vec::new();
    let mut left: Vec<Node<'_, '_>> = joints.clone();
    loop {
        let before = left.len();
        left.retain(|&j| {
            let (p, c) = ends(j);
            if !in_tree.contains_key(&p) {
                return true;
            }
            match in_tree.entry(c) {
                std::collections::hash_map::Entry::Occupied(_) => closing.push(j),
                std::collections::hash_map::Entry::Vacant(e) => {
                    e.insert(Some(j));
                    tree.push(j);
                }
            }
            false
        });
        if left.len() == before {
            break;
        }
    }
    for &j in &left {
        cx.error(
            &cx.tag(j),
            "the joint's parent is not tied to the world",
            "",
            "every link is reached from the world through parent -> child joints",
        );
    }
    for &l in links {
        let name = qname(l);
        if !in_tree.contains_key(&name) {
            cx.error(
                &cx.attr_range(l, "name"),
                format!("link `{name}` is not tied to the world by a joint: it would float"),
                "",
                "add a joint (fixed, to fix it) from `world` or another link",
            );
        }
    }

    // A joint no loop kind expresses (prismatic, universal, revolute2, screw) closing a loop
    // takes the place of the joint that brought its child in, which closes the loop instead (a
    // hinge, ball or weld loop).
    let mut swapped = false;
    let mut refused = Vec::new();
    for slot in closing.iter_mut() {
        let j = *slot;
        let kind = j.attribute("type").unwrap_or("");
        if !CUT_ELSEWHERE.contains(&kind) {
            continue;
        }
        let (p, c) = ends(j);
        let jname = &qname(j);
        let Some(&Some(t)) = in_tree.get(&c) else {
            continue;
        };
        let tname = &qname(t);
        // Whether the prismatic joint's parent hangs below its child: then the whole loop does,
        // and no other joint of it can bring the child in.
        let mut up = p.clone();
        let mut below = false;
        while let Some(Some(k)) = in_tree.get(&up) {
            if up == c {
                below = true;
                break;
            }
            up = ends(*k).0;
        }
        let t_kind = t.attribute("type").unwrap_or("");
        if below {
            cx.error(
                &cx.attr_range(j, "type"),
                format!(
                    "{kind} joint `{jname}` closes a loop that hangs below its own child `{c}`"
                ),
                "only this joint can close the loop",
                &format!(
                    "the model language has no {kind} loop: a loop through a {kind} joint is \
                     imported with the {kind} joint in the tree and the loop closed at the \
                     joint that brings the same link in; here `{p}` is reached through `{c}`, so \
                     `{c}` cannot be brought in by `{jname}`"
                ),
            );
            refused.push(j);
            continue;
        }
        if !matches!(t_kind, "revolute" | "continuous" | "ball" | "fixed") {
            cx.error(
                &cx.attr_range(j, "type"),
                format!(
                    "{kind} joint `{jname}` closes a loop whose other joint at `{c}`, \
                     `{tname}`, is a `{t_kind}` joint"
                ),
                "cannot close the loop",
                &format!(
                    "the model language has no {kind} loop: the loop is closed at the joint \
                     that brings `{c}` into the tree, which must be a revolute, ball or fixed \
                     joint (a hinge, ball or weld loop)"
                ),
            );
            refused.push(j);
            continue;
        }
        in_tree.insert(c.clone(), Some(j));
        *slot = t;
        swapped = true;
        let (jn, tn) = (cx.joint_name(jname), cx.joint_name(tname));
        out.notes.push(format!(
            "{kind} joint `{jn}` closes a loop: it brings `{c}` into the tree, and the loop \
             closes at joint `{tn}` instead"
        ));
    }
    // Reported once, here: not again as a joint that cannot close a loop.
    closing.retain(|j| !refused.contains(j));
    if swapped {
        // Every parent before its children again, in the order of the file's joints.
        let chosen: Vec<Node<'_, '_>> = joints
            .iter()
            .copied()
            .filter(|&j| in_tree.get(&ends(j).1) == Some(&Some(j)))
            .collect();
        let mut placed: Vec<String> = in_tree
            .iter()
            .filter(|(_, v)| v.is_none())
            .map(|(k, _)| k.clone())
            .collect();
        tree.clear();
        loop {
            let before = tree.len();
            for &j in &chosen {
                let (p, c) = ends(j);
                if !tree.contains(&j) && placed.contains(&p) {
                    tree.push(j);
                    placed.push(c);
                }
            }
            if tree.len() == before {
                break;
            }
        }
    }

    (tree, closing, floating)
}

/// Coordinates and bodies, in the order the tree reached them.
fn bodies<'a, 'i>(
    cx: &mut Cx<'_>,
    frames: &mut Frames<'a, 'i>,
    links: &[Node<'a, 'i>],
    tree: &[Node<'a, 'i>],
    out: &mut Imported,
) {
    for &j in tree {
        let (p, c) = ends(j);
        let Some(&l) = links.iter().find(|k| qname(**k) == c) else {
            continue;
        };
        let jname = cx.joint_name(&qname(j));
        let kind = j.attribute("type").unwrap_or("");
        let mut transforms = Vec::new();
        // A pose that failed is reported; the joint and the link are still checked.
        let (pa, ca) = (abs_of(cx, frames, &p), abs_of(cx, frames, &c));
        let placed = pa.is_some() && ca.is_some();
        let (pa, ca) = (pa.unwrap_or_else(origin_abs), ca.unwrap_or_else(origin_abs));
        if !pa.steps.is_empty() {
            transforms.push(format!("{{ inverse = [{}] }}", pa.steps.join(", ")));
        }
        transforms.extend(ca.steps.iter().cloned());
        let jpose = joint_pose(cx, frames, j, &c, &ca);
        let origin = Origin {
            element: format!("{} {}", element(l), element(j)),
            at: cx.at(j),
            place: Some(cx.place(l)),
        };
        match kind {
            "fixed" => {}
            "revolute" | "continuous" | "prismatic" | "ball" | "universal" | "revolute2"
            | "screw" => {
                transforms.extend(jpose.clone());
                let mut coord = Coord {
                    name: jname.clone(),
                    unit: if kind == "prismatic" { "m" } else { "rad" },
                    origin: cx.origin(j),
                    ..Coord::default()
                };
                dynamics(cx, j, "axis", &mut coord);
                match kind {
                    "ball" => {
                        let names: Vec<String> = ["x", "y", "z"]
                            .iter()
                            .map(|a| format!("{jname}_{a}"))
                            .collect();
                        transforms.push(format!(
                            "{{ spherical = [{}] }}",
                            names
                                .iter()
                                .map(|n| quote(n))
                                .collect::<Vec<_>>()
                                .join(", ")
                        ));
                        for n in &names {
                            let mut cc = coord.clone();
                            cc.name = n.clone();
                            out.coordinates.push(cc);
                        }
                        out.notes.push(format!(
                            "ball joint `{jname}` is three coordinates {}: angles Rx Ry Rz",
                            names.join(", ")
                        ));
                    }
                    "universal" | "revolute2" => {
                        let (a1, a2) = (
                            axis_in(cx, frames, j, "axis"),
                            axis_in(cx, frames, j, "axis2"),
                        );
                        let (Some(a1), Some(a2)) = (a1, a2) else {
                            continue;
                        };
                        if (geom::dot(a1, a2).abs() - 1.0).abs() < 1e-9 {
                            let x = child(j, "axis2").and_then(|a| child(a, "xyz")).unwrap_or(j);
                            cx.error(
                                &x.first_child().map_or_else(|| cx.tag(x), |c| c.range()),
                                format!(
                                    "the two axes of {kind} joint `{}` are parallel",
                                    j.attribute("name").unwrap_or("")
                                ),
                                "along `<axis>` (either sign)",
                                "the joint would turn twice about one line, one coordinate \
                                 too many: a revolute joint turns about one axis",
                            );
                            continue;
                        }
                        let names = [format!("{jname}_1"), format!("{jname}_2")];
                        transforms.extend(joint_steps("revolute", &names[0], a1));
                        transforms.extend(joint_steps("revolute", &names[1], a2));
                        let mut second = coord.clone();
                        dynamics(cx, j, "axis2", &mut second);
                        coord.name = names[0].clone();
                        second.name = names[1].clone();
                        out.notes.push(format!(
                            "{kind} joint `{jname}` is two coordinates {}, {}: the angle about \
                             `<axis>`, then about `<axis2>` (which turns with the first)",
                            names[0], names[1]
                        ));
                        out.actuated.extend(names.iter().cloned());
                        out.coordinates.push(coord);
                        out.coordinates.push(second);
                    }
                    "screw" => {
                        let Some(axis) = axis_of(cx, frames, j) else {
                            continue;
                        };
                        let Some(lead) = screw_lead(cx, j, &jname) else {
                            continue;
                        };
                        transforms.extend(screw_steps(&jname, &lead, axis));
                        out.notes.push(format!(
                            "screw joint `{jname}` is one coordinate: the angle about `<axis>`, \
                             with the translation {lead} along it"
                        ));
                        out.actuated.push(jname.clone());
                        out.coordinates.push(coord);
                    }
                    _ => {
                        let Some(axis) = axis_of(cx, frames, j) else {
                            continue;
                        };
                        let k = if kind == "prismatic" {
                            "prismatic"
                        } else {
                            "revolute"
                        };
                        transforms.extend(joint_steps(k, &jname, axis));
                        out.actuated.push(jname.clone());
                        out.coordinates.push(coord);
                    }
                }
                if !jpose.is_empty() {
                    transforms.push(format!("{{ inverse = [{}] }}", jpose.join(", ")));
                }
            }
            other => {
                cx.error(
                    &cx.attr_range(j, "type"),
                    format!("a `{other}` joint cannot be imported"),
                    "not supported",
                    "revolute, continuous, prismatic, ball, universal, revolute2, screw and \
                     fixed joints are",
                );
                continue;
            }
        }
        if transforms.is_empty() {
            transforms.push(quote("Tz(0)"));
        }
        let mass = child(l, "inertial").and_then(|i| inertial(cx, i));
        if !placed {
            continue;
        }
        out.bodies.push(BodyOut {
            name: cx.body_name(&c),
            parent: if p == "world" {
                "world".into()
            } else {
                cx.body_name(&p)
            },
            transforms,
            mass,
            origin,
            places: [("transforms", cx.place(j)), ("parent", cx.place(j))]
                .into_iter()
                .chain(inertial_places(cx, l))
                .collect(),
        });
    }
}

/// Loops: at the closing joint's frame, seen from its parent link and from its child.
fn loops<'a, 'i>(
    cx: &mut Cx<'_>,
    frames: &mut Frames<'a, 'i>,
    closing: &[Node<'a, 'i>],
    out: &mut Imported,
) {
    for &j in closing {
        let (p, c) = ends(j);
        let name = cx.joint_name(&qname(j));
        let kind = match j.attribute("type").unwrap_or("") {
            "ball" => "ball",
            "revolute" | "continuous" => "hinge",
            "fixed" => "weld",
            other => {
                cx.error(
                    &cx.attr_range(j, "type"),
                    format!("a `{other}` joint cannot close a loop"),
                    "not supported",
                    "ball, revolute and fixed joints can: they become ball, hinge and weld loops",
                );
                continue;
            }
        };
        // The axis is checked even where a pose failed (reported already).
        let axis = match kind {
            "hinge" => match axis_of(cx, frames, j) {
                Some(a) => Some(a),
                None => continue,
            },
            _ => None,
        };
        let (Some(pa), Some(ca)) = (abs_of(cx, frames, &p), abs_of(cx, frames, &c)) else {
            continue;
        };
        let mut at_child = joint_pose(cx, frames, j, &c, &ca);
        let mut axis_key = None;
        if let Some(axis) = axis {
            match geom::coordinate_axis(axis) {
                Some((k, _)) => axis_key = Some(["x", "y", "z"][k]),
                None => {
                    at_child.push(format!(
                        "{{ axis_angle = [{}] }}",
                        geom::z_onto(axis).map(fnum).join(", ")
                    ));
                    axis_key = Some("z");
                }
            }
        }
        let mut at_parent = Vec::new();
        if !pa.steps.is_empty() {
            at_parent.push(format!("{{ inverse = [{}] }}", pa.steps.join(", ")));
        }
        at_parent.extend(ca.steps.iter().cloned());
        at_parent.extend(at_child.iter().cloned());
        let side = |cx: &mut Cx<'_>, body: &str, steps: &[String]| {
            let b = if body == "world" {
                "world".to_string()
            } else {
                cx.body_name(body)
            };
            if steps.is_empty() {
                format!("{{ body = {} }}", quote(&b))
            } else {
                format!(
                    "{{ body = {}, transforms = [{}] }}",
                    quote(&b),
                    steps.join(", ")
                )
            }
        };
        let mut keys = vec![
            ("name", quote(&name)),
            ("kind", quote(kind)),
            ("a", side(cx, &p, &at_parent)),
            ("b", side(cx, &c, &at_child)),
        ];
        // `z` is the default: left out, so a model file can make the loop another kind.
        if let Some(a) = axis_key.filter(|a| *a != "z") {
            keys.push(("axis", quote(a)));
        }
        out.loops.push(LoopOut {
            keys,
            origin: cx.origin(j),
        });
    }
}

/// `gearbox` joints: a `coupling` between the angles of the two revolute joints that turn the
/// gearbox's parent and child links against its `<gearbox_reference_body>`. SDFormat's
/// `joint.sdf`: `theta_2 = -gearbox_ratio * theta_1`, `theta_1` the angle of the parent link
/// against the reference body about `<axis>`, `theta_2` the child's about `<axis2>` (ratio 1 by
/// default). With `q1`, `q2` those joints' coordinates, `theta = s q`, `s = ±1` as the joint's
/// axis agrees with the gearbox's (compared in the model's frame with every joint at 0) and as
/// the joint turns the link against the reference body (parent -> child) or the reference body
/// against the link; the loop is `q2 = -gearbox_ratio s1 s2 q1` (offset 0: the angles count
/// from the joints' zeros). The child's joint is not actuated (it follows the parent's).
fn gearboxes<'a, 'i>(
    cx: &mut Cx<'_>,
    frames: &mut Frames<'a, 'i>,
    links: &[Node<'a, 'i>],
    joints: &[Node<'a, 'i>],
    tree: &[Node<'a, 'i>],
    out: &mut Imported,
) {
    for &g in joints {
        if g.attribute("type") != Some("gearbox") {
            continue;
        }
        let gname = &qname(g);
        let name = cx.joint_name(gname);
        let Some(rn) = child(g, "gearbox_reference_body") else {
            cx.error(
                &cx.attr_range(g, "type"),
                format!("gearbox joint `{gname}` has no `<gearbox_reference_body>`"),
                "`<gearbox_reference_body>LINK</gearbox_reference_body>` missing",
                "the gearbox holds between the angles of its parent and child links, each \
                 measured against this link",
            );
            continue;
        };
        let reference = resolve(g, rn.text().unwrap_or("").trim());
        if reference != "world" && !links.iter().any(|k| qname(*k) == reference) {
            cx.error(
                &rn.first_child().map_or_else(|| cx.tag(rn), |c| c.range()),
                format!("unknown link `{reference}`"),
                "no `<link>` of this name",
                "",
            );
            continue;
        }
        let ratio_text = match child(g, "gearbox_ratio") {
            None => "1".to_string(),
            Some(n) => {
                let Some(v) = cx.text_numbers(n, 1) else {
                    continue;
                };
                if v[0].1 == 0.0 {
                    cx.error(
                        &n.first_child().map_or_else(|| cx.tag(n), |c| c.range()),
                        format!("gearbox joint `{gname}` has ratio 0"),
                        "holds the child's angle at 0",
                        "the child's angle is -gearbox_ratio times the parent's; a fixed joint \
                         holds a link",
                    );
                    continue;
                }
                number(&v[0].0, v[0].1)
            }
        };
        let gabs = abs_of(cx, frames, gname);
        let (p, c) = ends(g);
        // Per side: the coordinate of the joint that turns the link against the reference
        // body, and the sign of the gearbox's angle in it.
        let mut sides = Vec::new();
        for (link, tag, role) in [(&p, "axis", "parent"), (&c, "axis2", "child")] {
            let t = tree.iter().copied().find(|&t| {
                let (tp, tc) = ends(t);
                (tp == reference && tc == *link) || (tp == *link && tc == reference)
            });
            let Some(t) =
                t.filter(|t| matches!(t.attribute("type"), Some("revolute" | "continuous")))
            else {
                let e = child(g, role).unwrap_or(g);
                cx.error(
                    &e.first_child().map_or_else(|| cx.tag(e), |c| c.range()),
                    format!(
                        "gearbox joint `{gname}`: no revolute joint turns its {role} `{link}` \
                         against the reference body `{reference}`"
                    ),
                    "no angle to couple",
                    "a gearbox couples the angles of two revolute joints that join its parent \
                     and its child to `<gearbox_reference_body>` (a joint that closes a loop \
                     has no angle coordinate)",
                );
                continue;
            };
            let Some(u) = axis_in(cx, frames, g, tag) else {
                continue;
            };
            let Some(w) = axis_of(cx, frames, t) else {
                continue;
            };
            let tname = &qname(t);
            let (Some(ga), Some(ta)) = (gabs.clone(), abs_of(cx, frames, tname)) else {
                continue;
            };
            let (u, w) = (geom::apply(&ga.r, u), geom::apply(&ta.r, w));
            let dot = u[0] * w[0] + u[1] * w[1] + u[2] * w[2];
            if (dot.abs() - 1.0).abs() > 1e-9 {
                let x = child(g, tag).and_then(|a| child(a, "xyz")).unwrap_or(g);
                cx.error(
                    &x.first_child().map_or_else(|| cx.tag(x), |c| c.range()),
                    format!(
                        "the `<{tag}>` of gearbox joint `{gname}` is not the axis of joint \
                         `{tname}`"
                    ),
                    &format!(
                        "at {:.3} rad to `{tname}`'s axis",
                        dot.clamp(-1.0, 1.0).acos()
                    ),
                    &format!(
                        "the {role}'s angle is measured about `<{tag}>`: the axis of `{tname}`, \
                         which turns `{link}` against `{reference}` (either sign)"
                    ),
                );
                continue;
            }
            let turns_link = ends(t).0 == reference;
            let s = dot.signum() * if turns_link { 1.0 } else { -1.0 };
            sides.push((cx.joint_name(tname), s));
        }
        let [(q1, s1), (q2, s2)] = &sides[..] else {
            continue;
        };
        // q2 = -ratio s1 s2 q1.
        let ratio_out = if s1 * s2 > 0.0 {
            match ratio_text.strip_prefix('-') {
                Some(t) => t.to_string(),
                None => format!("-{ratio_text}"),
            }
        } else {
            ratio_text.clone()
        };
        out.notes.push(format!(
            "gearbox joint `{name}` is a coupling {q2} = {ratio_out} * {q1} (SDF: the child's \
             angle is -gearbox_ratio times the parent's, both against `{reference}`)"
        ));
        out.actuated.retain(|a| a != q2);
        out.loops.push(LoopOut {
            keys: vec![
                ("name", quote(&name)),
                ("kind", quote("coupling")),
                ("a", quote(q2)),
                ("b", quote(q1)),
                ("ratio", ratio_out),
            ],
            origin: cx.origin(g),
        });
    }
}

/// A screw joint's translation along its axis as an expression of its angle `q` (rad), from
/// SDFormat's `joint.sdf` (1.10 and later): `<screw_thread_pitch>` p is "the axial distance
/// traveled for each revolution of the joint, with units of meters / revolution with a positive
/// value corresponding to a right-handed thread", so the translation is `p q / (2 pi)`; the
/// deprecated `<thread_pitch>` t, "interpreted by gazebo-classic as having units of radians /
/// meter with a positive value corresponding to a left-handed thread", gives `-q / t`.
/// `<screw_thread_pitch>` "supersedes" `<thread_pitch>` when both are given; with neither, the
/// spec's default `<screw_thread_pitch>` 1 applies, with a warning.
fn screw_lead(cx: &mut Cx<'_>, j: Node<'_, '_>, q: &str) -> Option<String> {
    if let Some(n) = child(j, "screw_thread_pitch") {
        let v = cx.text_numbers(n, 1)?;
        return Some(format!("{} / (2 * pi) * {q}", number(&v[0].0, v[0].1)));
    }
    if let Some(n) = child(j, "thread_pitch") {
        let v = cx.text_numbers(n, 1)?;
        if v[0].1 == 0.0 {
            cx.error(
                &n.first_child().map_or_else(|| cx.tag(n), |c| c.range()),
                format!(
                    "screw joint `{}` has thread_pitch 0",
                    j.attribute("name").unwrap_or("")
                ),
                "radians per metre: an infinite lead",
                "`<thread_pitch>` is rad/m (positive: a left-handed thread); \
                 `<screw_thread_pitch>` (SDF 1.10) is m per revolution",
            );
            return None;
        }
        return Some(format!("-{q} / ({})", number(&v[0].0, v[0].1)));
    }
    cx.warn(
        &cx.attr_range(j, "type"),
        "the screw joint has no `<screw_thread_pitch>` or `<thread_pitch>`",
        "1 m per revolution",
        "SDFormat's default `<screw_thread_pitch>` is 1 (m per revolution, right-handed)",
    );
    Some(format!("1 / (2 * pi) * {q}"))
}

/// A screw joint's steps: the rotation about the unit `axis` by `q` and the translation `lead`
/// (an expression of `q`) along it; about a coordinate axis directly, else in a frame whose z
/// is the axis (turned onto it before and back after), as a revolute joint's.
fn screw_steps(q: &str, lead: &str, axis: [f64; 3]) -> Vec<String> {
    match geom::coordinate_axis(axis) {
        Some((k, s)) => {
            let a = ["x", "y", "z"][k];
            let mut steps = joint_steps("revolute", q, axis);
            steps.push(quote(&if s > 0.0 {
                format!("T{a}({lead})")
            } else {
                format!("T{a}(-({lead}))")
            }));
            steps
        }
        None => {
            let aa = format!(
                "{{ axis_angle = [{}] }}",
                geom::z_onto(axis).map(fnum).join(", ")
            );
            vec![
                aa.clone(),
                format!("{{ revolute = {} }}", quote(q)),
                quote(&format!("Tz({lead})")),
                format!("{{ inverse = [{aa}] }}"),
            ]
        }
    }
}

/// The steps from a joint's child link to the joint's frame: its `<pose>`, or through the model's
/// frame when the pose is relative to another frame than the child.
fn joint_pose<'a, 'i>(
    cx: &mut Cx<'_>,
    f: &mut Frames<'a, 'i>,
    j: Node<'a, 'i>,
    child_link: &str,
    ca: &Abs,
) -> Vec<String> {
    let Some(p) = child(j, "pose") else {
        return Vec::new();
    };
    match p.attribute("relative_to").map(|r| resolve(j, r)) {
        Some(r) if r != child_link => {
            let Some(abs) = abs_of(cx, f, &qname(j)) else {
                return Vec::new();
            };
            let mut steps = Vec::new();
            if !ca.steps.is_empty() {
                steps.push(format!("{{ inverse = [{}] }}", ca.steps.join(", ")));
            }
            steps.extend(abs.steps);
            steps
        }
        _ => pose(cx, p).map_or_else(Vec::new, |(s, _, _)| s),
    }
}

/// A `<pose>`: its steps and its numbers.
fn pose(cx: &mut Cx<'_>, p: Node<'_, '_>) -> Option<(Vec<String>, [f64; 3], Mat)> {
    let degrees = p.attribute("degrees") == Some("true");
    let quat = match p.attribute("rotation_format") {
        None | Some("euler_rpy") => false,
        Some("quat_xyzw") => true,
        Some(other) => {
            cx.error(
                &cx.attr_range(p, "rotation_format"),
                format!("unknown rotation format `{other}`"),
                "euler_rpy or quat_xyzw",
                "",
            );
            return None;
        }
    };
    let v = cx.text_numbers(p, if quat { 7 } else { 6 })?;
    let xyz = [v[0].1, v[1].1, v[2].1];
    let deg = if degrees { ", unit = \"deg\"" } else { "" };
    let (rot_key, r) = if quat {
        let q = [v[6].1, v[3].1, v[4].1, v[5].1];
        if q.iter().all(|x| *x == 0.0) {
            cx.error(
                &p.first_child().map_or_else(|| cx.tag(p), |c| c.range()),
                "a zero quaternion",
                "no rotation",
                "",
            );
            return None;
        }
        let t = [&v[6], &v[3], &v[4], &v[5]].map(|(s, x)| number(s, *x));
        (Some(format!("quat = [{}]", t.join(", "))), geom::quat(q))
    } else {
        let k = if degrees {
            std::f64::consts::PI / 180.0
        } else {
            1.0
        };
        let any = v[3..].iter().any(|x| x.1 != 0.0);
        let t: Vec<String> = v[3..].iter().map(|(s, x)| number(s, *x)).collect();
        (
            any.then(|| format!("rpy = [{}]{deg}", t.join(", "))),
            geom::rpy(v[3].1 * k, v[4].1 * k, v[5].1 * k),
        )
    };
    let xyz_text = xyz.iter().any(|x| *x != 0.0).then(|| {
        v[..3]
            .iter()
            .map(|(s, x)| number(s, *x))
            .collect::<Vec<_>>()
            .join(", ")
    });
    let steps = super::pose_step(xyz_text, rot_key).into_iter().collect();
    Some((steps, xyz, r))
}

/// The frame `name` (a link, joint or `<frame>`; `world` and `__model__` are the model's frame)
/// in the model's frame.
fn abs_of<'a, 'i>(cx: &mut Cx<'_>, f: &mut Frames<'a, 'i>, name: &str) -> Option<Abs> {
    if name == "world" || name == "__model__" || name.is_empty() {
        return Some(Abs {
            steps: Vec::new(),
            p: [0.0; 3],
            r: IDENTITY,
        });
    }
    if let Some(done) = f.done.get(name) {
        return done.clone();
    }
    let node = *f.nodes.get(name)?;
    if f.visiting.iter().any(|v| v == name) {
        cx.error(
            &cx.attr_range(node, "name"),
            format!("the poses of `{name}` are relative to each other in a cycle"),
            "",
            "",
        );
        return None;
    }
    f.visiting.push(name.to_string());
    let tag = node.tag_name().name();
    let pose_node = child(node, "pose");
    // What the pose is relative to: `relative_to`, else a joint's child link, a frame's
    // `attached_to`, the model it is written in (for a nested model: the model around it).
    let default = match tag {
        "joint" => child(node, "child")
            .and_then(|c| c.text())
            .map(str::trim)
            .unwrap_or("")
            .to_string(),
        "frame" => node.attribute("attached_to").unwrap_or("").to_string(),
        _ => String::new(),
    };
    let written = pose_node
        .and_then(|p| p.attribute("relative_to"))
        .map_or(default, str::to_string);
    let base_name = resolve(
        node,
        if written.is_empty() {
            "__model__"
        } else {
            &written
        },
    );
    if base_name != "world" && base_name != "__model__" && !f.nodes.contains_key(&base_name) {
        let at = pose_node.map_or_else(|| cx.tag(node), |p| cx.attr_range(p, "relative_to"));
        cx.error(
            &at,
            format!("unknown frame `{written}`"),
            "no link, joint or frame of this name",
            &scope_help(node, &base_name),
        );
        f.visiting.pop();
        f.done.insert(name.to_string(), None);
        return None;
    }
    let base = abs_of(cx, f, &base_name);
    let local = match pose_node {
        Some(p) => pose(cx, p),
        None => Some((Vec::new(), [0.0; 3], IDENTITY)),
    };
    f.visiting.pop();
    let result = base.zip(local).map(|(b, (steps, p, r))| {
        let d = geom::apply(&b.r, p);
        let mut all = b.steps.clone();
        all.extend(steps);
        Abs {
            steps: all,
            p: [b.p[0] + d[0], b.p[1] + d[1], b.p[2] + d[2]],
            r: geom::mul(&b.r, &r),
        }
    });
    f.done.insert(name.to_string(), result.clone());
    result
}

/// The unit axis of a joint, in the joint's frame.
fn axis_of<'a, 'i>(cx: &mut Cx<'_>, f: &mut Frames<'a, 'i>, j: Node<'a, 'i>) -> Option<[f64; 3]> {
    axis_in(cx, f, j, "axis")
}

/// The unit vector of a joint's `<axis>` or `<axis2>` (`tag`), in the joint's frame. SDFormat's
/// `joint.sdf`: the axis "is expressed in the joint frame unless a different frame is expressed
/// in the expressed_in attribute"; a vector given in another frame (a link, joint or `<frame>`,
/// `__model__`; SDF 1.6's `<use_parent_model_frame>true`, as SDFormat's 1.7 converter does) is
/// turned into the joint's axes with both frames as posed, every joint at zero.
/// A component within 1e-12 of zero after the turn is zero (an axis along a coordinate axis
/// stays one joint step).
fn axis_in<'a, 'i>(
    cx: &mut Cx<'_>,
    f: &mut Frames<'a, 'i>,
    j: Node<'a, 'i>,
    tag: &str,
) -> Option<[f64; 3]> {
    let Some(x) = child(j, tag).and_then(|a| child(a, "xyz")) else {
        cx.error(
            &cx.tag(j),
            format!("the joint has no `<{tag}><xyz>`"),
            "",
            "",
        );
        return None;
    };
    let written = x.attribute("expressed_in").filter(|e| !e.is_empty());
    // SDF 1.6's `<use_parent_model_frame>` (removed in 1.7, whose converter writes
    // `expressed_in="__model__"` for it): the axis in the model's frame.
    let parent_model = child(j, tag)
        .and_then(|a| child(a, "use_parent_model_frame"))
        .and_then(|n| n.text())
        .is_some_and(|t| matches!(t.trim(), "true" | "1"));
    let frame = written
        .or(parent_model.then_some("__model__"))
        .map(|e| resolve(j, e));
    let jname = qname(j);
    if let (Some(e), Some(w)) = (&frame, written)
        && e != "world"
        && e != "__model__"
        && !f.nodes.contains_key(e)
    {
        cx.error(
            &cx.attr_range(x, "expressed_in"),
            format!("unknown frame `{w}`"),
            "no link, joint or frame of this name",
            "the axis is expressed in the joint's frame unless `expressed_in` names another",
        );
        return None;
    }
    let v = cx.text_numbers(x, 3)?;
    let Some(a) = unit([v[0].1, v[1].1, v[2].1]) else {
        cx.error(
            &x.first_child().map_or_else(|| cx.tag(x), |c| c.range()),
            "the joint's axis is zero",
            "no direction",
            "",
        );
        return None;
    };
    match frame {
        Some(e) if e != jname => {
            let (ea, ja) = (abs_of(cx, f, &e)?, abs_of(cx, f, &jname)?);
            let turned = geom::apply(&geom::mul(&geom::transpose(&ja.r), &ea.r), a);
            let snapped = turned.map(|c| if c.abs() < 1e-12 { 0.0 } else { c });
            unit(snapped)
        }
        _ => Some(a),
    }
}

/// The `<dynamics>` of a joint's `<axis>` or `<axis2>` (`tag`) as the coordinate's keys.
fn dynamics(cx: &mut Cx<'_>, j: Node<'_, '_>, tag: &str, c: &mut Coord) {
    let Some(d) = child(j, tag).and_then(|a| child(a, "dynamics")) else {
        return;
    };
    let scalar = |cx: &mut Cx<'_>, tag: &str| {
        child(d, tag)
            .and_then(|n| cx.text_numbers(n, 1))
            .map(|v| number(&v[0].0, v[0].1))
    };
    c.damping = scalar(cx, "damping");
    c.stiffness = scalar(cx, "spring_stiffness");
    c.rest = scalar(cx, "spring_reference");
    if let Some(f) = child(d, "friction")
        && f.text()
            .is_some_and(|t| t.trim().parse::<f64>().is_ok_and(|v| v != 0.0))
    {
        cx.warn(
            &cx.tag(f),
            "joint friction is ignored",
            "not in the model",
            "the model language has viscous damping only",
        );
    }
}

fn inertial(cx: &mut Cx<'_>, i: Node<'_, '_>) -> Option<(String, [String; 3], [String; 6])> {
    let m = child(i, "mass").and_then(|m| cx.text_numbers(m, 1))?;
    let (mt, mv) = m[0].clone();
    if mv < 0.0 {
        let n = child(i, "mass").unwrap_or(i);
        cx.error(&cx.tag(n), "negative mass", "must be >= 0", "");
        return None;
    }
    let (mut com, mut r) = (["0".to_string(), "0".to_string(), "0".to_string()], None);
    if let Some(p) = child(i, "pose") {
        if p.attribute("relative_to").is_some() {
            cx.error(
                &cx.attr_range(p, "relative_to"),
                "an inertial pose relative to another frame is not supported",
                "",
                "give it in the link's frame",
            );
        }
        let (_, xyz, rot) = pose(cx, p)?;
        com = xyz.map(fnum);
        if rot != IDENTITY {
            r = Some(rot);
        }
    }
    let keys = ["ixx", "iyy", "izz", "ixy", "ixz", "iyz"];
    let mut e = [0.0; 6];
    if let Some(n) = child(i, "inertia") {
        for (k, key) in keys.iter().enumerate() {
            if let Some(v) = child(n, key).and_then(|x| cx.text_numbers(x, 1)) {
                e[k] = v[0].1;
            }
        }
    }
    let turned = match r {
        Some(r) => geom::inertia_entries(&geom::rotate_inertia(&r, &geom::inertia_matrix(e))),
        None => e,
    };
    if mv == 0.0 && e.iter().all(|x| *x == 0.0) {
        return None;
    }
    Some((number(&mt, mv), com, turned.map(fnum)))
}

/// The places of a link's mass properties: its `<inertial>`'s `<mass>`, `<pose>`, `<inertia>`.
fn inertial_places(cx: &Cx<'_>, l: Node<'_, '_>) -> Vec<(&'static str, Place)> {
    let Some(i) = child(l, "inertial") else {
        return Vec::new();
    };
    [("mass", "mass"), ("com", "pose"), ("inertia", "inertia")]
        .into_iter()
        .map(|(key, tag)| (key, cx.place(child(i, tag).unwrap_or(i))))
        .collect()
}
