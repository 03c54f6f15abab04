//! The paper's example (../shared/paper-example.md): the platform motion `TraekP` of the
//! 6-UPS robot, with its exact first and second time derivatives.

use crate::robots::stewart_6ups;

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

/// `t_k = k t_end / (samples - 1)`, `k = 0 .. samples`.
pub fn sample_times(t_end: f64, samples: usize) -> Vec<f64> {
    let last = samples.saturating_sub(1).max(1) as f64;
    (0..samples).map(|k| t_end * k as f64 / last).collect()
}

/// Inverse kinematics and dynamics along a trajectory, for any robot: along TraekP they give the
/// paper's figures 4 and 5 (`inverse_kinematics_along(&robot, &TraekP { omega }, &times)`).
pub use crate::trajectory::{inverse_dynamics_along, inverse_kinematics_along};

/// The samples and their table, generic over the robot (re-exported: the paper's own are the
/// defaults of the type parameters).
pub use crate::trajectory::{ForceSample, KinematicSample, force_table};

/// The paper's robot with its default parameters.
pub type Robot =
    rbss_runtime::Model<stewart_6ups::Stewart6Ups, { stewart_6ups::N }, { stewart_6ups::M }>;

/// How `rbss paper` integrates the forward dynamics.
#[derive(Debug, Clone, Copy)]
pub struct PaperOptions {
    pub omega: f64,
    pub t_end: f64,
    /// Kinematic and inverse-dynamics samples (figures 4 and 5), `t_k = k t_end / (samples - 1)`.
    pub samples: usize,
    pub integrate: rbss_runtime::IntegrateOptions,
}

impl Default for PaperOptions {
    fn default() -> Self {
        use rbss_runtime::{IntegrateOptions, Method, Stabilization};
        PaperOptions {
            omega: OMEGA,
            t_end: T_END,
            samples: 2001,
            integrate: IntegrateOptions::new(
                Method::dopri5(1e-10, 1e-12),
                Stabilization::Projection,
            ),
        }
    }
}

/// The figures of the paper's check, measured.
#[derive(Debug, Clone, Default)]
pub struct PaperSummary {
    pub samples: usize,
    pub max_ik_residual: f64,
    pub max_id_cond: f64,
    pub max_u: f64,
    /// Max |x, y, z simulated - TraekP| over every accepted step (m).
    pub position_error: f64,
    /// Max |rotx, roty, rotz simulated - TraekP| (rad).
    pub rotation_error: f64,
    /// Max platform velocity error (m/s or rad/s).
    pub velocity_error: f64,
    /// Max platform acceleration error (m/s² or rad/s²), from forward dynamics at the
    /// simulated states.
    pub acceleration_error: f64,
    /// Max |f(X)| seen after the accepted steps (before any projection).
    pub max_violation: f64,
    pub stats: rbss_runtime::IntegrateStats,
    pub kinematics_secs: f64,
    pub inverse_dynamics_secs: f64,
    /// Wall time of the integration alone.
    pub integration_secs: f64,
    pub total_secs: f64,
}

/// One recorded simulation state of the paper's robot (the generic type, re-exported).
pub use crate::trajectory::{Integration, SimState};

const PLATFORM: std::ops::Range<usize> = 18..24;
const POSE_NAMES: [&str; 6] = ["x", "y", "z", "rotx", "roty", "rotz"];

/// The paper's section 4 end to end: inverse kinematics along TraekP, inverse dynamics, then
/// forward dynamics from the `t = 0` state under the control forces `U(t)` evaluated exactly at
/// every integrator stage time (inverse kinematics + inverse dynamics at `t`, not held over a
/// step). Writes CSV files and PNG figures to `out` and returns the measured gaps.
pub fn run(
    out: &std::path::Path,
    opts: &PaperOptions,
    progress: &mut dyn FnMut(&str),
) -> Result<PaperSummary, String> {
    use rbss_runtime::{Data, Model, forward_dynamics};
    use std::time::Instant;
    let t_all = Instant::now();
    crate::trajectory::check_samples(opts.samples)?;
    crate::create_output_dir(out)?;
    let model: Robot = Model::new(stewart_6ups::Stewart6Ups::default());
    let mut sum = PaperSummary {
        samples: opts.samples,
        ..Default::default()
    };

    progress(&format!(
        "inverse kinematics along TraekP: {} samples over [0, {}] s",
        opts.samples, opts.t_end
    ));
    let t0 = Instant::now();
    let times = sample_times(opts.t_end, opts.samples);
    let traek = TraekP { omega: opts.omega };
    let (kin, worst) = inverse_kinematics_along(&model, &traek, &times)?;
    sum.kinematics_secs = t0.elapsed().as_secs_f64();
    sum.max_ik_residual = worst;

    progress("inverse dynamics: control forces U and multipliers lambda");
    let t1 = Instant::now();
    let forces = inverse_dynamics_along(&model, &kin)?;
    sum.inverse_dynamics_secs = t1.elapsed().as_secs_f64();
    sum.max_id_cond = forces.iter().map(|f| f.cond).fold(0.0, f64::max);
    sum.max_u = forces
        .iter()
        .flat_map(|f| f.u().iter().map(|u| u.abs()))
        .fold(0.0, f64::max);

    // --- forward dynamics ---
    progress(&format!(
        "forward dynamics: {:?}, {:?}",
        opts.integrate.method, opts.integrate.stabilization
    ));
    let omega = opts.omega;
    let sim = integrate(
        &model,
        &kin[0].x,
        &kin[0].xdot,
        omega,
        opts.t_end,
        opts.integrate,
        true,
    )?;
    sum.integration_secs = sim.secs;
    sum.stats = sim.stats;
    sum.max_violation = sum.stats.max_violation;
    let record = sim.states;
    let mut control = round_trip_control(&model, omega, &kin[0].x);

    // --- compare with TraekP at every accepted step ---
    progress(&format!(
        "comparing {} simulated states with TraekP",
        record.len()
    ));
    let mut acc_data = Data::new(&model);
    let mut rows = Vec::with_capacity(record.len());
    let mut u = [0.0; 6];
    for s in &record {
        let (p, v, a) = traek_p(s.t, omega);
        control(s.t, &s.x, &s.xdot, &mut u)
            .map_err(|e| format!("t = {}: control: {e}", rbss_runtime::integrate::Time(s.t)))?;
        acc_data.x = s.x;
        acc_data.xdot = s.xdot;
        forward_dynamics(
            &model,
            &mut acc_data,
            &u,
            None,
            rbss_runtime::Baumgarte::NONE,
        )
        .map_err(|e| {
            format!(
                "t = {}: forward dynamics: {e}",
                rbss_runtime::integrate::Time(s.t)
            )
        })?;
        let mut row = vec![s.t];
        for i in 0..6 {
            let (xs, vs, as_) = (
                s.x[PLATFORM][i],
                s.xdot[PLATFORM][i],
                acc_data.xddot[PLATFORM][i],
            );
            let e = (xs - p[i]).abs();
            if i < 3 {
                sum.position_error = sum.position_error.max(e);
            } else {
                sum.rotation_error = sum.rotation_error.max(e);
            }
            sum.velocity_error = sum.velocity_error.max((vs - v[i]).abs());
            sum.acceleration_error = sum.acceleration_error.max((as_ - a[i]).abs());
            row.extend_from_slice(&[p[i], xs, v[i], vs, a[i], as_]);
        }
        rows.push(row);
    }

    // --- CSV ---
    progress(&format!("writing CSV and PNG files to {}", out.display()));
    let mut kh = vec!["t".to_string()];
    for suffix in ["", "_dot", "_ddot"] {
        for name in stewart_6ups::STRUCTURE.coordinates {
            kh.push(format!("{name}{suffix}"));
        }
    }
    let krows: Vec<Vec<f64>> = kin
        .iter()
        .map(|s| {
            let mut r = vec![s.t];
            r.extend_from_slice(&s.x);
            r.extend_from_slice(&s.xdot);
            r.extend_from_slice(&s.xddot);
            r
        })
        .collect();
    // Every CSV and figure of the run together, or none (the old set stays).
    let mut files = crate::output::Outputs::new();
    crate::csv::write_to(&mut files, &out.join("inverse_kinematics.csv"), &kh, &krows)?;
    let (fh, frows) = force_table(&forces);
    crate::csv::write_to(&mut files, &out.join("inverse_dynamics.csv"), &fh, &frows)?;
    let mut sh = vec!["t".to_string()];
    for n in POSE_NAMES {
        for k in ["ref", "sim", "dot_ref", "dot_sim", "ddot_ref", "ddot_sim"] {
            sh.push(format!("{n}_{k}"));
        }
    }
    crate::csv::write_to(&mut files, &out.join("forward_dynamics.csv"), &sh, &rows)?;

    // --- figures ---
    figures(&mut files, out, &kin, &forces, &rows)?;
    files.commit()?;
    sum.total_secs = t_all.elapsed().as_secs_f64();
    Ok(sum)
}

fn figures(
    files: &mut crate::output::Outputs,
    out: &std::path::Path,
    kin: &[KinematicSample],
    forces: &[ForceSample],
    sim_rows: &[Vec<f64>],
) -> Result<(), String> {
    use crate::plot::{Panel, Series, write_png_to};
    let t: Vec<f64> = kin.iter().map(|s| s.t).collect();
    let legs = |f: &dyn Fn(&KinematicSample, usize) -> f64, title: &str, unit: &str, name: &str| {
        let mut p = Panel::new(title, "t [s]", unit);
        for i in 0..6 {
            p = p.with(Series::new(
                format!("{name}{}", i + 1),
                t.clone(),
                kin.iter().map(|s| f(s, i)).collect(),
            ));
        }
        p
    };
    write_png_to(
        files,
        &out.join("fig4_inverse_kinematics.png"),
        "Fig. 4: inverse kinematics along TraekP (legs)",
        &[
            legs(&|s, i| s.x[i], "leg lengths d_i", "m", "d"),
            legs(&|s, i| s.xdot[i], "leg velocities d_i'", "m/s", "d"),
            legs(&|s, i| s.xddot[i], "leg accelerations d_i''", "m/s²", "d"),
            legs(&|s, i| s.x[6 + i], "joint angles phi_i", "rad", "phi"),
            legs(&|s, i| s.x[12 + i], "joint angles psi_i", "rad", "psi"),
            legs(&|s, i| s.xdot[6 + i], "joint rates phi_i'", "rad/s", "phi"),
        ],
        3,
        1500,
        900,
    )?;
    let ft: Vec<f64> = forces.iter().map(|f| f.t).collect();
    let mut pu = Panel::new("control forces U_i", "t [s]", "N");
    for i in 0..6 {
        pu = pu.with(Series::new(
            format!("U{}", i + 1),
            ft.clone(),
            forces.iter().map(|f| f.u[i]).collect(),
        ));
    }
    let mut lam_panels = vec![pu];
    for (c, axis) in ["x", "y", "z"].iter().enumerate() {
        let mut p = Panel::new(format!("multipliers lambda (leg i, {axis})"), "t [s]", "N");
        for i in 0..6 {
            p = p.with(Series::new(
                format!("leg{}", i + 1),
                ft.clone(),
                forces.iter().map(|f| f.lambda[3 * i + c]).collect(),
            ));
        }
        lam_panels.push(p);
    }
    write_png_to(
        files,
        &out.join("fig5_inverse_dynamics.png"),
        "Fig. 5: inverse dynamics: control forces and multipliers",
        &lam_panels,
        2,
        1300,
        900,
    )?;

    let st: Vec<f64> = sim_rows.iter().map(|r| r[0]).collect();
    let col =
        |i: usize, k: usize| -> Vec<f64> { sim_rows.iter().map(|r| r[1 + 6 * i + k]).collect() };
    for (fig, k, what, units) in [
        ("fig6_platform_position", 0usize, "position", ["m", "rad"]),
        ("fig7_platform_velocity", 2, "velocity", ["m/s", "rad/s"]),
        (
            "fig8_platform_acceleration",
            4,
            "acceleration",
            ["m/s²", "rad/s²"],
        ),
    ] {
        let mut panels = Vec::new();
        for i in 0..6 {
            let unit = units[usize::from(i >= 3)];
            panels.push(
                Panel::new(format!("{} {what}", POSE_NAMES[i]), "t [s]", unit)
                    .with(Series::new("TraekP (commanded)", st.clone(), col(i, k)))
                    .with(Series::new("forward dynamics", st.clone(), col(i, k + 1)).reference()),
            );
        }
        for (group, range, unit) in [
            ("x, y, z", 0..3, units[0]),
            ("rotx, roty, rotz", 3..6, units[1]),
        ] {
            let mut p = Panel::new(
                format!("|simulated - commanded| {what}: {group}"),
                "t [s]",
                unit,
            )
            .log_y();
            for i in range {
                let (r, s) = (col(i, k), col(i, k + 1));
                p = p.with(Series::new(
                    POSE_NAMES[i],
                    st.clone(),
                    r.iter().zip(&s).map(|(a, b)| (a - b).abs()).collect(),
                ));
            }
            panels.push(p);
        }
        let n = fig[3..4].to_string();
        write_png_to(
            files,
            &out.join(format!("{fig}.png")),
            &format!("Fig. {n}: platform {what}, TraekP vs forward dynamics under U(t)"),
            &panels,
            4,
            1800,
            800,
        )?;
    }
    Ok(())
}

/// The control of the paper's round trip: [`crate::trajectory::control`] along TraekP (`U(t)`
/// by inverse kinematics and dynamics of TraekP at `t`, warm-started from `x0` and then from the
/// previous sample's Taylor polynomial). A `Simulator` control callback.
pub fn round_trip_control<'a>(
    model: &'a Robot,
    omega: f64,
    x0: &[f64; stewart_6ups::N],
) -> impl FnMut(
    f64,
    &[f64; stewart_6ups::N],
    &[f64; stewart_6ups::N],
    &mut [f64],
) -> Result<(), rbss_runtime::SolverError>
+ 'a {
    crate::trajectory::control(model, TraekP { omega }, x0)
}

/// Forward dynamics of the paper's robot from `(x0, xdot0)` at `t = 0` to `t_end` under the
/// round trip's control [`round_trip_control`] with the given integrator settings; writes no
/// file. With `report`, a progress line goes to stderr every quarter of the run once it has
/// taken a second. [`crate::trajectory::integrate`] along TraekP.
pub fn integrate(
    model: &Robot,
    x0: &[f64; stewart_6ups::N],
    xdot0: &[f64; stewart_6ups::N],
    omega: f64,
    t_end: f64,
    options: rbss_runtime::IntegrateOptions,
    report: bool,
) -> Result<Integration, String> {
    crate::trajectory::integrate(
        model,
        &TraekP { omega },
        0.0,
        x0,
        xdot0,
        t_end,
        options,
        report,
    )
}

/// Max |platform position - TraekP| (m) and max |platform rotation - TraekP| (rad) over the
/// states.
pub fn pose_errors(states: &[SimState], omega: f64) -> (f64, f64) {
    let (mut ep, mut er) = (0.0_f64, 0.0_f64);
    for s in states {
        let (p, _, _) = traek_p(s.t, omega);
        for (i, (xs, xr)) in s.x[PLATFORM].iter().zip(&p).enumerate() {
            let e = (xs - xr).abs();
            if i < 3 {
                ep = ep.max(e);
            } else {
                er = er.max(e);
            }
        }
    }
    (ep, er)
}

/// The paper's platform trajectory of `stewart_6ups` ([`traek_p`]).
#[derive(Debug, Clone, Copy)]
pub struct TraekP {
    /// Angular frequency `w` (rad/s).
    pub omega: f64,
}

impl crate::trajectory::Trajectory for TraekP {
    fn dim(&self) -> usize {
        6
    }

    fn eval(&self, t: f64, pos: &mut [f64], vel: &mut [f64], acc: &mut [f64]) {
        let (p, v, a) = traek_p(t, self.omega);
        for (d, s) in pos.iter_mut().zip(p) {
            *d = s;
        }
        for (d, s) in vel.iter_mut().zip(v) {
            *d = s;
        }
        for (d, s) in acc.iter_mut().zip(a) {
            *d = s;
        }
    }

    fn describe(&self) -> String {
        format!("TraekP (w = {} rad/s)", self.omega)
    }
}
