//! A robot's kernels generated at build time (see `build.rs`), used with rbss-runtime: inverse
//! kinematics of the five-bar at an effector position, inverse dynamics along a motion through
//! it, and forward dynamics under the control torques found, which must give back the motion's
//! accelerations.

use rbss_runtime::{
    Baumgarte, Data, Model, forward_dynamics, inverse_dynamics, inverse_kinematics_full,
};

/// The generated module (constants, `Params`, the kernels and `impl Kernels for FiveBar`);
/// this program uses a few of its items.
#[allow(clippy::approx_constant, dead_code)]
mod five_bar {
    include!(concat!(env!("OUT_DIR"), "/five_bar.rs"));
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let model = Model::new(five_bar::FiveBar::default());
    let s = model.structure();
    let mut data = Data::new(&model);

    // The effector at (0.05, 0.32) m, moving at (0.1, -0.2) m/s, accelerating at (1, 2) m/s².
    let (pose, rate, accel) = ([0.05, 0.32], [0.1, -0.2], [1.0, 2.0]);
    let kin = inverse_kinematics_full(&model, &mut data, &pose, &rate, &accel)?;
    println!(
        "inverse kinematics: {} Newton steps, max |f| = {:.1e}",
        kin.position.iterations, kin.position.residual
    );
    for (name, x) in s.coordinates.iter().zip(&data.x) {
        println!("  {name:<4} = {x:>16.12}");
    }

    // The actuator torques U (and the constraint forces lambda) that produce this motion.
    inverse_dynamics(&model, &mut data, None)?;
    let u: Vec<f64> = data.u[..s.actuated.len()].to_vec();
    println!("inverse dynamics: U = [{:.9}, {:.9}] N m", u[0], u[1]);

    // Forward dynamics under U from the same state: the accelerations come back.
    let xddot = data.xddot;
    forward_dynamics(&model, &mut data, &u, None, Baumgarte::NONE)?;
    let err = data
        .xddot
        .iter()
        .zip(&xddot)
        .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
    println!("forward dynamics under U: max |Xddot - Xddot(inverse)| = {err:.1e}");
    if err > 1e-9 {
        return Err(format!("forward dynamics does not give back the motion ({err:e})").into());
    }
    Ok(())
}
