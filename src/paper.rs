//! The paper's example (../shared/paper-example.md): the platform motion `TraekP` of the
//! 6-UPS robot, with its exact first and second time derivatives.

/// `w` of the paper's example, rad/s (assumed there: the paper gives no value).
pub const OMEGA: f64 = std::f64::consts::PI;
/// The motion runs over `t` in `[0, T_END]` s (one period).
pub const T_END: f64 = 2.0;

/// Platform pose `[x, y, z, rotx, roty, rotz]` and its first and second time derivatives at
/// time `t` for angular frequency `w`:
///
/// ```text
/// x = 0.1 cos(wt)   y = 0.1 sin(wt)   z = 0.94 (1 + 0.01 sin(3wt))
/// rotx = 0.1 cos(2wt)   roty = 0.1 sin(2wt)   rotz = 0.1 cos(2wt) sin(2wt) = 0.05 sin(4wt)
/// ```
pub fn traek_p(t: f64, w: f64) -> ([f64; 6], [f64; 6], [f64; 6]) {
    let (s1, c1) = (w * t).sin_cos();
    let (s2, c2) = (2.0 * w * t).sin_cos();
    let (s3, c3) = (3.0 * w * t).sin_cos();
    let (s4, c4) = (4.0 * w * t).sin_cos();
    let pos = [
        0.1 * c1,
        0.1 * s1,
        0.94 * (1.0 + 0.01 * s3),
        0.1 * c2,
        0.1 * s2,
        0.05 * s4,
    ];
    let vel = [
        -0.1 * w * s1,
        0.1 * w * c1,
        0.94 * 0.03 * w * c3,
        -0.2 * w * s2,
        0.2 * w * c2,
        0.2 * w * c4,
    ];
    let w2 = w * w;
    let acc = [
        -0.1 * w2 * c1,
        -0.1 * w2 * s1,
        -0.94 * 0.09 * w2 * s3,
        -0.4 * w2 * c2,
        -0.4 * w2 * s2,
        -0.8 * w2 * s4,
    ];
    (pos, vel, acc)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The closed-form derivatives against central differences of the pose.
    #[test]
    fn derivatives_match_differences() {
        let h = 1e-5;
        for k in 0..50 {
            let t = k as f64 * 0.04;
            let (_, v, a) = traek_p(t, OMEGA);
            let (pp, vp, _) = traek_p(t + h, OMEGA);
            let (pm, vm, _) = traek_p(t - h, OMEGA);
            for i in 0..6 {
                assert!(
                    ((pp[i] - pm[i]) / (2.0 * h) - v[i]).abs() < 1e-8,
                    "velocity {i} at t = {t}"
                );
                assert!(
                    ((vp[i] - vm[i]) / (2.0 * h) - a[i]).abs() < 1e-7,
                    "acceleration {i} at t = {t}"
                );
            }
        }
    }
}

/// One kinematic sample of the paper's robot along TraekP.
#[derive(Debug, Clone, Copy)]
pub struct KinematicSample {
    pub t: f64,
    pub x: [f64; stewart_6ups::N],
    pub xdot: [f64; stewart_6ups::N],
    pub xddot: [f64; stewart_6ups::N],
}

/// `t_k = k t_end / (samples - 1)`, `k = 0 .. samples`.
pub fn sample_times(t_end: f64, samples: usize) -> Vec<f64> {
    let last = samples.saturating_sub(1).max(1) as f64;
    (0..samples).map(|k| t_end * k as f64 / last).collect()
}

/// Inverse kinematics, velocity and acceleration of the paper's robot along TraekP (the
/// paper's figure 4), warm-started from one sample to the next. Returns the samples and the
/// largest IK residual.
pub fn inverse_kinematics_along(
    model: &rbss_runtime::Model<
        stewart_6ups::Stewart6Ups,
        { stewart_6ups::N },
        { stewart_6ups::M },
    >,
    omega: f64,
    times: &[f64],
) -> Result<(Vec<KinematicSample>, f64), String> {
    use rbss_runtime::{Data, inverse_acceleration, inverse_kinematics, inverse_velocity};
    let mut data = Data::new(model);
    let mut out = Vec::with_capacity(times.len());
    let mut worst: f64 = 0.0;
    for &t in times {
        let (pos, vel, acc) = traek_p(t, omega);
        let rep = inverse_kinematics(model, &mut data, &pos)
            .map_err(|e| format!("t = {t}: inverse kinematics: {e}"))?;
        worst = worst.max(rep.residual);
        inverse_velocity(model, &mut data, &vel)
            .map_err(|e| format!("t = {t}: inverse velocity: {e}"))?;
        inverse_acceleration(model, &mut data, &acc)
            .map_err(|e| format!("t = {t}: inverse acceleration: {e}"))?;
        out.push(KinematicSample {
            t,
            x: data.x,
            xdot: data.xdot,
            xddot: data.xddot,
        });
    }
    Ok((out, worst))
}

/// The paper's robot with its default parameters.
pub type Robot =
    rbss_runtime::Model<stewart_6ups::Stewart6Ups, { stewart_6ups::N }, { stewart_6ups::M }>;

/// One inverse-dynamics sample: the control forces `U` (on d1..d6, N) and the multipliers.
#[derive(Debug, Clone, Copy)]
pub struct ForceSample {
    pub t: f64,
    pub u: [f64; 6],
    pub lambda: [f64; stewart_6ups::M],
    /// Condition estimate of the reduced system solved for `U`.
    pub cond: f64,
}

/// Inverse dynamics at the kinematic samples (the paper's eqs. 33-36 and figure 5).
pub fn inverse_dynamics_along(
    model: &Robot,
    samples: &[KinematicSample],
) -> Result<Vec<ForceSample>, String> {
    use rbss_runtime::{Data, inverse_dynamics};
    let mut data = Data::new(model);
    let mut out = Vec::with_capacity(samples.len());
    for s in samples {
        data.x = s.x;
        data.xdot = s.xdot;
        data.xddot = s.xddot;
        let rep = inverse_dynamics(model, &mut data, None)
            .map_err(|e| format!("t = {}: inverse dynamics: {e}", s.t))?;
        let mut u = [0.0; 6];
        u.copy_from_slice(&data.u[..6]);
        out.push(ForceSample {
            t: s.t,
            u,
            lambda: data.lambda,
            cond: rep.cond,
        });
    }
    Ok(out)
}

/// `t, U1..U6, lambda1..lambda18` rows.
pub fn force_table(forces: &[ForceSample]) -> (Vec<String>, Vec<Vec<f64>>) {
    let mut header = vec!["t".to_string()];
    header.extend(crate::csv::numbered("U", 6));
    header.extend(crate::csv::numbered("lambda", stewart_6ups::M));
    let rows = forces
        .iter()
        .map(|f| {
            let mut r = vec![f.t];
            r.extend_from_slice(&f.u);
            r.extend_from_slice(&f.lambda);
            r
        })
        .collect();
    (header, rows)
}
