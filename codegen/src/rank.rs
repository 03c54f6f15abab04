//! Rank checks at generation: the numeric rank of `G` at the assembled home and at a few random
//! assembled states near it (the actuated coordinates perturbed, seeded, the others projected
//! back onto `f(X) = 0`). What is deficient at every state sampled is the model's, not the
//! configuration's, and is reported naming the loop and component or the coordinates:
//!
//! - a redundant equation: a row of `G` that is a combination of the rows before it (a planar
//!   loop written with the component across its plane in a frame that turns: identically zero,
//!   though not structurally);
//! - a missing one: with the actuated coordinates (or the outputs) held, a combination of the
//!   others still moves (`J_p` or the inverse-kinematics Jacobian has dependent columns).
//!
//! A Jacobian singular at the home only is a singular configuration, which
//! [`crate::assemble::check_regular`] reports with its condition number; [`regular_nearby`]
//! adds the condition numbers at the random states to that message.

// Matrices over index pairs read best with explicit indices.
#![allow(clippy::needless_range_loop)]

use crate::assemble::{cond1, solve};
use crate::derive::{Derivation, DeriveError};
use crate::model::Model;

/// Per vector: `None` (independent), or its combination of the independent ones before it.
type Dependence = Vec<Option<Vec<(usize, f64)>>>;

/// Random assembled states beside the home, the spread of the actuated coordinates (rad or m),
/// and the relative distance from the span of the others under which a row or column counts as
/// dependent (a regular Jacobian of the robots here is 1e-3 or more from it; rounding 1e-15).
const RANDOM_STATES: usize = 4;
const SPREAD: f64 = 0.05;
const DEPENDENT: f64 = 1e-8;

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m: f64, x| m.max(x.abs()))
}

/// `f` and `G` (row-major, m × n) at `x`.
fn f_and_g(d: &Derivation, p: &[f64], x: &[f64]) -> (Vec<f64>, Vec<Vec<f64>>) {
    let val = d.graph.eval_all(x, &vec![0.0; d.n], p);
    let f = d.f.iter().map(|&id| val[id as usize]).collect();
    let g =
        d.g.iter()
            .map(|row| row.iter().map(|&id| val[id as usize]).collect())
            .collect();
    (f, g)
}

/// Projects `x` onto `f = 0` moving only `cols`: minimum-norm Gauss–Newton steps, regularised
/// (Levenberg–Marquardt with a tiny damping) so that redundant rows and dependent columns do
/// not stop it. `None` when it does not converge.
fn project(d: &Derivation, p: &[f64], x: &mut [f64], cols: &[usize]) -> Option<()> {
    for _ in 0..60 {
        let (f, g) = f_and_g(d, p, x);
        if !f.iter().all(|v| v.is_finite()) {
            return None;
        }
        if max_abs(&f) <= 1e-13 {
            return Some(());
        }
        // (J Jᵀ + mu I) z = -f, dx = Jᵀ z.
        let m = f.len();
        let mut a = vec![vec![0.0; m]; m];
        for i in 0..m {
            for k in 0..m {
                a[i][k] = cols.iter().map(|&j| g[i][j] * g[k][j]).sum();
            }
        }
        let scale = (0..m).fold(0.0f64, |s, i| s.max(a[i][i]));
        for (i, row) in a.iter_mut().enumerate() {
            row[i] += 1e-12 * scale.max(1e-300);
        }
        let z = solve(a, f.iter().map(|v| -v).collect())?;
        for &j in cols {
            x[j] += (0..m).map(|i| g[i][j] * z[i]).sum::<f64>();
        }
    }
    let (f, _) = f_and_g(d, p, x);
    (max_abs(&f) <= 1e-11).then_some(())
}

/// A small seeded generator (xorshift64*), for reproducible states.
struct Rng(u64);

impl Rng {
    /// Uniform in [-1, 1).
    fn sym(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let r = self.0.wrapping_mul(0x2545_f491_4f6c_dd1d);
        (r >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

/// The base state (projected onto `f = 0` with its actuated values held: the assembled home, or
/// an assembly near the home guess) and up to [`RANDOM_STATES`] random assembled states near it.
/// Empty when even the base does not project.
pub fn states(model: &Model, d: &Derivation, base: &[f64]) -> Vec<Vec<f64>> {
    let p: Vec<f64> = model.parameters.iter().map(|p| p.value).collect();
    let mut x = base.to_vec();
    if project(d, &p, &mut x, &d.passive).is_none() {
        return Vec::new();
    }
    let mut out = vec![x.clone()];
    let mut rng = Rng(0x5eed_4a4b_0000_0020);
    for _ in 0..RANDOM_STATES * 3 {
        if out.len() > RANDOM_STATES {
            break;
        }
        let mut y = x.clone();
        for &a in &model.actuated {
            y[a] += SPREAD * rng.sym();
        }
        if project(d, &p, &mut y, &d.passive).is_some() {
            out.push(y);
        }
    }
    out
}

/// For each vector in order: `None` when it is independent of the independent ones before it,
/// or `Some` of its combination of them (index, coefficient) when it lies within [`DEPENDENT`]
/// (relative to its norm; or 1e-13 of the largest vector's) of their span. Modified
/// Gram–Schmidt, twice.
fn dependence(vectors: &[Vec<f64>]) -> Dependence {
    // A vector of rounding size beside the others is zero (a row that vanishes identically
    // comes out at 1e-17, not 0).
    let scale = vectors
        .iter()
        .map(|v| v.iter().map(|x| x * x).sum::<f64>().sqrt())
        .fold(0.0, f64::max);
    // The orthonormal basis, the indices of the vectors it spans, and R (a_j = Σ_k R[k][j] q_k).
    let mut q: Vec<Vec<f64>> = Vec::new();
    let mut basis: Vec<usize> = Vec::new();
    let mut r: Vec<Vec<f64>> = Vec::new();
    let mut out = Vec::with_capacity(vectors.len());
    for (j, v) in vectors.iter().enumerate() {
        let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        let mut w = v.clone();
        let mut c = vec![0.0; q.len()];
        for _ in 0..2 {
            for (k, qk) in q.iter().enumerate() {
                let dot: f64 = qk.iter().zip(&w).map(|(a, b)| a * b).sum();
                c[k] += dot;
                for (wi, qi) in w.iter_mut().zip(qk) {
                    *wi -= dot * qi;
                }
            }
        }
        let rest = w.iter().map(|x| x * x).sum::<f64>().sqrt();
        if rest <= DEPENDENT * norm || rest <= 1e-13 * scale {
            // v = Σ_k c_k q_k = Σ_i y_i a_basis[i] with R y = c (upper triangular).
            let k = q.len();
            let mut y = vec![0.0; k];
            for i in (0..k).rev() {
                let s: f64 = (i + 1..k).map(|l| r[i][l] * y[l]).sum();
                y[i] = (c[i] - s) / r[i][i];
            }
            out.push(Some(basis.iter().copied().zip(y).collect()));
        } else {
            for (i, ci) in c.iter().enumerate() {
                r[i].push(*ci);
            }
            let mut row = vec![0.0; q.len()];
            row.push(rest);
            r.push(row);
            for rr in r.iter_mut() {
                rr.resize(q.len() + 1, 0.0);
            }
            q.push(w.iter().map(|x| x / rest).collect());
            basis.push(j);
            out.push(None);
        }
    }
    out
}

/// `a  b, c and d` for messages.
fn listed(items: &[String]) -> String {
    match items {
        [] => String::new(),
        [one] => one.clone(),
        [init @ .., last] => format!("{} and {last}", init.join(", ")),
    }
}

/// The structural rank deficiencies of `G`, `J_p` and the inverse-kinematics Jacobian at
/// `states` (the first one the home, see [`states`]): empty when every deficiency (if any) is
/// the home's alone, or when there is no random state to tell.
pub fn diagnose(
    model: &Model,
    d: &Derivation,
    states: &[Vec<f64>],
    home: &str,
) -> Vec<DeriveError> {
    if states.len() < 2 {
        return Vec::new();
    }
    let p: Vec<f64> = model.parameters.iter().map(|p| p.value).collect();
    let n = d.n;
    let gs: Vec<Vec<Vec<f64>>> = states.iter().map(|x| f_and_g(d, &p, x).1).collect();
    let sampled = format!(
        "{home} and at {} random assembled states near it",
        states.len() - 1
    );
    let mut errors = Vec::new();

    // Redundant equations: rows dependent on the rows before them at every state.
    let rows: Vec<Dependence> = gs.iter().map(|g| dependence(g)).collect();
    let rank = rows[0].iter().filter(|r| r.is_none()).count();
    for i in 0..d.m {
        if !rows.iter().all(|r| r[i].is_some()) {
            continue;
        }
        let name = &d.constraint_names[i];
        let loop_name = name.split('.').next().unwrap_or(name);
        let lp = model.loops.iter().find(|l| l.name == loop_name);
        let combo = rows[0][i].as_ref().expect("dependent");
        let of: Vec<String> = combo
            .iter()
            .filter(|(_, c)| c.abs() > 1e-6)
            .map(|(k, c)| format!("{c:.3} × `{}`", d.constraint_names[*k]))
            .collect();
        let what = if of.is_empty() {
            "is zero".to_string()
        } else {
            format!("is {}", listed(&of))
        };
        let dof = n - rank;
        errors.push(DeriveError {
            pos: lp.map_or_else(Default::default, |l| l.pos),
            message: format!(
                "loop `{loop_name}`: constraint `{name}` is redundant: its row of G {what} \
                 {sampled} (G has rank {rank} of {} rows), so it constrains nothing the others \
                 do not, and the mechanism has {dof} degree{} of freedom, not the {} actuated; \
                 remove it (a component across the plane of a planar loop?) and write the \
                 equation that is missing",
                d.m,
                if dof == 1 { "" } else { "s" },
                model.actuated.len()
            ),
        });
    }

    // Missing equations: with the actuated coordinates (the outputs) held, the others move.
    // A model with passive degrees of freedom (fewer actuated coordinates than degrees of
    // freedom) moves with its actuators held by design: only the outputs are checked there.
    let non_outputs: Vec<usize> = (0..n).filter(|j| !model.outputs.contains(j)).collect();
    let checks = [
        (&d.passive, "the actuated coordinates", "actuated"),
        (&non_outputs, "the outputs", "an output"),
    ];
    // Without outputs (a model for dynamics only) there is no inverse kinematics to check.
    let first = usize::from(d.passive.len() > d.m);
    let last = if model.outputs.is_empty() { 1 } else { 2 };
    for &(cols, held, meant) in checks.get(first..last).unwrap_or_default() {
        let deps: Vec<Dependence> = gs
            .iter()
            .map(|g| {
                let columns: Vec<Vec<f64>> = cols
                    .iter()
                    .map(|&j| (0..d.m).map(|i| g[i][j]).collect())
                    .collect();
                dependence(&columns)
            })
            .collect();
        let Some(c) = (0..cols.len()).find(|&c| deps.iter().all(|dep| dep[c].is_some())) else {
            continue;
        };
        let combo = deps[0][c].as_ref().expect("dependent");
        let mut moving: Vec<usize> = combo
            .iter()
            .filter(|(_, k)| k.abs() > 1e-6)
            .map(|(k, _)| cols[*k])
            .collect();
        moving.push(cols[c]);
        let names: Vec<String> = moving
            .iter()
            .map(|&j| format!("`{}`", model.coordinates[j].name))
            .collect();
        let col_rank = deps[0].iter().filter(|x| x.is_none()).count();
        // An actuated coordinate that moves with the outputs held: a hip above a loop that
        // closes in world axes (its column of G vanishes on the constraint manifold only).
        let both = if meant == "an output" && moving.iter().any(|j| model.actuated.contains(j)) {
            " (an actuated coordinate that no loop moves, such as a hip above a knee's loop, \
             is an output as well: a coordinate may be both)"
        } else {
            ""
        };
        errors.push(DeriveError {
            pos: model.coordinates[cols[c]].pos,
            message: format!(
                "with {held} held, {} can still move {sampled} (the Jacobian of f in the \
                 {} other coordinates has rank {col_rank}): an equation is missing (a loop \
                 with a component too few, a rotation that a hinge or a weld would fix), or {} \
                 meant to be {meant}{both}",
                listed(&names),
                cols.len(),
                if names.len() == 1 {
                    "it is"
                } else {
                    "one of them is"
                },
            ),
        });
    }
    errors.sort_by_key(|e| e.pos);
    errors
}

/// For a home that [`crate::assemble::check_regular`] finds singular: the condition numbers of
/// `J_p` and of the inverse-kinematics Jacobian at the random states (`states[1..]`), their
/// largest, when every one is regular (the home alone is singular).
pub fn regular_nearby(model: &Model, d: &Derivation, states: &[Vec<f64>]) -> Option<(f64, f64)> {
    if states.len() < 2 {
        return None;
    }
    let p: Vec<f64> = model.parameters.iter().map(|p| p.value).collect();
    let non_outputs: Vec<usize> = (0..d.n).filter(|j| !model.outputs.contains(j)).collect();
    let (mut cp, mut ck) = (0.0f64, 0.0f64);
    for x in &states[1..] {
        let (_, g) = f_and_g(d, &p, x);
        let sub = |cols: &[usize]| -> Vec<Vec<f64>> {
            g.iter()
                .map(|row| cols.iter().map(|&j| row[j]).collect())
                .collect()
        };
        cp = cp.max(cond1(&sub(&d.passive)));
        if !model.outputs.is_empty() {
            ck = ck.max(cond1(&sub(&non_outputs)));
        }
    }
    (cp.is_finite() && ck.is_finite()).then_some((cp, ck))
}
