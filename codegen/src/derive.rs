//! The derivation with named intermediates: frames, loop closure `f(X)`, `G = ∂f/∂X`,
//! `gamma`, and the dynamics `M`, `psi`, `T`, `Pi`, as nodes of one [`Graph`].
//!
//! Each body's frame is built recursively from its parent's and its own elementary transforms
//! (`R' = R E`, `p' = p + R s e`), and so are its body-frame angular velocity and origin
//! velocity (`omega' = Eᵀ omega + theta_dot e`, `v' = Eᵀ v` for a rotation; `v' = v + omega × s e
//! + s_dot e` for a translation). Nothing is expanded: every quantity is a node that the
//! kernels compute once, named after its body (`rot_leg1_lower_01`, `omega_platform_z`, ...).
//!
//! - `f` is the difference of the loop points' world positions; `G = ∂f/∂X` by the chain rule
//!   through the graph; `gamma = -d²f/dt²` at `Xddot = 0` (`= -(dG/dt) Xdot`), row by row the
//!   cheapest of three ways (the fused dynamics kernel chooses again beside `M` and `psi`: the
//!   loop points' accelerations through the bodies' velocities share the work with `psi`).
//! - The dynamics are Lagrange's equations of `T = Σ ½ m |v_c|² + ½ omegaᵀ I omega`, written
//!   per body: `M = Σ m J_cᵀ J_c + J_wᵀ I J_w` with `J_c = ∂v_c/∂Xdot`, `J_w = ∂omega/∂Xdot`
//!   (exactly `∂²T/∂Xdot²`), and `psi = -Σ J_cᵀ F0 + J_wᵀ tau0` with
//!   `F0 = m (a0_c - g)`, `tau0 = I alpha0 + omega × I omega`, `a0_c`, `alpha0` the centre-of-mass
//!   and angular accelerations at `Xddot = 0` (all in body axes). This is `-(Christoffel terms)
//!   - ∂Pi/∂X` of the paper's eq. 21: `d/dt ∂T/∂Xdot - ∂T/∂X` evaluated body by body.
//! - The same `M` and `psi` recursively, twice: in world axes (`derive/world.rs`) and in each
//!   joint's own frame (`derive/local.rs`, Featherstone's composite-rigid-body and Newton-Euler
//!   algorithms over the elementary steps); the cheapest of the three forms, then entry by entry
//!   another where cheaper; then `M`, `psi`, `T`, `Pi` re-simplified algebraically
//!   ([`crate::simplify`]: local expansion, `sin² + cos² = 1`, Horner).

// Matrix algebra over index triples reads best with explicit indices.
#![allow(clippy::needless_range_loop)]

use std::collections::BTreeMap;

use crate::graph::{Graph, Id, Seed};
use crate::model::{Attachment, Axis, Expr, LoopKind, Model, Step};

mod closure;
mod derivatives;
mod local;
mod steps;
mod terms;
mod world;

pub use derivatives::{DynamicsDerivatives, dynamics_derivatives};
use world::{Spatial, recursive};

/// World frame of a body: rotation (row-major) and origin, as graph nodes.
#[derive(Clone, Copy)]
pub struct Frame {
    pub r: [[Id; 3]; 3],
    pub p: [Id; 3],
}

/// The symbolic results for one model.
pub struct Derivation {
    pub graph: Graph,
    pub n: usize,
    pub m: usize,
    /// Constraint names, `loop.axis`.
    pub constraint_names: Vec<String>,
    /// `f(X)`, length m.
    pub f: Vec<Id>,
    /// `G = ∂f/∂X`, row-major `g[i][j]`; [`Graph::ZERO`] is a structural zero.
    pub g: Vec<Vec<Id>>,
    /// The loop components a loop's `components` leave out that still depend on `X`
    /// (`origin(a) - origin(b)` along those world axes): not solved, but zero wherever the two
    /// points coincide, so the solvers' certificate checks them (the mirror roots of a loop
    /// written with fewer components, such as the UR5's tool axes).
    pub checks: Vec<Id>,
    /// Their names, `loop.axis`.
    pub check_names: Vec<String>,
    /// `gamma = -(dG/dt) Xdot`, length m.
    pub gamma: Vec<Id>,
    /// Passive coordinates (not actuated), ascending.
    pub passive: Vec<usize>,
    /// Independent IK blocks: (rows, cols).
    pub ik_blocks: Vec<(Vec<usize>, Vec<usize>)>,
    /// World frames of every body.
    pub frames: Vec<Frame>,
    /// The dynamics, when requested.
    pub dynamics: Option<Dynamics>,
}

/// The dynamics: `M(X)`, `psi(X, Xdot)`, the energies.
pub struct Dynamics {
    /// `M = ∂²T/∂Xdot²` (n × n, symmetric).
    pub mass: Vec<Vec<Id>>,
    /// `psi = -(Christoffel terms) - ∂Pi/∂X - damping Xdot` (n): gravity, the joints' springs
    /// (in `Pi`) and dampers.
    pub psi: Vec<Id>,
    /// Kinetic energy `T(X, Xdot)`, from the bodies' velocities (not from `M`) and the joints'
    /// armatures.
    pub kinetic: Id,
    /// Potential energy `Pi(X)` of gravity and the joints' springs.
    pub potential: Id,
    /// Diagonal blocks of `M`: groups of coordinates coupled by inertia (ascending).
    pub mass_blocks: Vec<Vec<usize>>,
    /// `gamma` as the fused kernel computes it: the same values as [`Derivation::gamma`], each
    /// row the way that is cheapest beside `M` and `psi` (often through the bodies'
    /// accelerations, which `psi` computes anyway).
    pub gamma: Vec<Id>,
}

/// An error found during derivation (the model parses but is not well posed).
#[derive(Debug, Clone)]
pub struct DeriveError {
    pub pos: crate::model::Pos,
    pub message: String,
}

/// A model expression as a graph node. Parameter `j` is the leaf `p[j]`, or, when
/// `frozen[j]`, its value's expression (so that it folds into the kernels).
pub fn expr(g: &mut Graph, e: &Expr, model: &Model, frozen: &[bool]) -> Id {
    match e {
        Expr::Num { num, den } => match crate::graph::Rat::new(*num, *den) {
            Some(r) => g.num(r),
            None => g.float(f64::NAN),
        },
        Expr::Pi => g.pi(),
        Expr::Param(j) => {
            if frozen[*j] {
                expr(g, &model.parameters[*j].expr, model, frozen)
            } else {
                g.p(*j)
            }
        }
        Expr::Coord(i) => g.x(*i),
        Expr::Neg(a) => {
            let a = expr(g, a, model, frozen);
            g.neg(a)
        }
        Expr::Add(a, b) | Expr::Sub(a, b) | Expr::Mul(a, b) | Expr::Div(a, b) | Expr::Pow(a, b) => {
            let x = expr(g, a, model, frozen);
            let y = expr(g, b, model, frozen);
            match e {
                Expr::Add(..) => g.add(x, y),
                Expr::Sub(..) => g.sub(x, y),
                Expr::Mul(..) => g.mul(x, y),
                Expr::Div(..) => g.div(x, y),
                _ => g.pow(x, y),
            }
        }
        Expr::Call(f, args) => {
            let args: Vec<Id> = args.iter().map(|a| expr(g, a, model, frozen)).collect();
            g.call(*f, &args)
        }
    }
}

/// A readable identifier fragment for a body or loop name (snake_case ASCII).
fn ident_part(name: &str) -> String {
    let mut s: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '_'
            }
        })
        .collect();
    if s.is_empty() {
        s.push('b');
    }
    s
}

fn dot(g: &mut Graph, a: &[Id; 3], b: &[Id; 3]) -> Id {
    let terms: Vec<Id> = (0..3).map(|i| g.mul(a[i], b[i])).collect();
    g.sum(&terms)
}

fn cross(g: &mut Graph, a: &[Id; 3], b: &[Id; 3]) -> [Id; 3] {
    std::array::from_fn(|i| {
        let (j, k) = ((i + 1) % 3, (i + 2) % 3);
        let l = g.mul(a[j], b[k]);
        let r = g.mul(a[k], b[j]);
        g.sub(l, r)
    })
}

fn add3(g: &mut Graph, a: &[Id; 3], b: &[Id; 3]) -> [Id; 3] {
    std::array::from_fn(|i| g.add(a[i], b[i]))
}

fn mat_vec(g: &mut Graph, m: &[[Id; 3]; 3], v: &[Id; 3]) -> [Id; 3] {
    std::array::from_fn(|i| dot(g, &m[i], v))
}

fn mat_t_vec(g: &mut Graph, m: &[[Id; 3]; 3], v: &[Id; 3]) -> [Id; 3] {
    std::array::from_fn(|i| {
        let col = [m[0][i], m[1][i], m[2][i]];
        dot(g, &col, v)
    })
}

/// The elementary rotation `E` about `axis` by the angle with cosine `c` and sine `s`.
fn rotation(g: &mut Graph, axis: Axis, c: Id, s: Id) -> [[Id; 3]; 3] {
    let (z, o) = (Graph::ZERO, Graph::ONE);
    let ns = g.neg(s);
    match axis {
        Axis::X => [[o, z, z], [z, c, ns], [z, s, c]],
        Axis::Y => [[c, z, s], [z, o, z], [ns, z, c]],
        Axis::Z => [[c, ns, z], [s, c, z], [z, z, o]],
    }
}

/// A frame with its body-axes velocities: `omega` (angular) and `vel` (of the origin).
#[derive(Clone, Copy)]
struct Moving {
    frame: Frame,
    omega: [Id; 3],
    vel: [Id; 3],
}

/// A step whose argument `theta(X)` moves: a revolute or prismatic joint of the tree.
#[derive(Clone, Copy)]
struct Joint {
    /// The body whose steps it is among (it moves that body and its descendants).
    body: usize,
    revolute: bool,
    /// Unit axis and a point of it, world axes.
    axis: [Id; 3],
    point: [Id; 3],
    theta: Id,
}

struct Builder<'a> {
    g: Graph,
    model: &'a Model,
    frozen: &'a [bool],
    /// Every body's steps as applied (constant runs folded), for the recursive forms.
    body_pieces: Vec<Vec<steps::Piece>>,
}

impl Builder<'_> {
    fn expr(&mut self, e: &Expr) -> Id {
        expr(&mut self.g, e, self.model, self.frozen)
    }
}

/// The upper triangle of a symmetric matrix, row by row.
fn upper_triangle(m: &[Vec<Id>]) -> Vec<Id> {
    m.iter()
        .enumerate()
        .flat_map(|(i, row)| row[i..].to_vec())
        .collect()
}

/// The candidate (the same quantity computed different ways) cheapest beside `given`.
fn cheapest(g: &Graph, candidates: &[Id], given: &[Id]) -> Id {
    *candidates
        .iter()
        .min_by_key(|&&c| g.cost(&[c], given))
        .expect("a candidate")
}

/// Names a 3-vector's nodes `{prefix}_x`, `_y`, `_z`.
fn name3(g: &mut Graph, ids: &[Id; 3], prefix: &str) {
    for (i, &id) in ids.iter().enumerate() {
        g.name(id, &format!("{prefix}_{}", ["x", "y", "z"][i]));
    }
}

/// Euler's equations at `Xddot = 0` in body axes: `(tau0, I omega)` with
/// `tau0 = I alpha0 + omega × I omega`, `alpha0 = d/dt omega`.
fn euler_torque(g: &mut Graph, inertia: &[[Id; 3]; 3], w: &[Id; 3]) -> ([Id; 3], [Id; 3]) {
    let alpha0: [Id; 3] = std::array::from_fn(|i| g.diff(w[i], Seed::Time));
    let iw = mat_vec(g, inertia, w);
    let ia = mat_vec(g, inertia, &alpha0);
    let gyro = cross(g, w, &iw);
    (add3(g, &ia, &gyro), iw)
}

/// The upper triangle of `M` and `psi` from their terms (like terms collected).
fn sum_terms(g: &mut Graph, mass_t: &[Vec<Vec<Id>>], psi_t: &[Vec<Id>]) -> (Vec<Vec<Id>>, Vec<Id>) {
    let n = psi_t.len();
    let mut mass = vec![vec![Graph::ZERO; n]; n];
    for i in 0..n {
        for j in i..n {
            mass[i][j] = g.sum(&mass_t[i][j]);
        }
    }
    let psi = psi_t.iter().map(|t| g.sum(t)).collect();
    (mass, psi)
}

fn world() -> Moving {
    let (z, o) = (Graph::ZERO, Graph::ONE);
    Moving {
        frame: Frame {
            r: [[o, z, z], [z, o, z], [z, z, o]],
            p: [z; 3],
        },
        omega: [z; 3],
        vel: [z; 3],
    }
}

/// How `M` and `psi` are formed (see [`derive_with`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Form {
    /// Whichever of the two needs fewer operations (what code generation uses).
    Cheaper,
    /// Body by body: `Σ m J_cᵀ J_c + J_wᵀ I J_w` and `-Σ J_cᵀ F0 + J_wᵀ tau0`.
    BodyByBody,
    /// Recursively over the joints: composite inertias and subtree wrenches, world axes.
    Recursive,
    /// Recursively over the steps, in each joint's own frame (`derive/local.rs`).
    Local,
}

/// Runs the derivation (kinematics, and the dynamics when `with_dynamics`); parameters with
/// `frozen[j]` are folded into the expressions. `progress` receives one line per stage.
pub fn derive(
    model: &Model,
    with_dynamics: bool,
    frozen: &[bool],
    progress: &mut dyn FnMut(&str),
) -> Result<Derivation, Vec<DeriveError>> {
    derive_with(model, with_dynamics, frozen, Form::Cheaper, progress)
}

/// [`derive`](fn@derive) with the form of `M` and `psi` chosen (the tests check each against the
/// expanded reference).
pub fn derive_with(
    model: &Model,
    with_dynamics: bool,
    frozen: &[bool],
    form: Form,
    progress: &mut dyn FnMut(&str),
) -> Result<Derivation, Vec<DeriveError>> {
    let n = model.coordinates.len();
    let mut b = Builder {
        g: Graph::new(n),
        model,
        frozen,
        body_pieces: Vec::with_capacity(model.bodies.len()),
    };

    progress("frames and body velocities, recursively");
    let mut moving: Vec<Moving> = Vec::with_capacity(model.bodies.len());
    let mut joints: Vec<Joint> = Vec::new();
    for body in &model.bodies {
        let start = match body.parent {
            Some(i) => moving[i],
            None => world(),
        };
        let mut mv = start;
        let pieces = b.pieces(&mv, &body.steps);
        for pc in &pieces {
            if let Some(j) = b.joint(&mv, pc, moving.len()) {
                joints.push(j);
            }
            // Velocities always: the loop points' accelerations for gamma go through them.
            mv = b.apply(&mv, pc);
        }
        b.body_pieces.push(pieces);
        let name = ident_part(&body.name);
        for i in 0..3 {
            for j in 0..3 {
                b.g.name(mv.frame.r[i][j], &format!("rot_{name}_{i}{j}"));
            }
        }
        name3(&mut b.g, &mv.frame.p, &format!("pos_{name}"));
        if with_dynamics {
            name3(&mut b.g, &mv.omega, &format!("omega_{name}"));
            name3(&mut b.g, &mv.vel, &format!("vel_{name}"));
        }
        moving.push(mv);
    }
    let frames: Vec<Frame> = moving.iter().map(|m| m.frame).collect();

    progress("loop closure f(X)");
    let closure::Rows {
        f,
        names,
        ends: rows,
        accelerations,
        axis: row_axis,
        gamma_w: row_gamma_w,
        checks,
        check_names,
    } = closure::closure(&mut b, &moving, &joints)?;
    let mut errors = Vec::new();
    let m = f.len();

    progress("Jacobian G = df/dX (chain rule through the frames, or joint screws)");
    // Each loop point's derivatives either by the chain rule through its frame or by the
    // joints' screws, ∂p/∂X_k = Σ_s ∂theta_s/∂X_k (a_s × (p - o_s)) (revolute) or
    // ∂theta_s/∂X_k a_s (prismatic): whichever needs fewer operations, point by point.
    let (mut by_chain, mut by_screw) = (0, 0);
    // A quaternion (a `free` joint) is no screw: its model's points go by the chain rule.
    let free = has_free_joint(model);
    let mut g = vec![vec![Graph::ZERO; n]; m];
    for (r, ends) in rows.iter().enumerate() {
        let Some(i) = row_axis[r] else {
            // A weld's rotation row: the chain rule.
            for (k, gk) in g[r].iter_mut().enumerate() {
                *gk = b.g.diff(f[r], Seed::X(k as u32));
            }
            by_chain += 1;
            continue;
        };
        let mut terms = vec![Vec::new(); n];
        for (sign, (p, path)) in ends.iter().enumerate() {
            let chain: Vec<Id> = (0..n).map(|k| b.g.diff(p[i], Seed::X(k as u32))).collect();
            let mut screw = vec![Vec::new(); n];
            for j in path {
                let col = if j.revolute {
                    let d: [Id; 3] = std::array::from_fn(|l| b.g.sub(p[l], j.point[l]));
                    cross(&mut b.g, &j.axis, &d)[i]
                } else {
                    j.axis[i]
                };
                for (k, dk) in theta_coords(&mut b.g, j.theta, n) {
                    screw[k].push(b.g.mul(dk, col));
                }
            }
            let screw: Vec<Id> = screw.iter().map(|t| b.g.sum(t)).collect();
            let (c_chain, c_screw) = (b.g.cost(&chain, &[]), b.g.cost(&screw, &[]));
            let cols = if !free && c_screw < c_chain {
                by_screw += 1;
                screw
            } else {
                by_chain += 1;
                chain
            };
            for k in 0..n {
                terms[k].push(if sign == 0 { cols[k] } else { b.g.neg(cols[k]) });
            }
        }
        for k in 0..n {
            g[r][k] = b.g.sum(&terms[k]);
        }
    }
    progress(&format!(
        "G: {by_chain} loop points by the chain rule, {by_screw} by joint screws"
    ));

    progress("acceleration term gamma = -(dG/dt) Xdot at Xddot = 0");
    // Row by row, -d²f/dt² or -Σ_k (dG_k/dt) Xdot_k through the G chosen above: the cheaper,
    // with G and the rows before given (their shared subexpressions cost nothing again).
    let mut gamma = Vec::with_capacity(m);
    // Three ways to each row: -d²f/dt², through G, and through the loop points' body-axes
    // velocities (dearer alone, but in the fused kernel it shares the bodies' accelerations
    // with psi, see below).
    let mut given: Vec<Id> = g.iter().flatten().copied().collect();
    let mut ways: Vec<[Id; 3]> = Vec::with_capacity(m);
    for (r, &fi) in f.iter().enumerate() {
        let fd = b.g.diff(fi, Seed::Time);
        let fdd = b.g.diff(fd, Seed::Time);
        let direct = b.g.neg(fdd);
        let terms: Vec<Id> = (0..n)
            .map(|k| {
                let d = b.g.diff(g[r][k], Seed::Time);
                let v = b.g.v(k);
                let t = b.g.mul(d, v);
                b.g.neg(t)
            })
            .collect();
        let through_g = b.g.sum(&terms);
        // Through the points' accelerations (a weld's rotation row: through its frames' angular
        // velocities).
        let through_v = match row_axis[r] {
            Some(i) => {
                let [aa, ab] = accelerations[r];
                let d = b.g.sub(aa[i], ab[i]);
                b.g.neg(d)
            }
            None => row_gamma_w[r].unwrap_or(through_g),
        };
        let candidates = [direct, through_g, through_v];
        let row = cheapest(&b.g, &candidates, &given);
        ways.push(candidates);
        given.push(row);
        gamma.push(row);
    }

    progress("structure: passive coordinates, IK blocks");
    let mut actuated = vec![false; n];
    for &a in &model.actuated {
        actuated[a] = true;
    }
    let passive: Vec<usize> = (0..n).filter(|&j| !actuated[j]).collect();
    let mut is_output = vec![false; n];
    for &o in &model.outputs {
        is_output[o] = true;
    }
    let nonzero: Vec<Vec<bool>> = g
        .iter()
        .map(|row| row.iter().map(|&x| x != Graph::ZERO).collect())
        .collect();
    // Without outputs there is no inverse kinematics, hence no blocks (a serial arm, a tree,
    // a model for dynamics only).
    let ik_blocks = if model.outputs.is_empty() {
        Vec::new()
    } else {
        ik_blocks(&nonzero, &is_output, &names, model, &mut errors)
    };
    if !errors.is_empty() {
        return Err(errors);
    }

    let mut dynamics = with_dynamics.then(|| dynamics(&mut b, &moving, &joints, form, progress));

    if let Some(dy) = dynamics.as_mut() {
        // The Lagrangian's algebra: terms that cancel between bodies, sin² + cos² = 1, common
        // factors (see [`crate::simplify`]).
        let t = std::time::Instant::now();
        let mut s = crate::simplify::Simplifier::default();
        let mut upper = upper_triangle(&dy.mass);
        let saved_m = s.simplify(&mut b.g, &mut upper);
        let mut k = 0;
        for i in 0..n {
            for j in i..n {
                dy.mass[i][j] = upper[k];
                dy.mass[j][i] = upper[k];
                k += 1;
            }
        }
        let saved_p = s.simplify(&mut b.g, &mut dy.psi);
        let mut energies = [dy.kinetic, dy.potential];
        let saved_e = s.simplify(&mut b.g, &mut energies);
        [dy.kinetic, dy.potential] = energies;
        progress(&format!(
            "M, psi, T and Pi re-simplified (expanded locally, sin² + cos² = 1, Horner): \
             {saved_m}, {saved_p} and {saved_e} operations fewer, in {:.3} s",
            t.elapsed().as_secs_f64()
        ));
        // gamma again for the fused kernel: the way whose rows together are cheapest beside G,
        // M and psi, then row by row another way where that is cheaper (sharing counted).
        let g_roots: Vec<Id> = g.iter().flatten().copied().collect();
        let upper_m = upper_triangle(&dy.mass);
        let given: Vec<Id> = [&g_roots[..], &upper_m, &dy.psi].concat();
        let sets: Vec<Vec<Id>> = (0..3)
            .map(|w| ways.iter().map(|r| r[w]).collect())
            .collect();
        let best = (0..3)
            .min_by_key(|&w| b.g.cost(&sets[w], &given))
            .expect("three ways");
        let k = given.len();
        let mut roots: Vec<Id> = given.iter().chain(&sets[best]).copied().collect();
        for (w, set) in sets.iter().enumerate() {
            if w != best {
                let other: Vec<Id> = given.iter().chain(set).copied().collect();
                crate::simplify::choose(&mut b.g, &mut roots, &other);
            }
        }
        dy.gamma = roots[k..].to_vec();
        // What each part adds to the fused kernel, in order (before CSE).
        let cost_g = b.g.cost(&g_roots, &[]);
        let mut fused = g_roots;
        let mut more = Vec::new();
        for part in [&dy.gamma, &upper_m, &dy.psi] {
            more.push(b.g.cost(part, &fused));
            fused.extend(part.iter().copied());
        }
        progress(&format!(
            "the fused kernel: G {cost_g} operations, gamma {} more, M {} more, psi {} more",
            more[0], more[1], more[2]
        ));
    }

    Ok(Derivation {
        graph: b.g,
        n,
        m,
        constraint_names: names,
        f,
        g,
        checks,
        check_names,
        gamma,
        passive,
        ik_blocks,
        frames,
        dynamics,
    })
}

/// `[v]x`, the cross-product matrix of `v`.
fn skew(g: &mut Graph, v: &[Id; 3]) -> [[Id; 3]; 3] {
    let n: [Id; 3] = std::array::from_fn(|i| g.neg(v[i]));
    let z = Graph::ZERO;
    [[z, n[2], v[1]], [v[2], z, n[0]], [n[1], v[0], z]]
}

/// The 3 × 3 product `a b` (`[row][col]`).
fn mat_mul(g: &mut Graph, a: &[[Id; 3]; 3], b: &[[Id; 3]; 3]) -> [[Id; 3]; 3] {
    let mut out = [[Graph::ZERO; 3]; 3];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, o) in row.iter_mut().enumerate() {
            let terms: Vec<Id> = (0..3).map(|k| g.mul(a[i][k], b[k][j])).collect();
            *o = g.sum(&terms);
        }
    }
    out
}

/// The coordinates `theta` depends on, with `∂theta/∂X_k`.
fn theta_coords(g: &mut Graph, theta: Id, n: usize) -> Vec<(usize, Id)> {
    let ks: Vec<usize> = (0..n).filter(|&k| g.depends_x(theta, k)).collect();
    ks.into_iter()
        .map(|k| (k, g.diff(theta, Seed::X(k as u32))))
        .collect()
}

/// `M` (upper triangle) or `psi` from `candidates` (form, entries, operations): the form asked
/// for, or the cheapest and then, entry by entry, another where that is cheaper (sharing
/// counted); returns it and the operations the mixing saved.
fn combine(
    g: &mut Graph,
    form: Form,
    mut candidates: Vec<(Form, Vec<Id>, usize)>,
) -> (Vec<Id>, usize) {
    let i = match form {
        Form::Cheaper => (0..candidates.len())
            .min_by_key(|&i| candidates[i].2)
            .expect("a form"),
        f => candidates
            .iter()
            .position(|c| c.0 == f)
            .expect("the form asked for is built"),
    };
    candidates.swap(0, i);
    let others = candidates.split_off(1);
    let (_, mut chosen, _) = candidates.pop().expect("a form");
    let mut saved = 0;
    if form == Form::Cheaper {
        for (_, other, _) in &others {
            saved += crate::simplify::choose(g, &mut chosen, other);
        }
    }
    (chosen, saved)
}

/// `m (a0 - g)`: the force a body's motion at `Xddot = 0` and gravity need.
fn weight_force(g: &mut Graph, m: Id, a0: &[Id; 3], gravity: &[Id; 3]) -> [Id; 3] {
    std::array::from_fn(|i| {
        let d = g.sub(a0[i], gravity[i]);
        g.mul(m, d)
    })
}

/// A body's translational part: mass, the columns `(k, J_c,k)` it moves with, `F0`.
type Linear = (Id, Vec<(usize, [Id; 3])>, [Id; 3]);

/// `M`, `psi` and the energies, body by body (see the module documentation).
fn dynamics(
    b: &mut Builder,
    moving: &[Moving],
    joints: &[Joint],
    form: Form,
    progress: &mut dyn FnMut(&str),
) -> Dynamics {
    let model = b.model;
    let n = model.coordinates.len();
    let gravity: [Id; 3] = std::array::from_fn(|a| b.expr(&model.gravity[a]));
    // Terms of M, psi, T and Pi, summed (like terms collected) at the end.
    let mut mass_t: Vec<Vec<Vec<Id>>> = vec![vec![Vec::new(); n]; n];
    let mut psi_t: Vec<Vec<Id>> = vec![Vec::new(); n];
    let mut kinetic_t: Vec<Id> = Vec::new();
    let mut potential_t: Vec<Id> = Vec::new();
    let half = b.g.num(crate::graph::Rat::new(1, 2).expect("1/2"));

    // Rotational parts: bodies with the same body-axes angular velocity (a leg's links) share
    // one: T_rot = ½ omegaᵀ (Σ I_b) omega, torques and M from the summed inertia.
    let mut groups: Vec<([Id; 3], [[Id; 3]; 3], String)> = Vec::new();
    // Translational parts, per body: (mass, J_c columns, F0), in body or world axes.
    let mut linear: Vec<Linear> = Vec::new();
    // Per body, for the recursive form: mass, world centre of mass, world rotational inertia,
    // and the wrench (moment about the world origin, force) it needs at Xddot = 0.
    let mut spatial: Vec<Option<Spatial>> = vec![None; model.bodies.len()];
    // The same in body axes, for the form in the joints' own frames.
    let mut body_frames: Vec<Option<local::BodyFrame>> = vec![None; model.bodies.len()];
    for (bi, body) in model.bodies.iter().enumerate() {
        let Some(mp) = &body.inertia else { continue };
        progress(&format!("dynamics of `{}`", body.name));
        let name = ident_part(&body.name);
        let mv = moving[bi];
        let mb = b.expr(&mp.mass);
        let com: [Id; 3] = std::array::from_fn(|a| b.expr(&mp.com[a]));
        let ie: [Id; 6] = std::array::from_fn(|a| b.expr(&mp.inertia[a]));
        let inertia = [
            [ie[0], ie[3], ie[4]],
            [ie[3], ie[1], ie[5]],
            [ie[4], ie[5], ie[2]],
        ];
        let g = &mut b.g;
        let w = mv.omega;
        match groups.iter_mut().find(|gr| gr.0 == w) {
            Some(gr) => {
                for i in 0..3 {
                    for j in 0..3 {
                        gr.1[i][j] = g.add(gr.1[i][j], inertia[i][j]);
                    }
                }
            }
            None => groups.push((w, inertia, name.clone())),
        }
        // Centre of mass in body axes: v_c = v + omega × c, a0_c = d/dt v_c + omega × v_c, and
        // gravity g_b = Rᵀ g.
        let wc = cross(g, &w, &com);
        let vc_b = add3(g, &mv.vel, &wc);
        let vc_dt: [Id; 3] = std::array::from_fn(|i| g.diff(vc_b[i], Seed::Time));
        let w_vc = cross(g, &w, &vc_b);
        let a0_b = add3(g, &vc_dt, &w_vc);
        let gb = mat_t_vec(g, &mv.frame.r, &gravity);
        // The same in world axes: r_c = p + R c, v_c = d/dt r_c, a0_c = d/dt v_c.
        let rc = mat_vec(g, &mv.frame.r, &com);
        let rc = add3(g, &mv.frame.p, &rc);
        let vc_w: [Id; 3] = std::array::from_fn(|i| g.diff(rc[i], Seed::Time));
        let a0_w: [Id; 3] = std::array::from_fn(|i| g.diff(vc_w[i], Seed::Time));
        let columns = |g: &mut Graph, vc: &[Id; 3]| -> Vec<(usize, [Id; 3])> {
            (0..n)
                .filter_map(|k| {
                    let jc: [Id; 3] = std::array::from_fn(|i| g.diff(vc[i], Seed::V(k as u32)));
                    jc.iter().any(|&x| x != Graph::ZERO).then_some((k, jc))
                })
                .collect()
        };
        let cols_b = columns(g, &vc_b);
        let cols_w = columns(g, &vc_w);
        let roots = |cols: &[(usize, [Id; 3])], a: &[Id; 3], extra: &[Id; 3]| -> Vec<Id> {
            cols.iter()
                .flat_map(|c| c.1)
                .chain(a.iter().copied())
                .chain(extra.iter().copied())
                .collect()
        };
        let given: Vec<Id> = w.to_vec();
        let body_cost = g.cost(&roots(&cols_b, &a0_b, &gb), &given);
        let world_cost = g.cost(&roots(&cols_w, &a0_w, &[Graph::ZERO; 3]), &given);
        let (vc, a0, gr, cols) = if world_cost < body_cost {
            (vc_w, a0_w, gravity, cols_w)
        } else {
            (vc_b, a0_b, gb, cols_b)
        };
        // F0 = m (a0 - g)
        let force = weight_force(g, mb, &a0, &gr);
        name3(g, &vc, &format!("vcom_{name}"));
        name3(g, &force, &format!("force_{name}"));
        let vv = dot(g, &vc, &vc);
        let mvv = g.mul(mb, vv);
        let t = g.mul(half, mvv);
        kinetic_t.push(t);
        let gr_dot = dot(g, &gravity, &rc);
        let mgr = g.mul(mb, gr_dot);
        potential_t.push(g.neg(mgr));
        // World wrench: f = F0 (world), n_O = r_c × f + R tau0 with the body's own tau0.
        let f_w = if world_cost < body_cost {
            force
        } else {
            mat_vec(g, &mv.frame.r, &force)
        };
        let (tau_b, _) = euler_torque(g, &inertia, &w);
        // Body axes: f = m (a0_c - g), n_O = c × f + tau0.
        let f_b = weight_force(g, mb, &a0_b, &gb);
        let cxf = cross(g, &com, &f_b);
        body_frames[bi] = Some(local::BodyFrame {
            mass: mb,
            com,
            inertia,
            wrench: (add3(g, &cxf, &tau_b), f_b),
        });
        let tau_w = mat_vec(g, &mv.frame.r, &tau_b);
        let rxf = cross(g, &rc, &f_w);
        let n_w = add3(g, &rxf, &tau_w);
        // R I Rᵀ
        let ri: [[Id; 3]; 3] = std::array::from_fn(|i| {
            std::array::from_fn(|j| {
                let row = [inertia[0][j], inertia[1][j], inertia[2][j]];
                dot(g, &mv.frame.r[i], &row)
            })
        });
        let i_w: [[Id; 3]; 3] =
            std::array::from_fn(|i| std::array::from_fn(|j| dot(g, &ri[i], &mv.frame.r[j])));
        spatial[bi] = Some(Spatial {
            mass: mb,
            com: rc,
            inertia: i_w,
            wrench: (n_w, f_w),
        });
        linear.push((mb, cols, force));
    }
    // Two recursive forms: in world axes about the world origin (composite inertias and subtree
    // wrenches over the joints), and in each joint's own frame. Whichever of the three needs
    // fewest operations: the body-by-body sums for shallow trees (a parallel robot's legs), a
    // recursive one for deep chains (O(N) for psi, O(N²) for M) and for subtrees riding on a
    // moving body; then, entry by entry, another where it is cheaper (sharing counted).
    // A `free` joint's quaternion is no elementary joint: its model has the body-by-body form
    // only.
    let free = has_free_joint(model);
    let (mass_r, psi_r, mass_l, psi_l) = if free {
        (Vec::new(), Vec::new(), Vec::new(), Vec::new())
    } else {
        let (mass_r, psi_r) = recursive(&mut b.g, model, joints, &spatial);
        let (mass_l, psi_l) = local::local(b, &body_frames);
        (mass_r, psi_r, mass_l, psi_l)
    };
    let (upper_r, upper_l) = (upper_triangle(&mass_r), upper_triangle(&mass_l));
    let cost_mr = b.g.cost(&upper_r, &[]);
    let cost_ml = b.g.cost(&upper_l, &[]);
    // M body by body is not built where it cannot compete: its translational terms alone, a
    // 3-vector dot product and a product by the mass each (6 operations), would cost more than
    // 4 times the cheaper recursive form (a long chain: O(N³) terms).
    let pairs: usize = linear
        .iter()
        .map(|(_, cols, _)| cols.len() * (cols.len() + 1) / 2)
        .sum();
    let skip_m = !free && form == Form::Cheaper && 6 * pairs > 4 * cost_mr.min(cost_ml);
    for (mb, cols, force) in &linear {
        let g = &mut b.g;
        for (ci, (k, jc)) in cols.iter().enumerate() {
            // psi_k -= J_c,k . F0;  M_kl += m J_c,k . J_c,l
            let a = dot(g, jc, force);
            psi_t[*k].push(g.neg(a));
            if skip_m {
                continue;
            }
            for (l, jc2) in &cols[ci..] {
                let cc = dot(g, jc, jc2);
                mass_t[*k][*l].push(g.mul(*mb, cc));
            }
        }
    }
    for (w, inertia, name) in &groups {
        let g = &mut b.g;
        let (torque, iw) = euler_torque(g, inertia, w);
        name3(g, &torque, &format!("torque_{name}"));
        let wiw = dot(g, w, &iw);
        kinetic_t.push(g.mul(half, wiw));
        let mut cols: Vec<(usize, [Id; 3], [Id; 3])> = Vec::new();
        for k in 0..n {
            let jw: [Id; 3] = std::array::from_fn(|i| g.diff(w[i], Seed::V(k as u32)));
            if jw.iter().all(|&x| x == Graph::ZERO) {
                continue;
            }
            let ijw = mat_vec(g, inertia, &jw);
            cols.push((k, jw, ijw));
        }
        for (ci, (k, jw, _)) in cols.iter().enumerate() {
            // psi_k -= J_w,k . tau0;  M_kl += J_w,k . I J_w,l
            let c = dot(g, jw, &torque);
            psi_t[*k].push(g.neg(c));
            if skip_m {
                continue;
            }
            for (l, _, ijw2) in &cols[ci..] {
                mass_t[*k][*l].push(dot(g, jw, ijw2));
            }
        }
    }
    let (mut mass, psi) = sum_terms(&mut b.g, &mass_t, &psi_t);
    let g = &mut b.g;
    let mut candidates_m = if free {
        Vec::new()
    } else {
        vec![
            (Form::Recursive, upper_r, cost_mr),
            (Form::Local, upper_l, cost_ml),
        ]
    };
    let mut cost_m = None;
    if !skip_m {
        let upper_b = upper_triangle(&mass);
        let c = g.cost(&upper_b, &[]);
        cost_m = Some(c);
        candidates_m.insert(0, (Form::BodyByBody, upper_b, c));
    }
    let cost_p: Vec<usize> = [&psi, &psi_r, &psi_l].map(|p| g.cost(p, &[])).to_vec();
    let mut candidates_p = vec![(Form::BodyByBody, psi, cost_p[0])];
    if !free {
        candidates_p.push((Form::Recursive, psi_r, cost_p[1]));
        candidates_p.push((Form::Local, psi_l, cost_p[2]));
    }
    let form = if free { Form::Cheaper } else { form };
    let (upper_m, mixed_m) = combine(g, form, candidates_m);
    let (mut psi, mixed_p) = combine(g, form, candidates_p);
    let mut k = 0;
    for i in 0..n {
        for j in i..n {
            mass[i][j] = upper_m[k];
            k += 1;
        }
    }
    progress(&format!(
        "M: {} body by body, {} recursively in world axes, {} in the joints' frames; \
         psi: {}, {}, {}; other forms entry by entry where cheaper: {mixed_m} and {mixed_p} fewer",
        match cost_m {
            Some(c) => format!("{c} operations"),
            None => format!("not built (at least {} operations)", 6 * pairs),
        },
        cost_mr,
        cost_ml,
        cost_p[0],
        cost_p[1],
        cost_p[2]
    ));
    joint_forces(b, &mut mass, &mut psi, &mut kinetic_t, &mut potential_t);
    quaternion_inertia(b, &mut mass, &mut psi, &mut kinetic_t);
    let g = &mut b.g;
    let kinetic = g.sum(&kinetic_t);
    let potential = g.sum(&potential_t);
    for i in 0..n {
        for j in 0..i {
            mass[i][j] = mass[j][i];
        }
    }

    // Diagonal blocks of M: connected components of its sparsity.
    let mut comp: Vec<usize> = (0..n).collect();
    fn root(c: &mut [usize], mut x: usize) -> usize {
        while c[x] != x {
            c[x] = c[c[x]];
            x = c[x];
        }
        x
    }
    for i in 0..n {
        for j in 0..n {
            if mass[i][j] != Graph::ZERO {
                let (a, c) = (root(&mut comp, i), root(&mut comp, j));
                if a != c {
                    comp[a.max(c)] = a.min(c);
                }
            }
        }
    }
    let mut blocks: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    for i in 0..n {
        let r = root(&mut comp, i);
        blocks.entry(r).or_default().push(i);
    }
    Dynamics {
        mass,
        psi,
        kinetic,
        potential,
        mass_blocks: blocks.into_values().collect(),
        gamma: Vec::new(),
    }
}

/// The joints' own forces (`model::JointForces`), per coordinate `q` with velocity `v`:
/// `armature` on `M`'s diagonal and `½ armature v²` in `T`; `-stiffness (q - rest) - damping v`
/// in `psi` and `½ stiffness (q - rest)²` in `Pi`. `mass` is the upper triangle (`i <= j`).
fn joint_forces(
    b: &mut Builder,
    mass: &mut [Vec<Id>],
    psi: &mut [Id],
    kinetic_t: &mut Vec<Id>,
    potential_t: &mut Vec<Id>,
) {
    let half = b.g.num(crate::graph::Rat::new(1, 2).expect("1/2"));
    for (i, c) in b.model.coordinates.iter().enumerate() {
        let f = &c.forces;
        if let Some(e) = &f.armature {
            let a = b.expr(e);
            let g = &mut b.g;
            mass[i][i] = g.add(mass[i][i], a);
            let v = g.v(i);
            let vv = g.mul(v, v);
            let av = g.mul(a, vv);
            kinetic_t.push(g.mul(half, av));
        }
        if let Some(e) = &f.stiffness {
            let k = b.expr(e);
            let rest = f.rest.as_ref().map(|r| b.expr(r));
            let g = &mut b.g;
            let q = g.x(i);
            let dq = match rest {
                Some(r) => g.sub(q, r),
                None => q,
            };
            let spring = g.mul(k, dq);
            psi[i] = g.sub(psi[i], spring);
            let sq = g.mul(spring, dq);
            potential_t.push(g.mul(half, sq));
        }
        if let Some(e) = &f.damping {
            let c = b.expr(e);
            let g = &mut b.g;
            let v = g.v(i);
            let damper = g.mul(c, v);
            psi[i] = g.sub(psi[i], damper);
        }
    }
}

/// True when a body of the model has a `free` joint (a [`Step::Quat`]).
pub fn has_free_joint(model: &Model) -> bool {
    model
        .bodies
        .iter()
        .any(|b| b.steps.iter().any(|s| matches!(s, Step::Quat(_))))
}

/// The inertia `mu` of a `free` joint's quaternion along itself: `½ mu (qᵀq̇)²` in `T` (see
/// [`quaternion_inertia`]), `mu = 4/3 Σ tr(I_b)` over the floating body and the bodies below
/// it (`4 I` is what the quaternion's tangent directions see of an inertia `I`, so `mu` is
/// their mean), or 1 where that is zero (point masses).
pub fn quaternion_mu(model: &Model, body: usize) -> Expr {
    let mut below = vec![false; model.bodies.len()];
    below[body] = true;
    let mut terms: Vec<Expr> = Vec::new();
    for (i, b) in model.bodies.iter().enumerate() {
        if let Some(p) = b.parent
            && below[p]
        {
            below[i] = true;
        }
        if below[i]
            && let Some(mp) = &b.inertia
        {
            terms.extend(mp.inertia[..3].iter().cloned());
        }
    }
    let sum = terms
        .into_iter()
        .reduce(|a, b| Expr::Add(Box::new(a), Box::new(b)));
    let values: Vec<f64> = model.parameters.iter().map(|p| p.value).collect();
    match sum {
        Some(s) if s.eval(&values, &[]) > 0.0 => {
            Expr::Mul(Box::new(Expr::Num { num: 4, den: 3 }), Box::new(s))
        }
        _ => Expr::int(1),
    }
}

/// A `free` joint's quaternion `q` moves nothing along itself (`T` depends on `q̇` only
/// through `omega = 2 Im(q* q̇) / |q|²`), so `M` would be singular along `q̇ ∥ q`. The kinetic
/// energy gets `½ mu (qᵀq̇)²`: `M_qq += mu q qᵀ` and `psi_q -= mu |q̇|² q` (Lagrange's terms
/// at `q̈ = 0`). Their force `mu (qᵀq̈ + |q̇|²) q` is zero wherever the unit norm's acceleration
/// row `qᵀq̈ = -|q̇|²` holds, so accelerations and multipliers are those of the system without
/// it, and `M` is regular. `mass` is the upper triangle (`i <= j`).
fn quaternion_inertia(
    b: &mut Builder,
    mass: &mut [Vec<Id>],
    psi: &mut [Id],
    kinetic_t: &mut Vec<Id>,
) {
    let model = b.model;
    let half = b.g.num(crate::graph::Rat::new(1, 2).expect("1/2"));
    for lp in &model.loops {
        let LoopKind::UnitNorm(q) = lp.kind else {
            continue;
        };
        let Some(body) = model.bodies.iter().position(|bd| {
            bd.steps.iter().any(|s| match s {
                Step::Quat(e) => e.iter().zip(q).all(|(e, k)| *e == Expr::Coord(k)),
                _ => false,
            })
        }) else {
            continue;
        };
        let mu = quaternion_mu(model, body);
        let mu = b.expr(&mu);
        let g = &mut b.g;
        let x: [Id; 4] = std::array::from_fn(|i| g.x(q[i]));
        let v: [Id; 4] = std::array::from_fn(|i| g.v(q[i]));
        let xv: Vec<Id> = (0..4).map(|i| g.mul(x[i], v[i])).collect();
        let vv: Vec<Id> = (0..4).map(|i| g.mul(v[i], v[i])).collect();
        let qv = g.sum(&xv);
        let qv2 = g.mul(qv, qv);
        let t = g.mul(mu, qv2);
        kinetic_t.push(g.mul(half, t));
        let vv = g.sum(&vv);
        let muvv = g.mul(mu, vv);
        for i in 0..4 {
            let f = g.mul(muvv, x[i]);
            psi[q[i]] = g.sub(psi[q[i]], f);
            for j in 0..4 {
                let (r, c) = (q[i], q[j]);
                if r > c || (r == c && i != j) {
                    continue;
                }
                let xx = g.mul(x[i], x[j]);
                let e = g.mul(mu, xx);
                mass[r][c] = g.add(mass[r][c], e);
            }
        }
    }
}

/// Connected components of the bipartite graph (constraint rows, non-output coordinates)
/// given by the sparsity of G. Each must be square.
fn ik_blocks(
    nonzero: &[Vec<bool>],
    is_output: &[bool],
    names: &[String],
    model: &Model,
    errors: &mut Vec<DeriveError>,
) -> Vec<(Vec<usize>, Vec<usize>)> {
    let m = nonzero.len();
    let n = is_output.len();
    // union-find over m rows + n columns
    let mut parent: Vec<usize> = (0..m + n).collect();
    fn find(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    for (i, row) in nonzero.iter().enumerate() {
        for (j, &nz) in row.iter().enumerate() {
            if !is_output[j] && nz {
                let a = find(&mut parent, i);
                let b = find(&mut parent, m + j);
                if a != b {
                    parent[a.max(b)] = a.min(b);
                }
            }
        }
    }
    let mut comps: BTreeMap<usize, (Vec<usize>, Vec<usize>)> = BTreeMap::new();
    for i in 0..m {
        let r = find(&mut parent, i);
        comps.entry(r).or_default().0.push(i);
    }
    for j in (0..n).filter(|&j| !is_output[j]) {
        let r = find(&mut parent, m + j);
        comps.entry(r).or_default().1.push(j);
    }
    let blocks: Vec<(Vec<usize>, Vec<usize>)> = comps.into_values().collect();
    for (rows, cols) in &blocks {
        if let ([], &[j]) = (rows.as_slice(), cols.as_slice()) {
            // A coordinate in no loop: nothing ties it to the outputs.
            let name = &model.coordinates[j].name;
            let message = if model.actuated.contains(&j) {
                format!(
                    "coordinate `{name}` is actuated and in no loop, so the outputs do not \
                     determine it and inverse kinematics cannot solve for it: list `{name}` in \
                     `outputs` as well (a coordinate may be both actuated and an output: inverse \
                     kinematics then takes it as given, inverse dynamics gives its force), close \
                     a loop through it, or leave `outputs` out (forward and inverse dynamics, \
                     simulation and the energy need none)"
                )
            } else {
                format!(
                    "coordinate `{name}` is in no loop, so the outputs do not determine it and \
                     inverse kinematics cannot solve for it: make `{name}` an output, close a \
                     loop through it, or leave `outputs` out (forward and inverse dynamics, \
                     simulation and the energy need none)"
                )
            };
            errors.push(DeriveError {
                pos: model.coordinates[j].pos,
                message,
            });
        } else if rows.len() != cols.len() {
            let rn: Vec<&str> = rows.iter().map(|&i| names[i].as_str()).collect();
            let cn: Vec<&str> = cols
                .iter()
                .map(|&j| model.coordinates[j].name.as_str())
                .collect();
            let pos = cols
                .first()
                .map(|&j| model.coordinates[j].pos)
                .unwrap_or_else(|| model.loops.first().map(|l| l.pos).unwrap_or_default());
            errors.push(DeriveError {
                pos,
                message: format!(
                    "with the outputs given, inverse kinematics is not well posed: the equations [{}] involve the \
                     coordinates [{}] ({} equations, {} unknowns); choose `outputs` so that every block is square",
                    rn.join(", "),
                    cn.join(", "),
                    rows.len(),
                    cols.len()
                ),
            });
        }
    }
    blocks
}
