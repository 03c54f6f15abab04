//! Forward dynamics of the 6-UPS at one assembled state, by every path: the default
//! (`forward_dynamics`: the generated elimination, with its backward error measured) and, for
//! the cost of the robust paths, the null-space method, the LU of the whole saddle-point
//! matrix and the Schur complement, each forced (`forward_dynamics_with`).
//!
//!   cargo bench -p rbss-runtime --bench fd_paths

use std::hint::black_box;

use divan::Bencher;
use rbss_runtime::{
    Baumgarte, Data, FdSolver, Model, forward_dynamics_with, inverse_kinematics, inverse_velocity,
};
use stewart_6ups::Stewart6Ups;

fn main() {
    divan::main();
}

fn setup() -> (Model<Stewart6Ups, 24, 18>, Data<24, 18>, [f64; 6]) {
    let model = Model::new(Stewart6Ups::default());
    let mut d = Data::new(&model);
    inverse_kinematics(&model, &mut d, &[0.05, -0.03, 0.95, 0.08, -0.05, 0.1]).unwrap();
    inverse_velocity(&model, &mut d, &[0.1, 0.2, -0.1, 0.3, -0.2, 0.1]).unwrap();
    (model, d, [120.0, -80.0, 300.0, 50.0, -40.0, 90.0])
}

fn run(b: Bencher, solver: FdSolver) {
    let (model, mut d, u) = setup();
    forward_dynamics_with(&model, &mut d, &u, None, Baumgarte::NONE, solver).unwrap();
    b.bench_local(|| {
        forward_dynamics_with(
            &model,
            black_box(&mut d),
            black_box(&u),
            None,
            Baumgarte::NONE,
            solver,
        )
    });
}

#[divan::bench]
fn auto(b: Bencher) {
    run(b, FdSolver::Auto);
}

#[divan::bench]
fn null_space(b: Bencher) {
    run(b, FdSolver::NullSpace);
}

#[divan::bench]
fn saddle_point_lu(b: Bencher) {
    run(b, FdSolver::SaddlePointLu);
}

#[divan::bench]
fn schur(b: Bencher) {
    run(b, FdSolver::Schur);
}
