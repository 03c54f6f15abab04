//! The first derivatives of the equations of motion, by the chain rule through the graph's named
//! intermediates (nothing is expanded): of the inverse-dynamics residual
//! `r(X, Xdot, Xddot, lambda) = M(X) Xddot - psi(X, Xdot) + G(X)ᵀ lambda` and of the
//! acceleration constraint `c(X, Xdot, Xddot) = G(X) Xddot - gamma(X, Xdot)`.
//!
//! `Xddot` and `lambda` enter as kernel inputs ([`Node::In`](crate::graph::Node::In)): the
//! residuals are built as graph nodes over them and differentiated with [`Graph::diff`], so
//! `∂r/∂X` is the directional product `Σ_k ∂M_ik/∂X_j Xddot_k + ...` sharing `M`'s, `G`'s and
//! `psi`'s intermediates (and their memoised derivatives) instead of an `n × n × n` tensor.

use super::Derivation;
use crate::graph::{Graph, Id, Seed};

/// The four derivative matrices, row-major (`[row][col]`); [`Graph::ZERO`] is a structural zero.
pub struct DynamicsDerivatives {
    /// `∂r/∂X` (n × n) at the given `Xddot`, `lambda`.
    pub dr_dx: Vec<Vec<Id>>,
    /// `∂r/∂Xdot = -∂psi/∂Xdot` (n × n).
    pub dr_dxdot: Vec<Vec<Id>>,
    /// `∂c/∂X = ∂(G Xddot - gamma)/∂X` (m × n) at the given `Xddot`.
    pub dc_dx: Vec<Vec<Id>>,
    /// `∂c/∂Xdot = -∂gamma/∂Xdot` (m × n).
    pub dc_dxdot: Vec<Vec<Id>>,
}

/// Adds the derivatives to the derivation's graph; `None` without dynamics. The kernel input
/// `In(k)` is `Xddot[k]` for `k < n`, then `lambda[k - n]`.
pub fn dynamics_derivatives(d: &mut Derivation) -> Option<DynamicsDerivatives> {
    let dy = d.dynamics.as_ref()?;
    let (n, m) = (d.n, d.m);
    let g = &mut d.graph;
    let a: Vec<Id> = (0..n).map(|k| g.input(k)).collect();
    let l: Vec<Id> = (0..m).map(|k| g.input(n + k)).collect();
    let r: Vec<Id> = (0..n)
        .map(|i| {
            let mut terms = Vec::new();
            for k in 0..n {
                let mik = dy.mass[i.min(k)][i.max(k)];
                if mik != Graph::ZERO {
                    terms.push(g.mul(mik, a[k]));
                }
            }
            terms.push(g.neg(dy.psi[i]));
            for (row, &lam) in d.g.iter().zip(&l) {
                if row[i] != Graph::ZERO {
                    terms.push(g.mul(row[i], lam));
                }
            }
            g.sum(&terms)
        })
        .collect();
    let c: Vec<Id> = (0..m)
        .map(|row| {
            let mut terms: Vec<Id> = (0..n)
                .filter(|&k| d.g[row][k] != Graph::ZERO)
                .map(|k| g.mul(d.g[row][k], a[k]))
                .collect();
            terms.push(g.neg(dy.gamma[row]));
            g.sum(&terms)
        })
        .collect();
    let jac = |g: &mut Graph, f: &[Id], seed: fn(u32) -> Seed| -> Vec<Vec<Id>> {
        f.iter()
            .map(|&fi| (0..n).map(|j| g.diff(fi, seed(j as u32))).collect())
            .collect()
    };
    Some(DynamicsDerivatives {
        dr_dx: jac(g, &r, Seed::X),
        dr_dxdot: jac(g, &r, Seed::V),
        dc_dx: jac(g, &c, Seed::X),
        dc_dxdot: jac(g, &c, Seed::V),
    })
}
