//! URDF -> [`Imported`].
//!
//! | URDF | rbss |
//! |---|---|
//! | `<link>` | a `[[body]]` (the root link is the world: it is fixed) |
//! | `<joint type="revolute\|continuous\|prismatic">` | a coordinate (`rad`, `m`) and the child's steps: `origin` as a `pose`, then the joint about its `axis` |
//! | `<joint type="fixed">` | the child's steps: the `origin` only |
//! | `<joint type="floating">` | a free joint: 7 coordinates `NAME_x`, `_y`, `_z` (m), `NAME_qw`, `_qx`, `_qy`, `_qz` (the quaternion, its unit norm a constraint), not actuated; the child's steps: `origin`, then `{ free = [...] }` |
//! | `<joint type="planar">` | three coordinates `NAME_x`, `NAME_y` (m), `NAME_theta` (rad), not actuated; the child's steps: `origin`, then `Tx Ty Rz` in the plane normal to `axis` |
//! | `<inertial>` | `mass`, `com` (= `origin xyz`), `inertia` (turned by `origin rpy` into the link's axes) |
//! | `<dynamics damping>` | the coordinate's `damping` (`friction` is ignored, with a warning) |
//! | `<mimic joint multiplier offset>` | a `coupling` loop |
//! | `<limit>`, `<visual>`, `<collision>`, `<transmission>`, `<gazebo>` | ignored |
//!
//! URDF is a tree: loops are written in the model file that names the URDF.

use std::collections::HashMap;

use roxmltree::{Document, Node};

use super::xml::{Cx, child, children, element};
use super::{
    BodyOut, Coord, Imported, LoopOut, Origin, fnum, geom, ident, joint_steps, nonzero_list,
    number, pose_step, quote, unit,
};

pub(super) fn import(cx: &mut Cx<'_>, doc: &Document<'_>) -> Option<Imported> {
    let root = doc.root_element();
    if root.tag_name().name() != "robot" {
        cx.error(
            &cx.tag(root),
            format!(
                "a URDF file's root element is `<robot>`, not `<{}>`",
                root.tag_name().name()
            ),
            "expected `<robot>`",
            "",
        );
        return None;
    }
    let mut out = Imported {
        name: ident(&root.attribute("name").unwrap_or("robot").to_lowercase()),
        gravity: ["0".into(), "0".into(), "-9.81".into()],
        root: Some(cx.place(root)),
        ..Imported::default()
    };
    out.description = format!("imported from {}", cx.path);

    let tree = tree(cx, root)?;
    coordinates(cx, &tree.joints, &mut out);
    bodies(cx, root, &tree, &mut out);
    Some(out)
}

/// The links and joints of a URDF, checked to form one tree.
struct Tree<'a, 'i> {
    /// The links by name, and their names in file order.
    links: HashMap<&'a str, Node<'a, 'i>>,
    link_order: Vec<&'a str>,
    joints: Vec<Node<'a, 'i>>,
    /// Each link's parent joint (every link but the root has one).
    parent_joint: HashMap<&'a str, Node<'a, 'i>>,
    /// The root link: the world.
    base: &'a str,
}

/// The links by name and the joints, their parents and children checked: `None` (the errors
/// reported) unless they form one tree.
fn tree<'a, 'i>(cx: &mut Cx<'_>, root: Node<'a, 'i>) -> Option<Tree<'a, 'i>> {
    // Links by name.
    let mut links: HashMap<&str, Node<'_, '_>> = HashMap::new();
    let mut link_order = Vec::new();
    for l in children(root, "link") {
        let Some(name) = cx.required(l, "name") else {
            continue;
        };
        if links.insert(name, l).is_some() {
            cx.error(
                &cx.attr_range(l, "name"),
                format!("link `{name}` is defined twice"),
                "second definition",
                "",
            );
        }
        link_order.push(name);
    }
    // Joints: child -> joint; check parents and children.
    let joints: Vec<Node<'_, '_>> = children(root, "joint").collect();
    let mut parent_joint: HashMap<&str, Node<'_, '_>> = HashMap::new();
    let mut ok = true;
    for &j in &joints {
        let (Some(_), Some(kind)) = (cx.required(j, "name"), cx.required(j, "type")) else {
            ok = false;
            continue;
        };
        match kind {
            "revolute" | "continuous" | "prismatic" | "fixed" | "floating" | "planar" => {}
            other => {
                cx.error(
                    &cx.attr_range(j, "type"),
                    format!("unknown joint type `{other}`"),
                    "expected revolute, continuous, prismatic, fixed, floating or planar",
                    "",
                );
                ok = false;
            }
        }
        for end in ["parent", "child"] {
            let Some(e) = child(j, end) else {
                cx.error(
                    &cx.tag(j),
                    format!("joint has no `<{end}>`"),
                    &format!("`<{end} link=\"...\"/>` missing"),
                    "",
                );
                ok = false;
                continue;
            };
            let Some(link) = cx.required(e, "link") else {
                ok = false;
                continue;
            };
            if !links.contains_key(link) {
                cx.error(
                    &cx.attr_range(e, "link"),
                    format!("unknown link `{link}`"),
                    "no `<link>` of this name",
                    "",
                );
                ok = false;
            } else if end == "child" && parent_joint.insert(link, j).is_some() {
                cx.error(
                    &cx.attr_range(e, "link"),
                    format!("link `{link}` is the child of two joints"),
                    "second parent",
                    "URDF is a tree: close the loop in the model file (`[[loop]]`) instead",
                );
                ok = false;
            }
        }
    }
    if !ok {
        return None;
    }
    let roots: Vec<&str> = link_order
        .iter()
        .copied()
        .filter(|l| !parent_joint.contains_key(l))
        .collect();
    if roots.len() != 1 {
        let at = roots
            .get(1)
            .map_or_else(|| cx.tag(root), |l| cx.attr_range(links[l], "name"));
        cx.error(
            &at,
            format!(
                "the URDF has {} root links ({}), not one",
                roots.len(),
                roots.join(", ")
            ),
            "",
            "every link but the root is the child of one joint",
        );
        return None;
    }

    Some(Tree {
        base: roots[0],
        links,
        link_order,
        joints,
        parent_joint,
    })
}

/// The coordinates, in the file's joint order (a `<mimic>` joint's as a `coupling` loop, the
/// others actuated).
fn coordinates(cx: &mut Cx<'_>, joints: &[Node<'_, '_>], out: &mut Imported) {
    for &j in joints {
        let kind = j.attribute("type").unwrap_or("");
        if kind == "fixed" {
            continue;
        }
        let name = cx.joint_name(j.attribute("name").unwrap_or(""));
        if kind == "floating" {
            let origin = cx.origin(j);
            out.coordinates.extend(super::free_joint(&name, &origin).0);
            continue;
        }
        if kind == "planar" {
            // Three coordinates, not actuated (a base moving in a plane, as `floating`).
            for (part, unit) in PLANAR {
                out.coordinates.push(Coord {
                    name: format!("{name}_{part}"),
                    unit,
                    origin: cx.origin(j),
                    ..Coord::default()
                });
            }
            continue;
        }
        let mut c = Coord {
            name: name.clone(),
            unit: if kind == "prismatic" { "m" } else { "rad" },
            origin: cx.origin(j),
            ..Coord::default()
        };
        if let Some(d) = child(j, "dynamics") {
            if let Some((t, v)) = d
                .attribute_node("damping")
                .and_then(|_| cx.number(d, "damping"))
            {
                c.damping = Some(number(&t, v));
            }
            if d.attribute("friction")
                .is_some_and(|f| f.trim().parse::<f64>().is_ok_and(|v| v != 0.0))
            {
                cx.warn(
                    &cx.attr_range(d, "friction"),
                    "joint friction is ignored",
                    "not in the model",
                    "the model language has viscous damping only",
                );
            }
        }
        if let Some(m) = child(j, "mimic") {
            if let Some(of) = cx.required(m, "joint") {
                let ratio = m
                    .attribute_node("multiplier")
                    .and_then(|_| cx.number(m, "multiplier"));
                let offset = m
                    .attribute_node("offset")
                    .and_then(|_| cx.number(m, "offset"));
                if !joints.iter().any(|o| {
                    o.attribute("name") == Some(of) && o.attribute("type") != Some("fixed")
                }) {
                    cx.error(
                        &cx.attr_range(m, "joint"),
                        format!("`{of}` is no moving joint"),
                        "mimicked joint",
                        "",
                    );
                }
                let mut keys = vec![
                    ("name", quote(&format!("mimic_{name}"))),
                    ("kind", quote("coupling")),
                    ("a", quote(&name)),
                    ("b", quote(&cx.joint_name(of))),
                ];
                if let Some((t, v)) = ratio {
                    keys.push(("ratio", number(&t, v)));
                }
                if let Some((t, v)) = offset {
                    keys.push(("offset", number(&t, v)));
                }
                out.loops.push(LoopOut {
                    keys,
                    origin: Origin {
                        element: "<mimic>".into(),
                        ..cx.origin(m)
                    },
                });
            }
        } else {
            out.actuated.push(name.clone());
        }
        out.coordinates.push(c);
    }
}

/// The bodies, parents before children (depth first from the root, children in file order).
fn bodies(cx: &mut Cx<'_>, root: Node<'_, '_>, tree: &Tree<'_, '_>, out: &mut Imported) {
    let Tree {
        links,
        link_order,
        joints,
        parent_joint,
        base,
    } = tree;
    let base = *base;
    let mut stack = vec![base];
    let mut kids: HashMap<&str, Vec<&str>> = HashMap::new();
    for &j in joints {
        let p = child(j, "parent")
            .and_then(|e| e.attribute("link"))
            .unwrap_or("");
        let c = child(j, "child")
            .and_then(|e| e.attribute("link"))
            .unwrap_or("");
        kids.entry(p).or_default().push(c);
    }
    let name_of = |cx: &mut Cx<'_>, l: &str| {
        if l == base {
            "world".to_string()
        } else {
            cx.body_name(l)
        }
    };
    let mut seen = 0usize;
    while let Some(l) = stack.pop() {
        seen += 1;
        if let Some(ks) = kids.get(l) {
            stack.extend(ks.iter().rev());
        }
        if l == base {
            if links[l]
                .children()
                .any(|c| c.is_element() && c.tag_name().name() == "inertial")
            {
                out.notes.push(format!(
                    "the root link `{base}` is the world (fixed): its inertial is not used"
                ));
            }
            continue;
        }
        let j = parent_joint[l];
        let parent = child(j, "parent")
            .and_then(|e| e.attribute("link"))
            .unwrap_or("");
        let mut transforms = Vec::new();
        if let Some(o) = child(j, "origin") {
            let xyz = o
                .attribute_node("xyz")
                .and_then(|_| cx.numbers(o, "xyz", 3));
            let rpy = o
                .attribute_node("rpy")
                .and_then(|_| cx.numbers(o, "rpy", 3));
            let rot = rpy
                .as_deref()
                .and_then(nonzero_list)
                .map(|r| format!("rpy = [{r}]"));
            transforms.extend(pose_step(xyz.as_deref().and_then(nonzero_list), rot));
        }
        let kind = j.attribute("type").unwrap_or("");
        if kind == "floating" {
            let name = cx.joint_name(j.attribute("name").unwrap_or(""));
            transforms.push(super::free_joint(&name, &Origin::default()).1);
        } else if kind != "fixed"
            && let Some(axis) = joint_axis(cx, j)
        {
            let q = cx.joint_name(j.attribute("name").unwrap_or(""));
            transforms.extend(match kind {
                "planar" => planar_steps(&q, axis),
                "prismatic" => joint_steps("prismatic", &q, axis),
                _ => joint_steps("revolute", &q, axis),
            });
        }
        if transforms.is_empty() {
            transforms.push(quote("Tz(0)"));
        }
        let mass = child(links[l], "inertial").and_then(|i| inertial(cx, i));
        // Errors of the body's keys at the elements they come from: the steps and the parent
        // at the joint, the mass properties at `<mass>`, `<origin>`, `<inertia>`.
        let mut places = vec![("transforms", cx.place(j))];
        if let Some(p) = child(j, "parent") {
            places.push(("parent", cx.place(p)));
        }
        if let Some(i) = child(links[l], "inertial") {
            for (key, tag) in [("mass", "mass"), ("com", "origin"), ("inertia", "inertia")] {
                places.push((key, cx.place(child(i, tag).unwrap_or(i))));
            }
        }
        out.bodies.push(BodyOut {
            name: cx.body_name(l),
            parent: name_of(cx, parent),
            transforms,
            mass,
            origin: Origin {
                element: format!("{} {}", element(links[l]), element(j)),
                at: cx.at(j),
                place: Some(cx.place(links[l])),
            },
            places,
        });
    }
    if seen != link_order.len() {
        // A cycle through the root's descendants cannot be, but stay total.
        cx.error(&cx.tag(root), "the links do not form one tree", "", "");
    }
}

/// `mass`, `com`, `inertia` of an `<inertial>`; `None` when the mass is zero or absent.
fn inertial(cx: &mut Cx<'_>, i: Node<'_, '_>) -> Option<(String, [String; 3], [String; 6])> {
    let m = child(i, "mass")?;
    let (mt, mv) = cx.number(m, "value")?;
    let negative = mv < 0.0;
    if negative {
        cx.error(
            &cx.attr_range(m, "value"),
            "negative mass",
            "must be >= 0",
            "",
        );
    }
    let zero = || "0".to_string();
    let mut com = [zero(), zero(), zero()];
    let mut rot = None;
    if let Some(o) = child(i, "origin") {
        if let Some(xyz) = o
            .attribute_node("xyz")
            .and_then(|_| cx.numbers(o, "xyz", 3))
        {
            com = [0, 1, 2].map(|k| number(&xyz[k].0, xyz[k].1));
        }
        if let Some(r) = o
            .attribute_node("rpy")
            .and_then(|_| cx.numbers(o, "rpy", 3))
            && r.iter().any(|(_, v)| *v != 0.0)
        {
            rot = Some(geom::rpy(r[0].1, r[1].1, r[2].1));
        }
    }
    let keys = ["ixx", "iyy", "izz", "ixy", "ixz", "iyz"];
    let entries: [(String, f64); 6] = match child(i, "inertia") {
        Some(n) => {
            let mut e = Vec::new();
            for k in keys {
                e.push(if n.attribute(k).is_some() {
                    cx.number(n, k)?
                } else {
                    ("0".into(), 0.0)
                });
            }
            e.try_into().ok()?
        }
        None => keys.map(|_| ("0".to_string(), 0.0)),
    };
    let inertia = match rot {
        None => entries.clone().map(|(t, v)| number(&t, v)),
        Some(r) => {
            let turned =
                geom::rotate_inertia(&r, &geom::inertia_matrix(entries.clone().map(|(_, v)| v)));
            geom::inertia_entries(&turned).map(super::fnum)
        }
    };
    if negative || (mv == 0.0 && entries.iter().all(|(_, v)| *v == 0.0)) {
        return None;
    }
    Some((number(&mt, mv), com, inertia))
}

/// A planar joint's coordinates: `NAME_x`, `NAME_y` (m) and `NAME_theta` (rad).
const PLANAR: [(&str, &str); 3] = [("x", "m"), ("y", "m"), ("theta", "rad")];

/// The steps of a planar joint `name` whose plane is normal to the unit `axis` (of the frame
/// reached so far): `Tx(NAME_x) Ty(NAME_y) Rz(NAME_theta)` in a frame whose z is the axis (the
/// joint's own frame when the axis is z; else the turn taking z onto the axis, the steps, and
/// that turn undone, so the plane's x and y are the turned frame's).
fn planar_steps(name: &str, axis: [f64; 3]) -> Vec<String> {
    let [x, y, t] = PLANAR.map(|(p, _)| quote(&format!("{name}_{p}")));
    let steps = [
        format!("{{ prismatic = {x}, axis = \"x\" }}"),
        format!("{{ prismatic = {y}, axis = \"y\" }}"),
        format!("{{ revolute = {t} }}"),
    ];
    if axis == [0.0, 0.0, 1.0] {
        return steps.to_vec();
    }
    let turn = geom::z_onto(axis);
    let aa = format!("{{ axis_angle = [{}] }}", turn.map(fnum).join(", "));
    let mut out = vec![aa.clone()];
    out.extend(steps);
    out.push(format!("{{ inverse = [{aa}] }}"));
    out
}

/// A moving joint's unit axis: `<axis xyz>` (URDF's default `1 0 0` without `<axis>`); `None`
/// after an error (a zero axis) or when `xyz` could not be read (reported where it was read).
fn joint_axis(cx: &mut Cx<'_>, j: Node<'_, '_>) -> Option<[f64; 3]> {
    let axis = match child(j, "axis") {
        Some(a) => a
            .attribute_node("xyz")
            .and_then(|_| cx.numbers(a, "xyz", 3))
            .map(|v| [v[0].1, v[1].1, v[2].1]),
        None => Some([1.0, 0.0, 0.0]),
    };
    let unit_axis = axis.and_then(unit);
    if unit_axis.is_none() && axis.is_some() {
        let a = child(j, "axis").unwrap_or(j);
        cx.error(
            &cx.attr_range(a, "xyz"),
            "the joint's axis is zero",
            "no direction",
            "",
        );
    }
    unit_axis
}
