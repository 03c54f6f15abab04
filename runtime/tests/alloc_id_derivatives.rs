//! No allocation in the derivatives of inverse dynamics: after
//! `InverseDynamicsDerivatives::new` and one warm-up call, `inverse_dynamics_derivatives`
//! allocates zero times on the generated 6-UPS (by the block elimination and by the dense LU),
//! also when it fails, and on the UR5 (a task frame, which moves no mass). Same counting global allocator as
//! `alloc.rs`; one `#[test]` per binary.

use rbss_runtime::{
    Data, IdDerivativesSolver, InverseDynamicsDerivatives, Model, inverse_dynamics_derivatives,
    inverse_dynamics_derivatives_with,
};

#[path = "common/counting.rs"]
mod counting;

use counting::allocations;

#[test]
fn inverse_dynamics_derivatives_do_not_allocate() {
    let model = Model::new(stewart_6ups::Stewart6Ups::default());
    let mut data = Data::new(&model);
    data.xdot = [0.1; stewart_6ups::N];
    data.xddot = [0.2; stewart_6ups::N];
    let mut out = InverseDynamicsDerivatives::new();
    inverse_dynamics_derivatives(&model, &mut data, &mut out, None).unwrap();
    let (n, r) = allocations(|| {
        for _ in 0..5 {
            inverse_dynamics_derivatives(&model, &mut data, &mut out, None)?;
        }
        inverse_dynamics_derivatives_with(
            &model,
            &mut data,
            &mut out,
            None,
            IdDerivativesSolver::DenseLu,
        )?;
        data.x[3] = f64::NAN;
        let err = inverse_dynamics_derivatives(&model, &mut data, &mut out, None);
        assert!(err.is_err());
        Ok::<_, rbss_runtime::SolverError>(())
    });
    r.unwrap();
    assert_eq!(
        n, 0,
        "6-UPS: inverse_dynamics_derivatives allocated {n} times"
    );

    let model = Model::new(ur5::Ur5::default());
    let mut data = Data::new(&model);
    data.xdot = [0.1; ur5::N];
    let mut out = InverseDynamicsDerivatives::new();
    inverse_dynamics_derivatives(&model, &mut data, &mut out, None).unwrap();
    let (n, r) = allocations(|| {
        for _ in 0..5 {
            inverse_dynamics_derivatives(&model, &mut data, &mut out, None)?;
        }
        Ok::<_, rbss_runtime::SolverError>(())
    });
    r.unwrap();
    assert_eq!(
        n, 0,
        "UR5: inverse_dynamics_derivatives allocated {n} times"
    );
}
