//! No allocation in the solvers: after one warm-up call, every kinematics solver (and a failing
//! call) allocates zero times, checked with a counting global allocator (Drake `LimitMalloc`).

mod common;

use common::five_bar::{FiveBar, HOME};
use rbss_runtime::{
    Data, Model, forward_acceleration, forward_kinematics, forward_velocity, inverse_acceleration,
    inverse_kinematics, inverse_velocity,
};

#[path = "common/counting.rs"]
mod counting;

use counting::allocations;

#[test]
fn kinematics_solvers_do_not_allocate() {
    let model = Model::new(FiveBar);
    let mut data = Data::new(&model);
    let pose = [0.03, 0.28];
    let q = [HOME[0] + 0.1, HOME[2] - 0.05];

    let mut all = |data: &mut Data<6, 4>| {
        inverse_kinematics(&model, data, &pose).unwrap();
        inverse_velocity(&model, data, &[0.1, -0.2]).unwrap();
        inverse_acceleration(&model, data, &[1.0, 0.5]).unwrap();
        forward_kinematics(&model, data, &q).unwrap();
        forward_velocity(&model, data, &[0.3, 0.1]).unwrap();
        forward_acceleration(&model, data, &[-0.5, 2.0]).unwrap();
        // Failing calls must not allocate either.
        assert!(inverse_kinematics(&model, data, &[0.0, 0.9]).is_err());
        assert!(forward_kinematics(&model, data, &[f64::NAN, 0.0]).is_err());
    };
    all(&mut data); // warm-up

    type Check<'a> = (&'a str, &'a mut dyn FnMut(&mut Data<6, 4>));
    let checks: [Check; 7] = [
        ("inverse_kinematics", &mut |d| {
            d.set_home(&model);
            inverse_kinematics(&model, d, &pose).unwrap();
        }),
        ("inverse_velocity", &mut |d| {
            inverse_velocity(&model, d, &[0.1, -0.2]).unwrap();
        }),
        ("inverse_acceleration", &mut |d| {
            inverse_acceleration(&model, d, &[1.0, 0.5]).unwrap();
        }),
        ("forward_kinematics", &mut |d| {
            d.set_home(&model);
            forward_kinematics(&model, d, &q).unwrap();
        }),
        ("forward_velocity", &mut |d| {
            forward_velocity(&model, d, &[0.3, 0.1]).unwrap();
        }),
        ("forward_acceleration", &mut |d| {
            forward_acceleration(&model, d, &[-0.5, 2.0]).unwrap();
        }),
        ("everything, with errors", &mut all),
    ];
    for (name, f) in checks {
        let (n, ()) = allocations(|| f(&mut data));
        assert_eq!(n, 0, "{name} allocated {n} times");
    }

    // The counter does count: a Vec allocates.
    let (n, v) = allocations(|| vec![1.0_f64; 4]);
    assert!(n >= 1 && v.len() == 4);
    // Data::new does not allocate either (fixed-size buffers).
    let (n, _d) = allocations(|| Data::new(&model));
    assert_eq!(n, 0);
}
