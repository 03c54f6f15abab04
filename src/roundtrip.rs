//! `rbss roundtrip --model NAME [--trajectory FILE]`: the paper's round trip for any robot.
//!
//! Inverse kinematics of the outputs' trajectory at its first time gives the start state; forward
//! dynamics from there under the control forces `U(t)` computed at every integrator stage time
//! by inverse kinematics, velocity, acceleration and inverse dynamics of the trajectory at that
//! very time; then the simulated outputs against the trajectory at every accepted step. A
//! robot's default trajectory is `models/trajectories/NAME.toml` (expressions in `t`).

use std::path::{Path, PathBuf};

use rbss_runtime::{Data, Dynamics, IntegrateOptions, Model, Simulator};

use crate::plot::{Panel, Series, write_png_to};
use crate::trajectory::{Trajectory, control, inverse_kinematics_along, load, output_names};

/// What `rbss roundtrip` was asked for.
#[derive(Debug, Clone)]
pub struct RoundTripRequest {
    pub model: String,
    /// `None`: `models/trajectories/NAME.toml`, in the current directory or else in the
    /// project the command was built from.
    pub trajectory: Option<String>,
    /// `None`: the trajectory's last sample, else 2 s.
    pub t_end: Option<f64>,
    pub integrate: IntegrateOptions,
    /// Directory for `roundtrip.csv` and `roundtrip.png`.
    pub out: String,
}

/// What the round trip measured.
#[derive(Debug, Clone, Default)]
pub struct RoundTripSummary {
    /// `max |simulated output - trajectory|` over the outputs and every accepted step.
    pub max_output_error: f64,
    pub steps: usize,
    pub max_violation: f64,
    pub seconds: f64,
    pub report: String,
}

/// Runs the round trip of the named robot (see the module documentation).
pub fn roundtrip_command(req: &RoundTripRequest) -> Result<RoundTripSummary, String> {
    with_robot!(req.model.as_str(), |model| roundtrip(&model, req))
}

/// A robot's default trajectory: `models/trajectories/NAME.toml`, in the current directory
/// (a user's edit) or else in the project the command was built from; an error naming both
/// and the outputs to give when neither exists.
pub fn default_trajectory(s: &rbss_runtime::Structure) -> Result<PathBuf, String> {
    let file = format!("{}.toml", s.name);
    let local = Path::new("models/trajectories").join(&file);
    let built_in = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("models/trajectories")
        .join(&file);
    match [&local, &built_in].into_iter().find(|f| f.exists()) {
        Some(f) => Ok(f.clone()),
        None => Err(format!(
            "`{}` has no default trajectory (neither {} nor {} exists): give the motion of its \
             outputs ({}) with --trajectory FILE (examples in models/trajectories/)",
            s.name,
            local.display(),
            built_in.display(),
            output_names(s).join(", ")
        )),
    }
}

/// The start and end times of a round trip along `trajectory`: its first sample (else 0) and
/// `t_end`, else its last sample (else [`crate::paper::T_END`]); an error unless the end is
/// finite, after the start and within the trajectory.
pub fn time_span(trajectory: &dyn Trajectory, t_end: Option<f64>) -> Result<(f64, f64), String> {
    let (d0, d1) = trajectory.domain();
    let t0 = if d0.is_finite() { d0 } else { 0.0 };
    let t1 = t_end.unwrap_or(if d1.is_finite() {
        d1
    } else {
        crate::paper::T_END
    });
    if !(t1.is_finite() && t1 > t0 && t1 <= d1) {
        return Err(format!(
            "--t-end {t1}: must be finite, after the start {t0} and within the {} (to {d1})",
            trajectory.describe()
        ));
    }
    Ok((t0, t1))
}

/// The round trip of one robot.
pub fn roundtrip<K: Dynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    req: &RoundTripRequest,
) -> Result<RoundTripSummary, String> {
    let started = std::time::Instant::now();
    let s = model.structure();
    s.require_outputs("the round trip (a trajectory of the outputs)")
        .map_err(|e| e.to_string())?;
    let names = output_names(s);
    let file = match &req.trajectory {
        Some(f) => PathBuf::from(f),
        None => default_trajectory(s)?,
    };
    let trajectory = load(&file, &names)?;
    let (t0, t1) = time_span(trajectory.as_ref(), req.t_end)?;

    // Start: the trajectory's state at t0.
    let (kin, _) = inverse_kinematics_along(model, trajectory.as_ref(), &[t0])?;
    let (x0, xdot0) = (kin[0].x, kin[0].xdot);

    // Forward dynamics under U(t), every accepted state recorded.
    let mut control = control(model, trajectory.as_ref(), &x0);
    let mut data = Data::new(model);
    let mut sim = Simulator::new(model, &mut data, t0, &x0, &xdot0, req.integrate)
        .map_err(|e| format!("forward dynamics: cannot start: {e}"))?;
    let mut states: Vec<(f64, [f64; N])> = vec![(t0, x0)];
    let stats = sim
        .run(model, &mut data, t1, &mut control, |s| {
            states.push((s.t(), *s.x()));
        })
        .map_err(|e| format!("forward dynamics: {e}"))?;

    // The simulated outputs against the trajectory.
    let k = names.len();
    let (mut p, mut v, mut a) = (vec![0.0; k], vec![0.0; k], vec![0.0; k]);
    let mut worst = 0.0_f64;
    let mut rows = Vec::with_capacity(states.len());
    for (t, x) in &states {
        trajectory.eval(*t, &mut p, &mut v, &mut a);
        let mut row = vec![*t];
        for (i, &o) in s.outputs.iter().enumerate() {
            let e = x[o] - p[i];
            worst = worst.max(e.abs());
            row.extend_from_slice(&[p[i], x[o], e]);
        }
        rows.push(row);
    }

    let out = Path::new(&req.out);
    crate::create_output_dir(out)?;
    let mut header = vec!["t".to_string()];
    for n in &names {
        header.extend([format!("{n}_ref"), format!("{n}_sim"), format!("{n}_error")]);
    }
    // The CSV and the figure together, or neither (the old pair stays).
    let mut files = crate::output::Outputs::new();
    crate::csv::write_to(&mut files, &out.join("roundtrip.csv"), &header, &rows)?;
    let t: Vec<f64> = rows.iter().map(|r| r[0]).collect();
    let mut motion = Panel::new("simulated outputs (trajectory dashed)", "t [s]", "output");
    let mut error = Panel::new(
        "|simulated - trajectory| per output",
        "t [s]",
        "error (m or rad)",
    )
    .log_y();
    for (i, n) in names.iter().enumerate() {
        let col = |c: usize| rows.iter().map(|r| r[1 + 3 * i + c]).collect::<Vec<f64>>();
        motion = motion
            .with(Series::new(n.to_string(), t.clone(), col(1)))
            .with(Series::new(format!("{n} (trajectory)"), t.clone(), col(0)).reference());
        let e: Vec<f64> = col(2).iter().map(|e| e.abs().max(1e-17)).collect();
        error = error.with(Series::new(n.to_string(), t.clone(), e));
    }
    write_png_to(
        &mut files,
        &out.join("roundtrip.png"),
        &format!(
            "{}: inverse kinematics and dynamics along {}, then forward dynamics under U(t)",
            s.name,
            file.display()
        ),
        &[motion, error],
        2,
        1600,
        600,
    )?;
    files.commit()?;
    let seconds = started.elapsed().as_secs_f64();
    Ok(RoundTripSummary {
        max_output_error: worst,
        steps: stats.steps,
        max_violation: stats.max_violation,
        seconds,
        report: format!(
            "{}: {} steps over [{t0}, {t1}] s along {} ({:?}, {:?}), max constraint violation \
             {:.1e}; wrote {}/roundtrip.csv and roundtrip.png ({seconds:.2} s)",
            s.name,
            stats.steps,
            file.display(),
            req.integrate.method,
            req.integrate.stabilization,
            stats.max_violation,
            out.display()
        ),
    })
}
