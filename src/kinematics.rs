//! `rbss ik` and `rbss fk`: one pose from the command line, as text or as JSON with full
//! precision, with the assembly mode of forward kinematics and the leg that cannot reach an
//! unreachable pose.

use rbss_runtime::{
    Data, FkRobustError, Kernels, LmOptions, ModePart, ModeSignature, Model, Parts, PathOptions,
    SolverError, Structure, certify_position, forward_kinematics, forward_kinematics_lm,
    forward_kinematics_path, inverse_kinematics, inverse_kinematics_path, inverse_velocity,
    mode_signature,
};
use serde::Serialize;

/// Parses a comma-separated list of `len` finite numbers given as `--what`; a blank string is
/// the empty list (a robot without actuated coordinates has `--q ""`).
pub fn parse_list(what: &str, s: &str, len: usize) -> Result<Vec<f64>, String> {
    let tokens: Vec<&str> = match s.trim().is_empty() {
        true => Vec::new(),
        false => s.split(',').map(str::trim).collect(),
    };
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
    method: &'static str,
    iterations: usize,
    residual: f64,
    cond: f64,
    mode: Mode,
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

/// How `rbss ik` and `rbss fk` solve: by continuation from the start (the default) or by one
/// Newton solve from it, and whether a change of assembly mode is accepted.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Solve {
    /// One Newton solve from the start (`--direct`) instead of continuation.
    pub direct: bool,
    /// Accept another assembly mode than the start's (`--allow-mode-change`).
    pub allow_mode_change: bool,
    /// Forward kinematics only: Levenberg–Marquardt with this mode policy
    /// (`--max-passive-change`).
    pub max_passive_change: Option<f64>,
    /// The mode the answer must be in (`--mode`), else an error.
    pub mode: Option<NamedMode>,
}

/// A mode the user names (`--mode`), in the signature's text form: one sign per IK block, `/`,
/// the sign of `det J_p`; `+` or `-` each, `?` for either (`--mode "+?-/+"`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NamedMode {
    /// The blocks' signs (`0` for `?`), the first `count` entries.
    blocks: [i8; 64],
    count: usize,
    jp: i8,
}

/// Parses `--mode` (see [`NamedMode`]).
pub fn parse_mode(s: &str) -> Result<NamedMode, String> {
    let sign = |c: char| match c {
        '+' => Ok(1),
        '-' => Ok(-1),
        '?' => Ok(0),
        _ => Err(format!(
            "`{c}` is not a sign: write `+`, `-` or `?` per IK block, `/`, then the sign of det J_p \
             (e.g. `+-?/+`, as `rbss fk` prints the mode)"
        )),
    };
    let Some((blocks, jp)) = s.trim().split_once('/') else {
        return Err(format!(
            "`{s}`: expected the IK blocks' signs, `/`, then the sign of det J_p (e.g. `+-?/+`, as \
             `rbss fk` prints the mode)"
        ));
    };
    let mut mode = NamedMode {
        blocks: [0; 64],
        count: 0,
        jp: 0,
    };
    for c in blocks.chars() {
        if mode.count == mode.blocks.len() {
            return Err(format!("`{s}`: more than 64 IK blocks"));
        }
        mode.blocks[mode.count] = sign(c)?;
        mode.count += 1;
    }
    let mut jp = jp.chars();
    mode.jp = match (jp.next(), jp.next()) {
        (Some(c), None) => sign(c)?,
        _ => return Err(format!("`{s}`: one sign after `/` (det J_p)")),
    };
    Ok(mode)
}

impl NamedMode {
    /// The first part where `sig` is not this mode: `(part, named sign, found sign)`.
    fn mismatch<const M: usize>(&self, sig: &ModeSignature<M>) -> Option<(ModePart, i8, i8)> {
        let differs = |want: i8, got: i8| want != 0 && got != want;
        for (b, (&w, &g)) in self.blocks[..self.count]
            .iter()
            .zip(sig.blocks())
            .enumerate()
        {
            if differs(w, g) {
                return Some((ModePart::Block(b), w, g));
            }
        }
        differs(self.jp, sig.jp()).then_some((ModePart::Jp, self.jp, sig.jp()))
    }

    fn text(&self) -> String {
        let c = |s: i8| match s {
            1 => '+',
            -1 => '-',
            _ => '?',
        };
        let mut t: String = self.blocks[..self.count].iter().map(|&s| c(s)).collect();
        t.push('/');
        t.push(c(self.jp));
        t
    }
}

/// Where a position solve of the command starts, for the advice of its errors: `rbss fk` moves
/// its start with `--near POSE`; `rbss ik` (and the inverse kinematics of `fk --near`) always
/// starts from the home assembly, so its advice names the options it has and the library's
/// start (`rbss_ik`'s `x_start`, Python's `robot.ik(pose, x_start=...)`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Start {
    /// The start can be moved with `--near POSE` (`rbss fk`).
    Near,
    /// The start is the home assembly (`rbss ik`).
    Home,
}

/// Where an inverse kinematics can start elsewhere than the home assembly: the library.
const LIBRARY_START: &str =
    "the library's `rbss_ik` (its `x_start`) or Python's `robot.ik(pose, x_start=...)`";

/// A solver error in the user's terms: an unreachable pose names the leg that cannot close; a
/// singular or mode-changing block names its constraints; a spurious root names the loop
/// component; a stalled continuation says what to try, with the options the command has
/// (`start`).
pub fn explain<K: Kernels<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    e: &SolverError,
    start: Start,
) -> String {
    let s = model.structure();
    let nearer = match start {
        Start::Near => "start nearer (--near POSE)".to_string(),
        Start::Home => {
            format!(
                "start nearer through {LIBRARY_START} (the command's inverse kinematics starts \
                 from the home assembly)"
            )
        }
    };
    match *e {
        SolverError::SpuriousRoot { check, residual } => format!(
            "converged to a spurious root: loop component `{}` (left out of the equations solved) \
             is {residual:.3e} from closing, so the solution closes the loops' solved components \
             but is a mirror of the configuration asked for; use the default continuation \
             (without --direct), or {nearer}",
            model
                .kernels()
                .closure_checks()
                .get(check)
                .copied()
                .unwrap_or("?")
        ),
        SolverError::ModeChange {
            part,
            start,
            found,
            t,
        } => {
            let what = match part {
                ModePart::Block(b) => block_description(s, b),
                ModePart::Jp => "J_p (the assembly mode of forward kinematics)".to_string(),
            };
            let place = if t < 1.0 {
                format!(
                    "the straight path from the start crosses a singularity at {t:.4} of the way"
                )
            } else {
                "the solution is in another assembly mode than the start".to_string()
            };
            format!(
                "{place}: the sign of det of {what} changed from {start:+} to {found:+}; pass \
                 --allow-mode-change to accept another mode, or, in the wanted mode, {nearer}"
            )
        }
        SolverError::PathStalled { t, residual } => format!(
            "did not converge from this start: the continuation stalled at {t:.4} of the way \
             (max |f| = {residual:.1e}), where a singularity or the limit of the reach lies on the \
             straight path from the start; try --direct (one Newton solve, not along the path), \
             or {nearer}"
        ),
        SolverError::NotConverged { .. } => format!(
            "did not converge from this start ({e}); drop --direct to walk there by \
             continuation, or {nearer}"
        ),
        _ => explain_ik_error(s, e),
    }
}

/// The assembly mode of a solution against its start, as JSON carries it.
#[derive(Serialize)]
struct Mode {
    /// `++-+/+`: the signs of det of each IK block's `G_r`, then of `J_p`.
    start_signature: String,
    signature: String,
    /// Each IK block's sign, at the start and at the solution.
    start_blocks: Vec<i8>,
    blocks: Vec<i8>,
    /// The sign of det `J_p`, at the start and at the solution.
    start_jp: i8,
    jp: i8,
    /// Whether a change was accepted (--allow-mode-change).
    changed: bool,
    /// The largest unsolved loop component at the solution (the certificate; 0 when every loop
    /// states all its components).
    closure_check: f64,
}

fn mode<const M: usize>(
    start: &ModeSignature<M>,
    sol: &ModeSignature<M>,
    parts: Parts,
    closure_check: f64,
) -> Mode {
    Mode {
        start_signature: start.text(),
        signature: sol.text(),
        start_blocks: start.blocks().to_vec(),
        blocks: sol.blocks().to_vec(),
        start_jp: start.jp(),
        jp: sol.jp(),
        changed: start.first_difference(sol, parts).is_some(),
        closure_check,
    }
}

fn mode_text(m: &Mode, with_jp: bool) -> String {
    let what = if with_jp {
        "signs of det(G_r) per IK block / det(J_p)"
    } else {
        "signs of det(G_r) per IK block"
    };
    let verdict = if m.changed {
        "ANOTHER MODE than the start (allowed by --allow-mode-change)"
    } else if m.signature != m.start_signature {
        "the start's assembly mode (same sign of det J_p, reached along a path where J_p stays \
         regular); legs whose sign differs passed their own singularity on the way"
    } else {
        "the start's mode"
    };
    format!(
        "mode: {} ({what}; start {}): {verdict}; certificate: unsolved loop components at most {:.1e}\n",
        m.signature, m.start_signature, m.closure_check
    )
}

/// Why [`position`] failed: a solver error (explained by [`explain`]) or a message.
enum Fail {
    Solver(SolverError),
    Text(String),
}

impl From<SolverError> for Fail {
    fn from(e: SolverError) -> Self {
        Fail::Solver(e)
    }
}

/// [`solve_position`], then the named mode (`how.mode`), if any: a solution in another mode is
/// an error naming the part, and `data.x` is left at the start.
#[allow(clippy::type_complexity)]
fn position<K: Kernels<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    target: &[f64],
    forward: bool,
    how: Solve,
) -> Result<(&'static str, usize, f64, f64, Mode), Fail> {
    let start = data.x;
    let out = solve_position(model, data, target, forward, how)?;
    let Some(named) = how.mode else {
        return Ok(out);
    };
    let s = model.structure();
    if named.count != s.ik_blocks.len() {
        return Err(Fail::Text(format!(
            "--mode {}: {} signs before `/`, but `{}` has {} IK blocks",
            named.text(),
            named.count,
            s.name,
            s.ik_blocks.len()
        )));
    }
    let sig = mode_signature(model, &data.x);
    if let Some((part, want, got)) = named.mismatch(&sig) {
        data.x = start;
        let what = match part {
            ModePart::Block(b) => block_description(s, b),
            ModePart::Jp => "J_p".to_string(),
        };
        let advice = if forward {
            "start nearer the named mode (--near POSE), or solve with --direct \
             --allow-mode-change from a start in it"
                .to_string()
        } else {
            format!(
                "the command's inverse kinematics starts from the home assembly; start from an \
                 assembly in the named mode with {LIBRARY_START}"
            )
        };
        return Err(Fail::Text(format!(
            "found a solution in mode {} (max |f| = {:.1e}), not the named --mode {}: the sign of \
             det of {what} is {got:+}, not {want:+}; {advice}",
            sig.text(),
            out.2,
            named.text()
        )));
    }
    Ok(out)
}

/// Solves position by continuation or directly (see [`Solve`]) from `data.x`; returns
/// `(method, iterations, residual, cond, mode)`.
#[allow(clippy::type_complexity)]
fn solve_position<K: Kernels<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    data: &mut Data<N, M>,
    target: &[f64],
    forward: bool,
    how: Solve,
) -> Result<(&'static str, usize, f64, f64, Mode), Fail> {
    let start_x = data.x;
    if !how.direct && how.max_passive_change.is_none() {
        let opts = PathOptions {
            allow_mode_change: how.allow_mode_change,
            ..PathOptions::default()
        };
        let rep = if forward {
            forward_kinematics_path(model, data, target, &opts)?
        } else {
            inverse_kinematics_path(model, data, target, &opts)?
        };
        let parts = if forward { Parts::Jp } else { Parts::Blocks };
        let m = mode(
            &rep.start_signature,
            &rep.signature,
            parts,
            rep.closure_check,
        );
        return Ok(("continuation", rep.iterations, rep.residual, rep.cond, m));
    }
    let start = mode_signature(model, &start_x);
    let (method, iterations, residual, cond) = if forward {
        match how.max_passive_change {
            Some(limit) => {
                let opts = LmOptions {
                    max_passive_change: limit,
                    ..LmOptions::default()
                };
                let rep = forward_kinematics_lm(model, data, target, &opts).map_err(|e| match e {
                    FkRobustError::Solver(e) => Fail::Solver(e),
                    FkRobustError::ModeChange {
                        max_change,
                        coordinate,
                        residual,
                    } => Fail::Text(format!(
                        "found a solution (max |f| = {residual:.1e}) in another assembly mode than \
                         the start: `{}` moved {max_change:.6} from the start \
                         (--max-passive-change {limit}); start nearer the wanted assembly with \
                         --near POSE",
                        model.structure().coordinates[coordinate]
                    )),
                })?;
                (
                    "levenberg-marquardt",
                    rep.iterations,
                    rep.residual,
                    rep.cond,
                )
            }
            None => {
                let rep = forward_kinematics(model, data, target)?;
                ("newton", rep.iterations, rep.residual, rep.cond)
            }
        }
    } else {
        let rep = inverse_kinematics(model, data, target)?;
        ("newton", rep.iterations, rep.residual, rep.cond)
    };
    let sol = mode_signature(model, &data.x);
    let parts = if forward { Parts::All } else { Parts::Blocks };
    if let Some((part, a, b)) = start.first_difference(&sol, parts)
        && !how.allow_mode_change
    {
        data.x = start_x;
        return Err(Fail::Solver(SolverError::ModeChange {
            part,
            start: a,
            found: b,
            t: 1.0,
        }));
    }
    let check = certify_position(model, &data.x)?;
    Ok((
        method,
        iterations,
        residual,
        cond,
        mode(&start, &sol, parts, check),
    ))
}

/// `rbss ik`: every coordinate from the outputs `pose` (and, with `rates`, every rate from the
/// output rates), as text or JSON; from the home assembly, by continuation unless `how.direct`.
pub fn ik<K: Kernels<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    pose: &str,
    rates: Option<&str>,
    json: bool,
    how: Solve,
) -> Result<String, String> {
    let s = model.structure();
    s.require_outputs("inverse kinematics")
        .map_err(|e| e.to_string())?;
    let pose = parse_list("pose", pose, s.outputs.len())?;
    let rates = rates
        .map(|r| parse_list("rates", r, s.outputs.len()))
        .transpose()?;
    let mut data = Data::new(model);
    let (method, iterations, residual, cond, mode) = position(model, &mut data, &pose, false, how)
        .map_err(|e| match e {
            Fail::Solver(e) => {
                let e = honest_reach(model, &pose, e);
                format!(
                    "inverse kinematics failed: {}",
                    explain(model, &e, Start::Home)
                )
            }
            Fail::Text(t) => format!("inverse kinematics {t}"),
        })?;
    if let Some(r) = &rates {
        inverse_velocity(model, &mut data, r)
            .map_err(|e| format!("inverse velocity failed: {}", explain_ik_error(s, &e)))?;
    }
    let q = |x: &[f64]| s.actuated.iter().map(|&j| x[j]).collect::<Vec<f64>>();
    if json {
        let out = IkJson {
            model: s.name,
            problem: "inverse_kinematics",
            method,
            iterations,
            residual,
            cond,
            mode,
            coordinates: named(s, &data.x),
            x: data.x.to_vec(),
            q: q(&data.x),
            xdot: rates.as_ref().map(|_| data.xdot.to_vec()),
            qdot: rates.as_ref().map(|_| q(&data.xdot)),
        };
        return serde_json::to_string_pretty(&out).map_err(|e| format!("cannot write JSON: {e}"));
    }
    let mut out = format!(
        "{}: inverse kinematics ({method}) converged in {iterations} Newton steps (max |f| = {residual:.1e}, worst block cond = {cond:.3e})\n",
        s.name
    );
    out.push_str(&mode_text(&mode, false));
    out.push_str(&print_x(s, &data.x, ""));
    if rates.is_some() {
        out.push_str("inverse velocity (d/dt):\n");
        out.push_str(&print_x(s, &data.xdot, "d"));
    }
    Ok(out)
}

/// After a failed inverse kinematics: `Unreachable` (with evidence from several starts) if one
/// direct solve from home finds the pose out of a leg's reach, else the error as it was.
fn honest_reach<K: Kernels<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    pose: &[f64],
    e: SolverError,
) -> SolverError {
    match e {
        SolverError::PathStalled { .. } | SolverError::NotConverged { .. } => {
            let mut data = Data::new(model);
            match inverse_kinematics(model, &mut data, pose) {
                Err(u @ SolverError::Unreachable { .. }) => u,
                _ => e,
            }
        }
        _ => e,
    }
}

/// The sign of `det J_p` at `x` (`0` if `J_p` is exactly singular or not finite): the last
/// entry of the [`ModeSignature`].
pub fn det_jp_sign<K: Kernels<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    x: &[f64; N],
) -> i8 {
    mode_signature(model, x).jp()
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
    mode: Mode,
    /// `max |p_j - p_j,start|` over the passive coordinates, and the coordinate.
    max_passive_change: f64,
    max_change_coordinate: &'static str,
    coordinates: Vec<Named>,
    x: Vec<f64>,
    /// The output coordinates (model `outputs` order).
    outputs: Vec<f64>,
}

/// `rbss fk`: every coordinate from the actuated ones `q`, from the home assembly or from the
/// inverse kinematics of `near` (`home` is the home assembly): by continuation (the default,
/// keeping the start's mode), by one Newton solve (`how.direct`), or by Levenberg–Marquardt with
/// a bound on the passive coordinates' change (`how.max_passive_change`). Reports the mode.
pub fn fk<K: Kernels<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    q: &str,
    near: Option<&str>,
    json: bool,
    how: Solve,
) -> Result<String, String> {
    let s = model.structure();
    let q = parse_list("q", q, s.actuated.len())?;
    if let Some(limit) = how.max_passive_change
        && (limit.is_nan() || limit <= 0.0)
    {
        return Err(format!(
            "--max-passive-change {limit}: expected a positive number (m or rad)"
        ));
    }
    let mut data = Data::new(model);
    if let Some(near) = near.filter(|n| n.trim() != "home") {
        s.require_outputs("inverse kinematics")
            .map_err(|e| format!("--near: {e}"))?;
        let pose = parse_list("near", near, s.outputs.len())?;
        let opts = PathOptions {
            allow_mode_change: how.allow_mode_change,
            ..PathOptions::default()
        };
        inverse_kinematics_path(model, &mut data, &pose, &opts).map_err(|e| {
            let e = honest_reach(model, &pose, e);
            format!(
                "--near: inverse kinematics failed: {}",
                explain(model, &e, Start::Home)
            )
        })?;
    }
    let mut start = data.x;
    for (&j, &v) in s.actuated.iter().zip(&q) {
        start[j] = v;
    }
    let (method, iterations, residual, cond, mode) = position(model, &mut data, &q, true, how)
        .map_err(|e| match e {
            Fail::Solver(e) => {
                format!(
                    "forward kinematics failed: {}",
                    explain(model, &e, Start::Near)
                )
            }
            Fail::Text(t) => format!("forward kinematics {t}"),
        })?;
    let (mut change, mut moved) = (0.0_f64, s.passive.first().copied().unwrap_or(0));
    for &j in s.passive {
        let d = (data.x[j] - start[j]).abs();
        if d > change {
            change = d;
            moved = j;
        }
    }
    if json {
        let out = FkJson {
            model: s.name,
            problem: "forward_kinematics",
            method,
            iterations,
            residual,
            cond,
            mode,
            max_passive_change: change,
            max_change_coordinate: s.coordinates[moved],
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
    out.push_str(&mode_text(&mode, true));
    out.push_str(&format!(
        "largest passive change from the start: `{}` by {change:.6}\n",
        s.coordinates[moved]
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
    how: Solve,
) -> Result<String, String> {
    with_robot!(model, |m| ik(&exact_cond(m), pose, rates, json, how))
}

/// `rbss fk --model NAME`: [`fk`] on the robot of that name (dispatched here, as [`ik_named`]).
pub fn fk_named(
    model: &str,
    q: &str,
    near: Option<&str>,
    json: bool,
    how: Solve,
) -> Result<String, String> {
    with_robot!(model, |m| fk(&exact_cond(m), q, near, json, how))
}

/// The command prints the condition numbers themselves, not the bounds a library call may
/// report to save time (`SolverOptions::exact_cond`): one solve, whose cost does not matter.
pub fn exact_cond<K: Kernels<N, M>, const N: usize, const M: usize>(
    m: Model<K, N, M>,
) -> Model<K, N, M> {
    let options = rbss_runtime::SolverOptions {
        exact_cond: true,
        ..m.options
    };
    m.with_options(options)
}
