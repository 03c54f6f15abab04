//! The MPC example (examples/mpc_traekp.rs) on a short horizon: the 6-UPS tracks TraekP from a
//! perturbed start under the time-varying LQR built on `linearize`'s A, B, simulated on the
//! nonlinear closed-chain model. Asserts that the feedback drives the error down (at the end
//! at least 100 times below the open loop's and below 1 % of the start's offset, the worst
//! error of each quarter of the horizon below the previous quarter's), that the discrete linear
//! model predicts the nonlinear closed loop's steps, and that the figure is written.

#[allow(dead_code)]
#[path = "../examples/mpc_traekp.rs"]
mod example;

use example::{Options, Sample, run};

/// The worst position (m) and rotation (rad) errors of the samples in `[t0, t1]`.
fn worst(s: &[Sample], t0: f64, t1: f64) -> (f64, f64) {
    s.iter()
        .filter(|p| p.t >= t0 - 1e-12 && p.t <= t1 + 1e-12)
        .fold((0.0_f64, 0.0_f64), |(a, b), p| {
            (a.max(p.position), b.max(p.rotation))
        })
}

#[test]
fn lqr_tracks_traek_p_from_a_perturbed_start() {
    let dir = tempfile::tempdir().unwrap();
    let opts = Options {
        t_end: 0.5,
        dt: 0.01,
        ..Options::default()
    };
    let rep = run(&opts, Some(dir.path())).unwrap();
    assert_eq!(rep.knots, 50);
    let t_end = 0.5;
    let start = rep.closed[0];
    // The start is the perturbation: 1 cm and 0.02 rad at most.
    assert!((start.position - 0.01).abs() < 1e-9, "{start:?}");
    assert!((start.rotation - 0.02).abs() < 1e-9, "{start:?}");
    let closed_end = *rep.closed.last().unwrap();
    let open_end = *rep.open.last().unwrap();
    assert!((closed_end.t - t_end).abs() < 1e-12 && (open_end.t - t_end).abs() < 1e-12);
    eprintln!("closed loop at the end: {closed_end:?}; open loop: {open_end:?}");
    assert!(
        closed_end.position < 0.01 * start.position && closed_end.rotation < 0.01 * start.rotation,
        "closed loop at the end: {closed_end:?}"
    );
    assert!(
        closed_end.position * 100.0 < open_end.position
            && closed_end.rotation * 100.0 < open_end.rotation,
        "closed {closed_end:?} vs open {open_end:?}"
    );
    // The worst error over each quarter of the horizon decreases.
    let quarters: Vec<(f64, f64)> = (0..4)
        .map(|i| {
            worst(
                &rep.closed,
                i as f64 * t_end / 4.0,
                (i + 1) as f64 * t_end / 4.0,
            )
        })
        .collect();
    eprintln!("worst errors per quarter: {quarters:?}");
    for w in quarters.windows(2) {
        assert!(w[1].0 < w[0].0 && w[1].1 < w[0].1, "{quarters:?}");
    }
    // The open loop does not recover: its error at the end is no smaller than at the start.
    assert!(open_end.position >= start.position, "{open_end:?}");
    // (A_d, B_d) predict the nonlinear closed loop's knot-to-knot error change to 10 %.
    eprintln!("prediction residual {:.3e}", rep.prediction_residual);
    assert!(rep.prediction_residual < 0.1, "{}", rep.prediction_residual);
    // The simulation stayed on the manifold.
    assert!(rep.max_violation < 1e-9, "{}", rep.max_violation);
    assert!(rep.linearize_mean > 0.0 && rep.riccati > 0.0);
    let png = std::fs::read(dir.path().join("mpc_traekp.png")).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    let csv = std::fs::read_to_string(dir.path().join("mpc_traekp.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + rep.knots);
}

#[test]
fn bad_horizon_is_an_error() {
    for (t_end, dt) in [(0.5, 0.0), (0.5, -0.01), (0.001, 0.01), (f64::NAN, 0.01)] {
        let opts = Options {
            t_end,
            dt,
            ..Options::default()
        };
        assert!(run(&opts, None).is_err(), "t_end {t_end}, dt {dt}");
    }
}
