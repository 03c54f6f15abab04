//! The small program of the scene benchmark (`bench/scenes/run.sh`): one scene's job, on the
//! crate `robot` (a scene crate, or the full generated crate, which offers the same traits).
//! The job is a cargo feature: `ik` (inverse kinematics along a path at 1 kHz), `id`
//! (`inverse_dynamics_full` along the same path) or `sim` (the simulator, RK4 at 1 ms). The
//! robot's type comes from `robot.rs`, written by run.sh (`type R = robot::FiveBar;`). Prints
//! `name median-ns-per-call` lines. Times are the thread's CPU time
//! (`CLOCK_THREAD_CPUTIME_ID`), not wall time: the machine is shared, and a descheduled thread
//! would otherwise count the other processes' time.
use std::hint::black_box;

#[allow(unused_imports)]
use rbss_runtime::tasks::{
    Constraints, Energy, EquationsOfMotion, ForwardKinematics, InverseKinematics, Jacobian,
};
use rbss_runtime::{Data, Model};

include!(concat!(env!("CARGO_MANIFEST_DIR"), "/robot.rs"));
const N: usize = robot::N;
const M: usize = robot::M;

/// The thread's CPU time in ns.
fn cpu_ns() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; the clock id is a constant of the platform.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    assert_eq!(rc, 0, "clock_gettime");
    ts.tv_sec as f64 * 1e9 + ts.tv_nsec as f64
}

/// Median over 7 rounds of the CPU time per call of `f` (called `reps` times a round), in ns.
fn time(reps: usize, mut f: impl FnMut()) -> f64 {
    let mut t: Vec<f64> = (0..7)
        .map(|_| {
            let t0 = cpu_ns();
            for _ in 0..reps {
                f();
            }
            (cpu_ns() - t0) / reps as f64
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[3]
}

/// The outputs, their rates and accelerations at time `t`: the platform heaves by 1 cm at
/// 1.5 Hz (6 outputs), or the effector runs a 1 cm circle at 1.5 Hz (2 outputs), from home.
#[allow(dead_code)]
fn path(home: &[f64; N], outputs: &[usize], t: f64) -> ([f64; 6], [f64; 6], [f64; 6]) {
    let (mut p, mut v, mut a) = ([0.0; 6], [0.0; 6], [0.0; 6]);
    for (i, &j) in outputs.iter().enumerate() {
        p[i] = home[j];
    }
    let w = 3.0 * std::f64::consts::PI;
    let (s, c) = (w * t).sin_cos();
    let k = if outputs.len() == 6 { 2 } else { 0 };
    p[k] += 0.01 * s;
    v[k] = 0.01 * w * c;
    a[k] = -0.01 * w * w * s;
    if outputs.len() == 2 {
        p[1] += 0.01 * (c - 1.0);
        v[1] = -0.01 * w * s;
        a[1] = -0.01 * w * w * c;
    }
    (p, v, a)
}

fn kernel(name: &str, f: impl FnMut()) {
    println!("kernel/{name} {:.1}", time(200_000, f));
}

fn main() {
    let model = Model::new(R::default());
    let s = model.structure();
    let k = model.kernels();
    let home: [f64; N] = s.home.try_into().unwrap();
    let x = &home;
    let xdot = [0.1; N];
    let (mut f, mut g) = ([0.0; M], [[0.0; M]; N]);
    let mut data = Data::new(&model);
    let o = s.outputs.len();
    let _ = (&xdot, o); // not every job reads them

    #[cfg(feature = "ik")]
    {
        kernel("constraints_jacobian_ik", || {
            k.constraints_jacobian_ik(black_box(x), &mut f, &mut g)
        });
        kernel("constraints", || k.constraints(black_box(x), &mut f));
        // One second of the path at 1 kHz, warm-started sample to sample.
        let ns = time(1, || {
            for i in 0..1000 {
                let (p, _, _) = path(&home, s.outputs, i as f64 * 1e-3);
                rbss_runtime::inverse_kinematics(&model, &mut data, black_box(&p[..o])).unwrap();
            }
        }) / 1000.0;
        println!("solver/inverse_kinematics {ns:.1}");
    }
    #[cfg(feature = "id")]
    {
        let (mut gamma, mut mass, mut psi) = ([0.0; M], [[0.0; N]; N], [0.0; N]);
        kernel("constraints_jacobian_ik", || {
            k.constraints_jacobian_ik(black_box(x), &mut f, &mut g)
        });
        kernel("jacobian", || k.jacobian(black_box(x), &mut g));
        kernel("dynamics_terms", || {
            k.dynamics_terms(black_box(x), &xdot, &mut g, &mut gamma, &mut mass, &mut psi)
        });
        let ns = time(1, || {
            for i in 0..1000 {
                let (p, v, a) = path(&home, s.outputs, i as f64 * 1e-3);
                rbss_runtime::inverse_dynamics_full(
                    &model,
                    &mut data,
                    black_box(&p[..o]),
                    &v[..o],
                    &a[..o],
                    None,
                )
                .unwrap();
            }
        }) / 1000.0;
        println!("solver/inverse_dynamics_full {ns:.1}");
    }
    #[cfg(feature = "sim")]
    {
        use rbss_runtime::{IntegrateOptions, Method, Simulator, Stabilization};
        let (mut gamma, mut mass, mut psi, mut e) = ([0.0; M], [[0.0; N]; N], [0.0; N], [0.0; 2]);
        kernel("constraints_jacobian_p", || {
            k.constraints_jacobian_p(black_box(x), &mut f, &mut g)
        });
        kernel("jacobian", || k.jacobian(black_box(x), &mut g));
        kernel("dynamics_terms", || {
            k.dynamics_terms(black_box(x), &xdot, &mut g, &mut gamma, &mut mass, &mut psi)
        });
        kernel("energy", || k.energy(black_box(x), &xdot, &mut e));
        // 0.1 s from rest at home under gravity (no control force), RK4 with 1 ms steps and
        // projection onto the constraints after each step.
        let options = IntegrateOptions::new(Method::Rk4 { dt: 1e-3 }, Stabilization::Projection);
        let mut control = |_t: f64, _x: &[f64; N], _v: &[f64; N], _u: &mut [f64]| Ok(());
        let ns = time(1, || {
            let mut sim = Simulator::new(&model, &mut data, 0.0, &home, &[0.0; N], options).unwrap();
            let stats = sim.run(&model, &mut data, 0.1, &mut control, |_| {}).unwrap();
            black_box(stats);
        }) / 100.0;
        println!("solver/simulator_step {ns:.1}");
    }
}
