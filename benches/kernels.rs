//! Generated kernels and the solvers built on them, per robot: bench ids `robot/kernel`.
//!
//! Run with `cargo bench --bench kernels` (release profile). For each generated robot:
//!
//! - every kernel (`constraints`, `jacobian`, `jacobian_p`, `jacobian_ik`, `gamma`, the fused
//!   `constraints_jacobian_ik` and `constraints_jacobian_p`, and the dynamics kernels
//!   `body_frames`, `mass_matrix`, `psi`, `energy` and the fused `dynamics_terms`) at the home
//!   assembly `X`
//!   with a consistent velocity `Ẋ` there (inverse velocity of the robot's reference motion at
//!   `t = 0`), inputs through `divan::black_box`;
//! - the numeric baseline `jacobian_fd`: `G` by central differences of the generated
//!   `constraints` (2 N evaluations), so `jacobian` reads as a ratio against it; likewise
//!   `mass_matrix_numeric` (`M` by exact polarisation of the generated kinetic energy `T`,
//!   N(N+1)/2 + N `energy` calls) and `psi_numeric` (`psi` from the numeric Lagrangian of `T`
//!   and `Pi`, central differences as in `tests/dynamics_fd.rs`, 6 N `energy` calls) for
//!   `mass_matrix` and `psi`; their accuracy against the generated kernels is printed to
//!   stderr once, before the benches;
//! - the solvers on a tracking loop along the reference motion (TraekP for the Stewart platform,
//!   TraekP and a second platform above it for `stewart_2stage`):
//!   `*_warm` starts from the solution one control period (`DT`) earlier, `*_cold` from home;
//!   the dynamics (`inverse_dynamics`, `forward_dynamics` with the `U` of inverse dynamics) at
//!   the motion's state at `T0`; `id_sample` is one sample of the paper's feed-forward loop
//!   (warm inverse kinematics, velocity, acceleration, inverse dynamics), `id_full` the same
//!   in one `inverse_dynamics_full` call, and `ik_full` likewise for `ik_vel_acc_sample`;
//!   `rk4_step` is one step of the simulator (RK4, four forward-dynamics right-hand sides with a
//!   constant `U`) and `rk4_step_id` one step of the paper's round trip (each right-hand side
//!   with `U` from `inverse_dynamics_full` along the motion); `rk4_run_id` is a step of the
//!   round trip as the command runs it (a continuing run, the control evaluated once per
//!   distinct time, time per step).
//!
//! Before the benches, the Newton iteration counts of the four position solves are printed to
//! stderr (deterministic, unlike the timings).

use divan::black_box;
use rbss::paper::{OMEGA, traek_p};
use rbss_runtime::{
    Data, Dynamics, IntegrateOptions, Kernels, Method, Model, Simulator, SolveReport, SolverError,
    Stabilization, forward_kinematics, inverse_acceleration, inverse_dynamics, inverse_kinematics,
    inverse_velocity,
};

/// Time of the benchmarked sample on the reference motion, s.
const T0: f64 = 0.3;
/// Control period of the tracking loop (1 kHz): warm starts come from `T0 - DT`, s.
const DT: f64 = 1e-3;
/// Offset of the `fk_cold` target pose from home in the first two outputs (x, y): 0.05 m.
const FK_COLD_OFFSET: [f64; 2] = [0.03, 0.04];

/// Output pose, rate and acceleration of a robot's reference motion at time `t`.
type MotionFn<const O: usize> = fn(f64) -> [[f64; O]; 3];

/// Steps of the continuing run of `rk4_run_id`.
const RUN_STEPS: usize = 20;

/// A reference motion as the command's trajectories are (`rbss::trajectory::Trajectory`), for
/// the round trip's control.
struct Motion<const O: usize>(MotionFn<O>);

impl<const O: usize> rbss::trajectory::Trajectory for Motion<O> {
    fn dim(&self) -> usize {
        O
    }
    fn eval(&self, t: f64, pos: &mut [f64], vel: &mut [f64], acc: &mut [f64]) {
        let [p, v, a] = (self.0)(t);
        pos[..O].copy_from_slice(&p);
        vel[..O].copy_from_slice(&v);
        acc[..O].copy_from_slice(&a);
    }
    fn describe(&self) -> String {
        "the bench's reference motion".to_string()
    }
}

/// The paper's platform motion TraekP (`src/paper.rs`); passes through home at `t = 0`.
fn traek(t: f64) -> [[f64; 6]; 3] {
    let (pos, vel, acc) = traek_p(t, OMEGA);
    [pos, vel, acc]
}

/// A figure eight of the five-bar's end effector through its home `(0, 0.3)` at `t = 0`:
/// `x = 0.05 sin(wt)`, `y = 0.3 + 0.03 sin(2wt)`, with TraekP's `w`.
fn figure_eight(t: f64) -> [[f64; 2]; 3] {
    let w = OMEGA;
    let (s1, c1) = (w * t).sin_cos();
    let (s2, c2) = (2.0 * w * t).sin_cos();
    [
        [0.05 * s1, 0.3 + 0.03 * s2],
        [0.05 * w * c1, 0.06 * w * c2],
        [-0.05 * w * w * s1, -0.12 * w * w * s2],
    ]
}

/// The UR5's flange motion of models/trajectories/ur5.toml: from its home pose at `t = 0`
/// (`link6_x`, `_y`, `_z`, `_roll`, `_pitch`, `_yaw`), a 5 cm circle, a 3 cm vertical figure and
/// a 0.2 rad turn of the yaw, with TraekP's `w`.
fn ur5_motion(t: f64) -> [[f64; 6]; 3] {
    let w = OMEGA;
    let (s1, c1) = (w * t).sin_cos();
    let (s2, c2) = (2.0 * w * t).sin_cos();
    let home = [
        -0.5615701059437073,
        -0.2252727516909624,
        0.34124203713702866,
        -3.113927766653958,
        0.009389622415266129,
        1.470937846115427,
    ];
    let mut out = [home, [0.0; 6], [0.0; 6]];
    out[0][0] += 0.05 * s1;
    out[0][1] += 0.05 * (1.0 - c1);
    out[0][2] += 0.03 * s2;
    out[0][5] += 0.2 * s1;
    out[1][0] = 0.05 * w * c1;
    out[1][1] = 0.05 * w * s1;
    out[1][2] = 0.06 * w * c2;
    out[1][5] = 0.2 * w * c1;
    out[2][0] = -0.05 * w * w * s1;
    out[2][1] = 0.05 * w * w * c1;
    out[2][2] = -0.12 * w * w * s2;
    out[2][5] = -0.2 * w * w * s1;
    out
}

/// The two platforms of `stewart_2stage`: platform 1 on TraekP, platform 2 0.56 m above it
/// (its home at `t = 0`) with TraekP's orientation and a sway of its own,
/// `x2 = x1 + 0.02 sin(2wt)`.
fn two_stage(t: f64) -> [[f64; 12]; 3] {
    let w = OMEGA;
    let (p, v, a) = traek_p(t, w);
    let (s2, c2) = (2.0 * w * t).sin_cos();
    let mut out = [[0.0; 12]; 3];
    for (o, d) in out.iter_mut().zip([p, v, a]) {
        o[..6].copy_from_slice(&d);
        o[6..].copy_from_slice(&d);
    }
    out[0][8] += 0.56;
    out[0][6] += 0.02 * s2;
    out[1][6] += 0.04 * w * c2;
    out[2][6] -= 0.08 * w * w * s2;
    out
}

/// Everything a bench needs, solved once outside the timed loop (the setup allocates the
/// actuated vectors; the timed calls do not allocate, see `tests/alloc.rs`).
struct Setup<K, const N: usize, const M: usize, const O: usize> {
    model: Model<K, N, M>,
    /// The home assembly `Structure::home`.
    x_home: [f64; N],
    /// A consistent velocity at home: inverse velocity of the motion's rate at `t = 0`.
    xdot_home: [f64; N],
    /// The motion's output pose, rate and acceleration at `T0`.
    pose: [[f64; O]; 3],
    /// The IK solution at `T0 - DT`: the warm start of the tracking loop.
    x_prev: [f64; N],
    /// The IK solution at `T0`, with its velocity and acceleration.
    x: [f64; N],
    /// Actuated `q`, `q̇`, `q̈` of the solution at `T0`.
    q: [Vec<f64>; 3],
    /// Actuated `q` of the IK solution at the pose `FK_COLD_OFFSET` away from home.
    q_far: Vec<f64>,
    /// The control forces `U` of inverse dynamics at `T0` (without applied forces).
    u: Vec<f64>,
    /// The reference motion.
    motion: MotionFn<O>,
}

impl<K: Dynamics<N, M>, const N: usize, const M: usize, const O: usize> Setup<K, N, M, O> {
    fn new(kernels: K, motion: MotionFn<O>) -> Self {
        let model = Model::new(kernels);
        let s = model.structure();
        let actuated = |x: &[f64; N]| s.actuated.iter().map(|&j| x[j]).collect::<Vec<_>>();
        let name = s.name;
        let ok = |what: &str, r: Result<SolveReport, SolverError>| {
            r.unwrap_or_else(|e| panic!("{name}: setup {what}: {e}"));
        };
        let mut d = Data::new(&model);
        let x_home = d.x;
        ok(
            "home velocity",
            inverse_velocity(&model, &mut d, &motion(0.0)[1]),
        );
        let xdot_home = d.xdot;

        let [p_prev, _, _] = motion(T0 - DT);
        ok("IK at T0 - DT", inverse_kinematics(&model, &mut d, &p_prev));
        let x_prev = d.x;
        let pose = motion(T0);
        ok("IK at T0", inverse_kinematics(&model, &mut d, &pose[0]));
        ok(
            "inverse velocity",
            inverse_velocity(&model, &mut d, &pose[1]),
        );
        ok(
            "inverse acceleration",
            inverse_acceleration(&model, &mut d, &pose[2]),
        );
        let x = d.x;
        let q = [actuated(&d.x), actuated(&d.xdot), actuated(&d.xddot)];
        inverse_dynamics(&model, &mut d, None)
            .unwrap_or_else(|e| panic!("{name}: setup inverse dynamics: {e}"));
        let u = d.u().to_vec();

        let mut far: [f64; O] = core::array::from_fn(|i| x_home[s.outputs[i]]);
        far[0] += FK_COLD_OFFSET[0];
        far[1] += FK_COLD_OFFSET[1];
        d.set_home(&model);
        ok(
            "IK at the fk_cold pose",
            inverse_kinematics(&model, &mut d, &far),
        );
        let q_far = actuated(&d.x);
        Self {
            model,
            x_home,
            xdot_home,
            pose,
            x_prev,
            x,
            q,
            q_far,
            u,
            motion,
        }
    }

    /// A `Data` at the solution at `T0`, with its velocity (for the acceleration solves).
    fn data_at_t0(&self) -> Data<N, M> {
        let mut d = Data::new(&self.model);
        d.x = self.x;
        inverse_velocity(&self.model, &mut d, &self.pose[1]).expect("setup: inverse velocity");
        d
    }

    /// A simulator at the state at `T0` (RK4 with the control period `DT`, no stabilisation, no
    /// monitoring), its `Data`, and `U` there.
    fn simulator_at_t0(&self) -> (Simulator<N, M>, Data<N, M>) {
        let mut d = self.state_at_t0();
        let (x0, v0) = (d.x, d.xdot);
        let mut o = IntegrateOptions::new(Method::Rk4 { dt: DT }, Stabilization::None);
        o.monitor = false;
        let sim = Simulator::new(&self.model, &mut d, T0, &x0, &v0, o).expect("setup: simulator");
        (sim, d)
    }

    /// A `Data` at the solution at `T0`, with its velocity and acceleration (for the dynamics).
    fn state_at_t0(&self) -> Data<N, M> {
        let mut d = self.data_at_t0();
        inverse_acceleration(&self.model, &mut d, &self.pose[2])
            .expect("setup: inverse acceleration");
        d
    }

    fn ik_cold(&self, d: &mut Data<N, M>) -> Result<SolveReport, SolverError> {
        d.set_home(&self.model);
        inverse_kinematics(&self.model, d, black_box(&self.pose[0]))
    }

    fn ik_warm(&self, d: &mut Data<N, M>) -> Result<SolveReport, SolverError> {
        d.x = self.x_prev;
        inverse_kinematics(&self.model, d, black_box(&self.pose[0]))
    }

    fn fk_cold(&self, d: &mut Data<N, M>) -> Result<SolveReport, SolverError> {
        d.set_home(&self.model);
        forward_kinematics(&self.model, d, black_box(&self.q_far))
    }

    fn fk_warm(&self, d: &mut Data<N, M>) -> Result<SolveReport, SolverError> {
        d.x = self.x_prev;
        forward_kinematics(&self.model, d, black_box(&self.q[0]))
    }
}

/// `G` by central differences of `constraints`: 2 N evaluations, step
/// `h_j = cbrt(ε) max(1, |x_j|)` (as in `tests/derivatives_fd.rs`).
fn jacobian_fd<K: Kernels<N, M>, const N: usize, const M: usize>(
    k: &K,
    x: &[f64; N],
    g: &mut [[f64; M]; N],
) {
    let mut xh = *x;
    let (mut fp, mut fm) = ([0.0; M], [0.0; M]);
    for (j, col) in g.iter_mut().enumerate() {
        let h = f64::EPSILON.cbrt() * x[j].abs().max(1.0);
        xh[j] = x[j] + h;
        k.constraints(&xh, &mut fp);
        xh[j] = x[j] - h;
        k.constraints(&xh, &mut fm);
        xh[j] = x[j];
        for ((gij, p), m) in col.iter_mut().zip(&fp).zip(&fm) {
            *gij = (p - m) / (2.0 * h);
        }
    }
}

/// `[T, Pi]` of the generated `energy` kernel.
fn energy<K: Dynamics<N, M>, const N: usize, const M: usize>(
    k: &K,
    x: &[f64; N],
    v: &[f64; N],
) -> [f64; 2] {
    let mut e = [0.0; 2];
    k.energy(x, v, &mut e);
    e
}

/// `M` by exact polarisation of the kinetic energy, a quadratic form in `Ẋ`:
/// `M_ij = T(e_i + e_j) - T(e_i) - T(e_j)` for `i <= j` (so `M_ii = T(2 e_i) - 2 T(e_i)`),
/// N(N+1)/2 + N evaluations of the generated `energy` kernel.
fn mass_matrix_numeric<K: Dynamics<N, M>, const N: usize, const M: usize>(
    k: &K,
    x: &[f64; N],
    out: &mut [[f64; N]; N],
) {
    let mut v = [0.0; N];
    let mut ti = [0.0; N];
    for (i, t) in ti.iter_mut().enumerate() {
        v[i] = 1.0;
        *t = energy(k, x, &v)[0];
        v[i] = 0.0;
    }
    for i in 0..N {
        for j in i..N {
            v[i] += 1.0;
            v[j] += 1.0;
            let m = energy(k, x, &v)[0] - ti[i] - ti[j];
            v[i] = 0.0;
            v[j] = 0.0;
            out[i][j] = m;
            out[j][i] = m;
        }
    }
}

/// `psi(X, Ẋ) = ∂T/∂X - ∂Pi/∂X - d/dt(∂T/∂Ẋ)` at `Ẍ = 0`, the numeric Lagrangian of
/// `tests/dynamics_fd.rs`: `∂T/∂Ẋ_k` exact (unit central difference of a quadratic), its time
/// derivative by central differences along `X ± h Ẋ` (`h = 1e-5`), `∂(T, Pi)/∂X_k` with step
/// `1e-6 max(1, |X_k|)`: 6 N evaluations of the generated `energy` kernel.
fn psi_numeric<K: Dynamics<N, M>, const N: usize, const M: usize>(
    k: &K,
    x: &[f64; N],
    v: &[f64; N],
    out: &mut [f64; N],
) {
    let h = 1e-5;
    let (mut xp, mut xm) = (*x, *x);
    for j in 0..N {
        xp[j] += h * v[j];
        xm[j] -= h * v[j];
    }
    let dt_dv = |x: &[f64; N], kk: usize| {
        let (mut vp, mut vm) = (*v, *v);
        vp[kk] += 1.0;
        vm[kk] -= 1.0;
        (energy(k, x, &vp)[0] - energy(k, x, &vm)[0]) / 2.0
    };
    for (kk, o) in out.iter_mut().enumerate() {
        let ddt = (dt_dv(&xp, kk) - dt_dv(&xm, kk)) / (2.0 * h);
        let hk = 1e-6 * x[kk].abs().max(1.0);
        let (mut x1, mut x2) = (*x, *x);
        x1[kk] += hk;
        x2[kk] -= hk;
        let (e1, e2) = (energy(k, &x1, v), energy(k, &x2, v));
        *o = (e1[0] - e2[0]) / (2.0 * hk) - (e1[1] - e2[1]) / (2.0 * hk) - ddt;
    }
}

/// The accuracy of the numeric baselines against the generated kernels at the bench state:
/// max |numeric - generated| and that relative to max |generated|.
fn print_numeric_accuracy<K: Dynamics<N, M>, const N: usize, const M: usize, const O: usize>(
    s: &Setup<K, N, M, O>,
) {
    let k = s.model.kernels();
    let name = s.model.structure().name;
    let (x, v) = (&s.x_home, &s.xdot_home);
    let report = |what: &str, num: &[f64], gen_: &[f64]| {
        let err = num
            .iter()
            .zip(gen_)
            .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
        let scale = gen_.iter().fold(0.0_f64, |m, a| m.max(a.abs()));
        eprintln!(
            "{name}/{what}: max |numeric - generated| = {err:.1e} ({:.1e} of max |generated| = {scale:.3e})",
            err / scale
        );
    };
    let mut g = [[0.0; M]; N];
    let mut gn = [[0.0; M]; N];
    k.jacobian(x, &mut g);
    jacobian_fd(k, x, &mut gn);
    report("jacobian_fd", gn.as_flattened(), g.as_flattened());
    let mut m = [[0.0; N]; N];
    let mut mn = [[0.0; N]; N];
    k.mass_matrix(x, &mut m);
    mass_matrix_numeric(k, x, &mut mn);
    report("mass_matrix_numeric", mn.as_flattened(), m.as_flattened());
    let (mut p, mut pn) = ([0.0; N], [0.0; N]);
    k.psi(x, v, &mut p);
    psi_numeric(k, x, v, &mut pn);
    report("psi_numeric", &pn, &p);
}

/// The bench functions of one robot (its module gives the `robot/` part of the id). Each solver
/// bench first checks, untimed, that its call succeeds: a failing solve would time an error path.
macro_rules! robot_benches {
    ($setup:path) => {
        use divan::{Bencher, black_box};
        // The solvers by path (`rt::`): the bench functions carry their names.
        use rbss_runtime::{self as rt, Data, Dynamics, Kernels};

        #[divan::bench]
        fn constraints(b: Bencher) {
            let s = $setup();
            let k = s.model.kernels();
            let mut f = [0.0; M];
            b.bench_local(|| black_box(k).constraints(black_box(&s.x_home), black_box(&mut f)));
        }

        #[divan::bench]
        fn jacobian(b: Bencher) {
            let s = $setup();
            let k = s.model.kernels();
            let mut g = [[0.0; M]; N];
            b.bench_local(|| black_box(k).jacobian(black_box(&s.x_home), black_box(&mut g)));
        }

        #[divan::bench]
        fn jacobian_p(b: Bencher) {
            let s = $setup();
            let k = s.model.kernels();
            let mut g = [[0.0; M]; N];
            b.bench_local(|| black_box(k).jacobian_p(black_box(&s.x_home), black_box(&mut g)));
        }

        #[divan::bench]
        fn jacobian_ik(b: Bencher) {
            let s = $setup();
            let k = s.model.kernels();
            let mut g = [[0.0; M]; N];
            b.bench_local(|| black_box(k).jacobian_ik(black_box(&s.x_home), black_box(&mut g)));
        }

        #[divan::bench]
        fn constraints_jacobian_ik(b: Bencher) {
            let s = $setup();
            let k = s.model.kernels();
            let (mut f, mut g) = ([0.0; M], [[0.0; M]; N]);
            b.bench_local(|| {
                black_box(k).constraints_jacobian_ik(
                    black_box(&s.x_home),
                    black_box(&mut f),
                    black_box(&mut g),
                )
            });
        }

        #[divan::bench]
        fn constraints_jacobian_p(b: Bencher) {
            let s = $setup();
            let k = s.model.kernels();
            let (mut f, mut g) = ([0.0; M], [[0.0; M]; N]);
            b.bench_local(|| {
                black_box(k).constraints_jacobian_p(
                    black_box(&s.x_home),
                    black_box(&mut f),
                    black_box(&mut g),
                )
            });
        }

        #[divan::bench]
        fn dynamics_terms(b: Bencher) {
            let s = $setup();
            let k = s.model.kernels();
            let (mut g, mut gam) = ([[0.0; M]; N], [0.0; M]);
            let (mut mass, mut psi) = ([[0.0; N]; N], [0.0; N]);
            b.bench_local(|| {
                black_box(k).dynamics_terms(
                    black_box(&s.x_home),
                    black_box(&s.xdot_home),
                    black_box(&mut g),
                    black_box(&mut gam),
                    black_box(&mut mass),
                    black_box(&mut psi),
                )
            });
        }

        #[divan::bench]
        fn gamma(b: Bencher) {
            let s = $setup();
            let k = s.model.kernels();
            let mut out = [0.0; M];
            b.bench_local(|| {
                black_box(k).gamma(
                    black_box(&s.x_home),
                    black_box(&s.xdot_home),
                    black_box(&mut out),
                )
            });
        }

        #[divan::bench]
        fn body_frames(b: Bencher) {
            let s = $setup();
            let k = s.model.kernels();
            let mut out = [[0.0; 12]; robot::NB];
            b.bench_local(|| {
                robot::body_frames(black_box(&k.c), black_box(&s.x_home), black_box(&mut out))
            });
        }

        #[divan::bench]
        fn mass_matrix(b: Bencher) {
            let s = $setup();
            let k = s.model.kernels();
            let mut out = [[0.0; N]; N];
            b.bench_local(|| black_box(k).mass_matrix(black_box(&s.x_home), black_box(&mut out)));
        }

        #[divan::bench]
        fn psi(b: Bencher) {
            let s = $setup();
            let k = s.model.kernels();
            let mut out = [0.0; N];
            b.bench_local(|| {
                black_box(k).psi(
                    black_box(&s.x_home),
                    black_box(&s.xdot_home),
                    black_box(&mut out),
                )
            });
        }

        #[divan::bench]
        fn energy(b: Bencher) {
            let s = $setup();
            let k = s.model.kernels();
            let mut out = [0.0; 2];
            b.bench_local(|| {
                black_box(k).energy(
                    black_box(&s.x_home),
                    black_box(&s.xdot_home),
                    black_box(&mut out),
                )
            });
        }

        /// Numeric baseline for `jacobian`.
        #[divan::bench]
        fn jacobian_fd(b: Bencher) {
            let s = $setup();
            let k = s.model.kernels();
            let mut g = [[0.0; M]; N];
            b.bench_local(|| {
                super::jacobian_fd(black_box(k), black_box(&s.x_home), black_box(&mut g))
            });
        }

        /// Numeric baseline for `mass_matrix`: polarisation of `T`.
        #[divan::bench]
        fn mass_matrix_numeric(b: Bencher) {
            let s = $setup();
            let k = s.model.kernels();
            let mut out = [[0.0; N]; N];
            b.bench_local(|| {
                super::mass_matrix_numeric(black_box(k), black_box(&s.x_home), black_box(&mut out))
            });
        }

        /// Numeric baseline for `psi`: the numeric Lagrangian of `T` and `Pi`.
        #[divan::bench]
        fn psi_numeric(b: Bencher) {
            let s = $setup();
            let k = s.model.kernels();
            let mut out = [0.0; N];
            b.bench_local(|| {
                super::psi_numeric(
                    black_box(k),
                    black_box(&s.x_home),
                    black_box(&s.xdot_home),
                    black_box(&mut out),
                )
            });
        }

        #[divan::bench]
        fn ik_warm(b: Bencher) {
            let s = $setup();
            let mut d = Data::new(&s.model);
            s.ik_warm(&mut d).expect("ik_warm");
            b.bench_local(|| s.ik_warm(&mut d));
        }

        #[divan::bench]
        fn ik_cold(b: Bencher) {
            let s = $setup();
            let mut d = Data::new(&s.model);
            s.ik_cold(&mut d).expect("ik_cold");
            b.bench_local(|| s.ik_cold(&mut d));
        }

        #[divan::bench]
        fn fk_warm(b: Bencher) {
            let s = $setup();
            let mut d = Data::new(&s.model);
            s.fk_warm(&mut d).expect("fk_warm");
            b.bench_local(|| s.fk_warm(&mut d));
        }

        #[divan::bench]
        fn fk_cold(b: Bencher) {
            let s = $setup();
            let mut d = Data::new(&s.model);
            s.fk_cold(&mut d).expect("fk_cold");
            b.bench_local(|| s.fk_cold(&mut d));
        }

        #[divan::bench]
        fn inverse_velocity(b: Bencher) {
            let s = $setup();
            let mut d = s.data_at_t0();
            rt::inverse_velocity(&s.model, &mut d, &s.pose[1]).expect("inverse_velocity");
            b.bench_local(|| rt::inverse_velocity(&s.model, &mut d, black_box(&s.pose[1])));
        }

        #[divan::bench]
        fn inverse_acceleration(b: Bencher) {
            let s = $setup();
            let mut d = s.data_at_t0();
            rt::inverse_acceleration(&s.model, &mut d, &s.pose[2]).expect("inverse_acceleration");
            b.bench_local(|| rt::inverse_acceleration(&s.model, &mut d, black_box(&s.pose[2])));
        }

        #[divan::bench]
        fn forward_velocity(b: Bencher) {
            let s = $setup();
            let mut d = s.data_at_t0();
            rt::forward_velocity(&s.model, &mut d, &s.q[1]).expect("forward_velocity");
            b.bench_local(|| rt::forward_velocity(&s.model, &mut d, black_box(&s.q[1])));
        }

        #[divan::bench]
        fn forward_acceleration(b: Bencher) {
            let s = $setup();
            let mut d = s.data_at_t0();
            rt::forward_acceleration(&s.model, &mut d, &s.q[2]).expect("forward_acceleration");
            b.bench_local(|| rt::forward_acceleration(&s.model, &mut d, black_box(&s.q[2])));
        }

        /// One sample of the tracking loop along the motion: IK warm-started from the previous
        /// sample, then inverse velocity and acceleration.
        #[divan::bench]
        fn ik_vel_acc_sample(b: Bencher) {
            let s = $setup();
            let mut d = Data::new(&s.model);
            let [pose, pose_dot, pose_ddot] = &s.pose;
            d.x = s.x_prev;
            rt::inverse_kinematics(&s.model, &mut d, pose).expect("inverse_kinematics");
            rt::inverse_velocity(&s.model, &mut d, pose_dot).expect("inverse_velocity");
            rt::inverse_acceleration(&s.model, &mut d, pose_ddot).expect("inverse_acceleration");
            b.bench_local(|| {
                d.x = s.x_prev;
                let ik = rt::inverse_kinematics(&s.model, &mut d, black_box(pose));
                let vel = rt::inverse_velocity(&s.model, &mut d, black_box(pose_dot));
                let acc = rt::inverse_acceleration(&s.model, &mut d, black_box(pose_ddot));
                (ik, vel, acc)
            });
        }

        #[divan::bench]
        fn inverse_dynamics(b: Bencher) {
            let s = $setup();
            let mut d = s.state_at_t0();
            rt::inverse_dynamics(&s.model, &mut d, None).expect("inverse_dynamics");
            b.bench_local(|| rt::inverse_dynamics(&s.model, black_box(&mut d), None));
        }

        #[divan::bench]
        fn forward_dynamics(b: Bencher) {
            let s = $setup();
            let mut d = s.state_at_t0();
            let none = rt::Baumgarte::NONE;
            rt::forward_dynamics(&s.model, &mut d, &s.u, None, none).expect("forward_dynamics");
            b.bench_local(|| {
                rt::forward_dynamics(&s.model, black_box(&mut d), black_box(&s.u), None, none)
            });
        }

        /// One sample of the inverse-dynamics tracking loop: `ik_vel_acc_sample`, then inverse
        /// dynamics (the control forces `U` of the paper's round trip).
        #[divan::bench]
        fn id_sample(b: Bencher) {
            let s = $setup();
            let mut d = Data::new(&s.model);
            let [pose, pose_dot, pose_ddot] = &s.pose;
            let sample = |d: &mut Data<N, M>| {
                d.x = s.x_prev;
                rt::inverse_kinematics(&s.model, d, black_box(pose))?;
                rt::inverse_velocity(&s.model, d, black_box(pose_dot))?;
                rt::inverse_acceleration(&s.model, d, black_box(pose_ddot))?;
                rt::inverse_dynamics(&s.model, d, None)
            };
            sample(&mut d).expect("id_sample");
            b.bench_local(|| sample(&mut d));
        }

        /// `ik_vel_acc_sample` in one call (`inverse_kinematics_full`).
        #[divan::bench]
        fn ik_full(b: Bencher) {
            let s = $setup();
            let mut d = Data::new(&s.model);
            let [pose, pose_dot, pose_ddot] = &s.pose;
            let sample = |d: &mut Data<N, M>| {
                d.x = s.x_prev;
                rt::inverse_kinematics_full(
                    &s.model,
                    d,
                    black_box(pose),
                    black_box(pose_dot),
                    black_box(pose_ddot),
                )
            };
            sample(&mut d).expect("ik_full");
            b.bench_local(|| sample(&mut d));
        }

        /// One RK4 step of the simulator from the state at `T0` (four right-hand sides, each a
        /// forward dynamics with `U` of inverse dynamics at `T0`, held constant).
        #[divan::bench]
        fn rk4_step(b: Bencher) {
            let s = $setup();
            let (sim, mut d) = s.simulator_at_t0();
            let mut control = |_: f64, _: &[f64; N], _: &[f64; N], u: &mut [f64]| {
                u.copy_from_slice(&s.u);
                Ok::<(), rt::SolverError>(())
            };
            sim.clone()
                .step(&s.model, &mut d, 1.0, &mut control)
                .expect("rk4_step");
            b.with_inputs(|| sim.clone())
                .bench_local_refs(|sim| sim.step(&s.model, &mut d, 1.0, &mut control));
        }

        /// One RK4 step of the paper's round trip from the state at `T0`: at each of the four
        /// right-hand sides, `U` from `inverse_dynamics_full` along the reference motion at the
        /// stage time (warm-started), then forward dynamics.
        #[divan::bench]
        fn rk4_step_id(b: Bencher) {
            let s = $setup();
            let (sim, mut d) = s.simulator_at_t0();
            let mut reference = s.state_at_t0();
            let motion = s.motion;
            let model = &s.model;
            let mut control = |t: f64, _: &[f64; N], _: &[f64; N], u: &mut [f64]| {
                let [p, v, a] = motion(t);
                rt::inverse_dynamics_full(model, &mut reference, &p, &v, &a, None)?;
                u.copy_from_slice(reference.u());
                Ok::<(), rt::SolverError>(())
            };
            sim.clone()
                .step(&s.model, &mut d, 1.0, &mut control)
                .expect("rk4_step_id");
            b.with_inputs(|| sim.clone())
                .bench_local_refs(|sim| sim.step(&s.model, &mut d, 1.0, &mut control));
        }

        /// One RK4 step of the round trip as `rbss roundtrip` and `rbss bench work-precision`
        /// run it: [`RUN_STEPS`] steps of a continuing run from `T0` (per step: the time of
        /// one divided by their number) with the round trip's control
        /// (`rbss::trajectory::control`), which evaluates `U` once per distinct stage time (RK4's
        /// two midpoint stages share one; a step's end is the next step's start: two
        /// `inverse_dynamics_full` per step, not four) warm-started from the last sample's
        /// Taylor polynomial. `rk4_step_id` above is the definition: four evaluations
        /// of `U` per step, each warm-started from the last solution alone.
        #[divan::bench(args = [super::RUN_STEPS])]
        fn rk4_run_id(b: Bencher, steps: usize) {
            let s = $setup();
            let (sim, mut d) = s.simulator_at_t0();
            let reference = s.state_at_t0();
            let motion = super::Motion(s.motion);
            let run = |d: &mut Data<N, M>| {
                let mut sim = sim.clone();
                let mut control = rbss::trajectory::control(&s.model, &motion, &reference.x);
                for _ in 0..steps {
                    sim.step(&s.model, d, 1.0, &mut control)?;
                }
                Ok::<f64, rt::IntegrateError>(sim.t())
            };
            run(&mut d).expect("rk4_run_id");
            b.counter(divan::counter::ItemsCount::new(steps))
                .bench_local(|| run(&mut d));
        }

        /// `id_sample` in one call (`inverse_dynamics_full`).
        #[divan::bench]
        fn id_full(b: Bencher) {
            let s = $setup();
            let mut d = Data::new(&s.model);
            let [pose, pose_dot, pose_ddot] = &s.pose;
            let sample = |d: &mut Data<N, M>| {
                d.x = s.x_prev;
                rt::inverse_dynamics_full(
                    &s.model,
                    d,
                    black_box(pose),
                    black_box(pose_dot),
                    black_box(pose_ddot),
                    None,
                )
            };
            sample(&mut d).expect("id_full");
            b.bench_local(|| sample(&mut d));
        }
    };
}

mod stewart_6ups {
    use ::stewart_6ups::{self as robot, M, N, Stewart6Ups};

    pub(crate) fn setup() -> super::Setup<Stewart6Ups, N, M, 6> {
        super::Setup::new(Stewart6Ups::default(), super::traek)
    }

    robot_benches!(setup);
}

mod five_bar {
    use ::five_bar::{self as robot, FiveBar, M, N};

    pub(crate) fn setup() -> super::Setup<FiveBar, N, M, 2> {
        super::Setup::new(FiveBar::default(), super::figure_eight)
    }

    robot_benches!(setup);
}

mod stewart_2stage {
    use ::stewart_2stage::{self as robot, M, N, Stewart2Stage};

    pub(crate) fn setup() -> super::Setup<Stewart2Stage, N, M, 12> {
        super::Setup::new(Stewart2Stage::default(), super::two_stage)
    }

    robot_benches!(setup);
}

mod ur5 {
    use ::ur5::{self as robot, M, N, Ur5};

    pub(crate) fn setup() -> super::Setup<Ur5, N, M, 6> {
        super::Setup::new(Ur5::default(), super::ur5_motion)
    }

    robot_benches!(setup);
}

/// Newton iterations and kernel evaluations of the position solves, as `SolveReport` gives them.
fn print_iterations<K: Dynamics<N, M>, const N: usize, const M: usize, const O: usize>(
    s: &Setup<K, N, M, O>,
) {
    let mut d = Data::new(&s.model);
    let name = s.model.structure().name;
    type Solve<K, const N: usize, const M: usize, const O: usize> =
        fn(&Setup<K, N, M, O>, &mut Data<N, M>) -> Result<SolveReport, SolverError>;
    let solves: [(&str, Solve<K, N, M, O>); 4] = [
        ("fk_cold", Setup::fk_cold),
        ("fk_warm", Setup::fk_warm),
        ("ik_cold", Setup::ik_cold),
        ("ik_warm", Setup::ik_warm),
    ];
    for (what, solve) in solves {
        match solve(s, &mut d) {
            Ok(r) => eprintln!(
                "{name}/{what}: {} Newton iterations, {} evaluations, residual {:.1e}, cond {:.1e}",
                r.iterations, r.evaluations, r.residual, r.cond
            ),
            Err(e) => eprintln!("{name}/{what}: FAILED: {e}"),
        }
    }
}

fn main() {
    print_iterations(&stewart_6ups::setup());
    print_iterations(&five_bar::setup());
    print_numeric_accuracy(&stewart_6ups::setup());
    print_numeric_accuracy(&five_bar::setup());
    print_iterations(&stewart_2stage::setup());
    print_numeric_accuracy(&stewart_2stage::setup());
    print_iterations(&ur5::setup());
    print_numeric_accuracy(&ur5::setup());
    divan::main();
}
