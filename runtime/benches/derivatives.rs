//! The derivatives of forward dynamics beside forward dynamics, in the same run, on the
//! generated 6-UPS at its home assembly with a non-zero velocity:
//! `cargo bench -p rbss-runtime --bench derivatives`.
//!
//! - `forward_dynamics`: the solver alone;
//! - `dynamics_derivatives`: the generated kernel alone (`∂r/∂X`, `∂r/∂Ẋ`, `∂c/∂X`, `∂c/∂Ẋ`);
//! - `forward_dynamics_derivatives`: forward dynamics, the kernel and the saddle-point system
//!   with `2 N + (N - M)` right-hand sides by the elimination onto the outputs;
//! - `linearize_outputs`: the manifold linearisation in the outputs' coordinates (forward
//!   dynamics' derivatives included), `A` 12 × 12 and `B` 12 × 6;
//! - `rk4_step_derivatives`: one RK4 step and its Jacobians `F_x` (48 × 48), `F_u` (48 × 6),
//!   four stages of forward dynamics' derivatives;
//! - `forward_dynamics_derivatives_dense`: the same with the dense LU of the saddle-point
//!   matrix (`DerivativesSolver::SaddlePointLu`), the reference.

use divan::{Bencher, black_box};
use rbss_runtime::{
    Baumgarte, Coordinates, Data, DerivativesSolver, DynamicsDerivatives,
    ForwardDynamicsDerivatives, Linearization, Model, forward_dynamics,
    forward_dynamics_derivatives, forward_dynamics_derivatives_with, linearize,
};
use stewart_6ups::{M, N, Stewart6Ups};

fn main() {
    divan::main();
}

const U: [f64; 6] = [300.0, 310.0, 320.0, 330.0, 340.0, 350.0];

fn state(model: &Model<Stewart6Ups, N, M>) -> Data<N, M> {
    let mut d = Data::new(model);
    for (j, v) in d.xdot.iter_mut().enumerate() {
        *v = 0.01 * (j as f64 + 1.0);
    }
    d
}

#[divan::bench]
fn forward_dynamics_6ups(b: Bencher) {
    let model = Model::new(Stewart6Ups::default());
    let mut d = state(&model);
    forward_dynamics(&model, &mut d, &U, None, Baumgarte::NONE).expect("forward_dynamics");
    b.bench_local(|| {
        forward_dynamics(
            &model,
            black_box(&mut d),
            black_box(&U),
            None,
            Baumgarte::NONE,
        )
    });
}

#[divan::bench]
fn dynamics_derivatives_6ups(b: Bencher) {
    let model = Model::new(Stewart6Ups::default());
    let mut d = state(&model);
    forward_dynamics(&model, &mut d, &U, None, Baumgarte::NONE).expect("forward_dynamics");
    let k = model.kernels();
    let (mut rx, mut rv) = ([[0.0; N]; N], [[0.0; N]; N]);
    let (mut cx, mut cv) = ([[0.0; M]; N], [[0.0; M]; N]);
    b.bench_local(|| {
        DynamicsDerivatives::dynamics_derivatives(
            black_box(k),
            black_box(&d.x),
            black_box(&d.xdot),
            black_box(&d.xddot),
            black_box(&d.lambda),
            black_box(&mut rx),
            black_box(&mut rv),
            black_box(&mut cx),
            black_box(&mut cv),
        )
    });
}

#[divan::bench]
fn forward_dynamics_derivatives_6ups(b: Bencher) {
    let model = Model::new(Stewart6Ups::default());
    let mut d = state(&model);
    let mut out = ForwardDynamicsDerivatives::new();
    forward_dynamics_derivatives(&model, &mut d, &mut out, &U, None)
        .expect("forward_dynamics_derivatives");
    b.bench_local(|| {
        forward_dynamics_derivatives(
            &model,
            black_box(&mut d),
            black_box(&mut out),
            black_box(&U),
            None,
        )
    });
}

#[divan::bench]
fn forward_dynamics_derivatives_dense_6ups(b: Bencher) {
    let model = Model::new(Stewart6Ups::default());
    let mut d = state(&model);
    let mut out = ForwardDynamicsDerivatives::new();
    let dense = DerivativesSolver::SaddlePointLu;
    forward_dynamics_derivatives_with(&model, &mut d, &mut out, &U, None, Baumgarte::NONE, dense)
        .expect("forward_dynamics_derivatives");
    b.bench_local(|| {
        forward_dynamics_derivatives_with(
            &model,
            black_box(&mut d),
            black_box(&mut out),
            black_box(&U),
            None,
            Baumgarte::NONE,
            dense,
        )
    });
}

#[divan::bench]
fn linearize_outputs_6ups(b: Bencher) {
    let model = Model::new(Stewart6Ups::default());
    let mut d = state(&model);
    // On the manifold: the velocity from the outputs' rates.
    let rates = [0.01, -0.02, 0.03, 0.01, 0.02, -0.01];
    rbss_runtime::inverse_velocity(&model, &mut d, &rates).expect("inverse_velocity");
    let mut out = Linearization::new();
    let (mut a, mut bm) = ([0.0; 144], [0.0; 72]);
    linearize(&model, &mut d, &mut out, &U, None, Coordinates::Outputs).expect("linearize");
    b.bench_local(|| {
        linearize(
            &model,
            black_box(&mut d),
            black_box(&mut out),
            black_box(&U),
            None,
            Coordinates::Outputs,
        )?;
        out.state_space(&mut a, &mut bm)
    });
}

#[divan::bench]
fn rk4_step_derivatives_6ups(b: Bencher) {
    let model = Model::new(Stewart6Ups::default());
    let mut d = state(&model);
    let (x0, v0) = (d.x, d.xdot);
    let mut out = rbss_runtime::StepDerivatives::new();
    b.bench_local(|| {
        d.x = x0;
        d.xdot = v0;
        rbss_runtime::rk4_step_derivatives(
            &model,
            black_box(&mut d),
            black_box(&mut out),
            black_box(&U),
            1e-3,
            Baumgarte::NONE,
        )
    });
}
