//! The loop kinds against oracles written here from the models' geometry (nothing of the
//! generated code):
//!
//! - models/four_bar_rod.toml (a `distance` loop): the rocker angle against Freudenstein's
//!   closed form, its rate against the closed form's derivative;
//! - models/leg_four_bar.toml (a loop planar in a frame that turns with a driven hip, `frame =
//!   "a"`, and the hip geared to its motor by a `coupling`): every coordinate and the foot's
//!   world position against the planar closed form turned by the hip angle, the rates too; its
//!   joints' springs, dampers and rotor inertia: the holding torques against the virtual work
//!   of gravity and the springs along the closed form, the potential energy against the closed
//!   form's, the energy's rate against the actuators' power less the dampers';
//! - models/gear_pair.toml (a `coupling`): forward dynamics against the reduced inertia of the
//!   pair, `(I1 + ratio² J2) q1'' = U - ratio m2 g e cos q2`;
//! - models/slider_crank.toml (a `point_in_plane`: the pin's other components free): the rod's
//!   angle and the pin's travel against the slider-crank's closed form;
//! - models/spatial_crank.toml (a `hinge` cutting a spatial R-S-U-R four-bar, a `point_on_line`
//!   slider): over a full turn of the crank, the rocker's frame against the closed form of the
//!   spatial four-bar, the pin's height against the slider's; the closure checks the loops
//!   leave open (the hinge's axes not reversed); the rates against the closed forms'
//!   derivatives; forward dynamics against the power balance of the energy kernel.

mod common;

use common::Rng;
use rbss_runtime::{
    Baumgarte, Data, Dynamics, Kernels, Model, forward_dynamics, forward_kinematics,
    forward_velocity, inverse_dynamics,
};

/// The planar four-bar's rocker angle: crank pivot (0, 0), rocker pivot (d, 0), crank `a` at
/// angle `th`, coupler `b`, rocker `c`; the open assembly (the models' home branch).
fn rocker(th: f64, [a, b, c, d]: [f64; 4]) -> f64 {
    let (kx, ky) = (a * th.cos() - d, a * th.sin());
    let k = kx.hypot(ky);
    ky.atan2(kx) - ((k * k + c * c - b * b) / (2.0 * c * k)).acos()
}

/// `t` wrapped to (-pi, pi].
fn wrap(t: f64) -> f64 {
    let tau = std::f64::consts::TAU;
    t - tau * (t / tau).round()
}

/// The derivative of `f` by a central difference (h = 1e-6: error ~1e-11 here).
fn derivative(f: impl Fn(f64) -> f64, t: f64) -> f64 {
    let h = 1e-6;
    wrap(f(t + h) - f(t - h)) / (2.0 * h)
}

#[test]
fn four_bar_rod_matches_freudenstein() {
    use four_bar_rod::{FourBarRod, Params};
    let p = Params::default();
    let dims = [p.a, p.b, p.c, p.d];
    let model = Model::new(FourBarRod::default());
    let mut data = Data::new(&model);
    data.set_home(&model);
    let (mut pos, mut vel) = (0.0f64, 0.0f64);
    // A full turn of the crank in steps of 0.1 rad (each FK from the last: the same assembly).
    let th0 = data.x[0];
    for i in 1..=63 {
        let th = th0 + 0.1 * f64::from(i);
        forward_kinematics(&model, &mut data, &[th]).unwrap_or_else(|e| panic!("FK at {th}: {e}"));
        pos = pos.max(wrap(data.x[1] - rocker(th, dims)).abs());
        let thdot = 1.3;
        forward_velocity(&model, &mut data, &[thdot]).expect("velocity");
        let want = derivative(|t| rocker(t, dims), th) * thdot;
        vel = vel.max((data.xdot[1] - want).abs() / (1.0 + want.abs()));
    }
    println!("four_bar_rod: rocker angle vs Freudenstein {pos:.1e} rad, rate {vel:.1e} (relative)");
    assert!(pos < 1e-12, "rocker angle error {pos:e}");
    assert!(vel < 1e-8, "rocker rate error {vel:e}");
}

/// `d(T + Pi)/dt` at `data`'s state and accelerations, from the generated energy kernel: a
/// central difference along `X + s Xdot + s²/2 Xddot`, `Xdot + s Xddot`, at h and h/2,
/// Richardson-extrapolated. On the leg the error falls as h⁴ (2.2e-4 relative at h = 1e-3,
/// 1.8e-6 at 3e-4) down to 1.8e-10 at h = 3e-5, where rounding takes over (6.4e-10 at 1e-5).
fn energy_rate<K: Dynamics<N, M>, const N: usize, const M: usize>(
    robot: &K,
    data: &Data<N, M>,
) -> f64 {
    let (x, xdot, xddot) = (data.x, data.xdot, data.xddot);
    let e_at = |s: f64| {
        let xs: [f64; N] = std::array::from_fn(|i| x[i] + s * xdot[i] + 0.5 * s * s * xddot[i]);
        let vs: [f64; N] = std::array::from_fn(|i| xdot[i] + s * xddot[i]);
        let mut e = [0.0; 2];
        robot.energy(&xs, &vs, &mut e);
        e[0] + e[1]
    };
    let d = |h: f64| (e_at(h) - e_at(-h)) / (2.0 * h);
    (4.0 * d(1.5e-5) - d(3e-5)) / 3.0
}

/// The leg's potential energy (gravity and the three torsion springs) as a function of the
/// actuated coordinates (motor, crank), along the closed form: the hip is geared to the motor
/// and turns about the vertical (it moves no mass up or down); in the hip's vertical plane a
/// point at (u, w) is at height z = -w (see the model file's header). The springs see the
/// angles themselves, not modulo a turn: `turns` are the whole turns of (k, r) beyond the
/// closed form's principal values.
fn leg_potential(p: &leg_four_bar::Params, mo: f64, c: f64, turns: [f64; 2]) -> f64 {
    let [a, b, l] = [p.a, p.b, p.l];
    let tau = std::f64::consts::TAU;
    let (k, r) = leg_potential_angles(p, c);
    let (k, r) = (k + tau * turns[0], r + tau * turns[1]);
    let h = p.gear * mo;
    // The boxes' masses (density times volume) and their centres' heights; the motor's rotor
    // (0.2 kg at z = 0.1) and the hip's bar (at z = 0) do not move vertically.
    let g = 9.81;
    let crank = p.rho * a * 0.02 * 0.01 * -(0.5 * a * c.sin());
    let coupler = p.rho * b * 0.02 * 0.01 * -(a * c.sin() + 0.5 * b * (c + k).sin());
    let rocker_bar = p.rho * l * 0.02 * 0.01 * -(0.5 * l * r.sin());
    let gravity = g * (0.2 * 0.1 + crank + coupler + rocker_bar);
    let spring = |stiffness: f64, q: f64, rest: f64| 0.5 * stiffness * (q - rest).powi(2);
    gravity + spring(p.kh, h, p.rh) + spring(p.kk, k, p.rk) + spring(p.kr, r, p.rr)
}

/// The closed form's (k, r) at crank angle `c` (principal values).
fn leg_potential_angles(p: &leg_four_bar::Params, c: f64) -> (f64, f64) {
    let r = rocker(c, [p.a, p.b, p.l, p.d]);
    let (ax, ay) = (p.a * c.cos(), p.a * c.sin());
    let (bx, by) = (p.d + p.l * r.cos(), p.l * r.sin());
    ((by - ay).atan2(bx - ax) - c, r)
}

#[test]
fn leg_four_bar_springs_against_virtual_work_and_energy() {
    use leg_four_bar::{LegFourBar, N, Params};
    let p = Params::default();
    let model = Model::new(LegFourBar::default());
    let robot = model.kernels();
    let mut data = Data::new(&model);
    data.set_home(&model);
    let energy = |x: &[f64; N], xdot: &[f64; N]| {
        let mut e = [0.0; 2];
        robot.energy(x, xdot, &mut e);
        e
    };
    let mut rng = Rng::new(0x5b1e);
    let (mut static_err, mut scale, mut pi_err, mut rate_err) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let c0 = data.x[2];
    for i in 1..=40 {
        let c = c0 + 0.15 * f64::from(i);
        let mo = 20.0 * rng.sym();
        forward_kinematics(&model, &mut data, &[mo, c]).expect("FK");
        // Holding torques at rest: U = dV/d(mo, c) along the closed form (virtual work; the
        // loop's multipliers do none). Central differences, h = 1e-5: error ~1e-10.
        data.xdot = [0.0; N];
        data.xddot = [0.0; N];
        inverse_dynamics(&model, &mut data, None).expect("inverse dynamics");
        let tau = std::f64::consts::TAU;
        let (k0, r0) = leg_potential_angles(&p, c);
        let turns = [
            ((data.x[3] - k0) / tau).round(),
            ((data.x[4] - r0) / tau).round(),
        ];
        let v = |mo: f64, c: f64| leg_potential(&p, mo, c, turns);
        let h = 1e-5;
        // The crank's actuator is geared (U the motor's torque, the crank's 20 U).
        let want = [
            (v(mo + h, c) - v(mo - h, c)) / (2.0 * h),
            (v(mo, c + h) - v(mo, c - h)) / (2.0 * h) / 20.0,
        ];
        for (got, want) in data.u().iter().zip(want) {
            static_err = static_err.max((got - want).abs());
            scale = scale.max(want.abs());
        }
        // The potential energy kernel against the closed form's.
        pi_err = pi_err.max((energy(&data.x, &data.xdot)[1] - v(mo, c)).abs());
        // dE/dt = U·q̇_a - Σ c q̇² at a moving state (the springs are in E, the multipliers do
        // no work): a central difference of the energy kernel along (Xdot, Xddot).
        forward_velocity(&model, &mut data, &[3.0 * rng.sym(), 2.0 * rng.sym()]).expect("rates");
        let u = [0.05 * rng.sym(), 0.025 * rng.sym()];
        forward_dynamics(&model, &mut data, &u, None, Baumgarte::NONE).expect("FD");
        let rate = energy_rate(robot, &data);
        let xdot = data.xdot;
        let power = u[0] * xdot[0] + 20.0 * u[1] * xdot[2]
            - p.ch * xdot[1].powi(2)
            - p.ck * xdot[3].powi(2)
            - p.cr * xdot[4].powi(2);
        rate_err = rate_err.max((rate - power).abs() / (1.0 + power.abs()));
    }
    println!(
        "leg_four_bar: holding torques vs virtual work {static_err:.1e} (torques up to \
         {scale:.2}), Pi vs closed form {pi_err:.1e} J, dE/dt vs power {rate_err:.1e} (relative)"
    );
    assert!(
        static_err <= 1e-8 * scale,
        "holding torques: {static_err:e}"
    );
    assert!(pi_err < 1e-12, "potential energy: {pi_err:e} J");
    assert!(rate_err < 1e-8, "energy rate: {rate_err:e}");
}

#[test]
fn leg_four_bar_closes_in_the_turning_plane() {
    use leg_four_bar::{BODIES, LegFourBar, NB, Params, body_frames};
    let p = Params::default();
    let dims = [p.a, p.b, p.l, p.d];
    let model = Model::new(LegFourBar::default());
    let mut data = Data::new(&model);
    data.set_home(&model);
    let foot = BODIES.iter().position(|&b| b == "foot").unwrap();
    let mut rng = Rng::new(0x1e6);
    let (mut pos, mut vel) = (0.0f64, 0.0f64);
    let c0 = data.x[2];
    for i in 1..=63 {
        // The crank turns in steps; the motor jumps at random (the hip over +-2 rad, where the
        // loop's plane is far from any world plane).
        let c = c0 + 0.1 * f64::from(i);
        let mo = 20.0 * rng.sym();
        forward_kinematics(&model, &mut data, &[mo, c])
            .unwrap_or_else(|e| panic!("FK at {mo}, {c}: {e}"));
        let h = p.gear * mo;
        let r = rocker(c, dims);
        // The coupler's angle from the crank: towards the rocker's tip.
        let (ax, ay) = (p.a * c.cos(), p.a * c.sin());
        let (bx, by) = (p.d + p.l * r.cos(), p.l * r.sin());
        let k = (by - ay).atan2(bx - ax) - c;
        let [x_mo, x_h, x_c, x_k, x_r] = data.x;
        pos = pos
            .max((x_mo - mo).abs())
            .max((x_h - h).abs())
            .max((x_c - c).abs())
            .max(wrap(x_k - k).abs())
            .max(wrap(x_r - r).abs());
        // The foot in world axes: the rocker's tip (u, w) in the hip's x-z plane (z = -w),
        // turned by the hip about z.
        let mut frames = [[0.0; 12]; NB];
        body_frames(&model.kernels().c, &data.x, &mut frames);
        let want = [h.cos() * bx, h.sin() * bx, -by];
        for (got, want) in frames[foot][9..].iter().zip(want) {
            pos = pos.max((got - want).abs());
        }
        // Rates: the hip geared to the motor, the knee by the closed form's derivative.
        let (mo_dot, c_dot) = (3.0 * rng.sym(), 1.5 * rng.sym());
        forward_velocity(&model, &mut data, &[mo_dot, c_dot]).expect("velocity");
        let r_dot = derivative(|t| rocker(t, dims), c) * c_dot;
        let k_of = |t: f64| {
            let r = rocker(t, dims);
            (p.l * r.sin() - p.a * t.sin()).atan2(p.d + p.l * r.cos() - p.a * t.cos()) - t
        };
        let k_dot = derivative(k_of, c) * c_dot;
        for (got, want) in [
            (data.xdot[1], p.gear * mo_dot),
            (data.xdot[3], k_dot),
            (data.xdot[4], r_dot),
        ] {
            vel = vel.max((got - want).abs() / (1.0 + want.abs()));
        }
    }
    println!(
        "leg_four_bar: coordinates and foot vs the turned closed form {pos:.1e}, rates {vel:.1e}"
    );
    assert!(pos < 1e-12, "position error {pos:e}");
    assert!(vel < 1e-8, "rate error {vel:e}");
}

#[test]
fn gear_pair_dynamics_match_the_reduced_inertia() {
    use gear_pair::{GearPair, Params};
    let p = Params::default();
    // The model's mass properties (models/gear_pair.toml): the pinion's Izz, the wheel's mass
    // and Izz about its centre of mass.
    let (i1, m2, i2) = (3e-4, 1.2, 5e-3);
    let j2 = i2 + m2 * p.e * p.e;
    let g = 9.81;
    let model = Model::new(GearPair::default());
    let mut data = Data::new(&model);
    let mut rng = Rng::new(0x6ea2);
    let mut worst = 0.0f64;
    for _ in 0..50 {
        let q1 = 3.0 * rng.sym();
        let q1dot = 4.0 * rng.sym();
        let u = 2.0 * rng.sym();
        data.set_home(&model);
        forward_kinematics(&model, &mut data, &[q1]).expect("FK");
        let q2 = p.ratio * q1 + p.offset;
        assert!((data.x[1] - q2).abs() < 1e-14, "q2 = {} vs {q2}", data.x[1]);
        forward_velocity(&model, &mut data, &[q1dot]).expect("velocity");
        assert!((data.xdot[1] - p.ratio * q1dot).abs() < 1e-14);
        forward_dynamics(&model, &mut data, &[u], None, Baumgarte::default()).expect("FD");
        let q1ddot = (u - p.ratio * m2 * g * p.e * q2.cos()) / (i1 + p.ratio * p.ratio * j2);
        for (got, want) in [(data.xddot[0], q1ddot), (data.xddot[1], p.ratio * q1ddot)] {
            worst = worst.max((got - want).abs() / (1.0 + want.abs()));
        }
    }
    println!("gear_pair: forward dynamics vs the reduced inertia {worst:.1e} (relative)");
    assert!(worst < 1e-12, "acceleration error {worst:e}");
}

#[test]
fn slider_crank_pin_stays_in_its_plane() {
    use slider_crank::{BODIES, NB, Params, SliderCrank, body_frames};
    let p = Params::default();
    // The rod's angle from the crank, a sin th + b sin(th + k) = 0 (the pin at x > 0).
    let rod = |th: f64| -(p.a * th.sin() / p.b).asin() - th;
    let model = Model::new(SliderCrank::default());
    let mut data = Data::new(&model);
    data.set_home(&model);
    let r = BODIES.iter().position(|&b| b == "rod").unwrap();
    let (mut pos, mut vel) = (0.0f64, 0.0f64);
    let th0 = data.x[0];
    // A full turn of the crank (each FK from the last).
    for i in 1..=63 {
        let th = th0 + 0.1 * f64::from(i);
        forward_kinematics(&model, &mut data, &[th]).unwrap_or_else(|e| panic!("FK at {th}: {e}"));
        let k = rod(th);
        pos = pos.max(wrap(data.x[1] - k).abs());
        // The pin: the rod's frame moved by b along its x axis; y = 0, x the free travel.
        let mut frames = [[0.0; 12]; NB];
        body_frames(&model.kernels().c, &data.x, &mut frames);
        let f = frames[r];
        let pin = [f[9] + p.b * f[0], f[10] + p.b * f[1]];
        let x = p.a * th.cos() + p.b * (th + k).cos();
        pos = pos.max((pin[0] - x).abs()).max(pin[1].abs());
        forward_velocity(&model, &mut data, &[0.7]).expect("velocity");
        let want = derivative(rod, th) * 0.7;
        vel = vel.max((data.xdot[1] - want).abs() / (1.0 + want.abs()));
    }
    println!("slider_crank: rod angle and pin vs the closed form {pos:.1e}, rate {vel:.1e}");
    assert!(pos < 1e-12, "position error {pos:e}");
    assert!(vel < 1e-8, "rate error {vel:e}");
}

/// The spatial crank's closed forms at crank angle `th` (models/spatial_crank.toml): the
/// rocker's angle phi (its tip at D - c (0, cos phi, sin phi), the model's assembly) and the
/// slider pin's height.
fn spatial_crank_closed_form(p: &spatial_crank::Params, th: f64) -> (f64, f64) {
    let (cx, cy) = (p.a * th.cos(), p.a * th.sin());
    // |D - c (0, cos phi, sin phi) - C|² = b²: A cos phi + B sin phi = K.
    let (dx, dy, dz) = (p.d - cx, -cy, p.h);
    let (a, b) = (-2.0 * p.c * dy, -2.0 * p.c * dz);
    let k = p.b * p.b - dx * dx - dy * dy - dz * dz - p.c * p.c;
    let phi = b.atan2(a) - (k / a.hypot(b)).acos();
    let rho = (p.xl - cx).hypot(p.yl - cy);
    (phi, -(p.e * p.e - rho * rho).sqrt())
}

#[test]
fn spatial_crank_hinge_and_slider_against_closed_forms() {
    use spatial_crank::{BODIES, N, NB, Params, SpatialCrank, body_frames};
    let p = Params::default();
    let model = Model::new(SpatialCrank::default());
    let robot = model.kernels();
    let mut data = Data::new(&model);
    data.set_home(&model);
    let rocker = BODIES.iter().position(|&b| b == "rocker").unwrap();
    let pin = BODIES.iter().position(|&b| b == "pin").unwrap();
    let mut frames = [[0.0; 12]; NB];
    let mut rng = Rng::new(0x5c);
    let (mut pos, mut vel, mut power, mut check) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let th0 = data.x[0];
    for i in 1..=64 {
        let th = th0 + std::f64::consts::TAU * f64::from(i) / 64.0;
        forward_kinematics(&model, &mut data, &[th]).unwrap_or_else(|e| panic!("FK at {th}: {e}"));
        let (phi, z) = spatial_crank_closed_form(&p, th);
        body_frames(&robot.c, &data.x, &mut frames);
        // The rocker's frame (rotation columns, then origin): its x axis from its tip towards
        // the pivot, (0, cos phi, sin phi); its z axis the ground's, world x; its tip.
        let f = &frames[rocker];
        let want_x = [0.0, phi.cos(), phi.sin()];
        let want_tip = [p.d, -p.c * phi.cos(), p.h - p.c * phi.sin()];
        for k in 0..3 {
            pos = pos
                .max((f[k] - want_x[k]).abs())
                .max((f[6 + k] - [1.0, 0.0, 0.0][k]).abs())
                .max((f[9 + k] - want_tip[k]).abs());
        }
        let f = &frames[pin];
        pos = pos
            .max((f[9] - p.xl).abs())
            .max((f[10] - p.yl).abs())
            .max((f[11] - z).abs());
        // The closure checks of the loops' open components: the hinge's axes agree (0, not 2).
        let mut open = [0.0; spatial_crank::MC];
        robot.closure_check(&data.x, &mut open);
        check = open.iter().fold(check, |m, v: &f64| m.max(v.abs()));
        // Rates: the rocker's angular velocity about world x, the pin's vertical speed, against
        // the closed forms' derivatives.
        let th_dot = 2.0 * rng.sym();
        forward_velocity(&model, &mut data, &[th_dot]).expect("velocity");
        let h = 1e-6;
        let phi_dot = derivative(|t| spatial_crank_closed_form(&p, t).0, th) * th_dot;
        let z_dot = (spatial_crank_closed_form(&p, th + h).1
            - spatial_crank_closed_form(&p, th - h).1)
            / (2.0 * h)
            * th_dot;
        // Velocities by a step of the frames along Xdot (central, first order exact to 1e-10).
        let step = |s: f64| -> [[f64; 12]; NB] {
            let xs: [f64; N] = std::array::from_fn(|i| data.x[i] + s * data.xdot[i]);
            let mut fr = [[0.0; 12]; NB];
            body_frames(&robot.c, &xs, &mut fr);
            fr
        };
        let (fp, fm) = (step(h), step(-h));
        // The rocker's tip moves as phi turns: d/dt (-c cos phi) = c sin phi phi_dot (y).
        let tip_y_dot = (fp[rocker][10] - fm[rocker][10]) / (2.0 * h);
        let pin_z_dot = (fp[pin][11] - fm[pin][11]) / (2.0 * h);
        for (got, want) in [(tip_y_dot, p.c * phi.sin() * phi_dot), (pin_z_dot, z_dot)] {
            vel = vel.max((got - want).abs() / (1.0 + want.abs()));
        }
        // Forward dynamics under a random torque: dE/dt = U th_dot (no springs, no dampers; the
        // multipliers do no work), by a central difference of the energy kernel.
        let u = 0.5 * rng.sym();
        forward_dynamics(&model, &mut data, &[u], None, Baumgarte::NONE).expect("FD");
        let rate = energy_rate(robot, &data);
        let xdot0 = data.xdot[0];
        power = power.max((rate - u * xdot0).abs() / (1.0 + (u * xdot0).abs()));
    }
    println!(
        "spatial_crank: rocker frame and pin vs closed forms {pos:.1e}, open components \
         {check:.1e}, rates {vel:.1e}, dE/dt vs U th_dot {power:.1e}"
    );
    assert!(pos < 1e-12, "position error {pos:e}");
    assert!(check < 1e-12, "closure check {check:e}");
    assert!(vel < 1e-8, "rate error {vel:e}");
    assert!(power < 1e-8, "energy rate error {power:e}");
}
