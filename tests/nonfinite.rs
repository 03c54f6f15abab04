//! Non-finite and absurd inputs to every solver, on both generated robots: NaN, ±inf (and the
//! finite but absurd 1e300, -1e300 and f64::MAX) in each argument and in each `Data` field a
//! solver reads.
//!
//! - NaN or ±inf: the solver fails with `SolverError::NonFinite` naming the input (or
//!   `IntegrateError::InvalidOptions` / `IntegrateError::Solver` for the simulator), and
//!   leaves its outputs as they were (its documented contract);
//! - 1e300 and friends are finite, so the solvers may accept them, but they never panic and
//!   never return a NaN or an infinity: either a typed error (outputs untouched) or finite
//!   results.
//!
//! The generated kernels are plain arithmetic functions without checks: a NaN in gives NaN out
//! (the last test shows it); the solvers are where inputs are checked.

use rbss_runtime::{
    Baumgarte, Data, Dynamics, IntegrateError, IntegrateOptions, LmOptions, Method, Model,
    Simulator, SolverError, Stabilization, forward_acceleration, forward_dynamics,
    forward_kinematics, forward_kinematics_lm, forward_velocity, inverse_acceleration,
    inverse_dynamics, inverse_dynamics_dense, inverse_kinematics, inverse_velocity,
    project_position, project_velocity,
};

const NON_FINITE: [f64; 3] = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY];
const HUGE: [f64; 3] = [1e300, -1e300, f64::MAX];

/// The outputs a solver may write, bit for bit (NaN == NaN).
fn snapshot<const N: usize, const M: usize>(d: &Data<N, M>) -> Vec<u64> {
    d.x.iter()
        .chain(&d.xdot)
        .chain(&d.xddot)
        .chain(&d.u)
        .chain(&d.lambda)
        .map(|v| v.to_bits())
        .collect()
}

fn all_finite<const N: usize, const M: usize>(d: &Data<N, M>) -> bool {
    d.x.iter()
        .chain(&d.xdot)
        .chain(&d.xddot)
        .chain(&d.u)
        .chain(&d.lambda)
        .all(|v| v.is_finite())
}

/// Runs `solve` on a copy of `base` after `corrupt`; checks the outcome for the value `v`.
fn check<const N: usize, const M: usize, T, E: std::fmt::Display + std::fmt::Debug>(
    what: &str,
    v: f64,
    base: &Data<N, M>,
    corrupt: impl FnOnce(&mut Data<N, M>),
    solve: impl FnOnce(&mut Data<N, M>) -> Result<T, E>,
    is_non_finite_error: impl Fn(&E) -> bool,
) {
    let mut d = base.clone();
    corrupt(&mut d);
    let before = snapshot(&d);
    match solve(&mut d) {
        Err(e) => {
            if !v.is_finite() {
                assert!(
                    is_non_finite_error(&e),
                    "{what} = {v}: expected a non-finite error, got {e:?}"
                );
                let msg = e.to_string();
                assert!(
                    msg.contains("non-finite") || msg.contains("invalid"),
                    "{what} = {v}: unclear message `{msg}`"
                );
            }
            assert_eq!(
                before,
                snapshot(&d),
                "{what} = {v}: the solver changed its outputs on error ({e})"
            );
        }
        Ok(_) => {
            assert!(v.is_finite(), "{what} = {v}: accepted");
            assert!(
                all_finite(&d),
                "{what} = {v}: succeeded with a non-finite result"
            );
        }
    }
}

fn non_finite(e: &SolverError) -> bool {
    matches!(e, SolverError::NonFinite { .. })
}

/// Every solver of `model` with every bad value in every argument, from a consistent state at
/// the home pose with non-zero rates. Returns the number of calls checked.
fn check_robot<K: Dynamics<N, M>, const N: usize, const M: usize>(model: &Model<K, N, M>) -> usize {
    let s = model.structure();
    let (n_out, n_act) = (s.outputs.len(), s.actuated.len());
    let pose: Vec<f64> = s.outputs.iter().map(|&j| s.home[j]).collect();
    let rates: Vec<f64> = (0..n_out).map(|i| 0.1 * (i as f64 + 1.0)).collect();
    let accels: Vec<f64> = (0..n_out).map(|i| 1.0 - 0.3 * i as f64).collect();
    let mut base = Data::new(model);
    inverse_kinematics(model, &mut base, &pose).unwrap();
    inverse_velocity(model, &mut base, &rates).unwrap();
    inverse_acceleration(model, &mut base, &accels).unwrap();
    inverse_dynamics(model, &mut base, None).unwrap();
    let q: Vec<f64> = s.actuated.iter().map(|&j| base.x[j]).collect();
    let qd: Vec<f64> = s.actuated.iter().map(|&j| base.xdot[j]).collect();
    let qdd: Vec<f64> = s.actuated.iter().map(|&j| base.xddot[j]).collect();
    let u: Vec<f64> = base.u().to_vec();
    let mut calls = 0;

    for v in NON_FINITE.into_iter().chain(HUGE) {
        for i in [0, n_out - 1] {
            let with = |xs: &[f64]| {
                let mut xs = xs.to_vec();
                xs[i] = v;
                xs
            };
            check(
                "IK outputs",
                v,
                &base,
                |_| {},
                |d| inverse_kinematics(model, d, &with(&pose)),
                non_finite,
            );
            check(
                "IK outputs_dot",
                v,
                &base,
                |_| {},
                |d| inverse_velocity(model, d, &with(&rates)),
                non_finite,
            );
            check(
                "IK outputs_ddot",
                v,
                &base,
                |_| {},
                |d| inverse_acceleration(model, d, &with(&accels)),
                non_finite,
            );
            calls += 3;
        }
        for i in [0, n_act - 1] {
            let with = |xs: &[f64]| {
                let mut xs = xs.to_vec();
                xs[i] = v;
                xs
            };
            check(
                "FK q",
                v,
                &base,
                |_| {},
                |d| forward_kinematics(model, d, &with(&q)),
                non_finite,
            );
            check(
                "FK (LM) q",
                v,
                &base,
                |_| {},
                |d| forward_kinematics_lm(model, d, &with(&q), &LmOptions::default()),
                |e| matches!(e, rbss_runtime::FkRobustError::Solver(e) if non_finite(e)),
            );
            check(
                "FK qdot",
                v,
                &base,
                |_| {},
                |d| forward_velocity(model, d, &with(&qd)),
                non_finite,
            );
            check(
                "FK qddot",
                v,
                &base,
                |_| {},
                |d| forward_acceleration(model, d, &with(&qdd)),
                non_finite,
            );
            check(
                "FD u",
                v,
                &base,
                |_| {},
                |d| forward_dynamics(model, d, &with(&u), None, Baumgarte::NONE),
                non_finite,
            );
            calls += 5;
        }
        // Warm starts: the coordinates Newton reads (IK overwrites the outputs, FK the
        // actuated coordinates, so a NaN there is harmless).
        let ik_unknowns: Vec<usize> = (0..N).filter(|j| !s.outputs.contains(j)).collect();
        for j in [ik_unknowns[0], ik_unknowns[ik_unknowns.len() - 1]] {
            check(
                "data.x (warm start) for IK",
                v,
                &base,
                |d| d.x[j] = v,
                |d| inverse_kinematics(model, d, &pose),
                non_finite,
            );
            calls += 1;
        }
        for j in [s.passive[0], s.passive[s.passive.len() - 1]] {
            check(
                "data.x (warm start) for FK",
                v,
                &base,
                |d| d.x[j] = v,
                |d| forward_kinematics(model, d, &q),
                non_finite,
            );
            check(
                "data.x (warm start) for FK (LM)",
                v,
                &base,
                |d| d.x[j] = v,
                |d| forward_kinematics_lm(model, d, &q, &LmOptions::default()),
                |e| matches!(e, rbss_runtime::FkRobustError::Solver(e) if non_finite(e)),
            );
            calls += 2;
        }
        for j in [0, N / 2, N - 1] {
            let mut forces = [0.0; N];
            forces[j] = v;
            check(
                "ID q_forces",
                v,
                &base,
                |_| {},
                |d| inverse_dynamics(model, d, Some(&forces)),
                non_finite,
            );
            check(
                "FD q_forces",
                v,
                &base,
                |_| {},
                |d| forward_dynamics(model, d, &u, Some(&forces), Baumgarte::NONE),
                non_finite,
            );
            calls += 2;
            // The state each solver reads.
            type Field<const N: usize, const M: usize> = fn(&mut Data<N, M>) -> &mut [f64; N];
            let fields: [(&str, Field<N, M>); 3] = [
                ("x", |d| &mut d.x),
                ("xdot", |d| &mut d.xdot),
                ("xddot", |d| &mut d.xddot),
            ];
            for (name, field) in fields {
                let corrupt = |d: &mut Data<N, M>| field(d)[j] = v;
                let reads_x = name == "x";
                if reads_x {
                    check(
                        "data.x for IK velocity",
                        v,
                        &base,
                        corrupt,
                        |d| inverse_velocity(model, d, &rates),
                        non_finite,
                    );
                    check(
                        "data.x for FK velocity",
                        v,
                        &base,
                        corrupt,
                        |d| forward_velocity(model, d, &qd),
                        non_finite,
                    );
                    check(
                        "data.x for position projection",
                        v,
                        &base,
                        corrupt,
                        |d| project_position(model, d),
                        non_finite,
                    );
                    calls += 3;
                }
                if name != "xddot" {
                    check(
                        &format!("data.{name} for IK acceleration"),
                        v,
                        &base,
                        corrupt,
                        |d| inverse_acceleration(model, d, &accels),
                        non_finite,
                    );
                    check(
                        &format!("data.{name} for FK acceleration"),
                        v,
                        &base,
                        corrupt,
                        |d| forward_acceleration(model, d, &qdd),
                        non_finite,
                    );
                    check(
                        &format!("data.{name} for velocity projection"),
                        v,
                        &base,
                        corrupt,
                        |d| project_velocity(model, d),
                        non_finite,
                    );
                    check(
                        &format!("data.{name} for FD"),
                        v,
                        &base,
                        corrupt,
                        |d| forward_dynamics(model, d, &u, None, Baumgarte::NONE),
                        non_finite,
                    );
                    calls += 4;
                }
                check(
                    &format!("data.{name} for ID"),
                    v,
                    &base,
                    corrupt,
                    |d| inverse_dynamics(model, d, None),
                    non_finite,
                );
                check(
                    &format!("data.{name} for dense ID"),
                    v,
                    &base,
                    corrupt,
                    |d| inverse_dynamics_dense(model, d, None),
                    non_finite,
                );
                calls += 2;
            }
        }
        for b in [
            Baumgarte {
                alpha: v,
                beta: 1.0,
            },
            Baumgarte {
                alpha: 1.0,
                beta: v,
            },
        ] {
            check(
                "FD Baumgarte gains",
                v,
                &base,
                |_| {},
                |d| forward_dynamics(model, d, &u, None, b),
                non_finite,
            );
            calls += 1;
        }
    }
    calls
}

#[test]
fn solvers_reject_non_finite_inputs() {
    let a = check_robot(&Model::new(stewart_6ups::Stewart6Ups::default()));
    let b = check_robot(&Model::new(five_bar::FiveBar::default()));
    println!("{a} + {b} solver calls checked");
}

/// The simulator: start time, initial state and options; the end time and the control.
#[test]
fn simulator_rejects_non_finite_inputs() {
    let model = Model::new(stewart_6ups::Stewart6Ups::default());
    let mut data = Data::new(&model);
    let x0: [f64; stewart_6ups::N] = stewart_6ups::STRUCTURE.home.try_into().unwrap();
    let v0 = [0.0; stewart_6ups::N];
    let opts = IntegrateOptions::new(Method::dopri5(1e-8, 1e-10), Stabilization::Projection);
    let invalid = |r: Result<Simulator<24, 18>, IntegrateError>| match r {
        Err(IntegrateError::InvalidOptions { .. }) => {}
        Err(e) => panic!("expected InvalidOptions, got {e}"),
        Ok(_) => panic!("accepted"),
    };
    for v in NON_FINITE {
        invalid(Simulator::new(&model, &mut data, v, &x0, &v0, opts));
        invalid(Simulator::new(
            &model,
            &mut data,
            0.0,
            &x0,
            &v0,
            IntegrateOptions::new(Method::Rk4 { dt: v }, Stabilization::None),
        ));
        for (rtol, atol) in [(v, 1e-10), (1e-8, v)] {
            invalid(Simulator::new(
                &model,
                &mut data,
                0.0,
                &x0,
                &v0,
                IntegrateOptions::new(Method::dopri5(rtol, atol), Stabilization::None),
            ));
        }
        invalid(Simulator::new(
            &model,
            &mut data,
            0.0,
            &x0,
            &v0,
            IntegrateOptions::new(
                Method::Rk4 { dt: 1e-3 },
                Stabilization::Baumgarte(Baumgarte { alpha: v, beta: v }),
            ),
        ));
        for j in [0, 12, 23] {
            let (mut x, mut xd) = (x0, v0);
            x[j] = v;
            match Simulator::new(&model, &mut data, 0.0, &x, &v0, opts) {
                Err(IntegrateError::Solver {
                    error: SolverError::NonFinite { .. },
                    ..
                }) => {}
                other => panic!("x0[{j}] = {v}: {:?}", other.map(|_| ())),
            }
            xd[j] = v;
            match Simulator::new(&model, &mut data, 0.0, &x0, &xd, opts) {
                Err(IntegrateError::Solver {
                    error: SolverError::NonFinite { .. },
                    ..
                }) => {}
                other => panic!("xdot0[{j}] = {v}: {:?}", other.map(|_| ())),
            }
        }
    }
    // Absurd but finite initial states: a typed error, never a NaN state.
    for v in HUGE {
        for j in [0, 12, 23] {
            let mut x = x0;
            x[j] = v;
            if let Ok(sim) = Simulator::new(&model, &mut data, 0.0, &x, &v0, opts) {
                assert!(sim.x().iter().all(|v| v.is_finite()), "x0[{j}] = {v}");
            }
        }
    }

    // A running simulation: a NaN end time, and a control that returns NaN.
    let mut sim = Simulator::new(&model, &mut data, 0.0, &x0, &v0, opts).unwrap();
    let mut zero = |_: f64, _: &[f64; 24], _: &[f64; 24], u: &mut [f64]| {
        u.fill(0.0);
        Ok(())
    };
    for t_end in NON_FINITE {
        assert!(matches!(
            sim.step(&model, &mut data, t_end, &mut zero),
            Err(IntegrateError::InvalidOptions { .. })
        ));
    }
    let mut nan = |_: f64, _: &[f64; 24], _: &[f64; 24], u: &mut [f64]| {
        u.fill(f64::NAN);
        Ok(())
    };
    let (t, x) = (sim.t(), *sim.x());
    match sim.step(&model, &mut data, 0.1, &mut nan) {
        Err(IntegrateError::Solver {
            error: SolverError::NonFinite { what },
            ..
        }) => assert_eq!(what, "u"),
        other => panic!("a NaN control: {other:?}"),
    }
    assert_eq!(
        (sim.t(), *sim.x()),
        (t, x),
        "a failed step changed the state"
    );
}

/// The kernels are plain functions: no checks, NaN in gives NaN out (and no panic).
#[test]
fn kernels_propagate_nan() {
    use rbss_runtime::Kernels;
    let k = stewart_6ups::Stewart6Ups::default();
    let mut x: [f64; 24] = stewart_6ups::STRUCTURE.home.try_into().unwrap();
    x[18] = f64::NAN; // the platform's x
    let mut f = [0.0; 18];
    k.constraints(&x, &mut f);
    assert!(f.iter().any(|v| v.is_nan()));
    let (mut mm, mut psi) = ([[0.0; 24]; 24], [0.0; 24]);
    k.mass_matrix(&x, &mut mm);
    k.psi(&x, &[f64::INFINITY; 24], &mut psi);
    assert!(psi.iter().any(|v| v.is_nan()));
}
