//! Scenes that drive the paper's 6-UPS into a singularity along a one-parameter path, and what
//! every solver reports on the way (see `rbss stress singularity`).

use crate::robots::stewart_6ups::{M, N, Stewart6Ups};
use rbss_runtime::{
    Baumgarte, Data, Kernels, Model, SolverError, SolverOptions, forward_dynamics,
    forward_dynamics_schur, forward_kinematics, inverse_dynamics, inverse_kinematics, linalg,
};

use super::Robot;
use super::geometry::{Geometry, axis_angle, xyz_angles};

/// Which singularity a path approaches.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Parallel (type II): `J_p` and the reduced inverse-dynamics system lose rank.
    Parallel,
    /// Serial (type I): one leg's inverse-kinematics block loses rank.
    Serial,
}

/// A path `pose(s)`, `s` in `[0, 1]`, singular at `s = 1`.
#[derive(Debug, Clone, Copy)]
pub struct Path {
    pub name: &'static str,
    pub kind: Kind,
    start: [f64; 6],
    end: [f64; 6],
}

impl Path {
    /// Type II: Fichter's singularity. The platform at `x = y = 0`, `z = 0.94` turns about the
    /// vertical axis, `rotz = s pi/2`, `rotx = roty = 0`.
    pub fn parallel() -> Self {
        Path {
            name: "parallel",
            kind: Kind::Parallel,
            start: [0.0, 0.0, 0.94, 0.0, 0.0, 0.0],
            end: [0.0, 0.0, 0.94, 0.0, 0.0, std::f64::consts::FRAC_PI_2],
        }
    }

    /// Type I: leg 1 lies down along its base radius. The end pose tilts the platform by 40
    /// degrees about the horizontal axis perpendicular to the direction of `P_1` so that `P_1`
    /// comes down to the base plane, on the radius of `0_1`, 0.25 m inside it: there the leg
    /// axis `z_11 = Rz(alpha_1) (sin psi, -sin phi cos psi, cos phi cos psi)` is
    /// `-Rz(alpha_1) e_x`, i.e. `psi_1 = -pi/2`, the universal joint's two axes align and
    /// `d f_1 / d phi_1 = d_1 cos psi_1 (...) = 0`. The path is the straight line in pose
    /// space from the regular pose `(0, 0, 0.94, 0, 0, 0)`.
    pub fn serial() -> Self {
        Self::serial_with(60f64.to_radians(), 0.35, Some(0.2))
    }

    /// The serial path's construction with other numbers: tilt (rad), distance of `P_1` inside
    /// the base joint (m), and, if given, a start `lift` metres straight above the end pose
    /// instead of the regular pose `(0, 0, 0.94, 0, 0, 0)`.
    pub fn serial_with(tilt: f64, inward: f64, lift: Option<f64>) -> Self {
        let g = Geometry::default();
        let (sb, cb) = g.beta[0].sin_cos();
        let (sa, ca) = g.alpha[0].sin_cos();
        // Target of P_1: on the base radius of leg 1, `inward` inside the base joint, z = 0.
        let rad = g.r0 - inward;
        let target = [rad * ca, rad * sa, 0.0];
        // Tilt about k = e_z x (cos beta_1, sin beta_1, 0): P_1 (at h = 0) goes down by
        // rp sin(tilt) and in by rp (1 - cos(tilt)).
        let k = [-sb, cb, 0.0];
        let r = axis_angle(k, tilt);
        let p_local = g.platform_point(0);
        let p_rot = [
            r[0][0] * p_local[0] + r[0][1] * p_local[1] + r[0][2] * p_local[2],
            r[1][0] * p_local[0] + r[1][1] * p_local[1] + r[1][2] * p_local[2],
            r[2][0] * p_local[0] + r[2][1] * p_local[1] + r[2][2] * p_local[2],
        ];
        let [a, b, c] = xyz_angles(&r);
        let end = [
            target[0] - p_rot[0],
            target[1] - p_rot[1],
            target[2] - p_rot[2],
            a,
            b,
            c,
        ];
        let start = match lift {
            Some(l) => [end[0], end[1], end[2] + l, end[3], end[4], end[5]],
            None => [0.0, 0.0, 0.94, 0.0, 0.0, 0.0],
        };
        Path {
            name: "serial",
            kind: Kind::Serial,
            start,
            end,
        }
    }

    pub fn pose(&self, s: f64) -> [f64; 6] {
        std::array::from_fn(|i| self.start[i] + s * (self.end[i] - self.start[i]))
    }
}

/// The path parameters sampled: `0, 0.05, ..., 0.9`, then `1 - 10^-k` for `k = 1.25, 1.5, ...,
/// 10`, and the singular pose `s = 1` itself.
pub fn samples() -> Vec<f64> {
    let mut s: Vec<f64> = (0..18).map(|k| k as f64 * 0.05).collect();
    let mut k = 1.0;
    while k <= 10.0 + 1e-9 {
        s.push(1.0 - 10f64.powf(-k));
        k += 0.25;
    }
    s.push(1.0);
    s
}

/// What one solver returned: a value (see the field's documentation) or its typed error.
pub type Outcome = Result<f64, SolverError>;

/// Everything measured at one point of a path.
#[derive(Debug, Clone, Copy)]
pub struct Point {
    pub s: f64,
    /// `1 - s`.
    pub dist: f64,
    pub pose: [f64; 6],
    /// `X` of the pose in closed form, and its kernel residual `max |f|`.
    pub x: [f64; N],
    pub closed_form_residual: f64,
    /// Measured with the threshold off (`cond_max = inf`), at the closed-form `X`, all with the
    /// solvers' own 1-norm estimator: `J_p` (forward kinematics), the worst inverse-kinematics
    /// block (and its index), the reduced inverse-dynamics system `A` and its worst block,
    /// `S_c = G M⁻¹ Gᵀ` (forward dynamics).
    pub cond_jp: f64,
    pub cond_ik: f64,
    pub ik_block: usize,
    pub cond_id: f64,
    pub cond_fd: f64,
    /// The static holding forces (`Ẋ = Ẍ = 0`) with the threshold off: `max |U_i|` (N), `inf`
    /// if even that solve failed.
    pub u_max: f64,
    /// What a user sees (default `SolverOptions`, `cond_max = 1e7`):
    /// inverse kinematics warm-started from the previous point: its condition estimate;
    pub ik: Outcome,
    /// forward kinematics of the closed-form `q`, warm-started from the previous point: its
    /// condition estimate (`fk_error`: `max |X - X_closed_form|` of the result);
    pub fk: Outcome,
    pub fk_error: f64,
    /// inverse dynamics, static: `max |U_i|`;
    pub id: Outcome,
    /// forward dynamics under the threshold-off holding forces: `max |Ẍ|`, which is 0 for exact
    /// forces (how well those forces actually hold the robot).
    pub fd: Outcome,
}

fn probe_model() -> Robot {
    // Thresholds off: the condition numbers themselves, and the Schur complement's answer (for
    // its condition number) whatever its backward error.
    Model::new(Stewart6Ups::default()).with_options(SolverOptions {
        cond_max: f64::INFINITY,
        backward_error_max: f64::INFINITY,
        ..Default::default()
    })
}

/// 1-norm condition estimate of `G[rows, cols]` by the solvers' estimator (`inf` for an exact
/// zero pivot).
fn cond_of(g: &[[f64; M]; N], rows: &[usize], cols: &[usize]) -> f64 {
    let k = rows.len();
    let mut a = vec![0.0; k * k];
    for (c, &j) in cols.iter().enumerate() {
        for (r, &i) in rows.iter().enumerate() {
            a[r + c * k] = g[j][i];
        }
    }
    let Ok(norm) = linalg::norm1(&a, k) else {
        return f64::NAN;
    };
    let mut piv = vec![0; k];
    if linalg::lu_factor(&mut a, k, &mut piv).is_err() {
        return f64::INFINITY;
    }
    let mut work = vec![0.0; 2 * k];
    linalg::cond1_estimate(&a, k, &piv, norm, &mut work).unwrap_or(f64::INFINITY)
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m: f64, x| m.max(x.abs()))
}

/// Walks `path` through `samples`, measuring every [`Point`].
pub fn walk(path: &Path, samples: &[f64]) -> Vec<Point> {
    let geo = Geometry::default();
    // The condition numbers themselves, not forward kinematics' default bound.
    let model: Robot = Model::new(Stewart6Ups::default()).with_options(SolverOptions {
        exact_cond: true,
        ..SolverOptions::default()
    });
    let probe = probe_model();
    let k = model.kernels();
    let st = model.structure();
    let mut ik_data = Data::new(&model);
    ik_data.x = geo.x_of_pose(&path.pose(0.0));
    let mut fk_data = ik_data.clone();
    let mut out = Vec::with_capacity(samples.len());
    for &s in samples {
        let pose = path.pose(s);
        let x = geo.x_of_pose(&pose);
        let mut f = [0.0; M];
        k.constraints(&x, &mut f);
        let mut g = [[0.0; M]; N];
        k.jacobian(&x, &mut g);
        let cond_jp = cond_of(&g, &std::array::from_fn::<usize, M, _>(|i| i), st.passive);
        let (mut cond_ik, mut ik_block) = (0.0_f64, 0);
        for (b, blk) in st.ik_blocks.iter().enumerate() {
            let c = cond_of(&g, blk.rows, blk.cols);
            if c > cond_ik || c.is_nan() {
                cond_ik = c;
                ik_block = b;
            }
        }

        // Static holding forces, threshold off.
        let mut d = Data::new(&probe);
        d.x = x;
        d.xdot = [0.0; N];
        d.xddot = [0.0; N];
        let (cond_id, u_probe) = match inverse_dynamics(&probe, &mut d, None) {
            Ok(rep) => (rep.cond, Some(d.u)),
            Err(SolverError::Singular { cond, .. }) => (cond, None),
            Err(_) => (f64::NAN, None),
        };
        let u_max = u_probe.map_or(f64::INFINITY, |u| max_abs(&u[..6]));
        let u_apply = u_probe.unwrap_or([0.0; N]);
        // S_c itself (the Schur path): the default path may solve on the outputs instead.
        let cond_fd =
            match forward_dynamics_schur(&probe, &mut d, &u_apply[..6], None, Baumgarte::NONE) {
                Ok(rep) => rep.cond,
                Err(SolverError::Singular { cond, .. }) => cond,
                Err(_) => f64::NAN,
            };

        // What a user sees.
        let ik = inverse_kinematics(&model, &mut ik_data, &pose).map(|r| r.cond);
        let fk = forward_kinematics(&model, &mut fk_data, &x[..6]).map(|r| r.cond);
        let fk_error = if fk.is_ok() {
            max_abs(&std::array::from_fn::<f64, N, _>(|j| fk_data.x[j] - x[j]))
        } else {
            f64::NAN
        };
        let mut d = Data::new(&model);
        d.x = x;
        d.xdot = [0.0; N];
        d.xddot = [0.0; N];
        let id = inverse_dynamics(&model, &mut d, None).map(|_| max_abs(d.u()));
        let fd = forward_dynamics(&model, &mut d, &u_apply[..6], None, Baumgarte::NONE)
            .map(|_| max_abs(&d.xddot));
        out.push(Point {
            s,
            dist: 1.0 - s,
            pose,
            x,
            closed_form_residual: max_abs(&f),
            cond_jp,
            cond_ik,
            ik_block,
            cond_id,
            cond_fd,
            u_max,
            ik,
            fk,
            fk_error,
            id,
            fd,
        });
    }
    out
}

/// `1.23e4` or the error's short name with its estimate.
pub fn outcome_str(o: &Outcome) -> String {
    match o {
        Ok(v) => format!("{v:.2e}"),
        Err(SolverError::Singular { cond, .. }) => format!("Singular({cond:.1e})"),
        Err(SolverError::NotConverged { iterations, .. }) => format!("NotConverged({iterations})"),
        Err(SolverError::Unreachable { block, .. }) => format!("Unreachable({block})"),
        Err(SolverError::NonFinite { .. }) => "NonFinite".into(),
        Err(SolverError::NotPositiveDefinite { .. }) => "NotPosDef".into(),
        Err(SolverError::Dimension { .. }) => "Dimension".into(),
        Err(SolverError::SpuriousRoot { check, .. }) => format!("SpuriousRoot({check})"),
        Err(SolverError::ModeChange { part, .. }) => format!("ModeChange({part})"),
        Err(SolverError::PathStalled { t, .. }) => format!("PathStalled({t:.3})"),
        Err(SolverError::Underactuated { .. }) => "Underactuated".into(),
        Err(SolverError::Inaccurate { backward_error, .. }) => {
            format!("Inaccurate({backward_error:.1e})")
        }
        Err(SolverError::NoOutputs { .. }) => "NoOutputs".into(),
    }
}

/// `(code, value)` of an outcome for the CSV: code 0 = Ok (value = the result), 1 = Singular
/// (value = its condition estimate), 2 = NotConverged, 3 = NonFinite, 4 = another error (value
/// NaN).
pub fn outcome_code(o: &Outcome) -> (f64, f64) {
    match o {
        Ok(v) => (0.0, *v),
        Err(SolverError::Singular { cond, .. }) => (1.0, *cond),
        Err(SolverError::NotConverged { .. }) => (2.0, f64::NAN),
        Err(SolverError::NonFinite { .. }) => (3.0, f64::NAN),
        Err(_) => (4.0, f64::NAN),
    }
}

/// The CSV of one path: `s, dist, x..rotz, cond_*, u_max, closed_form_residual`, then
/// `ik_code, ik_value, fk_code, fk_value, fk_distance, id_code, id_value, fd_code, fd_value`
/// (codes: see [`outcome_code`]).
pub fn write_csv(
    files: &mut crate::output::Outputs,
    file: &std::path::Path,
    points: &[Point],
) -> Result<(), String> {
    let header: Vec<String> = [
        "s",
        "dist",
        "x",
        "y",
        "z",
        "rotx",
        "roty",
        "rotz",
        "cond_jp",
        "cond_ik",
        "ik_block",
        "cond_id",
        "cond_fd",
        "u_max",
        "closed_form_residual",
        "ik_code",
        "ik_value",
        "fk_code",
        "fk_value",
        "fk_distance",
        "id_code",
        "id_value",
        "fd_code",
        "fd_value",
    ]
    .iter()
    .map(|h| h.to_string())
    .collect();
    let rows: Vec<Vec<f64>> = points
        .iter()
        .map(|p| {
            let mut r = vec![p.s, p.dist];
            r.extend_from_slice(&p.pose);
            r.extend_from_slice(&[
                p.cond_jp,
                p.cond_ik,
                p.ik_block as f64,
                p.cond_id,
                p.cond_fd,
                p.u_max,
                p.closed_form_residual,
            ]);
            let (c, v) = outcome_code(&p.ik);
            r.extend_from_slice(&[c, v]);
            let (c, v) = outcome_code(&p.fk);
            r.extend_from_slice(&[c, v, p.fk_error]);
            let (c, v) = outcome_code(&p.id);
            r.extend_from_slice(&[c, v]);
            let (c, v) = outcome_code(&p.fd);
            r.extend_from_slice(&[c, v]);
            r
        })
        .collect();
    crate::csv::write_to(files, file, &header, &rows)
}

/// A Markdown table of a path; with `brief`, only the points at `1 - s` = 1, 0.1, 0.01, ...,
/// 1e-10 and 0.
pub fn table(path: &Path, points: &[Point], brief: bool) -> String {
    let mut out = format!(
        "path `{}` ({:?}), pose(s) = [x, y, z, rotx, roty, rotz]:\n  s = 0: {:.4?}\n  s = 1: {:.4?}\n\n",
        path.name,
        path.kind,
        path.pose(0.0),
        path.pose(1.0)
    );
    out.push_str("| 1 - s | cond J_p | cond IK (block) | cond ID (A) | cond S_c | max \\|U\\| [N] | IK | FK | ID: max \\|U\\| | FD: max \\|Ẍ\\| |\n");
    out.push_str("|---|---|---|---|---|---|---|---|---|---|\n");
    for p in points {
        let decade = p.dist == 0.0 || (p.dist.log10() - p.dist.log10().round()).abs() < 1e-9;
        if brief && !decade {
            continue;
        }
        let fk = match (&p.fk, p.fk_error > 1e-6) {
            (Ok(_), true) => format!("{} (other solution)", outcome_str(&p.fk)),
            _ => outcome_str(&p.fk),
        };
        out.push_str(&format!(
            "| {:.1e} | {:.2e} | {:.2e} ({}) | {:.2e} | {:.2e} | {:.3e} | {} | {} | {} | {} |\n",
            p.dist,
            p.cond_jp,
            p.cond_ik,
            p.ik_block + 1,
            p.cond_id,
            p.cond_fd,
            p.u_max,
            outcome_str(&p.ik),
            fk,
            outcome_str(&p.id),
            outcome_str(&p.fd),
        ));
    }
    out
}

/// The figure: per path, the condition estimates and `max |U|` against `1 - s` (log-log), with
/// `cond_max`.
pub fn plot(
    files: &mut crate::output::Outputs,
    file: &std::path::Path,
    runs: &[(Path, Vec<Point>)],
    cond_max: f64,
) -> Result<(), String> {
    use crate::plot::{Panel, Series, write_png_to};
    let mut panels = Vec::new();
    for (path, pts) in runs {
        let pts: Vec<&Point> = pts.iter().filter(|p| p.dist > 0.0).collect();
        let d: Vec<f64> = pts.iter().map(|p| p.dist).collect();
        let col = |f: &dyn Fn(&Point) -> f64| pts.iter().map(|p| f(p)).collect::<Vec<f64>>();
        let title = match path.kind {
            Kind::Parallel => "parallel (type II): platform turned about z towards 90°",
            Kind::Serial => "serial (type I): leg 1 laid down along its base radius (psi1 → -90°)",
        };
        panels.push(
            Panel::new(
                title,
                "distance to the singular pose 1 - s (path parameter)",
                "condition estimate, |U| [N]",
            )
            .log_x()
            .log_y()
            .with(Series::new(
                "cond J_p (forward kinematics)",
                d.clone(),
                col(&|p| p.cond_jp),
            ))
            .with(Series::new(
                "cond IK block (worst leg)",
                d.clone(),
                col(&|p| p.cond_ik),
            ))
            .with(Series::new(
                "cond A (inverse dynamics, reduced)",
                d.clone(),
                col(&|p| p.cond_id),
            ))
            .with(Series::new(
                "cond S_c (forward dynamics)",
                d.clone(),
                col(&|p| p.cond_fd),
            ))
            .with(Series::new(
                "max |U| static holding forces [N]",
                d.clone(),
                col(&|p| p.u_max),
            ))
            .with(Series::new(
                "cond_max (1e7)",
                d.clone(),
                vec![cond_max; d.len()],
            )),
        );
    }
    write_png_to(
        files,
        file,
        "rbss stress singularity: conditioning along the approach (singular at the left)",
        &panels,
        2,
        1800,
        750,
    )
}
