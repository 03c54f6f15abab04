//! No allocation in the derivatives of forward dynamics: after `ForwardDynamicsDerivatives::new`
//! and one warm-up call, `forward_dynamics_derivatives` allocates zero times, on the generated
//! 6-UPS (by the elimination and by the dense fallback) and on the UR5 (a task frame, which moves no mass), also
//! when it fails; `linearize` and `state_space` on the 6-UPS, in both coordinates; the
//! RK4 and semi-implicit Euler steps' Jacobians, and the projected step's. Same counting global allocator as `alloc.rs`; one `#[test]` per binary.

use rbss_runtime::{
    Coordinates, Data, DerivativesSolver, ForwardDynamicsDerivatives, Linearization, Model,
    StepDerivatives, forward_dynamics_derivatives, forward_dynamics_derivatives_with, linearize,
    project_step_derivatives, rk4_step_derivatives, semi_implicit_euler_step,
    semi_implicit_euler_step_derivatives,
};

#[path = "common/counting.rs"]
mod counting;

use counting::allocations;

#[test]
fn forward_dynamics_derivatives_do_not_allocate() {
    let model = Model::new(stewart_6ups::Stewart6Ups::default());
    let mut data = Data::new(&model);
    data.xdot = [0.1; stewart_6ups::N];
    let mut out = ForwardDynamicsDerivatives::new();
    let u = [300.0, 310.0, 320.0, 330.0, 340.0, 350.0];
    forward_dynamics_derivatives(&model, &mut data, &mut out, &u, None).unwrap();
    let (n, r) = allocations(|| {
        for _ in 0..5 {
            forward_dynamics_derivatives(&model, &mut data, &mut out, &u, None)?;
        }
        // The dense fallback too.
        let dense = DerivativesSolver::SaddlePointLu;
        forward_dynamics_derivatives_with(
            &model,
            &mut data,
            &mut out,
            &u,
            None,
            rbss_runtime::Baumgarte::NONE,
            dense,
        )?;
        data.x[3] = f64::NAN;
        let err = forward_dynamics_derivatives(&model, &mut data, &mut out, &u, None);
        assert!(err.is_err());
        Ok::<_, rbss_runtime::SolverError>(())
    });
    r.unwrap();
    assert_eq!(
        n, 0,
        "6-UPS: forward_dynamics_derivatives allocated {n} times"
    );

    // The linearisation, in both coordinates.
    let mut lin = Linearization::new();
    data.x[3] = model.structure().home[3];
    for c in [Coordinates::Outputs, Coordinates::Actuated] {
        linearize(&model, &mut data, &mut lin, &u, None, c).unwrap();
    }
    let (mut a, mut b) = ([0.0; 144], [0.0; 72]);
    let (n, r) = allocations(|| {
        for c in [Coordinates::Outputs, Coordinates::Actuated] {
            linearize(&model, &mut data, &mut lin, &u, None, c)?;
            lin.state_space(&mut a, &mut b)?;
        }
        Ok::<_, rbss_runtime::SolverError>(())
    });
    r.unwrap();
    assert_eq!(n, 0, "6-UPS: linearize allocated {n} times");

    // The step Jacobians.
    let mut st = StepDerivatives::new();
    let b = rbss_runtime::Baumgarte::DEFAULT;
    let x0 = data.x;
    let (n, r) = allocations(|| {
        rk4_step_derivatives(&model, &mut data, &mut st, &u, 1e-3, b)?;
        data.x = x0;
        project_step_derivatives(&model, &mut data, &mut st)?;
        data.x = x0;
        semi_implicit_euler_step_derivatives(&model, &mut data, &mut st, &u, 1e-3, b)?;
        data.x = x0;
        semi_implicit_euler_step(&model, &mut data, &u, 1e-3, b)?;
        Ok::<_, rbss_runtime::SolverError>(())
    });
    r.unwrap();
    assert_eq!(n, 0, "6-UPS: the step Jacobians allocated {n} times");

    let model = Model::new(ur5::Ur5::default());
    let mut data = Data::new(&model);
    data.xdot = [0.1; ur5::N];
    let mut out = ForwardDynamicsDerivatives::new();
    let u = [1.0, 2.0, 3.0, 0.5, 0.2, 0.1];
    forward_dynamics_derivatives(&model, &mut data, &mut out, &u, None).unwrap();
    let (n, r) = allocations(|| {
        for _ in 0..5 {
            forward_dynamics_derivatives(&model, &mut data, &mut out, &u, None)?;
        }
        Ok::<_, rbss_runtime::SolverError>(())
    });
    r.unwrap();
    assert_eq!(
        n, 0,
        "UR5: forward_dynamics_derivatives allocated {n} times"
    );
}
