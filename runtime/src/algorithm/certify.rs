//! Certificates of position solves and assembly modes.
//!
//! A converged Newton iterate is a root of the equations solved, but not necessarily the
//! configuration asked for:
//!
//! - **Spurious roots.** A loop written with fewer components than its points have (the UR5's
//!   tool axes: equal `x`, `y` components of two unit vectors fix the axis up to its sign) has
//!   mirror roots that close every equation solved. The generator emits the components left out
//!   as `closure_check` ([`Kernels::closure_checks`](crate::Kernels::closure_checks)); every
//!   position solver calls [`certify_position`] after convergence and reports
//!   [`SolverError::SpuriousRoot`] instead of returning such a root.
//! - **Assembly modes.** Several configurations close the loops for the same actuated values
//!   (forward kinematics) or outputs (inverse kinematics). A [`ModeSignature`] is what the
//!   structure can see of a configuration's mode: the sign of the determinant of every
//!   inverse-kinematics block's `G_r` (one per leg: a leg's working mode, e.g. its elbow up or
//!   down) and of `J_p` (the assembly mode of forward kinematics). A sign changes only through a
//!   singularity of that block, so two configurations whose signatures differ are in different
//!   modes; equal signatures do not prove the same mode (an even number of flips inside one
//!   block keeps its sign).
//! - **Continuation** ([`path`](super::path)): [`forward_kinematics_path`](super::path::forward_kinematics_path)
//!   and [`inverse_kinematics_path`](super::path::inverse_kinematics_path) walk along a segment
//!   keeping the start's mode, with these signatures.

use super::input::check_finite;
use crate::error::{ModePart, SolverError};
use crate::linalg;
use crate::model::Model;
use crate::tasks::{Constraints, ForwardKinematics, InverseKinematics};

/// The certificate's tolerance on the unsolved loop components, as a multiple of
/// `SolverOptions::tol_f`: `1e4 tol_f` (`1e-8` m or rad by default). A correct root leaves them at
/// the level of the solved residual magnified by the conditioning of the loop's formulation (a
/// UR5 tool axis 1e-3 rad from horizontal: about `1e3 tol_f`); a mirror root leaves them at twice
/// the distance of the loop point from the mirror plane.
pub const CERTIFY_FACTOR: f64 = 1e4;

/// Checks the loop components the model does not solve ([`Constraints::closure_checks`]) at
/// `x`: `Ok(max |c|)` (0 when there are none), or [`SolverError::SpuriousRoot`] naming the
/// worst component when it exceeds `CERTIFY_FACTOR · tol_f`. Allocation-free.
pub fn certify_position<K: Constraints<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    x: &[f64; N],
) -> Result<f64, SolverError> {
    let k = model.kernels();
    let count = k.closure_checks().len();
    if count == 0 {
        return Ok(0.0);
    }
    // At most two left out per loop, and every loop solves at least one: count <= 2 M.
    let mut buf = [[0.0; M]; 2];
    let out = buf.as_flattened_mut();
    if count > out.len() {
        return Err(SolverError::Dimension {
            what: "closure checks (at most 2 M)",
            expected: out.len(),
            found: count,
        });
    }
    let out = &mut out[..count];
    k.closure_check(x, out);
    check_finite("closure checks (kernel output)", out)?;
    let (worst, residual) = out
        .iter()
        .enumerate()
        .fold((0, 0.0_f64), |(w, r), (i, &v)| {
            if v.abs() > r { (i, v.abs()) } else { (w, r) }
        });
    if residual > CERTIFY_FACTOR * model.options.tol_f {
        return Err(SolverError::SpuriousRoot {
            check: worst,
            residual,
        });
    }
    Ok(residual)
}

/// The assembly mode of a configuration as the structure sees it: the sign of `det G_r` of
/// every inverse-kinematics block (`Structure::ik_blocks` order, rows and columns in their
/// listed order) and the sign of `det J_p` (all rows, the passive columns in
/// `Structure::passive` order). A sign is `0` where the matrix is exactly singular or not
/// finite. See the [module](self) documentation for what a signature proves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ModeSignature<const M: usize> {
    blocks: [i8; M],
    count: usize,
    jp: i8,
}

impl<const M: usize> ModeSignature<M> {
    /// The signs of the inverse-kinematics blocks' determinants.
    pub fn blocks(&self) -> &[i8] {
        &self.blocks[..self.count]
    }

    /// The sign of `det J_p`.
    pub fn jp(&self) -> i8 {
        self.jp
    }

    /// The first part whose sign differs between `self` (the start) and `other`, with both
    /// signs; parts singular (`0`) in either are not compared, nor parts that `parts` leaves
    /// out.
    pub fn first_difference(&self, other: &Self, parts: Parts) -> Option<(ModePart, i8, i8)> {
        let differs = |a: i8, b: i8| a != 0 && b != 0 && a != b;
        if parts != Parts::Jp {
            for (b, (&s, &o)) in self.blocks().iter().zip(other.blocks()).enumerate() {
                if differs(s, o) {
                    return Some((ModePart::Block(b), s, o));
                }
            }
        }
        (parts != Parts::Blocks && differs(self.jp, other.jp)).then_some((
            ModePart::Jp,
            self.jp,
            other.jp,
        ))
    }

    /// Compact text: the blocks' signs, then `/` and `J_p`'s, e.g. `++-+++/-`.
    pub fn text(&self) -> String {
        let c = |s: i8| match s {
            1 => '+',
            -1 => '-',
            _ => '0',
        };
        let mut t: String = self.blocks().iter().map(|&s| c(s)).collect();
        t.push('/');
        t.push(c(self.jp));
        t
    }
}

/// Which parts of a [`ModeSignature`] a comparison looks at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Parts {
    /// The inverse-kinematics blocks (the legs' working modes): what inverse kinematics keeps.
    Blocks,
    /// `J_p` only: what a forward-kinematics path keeps. Along a path where `J_p` stays
    /// regular, the solution is unique and continuous (implicit function theorem), so a leg's
    /// block may pass its own singularity (a serial arm's wrist through `q5 = 0`, a leg
    /// stretched) and the mechanism with it: that is the configuration the actuators reach.
    Jp,
    /// Both: what a direct forward-kinematics solve is compared on (one jump, no path to vouch
    /// for a change).
    All,
}

/// The sign of the determinant of the column-major `k × k` matrix `a` (destroyed), `0` if it is
/// exactly singular or not finite.
fn det_sign(a: &mut [f64], k: usize, piv: &mut [usize]) -> i8 {
    if linalg::lu_factor(a, k, &mut piv[..k]).is_err() {
        return 0;
    }
    let mut neg = false;
    for (j, &p) in piv[..k].iter().enumerate() {
        neg ^= p != j;
        neg ^= a[j * k + j] < 0.0;
    }
    if neg { -1 } else { 1 }
}

/// The [`ModeSignature`] of `x`: one `constraints_jacobian_ik` and one `constraints_jacobian_p`
/// call, an LU of each block and of `J_p`. Allocation-free (stack buffers of `M × M`); writes
/// nothing of `data`.
pub fn mode_signature<K, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    x: &[f64; N],
) -> ModeSignature<M>
where
    K: InverseKinematics<N, M> + ForwardKinematics<N, M>,
{
    let s = model.structure();
    let k = model.kernels();
    let mut f = [0.0; M];
    let mut g = [[0.0; M]; N];
    let mut a = [[0.0; M]; M];
    let mut piv = [0usize; M];
    let mut sig = ModeSignature {
        blocks: [0; M],
        count: s.ik_blocks.len().min(M),
        jp: 0,
    };
    k.constraints_jacobian_ik(x, &mut f, &mut g);
    for (b, blk) in s.ik_blocks.iter().take(M).enumerate() {
        let n = blk.rows.len();
        if n != blk.cols.len() || n > M {
            continue;
        }
        let flat = a.as_flattened_mut();
        for (c, &j) in blk.cols.iter().enumerate() {
            for (r, &i) in blk.rows.iter().enumerate() {
                flat[c * n + r] = g[j][i];
            }
        }
        sig.blocks[b] = det_sign(&mut flat[..n * n], n, &mut piv);
    }
    let mut g = [[0.0; M]; N];
    k.constraints_jacobian_p(x, &mut f, &mut g);
    for (c, &j) in s.passive.iter().take(M).enumerate() {
        a[c] = g[j];
    }
    // With passive degrees of freedom `J_p` is not square: no assembly-mode sign (0).
    if s.fully_actuated() {
        sig.jp = det_sign(a.as_flattened_mut(), M, &mut piv);
    }
    sig
}
