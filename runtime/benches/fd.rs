//! Forward dynamics of the 6-UPS at one assembled state by the default path
//! (`forward_dynamics`), the function issue 33's "within 5 %" is about; this file compiles
//! against older runtimes too, so one binary per commit can be timed side by side.
//!
//!   cargo bench -p rbss-runtime --bench fd

use std::hint::black_box;

use divan::Bencher;
use rbss_runtime::{
    Baumgarte, Data, Model, forward_dynamics, inverse_kinematics, inverse_velocity,
};
use stewart_6ups::Stewart6Ups;

fn main() {
    divan::main();
}

#[divan::bench]
fn forward_dynamics_6ups(b: Bencher) {
    let model = Model::new(Stewart6Ups::default());
    let mut d = Data::new(&model);
    inverse_kinematics(&model, &mut d, &[0.05, -0.03, 0.95, 0.08, -0.05, 0.1]).unwrap();
    inverse_velocity(&model, &mut d, &[0.1, 0.2, -0.1, 0.3, -0.2, 0.1]).unwrap();
    let u = [120.0, -80.0, 300.0, 50.0, -40.0, 90.0];
    forward_dynamics(&model, &mut d, &u, None, Baumgarte::NONE).unwrap();
    b.bench_local(|| {
        forward_dynamics(
            &model,
            black_box(&mut d),
            black_box(&u),
            None,
            Baumgarte::NONE,
        )
    });
}
