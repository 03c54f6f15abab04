//! Calls one derivative path of the generated 6-UPS a given number of times, for instruction
//! counts under callgrind (`valgrind --tool=callgrind target/release/examples/derivatives_calls
//! WHAT CALLS`, WHAT one of `fd`, `fdd`, `lin`, `rk4`): the difference of two counts over the
//! difference of their calls is the instructions per call.

use rbss_runtime::{
    Baumgarte, Coordinates, Data, ForwardDynamicsDerivatives, Linearization, Model,
    StepDerivatives, forward_dynamics, forward_dynamics_derivatives, linearize,
    rk4_step_derivatives,
};
use std::hint::black_box;
use stewart_6ups::Stewart6Ups;

fn main() {
    let mut args = std::env::args().skip(1);
    let what = args.next().unwrap_or_else(|| "fdd".into());
    let calls: usize = args.next().and_then(|s| s.parse().ok()).unwrap_or(1000);
    let u = [300.0, 310.0, 320.0, 330.0, 340.0, 350.0];
    let model = Model::new(Stewart6Ups::default());
    let mut d = Data::new(&model);
    for (j, v) in d.xdot.iter_mut().enumerate() {
        *v = 0.01 * (j as f64 + 1.0);
    }
    let mut fdd = ForwardDynamicsDerivatives::new();
    let mut lin = Linearization::new();
    let mut step = StepDerivatives::new();
    if what == "lin" {
        let rates = [0.01, -0.02, 0.03, 0.01, 0.02, -0.01];
        rbss_runtime::inverse_velocity(&model, &mut d, &rates).expect("inverse_velocity");
    }
    let (x0, v0) = (d.x, d.xdot);
    for _ in 0..calls {
        let r = match what.as_str() {
            "fd" => {
                forward_dynamics(&model, black_box(&mut d), &u, None, Baumgarte::NONE).map(|_| ())
            }
            "fdd" => forward_dynamics_derivatives(&model, black_box(&mut d), &mut fdd, &u, None)
                .map(|_| ()),
            "lin" => linearize(
                &model,
                black_box(&mut d),
                &mut lin,
                &u,
                None,
                Coordinates::Outputs,
            )
            .map(|_| ()),
            "rk4" => {
                d.x = x0;
                d.xdot = v0;
                rk4_step_derivatives(
                    &model,
                    black_box(&mut d),
                    &mut step,
                    &u,
                    1e-3,
                    Baumgarte::NONE,
                )
            }
            _ => panic!("WHAT: fd, fdd, lin or rk4"),
        };
        r.expect("call");
        black_box(&fdd);
        black_box(&lin);
        black_box(&step);
    }
}
