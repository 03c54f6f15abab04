//! No allocation in the dynamics: after one warm-up call, inverse dynamics (block elimination
//! and dense), forward dynamics, the projections and the simulator's steps (every integrator
//! and stabilisation, with inverse dynamics in the control loop) allocate zero times, on the
//! generated 6-UPS. Same counting global allocator as `alloc.rs` (Drake `LimitMalloc`); one
//! `#[test]` per binary, so no other test's allocations interleave.

use rbss_runtime::{
    Baumgarte, Data, IntegrateOptions, Method, Model, Simulator, SolverError, Stabilization,
    forward_dynamics, inverse_acceleration, inverse_dynamics, inverse_dynamics_dense,
    inverse_kinematics, inverse_velocity, project_position, project_velocity,
};
use stewart_6ups::{M, N, Stewart6Ups};

#[path = "common/counting.rs"]
mod counting;

use counting::allocations;

/// The platform pose of the paper's TraekP (w = pi) and its derivatives.
fn traek_p(t: f64) -> ([f64; 6], [f64; 6], [f64; 6]) {
    let w = std::f64::consts::PI;
    let (s1, c1) = (w * t).sin_cos();
    let (s2, c2) = (2.0 * w * t).sin_cos();
    let (s3, c3) = (3.0 * w * t).sin_cos();
    let w2 = w * w;
    (
        [
            0.1 * c1,
            0.1 * s1,
            0.94 * (1.0 + 0.01 * s3),
            0.1 * c2,
            0.1 * s2,
            0.1 * c2 * s2,
        ],
        [
            -0.1 * w * s1,
            0.1 * w * c1,
            0.94 * 0.03 * w * c3,
            -0.2 * w * s2,
            0.2 * w * c2,
            0.2 * w * (c2 * c2 - s2 * s2),
        ],
        [
            -0.1 * w2 * c1,
            -0.1 * w2 * s1,
            -0.94 * 0.09 * w2 * s3,
            -0.4 * w2 * c2,
            -0.4 * w2 * s2,
            -1.6 * w2 * c2 * s2,
        ],
    )
}

fn reference_state(
    model: &Model<Stewart6Ups, N, M>,
    d: &mut Data<N, M>,
    t: f64,
) -> Result<(), SolverError> {
    let (p, v, a) = traek_p(t);
    inverse_kinematics(model, d, &p)?;
    inverse_velocity(model, d, &v)?;
    inverse_acceleration(model, d, &a)?;
    Ok(())
}

#[test]
fn dynamics_and_simulation_do_not_allocate() {
    let model = Model::new(Stewart6Ups::default());
    let mut data = Data::new(&model);
    reference_state(&model, &mut data, 0.3).unwrap();
    let state = data.clone();
    let q = [1.0; N];
    let u = [300.0, 310.0, 320.0, 330.0, 340.0, 350.0];

    // The control loop of the paper's round trip, on its own Data.
    let mut reference = state.clone();
    let mut feed_forward = |t: f64, _: &[f64; N], _: &[f64; N], u: &mut [f64]| {
        reference_state(&model, &mut reference, t)?;
        inverse_dynamics(&model, &mut reference, None)?;
        u.copy_from_slice(reference.u());
        Ok(())
    };
    let (x0, v0) = (state.x, state.xdot);
    let sim_options = [
        IntegrateOptions::new(Method::Rk4 { dt: 1e-3 }, Stabilization::None),
        IntegrateOptions::new(Method::Rk4 { dt: 1e-3 }, Stabilization::Projection),
        IntegrateOptions::new(
            Method::Rk4 { dt: 1e-3 },
            Stabilization::CoordinatePartitioning,
        ),
        IntegrateOptions::new(Method::dopri5(1e-8, 1e-10), Stabilization::baumgarte()),
        IntegrateOptions::new(Method::dopri5(1e-8, 1e-10), Stabilization::Projection),
        IntegrateOptions::new(
            Method::dopri5(1e-8, 1e-10),
            Stabilization::CoordinatePartitioning,
        ),
        IntegrateOptions::new(Method::dop853(1e-8, 1e-10), Stabilization::Projection),
        IntegrateOptions::new(
            Method::dop853(1e-8, 1e-10),
            Stabilization::CoordinatePartitioning,
        ),
    ];
    let mut simulators = sim_options.map(|o| {
        let mut d = data.clone();
        let sim = Simulator::new(&model, &mut d, 0.0, &x0, &v0, o).unwrap();
        (sim, d)
    });

    let mut all = |d: &mut Data<N, M>| {
        *d = state.clone();
        inverse_dynamics(&model, d, Some(&q)).unwrap();
        inverse_dynamics_dense(&model, d, None).unwrap();
        forward_dynamics(&model, d, &u, Some(&q), Baumgarte::NONE).unwrap();
        forward_dynamics(&model, d, &u, None, Baumgarte::DEFAULT).unwrap();
        d.x[20] += 1e-6;
        project_position(&model, d).unwrap();
        project_velocity(&model, d).unwrap();
        // Failing calls must not allocate either.
        assert!(forward_dynamics(&model, d, &u[..3], None, Baumgarte::NONE).is_err());
        d.xddot[0] = f64::NAN;
        assert!(inverse_dynamics(&model, d, None).is_err());
    };
    all(&mut data); // warm-up
    for (sim, d) in simulators.iter_mut() {
        sim.step(&model, d, 1.0, &mut feed_forward).unwrap();
    }

    type Check<'a> = (&'a str, &'a mut dyn FnMut(&mut Data<N, M>));
    let checks: [Check; 6] = [
        ("inverse_dynamics", &mut |d| {
            inverse_dynamics(&model, d, Some(&q)).unwrap();
        }),
        ("inverse_dynamics_dense", &mut |d| {
            inverse_dynamics_dense(&model, d, None).unwrap();
        }),
        ("forward_dynamics", &mut |d| {
            forward_dynamics(&model, d, &u, Some(&q), Baumgarte::DEFAULT).unwrap();
        }),
        ("project_position", &mut |d| {
            d.x[20] += 1e-6;
            project_position(&model, d).unwrap();
        }),
        ("project_velocity", &mut |d| {
            project_velocity(&model, d).unwrap();
        }),
        ("everything, with errors", &mut all),
    ];
    for (name, f) in checks {
        let mut d = state.clone();
        let (n, ()) = allocations(|| f(&mut d));
        assert_eq!(n, 0, "{name} allocated {n} times");
    }
    for ((sim, d), o) in simulators.iter_mut().zip(sim_options) {
        let (n, r) = allocations(|| {
            for _ in 0..5 {
                sim.step(&model, d, 1.0, &mut feed_forward)?;
            }
            Ok::<_, rbss_runtime::IntegrateError>(())
        });
        r.unwrap();
        assert_eq!(n, 0, "{o:?}: 5 steps allocated {n} times");
    }
    // Starting a simulation does not allocate either (fixed-size buffers).
    let (n, sim) = allocations(|| Simulator::new(&model, &mut data, 0.0, &x0, &v0, sim_options[4]));
    assert_eq!(n, 0);
    assert!(sim.is_ok());

    // The counter does count: a Vec allocates.
    let (n, v) = allocations(|| vec![1.0_f64; 4]);
    assert!(n >= 1 && v.len() == 4);
}
