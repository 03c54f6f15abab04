//! Mesh files (STL binary and ASCII, OBJ) and the mass properties MuJoCo's compiler gives a
//! mesh: its volume (or area), centre of mass and inertia, by the divergence theorem over the
//! triangles (each triangle and a common apex a tetrahedron), for the mesh's `inertia` mode
//! (`convex`: the convex hull's; `exact`: signed; `legacy`: every tetrahedron counted positive,
//! MuJoCo's default; `shell`: the mass on the surface).
//!
//! The arithmetic follows MuJoCo's (`user_mesh.cc`): vertices are single precision (rounded
//! after reading and after each of `refpos`, `refquat`, `scale`), the apex of the volume is the
//! area-weighted centroid of the faces, the apex of the inertia the centre of mass found with
//! it. Files are untrusted: size-limited ([`super::MAX_BYTES`]), every malformed input an error
//! (a message; the caller locates it), never a panic.

use std::collections::HashMap;
use std::path::Path;

use super::geom::{self, Mat};

/// A mesh's `inertia` attribute.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Inertia {
    Convex,
    Exact,
    Legacy,
    Shell,
}

impl Inertia {
    pub(crate) fn from_key(k: &str) -> Option<Inertia> {
        match k {
            "convex" => Some(Inertia::Convex),
            "exact" => Some(Inertia::Exact),
            "legacy" => Some(Inertia::Legacy),
            "shell" => Some(Inertia::Shell),
            _ => None,
        }
    }
}

/// Vertices and triangles (indices into the vertices).
#[derive(Debug, Clone, Default)]
pub(crate) struct Mesh {
    pub(crate) verts: Vec<[f64; 3]>,
    pub(crate) faces: Vec<[usize; 3]>,
}

/// What a mesh weighs per unit density: `volume` (the area for `shell`), the centre of mass and
/// the inertia about it, in the mesh's (scaled) coordinates.
#[derive(Debug, Clone, Copy)]
pub(crate) struct MassProps {
    pub(crate) volume: f64,
    pub(crate) com: [f64; 3],
    pub(crate) inertia: Mat,
}

/// MuJoCo's `mjMINVAL`.
const MINVAL: f64 = 1e-15;

fn f32r(v: f64) -> f64 {
    v as f32 as f64
}

/// The mesh of a file, by its extension (`.stl`, `.obj`, any case).
pub(crate) fn read_file(path: &Path) -> Result<Mesh, String> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    if ext != "stl" && ext != "obj" {
        return Err(format!(
            "mesh files are STL or OBJ, not `{}`",
            path.file_name()
                .map(|f| f.to_string_lossy().into_owned())
                .unwrap_or_default()
        ));
    }
    let meta = std::fs::metadata(path).map_err(|e| format!("cannot read it: {e}"))?;
    if meta.len() > super::MAX_BYTES as u64 {
        return Err(format!(
            "it is {} bytes, more than the {} bytes a mesh file may have",
            meta.len(),
            super::MAX_BYTES
        ));
    }
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read it: {e}"))?;
    if ext == "stl" {
        parse_stl(&bytes)
    } else {
        let text = std::str::from_utf8(&bytes).map_err(|_| "an OBJ file is text (UTF-8)")?;
        parse_obj(text)
    }
}

/// Binary STL (80-byte header, a count, 50 bytes a triangle, exactly) or ASCII STL (`solid`,
/// `facet`/`vertex` lines). Repeated vertices are merged (as MuJoCo does), so that faces share
/// edges.
pub(crate) fn parse_stl(bytes: &[u8]) -> Result<Mesh, String> {
    let binary_count = (bytes.len() >= 84)
        .then(|| u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize);
    let mut tris: Vec<[[f64; 3]; 3]> = Vec::new();
    if let Some(n) = binary_count
        .filter(|n| n.checked_mul(50).and_then(|b| b.checked_add(84)) == Some(bytes.len()))
    {
        let f = |o: usize| {
            f32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]) as f64
        };
        for t in 0..n {
            let o = 84 + 50 * t + 12;
            let v = [0, 1, 2].map(|k| [0, 1, 2].map(|c| f(o + 12 * k + 4 * c)));
            if v.iter().flatten().any(|x| !x.is_finite()) {
                return Err(format!(
                    "triangle {} has a coordinate that is not finite",
                    t + 1
                ));
            }
            tris.push(v);
        }
    } else {
        let text = std::str::from_utf8(bytes)
            .ok()
            .filter(|t| t.trim_start().starts_with("solid"));
        let Some(text) = text else {
            return Err(match binary_count {
                Some(n) => format!(
                    "not an STL file: a binary STL of {n} triangles has {} bytes, this one {}, and it is not ASCII STL (`solid ...`)",
                    84u128 + 50 * n as u128,
                    bytes.len()
                ),
                None => format!(
                    "not an STL file: {} bytes, and not ASCII STL (`solid ...`)",
                    bytes.len()
                ),
            });
        };
        let mut cur: Vec<[f64; 3]> = Vec::new();
        for (k, line) in text.lines().enumerate() {
            let mut w = line.split_ascii_whitespace();
            match w.next() {
                Some("vertex") => {
                    let v: Vec<f64> = w.map(|s| s.parse::<f64>().unwrap_or(f64::NAN)).collect();
                    if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
                        return Err(format!(
                            "line {}: `vertex` needs three finite numbers",
                            k + 1
                        ));
                    }
                    cur.push([f32r(v[0]), f32r(v[1]), f32r(v[2])]);
                }
                Some("endloop") => {
                    if cur.len() != 3 {
                        return Err(format!(
                            "line {}: a facet has {} vertices, not 3",
                            k + 1,
                            cur.len()
                        ));
                    }
                    tris.push([cur[0], cur[1], cur[2]]);
                    cur.clear();
                }
                _ => {}
            }
        }
    }
    if tris.is_empty() {
        return Err("the STL file has no triangles".into());
    }
    let mut mesh = Mesh::default();
    let mut index: HashMap<[u64; 3], usize> = HashMap::new();
    for t in &tris {
        let f = t.map(|v| {
            *index.entry(v.map(f64::to_bits)).or_insert_with(|| {
                mesh.verts.push(v);
                mesh.verts.len() - 1
            })
        });
        mesh.faces.push(f);
    }
    Ok(mesh)
}

/// OBJ: `v x y z` vertices and `f` faces (`i`, `i/t`, `i/t/n`, `i//n`, 1-based, negative from
/// the end), polygons cut into a fan of triangles; other lines are ignored.
pub(crate) fn parse_obj(text: &str) -> Result<Mesh, String> {
    let mut mesh = Mesh::default();
    for (k, line) in text.lines().enumerate() {
        let mut w = line.split_ascii_whitespace();
        match w.next() {
            Some("v") => {
                let v: Vec<f64> = w
                    .take(3)
                    .map(|s| s.parse::<f64>().unwrap_or(f64::NAN))
                    .collect();
                if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
                    return Err(format!("line {}: `v` needs three finite numbers", k + 1));
                }
                mesh.verts.push([f32r(v[0]), f32r(v[1]), f32r(v[2])]);
            }
            Some("f") => {
                let mut idx = Vec::new();
                for s in w {
                    let first = s.split('/').next().unwrap_or("");
                    let i: i64 = first
                        .parse()
                        .map_err(|_| format!("line {}: `{s}` is not a vertex index", k + 1))?;
                    let n = mesh.verts.len() as i64;
                    let j = if i > 0 { i - 1 } else { n + i };
                    if i == 0 || j < 0 || j >= n {
                        return Err(format!(
                            "line {}: vertex {i} does not exist ({n} vertices so far)",
                            k + 1
                        ));
                    }
                    idx.push(j as usize);
                }
                if idx.len() < 3 {
                    return Err(format!("line {}: a face has fewer than 3 vertices", k + 1));
                }
                for t in 1..idx.len() - 1 {
                    mesh.faces.push([idx[0], idx[t], idx[t + 1]]);
                }
            }
            _ => {}
        }
    }
    if mesh.verts.is_empty() {
        return Err("the OBJ file has no vertices (`v` lines)".into());
    }
    Ok(mesh)
}

/// The mesh moved by `refpos`, turned by `refquat` (as MuJoCo does: `v ← Rᵀ (v - refpos)`) and
/// scaled, each step rounded to single precision; a scale of negative determinant turns the
/// faces over (MuJoCo's left-handed scaling).
pub(crate) fn transform(mesh: &mut Mesh, refpos: [f64; 3], refquat: [f64; 4], scale: [f64; 3]) {
    if refpos != [0.0; 3] {
        for v in &mut mesh.verts {
            *v = [0, 1, 2].map(|k| f32r(v[k] - refpos[k]));
        }
    }
    if refquat != [1.0, 0.0, 0.0, 0.0] {
        let r = geom::transpose(&geom::quat(refquat));
        for v in &mut mesh.verts {
            *v = geom::apply(&r, *v).map(f32r);
        }
    }
    if scale != [1.0; 3] {
        for v in &mut mesh.verts {
            *v = [0, 1, 2].map(|k| f32r(v[k] * scale[k]));
        }
    }
    if scale[0] * scale[1] * scale[2] < 0.0 {
        for f in &mut mesh.faces {
            f.swap(1, 2);
        }
    }
}

/// MuJoCo's `triangle`: area, unit normal, centroid (area 0 for a face shorter than `MINVAL`).
fn triangle(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> (f64, [f64; 3], [f64; 3]) {
    let center = [0, 1, 2].map(|i| (a[i] + b[i] + c[i]) / 3.0);
    let n = geom::cross(
        [b[0] - a[0], b[1] - a[1], b[2] - a[2]],
        [c[0] - a[0], c[1] - a[1], c[2] - a[2]],
    );
    let len = geom::dot(n, n).sqrt();
    if len < MINVAL {
        return (0.0, n, center);
    }
    (len / 2.0, n.map(|x| x / len), center)
}

/// The mass properties per unit density of `mesh` for `mode` (faces from the convex hull for
/// `convex`, and for a mesh without faces). Errors as MuJoCo's: a surface or volume too small, a
/// negative volume (faces turned inwards), faces of inconsistent orientation (`exact`).
pub(crate) fn mass_properties(mesh: &Mesh, mode: Inertia) -> Result<MassProps, String> {
    let hull;
    let faces: &[[usize; 3]] = if mesh.faces.is_empty() {
        hull = convex_hull(&mesh.verts)?;
        &hull
    } else {
        &mesh.faces
    };
    let v = &mesh.verts;
    if mode == Inertia::Exact {
        // Every directed edge once (a face's edge and its neighbour's run opposite ways).
        let mut edges: Vec<(usize, usize)> = Vec::new();
        for f in faces {
            if triangle(v[f[0]], v[f[1]], v[f[2]]).0 > MINVAL.sqrt() {
                edges.extend([(f[0], f[1]), (f[1], f[2]), (f[2], f[0])]);
            }
        }
        edges.sort_unstable();
        if let Some(w) = edges.windows(2).find(|w| w[0] == w[1]) {
            return Err(format!(
                "its faces have inconsistent orientation (the faces with vertices {} and {}); `exact` needs a consistently oriented surface",
                w[0].0 + 1,
                w[0].1 + 1
            ));
        }
    }
    // The area-weighted centroid of the faces (the apex of the volume's tetrahedra).
    let mut facecen = [0.0; 3];
    let mut area = 0.0;
    for f in faces {
        let (a, _, c) = triangle(v[f[0]], v[f[1]], v[f[2]]);
        for k in 0..3 {
            facecen[k] += a * c[k];
        }
        area += a;
    }
    if area < MINVAL {
        return Err("its surface area is too small".into());
    }
    facecen = facecen.map(|x| x / area);
    let hull_faces;
    let solid: &[[usize; 3]] = if mode == Inertia::Convex && !mesh.faces.is_empty() {
        hull_faces = convex_hull(v)?;
        &hull_faces
    } else {
        faces
    };
    // Centre of mass: each face's pyramid to `facecen` (for `shell`, each face's area).
    let mut com = [0.0; 3];
    let mut total = 0.0;
    let used = if mode == Inertia::Shell { faces } else { solid };
    for f in used {
        let (a, n, c) = triangle(v[f[0]], v[f[1]], v[f[2]]);
        let mut w = if mode == Inertia::Shell {
            a
        } else {
            geom::dot([c[0] - facecen[0], c[1] - facecen[1], c[2] - facecen[2]], n) * a / 3.0
        };
        if mode == Inertia::Legacy {
            w = w.abs();
        }
        total += w;
        for k in 0..3 {
            com[k] += w * (c[k] * 3.0 / 4.0 + facecen[k] / 4.0);
        }
    }
    if total < MINVAL {
        return Err(if mode == Inertia::Shell {
            "its surface area is too small".into()
        } else if total < 0.0 {
            "its volume is negative: the faces are turned inwards (clockwise seen from outside)"
                .into()
        } else {
            "its volume is too small (a flat or open surface); `inertia=\"shell\"` puts the mass on the surface".into()
        });
    }
    com = com.map(|x| x / total);
    // Inertia about the centre of mass: each tetrahedron (face, centre of mass), or each face.
    let pairs = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)];
    let mut p = [0.0; 6];
    let mut volume = 0.0;
    for f in used {
        let [d, e, g] = f.map(|i| [0, 1, 2].map(|k| v[i][k] - com[k]));
        let (a, n, c) = triangle(d, e, g);
        let mut w = if mode == Inertia::Shell {
            a
        } else {
            geom::dot(c, n) * a / 3.0
        };
        if mode == Inertia::Legacy {
            w = w.abs();
        }
        volume += w;
        let cc = if mode == Inertia::Shell { 12.0 } else { 20.0 };
        for (j, &(r, s)) in pairs.iter().enumerate() {
            p[j] += w / cc
                * (2.0 * (d[r] * d[s] + e[r] * e[s] + g[r] * g[s])
                    + d[r] * e[s]
                    + d[s] * e[r]
                    + d[r] * g[s]
                    + d[s] * g[r]
                    + e[r] * g[s]
                    + e[s] * g[r]);
        }
    }
    // An open surface's volume depends on the apex: about the centre of mass it may vanish.
    if volume < MINVAL {
        return Err(format!(
            "its volume about its centre of mass is {volume:e}: the surface is not closed"
        ));
    }
    let inertia =
        geom::inertia_matrix([p[1] + p[2], p[0] + p[2], p[0] + p[1], -p[3], -p[4], -p[5]]);
    Ok(MassProps {
        volume,
        com,
        inertia,
    })
}

/// The convex hull of `pts`: triangles turned outwards (counter-clockwise seen from outside),
/// by an incremental hull (each point outside the current hull replaces the faces it sees by
/// a fan from their horizon). Points within a tolerance of the hull (1e-10 of its size) are
/// inside; an error when the points span no volume.
pub(crate) fn convex_hull(pts: &[[f64; 3]]) -> Result<Vec<[usize; 3]>, String> {
    let flat = || "its points span no volume (fewer than 4 points, or all in a plane)".to_string();
    if pts.len() < 4 {
        return Err(flat());
    }
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in pts {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let size = geom::dot(sub(hi, lo), sub(hi, lo)).sqrt();
    let eps = 1e-10 * size;
    if size.is_nan() || eps <= 0.0 {
        return Err(flat());
    }
    // A first tetrahedron: the two points farthest apart along an axis, the point farthest from
    // their line, the point farthest from their plane.
    let axis = (0..3)
        .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])))
        .unwrap_or(0);
    let i0 = (0..pts.len())
        .min_by(|&a, &b| pts[a][axis].total_cmp(&pts[b][axis]))
        .unwrap_or(0);
    let i1 = (0..pts.len())
        .max_by(|&a, &b| pts[a][axis].total_cmp(&pts[b][axis]))
        .unwrap_or(0);
    let d01 = sub(pts[i1], pts[i0]);
    let line_dist = |i: usize| {
        let c = geom::cross(d01, sub(pts[i], pts[i0]));
        geom::dot(c, c)
    };
    let i2 = (0..pts.len())
        .max_by(|&a, &b| line_dist(a).total_cmp(&line_dist(b)))
        .unwrap_or(0);
    let n012 = geom::cross(d01, sub(pts[i2], pts[i0]));
    let nlen = geom::dot(n012, n012).sqrt();
    if nlen <= eps * geom::dot(d01, d01).sqrt() {
        return Err(flat());
    }
    let plane_dist = |i: usize| geom::dot(n012, sub(pts[i], pts[i0])) / nlen;
    let i3 = (0..pts.len())
        .max_by(|&a, &b| plane_dist(a).abs().total_cmp(&plane_dist(b).abs()))
        .unwrap_or(0);
    if plane_dist(i3).abs() <= eps {
        return Err(flat());
    }
    struct Face {
        v: [usize; 3],
        n: [f64; 3],
        d: f64,
    }
    let make = |v: [usize; 3]| {
        let n = geom::cross(sub(pts[v[1]], pts[v[0]]), sub(pts[v[2]], pts[v[0]]));
        let l = geom::dot(n, n).sqrt();
        let n = if l > 0.0 { n.map(|x| x / l) } else { n };
        Face {
            v,
            n,
            d: geom::dot(n, pts[v[0]]),
        }
    };
    let mut faces: Vec<Face> = if plane_dist(i3) < 0.0 {
        // i3 below the plane (0, 1, 2): that face looks away from it.
        vec![
            make([i0, i1, i2]),
            make([i0, i3, i1]),
            make([i1, i3, i2]),
            make([i2, i3, i0]),
        ]
    } else {
        vec![
            make([i0, i2, i1]),
            make([i0, i1, i3]),
            make([i1, i2, i3]),
            make([i2, i0, i3]),
        ]
    };
    for (i, p) in pts.iter().enumerate() {
        if [i0, i1, i2, i3].contains(&i) {
            continue;
        }
        let visible: Vec<bool> = faces
            .iter()
            .map(|f| geom::dot(f.n, *p) - f.d > eps)
            .collect();
        if !visible.iter().any(|&s| s) {
            continue;
        }
        // The horizon: edges of seen faces whose reverse is not an edge of a seen face.
        let mut seen_edges: HashMap<(usize, usize), ()> = HashMap::new();
        for (f, _) in faces.iter().zip(&visible).filter(|(_, s)| **s) {
            for k in 0..3 {
                seen_edges.insert((f.v[k], f.v[(k + 1) % 3]), ());
            }
        }
        let horizon: Vec<(usize, usize)> = seen_edges
            .keys()
            .filter(|(a, b)| !seen_edges.contains_key(&(*b, *a)))
            .copied()
            .collect();
        let mut kept: Vec<Face> = faces
            .into_iter()
            .zip(visible)
            .filter(|(_, s)| !*s)
            .map(|(f, _)| f)
            .collect();
        for (a, b) in horizon {
            kept.push(make([a, b, i]));
        }
        faces = kept;
    }
    let mut out: Vec<[usize; 3]> = faces.iter().map(|f| f.v).collect();
    out.sort_unstable();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A box of half sizes `h` centred at `c`: 8 corners, 12 triangles turned outwards.
    fn cuboid(h: [f64; 3], c: [f64; 3]) -> Mesh {
        let mut verts = Vec::new();
        for k in 0..8 {
            let s = [k & 1, (k >> 1) & 1, (k >> 2) & 1].map(|b| if b == 1 { 1.0 } else { -1.0 });
            verts.push([0, 1, 2].map(|i| c[i] + s[i] * h[i]));
        }
        // Faces as quads (outward), cut in two.
        let quads = [
            [0, 2, 3, 1], // -z
            [4, 5, 7, 6], // +z
            [0, 1, 5, 4], // -y
            [2, 6, 7, 3], // +y
            [0, 4, 6, 2], // -x
            [1, 3, 7, 5], // +x
        ];
        let mut faces = Vec::new();
        for q in quads {
            faces.push([q[0], q[1], q[2]]);
            faces.push([q[0], q[2], q[3]]);
        }
        Mesh { verts, faces }
    }

    #[test]
    fn a_box_mesh_has_the_box_formula_in_every_solid_mode() {
        let h = [0.5, 0.25, 0.125];
        let m = cuboid(h, [1.0, -2.0, 0.5]);
        let vol = 8.0 * h[0] * h[1] * h[2];
        for mode in [Inertia::Exact, Inertia::Convex, Inertia::Legacy] {
            let p = mass_properties(&m, mode).unwrap();
            assert!((p.volume - vol).abs() < 1e-15, "{mode:?} {}", p.volume);
            for k in 0..3 {
                assert!((p.com[k] - [1.0, -2.0, 0.5][k]).abs() < 1e-15);
            }
            let want = [
                vol * (h[1] * h[1] + h[2] * h[2]) / 3.0,
                vol * (h[0] * h[0] + h[2] * h[2]) / 3.0,
                vol * (h[0] * h[0] + h[1] * h[1]) / 3.0,
            ];
            for (i, wi) in want.iter().enumerate() {
                for j in 0..3 {
                    let w = if i == j { *wi } else { 0.0 };
                    assert!((p.inertia[i][j] - w).abs() < 1e-15, "{mode:?} I[{i}][{j}]");
                }
            }
        }
        // The shell: six rectangles' area and second moments.
        let p = mass_properties(&m, Inertia::Shell).unwrap();
        let [a, b, c] = h;
        let area = 8.0 * (a * b + b * c + a * c);
        assert!((p.volume - area).abs() < 1e-15);
        // ∫x² over the surface: faces ±x (area 4bc, x = a), ±y and ±z (x² mean a²/3).
        let sx = 2.0 * 4.0 * b * c * a * a + 2.0 * (4.0 * a * c + 4.0 * a * b) * a * a / 3.0;
        let sy = 2.0 * 4.0 * a * c * b * b + 2.0 * (4.0 * b * c + 4.0 * a * b) * b * b / 3.0;
        let sz = 2.0 * 4.0 * a * b * c * c + 2.0 * (4.0 * b * c + 4.0 * a * c) * c * c / 3.0;
        let want = [sy + sz, sx + sz, sx + sy];
        for (k, w) in want.iter().enumerate() {
            assert!((p.inertia[k][k] - w).abs() < 1e-14, "{k}");
        }
    }

    #[test]
    fn the_hull_of_a_cube_with_inner_and_edge_points_is_the_cube() {
        let mut pts = cuboid([1.0, 2.0, 3.0], [0.0; 3]).verts;
        // Inner points, points on faces and edges (not hull vertices): ignored.
        pts.extend([
            [0.1, 0.2, 0.3],
            [1.0, 0.0, 0.0],
            [1.0, 2.0, 0.0],
            [-0.5, 0.5, 3.0],
        ]);
        pts.rotate_left(5);
        let faces = convex_hull(&pts).unwrap();
        let m = Mesh {
            verts: pts,
            faces: faces.clone(),
        };
        let p = mass_properties(&m, Inertia::Exact).unwrap();
        assert!((p.volume - 48.0).abs() < 1e-12, "{}", p.volume);
        let f = faces
            .iter()
            .flatten()
            .collect::<std::collections::BTreeSet<_>>();
        assert_eq!(f.len(), 8, "only the corners are hull vertices: {faces:?}");
        assert!(
            convex_hull(&[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]]).is_err()
        );
    }

    #[test]
    fn the_hull_of_points_on_a_sphere_approaches_the_ball() {
        // 2000 points of a Fibonacci sphere: the hull's volume below 4π/3, within 0.5 %.
        let n = 2000;
        let pts: Vec<[f64; 3]> = (0..n)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let r = (1.0 - z * z).sqrt();
                let t = i as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
                [r * t.cos(), r * t.sin(), z]
            })
            .collect();
        let faces = convex_hull(&pts).unwrap();
        let p = mass_properties(&Mesh { verts: pts, faces }, Inertia::Exact).unwrap();
        let ball = 4.0 * std::f64::consts::PI / 3.0;
        assert!(p.volume < ball && p.volume > 0.995 * ball, "{}", p.volume);
    }

    #[test]
    fn malformed_files_are_errors() {
        assert!(parse_stl(b"").is_err());
        assert!(parse_stl(&[0u8; 90]).is_err());
        let mut b = vec![0u8; 84];
        b[80] = 1;
        assert!(parse_stl(&b).is_err(), "one triangle announced, none there");
        assert!(
            parse_stl(b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0\nendloop\n").is_err()
        );
        assert!(parse_obj("v 0 0 0\nf 1 2 3\n").is_err());
        assert!(parse_obj("v 0 0 nan\n").is_err());
        assert!(parse_obj("# nothing\n").is_err());
        assert!(parse_obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -1\nf 1 2 0\n").is_err());
    }
}
