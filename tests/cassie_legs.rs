//! Forward dynamics of models/cassie_legs.toml (a Cassie-like leg pair: per leg an achilles rod
//! closing a hinge loop and a plantar rod closing a ball loop, shin and heel springs, thin rods
//! whose spin inertia is 3.754e-6 kg m² against 1e-1 elsewhere; issue 33) against an
//! independent reference: the dense saddle-point system `[M Gᵀ; G 0]` from the same kernel
//! values, solved in double-double arithmetic by a pivoted LU (tests/common/kkt.rs).
//!
//! States are assembled by the runtime's inverse kinematics (the outputs perturbed about the
//! home, the other coordinates solved), their rates by its inverse velocity (so `Ẋ` is in the
//! null space of `G`): a regular problem everywhere, which forward dynamics must answer, never
//! with `Singular`, with accelerations within 1e-12 (relative, in the max norm) of the
//! reference.

mod common;

use cassie_legs::{CassieLegs, M, N};
use common::Rng;
use common::kkt::{Dd, cond1, forward_dynamics_dd_kernels, kkt_matrix};
use rbss_runtime::{
    Baumgarte, Data, Dynamics, Model, forward_dynamics, inverse_kinematics, inverse_velocity,
};

/// `max |a - b| / max |b|`.
fn rel_err(a: &[f64], b: &[f64]) -> f64 {
    let scale = b.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    common::max_diff(a, b) / scale
}

/// The reference checks itself first: a saddle-point system with a known solution and masses
/// six decades apart, solved to the last bit, and double-double carrying the digits f64 drops.
#[test]
fn the_double_double_reference_is_exact_on_a_known_system() {
    // M = diag(1, 2⁻²⁰, 2¹³), G = [1 1 1]; x* = (1, -2, 1) (G x* = 0), lambda* = 3: the
    // right-hand side M x* + Gᵀ lambda* is exact in f64, so x* is the f64 system's solution.
    let mass = [
        [1.0, 0.0, 0.0],
        [0.0, 1.0 / 1048576.0, 0.0],
        [0.0, 0.0, 8192.0],
    ];
    let g = [[1.0], [1.0], [1.0]];
    let (xs, ls) = ([1.0, -2.0, 1.0], 3.0);
    let force: [f64; 3] = std::array::from_fn(|i| mass[i][i] * xs[i] + ls);
    let (x, l) = forward_dynamics_dd_kernels(&mass, &g, &force, &[0.0]).unwrap();
    assert_eq!(x, xs, "accelerations");
    assert_eq!(l, [ls], "multiplier");
    let rows = |a: &[[f64; 3]; 3]| a.iter().map(|r| r.to_vec()).collect::<Vec<_>>();
    let c = cond1(&kkt_matrix(&rows(&mass), &[vec![1.0, 1.0, 1.0]])).unwrap();
    assert!(c > 1e4, "cond {c:e}");
    let third = Dd::from_f64(1.0).div(Dd::from_f64(3.0));
    let back = third.mul(Dd::from_f64(3.0)).sub(Dd::from_f64(1.0));
    assert!(
        back.to_f64().abs() < 1e-31 && third.lo != 0.0,
        "{third:?} {back:?}"
    );
}

/// The derived parameters of the model file (the achilles rod's direction and length, the
/// hinge's axis) close both loops at the design pose, so the generated home assembly is that
/// pose; there the achilles rod's spin `ach_a` moves only the rod about its own axis, and its
/// diagonal entry of `M` is the rod's thin-axis inertia.
#[test]
fn the_home_is_the_design_pose_and_the_rods_are_thin() {
    let model = Model::new(CassieLegs::default());
    let s = model.structure();
    let design = |name: &str| -> f64 {
        let base = name.trim_end_matches(['1', '2']);
        match base {
            "pz" => 1.0,
            "knee" => 0.12,
            "shin" => 0.62,
            "tarsus" => -0.87,
            _ => 0.0,
        }
    };
    for (j, name) in s.coordinates.iter().enumerate() {
        assert!(
            (s.home[j] - design(name)).abs() < 1e-12,
            "{name}: home {} against the design pose {}",
            s.home[j],
            design(name)
        );
    }
    let x: [f64; N] = s.home.try_into().unwrap();
    let mut mass = [[0.0; N]; N];
    model.kernels().mass_matrix(&x, &mut mass);
    for rod in ["ach_a1", "ach_a2"] {
        let j = s.coordinates.iter().position(|c| *c == rod).unwrap();
        assert!(
            (mass[j][j] - 3.754e-6).abs() < 1e-18,
            "M[{rod}][{rod}] = {:e}",
            mass[j][j]
        );
    }
}

#[test]
fn forward_dynamics_matches_the_double_double_saddle_point_solve() {
    let model = Model::new(CassieLegs::default());
    let s = model.structure();
    let k = model.kernels();
    assert!(s.actuated.is_empty(), "the leg pair has no actuator");
    let home: Vec<f64> = s.outputs.iter().map(|&j| s.home[j]).collect();
    let mut rng = Rng::new(0xca55_1e00);
    let mut data = Data::new(&model);
    let (mut worst_acc, mut worst_lambda, mut worst_cond_kkt) = (0.0_f64, 0.0_f64, 0.0_f64);
    let mut min_cond_m = f64::INFINITY;
    let states = 40;
    for state in 0..states {
        // Outputs within 0.1 (rad, m) of the home, rates up to 1 rad/s (0.5 m/s for the pelvis).
        let outputs: Vec<f64> = home.iter().map(|h| h + 0.1 * rng.sym()).collect();
        let rates: Vec<f64> = s
            .outputs
            .iter()
            .map(|&j| rng.sym() * if s.coordinates[j] == "pz" { 0.5 } else { 1.0 })
            .collect();
        data.set_home(&model);
        inverse_kinematics(&model, &mut data, &outputs)
            .unwrap_or_else(|e| panic!("state {state}: inverse kinematics: {e}"));
        inverse_velocity(&model, &mut data, &rates)
            .unwrap_or_else(|e| panic!("state {state}: inverse velocity: {e}"));
        let (x, xdot) = (data.x, data.xdot);

        // The kernel values forward dynamics uses (the fused kernel it calls, bit for bit).
        let (mut g, mut gamma, mut mass, mut psi) =
            ([[0.0; M]; N], [0.0; M], [[0.0; N]; N], [0.0; N]);
        k.dynamics_terms(&x, &xdot, &mut g, &mut gamma, &mut mass, &mut psi);
        // Xdot is in the null space of G (to the rounding of the rates' solve).
        let g_xdot = (0..M)
            .map(|c| (0..N).map(|j| g[j][c] * xdot[j]).sum::<f64>().abs())
            .fold(0.0, f64::max);
        assert!(g_xdot < 1e-12, "state {state}: |G Xdot| = {g_xdot:e}");
        let (ref_xddot, ref_lambda) = forward_dynamics_dd_kernels(&mass, &g, &psi, &gamma)
            .unwrap_or_else(|| panic!("state {state}: the saddle-point matrix is singular"));

        // The problem is as ill-conditioned as Cassie's: M's condition number from the thin rods.
        let rows_m: Vec<Vec<f64>> = (0..N)
            .map(|i| (0..N).map(|j| mass[j][i]).collect())
            .collect();
        let rows_g: Vec<Vec<f64>> = (0..M).map(|c| (0..N).map(|j| g[j][c]).collect()).collect();
        min_cond_m = min_cond_m.min(cond1(&rows_m).unwrap());
        worst_cond_kkt = worst_cond_kkt.max(cond1(&kkt_matrix(&rows_m, &rows_g)).unwrap());

        forward_dynamics(&model, &mut data, &[], None, Baumgarte::NONE).unwrap_or_else(|e| {
            panic!("state {state}: forward dynamics refused a regular problem: {e}")
        });
        let acc = rel_err(&data.xddot, &ref_xddot);
        let lam = rel_err(&data.lambda, &ref_lambda);
        assert!(
            acc <= 1e-12,
            "state {state}: accelerations {acc:.2e} (relative, max norm) from the double-double \
             reference"
        );
        worst_acc = worst_acc.max(acc);
        worst_lambda = worst_lambda.max(lam);
    }
    println!(
        "cassie_legs, {states} states: accelerations {worst_acc:.2e}, multipliers \
         {worst_lambda:.2e} (relative, max norm) from the double-double reference; cond1(M) >= \
         {min_cond_m:.2e}, cond1([M Gᵀ; G 0]) <= {worst_cond_kkt:.2e}"
    );
    assert!(
        min_cond_m > 1e6,
        "the thin rods make M ill-conditioned: cond1(M) {min_cond_m:e}"
    );
}
