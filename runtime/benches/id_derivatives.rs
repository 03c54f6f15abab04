//! The derivatives of inverse dynamics beside inverse dynamics, in the same run, on the
//! generated 6-UPS at its home assembly with a non-zero velocity and acceleration:
//! `cargo bench -p rbss-runtime --bench id_derivatives`.
//!
//! - `inverse_dynamics`: the solver alone;
//! - `inverse_dynamics_derivatives`: inverse dynamics, the kernel `dynamics_derivatives` and
//!   `[S | Gᵀ]` with `3 N` right-hand sides by the block elimination;
//! - `inverse_dynamics_derivatives_dense`: the same by the dense LU of `[S | Gᵀ]`.

use divan::{Bencher, black_box};
use rbss_runtime::{
    Data, IdDerivativesSolver, InverseDynamicsDerivatives, Model, inverse_dynamics,
    inverse_dynamics_derivatives_with,
};
use stewart_6ups::{M, N, Stewart6Ups};

fn main() {
    divan::main();
}

fn state(model: &Model<Stewart6Ups, N, M>) -> Data<N, M> {
    let mut d = Data::new(model);
    for (j, (v, a)) in d.xdot.iter_mut().zip(d.xddot.iter_mut()).enumerate() {
        *v = 0.01 * (j as f64 + 1.0);
        *a = 0.02 * (j as f64 + 1.0);
    }
    d
}

#[divan::bench]
fn inverse_dynamics_6ups(b: Bencher) {
    let model = Model::new(Stewart6Ups::default());
    let mut d = state(&model);
    inverse_dynamics(&model, &mut d, None).expect("inverse_dynamics");
    b.bench_local(|| inverse_dynamics(&model, black_box(&mut d), None));
}

fn derivatives(b: Bencher, solver: IdDerivativesSolver) {
    let model = Model::new(Stewart6Ups::default());
    let mut d = state(&model);
    let mut out = InverseDynamicsDerivatives::<N, M>::new();
    inverse_dynamics_derivatives_with(&model, &mut d, &mut out, None, solver)
        .expect("inverse_dynamics_derivatives");
    b.bench_local(|| {
        inverse_dynamics_derivatives_with(
            &model,
            black_box(&mut d),
            black_box(&mut out),
            None,
            solver,
        )
    });
}

#[divan::bench]
fn inverse_dynamics_derivatives_6ups(b: Bencher) {
    derivatives(b, IdDerivativesSolver::Auto);
}

#[divan::bench]
fn inverse_dynamics_derivatives_dense_6ups(b: Bencher) {
    derivatives(b, IdDerivativesSolver::DenseLu);
}
