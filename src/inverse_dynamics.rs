//! `rbss inverse-dynamics --model NAME [--trajectory FILE]`: inverse kinematics and dynamics of
//! a robot along its outputs' trajectory (the paper's TraekP by default for `stewart_6ups`),
//! written as a CSV table of `U` and the multipliers.

use std::path::Path;

use rbss_runtime::{Dynamics, Model};

use crate::paper::{OMEGA, T_END, TraekP};
use crate::trajectory::{
    Trajectory, check_samples, force_table, inverse_dynamics_along, inverse_kinematics_along, load,
    output_names, sample_times,
};

/// What `rbss inverse-dynamics` was asked for.
#[derive(Debug, Clone, Default)]
pub struct InverseDynamicsRequest {
    /// Robot name.
    pub model: String,
    /// A trajectory file (`.csv` samples, `.toml` expressions); `None`: TraekP (stewart_6ups).
    pub trajectory: Option<String>,
    /// TraekP's `w`; `None`: [`OMEGA`].
    pub omega: Option<f64>,
    /// First time; `None`: the first sample of a samples file, else 0.
    pub t_start: Option<f64>,
    /// Last time; `None`: the last sample of a samples file, else [`T_END`].
    pub t_end: Option<f64>,
    /// Number of times (>= 2).
    pub samples: usize,
    /// Output CSV file: `t,U1..Uk,lambda1..lambdam`.
    pub csv: String,
}

/// `rbss inverse-dynamics`: inverse kinematics and dynamics of the named robot along the
/// requested trajectory, written to the CSV file. Returns a one-line report.
pub fn inverse_dynamics_command(req: &InverseDynamicsRequest) -> Result<String, String> {
    with_robot!(req.model.as_str(), |model| inverse_dynamics_for(
        &model, req
    ))
}

pub fn inverse_dynamics_for<K: Dynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    req: &InverseDynamicsRequest,
) -> Result<String, String> {
    let s = model.structure();
    let names = output_names(s);
    let trajectory: Box<dyn Trajectory> = match (&req.trajectory, req.omega) {
        (Some(_), Some(_)) => {
            return Err(
                "--omega sets TraekP's frequency; it does not apply with --trajectory".into(),
            );
        }
        (Some(file), None) => load(Path::new(file), &names)?,
        (None, omega) if s.name == "stewart_6ups" => {
            let omega = omega.unwrap_or(OMEGA);
            if !omega.is_finite() {
                return Err(format!("--omega {omega}: not a finite number"));
            }
            Box::new(TraekP { omega })
        }
        (None, _) => {
            return Err(format!(
                "`{}` has no built-in trajectory (TraekP is the paper's, for stewart_6ups): give \
                 the motion of its outputs ({}) with --trajectory FILE, a .csv file of samples \
                 `t,{}` or a .toml file of expressions in t (examples in models/trajectories/)",
                s.name,
                names.join(", "),
                names.join(",")
            ));
        }
    };
    check_samples(req.samples)?;
    let (d0, d1) = trajectory.domain();
    let t0 = req.t_start.unwrap_or(if d0.is_finite() { d0 } else { 0.0 });
    let t1 = req.t_end.unwrap_or(if d1.is_finite() { d1 } else { T_END });
    if req.samples < 2 || !(t0.is_finite() && t1.is_finite() && t1 > t0) {
        return Err(format!(
            "need --samples >= 2 and finite times with --t-end > --t-start (got {} samples over \
             [{t0}, {t1}])",
            req.samples
        ));
    }
    if t0 < d0 || t1 > d1 {
        return Err(format!(
            "[{t0}, {t1}] is outside the {}, which cover [{d0}, {d1}]: choose --t-start and \
             --t-end within it",
            trajectory.describe()
        ));
    }
    let times = sample_times(t0, t1, req.samples);
    let (kin, ik_residual) = inverse_kinematics_along(model, trajectory.as_ref(), &times)?;
    let forces = inverse_dynamics_along(model, &kin)?;
    let (header, rows) = force_table(&forces);
    crate::csv::write(Path::new(&req.csv), &header, &rows)?;
    let worst = forces.iter().map(|f| f.cond).fold(0.0, f64::max);
    Ok(format!(
        "wrote {}: {} samples over [{t0}, {t1}] s of U1..U{} and lambda1..lambda{} of `{}` along \
         {} (max IK residual {ik_residual:.1e}, worst condition estimate {worst:.3e})",
        req.csv,
        req.samples,
        N - M,
        M,
        s.name,
        trajectory.describe()
    ))
}
