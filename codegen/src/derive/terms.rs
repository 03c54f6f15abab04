//! What the two recursive forms of `M` and `psi` (`world.rs`, `local.rs`) share:
//! a point mass's inertia about an origin, and the terms of `M` and `psi` over the joints.

use super::sum_terms;
use crate::graph::{Graph, Id};

/// `m (|c|² 1 - c cᵀ)`: the inertia about the origin of a point mass `m` at `c` (both
/// triangles filled).
pub fn steiner(g: &mut Graph, m: Id, c: &[Id; 3]) -> [[Id; 3]; 3] {
    let mut out = [[Graph::ZERO; 3]; 3];
    for i in 0..3 {
        for j in i..3 {
            let t = if i == j {
                let sq: Vec<Id> = (0..3)
                    .filter(|&l| l != i)
                    .map(|l| g.mul(c[l], c[l]))
                    .collect();
                g.sum(&sq)
            } else {
                let cc = g.mul(c[i], c[j]);
                g.neg(cc)
            };
            out[i][j] = g.mul(m, t);
            out[j][i] = out[i][j];
        }
    }
    out
}

/// The coordinates a joint's argument depends on, `(k, ∂theta/∂X_k)` (see `theta_coords`).
pub type Coords = [(usize, Id)];

/// The terms of `M` (upper triangle) and `psi` over the joints of a recursive form, through
/// their arguments `theta(X)` (`coords`: `(k, ∂theta/∂X_k)`): `psi_k -= ∂theta_s/∂X_k Q_s`,
/// `M_kl += ∂theta_s/∂X_k ∂theta_t/∂X_l K_st`.
pub struct JointTerms {
    mass: Vec<Vec<Vec<Id>>>,
    psi: Vec<Vec<Id>>,
}

impl JointTerms {
    pub fn new(n: usize) -> JointTerms {
        JointTerms {
            mass: vec![vec![Vec::new(); n]; n],
            psi: vec![Vec::new(); n],
        }
    }

    /// The generalized force `q = Q_s` of a joint.
    pub fn force(&mut self, g: &mut Graph, coords: &Coords, q: Id) {
        for &(k, d) in coords {
            let dq = g.mul(d, q);
            self.psi[k].push(g.neg(dq));
        }
    }

    /// `e = K_st` of joints `s` (at or above `t`) and `t`; `same` when they are one joint.
    pub fn inertia(&mut self, g: &mut Graph, s: &Coords, t: &Coords, same: bool, e: Id) {
        let orders: &[(&Coords, &Coords)] = if same { &[(s, t)] } else { &[(s, t), (t, s)] };
        for &(u, w) in orders {
            for &(k, du) in u {
                for &(l, dw) in w {
                    if k <= l {
                        let d = g.mul(du, dw);
                        self.mass[k][l].push(g.mul(d, e));
                    }
                }
            }
        }
    }

    /// `M` (upper triangle) and `psi`, like terms collected.
    pub fn sum(self, g: &mut Graph) -> (Vec<Vec<Id>>, Vec<Id>) {
        sum_terms(g, &self.mass, &self.psi)
    }
}
