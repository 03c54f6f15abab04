//! The joints' own forces (stiffness with rest, damping, armature) on models/spring_pendulum.toml,
//! a hanging double pendulum, against oracles written here and nothing of rbss's kernels:
//!
//! - `M`, `psi`, `T` and `Pi` against the closed-form Lagrangian of a double pendulum of uniform
//!   rods (itself checked against numeric differentiation of its own `T` and `Pi`);
//! - the kernels against numeric differentiation of the generated energy kernel (`M` the Hessian
//!   of `T` in `Xdot`, `psi + damping` Lagrange's expression of `T` and `Pi`, `G` of `f`);
//! - energy: conserved along a simulation without damping, and its rate `dE/dt = U q̇ - c q̇²`
//!   at random states under forward dynamics;
//! - the passive joint (th2, no actuator): forward dynamics, simulation and inverse kinematics
//!   work, forward kinematics and inverse dynamics are refused with a typed error and a message;
//! - `rbss fd` and `rbss simulate`.

// Matrices over index pairs read best with explicit indices.
#![allow(clippy::needless_range_loop)]

mod common;

use common::Rng;
use rbss_runtime::{
    Baumgarte, Data, Dynamics, IntegrateOptions, Kernels, Method, Model, Simulator, SolverError,
    Stabilization, forward_dynamics, forward_kinematics, forward_velocity, inverse_dynamics,
    inverse_kinematics,
};
use spring_pendulum::{M, N, Params, SpringPendulum};

const G: f64 = 9.81;

/// The closed-form Lagrangian of the double pendulum (th1 from the downward vertical, th2
/// relative to link 1, both about +y; uniform rods with the centre of mass at mid-length and
/// `m l² / 12` about it), with the joints' springs, dampers and armatures.
struct Oracle(Params);

impl Oracle {
    /// `[[M11, M12], [M12, M22]]`.
    fn mass(&self, q: [f64; 2]) -> [[f64; 2]; 2] {
        let p = &self.0;
        let (a1, a2) = (p.l1 / 2.0, p.l2 / 2.0);
        let (i1, i2) = (p.m1 * p.l1 * p.l1 / 12.0, p.m2 * p.l2 * p.l2 / 12.0);
        let c2 = q[1].cos();
        let m12 = i2 + p.m2 * (a2 * a2 + p.l1 * a2 * c2);
        [
            [
                i1 + p.m1 * a1 * a1
                    + i2
                    + p.m2 * (p.l1 * p.l1 + a2 * a2 + 2.0 * p.l1 * a2 * c2)
                    + p.J1,
                m12,
            ],
            [m12, i2 + p.m2 * a2 * a2 + p.J2],
        ]
    }
    /// Gravity's and the springs' potential.
    fn potential(&self, q: [f64; 2]) -> f64 {
        let p = &self.0;
        let (a1, a2) = (p.l1 / 2.0, p.l2 / 2.0);
        let z1 = -a1 * q[0].cos();
        let z2 = -p.l1 * q[0].cos() - a2 * (q[0] + q[1]).cos();
        let s1 = q[0] - p.r1;
        let s2 = q[1] - p.r2;
        G * (p.m1 * z1 + p.m2 * z2) + 0.5 * p.k1 * s1 * s1 + 0.5 * p.k2 * s2 * s2
    }
    fn kinetic(&self, q: [f64; 2], v: [f64; 2]) -> f64 {
        let m = self.mass(q);
        0.5 * (m[0][0] * v[0] * v[0] + 2.0 * m[0][1] * v[0] * v[1] + m[1][1] * v[1] * v[1])
    }
    /// `psi = -(Christoffel terms) - ∂Pi/∂q - c q̇`, by hand: with `h = m2 l1 a2 sin th2`,
    /// `C1 = -h (2 q̇1 q̇2 + q̇2²)`, `C2 = h q̇1²`.
    fn psi(&self, q: [f64; 2], v: [f64; 2]) -> [f64; 2] {
        let p = &self.0;
        let a2 = p.l2 / 2.0;
        let h = p.m2 * p.l1 * a2 * q[1].sin();
        let s12 = (q[0] + q[1]).sin();
        let dv1 = G * (p.m1 * p.l1 / 2.0 * q[0].sin() + p.m2 * (p.l1 * q[0].sin() + a2 * s12))
            + p.k1 * (q[0] - p.r1);
        let dv2 = G * p.m2 * a2 * s12 + p.k2 * (q[1] - p.r2);
        [
            h * (2.0 * v[0] * v[1] + v[1] * v[1]) - dv1 - p.c1 * v[0],
            -h * v[0] * v[0] - dv2 - p.c2 * v[1],
        ]
    }
    /// The tip (x, z) and its velocity: a state on the constraint manifold.
    fn state(&self, q: [f64; 2], v: [f64; 2]) -> ([f64; N], [f64; N]) {
        let p = &self.0;
        let (s1, c1) = q[0].sin_cos();
        let (s12, c12) = (q[0] + q[1]).sin_cos();
        let x = -p.l1 * s1 - p.l2 * s12;
        let z = -p.l1 * c1 - p.l2 * c12;
        let w12 = v[0] + v[1];
        let xd = -p.l1 * c1 * v[0] - p.l2 * c12 * w12;
        let zd = p.l1 * s1 * v[0] + p.l2 * s12 * w12;
        ([q[0], q[1], x, z], [v[0], v[1], xd, zd])
    }
}

fn random_q(rng: &mut Rng) -> ([f64; 2], [f64; 2]) {
    (
        [1.5 * rng.sym(), 1.5 * rng.sym()],
        [2.0 * rng.sym(), 2.0 * rng.sym()],
    )
}

/// `|a - b| <= tol (1 + |b|)`, naming the entry.
#[track_caller]
fn close(what: &str, a: f64, b: f64, tol: f64) {
    assert!(
        (a - b).abs() <= tol * (1.0 + b.abs()),
        "{what}: kernel {a:e}, oracle {b:e}, diff {:e}",
        a - b
    );
}

#[test]
fn the_oracle_is_lagrange_of_its_own_energies() {
    // The hand-derived psi against d/dt ∂T/∂q̇ - ∂T/∂q + ∂Pi/∂q by central differences of the
    // oracle's own T and Pi (so a slip in the hand derivation cannot hide in both).
    let o = Oracle(Params::default());
    let mut rng = Rng::new(11);
    let h = 1e-5;
    for _ in 0..16 {
        let (q, v) = random_q(&mut rng);
        let m = o.mass(q);
        let want = o.psi(q, v);
        for k in 0..2 {
            let mut qp = q;
            let mut qm = q;
            qp[k] += h;
            qm[k] -= h;
            // ∂T/∂q_k and ∂Pi/∂q_k
            let dt_dq = (o.kinetic(qp, v) - o.kinetic(qm, v)) / (2.0 * h);
            let dpi = (o.potential(qp) - o.potential(qm)) / (2.0 * h);
            // d/dt (M q̇)_k at q̈ = 0: Σ_l ∂(M q̇)_k/∂q_l q̇_l
            let mut ddt = 0.0;
            for l in 0..2 {
                let mut qp = q;
                let mut qm = q;
                qp[l] += h;
                qm[l] -= h;
                let (mp, mm) = (o.mass(qp), o.mass(qm));
                let row = |m: &[[f64; 2]; 2]| m[k][0] * v[0] + m[k][1] * v[1];
                ddt += (row(&mp) - row(&mm)) / (2.0 * h) * v[l];
            }
            let damping = [o.0.c1, o.0.c2][k] * v[k];
            let lagrange = -(ddt - dt_dq) - dpi - damping;
            close(&format!("oracle psi[{k}]"), want[k], lagrange, 1e-8);
        }
        assert!(m[0][0] > 0.0 && m[0][0] * m[1][1] > m[0][1] * m[0][1]);
    }
}

#[test]
fn kernels_match_the_closed_form_lagrangian() {
    // Default parameters and others (the kernels take the parameters at run time).
    let others = Params {
        k1: 0.0,
        c2: 0.4,
        J1: 0.05,
        r2: 0.7,
        m2: 1.7,
        ..Params::default()
    };
    let mut rng = Rng::new(3);
    let mut worst = 0.0_f64;
    for params in [Params::default(), others] {
        let robot = SpringPendulum::new(&params);
        let o = Oracle(params);
        for _ in 0..32 {
            let (q, v) = random_q(&mut rng);
            let (x, xdot) = o.state(q, v);
            let mut mass = [[0.0; N]; N];
            let mut psi = [0.0; N];
            let mut energy = [0.0; 2];
            robot.mass_matrix(&x, &mut mass);
            robot.psi(&x, &xdot, &mut psi);
            robot.energy(&x, &xdot, &mut energy);
            let (m_o, psi_o) = (o.mass(q), o.psi(q, v));
            for i in 0..N {
                for j in 0..N {
                    let want = if i < 2 && j < 2 { m_o[i][j] } else { 0.0 };
                    close(&format!("M[{i}][{j}]"), mass[j][i], want, 1e-13);
                    worst = worst.max((mass[j][i] - want).abs());
                }
                let want = if i < 2 { psi_o[i] } else { 0.0 };
                close(&format!("psi[{i}]"), psi[i], want, 1e-13);
                worst = worst.max((psi[i] - want).abs());
            }
            close("T", energy[0], o.kinetic(q, v), 1e-13);
            close("Pi", energy[1], o.potential(q), 1e-13);
            // The dynamics_terms kernel (fused) agrees with the separate ones.
            let (mut g, mut gamma, mut mass2, mut psi2) =
                ([[0.0; M]; N], [0.0; M], [[0.0; N]; N], [0.0; N]);
            robot.dynamics_terms(&x, &xdot, &mut g, &mut gamma, &mut mass2, &mut psi2);
            for i in 0..N {
                close(&format!("fused psi[{i}]"), psi2[i], psi[i], 1e-14);
                for j in 0..N {
                    close(
                        &format!("fused M[{i}][{j}]"),
                        mass2[j][i],
                        mass[j][i],
                        1e-14,
                    );
                }
            }
        }
    }
    println!(
        "spring_pendulum: M, psi against the closed form, worst absolute difference {worst:.1e}"
    );
}

#[test]
fn kernels_match_numeric_differentiation() {
    let robot = SpringPendulum::default();
    let p = Params::default();
    let mut rng = Rng::new(5);
    let energy = |x: &[f64; N], v: &[f64; N]| {
        let mut e = [0.0; 2];
        robot.energy(x, v, &mut e);
        e
    };
    for _ in 0..32 {
        let x: [f64; N] = std::array::from_fn(|_| 1.5 * rng.sym());
        let v: [f64; N] = std::array::from_fn(|_| 2.0 * rng.sym());
        let (mut mass, mut psi, mut g) = ([[0.0; N]; N], [0.0; N], [[0.0; M]; N]);
        robot.mass_matrix(&x, &mut mass);
        robot.psi(&x, &v, &mut psi);
        robot.jacobian(&x, &mut g);
        // T is quadratic in Xdot: its Hessian by central differences is exact up to rounding,
        // and ½ Xdotᵀ M Xdot = T.
        let h = 1e-3;
        let mut quad = 0.0;
        for i in 0..N {
            for j in 0..N {
                quad += 0.5 * v[i] * mass[j][i] * v[j];
                let t = |di: f64, dj: f64| {
                    let mut w = v;
                    w[i] += di;
                    w[j] += dj;
                    energy(&x, &w)[0]
                };
                let hess = (t(h, h) - t(h, -h) - t(-h, h) + t(-h, -h)) / (4.0 * h * h);
                close(&format!("M[{i}][{j}] vs ∂²T"), mass[j][i], hess, 1e-7);
            }
        }
        close("½ Xdotᵀ M Xdot vs T", quad, energy(&x, &v)[0], 1e-13);
        // psi + c q̇ = -(d/dt ∂T/∂Xdot - ∂T/∂X) - ∂Pi/∂X at Xddot = 0, from the energy kernel:
        // d/dt ∂T/∂Xdot_k at Xddot = 0 is Σ_l ∂(M Xdot)_k/∂X_l Xdot_l, a directional derivative.
        let h = 1e-5;
        let along = |s: f64| -> [f64; N] { std::array::from_fn(|l| x[l] + s * v[l]) };
        let (mut mp, mut mm) = ([[0.0; N]; N], [[0.0; N]; N]);
        robot.mass_matrix(&along(h), &mut mp);
        robot.mass_matrix(&along(-h), &mut mm);
        for k in 0..N {
            let row = |m: &[[f64; N]; N]| (0..N).map(|l| m[l][k] * v[l]).sum::<f64>();
            let ddt = (row(&mp) - row(&mm)) / (2.0 * h);
            let mut xp = x;
            let mut xm = x;
            xp[k] += h;
            xm[k] -= h;
            let (ep, em) = (energy(&xp, &v), energy(&xm, &v));
            let dt_dx = (ep[0] - em[0]) / (2.0 * h);
            let dpi = (ep[1] - em[1]) / (2.0 * h);
            let damping = match k {
                0 => p.c1 * v[0],
                1 => p.c2 * v[1],
                _ => 0.0,
            };
            close(
                &format!("psi[{k}] + damping vs Lagrange"),
                psi[k] + damping,
                -(ddt - dt_dx) - dpi,
                1e-7,
            );
        }
        // G = ∂f/∂X.
        for j in 0..N {
            let (mut fp, mut fm) = ([0.0; M], [0.0; M]);
            let mut xp = x;
            let mut xm = x;
            xp[j] += h;
            xm[j] -= h;
            robot.constraints(&xp, &mut fp);
            robot.constraints(&xm, &mut fm);
            for i in 0..M {
                close(
                    &format!("G[{i}][{j}]"),
                    g[j][i],
                    (fp[i] - fm[i]) / (2.0 * h),
                    1e-8,
                );
            }
        }
    }
}

/// `E = T + Pi` from the generated energy kernel.
fn total_energy(robot: &SpringPendulum, x: &[f64; N], xdot: &[f64; N]) -> f64 {
    let mut e = [0.0; 2];
    robot.energy(x, xdot, &mut e);
    e[0] + e[1]
}

#[test]
fn energy_rate_is_the_power_of_the_actuators_minus_the_dampers() {
    // dE/dt = U·q̇ - Σ c q̇² at any state: the springs are in Pi, the loop's multipliers do no
    // work. dE/dt by a central difference of the energy kernel along (Xdot, Xddot).
    let p = Params::default();
    let robot = SpringPendulum::new(&p);
    let model = Model::new(robot);
    let mut data = Data::new(&model);
    let o = Oracle(p);
    let mut rng = Rng::new(9);
    let mut worst = 0.0_f64;
    for trial in 0..32 {
        let (q, v) = random_q(&mut rng);
        let (x, xdot) = o.state(q, v);
        // th1 is driven, th2 is the passive spring joint.
        let u = if trial % 2 == 0 { 0.0 } else { rng.sym() };
        data.x = x;
        data.xdot = xdot;
        forward_dynamics(&model, &mut data, &[u], None, Baumgarte::NONE).unwrap();
        let xddot = data.xddot;
        // Accelerations reach some 300 rad/s² (light links, stiff springs): a short step.
        let h = 1e-4;
        let shifted = |s: f64| {
            let xs: [f64; N] = std::array::from_fn(|i| x[i] + s * xdot[i] + 0.5 * s * s * xddot[i]);
            let vs: [f64; N] = std::array::from_fn(|i| xdot[i] + s * xddot[i]);
            total_energy(&robot, &xs, &vs)
        };
        // Central differences at h and h/2, Richardson-extrapolated (error O(h⁴)).
        let d = |h: f64| (shifted(h) - shifted(-h)) / (2.0 * h);
        let rate = (4.0 * d(h / 2.0) - d(h)) / 3.0;
        let want = u * v[0] - p.c1 * v[0] * v[0] - p.c2 * v[1] * v[1];
        close(&format!("dE/dt (trial {trial})"), rate, want, 1e-9);
        worst = worst.max((rate - want).abs());
    }
    println!("spring_pendulum: dE/dt against U q̇ - c q̇², worst {worst:.1e} W");
}

#[test]
fn energy_is_conserved_without_damping_and_decays_with_it() {
    let start = Oracle(Params::default()).state([1.0, -0.6], [0.0, 1.5]);
    for (case, (c1, c2)) in [(0.0, 0.0), (0.05, 0.03)].into_iter().enumerate() {
        let p = Params {
            c1,
            c2,
            ..Params::default()
        };
        let robot = SpringPendulum::new(&p);
        let model = Model::new(robot);
        let mut data = Data::new(&model);
        let options =
            IntegrateOptions::new(Method::dopri5(1e-11, 1e-13), Stabilization::Projection);
        let mut sim = Simulator::new(&model, &mut data, 0.0, &start.0, &start.1, options).unwrap();
        let e0 = total_energy(&robot, sim.x(), sim.xdot());
        // Energy lost in the dampers, ∫ Σ c q̇² dt, by the trapezoidal rule over the steps.
        let mut dissipated = 0.0;
        let mut last = (0.0, c1 * start.1[0].powi(2) + c2 * start.1[1].powi(2));
        let mut worst = 0.0_f64;
        let mut no_control = |_: f64, _: &[f64; N], _: &[f64; N], u: &mut [f64]| {
            u.fill(0.0);
            Ok(())
        };
        sim.run(&model, &mut data, 3.0, &mut no_control, |s| {
            let v = s.xdot();
            let power = c1 * v[0] * v[0] + c2 * v[1] * v[1];
            dissipated += 0.5 * (power + last.1) * (s.t() - last.0);
            last = (s.t(), power);
            let e = total_energy(&robot, s.x(), s.xdot());
            worst = worst.max((e - e0).abs());
        })
        .unwrap();
        let e_end = total_energy(&robot, sim.x(), sim.xdot());
        if case == 0 {
            // Conserved to the integrator's tolerance.
            assert!(worst < 1e-8, "energy drift without damping: {worst:e} J");
        } else {
            // Decays by what the dampers dissipated (the trapezoidal rule over dopri5's steps:
            // its error bounds the comparison).
            assert!(e_end < e0 - 1e-3, "no decay: {e0} -> {e_end}");
            let rel = ((e0 - e_end) - dissipated).abs() / dissipated;
            assert!(
                rel < 1e-3,
                "energy lost {:e} J against dissipated {dissipated:e} J (rel {rel:e})",
                e0 - e_end
            );
        }
        println!(
            "spring_pendulum c = ({c1}, {c2}): E {e0:.6} -> {e_end:.6} J over 3 s, max |E - E0| {worst:.1e}, dissipated {dissipated:.6} J"
        );
    }
}

#[test]
fn the_passive_joint_leaves_the_tasks_that_need_square_actuation_unavailable() {
    // th2 is a passive spring joint: 2 degrees of freedom, 1 actuated coordinate.
    let model = Model::new(SpringPendulum::default());
    let s = model.structure();
    assert!(!s.fully_actuated());
    assert_eq!(
        (s.actuated, s.passive.len(), s.outputs.len()),
        (&[0][..], 3, 2)
    );
    let under = |e: SolverError, want: &str| {
        assert!(
            matches!(e, SolverError::Underactuated { task, dof: 2, actuated: 1 } if task == want),
            "{want}: {e:?}"
        );
    };
    let mut data = Data::new(&model);
    let home: [f64; N] = s.home.try_into().unwrap();
    data.x = home;
    data.xdot = [0.0; N];
    data.xddot = [0.0; N];
    under(
        forward_kinematics(&model, &mut data, &[0.3]).unwrap_err(),
        "forward kinematics",
    );
    under(
        forward_velocity(&model, &mut data, &[0.1]).unwrap_err(),
        "forward velocity",
    );
    under(
        inverse_dynamics(&model, &mut data, None).unwrap_err(),
        "inverse dynamics",
    );
    // Inverse kinematics needs no actuation: the tip's position gives both angles back.
    data.x = [0.5, 0.2, 0.0, 0.0];
    inverse_kinematics(&model, &mut data, &[home[2], home[3]]).unwrap();
    assert!(
        common::max_diff(&data.x, &home) < 1e-10,
        "{:?} vs {home:?}",
        data.x
    );
    // The command says why, and which tasks remain.
    for args in [
        &["fk", "--model", "spring_pendulum", "--q", "0.3"][..],
        &["fk", "--model", "spring_pendulum", "--q", "0.3", "--direct"][..],
    ] {
        let (ok, _, stderr) = common::rbss(args);
        assert!(!ok, "{args:?}");
        assert!(
            stderr.contains("forward kinematics is unavailable: the robot has 2 degrees of freedom but 1 actuated coordinate (the others are passive)")
                && stderr.contains("forward dynamics, simulation and the energy do not"),
            "{args:?}: {stderr}"
        );
    }
    let dir = tempfile::tempdir().unwrap();
    let traj = dir.path().join("tip.toml");
    std::fs::write(&traj, "x = \"-0.333 + 0.01*t\"\nz = \"-0.591\"\n").unwrap();
    let csv = dir.path().join("u.csv");
    let (ok, _, stderr) = common::rbss(&[
        "inverse-dynamics",
        "--model",
        "spring_pendulum",
        "--trajectory",
        traj.to_str().unwrap(),
        "--csv",
        csv.to_str().unwrap(),
    ]);
    assert!(
        !ok && stderr.contains("inverse dynamics is unavailable"),
        "{stderr}"
    );
    assert!(!csv.exists());
}

#[test]
fn fd_and_simulate_commands() {
    // `rbss fd` at a state against the runtime's forward dynamics, and `rbss simulate` from it
    // under a table of U.
    let o = Oracle(Params::default());
    let (x, xdot) = o.state([0.7, -0.4], [0.5, 1.0]);
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state.json");
    std::fs::write(
        &state,
        serde_json::json!({"X": x, "Xdot": xdot, "U": [0.25]}).to_string(),
    )
    .unwrap();
    let (ok, stdout, stderr) = common::rbss(&[
        "fd",
        "--model",
        "spring_pendulum",
        "--state",
        state.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let model = Model::new(SpringPendulum::default());
    let mut data = Data::new(&model);
    data.x = x;
    data.xdot = xdot;
    forward_dynamics(&model, &mut data, &[0.25], None, Baumgarte::NONE).unwrap();
    for i in 0..N {
        assert_eq!(v["Xddot"][i].as_f64().unwrap(), data.xddot[i], "Xddot[{i}]");
    }
    for i in 0..M {
        assert_eq!(
            v["lambda"][i].as_f64().unwrap(),
            data.lambda[i],
            "lambda[{i}]"
        );
    }
    let res = v["residual"][0].as_f64().unwrap();
    assert!(res < 1e-12, "residual {res:e}");
    let p = Params::default();
    assert_eq!(v["energy"][1].as_f64().unwrap(), {
        let mut e = [0.0; 2];
        SpringPendulum::new(&p).energy(&x, &xdot, &mut e);
        e[1]
    });
    // A table of U: linear between rows.
    std::fs::write(
        &state,
        serde_json::json!({"X": x, "Xdot": xdot, "U_table": [[0.0, 0.0], [0.5, 1.0]]}).to_string(),
    )
    .unwrap();
    let out = dir.path().join("sim");
    let (ok, stdout, stderr) = common::rbss(&[
        "simulate",
        "--model",
        "spring_pendulum",
        "--state",
        state.to_str().unwrap(),
        "--t-end",
        "1",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    let csv = std::fs::read_to_string(out.join("simulate.csv")).unwrap();
    let header = csv.lines().next().unwrap();
    assert_eq!(header, "t,th1,th2,x,z,th1_dot,th2_dot,x_dot,z_dot,T,Pi,E");
    let last: Vec<f64> = csv
        .lines()
        .last()
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    assert_eq!(last[0], 1.0);
    assert!(stdout.contains("energy"), "{stdout}");
    // Bad input is named: the wrong number of forces.
    std::fs::write(
        &state,
        serde_json::json!({"X": x, "Xdot": xdot, "U": [1.0, 2.0]}).to_string(),
    )
    .unwrap();
    let (ok, _, stderr) = common::rbss(&[
        "fd",
        "--model",
        "spring_pendulum",
        "--state",
        state.to_str().unwrap(),
    ]);
    assert!(
        !ok && stderr.contains("\"U\" has 2 values, the robot has 1 actuated coordinates"),
        "{stderr}"
    );
}
