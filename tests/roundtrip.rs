//! `rbss roundtrip`: the paper's round trip (inverse kinematics and dynamics along an output
//! trajectory, forward dynamics under the resulting U(t), outputs compared) for any robot, along
//! its default trajectory models/trajectories/NAME.toml.

use rbss::roundtrip::{RoundTripRequest, roundtrip_command};
use rbss_runtime::{IntegrateOptions, Method, Stabilization};

fn run(model: &str, rtol: f64) -> f64 {
    run_with(model, Method::dopri5(rtol, rtol / 100.0)).0
}

/// The round trip with the integrator `method` (projection): (max output error, steps).
fn run_with(model: &str, method: Method) -> (f64, usize) {
    // A directory of its own per call: two tests of this binary may run the same model at once.
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path();
    let req = RoundTripRequest {
        model: model.to_string(),
        trajectory: None,
        t_end: None,
        integrate: IntegrateOptions::new(method, Stabilization::Projection),
        out: out.to_string_lossy().into_owned(),
    };
    let s = roundtrip_command(&req).unwrap_or_else(|e| panic!("{model}: {e}"));
    assert!(out.join("roundtrip.csv").exists() && out.join("roundtrip.png").exists());
    println!(
        "{model}, {method:?}: max output error {:.3e}, {} steps",
        s.max_output_error, s.steps
    );
    (s.max_output_error, s.steps)
}

/// DOP853 against DOPRI5 at the same tolerance, every robot family: at most a third of the
/// steps (each of twelve right-hand sides against six) and an error within the same decade.
/// Measured at rtol 1e-10 (projection): 6-UPS 66 / 369 steps, UR5 68 / 496, delta 32 / 211,
/// planar 3-RRR 41 / 222, hexapod 69 / 392, Tricept 42 / 378; errors (DOP853 / DOPRI5) 3.0e-10 /
/// 4.3e-9, 2.3e-11 / 7.1e-10, 2.3e-11 / 5.9e-11, 8.8e-12 / 2.1e-12, 3.1e-11 / 5.3e-11,
/// 1.2e-11 / 2.6e-11.
#[test]
fn dop853_takes_fewer_steps_for_the_same_accuracy() {
    for model in [
        "stewart_6ups",
        "ur5",
        "delta",
        "planar_3rrr",
        "hexa_6rus",
        "hybrid_tricept",
    ] {
        let (e5, s5) = run_with(model, Method::dopri5(1e-10, 1e-12));
        let (e8, s8) = run_with(model, Method::dop853(1e-10, 1e-12));
        assert!(3 * s8 <= s5, "{model}: {s8} DOP853 steps against {s5}");
        assert!(e8 <= 10.0 * e5, "{model}: error {e8:e} against {e5:e}");
    }
}

/// Measured: 2.2e-12 (rad or m) at rtol 1e-12, 8.1e-10 at 1e-10 (the flange's task frame).
#[test]
fn ur5_round_trip() {
    assert!(run("ur5", 1e-12) < 1e-10);
}

/// Measured: 4.286e-9 rad (the rotations; positions 4.4e-11 m, as `rbss paper`).
#[test]
fn stewart_6ups_round_trip() {
    assert!(run("stewart_6ups", 1e-10) < 1e-8);
}

/// The five-bar under its figure eight is open-loop unstable (its links stand above the base
/// joints against gravity): the feed-forward round trip's error grows about tenfold every
/// 0.15 s, so it scales with the integrator's tolerance. Measured: 8.2e-5 m at rtol 1e-10,
/// 8.6e-7 at 1e-12, 8.4e-8 at 1e-13.
#[test]
fn five_bar_round_trip_scales_with_the_tolerance() {
    let coarse = run("five_bar", 1e-11);
    let fine = run("five_bar", 1e-13);
    assert!(fine < 1e-6, "{fine:e}");
    assert!(fine < coarse / 10.0, "{fine:e} vs {coarse:e}");
}

/// Measured: 5.9e-11 m at rtol 1e-10 (2.8e-13 at 1e-12).
#[test]
fn delta_round_trip() {
    assert!(run("delta", 1e-10) < 1e-9);
}

/// Measured: 2.1e-12 (m or rad) at rtol 1e-10 (1.7e-14 at 1e-12).
#[test]
fn planar_3rrr_round_trip() {
    assert!(run("planar_3rrr", 1e-10) < 1e-9);
}

/// The tripod under feed-forward leg forces is open-loop unstable (its platform stands on the
/// legs; the error grows about 3.6-fold every 0.2 s), so its error scales with the
/// integrator's tolerance: measured 3.3e-7 at rtol 1e-10, 3.5e-9 at 1e-12, 3.6e-10 at 1e-13.
#[test]
fn tripod_3rps_round_trip() {
    assert!(run("tripod_3rps", 1e-13) < 1e-9);
}

/// The two-stage robot along models/trajectories/stewart_2stage.toml is open-loop unstable like
/// the tripod: measured 3.3e-7 at rtol 1e-10, 3.4e-8 at 1e-11, 3.4e-9 at 1e-12 (m or rad).
#[cfg(feature = "all-robots")]
#[test]
fn stewart_2stage_round_trip_scales_with_the_tolerance() {
    let coarse = run("stewart_2stage", 1e-10);
    let fine = run("stewart_2stage", 1e-12);
    assert!(fine < 1e-8, "{fine:e}");
    assert!(fine < coarse / 10.0, "{fine:e} vs {coarse:e}");
}

/// five_bar_turned is the five-bar written with redundant constant rotations (other kernels,
/// the same mechanism): along the same figure eight, its round trip, which the five-bar's open-loop
/// instability makes sensitive to every rounding, ends with the same error to 1 %. Measured at
/// rtol 1e-11: 8.458e-6 and 8.464e-6 m.
#[cfg(feature = "all-robots")]
#[test]
fn five_bar_turned_round_trip_matches_the_five_bar() {
    let plain = run("five_bar", 1e-11);
    let turned = run("five_bar_turned", 1e-11);
    assert!(
        (plain - turned).abs() <= 0.01 * plain,
        "{plain:e} vs {turned:e}"
    );
}

/// The command prints the line scripts read.
#[test]
fn the_command_prints_the_error() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_rbss"))
        .args([
            "roundtrip",
            "--model",
            "ur5",
            "--out",
            dir.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let line = stdout
        .lines()
        .find_map(|l| l.strip_prefix("round-trip max output error: "))
        .unwrap_or_else(|| panic!("no error line in {stdout}"));
    let e: f64 = line.trim().parse().unwrap();
    assert!(e < 1e-8, "{e:e}");
}
