//! No allocation on the generated robots: after one warm-up of each solver call, every kernel
//! (through `Kernels` and `Dynamics`) and every kinematics solver allocates zero times over 100
//! calls, checked with a counting global allocator (Drake `LimitMalloc`).
//!
//! The counter (runtime/tests/common/counting.rs, shared with the runtime's no-allocation tests)
//! is per thread: only the allocations of the thread that runs the calls count.
//! A process-wide counter was not enough: libtest's own threads allocate now and then while a
//! window is open (seen on CI and locally: 4 allocations charged to a different solver on
//! each failing run). Nothing inside a window prints.

use rbss::paper::{OMEGA, traek_p};
use rbss_runtime::{
    Baumgarte, Data, Dynamics, Model, forward_acceleration, forward_dynamics, forward_kinematics,
    forward_velocity, inverse_acceleration, inverse_kinematics, inverse_velocity,
};

#[path = "../runtime/tests/common/counting.rs"]
mod counting;

mod common;
use common::two_stage;

const CALLS: usize = 100;

/// Allocations made by `CALLS` calls of `call(k)`, `k = 0..CALLS`.
fn allocations(mut call: impl FnMut(usize)) -> u64 {
    counting::allocations(|| {
        for k in 0..CALLS {
            call(k);
        }
    })
    .0
}

/// Output pose, rate and acceleration of the 6-UPS's reference motion (TraekP) at time `t`.
fn traek(t: f64) -> [[f64; 6]; 3] {
    let (pos, vel, acc) = traek_p(t, OMEGA);
    [pos, vel, acc]
}

/// A figure eight of the five-bar's end effector through its home `(0, 0.3)` at `t = 0`.
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

/// Checks one robot along `motion` (a 1 kHz tracking loop, sample `k` at `t = k ms`); returns
/// one message per call that allocated.
fn check<K: Dynamics<N, M>, const N: usize, const M: usize, const O: usize>(
    kernels: K,
    motion: impl Fn(f64) -> [[f64; O]; 3],
) -> Vec<String> {
    let model = Model::new(kernels);
    let mut data = Data::new(&model);
    let s = model.structure();
    let k = model.kernels();
    let t = |i: usize| i as f64 * 1e-3;
    let samples: Vec<[[f64; O]; 3]> = (0..CALLS).map(|i| motion(t(i))).collect();

    // Per sample: the IK solution with its velocity and acceleration, and the actuated q, q̇, q̈
    // that the forward solvers get. Doubles as the warm-up of every solver call.
    let mut states = Vec::with_capacity(CALLS);
    let mut actuated = Vec::with_capacity(CALLS);
    for [pose, pose_dot, pose_ddot] in &samples {
        inverse_kinematics(&model, &mut data, pose).expect("IK along the motion");
        inverse_velocity(&model, &mut data, pose_dot).expect("inverse velocity");
        inverse_acceleration(&model, &mut data, pose_ddot).expect("inverse acceleration");
        let q = |v: &[f64; N]| s.actuated.iter().map(|&j| v[j]).collect::<Vec<_>>();
        actuated.push([q(&data.x), q(&data.xdot), q(&data.xddot)]);
        states.push((data.x, data.xdot));
    }
    data.x = states[0].0;
    forward_kinematics(&model, &mut data, &actuated[0][0]).expect("FK");
    forward_velocity(&model, &mut data, &actuated[0][1]).expect("forward velocity");
    forward_acceleration(&model, &mut data, &actuated[0][2]).expect("forward acceleration");

    let mut f = [0.0; M];
    let mut g = [[0.0; M]; N];
    let mut gamma = [0.0; M];
    let mut counts: Vec<(&str, u64)> = Vec::with_capacity(16);
    counts.push((
        "Kernels::constraints",
        allocations(|i| k.constraints(&states[i].0, &mut f)),
    ));
    counts.push((
        "Kernels::jacobian",
        allocations(|i| k.jacobian(&states[i].0, &mut g)),
    ));
    counts.push((
        "Kernels::jacobian_p",
        allocations(|i| k.jacobian_p(&states[i].0, &mut g)),
    ));
    counts.push((
        "Kernels::jacobian_ik",
        allocations(|i| k.jacobian_ik(&states[i].0, &mut g)),
    ));
    counts.push((
        "Kernels::gamma",
        allocations(|i| k.gamma(&states[i].0, &states[i].1, &mut gamma)),
    ));

    let mut mass = [[0.0; N]; N];
    let mut psi = [0.0; N];
    let mut energy = [0.0; 2];
    counts.push((
        "Dynamics::mass_matrix",
        allocations(|i| k.mass_matrix(&states[i].0, &mut mass)),
    ));
    counts.push((
        "Dynamics::psi",
        allocations(|i| k.psi(&states[i].0, &states[i].1, &mut psi)),
    ));
    counts.push((
        "Dynamics::energy",
        allocations(|i| k.energy(&states[i].0, &states[i].1, &mut energy)),
    ));

    // The solvers along the motion; inverse kinematics is warm-started from the previous
    // sample's solution, as in a tracking loop.
    data.x = states[0].0;
    counts.push((
        "inverse_kinematics (warm)",
        allocations(|i| {
            inverse_kinematics(&model, &mut data, &samples[i][0]).expect("IK");
        }),
    ));
    counts.push((
        "inverse_velocity",
        allocations(|i| {
            data.x = states[i].0;
            inverse_velocity(&model, &mut data, &samples[i][1]).expect("inverse velocity");
        }),
    ));
    counts.push((
        "inverse_acceleration",
        allocations(|i| {
            (data.x, data.xdot) = states[i];
            inverse_acceleration(&model, &mut data, &samples[i][2]).expect("inverse acc.");
        }),
    ));
    counts.push((
        "forward_kinematics (warm)",
        allocations(|i| {
            data.x = states[i.saturating_sub(1)].0;
            forward_kinematics(&model, &mut data, &actuated[i][0]).expect("FK");
        }),
    ));
    counts.push((
        "forward_velocity",
        allocations(|i| {
            data.x = states[i].0;
            forward_velocity(&model, &mut data, &actuated[i][1]).expect("forward velocity");
        }),
    ));
    counts.push((
        "forward_acceleration",
        allocations(|i| {
            (data.x, data.xdot) = states[i];
            forward_acceleration(&model, &mut data, &actuated[i][2]).expect("forward acc.");
        }),
    ));

    // Forward dynamics under zero control forces, after one call (the saddle-point path of a
    // robot with massless coordinates, the UR5, sizes its buffers at its first call).
    let u0 = vec![0.0; s.actuated.len()];
    (data.x, data.xdot) = states[0];
    forward_dynamics(&model, &mut data, &u0, None, Baumgarte::NONE).expect("FD");
    counts.push((
        "forward_dynamics",
        allocations(|i| {
            (data.x, data.xdot) = states[i];
            forward_dynamics(&model, &mut data, &u0, None, Baumgarte::NONE).expect("FD");
        }),
    ));

    counts
        .into_iter()
        .filter(|&(_, n)| n != 0)
        .map(|(what, n)| format!("{}: {what} allocated {n} times in {CALLS} calls", s.name))
        .collect()
}

#[test]
fn kernels_and_solvers_do_not_allocate() {
    // The counter does count.
    let (n, v) = counting::allocations(|| std::hint::black_box(vec![1.0_f64; 4]));
    assert!(n > 0 && v.len() == 4);

    let mut failures = check(stewart_6ups::Stewart6Ups::default(), traek);
    failures.extend(check(five_bar::FiveBar::default(), figure_eight));
    failures.extend(check(stewart_2stage::Stewart2Stage::default(), two_stage));
    // The UR5 along its tool motion of models/trajectories/ur5.toml.
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let flange = [
        "link6_x",
        "link6_y",
        "link6_z",
        "link6_roll",
        "link6_pitch",
        "link6_yaw",
    ];
    let tool = rbss::trajectory::load(&root.join("models/trajectories/ur5.toml"), &flange)
        .expect("the UR5's trajectory");
    let ur5_motion = |t: f64| {
        let mut out = [[0.0; 6]; 3];
        let [p, v, a] = &mut out;
        tool.eval(t, p, v, a);
        out
    };
    failures.extend(check(ur5::Ur5::default(), ur5_motion));
    // The robot families along theirs.
    let family = |name: &str, names: [&str; 3]| {
        let file = root.join(format!("models/trajectories/{name}.toml"));
        let traj = rbss::trajectory::load(&file, &names).expect("the family's trajectory");
        move |t: f64| {
            let mut out = [[0.0; 3]; 3];
            let [p, v, a] = &mut out;
            traj.eval(t, p, v, a);
            out
        }
    };
    failures.extend(check(
        delta::Delta::default(),
        family("delta", ["x", "y", "z"]),
    ));
    failures.extend(check(
        planar_3rrr::Planar3Rrr::default(),
        family("planar_3rrr", ["x", "y", "phi"]),
    ));
    failures.extend(check(
        tripod_3rps::Tripod3Rps::default(),
        family("tripod_3rps", ["z", "rotx", "roty"]),
    ));
    // The 6-RUS hexapod along models/trajectories/hexa_6rus.toml.
    let names = ["x", "y", "z", "rotx", "roty", "rotz"];
    let hexa = rbss::trajectory::load(&root.join("models/trajectories/hexa_6rus.toml"), &names)
        .expect("the hexapod's trajectory");
    let hexa_motion = |t: f64| {
        let mut out = [[0.0; 6]; 3];
        let [p, v, a] = &mut out;
        hexa.eval(t, p, v, a);
        out
    };
    failures.extend(check(hexa_6rus::Hexa6Rus::default(), hexa_motion));
    // The hybrid machine along models/trajectories/hybrid_tricept.toml (5 outputs).
    let tool5 = ["x", "y", "z", "rotx", "roty"];
    let tricept = rbss::trajectory::load(
        &root.join("models/trajectories/hybrid_tricept.toml"),
        &tool5,
    )
    .expect("the hybrid machine's trajectory");
    let tricept_motion = |t: f64| {
        let mut out = [[0.0; 5]; 3];
        let [p, v, a] = &mut out;
        tricept.eval(t, p, v, a);
        out
    };
    failures.extend(check(
        hybrid_tricept::HybridTricept::default(),
        tricept_motion,
    ));
    // The expression trajectories themselves (the round trip's control evaluates one at every
    // stage time): their evaluation stacks live on the machine stack.
    let (mut p, mut v, mut a) = ([0.0; 6], [0.0; 6], [0.0; 6]);
    tool.eval(0.1, &mut p, &mut v, &mut a);
    let n = allocations(|k| tool.eval(0.01 * k as f64, &mut p, &mut v, &mut a));
    if n > 0 {
        failures.push(format!(
            "the UR5's expression trajectory allocated {n} times in {CALLS} evaluations"
        ));
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
