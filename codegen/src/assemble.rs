//! Assembling the home configuration: the model's `home` values need only be a rough guess.
//!
//! With the outputs held at their home values, Newton's method on `f(X) = 0` over the other
//! coordinates (the inverse-kinematics unknowns, a square system by the IK blocks' check), with
//! the generated expressions evaluated numerically, step halving when a step does not reduce
//! `max |f|`. The assembled values become the generated crate's `STRUCTURE.home`, the solvers'
//! cold start; the model file keeps the guess.

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

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m: f64, x| m.max(x.abs()))
}

/// Solves `a x = b` (`a` row-major, `k × k`) by Gaussian elimination with partial pivoting;
/// `None` when a pivot is zero or not finite.
fn solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
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
    let unknowns: Vec<usize> = (0..n).filter(|&j| !is_output[j]).collect();
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
        let Some(dx) = solve(jac, rhs) else {
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
