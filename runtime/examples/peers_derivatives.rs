//! rbss's side of `bench/peers/run_derivatives.sh` (issue 36, "peers in the same run"): the
//! derivatives of forward dynamics and of one step on the generated 6-UPS, through the public
//! runtime API only, at the states the peers get, then timed.
//!
//! ```text
//! cargo build --release -p rbss-runtime --example peers_derivatives
//! peers_derivatives STATES_IN OUT TIMING_STATE_INDEX DT
//! ```
//!
//! `STATES_IN` is `bench/peers/build/states.txt` (`peers.py states`: the count, then per state
//! `t, X (24), Xdot (24), Xddot (24), U (6), lambda (18), M (576), f (18)`; only `t`, `X`,
//! `Xdot` and `U` are read). `OUT` gets `key value` lines:
//!
//! - `mat K NAME ROWS COLS v...` (row-major) at state `K`: `xddot`, `lambda` (forward dynamics
//!   under `U`), `dxddot_dx`, `dxddot_dxdot`, `dxddot_du` (24 × 6), `dlambda_dx`,
//!   `dlambda_dxdot`, `dlambda_du` ([`forward_dynamics_derivatives`]); `tangent`, `dxdot_dy`
//!   (24 × 6: the manifold's directions, [`linearize`] in the outputs); `rk4_F`, `euler_F`
//!   (48 × 54: `[F_x F_u]` of [`rk4_step_derivatives`] and
//!   [`semi_implicit_euler_step_derivatives`] with `DT`, no stabilisation) and `rk4_next`,
//!   `euler_next` (1 × 48: the state after the step);
//! - `time NAME NS`: the median time per call over batches of ~1 ms at state
//!   `TIMING_STATE_INDEX`, for `forward_dynamics`, `forward_dynamics_derivatives`,
//!   `linearize_outputs` (`linearize` + `state_space`: A 12 × 12, B 12 × 6),
//!   `rk4_step_derivatives` and `semi_implicit_euler_step_derivatives`.
//!
//! Errors (a malformed file, a solver failure) exit with status 1 and a message.

use std::hint::black_box;
use std::time::Instant;

use rbss_runtime::{
    Baumgarte, Coordinates, Data, ForwardDynamicsDerivatives, Linearization, Model,
    StepDerivatives, forward_dynamics, forward_dynamics_derivatives, linearize,
    rk4_step_derivatives, semi_implicit_euler_step_derivatives,
};
use stewart_6ups::{M, N, Stewart6Ups};

/// rbss's coordinate order the peers' harnesses assume (`bench/peers/stewart_pin.hpp`).
const NAMES: [&str; 24] = [
    "d1", "d2", "d3", "d4", "d5", "d6", "phi1", "phi2", "phi3", "phi4", "phi5", "phi6", "psi1",
    "psi2", "psi3", "psi4", "psi5", "psi6", "x", "y", "z", "rotx", "roty", "rotz",
];
const NA: usize = 6;

struct State {
    x: [f64; N],
    xdot: [f64; N],
    u: [f64; NA],
}

fn read_states(path: &str) -> Result<Vec<State>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?;
    let mut it = text.split_whitespace().map(|w| {
        w.parse::<f64>()
            .map_err(|e| format!("{path}: {w:?} is not a number ({e})"))
    });
    let mut next = || it.next().unwrap_or(Err(format!("{path} is truncated")));
    let n = next()?;
    if !(n >= 1.0 && n.fract() == 0.0) {
        return Err(format!("{path}: bad state count {n}"));
    }
    let per = 1 + 3 * N + NA + M + N * N + M;
    let mut out = Vec::new();
    for _ in 0..n as usize {
        let mut v = vec![0.0; per];
        for s in v.iter_mut() {
            *s = next()?;
        }
        let mut st = State {
            x: [0.0; N],
            xdot: [0.0; N],
            u: [0.0; NA],
        };
        st.x.copy_from_slice(&v[1..1 + N]);
        st.xdot.copy_from_slice(&v[1 + N..1 + 2 * N]);
        st.u.copy_from_slice(&v[1 + 3 * N..1 + 3 * N + NA]);
        out.push(st);
    }
    Ok(out)
}

fn mat(
    out: &mut String,
    k: usize,
    name: &str,
    rows: usize,
    cols: usize,
    f: impl Fn(usize, usize) -> f64,
) {
    use std::fmt::Write;
    let _ = write!(out, "mat {k} {name} {rows} {cols}");
    for i in 0..rows {
        for j in 0..cols {
            let _ = write!(out, " {:e}", f(i, j));
        }
    }
    out.push('\n');
}

/// Median time per call [ns] over `batches` batches of calls sized to ~1 ms.
fn time_ns(mut f: impl FnMut(), batches: usize) -> f64 {
    let t0 = Instant::now();
    let mut calls = 0usize;
    while t0.elapsed().as_secs_f64() < 0.05 {
        f();
        calls += 1;
    }
    let per = (t0.elapsed().as_secs_f64() / calls as f64).max(1e-9);
    let batch = ((1e-3 / per) as usize).max(1);
    let mut t: Vec<f64> = (0..batches)
        .map(|_| {
            let s = Instant::now();
            for _ in 0..batch {
                f();
            }
            s.elapsed().as_secs_f64() * 1e9 / batch as f64
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[batches / 2]
}

fn run(args: &[String]) -> Result<(), String> {
    let [states, out_path, ti, dt] = args else {
        return Err("usage: peers_derivatives STATES_IN OUT TIMING_STATE_INDEX DT".into());
    };
    let ti: usize = ti
        .parse()
        .map_err(|e| format!("TIMING_STATE_INDEX {ti:?}: {e}"))?;
    let dt: f64 = dt.parse().map_err(|e| format!("DT {dt:?}: {e}"))?;
    if !(dt > 0.0 && dt.is_finite()) {
        return Err(format!("DT must be positive, got {dt}"));
    }
    let st = read_states(states)?;
    if ti >= st.len() {
        return Err(format!(
            "timing state index {ti} out of range (0..{})",
            st.len()
        ));
    }
    let model = Model::new(Stewart6Ups::default());
    let s = model.structure();
    if s.coordinates != NAMES || s.actuated != [0, 1, 2, 3, 4, 5] {
        return Err(format!(
            "the generated 6-UPS's coordinates {:?} / actuated {:?} are not the order the peers assume",
            s.coordinates, s.actuated
        ));
    }
    let mut data = Data::new(&model);
    let mut fdd = ForwardDynamicsDerivatives::new();
    let mut lin = Linearization::new();
    let mut step = StepDerivatives::new();
    let mut out = String::new();
    let err = |what: &'static str, k: usize| move |e| format!("{what} at state {k}: {e}");
    for (k, x) in st.iter().enumerate() {
        data.x = x.x;
        data.xdot = x.xdot;
        forward_dynamics_derivatives(&model, &mut data, &mut fdd, &x.u, None)
            .map_err(err("forward_dynamics_derivatives", k))?;
        mat(&mut out, k, "xddot", 1, N, |_, j| data.xddot[j]);
        mat(&mut out, k, "lambda", 1, M, |_, j| data.lambda[j]);
        mat(&mut out, k, "dxddot_dx", N, N, |i, j| fdd.dxddot_dx[(i, j)]);
        mat(&mut out, k, "dxddot_dxdot", N, N, |i, j| {
            fdd.dxddot_dxdot[(i, j)]
        });
        mat(&mut out, k, "dxddot_du", N, NA, |i, j| {
            fdd.dxddot_du[(i, j)]
        });
        mat(&mut out, k, "dlambda_dx", M, N, |i, j| {
            fdd.dlambda_dx[(i, j)]
        });
        mat(&mut out, k, "dlambda_dxdot", M, N, |i, j| {
            fdd.dlambda_dxdot[(i, j)]
        });
        mat(&mut out, k, "dlambda_du", M, NA, |i, j| {
            fdd.dlambda_du[(i, j)]
        });
        data.x = x.x;
        data.xdot = x.xdot;
        linearize(
            &model,
            &mut data,
            &mut lin,
            &x.u,
            None,
            Coordinates::Outputs,
        )
        .map_err(err("linearize", k))?;
        mat(&mut out, k, "tangent", N, lin.d, |i, j| lin.tangent[(i, j)]);
        mat(&mut out, k, "dxdot_dy", N, lin.d, |i, j| {
            lin.dxdot_dy[(i, j)]
        });
        for (name, rk4) in [("rk4", true), ("euler", false)] {
            data.x = x.x;
            data.xdot = x.xdot;
            if rk4 {
                rk4_step_derivatives(&model, &mut data, &mut step, &x.u, dt, Baumgarte::NONE)
                    .map_err(err("rk4_step_derivatives", k))?;
            } else {
                semi_implicit_euler_step_derivatives(
                    &model,
                    &mut data,
                    &mut step,
                    &x.u,
                    dt,
                    Baumgarte::NONE,
                )
                .map_err(err("semi_implicit_euler_step_derivatives", k))?;
            }
            let n2 = 2 * N;
            mat(&mut out, k, &format!("{name}_F"), n2, n2 + NA, |i, j| {
                if j < n2 {
                    step.fx(i, j)
                } else {
                    step.fu(i, j - n2)
                }
            });
            mat(&mut out, k, &format!("{name}_next"), 1, n2, |_, j| {
                if j < N { step.x[j] } else { step.xdot[j - N] }
            });
        }
    }

    // Timing at state ti; each solver from the same start state.
    let x = &st[ti];
    let batches = 101;
    let reset = |d: &mut Data<N, M>| {
        d.x = x.x;
        d.xdot = x.xdot;
    };
    let mut times = Vec::new();
    reset(&mut data);
    times.push((
        "forward_dynamics",
        time_ns(
            || {
                let _ = black_box(forward_dynamics(
                    &model,
                    black_box(&mut data),
                    black_box(&x.u),
                    None,
                    Baumgarte::NONE,
                ));
            },
            batches,
        ),
    ));
    reset(&mut data);
    times.push((
        "forward_dynamics_derivatives",
        time_ns(
            || {
                let _ = black_box(forward_dynamics_derivatives(
                    &model,
                    black_box(&mut data),
                    black_box(&mut fdd),
                    black_box(&x.u),
                    None,
                ));
            },
            batches,
        ),
    ));
    reset(&mut data);
    let (mut a, mut b) = ([0.0; 144], [0.0; 72]);
    times.push((
        "linearize_outputs",
        time_ns(
            || {
                let _ = black_box(linearize(
                    &model,
                    black_box(&mut data),
                    black_box(&mut lin),
                    black_box(&x.u),
                    None,
                    Coordinates::Outputs,
                ));
                let _ = black_box(lin.state_space(&mut a, &mut b));
            },
            batches,
        ),
    ));
    times.push((
        "rk4_step_derivatives",
        time_ns(
            || {
                reset(&mut data);
                let _ = black_box(rk4_step_derivatives(
                    &model,
                    black_box(&mut data),
                    black_box(&mut step),
                    black_box(&x.u),
                    dt,
                    Baumgarte::NONE,
                ));
            },
            batches,
        ),
    ));
    times.push((
        "semi_implicit_euler_step_derivatives",
        time_ns(
            || {
                reset(&mut data);
                let _ = black_box(semi_implicit_euler_step_derivatives(
                    &model,
                    black_box(&mut data),
                    black_box(&mut step),
                    black_box(&x.u),
                    dt,
                    Baumgarte::NONE,
                ));
            },
            batches,
        ),
    ));
    out.push_str(&format!("timing_state {ti}\ndt {dt:e}\n"));
    for (name, ns) in times {
        out.push_str(&format!("time {name} {ns:.1}\n"));
    }
    std::fs::write(out_path, out).map_err(|e| format!("{out_path}: {e}"))
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if let Err(e) = run(&args) {
        eprintln!("peers_derivatives: {e}");
        std::process::exit(1);
    }
}
