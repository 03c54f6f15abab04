//! A hand-written robot for the runtime's tests: the planar five-bar linkage.
//!
//! Base joints at `(-B, 0)` and `(B, 0)`; proximal links `L1`, distal links `L2`.
//! `X = [th1, a1, th2, a2, x, y]`: `th_i` absolute base angles (actuated), `a_i` elbow angles
//! relative to the proximal link, `(x, y)` the effector point (the outputs).
//!
//! ```text
//! f0 = -B + L1 cos th1 + L2 cos(th1 + a1) - x      left.x
//! f1 =      L1 sin th1 + L2 sin(th1 + a1) - y      left.y
//! f2 =  B + L1 cos th2 + L2 cos(th2 + a2) - x      right.x
//! f3 =      L1 sin th2 + L2 sin(th2 + a2) - y      right.y
//! ```
//!
//! With `w1 = th1'`, `w12 = th1' + a1'`: `d²/dt² (L1 cos th1 + L2 cos th12)
//! = G_row Xddot - L1 cos th1 w1² - L2 cos th12 w12²`, so
//! `gamma0 = L1 cos th1 w1² + L2 cos th12 w12²`, `gamma1 = L1 sin th1 w1² + L2 sin th12 w12²`,
//! and the same for the right arm.

#![allow(dead_code)]

use rbss_runtime::{IkBlock, Kernels, Structure};

pub const N: usize = 6;
pub const M: usize = 4;
/// Half the distance between the base joints [m].
pub const B: f64 = 0.15;
/// Proximal link length [m].
pub const L1: f64 = 0.2;
/// Distal link length [m].
pub const L2: f64 = 0.25;

/// Home: effector at (0, 0.3), both elbows out (left elbow left of the line base -> effector,
/// right elbow right of it); symmetric, th2 = pi - th1, a2 = -a1.
pub const HOME: [f64; N] = [
    1.9426305917723186,
    -1.4706289056333368,
    1.1989620618174746,
    1.4706289056333368,
    0.0,
    0.3,
];

pub static STRUCTURE: Structure = Structure {
    name: "five_bar",
    coordinates: &["th1", "a1", "th2", "a2", "x", "y"],
    constraints: &["left.x", "left.y", "right.x", "right.y"],
    actuated: &[0, 2],
    passive: &[1, 3, 4, 5],
    outputs: &[4, 5],
    ik_blocks: &[
        IkBlock {
            rows: &[0, 1],
            cols: &[0, 1],
        },
        IkBlock {
            rows: &[2, 3],
            cols: &[2, 3],
        },
    ],
    home: &HOME,
    gear: &[],
};

#[derive(Debug, Clone, Copy, Default)]
pub struct FiveBar;

/// Writes the columns `cols` (a subset of 0..6) of G; only structural non-zeros.
fn write_jacobian(x: &[f64; N], g: &mut [[f64; M]; N], cols: [bool; N]) {
    let (s1, c1) = x[0].sin_cos();
    let (s12, c12) = (x[0] + x[1]).sin_cos();
    let (s2, c2) = x[2].sin_cos();
    let (s22, c22) = (x[2] + x[3]).sin_cos();
    if cols[0] {
        g[0][0] = -L1 * s1 - L2 * s12;
        g[0][1] = L1 * c1 + L2 * c12;
    }
    if cols[1] {
        g[1][0] = -L2 * s12;
        g[1][1] = L2 * c12;
    }
    if cols[2] {
        g[2][2] = -L1 * s2 - L2 * s22;
        g[2][3] = L1 * c2 + L2 * c22;
    }
    if cols[3] {
        g[3][2] = -L2 * s22;
        g[3][3] = L2 * c22;
    }
    if cols[4] {
        g[4][0] = -1.0;
        g[4][2] = -1.0;
    }
    if cols[5] {
        g[5][1] = -1.0;
        g[5][3] = -1.0;
    }
}

impl Kernels<N, M> for FiveBar {
    fn structure(&self) -> &'static Structure {
        &STRUCTURE
    }

    fn constraints(&self, x: &[f64; N], f: &mut [f64; M]) {
        let (s1, c1) = x[0].sin_cos();
        let (s12, c12) = (x[0] + x[1]).sin_cos();
        let (s2, c2) = x[2].sin_cos();
        let (s22, c22) = (x[2] + x[3]).sin_cos();
        f[0] = (-B + L1 * c1 + L2 * c12) - x[4];
        f[1] = (L1 * s1 + L2 * s12) - x[5];
        f[2] = (B + L1 * c2 + L2 * c22) - x[4];
        f[3] = (L1 * s2 + L2 * s22) - x[5];
    }

    fn jacobian(&self, x: &[f64; N], g: &mut [[f64; M]; N]) {
        write_jacobian(x, g, [true; N]);
    }

    fn jacobian_p(&self, x: &[f64; N], g: &mut [[f64; M]; N]) {
        write_jacobian(x, g, [false, true, false, true, true, true]);
    }

    fn jacobian_ik(&self, x: &[f64; N], g: &mut [[f64; M]; N]) {
        write_jacobian(x, g, [true, true, true, true, false, false]);
    }

    fn gamma(&self, x: &[f64; N], xdot: &[f64; N], gamma: &mut [f64; M]) {
        let (s1, c1) = x[0].sin_cos();
        let (s12, c12) = (x[0] + x[1]).sin_cos();
        let (s2, c2) = x[2].sin_cos();
        let (s22, c22) = (x[2] + x[3]).sin_cos();
        let w1 = xdot[0] * xdot[0];
        let w12 = (xdot[0] + xdot[1]) * (xdot[0] + xdot[1]);
        let w2 = xdot[2] * xdot[2];
        let w22 = (xdot[2] + xdot[3]) * (xdot[2] + xdot[3]);
        gamma[0] = L1 * c1 * w1 + L2 * c12 * w12;
        gamma[1] = L1 * s1 * w1 + L2 * s12 * w12;
        gamma[2] = L1 * c2 * w2 + L2 * c22 * w22;
        gamma[3] = L1 * s2 * w2 + L2 * s22 * w22;
    }
}

/// Is the effector point (px, py) reachable by both arms with a margin `m` [m] from the
/// workspace boundary (|P - base| in [L2 - L1 + m, L1 + L2 - m])?
pub fn reachable(px: f64, py: f64, m: f64) -> bool {
    let dl = (px + B).hypot(py);
    let dr = (px - B).hypot(py);
    let ok = |d: f64| d >= L2 - L1 + m && d <= L1 + L2 - m;
    ok(dl) && ok(dr)
}
