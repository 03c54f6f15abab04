//! Assembling the home configuration: the model's `home` values need only be a rough guess.
//!
//! With the outputs held at their home values, Newton's method on `f(X) = 0` over the other
//! coordinates (the inverse-kinematics unknowns, a square system by the IK blocks' check), with
//! the generated expressions evaluated numerically, step halving when a step does not reduce
//! `max |f|`. The assembled values become the generated crate's `STRUCTURE.home`, the solvers'
//! cold start; the model file keeps the guess. The assembly is certified as the runtime's
//! solves are: the loop components that `components` leave out must close too.

use crate::derive::{Derivation, DeriveError};
use crate::model::Model;

/// The assembled home and how it was reached.
#[derive(Debug, Clone)]
pub struct Assembly {
    pub home: Vec<f64>,
    pub iterations: usize,
    /// `max |f|` at the model's values and at the assembled ones.
    pub residual_guess: f64,
    pub residual: f64,
    /// The largest change of a coordinate, and which.
    pub largest_change: (f64, usize),
}

/// Newton steps at most, and the residual an assembly must reach (`f` is in metres).
const MAX_STEPS: usize = 50;
const TOLERANCE: f64 = 1e-12;
/// The loop components left out of `f` must close to this at home (the runtime's certificate:
/// `1e4 tol_f`).
const CHECK_TOLERANCE: f64 = 1e4 * TOLERANCE;

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m: f64, x| m.max(x.abs()))
}

/// Solves `a x = b` (`a` row-major, `k × k`) by Gaussian elimination with partial pivoting;
/// `None` when a pivot is zero or not finite.
pub(crate) fn solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let k = b.len();
    for c in 0..k {
        let p = (c..k).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        if !a[p][c].is_finite() || a[p][c] == 0.0 {
            return None;
        }
        a.swap(c, p);
        b.swap(c, p);
        for r in c + 1..k {
            let f = a[r][c] / a[c][c];
            if f != 0.0 {
                let (top, bottom) = a.split_at_mut(r);
                for (x, &y) in bottom[0][c..].iter_mut().zip(&top[c][c..]) {
                    *x -= f * y;
                }
                b[r] -= f * b[c];
            }
        }
    }
    for c in (0..k).rev() {
        let s: f64 = (c + 1..k).map(|j| a[c][j] * b[j]).sum();
        b[c] = (b[c] - s) / a[c][c];
    }
    b.iter().all(|x| x.is_finite()).then_some(b)
}

/// Assembles the home of `model` (see the module documentation).
pub fn assemble(model: &Model, d: &Derivation) -> Result<Assembly, DeriveError> {
    let n = d.n;
    let p: Vec<f64> = model.parameters.iter().map(|p| p.value).collect();
    let mut is_output = vec![false; n];
    for &o in &model.outputs {
        is_output[o] = true;
    }
    // Without outputs, the actuated coordinates are held (as forward kinematics holds them)
    // and the others solved for; with passive degrees of freedom that system is not square,
    // and the step is the minimum-norm one.
    let unknowns: Vec<usize> = if model.outputs.is_empty() {
        d.passive.clone()
    } else {
        (0..n).filter(|&j| !is_output[j]).collect()
    };
    let guess: Vec<f64> = model.coordinates.iter().map(|c| c.home).collect();
    let v = vec![0.0; n];
    let residual = |x: &[f64]| -> (Vec<f64>, Vec<f64>) {
        let val = d.graph.eval_all(x, &v, &p);
        let f: Vec<f64> = d.f.iter().map(|&id| val[id as usize]).collect();
        (f, val)
    };
    // Errors point at the first output's home: the held values are what may be out of reach.
    let pos = model
        .outputs
        .first()
        .or(unknowns.first())
        .map(|&j| model.coordinates[j].pos)
        .unwrap_or_default();
    let fail = |message: String| DeriveError { pos, message };
    let (mut f, mut val) = residual(&guess);
    let residual_guess = max_abs(&f);
    let mut x = guess.clone();
    let mut iterations = 0;
    while max_abs(&f) > TOLERANCE / 16.0 && iterations < MAX_STEPS {
        iterations += 1;
        let jac: Vec<Vec<f64>> = (0..d.m)
            .map(|i| unknowns.iter().map(|&j| val[d.g[i][j] as usize]).collect())
            .collect();
        let rhs: Vec<f64> = f.iter().map(|r| -r).collect();
        let step = if unknowns.len() == d.m {
            solve(jac, rhs)
        } else {
            // dx = Jᵀ (J Jᵀ)⁻¹ rhs.
            let jjt: Vec<Vec<f64>> = (0..d.m)
                .map(|i| {
                    (0..d.m)
                        .map(|k| jac[i].iter().zip(&jac[k]).map(|(a, b)| a * b).sum())
                        .collect()
                })
                .collect();
            solve(jjt, rhs).map(|y| {
                (0..unknowns.len())
                    .map(|c| (0..d.m).map(|i| jac[i][c] * y[i]).sum())
                    .collect()
            })
        };
        let Some(dx) = step else {
            return Err(fail(format!(
                "the home configuration does not assemble: the Jacobian of f with respect to the \
                 non-output coordinates is singular at the home values (step {iterations}, max |f| = {:.2e}); \
                 move the home guess away from a singular configuration",
                max_abs(&f)
            )));
        };
        // Newton step, halved until max |f| decreases (at most 20 times).
        let before = max_abs(&f);
        let mut t = 1.0;
        loop {
            let mut trial = x.clone();
            for (&j, s) in unknowns.iter().zip(&dx) {
                trial[j] += t * s;
            }
            let (ft, vt) = residual(&trial);
            if max_abs(&ft) < before || t < 1e-6 {
                x = trial;
                f = ft;
                val = vt;
                break;
            }
            t /= 2.0;
        }
        if t < 1e-6 {
            break;
        }
    }
    let res = max_abs(&f);
    if res.is_nan() || res > TOLERANCE {
        let worst = f
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
            .map_or(0, |(i, _)| i);
        return Err(fail(format!(
            "the home configuration does not assemble: with the outputs held at their home values, \
             Newton on f(X) = 0 stopped after {iterations} steps at max |f| = {res:.2e} (constraint `{}`); \
             the outputs' home values may be out of reach, or the guess too far from an assembly",
            d.constraint_names[worst]
        )));
    }
    // The certificate of every position solve (the runtime's `certify_position`): the loop
    // components a loop leaves out of `f` must close too, or the home is a mirror root.
    if let Some((c, r)) = d
        .checks
        .iter()
        .map(|&id| val[id as usize])
        .enumerate()
        .find(|(_, r)| r.is_nan() || r.abs() > CHECK_TOLERANCE)
    {
        return Err(fail(format!(
            "the home configuration assembles a mirror of the loops: `{}` (a component its loop \
             leaves out of `components`) is {r:.3e} from closing at the assembled home, which \
             closes every component solved; move the home values (the outputs held, or the guess of the others) nearer the intended assembly",
            d.check_names[c]
        )));
    }
    let largest_change = (0..n)
        .map(|j| ((x[j] - guess[j]).abs(), j))
        .fold((0.0, 0), |m, c| if c.0 > m.0 { c } else { m });
    Ok(Assembly {
        home: x,
        iterations,
        residual_guess,
        residual: res,
        largest_change,
    })
}

/// The 1-norm condition number of the row-major `k × k` matrix `a` (its explicit inverse by
/// Gauss–Jordan with partial pivoting); infinite when a pivot is zero or not finite.
pub(crate) fn cond1(a: &[Vec<f64>]) -> f64 {
    let k = a.len();
    let norm1 = |m: &[Vec<f64>]| {
        (0..k)
            .map(|c| (0..k).map(|r| m[r][c].abs()).sum::<f64>())
            .fold(0.0, f64::max)
    };
    let anorm = norm1(a);
    let mut m: Vec<Vec<f64>> = a.to_vec();
    let mut inv: Vec<Vec<f64>> = (0..k)
        .map(|i| (0..k).map(|j| f64::from(u8::from(i == j))).collect())
        .collect();
    for c in 0..k {
        let Some(p) = (c..k).max_by(|&i, &j| m[i][c].abs().total_cmp(&m[j][c].abs())) else {
            return f64::INFINITY;
        };
        if !m[p][c].is_finite() || m[p][c] == 0.0 {
            return f64::INFINITY;
        }
        m.swap(c, p);
        inv.swap(c, p);
        let d = m[c][c];
        for j in 0..k {
            m[c][j] /= d;
            inv[c][j] /= d;
        }
        for r in 0..k {
            let f = m[r][c];
            if r != c && f != 0.0 {
                for j in 0..k {
                    m[r][j] -= f * m[c][j];
                    inv[r][j] -= f * inv[c][j];
                }
            }
        }
    }
    anorm * norm1(&inv)
}

/// The largest condition number the home may have: the runtime solvers' default `cond_max`
/// (a home past it would make forward or inverse kinematics report `Singular` at once).
const COND_MAX: f64 = 1e7;

/// Checks that the assembled home is a regular configuration of the mechanism: `J_p` (forward
/// kinematics: all rows, the non-actuated columns) and the Jacobian of inverse kinematics (the
/// non-output columns) are square and well conditioned there. A home at a singularity (a
/// flattened parallelogram, a fully stretched leg, a loop with a redundant equation) was
/// accepted without a word; the solvers then start from it and fail. Returns the two condition
/// numbers.
pub fn check_regular(
    model: &Model,
    d: &Derivation,
    home: &[f64],
) -> Result<(f64, f64), DeriveError> {
    let n = d.n;
    let p: Vec<f64> = model.parameters.iter().map(|p| p.value).collect();
    let val = d.graph.eval_all(home, &vec![0.0; n], &p);
    let jac = |cols: &[usize]| -> Vec<Vec<f64>> {
        (0..d.m)
            .map(|i| cols.iter().map(|&j| val[d.g[i][j] as usize]).collect())
            .collect()
    };
    let non_outputs: Vec<usize> = (0..n).filter(|j| !model.outputs.contains(j)).collect();
    // With passive degrees of freedom `J_p` is not square (forward kinematics is unavailable):
    // only the inverse-kinematics Jacobian is checked (and 1 returned for `J_p`).
    let cond_p = if d.passive.len() == d.m {
        cond1(&jac(&d.passive))
    } else {
        1.0
    };
    // Without outputs there is no inverse kinematics (and 1 is returned for it).
    let cond_ik = if model.outputs.is_empty() {
        1.0
    } else {
        cond1(&jac(&non_outputs))
    };
    for (cond, what, does, pos) in [
        (
            cond_p,
            "J_p (forward kinematics)",
            "the actuated coordinates do not determine the others there",
            model.actuated.first(),
        ),
        (
            cond_ik,
            "the inverse-kinematics Jacobian",
            "the outputs do not determine the other coordinates there",
            model.outputs.first(),
        ),
    ] {
        if cond.is_nan() || cond > COND_MAX {
            let pos = pos.map(|&j| model.coordinates[j].pos).unwrap_or_default();
            let cond = if cond.is_finite() {
                format!("{cond:.2e}")
            } else {
                "infinite (a zero pivot)".to_string()
            };
            return Err(DeriveError {
                pos,
                message: format!(
                    "the home configuration is singular: the condition number of {what} is \
                     {cond} at the assembled home ({does}: a flattened parallelogram, a \
                     stretched leg, or a loop equation that repeats another); move the home values \
                     away from the singularity, or check the loops' components"
                ),
            });
        }
    }
    Ok((cond_p, cond_ik))
}

/// Symmetric eigen-decomposition by cyclic Jacobi rotations: (eigenvalues, eigenvectors as
/// columns `v[row][k]`). For the small diagonal blocks of `M`.
fn jacobi_eigen(mut a: Vec<Vec<f64>>) -> (Vec<f64>, Vec<Vec<f64>>) {
    let k = a.len();
    let mut v: Vec<Vec<f64>> = (0..k)
        .map(|i| (0..k).map(|j| f64::from(u8::from(i == j))).collect())
        .collect();
    for _sweep in 0..60 {
        let off: f64 = (0..k)
            .flat_map(|i| (0..k).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i][j] * a[i][j])
            .sum();
        let scale: f64 = (0..k).map(|i| a[i][i] * a[i][i]).sum();
        if off <= 1e-30 * scale.max(f64::MIN_POSITIVE) {
            break;
        }
        for p in 0..k {
            for q in p + 1..k {
                if a[p][q] == 0.0 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for row in a.iter_mut() {
                    let (arp, arq) = (row[p], row[q]);
                    row[p] = c * arp - s * arq;
                    row[q] = s * arp + c * arq;
                }
                let (rp, rq) = (a[p].clone(), a[q].clone());
                a[p] = rp.iter().zip(&rq).map(|(x, y)| c * x - s * y).collect();
                a[q] = rp.iter().zip(&rq).map(|(x, y)| s * x + c * y).collect();
                for row in v.iter_mut() {
                    let (vp, vq) = (row[p], row[q]);
                    row[p] = c * vp - s * vq;
                    row[q] = s * vp + c * vq;
                }
            }
        }
    }
    ((0..k).map(|i| a[i][i]).collect(), v)
}

/// Relative size below which an eigenvalue of a block of `M` counts as zero.
const MASSLESS: f64 = 1e-10;

/// Checks that the dynamics can be solved at the assembled home: every diagonal block of the
/// mass matrix `M` is positive definite, or exactly zero (coordinates of a massless frame that
/// only closes loops, such as a serial arm's end-effector pose: forward dynamics then solves
/// the whole saddle-point system, which needs `M` positive definite on the motions `G` allows,
/// checked here as a non-singular `[M Gᵀ; G 0]`). Bodies may have positive semidefinite inertia
/// (a thin rod has none about its axis); what matters is `M` of the whole robot.
pub fn check_mass(model: &Model, d: &Derivation, home: &[f64]) -> Result<(), DeriveError> {
    let Some(dy) = &d.dynamics else {
        return Ok(());
    };
    let n = d.n;
    let p: Vec<f64> = model.parameters.iter().map(|p| p.value).collect();
    let val = d.graph.eval_all(home, &vec![0.0; n], &p);
    let mass: Vec<Vec<f64>> = dy
        .mass
        .iter()
        .map(|row| row.iter().map(|&id| val[id as usize]).collect())
        .collect();
    let scale = mass
        .iter()
        .enumerate()
        .fold(0.0f64, |s, (i, row)| s.max(row[i].abs()));
    let names = |cols: &[usize]| -> String {
        cols.iter()
            .map(|&j| format!("`{}`", model.coordinates[j].name))
            .collect::<Vec<_>>()
            .join(", ")
    };
    // Masses or inertias beyond f64 (a density of 1e38 over a volume): no eigenvalue to speak
    // of, and no direction to name.
    if let Some(j) = (0..n).find(|&j| mass[j].iter().any(|x| !x.is_finite())) {
        return Err(DeriveError {
            pos: model.coordinates[j].pos,
            message: format!(
                "the mass matrix M is not finite at the assembled home (its row of {}): the \
                 masses or inertias of the bodies it moves overflow f64 (beyond about 1.8e308, \
                 e.g. a density times a volume); give them values within range",
                names(&[j])
            ),
        });
    }
    let mut zero_blocks = Vec::new();
    for block in &dy.mass_blocks {
        let sub: Vec<Vec<f64>> = block
            .iter()
            .map(|&r| block.iter().map(|&c| mass[r][c]).collect())
            .collect();
        if sub.iter().flatten().all(|&x| x == 0.0) {
            zero_blocks.extend(block.iter().copied());
            continue;
        }
        let (values, vectors) = jacobi_eigen(sub);
        let Some((k, &lowest)) = values.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1)) else {
            continue;
        };
        if lowest > MASSLESS * scale && lowest.is_finite() {
            continue;
        }
        // The coordinates of the massless direction (its largest components).
        let big = vectors.iter().fold(0.0f64, |m, row| m.max(row[k].abs()));
        let cols: Vec<usize> = block
            .iter()
            .zip(&vectors)
            .filter(|(_, row)| row[k].abs() >= 0.1 * big)
            .map(|(&j, _)| j)
            .collect();
        let direction: Vec<String> = block
            .iter()
            .zip(&vectors)
            .filter(|(_, row)| row[k].abs() >= 1e-3 * big)
            .map(|(&j, row)| format!("{:+.3} {}", row[k] / big, model.coordinates[j].name))
            .collect();
        return Err(DeriveError {
            pos: model.coordinates[cols.first().copied().unwrap_or(block[0])].pos,
            message: format!(
                "the mass matrix M is not positive definite at the assembled home: moving {} (the direction [{}]) \
                 moves no mass (eigenvalue {lowest:.2e}, largest diagonal entry {scale:.2e}), so forward dynamics \
                 cannot be solved; give the bodies these coordinates move mass or inertia about that motion \
                 (a thin rod has none about its own axis)",
                names(&cols),
                direction.join(", "),
            ),
        });
    }
    if zero_blocks.is_empty() {
        return Ok(());
    }
    // Saddle-point system [M Gᵀ; G 0] at the home: must be non-singular.
    let m = d.m;
    let size = n + m;
    let mut kkt = vec![vec![0.0; size]; size];
    for (row, m_row) in kkt.iter_mut().zip(&mass) {
        row[..n].copy_from_slice(m_row);
    }
    for (i, g_row) in d.g.iter().enumerate().take(m) {
        for (j, &id) in g_row.iter().enumerate().take(n) {
            let g = val[id as usize];
            kkt[n + i][j] = g;
            kkt[j][n + i] = g;
        }
    }
    if is_singular(kkt) {
        zero_blocks.sort_unstable();
        return Err(DeriveError {
            pos: model.coordinates[zero_blocks[0]].pos,
            message: format!(
                "the coordinates {} move no mass, and at the assembled home the loops do not tie them to \
                 coordinates that do: the saddle-point system [M Gᵀ; G 0] is singular, so forward dynamics \
                 cannot be solved; give the bodies these coordinates move mass, or close a loop through them",
                names(&zero_blocks)
            ),
        });
    }
    Ok(())
}

/// True when Gaussian elimination with partial pivoting meets a pivot below `1e-12` of the
/// largest entry (or one that is not finite).
fn is_singular(mut a: Vec<Vec<f64>>) -> bool {
    let k = a.len();
    let big = a.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    for c in 0..k {
        let Some(p) = (c..k).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs())) else {
            return true;
        };
        if !a[p][c].is_finite() || a[p][c].abs() <= 1e-12 * big {
            return true;
        }
        a.swap(c, p);
        for r in c + 1..k {
            let f = a[r][c] / a[c][c];
            if f != 0.0 {
                let (top, bottom) = a.split_at_mut(r);
                for (x, &y) in bottom[0][c..].iter_mut().zip(&top[c][c..]) {
                    *x -= f * y;
                }
            }
        }
    }
    false
}
