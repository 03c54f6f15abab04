//! Closed-form kinematics of the paper's 6-UPS, written from `../shared/paper-example.md`
//! independently of the generated kernels: platform joint positions, the leg solution
//! `d_i, phi_i, psi_i` of a pose, and the rotation matrix of the pose.
//!
//! The stress scenes use it to place the robot exactly on a path, including at singular poses
//! where Newton-based inverse kinematics is itself ill-conditioned.

use crate::robots::stewart_6ups;
use crate::robots::stewart_6ups::{M, N, Params};

/// Base angles `alpha_i`, platform angles `beta_i` (rad) and the radii of the default robot.
pub struct Geometry {
    pub alpha: [f64; 6],
    pub beta: [f64; 6],
    pub r0: f64,
    pub rp: f64,
    pub h: f64,
}

impl Default for Geometry {
    fn default() -> Self {
        Self::new(&Params::default())
    }
}

/// `Rx(a) Ry(b) Rz(c)`, row-major.
pub fn rotation_xyz(a: f64, b: f64, c: f64) -> [[f64; 3]; 3] {
    let (sa, ca) = a.sin_cos();
    let (sb, cb) = b.sin_cos();
    let (sc, cc) = c.sin_cos();
    [
        [cb * cc, -cb * sc, sb],
        [ca * sc + sa * sb * cc, ca * cc - sa * sb * sc, -sa * cb],
        [sa * sc - ca * sb * cc, sa * cc + ca * sb * sc, ca * cb],
    ]
}

/// The angles `(a, b, c)` of `R = Rx(a) Ry(b) Rz(c)` (with `|b| < pi/2`).
pub fn xyz_angles(r: &[[f64; 3]; 3]) -> [f64; 3] {
    let b = r[0][2].clamp(-1.0, 1.0).asin();
    let a = (-r[1][2]).atan2(r[2][2]);
    let c = (-r[0][1]).atan2(r[0][0]);
    [a, b, c]
}

/// The rotation by `angle` about the unit axis `k` (Rodrigues), row-major.
pub fn axis_angle(k: [f64; 3], angle: f64) -> [[f64; 3]; 3] {
    let (s, c) = angle.sin_cos();
    let v = 1.0 - c;
    let [x, y, z] = k;
    [
        [c + x * x * v, x * y * v - z * s, x * z * v + y * s],
        [y * x * v + z * s, c + y * y * v, y * z * v - x * s],
        [z * x * v - y * s, z * y * v + x * s, c + z * z * v],
    ]
}

fn mat_vec(r: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    [
        r[0][0] * v[0] + r[0][1] * v[1] + r[0][2] * v[2],
        r[1][0] * v[0] + r[1][1] * v[1] + r[1][2] * v[2],
        r[2][0] * v[0] + r[2][1] * v[1] + r[2][2] * v[2],
    ]
}

impl Geometry {
    pub fn new(p: &Params) -> Self {
        Geometry {
            alpha: [p.alpha1, p.alpha2, p.alpha3, p.alpha4, p.alpha5, p.alpha6],
            beta: [p.beta1, p.beta2, p.beta3, p.beta4, p.beta5, p.beta6],
            r0: p.r0,
            rp: p.rp,
            h: p.h,
        }
    }

    /// Base joint `0_i` in the world frame.
    pub fn base_joint(&self, i: usize) -> [f64; 3] {
        let (s, c) = self.alpha[i].sin_cos();
        [self.r0 * c, self.r0 * s, 0.0]
    }

    /// Platform joint `P_i` in the platform frame: `Rz(beta_i) Tz(h) Tx(rp)`.
    pub fn platform_point(&self, i: usize) -> [f64; 3] {
        let (s, c) = self.beta[i].sin_cos();
        [self.rp * c, self.rp * s, self.h]
    }

    /// Platform joint `P_i` in the world frame at `pose = [x, y, z, rotx, roty, rotz]`.
    pub fn platform_joint(&self, pose: &[f64; 6], i: usize) -> [f64; 3] {
        let r = rotation_xyz(pose[3], pose[4], pose[5]);
        let p = mat_vec(&r, self.platform_point(i));
        [pose[0] + p[0], pose[1] + p[1], pose[2] + p[2]]
    }

    /// The leg solution of a pose in closed form: `d_i = |P_i - 0_i|` and, with
    /// `w = Rz(-alpha_i) (P_i - 0_i) / d_i = (sin psi, -sin phi cos psi, cos phi cos psi)`,
    /// `psi_i = atan2(w_x, |(w_y, w_z)|)`,
    /// `phi_i = atan2(-w_y, w_z)`: the assembly with `d_i > 0` and
    /// `|psi_i| <= pi/2`, `|phi_i| <= pi` (`|phi_i| < pi/2` while the leg points up). At
    /// `psi_i = ±pi/2` (the universal joint's own singularity) `phi_i` is arbitrary; this returns
    /// `atan2` of the rounding residue there.
    pub fn x_of_pose(&self, pose: &[f64; 6]) -> [f64; N] {
        let mut x = [0.0; N];
        for i in 0..6 {
            let p = self.platform_joint(pose, i);
            let b = self.base_joint(i);
            let v = [p[0] - b[0], p[1] - b[1], p[2] - b[2]];
            let d = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            let (s, c) = self.alpha[i].sin_cos();
            let w = [
                (c * v[0] + s * v[1]) / d,
                (-s * v[0] + c * v[1]) / d,
                v[2] / d,
            ];
            x[i] = d;
            // atan2, not asin: accurate near psi = ±pi/2 as well.
            x[12 + i] = w[0].atan2(w[1].hypot(w[2]));
            x[6 + i] = (-w[1]).atan2(w[2]);
        }
        x[18..24].copy_from_slice(pose);
        x
    }
}

/// `max |f(x)|` of the generated kernels (a check of the closed form).
pub fn residual(x: &[f64; N]) -> f64 {
    use rbss_runtime::Kernels;
    let mut f = [0.0; M];
    stewart_6ups::Stewart6Ups::default().constraints(x, &mut f);
    f.iter().fold(0.0, |m: f64, v| m.max(v.abs()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closed_form_matches_home_and_kernels() {
        let g = Geometry::default();
        let home = stewart_6ups::STRUCTURE.home;
        let pose: [f64; 6] = home[18..24].try_into().unwrap();
        let x = g.x_of_pose(&pose);
        for j in 0..N {
            assert!(
                (x[j] - home[j]).abs() < 1e-10,
                "{j}: {} vs {}",
                x[j],
                home[j]
            );
        }
        let pose = [0.03, -0.05, 0.9, 0.2, -0.1, 0.3];
        assert!(residual(&g.x_of_pose(&pose)) < 1e-15);
        let r = rotation_xyz(0.2, -0.1, 0.3);
        let a = xyz_angles(&r);
        assert!((a[0] - 0.2).abs() < 1e-15 && (a[1] + 0.1).abs() < 1e-15);
        assert!((a[2] - 0.3).abs() < 1e-15);
    }
}
