//! Dynamics on the generated robots (`generated/stewart_6ups`, the paper's 6-UPS, and
//! `generated/five_bar`): inverse dynamics against forward dynamics and against the dense
//! solve, energy conservation of the free robot, Baumgarte's stabilisation against drift, and
//! the paper's round trip (inverse dynamics along `TraekP`, then forward simulation).
//!
//! Every bound below was measured first (the numbers are printed with `--nocapture`) and set
//! with a margin; the measured values are quoted next to each bound.

mod common;

use std::f64::consts::PI;

use common::XorShift;
use five_bar::FiveBar;
use rbss_runtime::{
    Baumgarte, Data, Dynamics, DynamicsMethod, IntegrateOptions, IntegrateStats, Kernels, Method,
    Model, Simulator, SolverError, Stabilization, forward_dynamics, forward_dynamics_schur,
    inverse_acceleration, inverse_dynamics, inverse_dynamics_dense, inverse_kinematics,
    inverse_velocity,
};
use stewart_6ups::Stewart6Ups;

const NS: usize = stewart_6ups::N;
const MS: usize = stewart_6ups::M;

// ---------------------------------------------------------------------------------------------
// The paper's platform motion TraekP (shared/paper-example.md), w = pi, with its exact
// derivatives.

const W: f64 = PI;

/// `[x, y, z, rotx, roty, rotz]` and its first and second time derivatives at `t`.
fn traek_p(t: f64) -> ([f64; 6], [f64; 6], [f64; 6]) {
    let w = W;
    let (s1, c1) = (w * t).sin_cos();
    let (s2, c2) = (2.0 * w * t).sin_cos();
    let (s3, c3) = (3.0 * w * t).sin_cos();
    // rotz = 0.1 cos(2wt) sin(2wt); d/dt = 0.2 w (cos² - sin²)(2wt); d²/dt² = -1.6 w² cs.
    let pos = [
        0.1 * c1,
        0.1 * s1,
        0.94 * (1.0 + 0.01 * s3),
        0.1 * c2,
        0.1 * s2,
        0.1 * c2 * s2,
    ];
    let vel = [
        -0.1 * w * s1,
        0.1 * w * c1,
        0.94 * 0.03 * w * c3,
        -0.2 * w * s2,
        0.2 * w * c2,
        0.2 * w * (c2 * c2 - s2 * s2),
    ];
    let w2 = w * w;
    let acc = [
        -0.1 * w2 * c1,
        -0.1 * w2 * s1,
        -0.94 * 0.09 * w2 * s3,
        -0.4 * w2 * c2,
        -0.4 * w2 * s2,
        -1.6 * w2 * c2 * s2,
    ];
    (pos, vel, acc)
}

#[test]
fn traek_p_derivatives_match_central_differences() {
    let h = 1e-3;
    for k in 0..50 {
        let t = k as f64 * 0.04;
        let xs: [[f64; 6]; 5] = core::array::from_fn(|i| traek_p(t + (i as f64 - 2.0) * h).0);
        let (d1, d2) = common::central_4th(&xs, h);
        let (_, v, a) = traek_p(t);
        for j in 0..6 {
            assert!((d1[j] - v[j]).abs() < 1e-9, "vel {j} at {t}");
            assert!((d2[j] - a[j]).abs() < 1e-6, "acc {j} at {t}");
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Consistent states.

/// Sets `data` to the state with outputs `o`, `od`, `odd` (IK warm-started from `data.x`).
fn set_state<K: Dynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    o: &[f64],
    od: &[f64],
    odd: &[f64],
) -> Result<(), SolverError> {
    inverse_kinematics(model, data, o)?;
    inverse_velocity(model, data, od)?;
    inverse_acceleration(model, data, odd)?;
    Ok(())
}

/// A random consistent state of the 6-UPS near home: pose within ±0.1 m, z 0.89..0.99 m,
/// angles ±0.15 rad; output rates ±0.5, accelerations ±5 (SI).
fn random_stewart_state(model: &Model<Stewart6Ups, NS, MS>, rng: &mut XorShift) -> Data<NS, MS> {
    let mut d = Data::new(model);
    let pose = common::random_stewart_pose(rng);
    let od: [f64; 6] = core::array::from_fn(|_| rng.range(-0.5, 0.5));
    let odd: [f64; 6] = core::array::from_fn(|_| rng.range(-5.0, 5.0));
    set_state(model, &mut d, &pose, &od, &odd).unwrap();
    d
}

/// A random consistent state of the five-bar: the effector at a reachable point with a 2 cm
/// margin, near home; rates ±1 m/s, accelerations ±10 m/s².
fn random_five_bar_state(model: &Model<FiveBar, 6, 4>, rng: &mut XorShift) -> Data<6, 4> {
    let mut d = Data::new(model);
    let (px, py) = loop {
        let (px, py) = (rng.range(-0.1, 0.1), rng.range(0.22, 0.38));
        if common::five_bar::reachable(px, py, 0.02) {
            break (px, py);
        }
    };
    let od = [rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)];
    let odd = [rng.range(-10.0, 10.0), rng.range(-10.0, 10.0)];
    set_state(model, &mut d, &[px, py], &od, &odd).unwrap();
    d
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m, x| m.max(x.abs()))
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).fold(0.0, |m, (x, y)| m.max((x - y).abs()))
}

// ---------------------------------------------------------------------------------------------
// Inverse dynamics <-> forward dynamics, structured <-> dense.

#[derive(Debug, Default)]
struct RoundTrip {
    xddot: f64,
    lambda: f64,
    u_dense: f64,
    lambda_dense: f64,
    id_residual: f64,
    fd_residual: f64,
    cond_blocks: f64,
    cond_id: f64,
    cond_dense: f64,
    cond_sc: f64,
    cond_reduced: f64,
    schur_xddot: f64,
    schur_lambda: f64,
    cond_mass: f64,
    cond_gram: f64,
}

/// ID, then dense ID, then FD with the ID's U, at `data`'s state; relative differences.
fn id_fd<K: Dynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &Data<N, M>,
    q: Option<&[f64; N]>,
    worst: &mut RoundTrip,
) {
    let mut id = data.clone();
    let rep = inverse_dynamics(model, &mut id, q).unwrap();
    assert_eq!(rep.method, DynamicsMethod::BlockElimination);
    let mut dense = data.clone();
    let rep_d = inverse_dynamics_dense(model, &mut dense, q).unwrap();
    assert_eq!(rep_d.method, DynamicsMethod::DenseLu);
    let mut fd = data.clone();
    fd.xddot = [f64::NAN; N];
    let rep_f = forward_dynamics(model, &mut fd, id.u(), q, Baumgarte::NONE).unwrap();
    assert_eq!(rep_f.method, DynamicsMethod::Reduced);
    let mut schur = data.clone();
    let rep_s = forward_dynamics_schur(model, &mut schur, id.u(), q, Baumgarte::NONE).unwrap();
    assert_eq!(rep_s.method, DynamicsMethod::SchurComplement);

    let su = max_abs(id.u()).max(1e-300);
    let sl = max_abs(&id.lambda).max(1e-300);
    let sa = max_abs(&data.xddot).max(1e-300);
    let w = worst;
    w.schur_xddot = w
        .schur_xddot
        .max(max_diff(&fd.xddot, &schur.xddot) / max_abs(&schur.xddot).max(1e-300));
    w.schur_lambda = w
        .schur_lambda
        .max(max_diff(&fd.lambda, &schur.lambda) / max_abs(&schur.lambda).max(1e-300));
    w.cond_sc = w.cond_sc.max(rep_s.cond);
    w.cond_reduced = w.cond_reduced.max(rep_f.cond);
    w.xddot = w.xddot.max(max_diff(&fd.xddot, &data.xddot) / sa);
    w.lambda = w.lambda.max(max_diff(&fd.lambda, &id.lambda) / sl);
    w.u_dense = w.u_dense.max(max_diff(dense.u(), id.u()) / su);
    w.lambda_dense = w.lambda_dense.max(max_diff(&dense.lambda, &id.lambda) / sl);
    let scale = su.max(sl);
    w.id_residual = w.id_residual.max(rep.residual / scale);
    w.fd_residual = w.fd_residual.max(rep_f.residual);
    w.cond_blocks = w.cond_blocks.max(rep.cond_blocks);
    w.cond_id = w.cond_id.max(rep.cond);
    w.cond_dense = w.cond_dense.max(rep_d.cond);

    w.cond_mass = w.cond_mass.max(rep_f.cond_blocks);
    let rep_p = rbss_runtime::project_velocity(model, &mut data.clone()).unwrap();
    assert!(rep_p.residual < 1e-13, "{rep_p:?}");
    w.cond_gram = w.cond_gram.max(rep_p.cond);
    // U = 0 on no coordinate beyond N - M; FD copies U.
    assert_eq!(&fd.u, &id.u);
}

/// Measured over 200 states (relative to the largest entry): Ẍ 1.7e-14, lambda 1.5e-15,
/// structured vs dense U 1.1e-15, lambda 1.8e-15; condition estimates at most: IK blocks 2.5,
/// reduced system 23, dense 80, S_c 14, M 26, G Gᵀ 53.
#[test]
fn inverse_then_forward_dynamics_round_trip_stewart() {
    let model = Model::new(Stewart6Ups::default());
    let mut rng = XorShift(0xD1_2009_0001);
    let mut w = RoundTrip::default();
    for k in 0..200 {
        let data = random_stewart_state(&model, &mut rng);
        let q: [f64; NS] = core::array::from_fn(|_| rng.range(-50.0, 50.0));
        id_fd(
            &model,
            &data,
            if k % 2 == 0 { Some(&q) } else { None },
            &mut w,
        );
    }
    println!("stewart_6ups, 200 random states: {w:#?}");
    assert!(w.xddot < 1e-10 && w.lambda < 1e-10, "{w:?}");
    assert!(w.u_dense < 1e-11 && w.lambda_dense < 1e-11, "{w:?}");
    assert!(w.id_residual < 1e-13 && w.fd_residual < 1e-11, "{w:?}");
    assert!(w.schur_xddot < 1e-12 && w.schur_lambda < 1e-12, "{w:?}");
}

/// Measured over 200 states: Ẍ 1.2e-14, lambda 1.7e-15, structured vs dense 2.2e-15 and
/// 1.5e-15; condition estimates at most: IK blocks 11, reduced 6.3, dense 42, S_c 12, M 66,
/// G Gᵀ 18.
#[test]
fn inverse_then_forward_dynamics_round_trip_five_bar() {
    let model = Model::new(FiveBar::default());
    let mut rng = XorShift(0xD1_2009_0002);
    let mut w = RoundTrip::default();
    for k in 0..200 {
        let data = random_five_bar_state(&model, &mut rng);
        let q: [f64; 6] = core::array::from_fn(|_| rng.range(-1.0, 1.0));
        id_fd(
            &model,
            &data,
            if k % 2 == 0 { Some(&q) } else { None },
            &mut w,
        );
    }
    println!("five_bar, 200 random states: {w:#?}");
    assert!(w.xddot < 1e-10 && w.lambda < 1e-10, "{w:?}");
    assert!(w.u_dense < 1e-11 && w.lambda_dense < 1e-11, "{w:?}");
    assert!(w.id_residual < 1e-13 && w.fd_residual < 1e-11, "{w:?}");
    assert!(w.schur_xddot < 1e-12 && w.schur_lambda < 1e-12, "{w:?}");
}

// ---------------------------------------------------------------------------------------------
// Simulation helpers.

type Control<'a> =
    dyn FnMut(f64, &[f64; NS], &[f64; NS], &mut [f64]) -> Result<(), SolverError> + 'a;

fn zero_control() -> impl FnMut(f64, &[f64; NS], &[f64; NS], &mut [f64]) -> Result<(), SolverError>
{
    |_, _, _, u: &mut [f64]| {
        u.fill(0.0);
        Ok(())
    }
}

/// Simulates from `(x0, v0)` over `[0, t_end]`; returns the stats and the largest relative drift
/// of the total energy `T + Pi` (relative to the kinetic-energy scale `max(T0, 1 J)`... see
/// the energy test), evaluated at every accepted step.
#[allow(clippy::type_complexity)]
fn simulate(
    model: &Model<Stewart6Ups, NS, MS>,
    x0: &[f64; NS],
    v0: &[f64; NS],
    t_end: f64,
    options: IntegrateOptions,
    control: &mut Control<'_>,
    observer: &mut dyn FnMut(&Simulator<NS, MS>),
) -> (IntegrateStats, f64) {
    let mut data = Data::new(model);
    let start = std::time::Instant::now();
    let mut sim = Simulator::new(model, &mut data, 0.0, x0, v0, options).unwrap();
    observer(&sim);
    let stats = sim
        .run(model, &mut data, t_end, control, |s| observer(s))
        .unwrap_or_else(|e| panic!("{options:?}: {e}"));
    (stats, start.elapsed().as_secs_f64())
}

fn energy(model: &Model<Stewart6Ups, NS, MS>, x: &[f64; NS], v: &[f64; NS]) -> [f64; 2] {
    let mut e = [0.0; 2];
    model.kernels().energy(x, v, &mut e);
    e
}

/// The paper's initial state: TraekP at t = 0.
fn traek_p_start(model: &Model<Stewart6Ups, NS, MS>) -> Data<NS, MS> {
    let mut d = Data::new(model);
    let (p, v, a) = traek_p(0.0);
    set_state(model, &mut d, &p, &v, &a).unwrap();
    d
}

// ---------------------------------------------------------------------------------------------
// Inverse dynamics: the fallback at a singular block, and the typed errors.

/// The five-bar with its left arm fully stretched (`a1 = 0`): the left inverse-kinematics block
/// `G_kk` is singular, `[S | Gᵀ]` is not (the distal links are not parallel). Inverse dynamics
/// falls back to the dense LU and agrees with it.
#[test]
fn inverse_dynamics_falls_back_to_dense_at_a_singular_block() {
    use common::five_bar::{B, L1, L2};
    let model = Model::new(FiveBar::default());
    let mut d = Data::new(&model);
    let th1 = PI / 3.0;
    let (px, py) = (-B + (L1 + L2) * th1.cos(), (L1 + L2) * th1.sin());
    // Right arm, elbow out (as at home): law of cosines from the base (B, 0).
    let (dx, dy) = (px - B, py);
    let dist = dx.hypot(dy);
    let g = ((L1 * L1 + dist * dist - L2 * L2) / (2.0 * L1 * dist)).acos();
    let th2 = dy.atan2(dx) - g;
    let (ex, ey) = (B + L1 * th2.cos(), L1 * th2.sin());
    let a2 = (py - ey).atan2(px - ex) - th2;
    d.x = [th1, 0.0, th2, a2, px, py];
    let mut f = [0.0; 4];
    model.kernels().constraints(&d.x, &mut f);
    assert!(max_abs(&f) < 1e-15, "{f:?}");
    // A consistent motion: forward kinematics is regular there (J_p is).
    rbss_runtime::forward_velocity(&model, &mut d, &[0.4, -0.3]).unwrap();
    rbss_runtime::forward_acceleration(&model, &mut d, &[0.3, 0.1]).unwrap();

    let mut dense = d.clone();
    let rep = inverse_dynamics(&model, &mut d, None).unwrap();
    let rep_d = inverse_dynamics_dense(&model, &mut dense, None).unwrap();
    println!("stretched arm: {rep:?}; dense {rep_d:?}");
    assert_eq!(rep.method, DynamicsMethod::DenseLu);
    assert!(rep.cond_blocks > model.options.cond_max, "{rep:?}");
    assert!(rep.cond < 1e3, "{rep:?}");
    assert_eq!(d.u, dense.u);
    assert_eq!(d.lambda, dense.lambda);
    // And forward dynamics with those U reproduces the accelerations.
    let u = d.u;
    forward_dynamics(&model, &mut d, &u[..2], None, Baumgarte::NONE).unwrap();
    assert!(max_diff(&d.xddot, &dense.xddot) < 1e-12, "{:?}", d.xddot);
}

#[test]
fn dynamics_errors_are_typed() {
    let model = Model::new(Stewart6Ups::default());
    let mut rng = XorShift(0xE_2009);
    let good = random_stewart_state(&model, &mut rng);
    let u = [100.0; 6];

    let mut d = good.clone();
    d.xddot[3] = f64::NAN;
    assert_eq!(
        inverse_dynamics(&model, &mut d, None),
        Err(SolverError::NonFinite { what: "data.xddot" })
    );
    let mut d = good.clone();
    d.xdot[0] = f64::INFINITY;
    assert_eq!(
        forward_dynamics(&model, &mut d, &u, None, Baumgarte::NONE),
        Err(SolverError::NonFinite { what: "data.xdot" })
    );
    let mut d = good.clone();
    let mut q = [0.0; NS];
    q[7] = f64::NAN;
    assert_eq!(
        forward_dynamics(&model, &mut d, &u, Some(&q), Baumgarte::NONE),
        Err(SolverError::NonFinite { what: "q_forces" })
    );
    assert_eq!(
        forward_dynamics(&model, &mut d, &u[..5], None, Baumgarte::NONE),
        Err(SolverError::Dimension {
            what: "u",
            expected: 6,
            found: 5
        })
    );
    let nan_gains = Baumgarte {
        alpha: f64::NAN,
        beta: 1.0,
    };
    assert!(matches!(
        forward_dynamics(&model, &mut d, &u, None, nan_gains),
        Err(SolverError::NonFinite { .. })
    ));
    // Outputs untouched on error.
    assert_eq!(d.xddot, good.xddot);
    assert_eq!(d.lambda, good.lambda);

    // Negative density: the mass blocks are negative definite.
    let params = stewart_6ups::Params {
        rho: -7800.0,
        ..Default::default()
    };
    let bad = Model::new(Stewart6Ups::new(&params));
    let mut d = good.clone();
    let e = forward_dynamics(&bad, &mut d, &u, None, Baumgarte::NONE).unwrap_err();
    assert!(
        matches!(
            e,
            SolverError::NotPositiveDefinite {
                what: "mass block",
                block: Some(_),
                column: 0
            }
        ),
        "{e}"
    );

    // A condition limit below the conditioning of S_c = G M⁻¹ Gᵀ (about 12 here): the Schur
    // complement refuses, but that is not what makes forward dynamics ill posed. The null-space
    // method answers, its Jacobi-scaled projected mass matrix being far better conditioned
    // (measured 1.09), with the same accelerations.
    let strict = Model::new(Stewart6Ups::default()).with_options(rbss_runtime::SolverOptions {
        cond_max: 2.0,
        ..Default::default()
    });
    let mut d = good.clone();
    let rep = forward_dynamics(&strict, &mut d, &u, None, Baumgarte::NONE).unwrap();
    assert_eq!(rep.method, DynamicsMethod::NullSpace);
    assert!(rep.cond <= 2.0 && rep.backward_error <= 1e-14, "{rep:?}");
    let mut reference = good.clone();
    forward_dynamics(&model, &mut reference, &u, None, Baumgarte::NONE).unwrap();
    let scale = reference.xddot.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    for (a, b) in d.xddot.iter().zip(&reference.xddot) {
        assert!((a - b).abs() <= 1e-13 * scale, "{a} vs {b}");
    }
    // Below that too: Singular, with the estimate of the matrix that decides it.
    let stricter = Model::new(Stewart6Ups::default()).with_options(rbss_runtime::SolverOptions {
        cond_max: 1.01,
        ..Default::default()
    });
    let mut d = good.clone();
    match forward_dynamics(&stricter, &mut d, &u, None, Baumgarte::NONE) {
        Err(SolverError::Singular { cond, what, .. }) => {
            assert!(cond > 1.01 && cond.is_finite());
            assert!(what.contains("projected mass matrix"), "{what}");
        }
        other => panic!("{other:?}"),
    }
    let mut d = good.clone();
    assert!(matches!(
        inverse_dynamics(&strict, &mut d, None),
        Err(SolverError::Singular { .. })
    ));
}

// ---------------------------------------------------------------------------------------------
// Energy.

/// Free motion (U = 0, Q = 0) from the home pose, the platform thrown upwards (2.4 m/s) while
/// moving sideways and turning: it rises to z = 1.23 m and falls back to 0.89 m in 0.5 s,
/// clear of singularities. The work–energy balance `d(T + Pi)/dt = Uᵀ q̇ = 0` says `T + Pi` is
/// conserved; the drift `max |E(t) - E(0)|` is taken relative to the largest kinetic energy of
/// the run (not to `Pi`, whose zero is arbitrary).
fn free_motion(options: IntegrateOptions) -> (f64, IntegrateStats, f64) {
    let model = Model::new(Stewart6Ups::default());
    let mut d = Data::new(&model);
    let pose = [0.1, 0.0, 0.94, 0.1, 0.0, 0.0];
    let rates = [0.2, -0.1, 2.4, 0.3, 0.2, -0.4];
    set_state(&model, &mut d, &pose, &rates, &[0.0; 6]).unwrap();
    let (x0, v0) = (d.x, d.xdot);
    let e0 = energy(&model, &x0, &v0);
    let (mut worst, mut t_max) = (0.0_f64, e0[0]);
    let (stats, secs) = simulate(
        &model,
        &x0,
        &v0,
        0.5,
        options,
        &mut zero_control(),
        &mut |s| {
            let e = energy(&model, s.x(), s.xdot());
            worst = worst.max(((e[0] + e[1]) - (e0[0] + e0[1])).abs());
            t_max = t_max.max(e[0]);
        },
    );
    (worst / t_max, stats, secs)
}

/// Measured (relative drift): DOPRI5 rtol 1e-10 + projection 1.6e-12 (78 steps); RK4 dt 1e-3 +
/// projection 1.2e-12; DOPRI5 1e-10 with coordinate partitioning 1.4e-10 (its error control
/// sees only `q, q̇`: 40 steps); with Baumgarte's default gains 4.3e-13. RK4 at dt 2e-2: 1.1e-7.
#[test]
fn free_motion_conserves_energy() {
    let cases = [
        (
            "DOPRI5 rtol 1e-10, projection",
            IntegrateOptions::new(Method::dopri5(1e-10, 1e-12), Stabilization::Projection),
            2e-11,
        ),
        (
            "RK4 dt 1e-3, projection",
            IntegrateOptions::new(Method::Rk4 { dt: 1e-3 }, Stabilization::Projection),
            2e-11,
        ),
        (
            "DOPRI5 rtol 1e-10, coordinate partitioning",
            IntegrateOptions::new(
                Method::dopri5(1e-10, 1e-12),
                Stabilization::CoordinatePartitioning,
            ),
            2e-9,
        ),
        (
            "DOPRI5 rtol 1e-10, Baumgarte (default gains)",
            IntegrateOptions::new(Method::dopri5(1e-10, 1e-12), Stabilization::baumgarte()),
            2e-11,
        ),
    ];
    for (name, options, bound) in cases {
        let (drift, stats, _) = free_motion(options);
        println!("{name}: relative energy drift {drift:.2e} (bound {bound:.0e}); {stats:?}");
        assert!(drift < bound, "{name}: drift {drift:e}");
        assert!(stats.max_violation < 1e-10, "{name}: {stats:?}");
    }
    // The loose check is not vacuous: a coarse RK4 step drifts measurably.
    let (drift, _, _) = free_motion(IntegrateOptions::new(
        Method::Rk4 { dt: 2e-2 },
        Stabilization::Projection,
    ));
    println!("RK4 dt 2e-2, projection: relative energy drift {drift:.2e}");
    assert!(drift > 1e-9, "{drift:e}");
}

// ---------------------------------------------------------------------------------------------
// The paper's round trip.

struct RoundTripRun {
    /// max |(x, y, z) - TraekP| over the accepted steps [m].
    pos: f64,
    /// max |(rotx, roty, rotz) - TraekP| [rad].
    rot: f64,
    /// max |platform velocity - TraekP'| [m/s, rad/s].
    vel: f64,
    /// max |f(X)| at the accepted steps in the first and the second half of the run
    /// (before any projection).
    violation_halves: [f64; 2],
    stats: IntegrateStats,
    secs: f64,
}

/// U(t) by inverse kinematics, velocity, acceleration and inverse dynamics along TraekP at the
/// exact stage time (on the callback's own Data, warm-started), then the forward simulation
/// from the t = 0 state; errors of the platform pose against TraekP at every accepted step.
fn paper_round_trip(t_end: f64, options: IntegrateOptions) -> RoundTripRun {
    paper_round_trip_with(t_end, options, false)
}

/// [`paper_round_trip`], with the control's IK, velocity, acceleration and inverse dynamics in
/// one `inverse_dynamics_full` call (`combined`) instead of four calls.
fn paper_round_trip_with(t_end: f64, options: IntegrateOptions, combined: bool) -> RoundTripRun {
    let model = Model::new(Stewart6Ups::default());
    let start = traek_p_start(&model);
    let mut reference = start.clone();
    let mut control = |t: f64, _: &[f64; NS], _: &[f64; NS], u: &mut [f64]| {
        let (p, v, a) = traek_p(t);
        if combined {
            rbss_runtime::inverse_dynamics_full(&model, &mut reference, &p, &v, &a, None)?;
        } else {
            set_state(&model, &mut reference, &p, &v, &a)?;
            inverse_dynamics(&model, &mut reference, None)?;
        }
        u.copy_from_slice(reference.u());
        Ok(())
    };
    let (mut pos, mut rot, mut vel) = (0.0_f64, 0.0_f64, 0.0_f64);
    let mut halves = [0.0_f64; 2];
    let mut f = [0.0; MS];
    let (stats, secs) = simulate(
        &model,
        &start.x,
        &start.xdot,
        t_end,
        options,
        &mut control,
        &mut |s| {
            let (p, v, _) = traek_p(s.t());
            let x = &s.x()[18..24];
            let xd = &s.xdot()[18..24];
            pos = pos.max(max_diff(&x[..3], &p[..3]));
            rot = rot.max(max_diff(&x[3..], &p[3..]));
            vel = vel.max(max_diff(xd, &v));
            model.kernels().constraints(s.x(), &mut f);
            let h = usize::from(s.t() > 0.5 * t_end);
            halves[h] = halves[h].max(max_abs(&f));
        },
    );
    RoundTripRun {
        pos,
        rot,
        vel,
        violation_halves: halves,
        stats,
        secs,
    }
}

fn print_run(name: &str, r: &RoundTripRun) {
    println!(
        "{name:<40} pos {:.2e} m  rot {:.2e} rad  vel {:.2e}  |f| {:.2e} / {:.2e}  \
         steps {:>5} rej {:>2} rhs {:>6}  newton {:>5}  {:.1} ms",
        r.pos,
        r.rot,
        r.vel,
        r.violation_halves[0],
        r.violation_halves[1],
        r.stats.steps,
        r.stats.rejected,
        r.stats.rhs_evaluations,
        r.stats.newton_iterations,
        r.secs * 1e3
    );
}

/// The paper's check, short: 0.5 s of TraekP. Measured: RK4 dt 1e-3 (no stabilisation, as in
/// the paper) position error 1.1e-12 m, angles 5.4e-12 rad; DOPRI5 rtol 1e-10 with projection
/// (99 steps) 2.2e-13 m, 4.0e-12 rad.
#[test]
fn paper_round_trip_follows_traek_p() {
    let rk4 = paper_round_trip(
        0.5,
        IntegrateOptions::new(Method::Rk4 { dt: 1e-3 }, Stabilization::None),
    );
    print_run("RK4 dt 1e-3, none, 0.5 s", &rk4);
    assert_eq!(rk4.stats.steps, 500);
    assert_eq!(rk4.stats.rhs_evaluations, 2000);
    assert!(
        rk4.pos < 2e-11 && rk4.rot < 1e-10,
        "pos {:e} rot {:e}",
        rk4.pos,
        rk4.rot
    );

    let dp = paper_round_trip(
        0.5,
        IntegrateOptions::new(Method::dopri5(1e-10, 1e-12), Stabilization::Projection),
    );
    print_run("DOPRI5 rtol 1e-10, projection, 0.5 s", &dp);
    assert!(
        dp.pos < 2e-11 && dp.rot < 1e-10,
        "pos {:e} rot {:e}",
        dp.pos,
        dp.rot
    );
    // FSAL: 6 evaluations per attempt, plus the first one, plus one after each projection
    // (all but the last step's), plus HINIT's.
    let s = dp.stats;
    assert_eq!(s.rhs_evaluations, 6 * (s.steps + s.rejected) + s.steps + 1);
}

/// Baumgarte against no stabilisation, on the round trip at loose settings (2 s). Measured
/// max |f| [m]: DOPRI5 rtol 1e-6: none 1.8e-6, Baumgarte (10 /s) 1.8e-8; RK4 dt 1e-2: none
/// 9.3e-7, Baumgarte 1.1e-8. Without stabilisation the violation grows (second half over first
/// half: 5.8 and 4.1 times); with it, it stays bounded (1.6 and 1.5 times). max |G Ẋ|: none
/// 2.0e-6 and 9.3e-7, Baumgarte 1.5e-7 and 1.5e-7.
#[test]
fn baumgarte_bounds_the_drift() {
    for (name, method) in [
        ("DOPRI5 rtol 1e-6", Method::dopri5(1e-6, 1e-8)),
        ("RK4 dt 1e-2", Method::Rk4 { dt: 1e-2 }),
    ] {
        let none = paper_round_trip(2.0, IntegrateOptions::new(method, Stabilization::None));
        let baum = paper_round_trip(
            2.0,
            IntegrateOptions::new(method, Stabilization::baumgarte()),
        );
        print_run(&format!("{name}, none"), &none);
        print_run(&format!("{name}, Baumgarte 10/s"), &baum);
        let (vn, vb) = (none.stats.max_violation, baum.stats.max_violation);
        assert!(vn > 3e-7, "{name}: no drift to remove? {vn:e}");
        assert!(vb < vn / 30.0, "{name}: none {vn:e}, Baumgarte {vb:e}");
        assert!(
            none.violation_halves[1] > 3.0 * none.violation_halves[0],
            "{name}: drift does not grow {:?}",
            none.violation_halves
        );
        assert!(
            baum.violation_halves[1] < 2.5 * baum.violation_halves[0],
            "{name}: Baumgarte not bounded {:?}",
            baum.violation_halves
        );
        // The velocity constraint improves too.
        assert!(
            baum.stats.max_velocity_violation < none.stats.max_velocity_violation / 3.0,
            "{name}"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// The simulator's bookkeeping.

#[test]
fn inconsistent_initial_state_is_projected_and_reported() {
    let model = Model::new(Stewart6Ups::default());
    let start = traek_p_start(&model);
    let mut rng = XorShift(0x1_2009);
    let x0: [f64; NS] = core::array::from_fn(|j| start.x[j] + rng.range(-1e-4, 1e-4));
    let v0: [f64; NS] = core::array::from_fn(|j| start.xdot[j] + rng.range(-1e-3, 1e-3));
    let mut d = Data::new(&model);
    for stab in [
        Stabilization::None,
        Stabilization::Projection,
        Stabilization::CoordinatePartitioning,
    ] {
        let options = IntegrateOptions::new(Method::Rk4 { dt: 1e-3 }, stab);
        let mut sim = Simulator::new(&model, &mut d, 0.0, &x0, &v0, options).unwrap();
        let s = *sim.stats();
        assert!(
            s.initial_correction > 1e-6 && s.initial_correction < 1e-3,
            "{s:?}"
        );
        assert!(s.initial_velocity_correction > 1e-5, "{s:?}");
        assert!(
            s.max_violation < 1e-12 && s.max_velocity_violation < 1e-12,
            "{s:?}"
        );
        let mut f = [0.0; MS];
        model.kernels().constraints(sim.x(), &mut f);
        assert!(max_abs(&f) < 1e-12);
        sim.run(&model, &mut d, 0.01, &mut zero_control(), |_| {})
            .unwrap();
        assert_eq!(sim.stats().steps, 10);
        assert!((sim.t() - 0.01).abs() < 1e-15);
    }
}

#[test]
fn invalid_options_and_times_are_errors() {
    use rbss_runtime::IntegrateError;
    let model = Model::new(Stewart6Ups::default());
    let start = traek_p_start(&model);
    let mut d = Data::new(&model);
    let new = |d: &mut Data<NS, MS>, method| {
        Simulator::new(
            &model,
            d,
            0.0,
            &start.x,
            &start.xdot,
            IntegrateOptions::new(method, Stabilization::None),
        )
    };
    for (method, what) in [
        (Method::Rk4 { dt: 0.0 }, "dt"),
        (Method::Rk4 { dt: f64::NAN }, "dt"),
        (Method::dopri5(-1.0, 1e-9), "rtol"),
        (Method::dopri5(0.0, 0.0), "atol"),
        (Method::dop853(f64::NAN, 1e-9), "rtol"),
        (Method::dop853(0.0, 0.0), "atol"),
        (
            Method::Dop853 {
                rtol: 1e-8,
                atol: 1e-10,
                h_init: 0.0,
                h_max: 0.0,
                control: rbss_runtime::StepControl::Standard,
            },
            "h_max",
        ),
    ] {
        assert_eq!(
            new(&mut d, method).unwrap_err(),
            IntegrateError::InvalidOptions { what }
        );
    }
    let mut sim = new(&mut d, Method::dopri5(1e-6, 1e-8)).unwrap();
    assert!(matches!(
        sim.step(&model, &mut d, 0.0, &mut zero_control()),
        Err(IntegrateError::InvalidOptions { .. })
    ));
    // `run` with a non-finite end time is an error, not a silent success after zero steps.
    for t_end in [f64::NAN, f64::INFINITY] {
        assert_eq!(
            sim.run(&model, &mut d, t_end, &mut zero_control(), |_| {})
                .unwrap_err(),
            IntegrateError::InvalidOptions {
                what: "t_end (not finite)"
            }
        );
    }
    // A failing control callback stops the simulation with its time and error.
    let mut failing = |t: f64, _: &[f64; NS], _: &[f64; NS], _: &mut [f64]| {
        if t > 0.05 {
            Err(SolverError::NonFinite { what: "test" })
        } else {
            Ok(())
        }
    };
    match sim.run(&model, &mut d, 1.0, &mut failing, |_| {}) {
        Err(IntegrateError::Control { t, error }) => {
            assert!(t > 0.05 && t < 0.2, "{t}");
            assert_eq!(error, SolverError::NonFinite { what: "test" });
        }
        other => panic!("{other:?}"),
    }
    // A step limit.
    let mut options = IntegrateOptions::new(Method::Rk4 { dt: 1e-3 }, Stabilization::None);
    options.max_steps = 5;
    let mut sim = Simulator::new(&model, &mut d, 0.0, &start.x, &start.xdot, options).unwrap();
    assert!(matches!(
        sim.run(&model, &mut d, 1.0, &mut zero_control(), |_| {}),
        Err(IntegrateError::MaxSteps { steps: 5, .. })
    ));
}

// ---------------------------------------------------------------------------------------------
// The full report (run once, by hand):
// cargo test --release -p rbss-runtime --test dynamics -- --ignored --nocapture

/// The paper's full period [0, 2] s with RK4 and DOPRI5 at several tolerances and every
/// stabilisation, energy drift, and Baumgarte's gain: numbers and wall times, printed only.
#[test]
#[ignore = "a report, run by hand with --nocapture"]
fn report_full_period() {
    let o = IntegrateOptions::new;
    println!("== per call, 6-UPS, mean over 64 random states x 300 calls (wall time)");
    let model = Model::new(Stewart6Ups::default());
    let mut rng = XorShift(0x71_2009);
    let states: Vec<Data<NS, MS>> = (0..64)
        .map(|_| random_stewart_state(&model, &mut rng))
        .collect();
    let time = |name: &str, f: &mut dyn FnMut(&mut Data<NS, MS>)| {
        let mut ds = states.clone();
        let start = std::time::Instant::now();
        for _ in 0..300 {
            for d in ds.iter_mut() {
                f(d);
            }
        }
        let per = start.elapsed().as_secs_f64() / (300.0 * ds.len() as f64);
        println!("{name:<40} {:.2} µs", per * 1e6);
    };
    let u = [300.0; 6];
    time("inverse_dynamics (block elimination)", &mut |d| {
        std::hint::black_box(inverse_dynamics(&model, d, None).unwrap());
    });
    time("inverse_dynamics_dense", &mut |d| {
        std::hint::black_box(inverse_dynamics_dense(&model, d, None).unwrap());
    });
    time("forward_dynamics", &mut |d| {
        std::hint::black_box(forward_dynamics(&model, d, &u, None, Baumgarte::NONE).unwrap());
    });
    time("forward_dynamics, Baumgarte", &mut |d| {
        std::hint::black_box(forward_dynamics(&model, d, &u, None, Baumgarte::DEFAULT).unwrap());
    });
    time("dynamics_terms kernel alone", &mut |d| {
        let (x, v) = (d.x, d.xdot);
        let (mut g, mut gam, mut m, mut p) =
            ([[0.0; MS]; NS], [0.0; MS], [[0.0; NS]; NS], [0.0; NS]);
        model
            .kernels()
            .dynamics_terms(&x, &v, &mut g, &mut gam, &mut m, &mut p);
        std::hint::black_box((g, gam, m, p));
    });
    time("IK + velocity + acceleration (warm)", &mut |d| {
        let o: [f64; 6] = core::array::from_fn(|i| d.x[18 + i]);
        let z = [0.1; 6];
        set_state(&model, d, &o, &z, &z).unwrap();
        std::hint::black_box(&d.xddot);
    });
    time("the same, inverse_kinematics_full", &mut |d| {
        let o: [f64; 6] = core::array::from_fn(|i| d.x[18 + i]);
        let z = [0.1; 6];
        rbss_runtime::inverse_kinematics_full(&model, d, &o, &z, &z).unwrap();
        std::hint::black_box(&d.xddot);
    });
    time("IK + vel + acc + inverse dynamics", &mut |d| {
        let o: [f64; 6] = core::array::from_fn(|i| d.x[18 + i]);
        let z = [0.1; 6];
        set_state(&model, d, &o, &z, &z).unwrap();
        std::hint::black_box(inverse_dynamics(&model, d, None).unwrap());
    });
    time("the same, inverse_dynamics_full", &mut |d| {
        let o: [f64; 6] = core::array::from_fn(|i| d.x[18 + i]);
        let z = [0.1; 6];
        std::hint::black_box(
            rbss_runtime::inverse_dynamics_full(&model, d, &o, &z, &z, None).unwrap(),
        );
    });
    println!("== round trip over [0, 2] s (platform error vs TraekP; |f| max in each half)");
    let pi = |beta| rbss_runtime::StepControl::Pi { beta };
    let dopri = |rtol: f64, control| Method::Dopri5 {
        rtol,
        atol: rtol * 1e-2,
        h_init: 0.0,
        h_max: f64::INFINITY,
        control,
    };
    let runs: Vec<(&str, IntegrateOptions)> = vec![
        (
            "RK4 dt 1e-3, none (the paper)",
            o(Method::Rk4 { dt: 1e-3 }, Stabilization::None),
        ),
        (
            "RK4 dt 1e-3, projection",
            o(Method::Rk4 { dt: 1e-3 }, Stabilization::Projection),
        ),
        (
            "RK4 dt 1e-3, Baumgarte",
            o(Method::Rk4 { dt: 1e-3 }, Stabilization::baumgarte()),
        ),
        (
            "RK4 dt 1e-3, coord. partitioning",
            o(
                Method::Rk4 { dt: 1e-3 },
                Stabilization::CoordinatePartitioning,
            ),
        ),
        (
            "RK4 dt 1e-2, none",
            o(Method::Rk4 { dt: 1e-2 }, Stabilization::None),
        ),
        (
            "DOPRI5 1e-6, projection",
            o(dopri(1e-6, pi(0.04)), Stabilization::Projection),
        ),
        (
            "DOPRI5 1e-8, projection",
            o(dopri(1e-8, pi(0.04)), Stabilization::Projection),
        ),
        (
            "DOPRI5 1e-10, projection",
            o(dopri(1e-10, pi(0.04)), Stabilization::Projection),
        ),
        (
            "DOPRI5 1e-12, projection",
            o(dopri(1e-12, pi(0.04)), Stabilization::Projection),
        ),
        (
            "DOPRI5 1e-10, none",
            o(dopri(1e-10, pi(0.04)), Stabilization::None),
        ),
        (
            "DOPRI5 1e-10, Baumgarte",
            o(dopri(1e-10, pi(0.04)), Stabilization::baumgarte()),
        ),
        (
            "DOPRI5 1e-10, coord. partitioning",
            o(
                dopri(1e-10, pi(0.04)),
                Stabilization::CoordinatePartitioning,
            ),
        ),
        (
            "DOPRI5 1e-10 standard ctrl, proj.",
            o(
                dopri(1e-10, rbss_runtime::StepControl::Standard),
                Stabilization::Projection,
            ),
        ),
        (
            "DOPRI5 1e-6 standard ctrl, proj.",
            o(
                dopri(1e-6, rbss_runtime::StepControl::Standard),
                Stabilization::Projection,
            ),
        ),
    ];
    for (name, options) in runs {
        print_run(name, &paper_round_trip(2.0, options));
    }
    println!("== the same with the control in one inverse_dynamics_full call per evaluation");
    for (name, options) in [
        (
            "RK4 dt 1e-3, none, combined ID",
            o(Method::Rk4 { dt: 1e-3 }, Stabilization::None),
        ),
        (
            "DOPRI5 1e-10, projection, combined ID",
            o(dopri(1e-10, pi(0.04)), Stabilization::Projection),
        ),
        (
            "DOPRI5 1e-10, none, combined ID",
            o(dopri(1e-10, pi(0.04)), Stabilization::None),
        ),
        (
            "DOPRI5 1e-12, projection, combined ID",
            o(dopri(1e-12, pi(0.04)), Stabilization::Projection),
        ),
    ] {
        print_run(name, &paper_round_trip_with(2.0, options, true));
    }

    println!("== energy drift, free motion 0.5 s (relative to max T)");
    for (name, options) in [
        (
            "DOPRI5 1e-8, projection",
            o(Method::dopri5(1e-8, 1e-10), Stabilization::Projection),
        ),
        (
            "DOPRI5 1e-10, projection",
            o(Method::dopri5(1e-10, 1e-12), Stabilization::Projection),
        ),
        (
            "DOPRI5 1e-10, none",
            o(Method::dopri5(1e-10, 1e-12), Stabilization::None),
        ),
        (
            "DOPRI5 1e-10, coord. partitioning",
            o(
                Method::dopri5(1e-10, 1e-12),
                Stabilization::CoordinatePartitioning,
            ),
        ),
        (
            "DOPRI5 1e-10, Baumgarte",
            o(Method::dopri5(1e-10, 1e-12), Stabilization::baumgarte()),
        ),
        (
            "RK4 dt 1e-2, projection",
            o(Method::Rk4 { dt: 1e-2 }, Stabilization::Projection),
        ),
        (
            "RK4 dt 1e-3, projection",
            o(Method::Rk4 { dt: 1e-3 }, Stabilization::Projection),
        ),
        (
            "RK4 dt 1e-4, projection",
            o(Method::Rk4 { dt: 1e-4 }, Stabilization::Projection),
        ),
        (
            "RK4 dt 1e-3, none",
            o(Method::Rk4 { dt: 1e-3 }, Stabilization::None),
        ),
    ] {
        let (drift, s, secs) = free_motion(options);
        println!(
            "{name:<40} drift {drift:.2e}  steps {:>5} rhs {:>6} |f| {:.1e}  {:.1} ms",
            s.steps,
            s.rhs_evaluations,
            s.max_violation,
            secs * 1e3
        );
    }

    println!("== Baumgarte gain sweep (round trip, 2 s): max |f|, max |G Xdot|, rhs");
    for (mname, method) in [
        ("RK4 dt 1e-2", Method::Rk4 { dt: 1e-2 }),
        ("RK4 dt 1e-3", Method::Rk4 { dt: 1e-3 }),
        ("DOPRI5 1e-4", Method::dopri5(1e-4, 1e-6)),
        ("DOPRI5 1e-6", Method::dopri5(1e-6, 1e-8)),
        ("DOPRI5 1e-8", Method::dopri5(1e-8, 1e-10)),
    ] {
        for w in [0.0, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0] {
            let stab = if w == 0.0 {
                Stabilization::None
            } else {
                Stabilization::Baumgarte(Baumgarte::critical(w))
            };
            let r = paper_round_trip(2.0, o(method, stab));
            println!(
                "{mname:<12} omega {w:>5}: |f| {:.2e}  |G Xdot| {:.2e}  pos {:.2e}  rhs {}",
                r.stats.max_violation,
                r.stats.max_velocity_violation,
                r.pos,
                r.stats.rhs_evaluations
            );
        }
    }
}
