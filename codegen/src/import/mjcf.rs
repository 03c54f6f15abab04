//! MJCF (MuJoCo's XML) -> [`Imported`].
//!
//! | MJCF | rbss |
//! |---|---|
//! | `<body pos quat\|euler\|axisangle\|xyaxes\|zaxis>` | a `[[body]]`: a `pose` step (`euler` as elementary steps in `<compiler eulerseq>`) |
//! | `<joint type="hinge\|slide">` (`pos`, `axis`) | a coordinate and its steps, about the anchor `pos` |
//! | `<joint type="ball">` | three coordinates `NAME_x`, `NAME_y`, `NAME_z` (a spherical joint, `Rx Ry Rz`) |
//! | `<joint type="free">`, `<freejoint>` (a body of `<worldbody>`) | a free joint: 7 coordinates `NAME_x`, `_y`, `_z`, `NAME_qw`, `_qx`, `_qy`, `_qz` (MuJoCo's `qpos`: world position, quaternion), their homes the body's `pos` and orientation; the body's steps are the free joint only |
//! | joint `stiffness`, `springref`, `damping`, `armature` | `stiffness`, `rest`, `damping`, `armature` |
//! | joint `ref` (hinge, slide) | the steps move by `q - ref` and the coordinate's home is `ref` (MuJoCo's `qpos0`: the body as written) |
//! | `<inertial pos quat mass diaginertia\|fullinertia>` | `mass`, `com`, `inertia` (in the body's axes) |
//! | `<geom>` (no `<inertial>`, `<compiler inertiafromgeom>`) | the mass and inertia of the body's spheres, capsules, cylinders, boxes, ellipsoids, meshes and height fields (`density` 1000 or `mass`), as MuJoCo's compiler computes them |
//! | `<asset><mesh file\|vertex face scale refpos refquat inertia>`, `<compiler meshdir assetdir strippath>` | a mesh geom's volume, centre of mass and inertia ([`super::mesh`]: STL, OBJ; `legacy` by default, `exact`, `convex`, `shell`) in its file's frame, put where the geom is |
//! | `<asset><hfield size>` | a height field geom's box (half sizes `x`, `y`, `elevation / 4 + base / 2`), as MuJoCo's |
//! | `<default class>`, `class`, `childclass` | attribute defaults of joints, geoms and actuators |
//! | `<equality><connect>` | a `ball` loop (`site1`/`site2`, or `body1`, `body2`, `anchor` with body2's point found at `qpos0`) |
//! | `<equality><weld>` | a `weld` loop (`relpose`, or the relative pose at `qpos0`) |
//! | `<equality><joint joint1 joint2 polycoef>` | a `coupling`: `a` = joint1, `b` = joint2, each counted from `qpos0` (`"q - ref"`); `ratio`/`offset` when linear, else `poly`; without joint2 (or with c1..c4 zero) `a = c0` |
//! | `<equality><tendon tendon1 tendon2 polycoef>` on `<fixed>` tendons | a `coupling` between the tendons' lengths from `qpos0`, `Σ coef (q - ref)`; a spatial tendon is refused (a path's length) |
//! | `<actuator>` with `joint` | the actuated coordinates; its `gear` (first entry) the coordinate's `gear` (U in the motor's units) |
//! | `<actuator>` with `tendon`, `site` or `body`, `<tendon>` no equality couples, `<sensor>` | skipped, a warning each (a coupled tendon's stiffness, damping, friction, range: a warning) |
//! | `<option gravity>` | `gravity` |
//! | `<include file>` | the included file's elements in its place (each file once) |

use std::cell::RefCell;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

use roxmltree::{Document, Node};

use super::geom::{self, Mat};
use super::mesh;
use super::xml::{Cx, child, children};
use super::{
    BodyOut, Coord, Imported, LoopOut, fnum, ident, joint_steps, number, pose_step, quote, unit,
};

/// A body's pose at `qpos0` in the world, and where it is.
#[derive(Clone, Copy)]
struct Placed {
    p: [f64; 3],
    r: Mat,
}

const WORLD: Placed = Placed {
    p: [0.0; 3],
    r: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
};

/// An orientation attribute: TOML inside a `pose` (`quat = [..]`), or steps after it; the matrix.
struct Orient {
    key: Option<String>,
    steps: Vec<String>,
    r: Mat,
}

struct Ctx<'a, 'i> {
    degree: bool,
    /// `eulerseq`: (axis, intrinsic) per angle.
    eulerseq: [(usize, bool); 3],
    /// `inertiafromgeom`: `None` auto, `Some(true)`, `Some(false)`.
    from_geom: Option<bool>,
    /// class -> (parent class, `<default>` node).
    defaults: HashMap<String, (Option<String>, Node<'a, 'i>)>,
    placed: HashMap<String, Placed>,
    /// site name -> (body, position and rotation in the body, node).
    sites: HashMap<String, (String, [f64; 3], Mat, Node<'a, 'i>)>,
    /// joint name -> (its coordinates, kind, its value counted from `qpos0` as an expression:
    /// `"q"`, or `"q - ref"`).
    joints: HashMap<String, (Vec<String>, &'static str, String)>,
    /// tendon name -> its `<fixed>` or `<spatial>` element.
    tendons: HashMap<String, Node<'a, 'i>>,
    bodies_seen: usize,
    /// `<include file>` -> the included file's root.
    includes: Vec<(&'a str, Node<'a, 'i>)>,
    /// The source's directory (mesh files are relative to it and `meshdir`).
    dir: PathBuf,
    /// `<compiler meshdir>` (else `assetdir`), `strippath`.
    meshdir: Option<String>,
    assetdir: Option<String>,
    strippath: bool,
    /// `<asset><mesh>` and `<hfield>` by name.
    meshes: HashMap<String, Node<'a, 'i>>,
    hfields: HashMap<String, Node<'a, 'i>>,
    /// A mesh's mass properties once read (`None`: its error reported).
    mesh_props: RefCell<HashMap<String, Option<mesh::MassProps>>>,
}

/// The files `<include>`d by the source and by them (`file` relative to the source's directory,
/// as MuJoCo reads it): (the `file` as written, the path as shown, the text). A file included
/// twice, the source included, a missing file and more than 64 files are located errors.
pub(super) fn includes(
    path: &Path,
    shown: &str,
    text: &str,
) -> Result<Vec<(String, String, String)>, crate::diagnostics::Diagnostics> {
    let dir = path.parent().unwrap_or(Path::new(""));
    let mut out: Vec<(String, String, String)> = Vec::new();
    let mut queue: Vec<(String, String)> = vec![(shown.to_string(), text.to_string())];
    let mut i = 0;
    while i < queue.len() {
        let (from, from_text) = queue[i].clone();
        i += 1;
        let opts = roxmltree::ParsingOptions {
            allow_dtd: false,
            nodes_limit: super::MAX_NODES,
            ..Default::default()
        };
        // A file that does not parse is reported when it is parsed for the import.
        let Ok(doc) = Document::parse_with_options(&from_text, opts) else {
            continue;
        };
        let mut cx = Cx::new(&from, &from_text);
        for inc in doc
            .descendants()
            .filter(|n| n.is_element() && n.tag_name().name() == "include")
        {
            let Some(file) = cx.required(inc, "file") else {
                continue;
            };
            let p = dir.join(file);
            let p_shown = p.display().to_string().replace('\\', "/");
            if out.iter().any(|(k, _, _)| k == file) || p == path {
                cx.error(
                    &cx.attr_range(inc, "file"),
                    format!("`{file}` is included twice"),
                    "",
                    "MuJoCo includes a file once",
                );
                continue;
            }
            if out.len() >= 64 {
                cx.error(
                    &cx.attr_range(inc, "file"),
                    "more than 64 included files",
                    "",
                    "",
                );
                break;
            }
            match super::read_xml(&p, &p_shown) {
                Ok(t) => {
                    queue.push((p_shown.clone(), t.clone()));
                    out.push((file.to_string(), p_shown, t));
                }
                Err(e) => {
                    let why = e.items.first().map_or(String::new(), |d| d.message.clone());
                    cx.error(
                        &cx.attr_range(inc, "file"),
                        format!("cannot include `{p_shown}`: {why}"),
                        "relative to the source's directory",
                        "",
                    );
                }
            }
        }
        if let (Some(errors), _) = cx.finish() {
            return Err(errors);
        }
    }
    Ok(out)
}

/// The child elements of `n`, each `<include>` replaced by the children of the included file's
/// `<mujoco>`.
fn kids<'a, 'i>(ctx: &Ctx<'a, 'i>, n: Node<'a, 'i>) -> Vec<Node<'a, 'i>> {
    let mut out = Vec::new();
    for c in n.children().filter(|c| c.is_element()) {
        if c.tag_name().name() != "include" {
            out.push(c);
        } else if let Some((_, root)) = c
            .attribute("file")
            .and_then(|f| ctx.includes.iter().find(|(k, _)| *k == f))
        {
            out.extend(kids(ctx, *root));
        }
    }
    out
}

/// [`kids`] named `tag`.
fn kids_named<'a, 'i>(ctx: &Ctx<'a, 'i>, n: Node<'a, 'i>, tag: &str) -> Vec<Node<'a, 'i>> {
    kids(ctx, n)
        .into_iter()
        .filter(|c| c.tag_name().name() == tag)
        .collect()
}

pub(super) fn import<'a, 'i>(
    cx: &mut Cx<'_>,
    doc: &'a Document<'i>,
    includes: &[(&'a str, Node<'a, 'i>)],
    dir: &Path,
) -> Option<Imported> {
    let root = doc.root_element();
    if root.tag_name().name() != "mujoco" {
        cx.error(
            &cx.tag(root),
            format!(
                "an MJCF file's root element is `<mujoco>`, not `<{}>`",
                root.tag_name().name()
            ),
            "expected `<mujoco>`",
            "",
        );
        return None;
    }
    let mut ctx = Ctx {
        degree: true,
        eulerseq: [(0, true), (1, true), (2, true)],
        from_geom: None,
        defaults: HashMap::new(),
        placed: HashMap::new(),
        sites: HashMap::new(),
        joints: HashMap::new(),
        tendons: HashMap::new(),
        bodies_seen: 0,
        includes: includes.to_vec(),
        dir: dir.to_path_buf(),
        meshdir: None,
        assetdir: None,
        strippath: false,
        meshes: HashMap::new(),
        hfields: HashMap::new(),
        mesh_props: RefCell::new(HashMap::new()),
    };
    let mut out = Imported {
        name: ident(&root.attribute("model").unwrap_or("robot").to_lowercase()),
        description: format!("imported from {}", cx.path),
        gravity: ["0".into(), "0".into(), "-9.81".into()],
        root: Some(cx.place(root)),
        ..Imported::default()
    };
    for c in kids_named(&ctx, root, "compiler") {
        compiler(cx, c, &mut ctx);
    }
    for o in kids_named(&ctx, root, "option") {
        if let Some(g) = o
            .attribute_node("gravity")
            .and_then(|_| cx.numbers(o, "gravity", 3))
        {
            out.gravity = [0, 1, 2].map(|k| number(&g[k].0, g[k].1));
        }
    }
    for d in kids_named(&ctx, root, "default") {
        collect_defaults(cx, d, None, &mut ctx);
    }
    for a in kids_named(&ctx, root, "asset") {
        for m in kids(&ctx, a) {
            let tag = m.tag_name().name();
            if tag != "mesh" && tag != "hfield" {
                continue;
            }
            // A mesh without a name is named by its file (no directory, no extension).
            let name = m.attribute("name").map(str::to_string).or_else(|| {
                m.attribute("file").map(|f| {
                    let base = f.rsplit(['/', '\\']).next().unwrap_or(f);
                    base.rsplit_once('.').map_or(base, |(b, _)| b).to_string()
                })
            });
            if let Some(name) = name {
                let map = if tag == "mesh" {
                    &mut ctx.meshes
                } else {
                    &mut ctx.hfields
                };
                map.insert(name, m);
            }
        }
    }
    for w in kids_named(&ctx, root, "worldbody") {
        for b in kids_named(&ctx, w, "body") {
            walk(cx, b, "world", WORLD, None, &mut ctx, &mut out);
        }
    }
    for t in kids_named(&ctx, root, "tendon") {
        for k in kids(&ctx, t) {
            if let Some(n) = k.attribute("name") {
                ctx.tendons.insert(n.to_string(), k);
            }
        }
    }
    // The tendons the equalities couple.
    let mut coupled: Vec<String> = Vec::new();
    for e in kids_named(&ctx, root, "equality") {
        for q in kids(&ctx, e) {
            equality(cx, q, &ctx, &mut out, &mut coupled);
        }
    }
    for a in kids_named(&ctx, root, "actuator") {
        for m in kids(&ctx, a) {
            actuator(cx, m, &ctx, &mut out);
        }
    }
    // A tendon is in the model only through its equalities (a fixed tendon's length is an
    // expression of the coordinates): the others are skipped with a warning, and a coupled
    // one's stiffness, damping, friction or limits are not applied (a warning too).
    for t in kids_named(&ctx, root, "tendon") {
        for k in kids(&ctx, t) {
            if k.attribute("name")
                .is_some_and(|n| coupled.iter().any(|c| c == n))
            {
                let forces = ["stiffness", "damping", "frictionloss", "range"]
                    .into_iter()
                    .filter(|a| {
                        k.attribute(*a).is_some_and(|v| {
                            v.split_ascii_whitespace()
                                .any(|x| x.parse::<f64>() != Ok(0.0))
                        })
                    })
                    .collect::<Vec<_>>();
                if !forces.is_empty() {
                    cx.warn(
                        &cx.tag(k),
                        format!(
                            "tendon `{}`'s {} {} not applied",
                            k.attribute("name").unwrap_or_default(),
                            forces.join(", "),
                            if forces.len() == 1 { "is" } else { "are" }
                        ),
                        "not applied",
                        "the tendon is in the model through its equality only: a coupling of its length",
                    );
                }
                continue;
            }
            cx.warn(
                &cx.tag(k),
                format!(
                    "tendon{} is skipped",
                    k.attribute("name")
                        .map(|n| format!(" `{n}`"))
                        .unwrap_or_default()
                ),
                "skipped",
                "tendons are not in the model language: a tendon's stiffness, damping or limits are not applied",
            );
        }
    }
    for s in kids_named(&ctx, root, "sensor") {
        cx.warn(
            &cx.tag(s),
            "sensors are skipped",
            "skipped",
            "they measure and do not act: the dynamics are the same",
        );
    }
    Some(out)
}

fn compiler(cx: &mut Cx<'_>, c: Node<'_, '_>, ctx: &mut Ctx<'_, '_>) {
    match c.attribute("angle") {
        None | Some("degree") => {}
        Some("radian") => ctx.degree = false,
        Some(v) => cx.error(
            &cx.attr_range(c, "angle"),
            format!("`angle` is `degree` or `radian`, not `{v}`"),
            "",
            "",
        ),
    }
    if let Some(seq) = c.attribute("eulerseq") {
        let axes: Vec<(usize, bool)> = seq
            .chars()
            .filter_map(|ch| {
                "xyz"
                    .find(ch.to_ascii_lowercase())
                    .map(|k| (k, ch.is_ascii_lowercase()))
            })
            .collect();
        if axes.len() == 3 && seq.chars().count() == 3 {
            ctx.eulerseq = [axes[0], axes[1], axes[2]];
        } else {
            cx.error(
                &cx.attr_range(c, "eulerseq"),
                format!("`eulerseq` is three of x, y, z, X, Y, Z, not `{seq}`"),
                "",
                "",
            );
        }
    }
    match c.attribute("inertiafromgeom") {
        None | Some("auto") => {}
        Some("true") => ctx.from_geom = Some(true),
        Some("false") => ctx.from_geom = Some(false),
        Some(v) => cx.error(
            &cx.attr_range(c, "inertiafromgeom"),
            format!("`inertiafromgeom` is auto, true or false, not `{v}`"),
            "",
            "",
        ),
    }
    if let Some(d) = c.attribute("meshdir") {
        ctx.meshdir = Some(d.to_string());
    }
    if let Some(d) = c.attribute("assetdir") {
        ctx.assetdir = Some(d.to_string());
    }
    if let Some(v) = c.attribute("strippath") {
        ctx.strippath = v == "true";
    }
    if c.attribute("coordinate").is_some_and(|v| v != "local") {
        cx.error(
            &cx.attr_range(c, "coordinate"),
            "global coordinates are not supported",
            "",
            "MuJoCo itself removed them: write the model in local coordinates",
        );
    }
}

fn collect_defaults<'a, 'i>(
    cx: &mut Cx<'_>,
    d: Node<'a, 'i>,
    parent: Option<String>,
    ctx: &mut Ctx<'a, 'i>,
) {
    let class = match d.attribute("class") {
        Some(c) => c.to_string(),
        None if parent.is_none() => "main".to_string(),
        None => {
            cx.error(&cx.tag(d), "a nested `<default>` needs a `class`", "", "");
            return;
        }
    };
    if ctx.defaults.insert(class.clone(), (parent, d)).is_some() {
        cx.error(
            &cx.attr_range(d, "class"),
            format!("default class `{class}` is defined twice"),
            "",
            "",
        );
    }
    for c in children(d, "default") {
        collect_defaults(cx, c, Some(class.clone()), ctx);
    }
}

/// The node holding attribute `name` of `el`: `el` itself, else the default of its class (or
/// `class`, the inherited `childclass`, else `main`) and the classes above it.
fn lookup<'a, 'i>(
    cx: &mut Cx<'_>,
    ctx: &Ctx<'a, 'i>,
    el: Node<'a, 'i>,
    class: Option<&str>,
    name: &str,
) -> Option<Node<'a, 'i>> {
    if el.attribute(name).is_some() {
        return Some(el);
    }
    let mut cls = el
        .attribute("class")
        .or(class)
        .unwrap_or("main")
        .to_string();
    if !ctx.defaults.contains_key(&cls) {
        if el.attribute("class").is_some() {
            cx.error(
                &cx.attr_range(el, "class"),
                format!("unknown default class `{cls}`"),
                "no `<default class>` of this name",
                "",
            );
        }
        return None;
    }
    let tag = el.tag_name().name();
    loop {
        let (parent, d) = ctx.defaults.get(&cls)?;
        if let Some(n) = child(*d, tag).filter(|n| n.attribute(name).is_some()) {
            return Some(n);
        }
        cls = parent.clone()?;
    }
}

/// The angle of `text` as an expression in radians.
fn angle(ctx: &Ctx<'_, '_>, text: &str, v: f64) -> String {
    if ctx.degree {
        format!("{} * pi / 180", number(text, v))
    } else {
        number(text, v)
    }
}

fn radians(ctx: &Ctx<'_, '_>, v: f64) -> f64 {
    if ctx.degree {
        v * std::f64::consts::PI / 180.0
    } else {
        v
    }
}

/// The orientation of a body, inertial, geom or site (at most one of its five attributes).
fn orientation(cx: &mut Cx<'_>, ctx: &Ctx<'_, '_>, el: Node<'_, '_>) -> Option<Orient> {
    let given: Vec<&str> = ["quat", "euler", "axisangle", "xyaxes", "zaxis"]
        .into_iter()
        .filter(|a| el.attribute(*a).is_some())
        .collect();
    if given.len() > 1 {
        cx.error(
            &cx.attr_range(el, given[1]),
            format!(
                "`{}` and `{}` both orient `<{}>`",
                given[0],
                given[1],
                el.tag_name().name()
            ),
            "one orientation only",
            "",
        );
        return None;
    }
    let none = Orient {
        key: None,
        steps: Vec::new(),
        r: WORLD.r,
    };
    let Some(&which) = given.first() else {
        return Some(none);
    };
    let numeric = |r: Mat| {
        let q = geom::to_quat(&r);
        Orient {
            key: Some(format!("quat = [{}]", q.map(fnum).join(", "))),
            steps: Vec::new(),
            r,
        }
    };
    match which {
        "quat" => {
            let q = cx.numbers(el, "quat", 4)?;
            let v = [q[0].1, q[1].1, q[2].1, q[3].1];
            if v.iter().all(|x| *x == 0.0) {
                cx.error(
                    &cx.attr_range(el, "quat"),
                    "a zero quaternion",
                    "no rotation",
                    "",
                );
                return None;
            }
            let texts: Vec<String> = q.iter().map(|(t, x)| number(t, *x)).collect();
            Some(Orient {
                key: Some(format!("quat = [{}]", texts.join(", "))),
                steps: Vec::new(),
                r: geom::quat(v),
            })
        }
        "axisangle" => {
            let a = cx.numbers(el, "axisangle", 4)?;
            let axis = unit([a[0].1, a[1].1, a[2].1]);
            let Some(axis) = axis else {
                cx.error(
                    &cx.attr_range(el, "axisangle"),
                    "the axis is zero",
                    "no direction",
                    "",
                );
                return None;
            };
            let t = radians(ctx, a[3].1);
            let r = axis_angle(axis, t);
            let texts: Vec<String> = a.iter().map(|(s, x)| number(s, *x)).collect();
            let deg = if ctx.degree { ", unit = \"deg\"" } else { "" };
            Some(Orient {
                key: Some(format!("axis_angle = [{}]{deg}", texts.join(", "))),
                steps: Vec::new(),
                r,
            })
        }
        "euler" => {
            let e = cx.numbers(el, "euler", 3)?;
            let mut r = WORLD.r;
            for (k, &(axis, intrinsic)) in ctx.eulerseq.iter().enumerate() {
                let m = geom::elementary(axis, radians(ctx, e[k].1));
                r = if intrinsic {
                    geom::mul(&r, &m)
                } else {
                    geom::mul(&m, &r)
                };
            }
            let all_in = ctx.eulerseq.iter().all(|a| a.1);
            let all_ex = ctx.eulerseq.iter().all(|a| !a.1);
            if !(all_in || all_ex) {
                return Some(numeric(r));
            }
            let mut steps: Vec<String> = (0..3)
                .filter(|&k| e[k].1 != 0.0)
                .map(|k| {
                    quote(&format!(
                        "R{}({})",
                        ["x", "y", "z"][ctx.eulerseq[k].0],
                        angle(ctx, &e[k].0, e[k].1)
                    ))
                })
                .collect();
            if all_ex {
                steps.reverse();
            }
            Some(Orient {
                key: None,
                steps,
                r,
            })
        }
        "xyaxes" => {
            let v = cx.numbers(el, "xyaxes", 6)?;
            let x = unit([v[0].1, v[1].1, v[2].1]);
            let yraw = [v[3].1, v[4].1, v[5].1];
            let y = x.and_then(|x| {
                let d = geom::dot(x, yraw);
                unit([yraw[0] - d * x[0], yraw[1] - d * x[1], yraw[2] - d * x[2]])
            });
            let (Some(x), Some(y)) = (x, y) else {
                cx.error(
                    &cx.attr_range(el, "xyaxes"),
                    "the axes are zero or parallel",
                    "no frame",
                    "",
                );
                return None;
            };
            let z = geom::cross(x, y);
            Some(numeric([
                [x[0], y[0], z[0]],
                [x[1], y[1], z[1]],
                [x[2], y[2], z[2]],
            ]))
        }
        _ => {
            let v = cx.numbers(el, "zaxis", 3)?;
            let Some(z) = unit([v[0].1, v[1].1, v[2].1]) else {
                cx.error(
                    &cx.attr_range(el, "zaxis"),
                    "the axis is zero",
                    "no direction",
                    "",
                );
                return None;
            };
            if z[0] == 0.0 && z[1] == 0.0 {
                return Some(if z[2] > 0.0 {
                    none
                } else {
                    numeric(geom::elementary(0, std::f64::consts::PI))
                });
            }
            let t = geom::z_onto(z);
            let r = axis_angle(unit([t[0], t[1], t[2]]).unwrap_or([1.0, 0.0, 0.0]), t[3]);
            Some(Orient {
                key: Some(format!("axis_angle = [{}]", t.map(fnum).join(", "))),
                steps: Vec::new(),
                r,
            })
        }
    }
}

/// The rotation by `t` about the unit axis `a` (Rodrigues).
fn axis_angle(a: [f64; 3], t: f64) -> Mat {
    let (s, c) = t.sin_cos();
    let v = 1.0 - c;
    let [x, y, z] = a;
    [
        [c + x * x * v, x * y * v - z * s, x * z * v + y * s],
        [y * x * v + z * s, c + y * y * v, y * z * v - x * s],
        [z * x * v - y * s, z * y * v + x * s, c + z * z * v],
    ]
}

/// A body, its joints, mass and children.
fn walk<'a, 'i>(
    cx: &mut Cx<'_>,
    b: Node<'a, 'i>,
    parent: &str,
    at: Placed,
    childclass: Option<&str>,
    ctx: &mut Ctx<'a, 'i>,
    out: &mut Imported,
) {
    ctx.bodies_seen += 1;
    let name = match b.attribute("name") {
        Some(n) => cx.body_name(n),
        None => format!("body{}", ctx.bodies_seen),
    };
    let class = b.attribute("childclass").or(childclass);
    let pos = b
        .attribute_node("pos")
        .and_then(|_| cx.numbers(b, "pos", 3));
    let orient = orientation(cx, ctx, b);
    let p = pos.as_ref().map_or([0.0; 3], |v| [v[0].1, v[1].1, v[2].1]);
    let rot = orient.as_ref().map_or(WORLD.r, |o| o.r);
    let here = Placed {
        p: {
            let d = geom::apply(&at.r, p);
            [at.p[0] + d[0], at.p[1] + d[1], at.p[2] + d[2]]
        },
        r: geom::mul(&at.r, &rot),
    };
    ctx.placed.insert(name.clone(), here);
    let mut transforms = Vec::new();
    let (key, steps) = orient.map_or((None, Vec::new()), |o| (o.key, o.steps));
    transforms.extend(pose_step(pos.as_deref().and_then(super::nonzero_list), key));
    transforms.extend(steps);

    for j in kids(ctx, b)
        .into_iter()
        .filter(|n| matches!(n.tag_name().name(), "joint" | "freejoint"))
    {
        joint(
            cx,
            ctx,
            j,
            class,
            (&name, parent, &here),
            &mut transforms,
            out,
        );
    }
    for s in kids_named(ctx, b, "site") {
        if let Some(n) = s.attribute("name") {
            let sp = s
                .attribute_node("pos")
                .and_then(|_| cx.numbers(s, "pos", 3))
                .map_or([0.0; 3], |v| [v[0].1, v[1].1, v[2].1]);
            let sr = orientation(cx, ctx, s).map_or(WORLD.r, |o| o.r);
            ctx.sites.insert(n.to_string(), (name.clone(), sp, sr, s));
        }
    }
    let mass = match (child(b, "inertial"), ctx.from_geom) {
        (Some(i), None | Some(false)) => inertial(cx, ctx, i),
        (_, Some(true)) | (None, None) => from_geoms(cx, ctx, b, class),
        (None, Some(false)) => None,
    };
    if transforms.is_empty() {
        transforms.push(quote("Tz(0)"));
    }
    // The steps' errors at the body's first joint (its pose's at the body), the mass
    // properties' at `<inertial>`.
    let mut places = Vec::new();
    if let Some(j) = kids(ctx, b)
        .into_iter()
        .find(|n| matches!(n.tag_name().name(), "joint" | "freejoint"))
    {
        places.push(("transforms", cx.place(j)));
    }
    if let Some(i) = child(b, "inertial") {
        for key in ["mass", "com", "inertia"] {
            places.push((key, cx.place(i)));
        }
    }
    out.bodies.push(BodyOut {
        name: name.clone(),
        parent: parent.to_string(),
        transforms,
        mass,
        origin: cx.origin(b),
        places,
    });
    for c in kids_named(ctx, b, "body") {
        walk(cx, c, &name, here, class, ctx, out);
    }
}

#[allow(clippy::too_many_arguments)]
fn joint<'a, 'i>(
    cx: &mut Cx<'_>,
    ctx: &mut Ctx<'a, 'i>,
    j: Node<'a, 'i>,
    class: Option<&str>,
    (body, parent, here): (&str, &str, &Placed),
    transforms: &mut Vec<String>,
    out: &mut Imported,
) {
    let kind_node = lookup(cx, ctx, j, class, "type");
    let kind = if j.tag_name().name() == "freejoint" {
        "free"
    } else {
        kind_node
            .and_then(|n| n.attribute("type"))
            .unwrap_or("hinge")
    };
    let name = match j.attribute("name") {
        Some(n) => cx.joint_name(n),
        None => format!("{body}_joint{}", out.coordinates.len() + 1),
    };
    let origin = cx.origin(j);
    let num = |cx: &mut Cx<'_>, ctx: &Ctx<'a, 'i>, key: &str| -> Option<(String, f64)> {
        let n = lookup(cx, ctx, j, class, key)?;
        cx.number(n, key)
    };
    let vec3 = |cx: &mut Cx<'_>, ctx: &Ctx<'a, 'i>, key: &str| -> Option<[f64; 3]> {
        let n = lookup(cx, ctx, j, class, key)?;
        cx.numbers(n, key, 3).map(|v| [v[0].1, v[1].1, v[2].1])
    };
    let unit_of = match kind {
        "hinge" | "ball" => "rad",
        "slide" => "m",
        "free" => {
            let at = if j.tag_name().name() == "freejoint" {
                cx.tag(j)
            } else {
                cx.attr_range(kind_node.unwrap_or(j), "type")
            };
            if parent != "world" {
                cx.error(
                    &at,
                    "a free joint in a body that is not a child of `<worldbody>`",
                    "not a top-level body",
                    "MuJoCo allows free joints in top-level bodies only",
                );
                return;
            }
            // MuJoCo's qpos of a free joint is the body's world pose: the body's steps are the
            // free joint alone, its homes the pose as written.
            let (mut coords, step) = super::free_joint(&name, &origin);
            let q = geom::to_quat(&here.r);
            for (i, c) in coords.iter_mut().enumerate() {
                let v = if i < 3 { here.p[i] } else { q[i - 3] };
                c.home = (v != 0.0).then(|| fnum(v));
            }
            transforms.clear();
            transforms.push(step);
            out.coordinates.extend(coords);
            return;
        }
        other => {
            cx.error(
                &cx.attr_range(kind_node.unwrap_or(j), "type"),
                format!("unknown joint type `{other}`"),
                "expected hinge, slide or ball",
                "",
            );
            return;
        }
    };
    let mut c = Coord {
        name: name.clone(),
        unit: unit_of,
        origin: origin.clone(),
        ..Coord::default()
    };
    if let Some((t, v)) = num(cx, ctx, "stiffness") {
        c.stiffness = Some(number(&t, v));
    }
    if let Some((t, v)) = num(cx, ctx, "springref") {
        c.rest = Some(if kind == "hinge" {
            angle(ctx, &t, v)
        } else {
            number(&t, v)
        });
        if kind == "hinge" && ctx.degree {
            c.rest = Some(quote(c.rest.as_deref().unwrap_or("0")));
        }
    }
    if let Some((t, v)) = num(cx, ctx, "damping") {
        c.damping = Some(number(&t, v));
    }
    if let Some((t, v)) = num(cx, ctx, "armature") {
        c.armature = Some(number(&t, v));
    }
    // `ref`: the joint's value at the body's pose as written (MuJoCo's qpos0), so the steps
    // move by `q - ref` and the coordinate's home is `ref` (slide and hinge joints only).
    let mut q_expr = name.clone();
    if let Some((t, v)) = num(cx, ctx, "ref")
        && v != 0.0
        && matches!(kind, "hinge" | "slide")
    {
        let r = if kind == "hinge" {
            angle(ctx, &t, v)
        } else {
            number(&t, v)
        };
        q_expr = format!("{name} - {r}");
        c.home = Some(if kind == "hinge" && ctx.degree {
            quote(&r)
        } else {
            r
        });
    }
    let anchor = vec3(cx, ctx, "pos").filter(|p| p.iter().any(|x| *x != 0.0));
    let anchor_text = anchor.map(|p| p.map(fnum).join(", "));
    let axis = vec3(cx, ctx, "axis").unwrap_or([0.0, 0.0, 1.0]);
    if let Some(a) = &anchor_text
        && kind != "slide"
    {
        transforms.push(format!("{{ pose = {{ xyz = [{a}] }} }}"));
    }
    let coords = match kind {
        "ball" => {
            let names: Vec<String> = ["x", "y", "z"]
                .iter()
                .map(|a| format!("{name}_{a}"))
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
                let mut cc = c.clone();
                cc.name = n.clone();
                out.coordinates.push(cc);
            }
            out.notes.push(format!("ball joint `{name}` is three coordinates {}: angles Rx Ry Rz, not MuJoCo's quaternion", names.join(", ")));
            names
        }
        _ => {
            let Some(axis) = unit(axis) else {
                let n = lookup(cx, ctx, j, class, "axis").unwrap_or(j);
                cx.error(
                    &cx.attr_range(n, "axis"),
                    "the joint's axis is zero",
                    "no direction",
                    "",
                );
                return;
            };
            let k = if kind == "slide" {
                "prismatic"
            } else {
                "revolute"
            };
            transforms.extend(joint_steps(k, &q_expr, axis));
            out.coordinates.push(c);
            vec![name.clone()]
        }
    };
    if let Some(a) = &anchor_text
        && kind != "slide"
    {
        transforms.push(format!("{{ inverse = [{{ pose = {{ xyz = [{a}] }} }}] }}"));
    }
    let kind_static: &'static str = match kind {
        "ball" => "ball",
        "slide" => "slide",
        _ => "hinge",
    };
    if ctx
        .joints
        .insert(
            j.attribute("name").unwrap_or(&name).to_string(),
            (coords, kind_static, q_expr.clone()),
        )
        .is_some()
    {
        cx.error(
            &cx.attr_range(j, "name"),
            format!("joint `{name}` is defined twice"),
            "",
            "",
        );
    }
}

type MassOut = (String, [String; 3], [String; 6]);

fn vec_of(v: &[(String, f64)]) -> [f64; 3] {
    [v[0].1, v[1].1, v[2].1]
}

fn inertial(cx: &mut Cx<'_>, ctx: &Ctx<'_, '_>, i: Node<'_, '_>) -> Option<MassOut> {
    let (mt, mv) = cx.required(i, "mass").and_then(|_| cx.number(i, "mass"))?;
    if mv < 0.0 {
        cx.error(
            &cx.attr_range(i, "mass"),
            "negative mass",
            "must be >= 0",
            "",
        );
    }
    let com = match i
        .attribute_node("pos")
        .and_then(|_| cx.numbers(i, "pos", 3))
    {
        Some(v) => [0, 1, 2].map(|k| number(&v[k].0, v[k].1)),
        None => {
            cx.required(i, "pos");
            return None;
        }
    };
    let r = orientation(cx, ctx, i).map_or(WORLD.r, |o| o.r);
    let entries = if i.attribute("fullinertia").is_some() {
        if i.attribute("diaginertia").is_some() {
            cx.error(
                &cx.attr_range(i, "fullinertia"),
                "`diaginertia` and `fullinertia` both given",
                "",
                "",
            );
        }
        // MuJoCo's order: ixx iyy izz ixy ixz iyz, the rbss order.
        let v = cx.numbers(i, "fullinertia", 6)?;
        [0, 1, 2, 3, 4, 5].map(|k| v[k].1)
    } else if i.attribute("diaginertia").is_some() {
        let v = cx.numbers(i, "diaginertia", 3)?;
        [v[0].1, v[1].1, v[2].1, 0.0, 0.0, 0.0]
    } else {
        cx.error(
            &cx.tag(i),
            "`<inertial>` has no `diaginertia` or `fullinertia`",
            "",
            "",
        );
        return None;
    };
    let turned = geom::inertia_entries(&geom::rotate_inertia(&r, &geom::inertia_matrix(entries)));
    (mv >= 0.0).then(|| (number(&mt, mv), com, turned.map(fnum)))
}

/// The mass, centre of mass and inertia of a body's geoms (MuJoCo's compiler: density 1000
/// unless given, `mass` overriding it; each shape's inertia about its centre, turned and moved
/// to the body's centre of mass). `None` for a body without geoms.
fn from_geoms(
    cx: &mut Cx<'_>,
    ctx: &Ctx<'_, '_>,
    b: Node<'_, '_>,
    class: Option<&str>,
) -> Option<MassOut> {
    let mut parts: Vec<(f64, [f64; 3], Mat)> = Vec::new();
    for g in kids_named(ctx, b, "geom") {
        let get = |cx: &mut Cx<'_>, key: &str| lookup(cx, ctx, g, class, key);
        let kind = get(cx, "type")
            .and_then(|n| n.attribute("type"))
            .unwrap_or("sphere");
        let size = match get(cx, "size") {
            Some(n) => cx
                .numbers(n, "size", 0)
                .unwrap_or_default()
                .iter()
                .map(|x| x.1)
                .collect::<Vec<f64>>(),
            None => Vec::new(),
        };
        let fromto = match get(cx, "fromto") {
            Some(n) => cx
                .numbers(n, "fromto", 6)
                .map(|v| v.iter().map(|x| x.1).collect::<Vec<f64>>()),
            None => None,
        };
        let mut pos = match get(cx, "pos") {
            Some(n) => cx.numbers(n, "pos", 3).map_or([0.0; 3], |v| vec_of(&v)),
            None => [0.0; 3],
        };
        let mut r = orientation(cx, ctx, g).map_or(WORLD.r, |o| o.r);
        if kind != "mesh" && g.attribute("mesh").is_some() {
            cx.error(
                &cx.attr_range(g, "mesh"),
                format!("the inertia of a `{kind}` geom fitted to a mesh is not computed"),
                "",
                "write `type=\"mesh\"` (the mesh's own inertia) or give the body an `<inertial>`",
            );
            continue;
        }
        if kind == "mesh" {
            // The mesh's mass properties in its file's (scaled) frame, put where the geom is:
            // the same body inertia as MuJoCo's, which moves the mesh to its centre of mass
            // and principal axes and the geom frame with it.
            let Some(p) = geom_mesh(cx, ctx, g, class) else {
                continue;
            };
            let m = geom_mass(cx, ctx, g, class, p.volume);
            let c = geom::apply(&r, p.com);
            let scaled = p.inertia.map(|row| row.map(|x| x * m / p.volume));
            parts.push((
                m,
                [pos[0] + c[0], pos[1] + c[1], pos[2] + c[2]],
                geom::rotate_inertia(&r, &scaled),
            ));
            continue;
        }
        let mut size = size;
        if kind == "hfield" {
            // MuJoCo's compiler gives a height field the inertia of a box of half sizes
            // (x, y, elevation / 4 + base / 2), its `<hfield size>`'s, at the geom.
            let Some(h) = hfield_size(cx, ctx, g, class) else {
                continue;
            };
            size = vec![h[0], h[1], 0.25 * h[2] + 0.5 * h[3]];
        }
        let need = match kind {
            "sphere" => 1,
            "capsule" | "cylinder" => {
                if fromto.is_some() {
                    1
                } else {
                    2
                }
            }
            "box" | "ellipsoid" | "hfield" => 3,
            "plane" => continue,
            other => {
                let n = get(cx, "type").unwrap_or(g);
                cx.error(
                    &cx.attr_range(n, "type"),
                    format!("the inertia of a `{other}` geom is not computed"),
                    "",
                    "give the body an `<inertial>`",
                );
                continue;
            }
        };
        if size.len() < need {
            let at = get(cx, "size").unwrap_or(g);
            cx.error(
                &cx.attr_range(at, "size"),
                format!(
                    "a `{kind}` geom needs {need} size number{}",
                    if need == 1 { "" } else { "s" }
                ),
                "",
                "",
            );
            continue;
        }
        let mut half = size.get(1).copied().unwrap_or(0.0);
        if let Some(ft) = &fromto {
            let d = [ft[3] - ft[0], ft[4] - ft[1], ft[5] - ft[2]];
            pos = [
                (ft[0] + ft[3]) / 2.0,
                (ft[1] + ft[4]) / 2.0,
                (ft[2] + ft[5]) / 2.0,
            ];
            half = geom::dot(d, d).sqrt() / 2.0;
            if let Some(z) = unit(d) {
                r = if z[0] == 0.0 && z[1] == 0.0 {
                    if z[2] > 0.0 {
                        WORLD.r
                    } else {
                        geom::elementary(0, std::f64::consts::PI)
                    }
                } else {
                    let t = geom::z_onto(z);
                    axis_angle(unit([t[0], t[1], t[2]]).unwrap_or([1.0, 0.0, 0.0]), t[3])
                };
            }
        }
        let pi = std::f64::consts::PI;
        let s = &size;
        let (volume, diag) = match kind {
            "sphere" => {
                let i = 2.0 * s[0] * s[0] / 5.0;
                (4.0 * pi * s[0].powi(3) / 3.0, [i, i, i])
            }
            "capsule" => {
                let (rr, h) = (s[0], 2.0 * half);
                let vc = pi * rr * rr * h;
                let vs = 4.0 * pi * rr.powi(3) / 3.0;
                let v = vc + vs;
                // Per unit mass: the cylinder and the two half spheres at its ends.
                let ixx = (vc * (h * h / 12.0 + rr * rr / 4.0)
                    + vs * (2.0 * rr * rr / 5.0 + h * h / 4.0 + 3.0 * h * rr / 8.0))
                    / v;
                let izz = (vc * rr * rr / 2.0 + vs * 2.0 * rr * rr / 5.0) / v;
                (v, [ixx, ixx, izz])
            }
            "cylinder" => {
                let (rr, h) = (s[0], 2.0 * half);
                let ixx = (3.0 * rr * rr + h * h) / 12.0;
                (pi * rr * rr * h, [ixx, ixx, rr * rr / 2.0])
            }
            "box" | "hfield" => {
                let [a, bb, c] = [s[0], s[1], s[2]];
                (
                    8.0 * a * bb * c,
                    [
                        (bb * bb + c * c) / 3.0,
                        (a * a + c * c) / 3.0,
                        (a * a + bb * bb) / 3.0,
                    ],
                )
            }
            _ => {
                let [a, bb, c] = [s[0], s[1], s[2]];
                (
                    4.0 * pi * a * bb * c / 3.0,
                    [
                        (bb * bb + c * c) / 5.0,
                        (a * a + c * c) / 5.0,
                        (a * a + bb * bb) / 5.0,
                    ],
                )
            }
        };
        let m = geom_mass(cx, ctx, g, class, volume);
        let i = [
            [diag[0] * m, 0.0, 0.0],
            [0.0, diag[1] * m, 0.0],
            [0.0, 0.0, diag[2] * m],
        ];
        parts.push((m, pos, geom::rotate_inertia(&r, &i)));
    }
    let total: f64 = parts.iter().map(|p| p.0).sum();
    if parts.is_empty() || total <= 0.0 {
        return None;
    }
    let c = [0, 1, 2].map(|k| parts.iter().map(|p| p.0 * p.1[k]).sum::<f64>() / total);
    let mut inertia = [[0.0; 3]; 3];
    for (m, p, i) in &parts {
        let d = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
        let dd = geom::dot(d, d);
        for a in 0..3 {
            for k in 0..3 {
                let delta = if a == k { 1.0 } else { 0.0 };
                inertia[a][k] += i[a][k] + m * (dd * delta - d[a] * d[k]);
            }
        }
    }
    Some((
        fnum(total),
        c.map(fnum),
        geom::inertia_entries(&inertia).map(fnum),
    ))
}

/// A geom's mass: its `mass`, else its `density` (1000) times `volume`.
fn geom_mass(
    cx: &mut Cx<'_>,
    ctx: &Ctx<'_, '_>,
    g: Node<'_, '_>,
    class: Option<&str>,
    volume: f64,
) -> f64 {
    match lookup(cx, ctx, g, class, "mass") {
        Some(n) => cx.number(n, "mass").map_or(0.0, |x| x.1),
        None => {
            let rho = lookup(cx, ctx, g, class, "density")
                .and_then(|n| cx.number(n, "density"))
                .map_or(1000.0, |x| x.1);
            rho * volume
        }
    }
}

/// The `size` (4 numbers) of the `<hfield>` a geom names; `None` after an error.
fn hfield_size(
    cx: &mut Cx<'_>,
    ctx: &Ctx<'_, '_>,
    g: Node<'_, '_>,
    class: Option<&str>,
) -> Option<Vec<f64>> {
    let at = lookup(cx, ctx, g, class, "hfield").unwrap_or(g);
    let Some(name) = at.attribute("hfield") else {
        cx.error(&cx.tag(g), "an `hfield` geom has no `hfield`", "", "");
        return None;
    };
    let Some(h) = ctx.hfields.get(name).copied() else {
        cx.error(
            &cx.attr_range(at, "hfield"),
            format!("no `<hfield>` named `{name}` in `<asset>`"),
            "",
            "",
        );
        return None;
    };
    cx.required(h, "size")?;
    cx.numbers(h, "size", 4)
        .map(|v| v.iter().map(|x| x.1).collect())
}

/// The mass properties (per unit density, in the mesh's frame) of the `<mesh>` a geom names,
/// read once per mesh; `None` after an error (located at the geom's `mesh` or the
/// `<mesh>`).
fn geom_mesh(
    cx: &mut Cx<'_>,
    ctx: &Ctx<'_, '_>,
    g: Node<'_, '_>,
    class: Option<&str>,
) -> Option<mesh::MassProps> {
    let at = lookup(cx, ctx, g, class, "mesh").unwrap_or(g);
    let Some(name) = at.attribute("mesh") else {
        cx.error(&cx.tag(g), "a `mesh` geom has no `mesh`", "", "");
        return None;
    };
    if let Some(p) = ctx.mesh_props.borrow().get(name) {
        return *p;
    }
    let Some(m) = ctx.meshes.get(name).copied() else {
        cx.error(
            &cx.attr_range(at, "mesh"),
            format!("no `<mesh>` named `{name}` in `<asset>`"),
            "",
            "",
        );
        return None;
    };
    let p = read_mesh(cx, ctx, m, name);
    ctx.mesh_props.borrow_mut().insert(name.to_string(), p);
    p
}

/// The path MuJoCo reads a mesh `file` from: as written when absolute, else in `meshdir`
/// (else `assetdir`), itself relative to the source's directory unless absolute.
pub fn mesh_path(dir: &Path, meshdir: Option<&str>, file: &str, strip: bool) -> PathBuf {
    let file = if strip {
        file.rsplit(['/', '\\']).next().unwrap_or(file)
    } else {
        file
    };
    let f = Path::new(file);
    if f.is_absolute() {
        return f.to_path_buf();
    }
    match meshdir.filter(|d| !d.is_empty()) {
        Some(d) => dir.join(d).join(f),
        None => dir.join(f),
    }
}

fn read_mesh(
    cx: &mut Cx<'_>,
    ctx: &Ctx<'_, '_>,
    m: Node<'_, '_>,
    name: &str,
) -> Option<mesh::MassProps> {
    let class = m.attribute("class");
    let get = |cx: &mut Cx<'_>, key: &str, n: usize| {
        lookup(cx, ctx, m, class, key).and_then(|at| cx.numbers(at, key, n).map(|v| (at, v)))
    };
    let scale = get(cx, "scale", 3).map_or([1.0; 3], |(_, v)| vec_of(&v));
    let refpos = get(cx, "refpos", 3).map_or([0.0; 3], |(_, v)| vec_of(&v));
    let refquat = get(cx, "refquat", 4).map_or([1.0, 0.0, 0.0, 0.0], |(_, v)| {
        [v[0].1, v[1].1, v[2].1, v[3].1]
    });
    let vertex = get(cx, "vertex", 0);
    let face = get(cx, "face", 0);
    let mode_at = lookup(cx, ctx, m, class, "inertia");
    let mode = match mode_at.and_then(|n| n.attribute("inertia")) {
        None => mesh::Inertia::Legacy,
        Some(k) => match mesh::Inertia::from_key(k) {
            Some(i) => i,
            None => {
                let at = mode_at.unwrap_or(m);
                cx.error(
                    &cx.attr_range(at, "inertia"),
                    format!("a mesh's `inertia` is convex, exact, legacy or shell, not `{k}`"),
                    "",
                    "",
                );
                return None;
            }
        },
    };
    let (mut data, at) = if let Some(file) = m.attribute("file") {
        let meshdir = ctx.meshdir.as_deref().or(ctx.assetdir.as_deref());
        let path = mesh_path(&ctx.dir, meshdir, file, ctx.strippath);
        let shown = path.display().to_string().replace('\\', "/");
        match mesh::read_file(&path) {
            Ok(d) => (d, Some((m, "file", shown))),
            Err(e) => {
                cx.error(
                    &cx.attr_range(m, "file"),
                    format!("mesh `{name}`: `{shown}`: {e}"),
                    "relative to the source's directory and `<compiler meshdir>`",
                    "",
                );
                return None;
            }
        }
    } else if let Some((_, v)) = vertex {
        let f: Vec<f64> = face
            .map(|(_, f)| f.iter().map(|x| x.1).collect())
            .unwrap_or_default();
        let n = v.len() / 3;
        if !v.len().is_multiple_of(3)
            || n < 4
            || !f.len().is_multiple_of(3)
            || f.iter()
                .any(|&i| i < 0.0 || i.fract() != 0.0 || i >= n as f64)
        {
            cx.error(
                &cx.tag(m),
                format!("mesh `{name}`: `vertex` is 3 numbers a vertex (at least 4), `face` 3 vertex indices a triangle"),
                "",
                "",
            );
            return None;
        }
        let verts = v
            .chunks(3)
            .map(|c| [c[0].1, c[1].1, c[2].1].map(|x| x as f32 as f64))
            .collect();
        let faces = f
            .chunks(3)
            .map(|c| [c[0] as usize, c[1] as usize, c[2] as usize])
            .collect();
        (mesh::Mesh { verts, faces }, None)
    } else {
        cx.error(
            &cx.tag(m),
            format!("mesh `{name}` has no `file` and no `vertex`"),
            "",
            "the inertia of builtin and plugin meshes is not computed: give the body an `<inertial>`",
        );
        return None;
    };
    mesh::transform(&mut data, refpos, refquat, scale);
    match mesh::mass_properties(&data, mode) {
        Ok(p) => Some(p),
        Err(e) => {
            let what = at
                .as_ref()
                .map_or(String::new(), |(_, _, s)| format!(" (`{s}`)"));
            cx.error(&cx.tag(m), format!("mesh `{name}`{what}: {e}"), "", "");
            None
        }
    }
}

/// An attachment `{ body = "...", transforms = [...] }` at `p` (and `r`) in `body`.
fn attachment(body: &str, p: [f64; 3], r: Option<&Mat>) -> String {
    let xyz = p.iter().any(|x| *x != 0.0).then(|| p.map(fnum).join(", "));
    let rot = r
        .filter(|r| **r != WORLD.r)
        .map(|r| format!("quat = [{}]", geom::to_quat(r).map(fnum).join(", ")));
    match pose_step(xyz, rot) {
        Some(s) => format!("{{ body = {}, transforms = [{s}] }}", quote(body)),
        None => format!("{{ body = {} }}", quote(body)),
    }
}

fn equality(
    cx: &mut Cx<'_>,
    q: Node<'_, '_>,
    ctx: &Ctx<'_, '_>,
    out: &mut Imported,
    coupled: &mut Vec<String>,
) {
    let tag = q.tag_name().name();
    let name = q
        .attribute("name")
        .map_or_else(|| format!("{tag}{}", out.loops.len() + 1), ident);
    let origin = cx.origin(q);
    let body_of = |cx: &mut Cx<'_>, key: &str, required: bool| -> Option<String> {
        match q.attribute(key) {
            None if required => {
                cx.required(q, key);
                None
            }
            None => Some("world".to_string()),
            Some("world") => Some("world".to_string()),
            Some(b) if ctx.placed.contains_key(&cx.body_name(b)) => Some(cx.body_name(b)),
            Some(b) => {
                cx.error(
                    &cx.attr_range(q, key),
                    format!("unknown body `{b}`"),
                    "no `<body>` of this name",
                    "",
                );
                None
            }
        }
    };
    let site = |cx: &mut Cx<'_>, key: &str| {
        let s = q.attribute(key)?;
        let hit = ctx.sites.get(s).map(|(b, p, r, _)| (b.clone(), *p, *r));
        if hit.is_none() {
            cx.error(
                &cx.attr_range(q, key),
                format!("unknown site `{s}`"),
                "no `<site>` of this name",
                "",
            );
        }
        hit
    };
    let placed = |b: &str| ctx.placed.get(b).copied().unwrap_or(WORLD);
    let keys = match tag {
        "connect" | "weld" => {
            let kind = if tag == "connect" { "ball" } else { "weld" };
            let rot = tag == "weld";
            let (a, b) = if q.attribute("site1").is_some() || q.attribute("site2").is_some() {
                let (Some(s1), Some(s2)) = (site(cx, "site1"), site(cx, "site2")) else {
                    if q.attribute("site1").is_none() || q.attribute("site2").is_none() {
                        cx.error(
                            &cx.tag(q),
                            format!("`<{tag}>` with sites needs `site1` and `site2`"),
                            "",
                            "",
                        );
                    }
                    return;
                };
                (
                    attachment(&s1.0, s1.1, rot.then_some(&s1.2)),
                    attachment(&s2.0, s2.1, rot.then_some(&s2.2)),
                )
            } else {
                let (Some(b1), Some(b2)) =
                    (body_of(cx, "body1", true), body_of(cx, "body2", false))
                else {
                    return;
                };
                let (w1, w2) = (placed(&b1), placed(&b2));
                if tag == "connect" {
                    let Some(anchor) = cx
                        .required(q, "anchor")
                        .and_then(|_| cx.numbers(q, "anchor", 3))
                    else {
                        return;
                    };
                    let an = vec_of(&anchor);
                    // body2's point: where body1's anchor is at qpos0.
                    let world = geom::apply(&w1.r, an);
                    let d = [
                        w1.p[0] + world[0] - w2.p[0],
                        w1.p[1] + world[1] - w2.p[1],
                        w1.p[2] + world[2] - w2.p[2],
                    ];
                    let p2 = geom::apply(&geom::transpose(&w2.r), d);
                    (attachment(&b1, an, None), attachment(&b2, p2, None))
                } else {
                    let rel = q
                        .attribute_node("relpose")
                        .and_then(|_| cx.numbers(q, "relpose", 7));
                    let (p, r) = match rel {
                        Some(v) if v[3..].iter().any(|x| x.1 != 0.0) => (
                            [v[0].1, v[1].1, v[2].1],
                            geom::quat([v[3].1, v[4].1, v[5].1, v[6].1]),
                        ),
                        _ => {
                            // body2's pose in body1's frame at qpos0.
                            let rt = geom::transpose(&w1.r);
                            let d = [w2.p[0] - w1.p[0], w2.p[1] - w1.p[1], w2.p[2] - w1.p[2]];
                            (geom::apply(&rt, d), geom::mul(&rt, &w2.r))
                        }
                    };
                    (
                        attachment(&b1, p, Some(&r)),
                        attachment(&b2, [0.0; 3], None),
                    )
                }
            };
            vec![
                ("name", quote(&name)),
                ("kind", quote(kind)),
                ("a", a),
                ("b", b),
            ]
        }
        "joint" | "tendon" => {
            let keys_of = if tag == "joint" {
                ["joint1", "joint2"]
            } else {
                ["tendon1", "tendon2"]
            };
            // Each side counted from qpos0, as MuJoCo's equality counts it: a joint's `q - ref`,
            // a fixed tendon's length minus its length at qpos0, `Σ coef (q - ref)`.
            let mut side = |cx: &mut Cx<'_>, key: &str| -> Option<String> {
                let name = cx.required(q, key)?;
                if tag == "joint" {
                    joint_side(cx, q, key, name, ctx)
                } else {
                    coupled.push(name.to_string());
                    tendon_side(cx, q, key, name, ctx)
                }
            };
            let a = side(cx, keys_of[0]);
            let b = match q.attribute(keys_of[1]) {
                None => Some(None),
                Some(_) => side(cx, keys_of[1]).map(Some),
            };
            let coef = q
                .attribute_node("polycoef")
                .and_then(|_| cx.numbers(q, "polycoef", 5));
            let (Some(a), Some(b)) = (a, b) else {
                return;
            };
            let mut keys = vec![
                ("name", quote(&name)),
                ("kind", quote("coupling")),
                ("a", quote(&a)),
            ];
            // MuJoCo's `a = c0 + c1 b + … + c4 b⁴`; without `b` (or with c1..c4 zero), `a = c0`.
            let c: Vec<(String, f64)> =
                coef.unwrap_or_else(|| vec![("0".to_string(), 0.0), ("1".to_string(), 1.0)]);
            let degree = c.iter().rposition(|x| x.1 != 0.0).unwrap_or(0);
            let offset = (c[0].1 != 0.0).then(|| ("offset", number(&c[0].0, c[0].1)));
            match b {
                Some(b) if degree > 0 => {
                    keys.push(("b", quote(&b)));
                    if degree == 1 {
                        if q.attribute("polycoef").is_some() {
                            keys.push(("ratio", number(&c[1].0, c[1].1)));
                            keys.push(("offset", number(&c[0].0, c[0].1)));
                        }
                    } else {
                        let poly: Vec<String> =
                            c[..=degree].iter().map(|x| number(&x.0, x.1)).collect();
                        keys.push(("poly", format!("[{}]", poly.join(", "))));
                    }
                }
                _ => keys.extend(offset),
            }
            keys
        }
        other => {
            cx.error(
                &cx.tag(q),
                format!("`<{other}>` equalities are not supported"),
                "",
                "connect, weld, joint and tendon are",
            );
            return;
        }
    };
    out.loops.push(LoopOut { keys, origin });
}

/// A joint equality's side: the joint's coordinate counted from `qpos0` (`"q"`, `"q - ref"`).
fn joint_side(
    cx: &mut Cx<'_>,
    q: Node<'_, '_>,
    key: &str,
    j: &str,
    ctx: &Ctx<'_, '_>,
) -> Option<String> {
    match ctx.joints.get(j) {
        Some((_, "hinge" | "slide", shifted)) => Some(shifted.clone()),
        Some(_) => {
            let in_tendon = q
                .parent_element()
                .is_some_and(|p| p.tag_name().name() == "fixed");
            let help = if in_tendon {
                "a fixed tendon's joints are hinge and slide joints (MuJoCo's too)"
            } else {
                "a joint equality couples hinge and slide joints"
            };
            cx.error(
                &cx.attr_range(q, key),
                format!("joint `{j}` is a ball joint"),
                "",
                help,
            );
            None
        }
        None => {
            cx.error(
                &cx.attr_range(q, key),
                format!("unknown joint `{j}`"),
                "no `<joint>` of this name",
                "",
            );
            None
        }
    }
}

/// A tendon equality's side: a fixed tendon's length minus its length at `qpos0`,
/// `Σ coef (q - ref)` over its joints. A spatial tendon is refused: its length is a path's.
fn tendon_side(
    cx: &mut Cx<'_>,
    q: Node<'_, '_>,
    key: &str,
    t: &str,
    ctx: &Ctx<'_, '_>,
) -> Option<String> {
    let Some(&node) = ctx.tendons.get(t) else {
        cx.error(
            &cx.attr_range(q, key),
            format!("unknown tendon `{t}`"),
            "no `<tendon>` element of this name",
            "",
        );
        return None;
    };
    if node.tag_name().name() != "fixed" {
        cx.error(
            &cx.attr_range(q, key),
            format!("tendon `{t}` is a spatial tendon"),
            "only fixed tendons can be coupled",
            "a spatial tendon's length is the length of a path through its sites and around its \
             wrapping geoms, which no expression of the coordinates writes; a fixed tendon's, \
             Σ coef q, is one",
        );
        return None;
    }
    let mut text = String::new();
    let mut ok = true;
    for jn in kids(ctx, node)
        .into_iter()
        .filter(|c| c.tag_name().name() == "joint")
    {
        let (Some(j), Some(coef)) = (
            cx.required(jn, "joint"),
            cx.required(jn, "coef")
                .and_then(|_| cx.numbers(jn, "coef", 1)),
        ) else {
            ok = false;
            continue;
        };
        let Some(mut shifted) = joint_side(cx, jn, "joint", j, ctx) else {
            ok = false;
            continue;
        };
        if shifted.contains(' ') {
            shifted = format!("({shifted})");
        }
        let (ct, cv) = &coef[0];
        let negative = *cv < 0.0;
        let magnitude = number(ct.strip_prefix('-').unwrap_or(ct), cv.abs());
        let term = if cv.abs() == 1.0 {
            shifted
        } else {
            format!("{magnitude} * {shifted}")
        };
        text = match (text.is_empty(), negative) {
            (true, false) => term,
            (true, true) => format!("-{term}"),
            (false, false) => format!("{text} + {term}"),
            (false, true) => format!("{text} - {term}"),
        };
    }
    if ok && text.is_empty() {
        cx.error(
            &cx.tag(node),
            format!("tendon `{t}` has no joints"),
            "an empty fixed tendon",
            "a fixed tendon's length is Σ coef q over its `<joint joint coef>` elements",
        );
        return None;
    }
    ok.then_some(text)
}

fn actuator(cx: &mut Cx<'_>, m: Node<'_, '_>, ctx: &Ctx<'_, '_>, out: &mut Imported) {
    let Some(j) = m.attribute("joint") else {
        // A tendon, site or body transmission: an input rbss cannot apply. The mechanism's
        // dynamics are the same without it; only its force is not among the inputs `U`.
        let via = ["tendon", "site", "body", "jointinparent", "cranksite"]
            .into_iter()
            .find(|a| m.attribute(*a).is_some())
            .unwrap_or("no joint");
        cx.warn(
            &cx.tag(m),
            format!(
                "actuator{} is skipped: its transmission is `{via}`, not `joint`",
                m.attribute("name")
                    .map(|n| format!(" `{n}`"))
                    .unwrap_or_default()
            ),
            "skipped",
            "only joint transmissions become inputs `U`; the model file's `[robot] actuated` can name the coordinates to drive",
        );
        return;
    };
    match ctx.joints.get(j) {
        Some((c, "hinge" | "slide", _)) => {
            // MuJoCo's force on the joint is gear * ctrl, rbss's with `gear`: the same.
            if let Some(n) = lookup(cx, ctx, m, None, "gear")
                && let Some(g) = cx.numbers(n, "gear", 0)
                && let Some((text, value)) = g.first().filter(|x| x.1 != 1.0)
            {
                if *value == 0.0 {
                    cx.error(
                        &cx.attr_range(n, "gear"),
                        "a gear ratio of 0",
                        "the actuator would exert no force",
                        "a nonzero ratio",
                    );
                } else if let Some(coord) = out.coordinates.iter_mut().find(|k| k.name == c[0]) {
                    coord.gear = Some(number(text, *value));
                }
            }
            if !out.actuated.contains(&c[0]) {
                out.actuated.push(c[0].clone());
            }
        }
        Some(_) => cx.error(
            &cx.attr_range(m, "joint"),
            format!("joint `{j}` is a ball joint"),
            "",
            "actuate hinge and slide joints",
        ),
        None => cx.error(
            &cx.attr_range(m, "joint"),
            format!("unknown joint `{j}`"),
            "no `<joint>` of this name",
            "",
        ),
    }
}
