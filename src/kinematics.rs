//! `rbss ik` and `rbss fk`: one pose from the command line, as text or as JSON with full
//! precision, with the assembly mode of forward kinematics and the leg that cannot reach an
//! unreachable pose.

use rbss_runtime::{
    Data, FkRobustError, Kernels, LmOptions, Model, SolverError, Structure, forward_kinematics,
    forward_kinematics_lm, inverse_kinematics, inverse_velocity,
};
use serde::Serialize;

/// Parses a comma-separated list of `len` finite numbers given as `--what`.
pub fn parse_list(what: &str, s: &str, len: usize) -> Result<Vec<f64>, String> {
    let tokens: Vec<&str> = s.split(',').map(str::trim).collect();
    let vals: Result<Vec<f64>, _> = tokens.iter().map(|t| t.parse::<f64>()).collect();
    let vals = vals
        .map_err(|e| format!("--{what}: `{s}` is not a comma-separated list of numbers ({e})"))?;
    if vals.len() != len {
        return Err(format!(
            "--{what}: expected {len} values, got {}",
            vals.len()
        ));
    }
    // Quote what the user wrote (`1e999`), not what it parsed to (`inf`).
    if let Some(i) = vals.iter().position(|v| !v.is_finite()) {
        return Err(format!(
            "--{what}: `{}` (value {}) is not a finite number",
            tokens[i],
            i + 1
        ));
    }
    Ok(vals)
}

/// The constraints of IK block `b` and, when they share one, the leg's name (the part before
/// the first `.` of every constraint name, e.g. `leg3` of `leg3.x, leg3.y, leg3.z`).
pub fn block_description(s: &Structure, b: usize) -> String {
    let Some(blk) = s.ik_blocks.get(b) else {
        return format!("IK block {b}");
    };
    let names: Vec<&str> = blk.rows.iter().map(|&r| s.constraints[r]).collect();
    let coords: Vec<&str> = blk.cols.iter().map(|&j| s.coordinates[j]).collect();
    let leg = names
        .first()
        .and_then(|n| n.split_once('.'))
        .map(|(p, _)| p)
        .filter(|p| {
            names
                .iter()
                .all(|n| n.split_once('.').map(|(q, _)| q) == Some(*p))
        });
    let what = match leg {
        Some(leg) => format!("leg `{leg}` (IK block {b}"),
        None => format!("IK block {b} ("),
    };
    let sep = if leg.is_some() { ": " } else { "" };
    format!(
        "{what}{sep}constraints {}; coordinates {})",
        names.join(", "),
        coords.join(", ")
    )
}

/// An inverse-kinematics error in the user's terms: an unreachable pose names the leg that
/// cannot close; a singular block names its constraints.
pub fn explain_ik_error(s: &Structure, e: &SolverError) -> String {
    match *e {
        SolverError::Unreachable { block, residual } => format!(
            "the pose is out of reach: {} cannot close; the nearest it gets leaves max |f| = \
             {residual:.4e} (in the constraints' units, m for a position loop)",
            block_description(s, block)
        ),
        SolverError::Singular {
            cond,
            what,
            block: Some(b),
        } => format!(
            "singular {what} at {}: estimated condition number {cond:e} (the leg is at a \
             singular posture, e.g. fully stretched: the pose is on the boundary of its reach)",
            block_description(s, b)
        ),
        ref other => other.to_string(),
    }
}

/// Coordinates by name, in model order.
#[derive(Serialize)]
struct Named {
    name: &'static str,
    value: f64,
    role: &'static str,
}

fn role(s: &Structure, j: usize) -> &'static str {
    if s.actuated.contains(&j) {
        "actuated"
    } else if s.outputs.contains(&j) {
        "output"
    } else {
        "passive"
    }
}

fn named(s: &Structure, x: &[f64]) -> Vec<Named> {
    s.coordinates
        .iter()
        .enumerate()
        .map(|(j, &name)| Named {
            name,
            value: x[j],
            role: role(s, j),
        })
        .collect()
}

/// What `rbss ik --json` prints (f64 values round-trip exactly: shortest representation).
#[derive(Serialize)]
struct IkJson {
    model: &'static str,
    problem: &'static str,
    iterations: usize,
    residual: f64,
    cond: f64,
    /// Every coordinate: `X` in model order, with names and roles.
    coordinates: Vec<Named>,
    /// `X` in model order.
    x: Vec<f64>,
    /// The actuated coordinates `q` (model `actuated` order).
    q: Vec<f64>,
    /// With `--rates`: `Xdot` and `qdot`.
    #[serde(skip_serializing_if = "Option::is_none")]
    xdot: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    qdot: Option<Vec<f64>>,
}

fn print_x(s: &Structure, x: &[f64], label: &str) -> String {
    let mut out = String::new();
    for (j, name) in s.coordinates.iter().enumerate() {
        let tag = match role(s, j) {
            "passive" => String::new(),
            r => format!("  ({r})"),
        };
        out.push_str(&format!("  {label}{name:<8} = {:>18.12}{tag}\n", x[j]));
    }
    out
}

/// `rbss ik`: every coordinate from the outputs `pose` (and, with `rates`, every rate from the
/// output rates), as text or JSON.
pub fn ik<K: Kernels<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    pose: &str,
    rates: Option<&str>,
    json: bool,
) -> Result<String, String> {
    let s = model.structure();
    let pose = parse_list("pose", pose, s.outputs.len())?;
    let rates = rates
        .map(|r| parse_list("rates", r, s.outputs.len()))
        .transpose()?;
    let mut data = Data::new(model);
    let rep = inverse_kinematics(model, &mut data, &pose)
        .map_err(|e| format!("inverse kinematics failed: {}", explain_ik_error(s, &e)))?;
    if let Some(r) = &rates {
        inverse_velocity(model, &mut data, r)
            .map_err(|e| format!("inverse velocity failed: {}", explain_ik_error(s, &e)))?;
    }
    let q = |x: &[f64]| s.actuated.iter().map(|&j| x[j]).collect::<Vec<f64>>();
    if json {
        let out = IkJson {
            model: s.name,
            problem: "inverse_kinematics",
            iterations: rep.iterations,
            residual: rep.residual,
            cond: rep.cond,
            coordinates: named(s, &data.x),
            x: data.x.to_vec(),
            q: q(&data.x),
            xdot: rates.as_ref().map(|_| data.xdot.to_vec()),
            qdot: rates.as_ref().map(|_| q(&data.xdot)),
        };
        return serde_json::to_string_pretty(&out).map_err(|e| format!("cannot write JSON: {e}"));
    }
    let mut out = format!(
        "{}: inverse kinematics converged in {} Newton steps (max |f| = {:.1e}, worst block cond = {:.3e})\n",
        s.name, rep.iterations, rep.residual, rep.cond
    );
    out.push_str(&print_x(s, &data.x, ""));
    if rates.is_some() {
        out.push_str("inverse velocity (d/dt):\n");
        out.push_str(&print_x(s, &data.xdot, "d"));
    }
    Ok(out)
}

/// The sign of `det J_p` at `x` (`0` if `J_p` is exactly singular or not finite). `J_p`
/// changes sign only through a singularity of forward kinematics, so a solution whose sign
/// differs from the start's is in another assembly mode than the start (the same sign does
/// not prove the same mode).
pub fn det_jp_sign<K: Kernels<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    x: &[f64; N],
) -> i8 {
    let s = model.structure();
    let mut g = [[0.0; M]; N];
    model.kernels().jacobian_p(x, &mut g);
    let mut a: Vec<f64> = s.passive.iter().flat_map(|&j| g[j]).collect();
    let mut piv = vec![0; M];
    if rbss_runtime::linalg::lu_factor(&mut a, M, &mut piv).is_err() {
        return 0;
    }
    let mut neg = false;
    for (j, &p) in piv.iter().enumerate() {
        neg ^= p != j;
        neg ^= a[j * M + j] < 0.0;
    }
    if neg { -1 } else { 1 }
}

/// The assembly of a forward-kinematics solution against its start.
#[derive(Serialize)]
struct Assembly {
    /// Sign of `det J_p` at the solution and at the start (see [`det_jp_sign`]).
    det_jp_sign: i8,
    start_det_jp_sign: i8,
    /// `max |p_j - p_j,start|` over the passive coordinates, and the coordinate.
    max_passive_change: f64,
    max_change_coordinate: &'static str,
}

/// What `rbss fk --json` prints.
#[derive(Serialize)]
struct FkJson {
    model: &'static str,
    problem: &'static str,
    method: &'static str,
    iterations: usize,
    residual: f64,
    cond: f64,
    assembly: Assembly,
    coordinates: Vec<Named>,
    x: Vec<f64>,
    /// The output coordinates (model `outputs` order).
    outputs: Vec<f64>,
}

/// `rbss fk`: every coordinate from the actuated ones `q`, Newton from the home assembly or
/// from the inverse kinematics of `near`; with `max_passive_change`, Levenberg–Marquardt with
/// that mode policy (a solution farther from the start is refused). Reports the assembly.
pub fn fk<K: Kernels<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    q: &str,
    near: Option<&str>,
    max_passive_change: Option<f64>,
    json: bool,
) -> Result<String, String> {
    let s = model.structure();
    let q = parse_list("q", q, s.actuated.len())?;
    let mut data = Data::new(model);
    if let Some(near) = near {
        let pose = parse_list("near", near, s.outputs.len())?;
        inverse_kinematics(model, &mut data, &pose).map_err(|e| {
            format!(
                "--near: inverse kinematics failed: {}",
                explain_ik_error(s, &e)
            )
        })?;
    }
    let mut start = data.x;
    for (&j, &v) in s.actuated.iter().zip(&q) {
        start[j] = v;
    }
    let (method, iterations, residual, cond) = match max_passive_change {
        None => {
            let rep = forward_kinematics(model, &mut data, &q)
                .map_err(|e| format!("forward kinematics failed: {e}"))?;
            ("newton", rep.iterations, rep.residual, rep.cond)
        }
        Some(limit) => {
            if limit.is_nan() || limit <= 0.0 {
                return Err(format!(
                    "--max-passive-change {limit}: expected a positive number (m or rad)"
                ));
            }
            let opts = LmOptions {
                max_passive_change: limit,
                ..LmOptions::default()
            };
            let rep = forward_kinematics_lm(model, &mut data, &q, &opts).map_err(|e| match e {
                FkRobustError::ModeChange {
                    max_change,
                    coordinate,
                    residual,
                } => format!(
                    "forward kinematics found a solution (max |f| = {residual:.1e}) in another \
                     assembly mode than the start: `{}` moved {max_change:.6} from the start \
                     (--max-passive-change {limit}); start nearer the wanted assembly with --near \
                     POSE",
                    s.coordinates[coordinate]
                ),
                FkRobustError::Solver(e) => format!("forward kinematics failed: {e}"),
            })?;
            (
                "levenberg-marquardt",
                rep.iterations,
                rep.residual,
                rep.cond,
            )
        }
    };
    let (mut change, mut moved) = (0.0_f64, s.passive.first().copied().unwrap_or(0));
    for &j in s.passive {
        let d = (data.x[j] - start[j]).abs();
        if d > change {
            change = d;
            moved = j;
        }
    }
    let assembly = Assembly {
        det_jp_sign: det_jp_sign(model, &data.x),
        start_det_jp_sign: det_jp_sign(model, &start),
        max_passive_change: change,
        max_change_coordinate: s.coordinates[moved],
    };
    if json {
        let out = FkJson {
            model: s.name,
            problem: "forward_kinematics",
            method,
            iterations,
            residual,
            cond,
            assembly,
            coordinates: named(s, &data.x),
            x: data.x.to_vec(),
            outputs: s.outputs.iter().map(|&j| data.x[j]).collect(),
        };
        return serde_json::to_string_pretty(&out).map_err(|e| format!("cannot write JSON: {e}"));
    }
    let mut out = format!(
        "{}: forward kinematics ({method}) converged in {iterations} steps (max |f| = {residual:.1e}, cond(J_p) = {cond:.3e})\n",
        s.name
    );
    let same = if assembly.det_jp_sign == assembly.start_det_jp_sign {
        "same sign as at the start"
    } else {
        "differs from the start: another assembly mode"
    };
    out.push_str(&format!(
        "assembly: sign det(J_p) = {:+} ({same}); largest passive change from the start: `{}` by {:.6}\n",
        assembly.det_jp_sign, assembly.max_change_coordinate, assembly.max_passive_change
    ));
    out.push_str(&print_x(s, &data.x, ""));
    Ok(out)
}

/// `rbss ik --model NAME`: [`ik`] on the robot of that name. The dispatch over the registered
/// robots is here, in the library, so that the command's binary instantiates no solver: each
/// is compiled once, with the library's own uses of it (issue 11, the default build).
pub fn ik_named(
    model: &str,
    pose: &str,
    rates: Option<&str>,
    json: bool,
) -> Result<String, String> {
    with_robot!(model, |m| ik(&m, pose, rates, json))
}

/// `rbss fk --model NAME`: [`fk`] on the robot of that name (dispatched here, as [`ik_named`]).
pub fn fk_named(
    model: &str,
    q: &str,
    near: Option<&str>,
    max_passive_change: Option<f64>,
    json: bool,
) -> Result<String, String> {
    with_robot!(model, |m| fk(&m, q, near, max_passive_change, json))
}
