//! Output (task-space) trajectories: the motion of a robot's `Structure::outputs` with its
//! first and second time derivatives, from the paper's TraekP, from a CSV file of samples
//! (not-a-knot cubic spline) or from a TOML file of expressions in `t` (exact derivatives by
//! hyper-dual numbers).
//!
//! ```text
//! # samples.csv: header t,<outputs>[,<name>_dot][,<name>_ddot], t strictly increasing
//! t,x,y
//! 0,0,0.3
//! 0.02,0.0031395259764656688,0.30376943637197186
//!
//! # expressions.toml: one expression in t per output
//! x = "0.05*sin(pi*t)"
//! y = "0.3 + 0.03*sin(2*pi*t)"
//! ```

pub mod expr;
pub mod spline;

use std::path::Path;

use rbss_runtime::{Data, Dynamics, Kernels, Model, SolverError, Structure, inverse_dynamics_full};

use crate::robots::stewart_6ups;

use expr::{Expr, ExprError};
use spline::Spline;

/// A motion of the output coordinates, in the order of `Structure::outputs`.
pub trait Trajectory {
    /// How many output coordinates it moves.
    fn dim(&self) -> usize;
    /// Position, velocity and acceleration at time `t`: each slice has `dim()` entries (extra
    /// entries are left alone, missing ones are not written).
    fn eval(&self, t: f64, pos: &mut [f64], vel: &mut [f64], acc: &mut [f64]);
    /// The times it is defined on (samples: from the first to the last; others: all times).
    fn domain(&self) -> (f64, f64) {
        (f64::NEG_INFINITY, f64::INFINITY)
    }
    /// What it is, for messages.
    fn describe(&self) -> String;
}

/// A borrowed trajectory is one (so a `&dyn Trajectory` goes where a `Trajectory` is owned).
impl<T: Trajectory + ?Sized> Trajectory for &T {
    fn dim(&self) -> usize {
        (**self).dim()
    }
    fn eval(&self, t: f64, pos: &mut [f64], vel: &mut [f64], acc: &mut [f64]) {
        (**self).eval(t, pos, vel, acc)
    }
    fn domain(&self) -> (f64, f64) {
        (**self).domain()
    }
    fn describe(&self) -> String {
        (**self).describe()
    }
}

/// The output names of a robot, in the order of `Structure::outputs`.
pub fn output_names(s: &Structure) -> Vec<&'static str> {
    s.outputs.iter().map(|&j| s.coordinates[j]).collect()
}

/// 1-based line and column (in characters) of byte `offset` of `text`.
fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    let mut o = offset;
    while !text.is_char_boundary(o) {
        o -= 1;
    }
    let before = &text[..o];
    let line = before.matches('\n').count() + 1;
    let start = before.rfind('\n').map_or(0, |i| i + 1);
    (line, before[start..].chars().count() + 1)
}

// ---------------------------------------------------------------------------------------------
// Samples

/// One output coordinate of a samples file: its position spline, and the splines of the
/// `_dot` / `_ddot` columns when the file has them.
#[derive(Debug, Clone)]
struct SampledOutput {
    pos: Spline,
    dot: Option<Spline>,
    ddot: Option<Spline>,
}

/// A trajectory given by samples `t, outputs...` (a CSV file): interpolated by not-a-knot
/// cubic splines (see [`spline`]), whose exact derivatives are the velocity and acceleration.
///
/// Where the file has a `<name>_dot` column, the velocity of `<name>` is the spline through it
/// and the acceleration that spline's derivative; a `<name>_ddot` column likewise gives the
/// acceleration. At the sample times the given values come back exactly; between them each
/// column is interpolated on its own, so the columns should be consistent.
#[derive(Debug, Clone)]
pub struct Samples {
    source: String,
    t: Vec<f64>,
    outputs: Vec<SampledOutput>,
}

impl Samples {
    /// Reads a samples file for a robot with output coordinates `outputs`.
    pub fn load(path: &Path, outputs: &[&str]) -> Result<Samples, String> {
        let text = crate::read_input(path)?;
        Samples::parse(&path.display().to_string(), &text, outputs)
    }

    /// Parses the text of a samples file; `file` names it in messages (`file:line: ...`).
    ///
    /// Format: lines of comma-separated fields; blank lines and lines starting with `#` are
    /// skipped. The first other line is the header: `t`, then every output name once, in any
    /// order, and optionally `<name>_dot` and `<name>_ddot` columns. Every following line has
    /// one finite number per header field; `t` strictly increases; at least 2 rows.
    pub fn parse(file: &str, text: &str, outputs: &[&str]) -> Result<Samples, String> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let mut lines = text
            .lines()
            .enumerate()
            .map(|(i, l)| (i + 1, l.trim()))
            .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
        let Some((hline, header)) = lines.next() else {
            return Err(format!(
                "{file}: empty: expected a header `t,{}`",
                outputs.join(",")
            ));
        };
        let names: Vec<&str> = header.split(',').map(str::trim).collect();
        let herr = |msg: String| format!("{file}:{hline}: header: {msg}");
        if names[0] != "t" {
            return Err(herr(format!(
                "the first column must be `t`, found `{}` (expected `t,{}`)",
                names[0],
                outputs.join(",")
            )));
        }
        // Column of each output's position, velocity, acceleration.
        let mut cols = vec![[None::<usize>; 3]; outputs.len()];
        for (c, &name) in names.iter().enumerate().skip(1) {
            let (base, kind) = if let Some(b) = name.strip_suffix("_ddot") {
                (b, 2)
            } else if let Some(b) = name.strip_suffix("_dot") {
                (b, 1)
            } else {
                (name, 0)
            };
            let Some(o) = outputs.iter().position(|&n| n == base) else {
                return Err(herr(format!(
                    "column {}: `{name}` is not an output coordinate; expected t,{} (and \
                     optionally <name>_dot, <name>_ddot)",
                    c + 1,
                    outputs.join(",")
                )));
            };
            if cols[o][kind].is_some() {
                return Err(herr(format!("column {}: `{name}` appears twice", c + 1)));
            }
            cols[o][kind] = Some(c);
        }
        let missing: Vec<&str> = outputs
            .iter()
            .zip(&cols)
            .filter(|(_, c)| c[0].is_none())
            .map(|(n, _)| *n)
            .collect();
        if !missing.is_empty() {
            return Err(herr(format!(
                "no column for {}; expected t,{}",
                missing
                    .iter()
                    .map(|n| format!("`{n}`"))
                    .collect::<Vec<_>>()
                    .join(", "),
                outputs.join(",")
            )));
        }
        let mut data: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
        let mut prev: Option<(usize, f64)> = None;
        for (line, row) in lines {
            let fields: Vec<&str> = row.split(',').map(str::trim).collect();
            if fields.len() != names.len() {
                return Err(format!(
                    "{file}:{line}: expected {} fields ({}), found {}",
                    names.len(),
                    names.join(","),
                    fields.len()
                ));
            }
            for (c, f) in fields.iter().enumerate() {
                let v: f64 = match f.parse::<f64>() {
                    Ok(v) if v.is_finite() => v,
                    Ok(_) => {
                        return Err(format!(
                            "{file}:{line}: column `{}`: `{f}` is not a finite number",
                            names[c]
                        ));
                    }
                    Err(_) => {
                        return Err(format!(
                            "{file}:{line}: column `{}`: `{f}` is not a number",
                            names[c]
                        ));
                    }
                };
                data[c].push(v);
            }
            let t = data[0][data[0].len() - 1];
            if let Some((pl, pt)) = prev
                && t <= pt
            {
                return Err(format!(
                    "{file}:{line}: column `t`: {t} is not greater than {pt} (line {pl}): \
                     t must strictly increase"
                ));
            }
            prev = Some((line, t));
        }
        if data[0].len() < 2 {
            return Err(format!(
                "{file}: {} sample row(s): at least 2 are needed (4 or more for a cubic spline)",
                data[0].len()
            ));
        }
        let t = data[0].clone();
        let spline = |c: Option<usize>| c.map(|c| Spline::not_a_knot(&t, &data[c]));
        let outputs = cols
            .iter()
            .map(|c| SampledOutput {
                pos: Spline::not_a_knot(&t, &data[c[0].unwrap_or(0)]),
                dot: spline(c[1]),
                ddot: spline(c[2]),
            })
            .collect();
        Ok(Samples {
            source: file.to_string(),
            t,
            outputs,
        })
    }

    /// The sample times.
    pub fn times(&self) -> &[f64] {
        &self.t
    }
}

impl Trajectory for Samples {
    fn dim(&self) -> usize {
        self.outputs.len()
    }

    fn eval(&self, t: f64, pos: &mut [f64], vel: &mut [f64], acc: &mut [f64]) {
        for (((o, p), v), a) in self.outputs.iter().zip(pos).zip(vel).zip(acc) {
            let (s, s1, s2) = o.pos.eval(&self.t, t);
            *p = s;
            match &o.dot {
                Some(d) => {
                    let (d0, d1, _) = d.eval(&self.t, t);
                    *v = d0;
                    *a = d1;
                }
                None => {
                    *v = s1;
                    *a = s2;
                }
            }
            if let Some(dd) = &o.ddot {
                *a = dd.eval(&self.t, t).0;
            }
        }
    }

    fn domain(&self) -> (f64, f64) {
        (self.t[0], self.t[self.t.len() - 1])
    }

    fn describe(&self) -> String {
        format!(
            "{} samples from {} (not-a-knot cubic spline)",
            self.t.len(),
            self.source
        )
    }
}

// ---------------------------------------------------------------------------------------------
// Expressions

/// A trajectory given by one expression in `t` per output coordinate (a TOML file), with
/// exact derivatives (forward-mode automatic differentiation, [`expr::HyperDual`]).
#[derive(Debug, Clone)]
pub struct Expressions {
    source: String,
    exprs: Vec<Expr>,
}

impl Expressions {
    /// Reads an expressions file for a robot with output coordinates `outputs`.
    pub fn load(path: &Path, outputs: &[&str]) -> Result<Expressions, String> {
        let text = crate::read_input(path)?;
        Expressions::parse(&path.display().to_string(), &text, outputs)
    }

    /// Parses a TOML document with one top-level key per output coordinate, each a string
    /// expression in `t` (or a number); `file` names it in messages (`file:line:col: ...`).
    ///
    /// Expressions: numbers, `t`, `pi`, `+ - * / ^` (`^` right-associative, above unary
    /// minus), parentheses, and the functions of rbss's expression language
    /// (`sin cos tan exp ln sqrt asin acos abs` of one argument, `atan2(y, x)`, `hypot(x, y)`).
    pub fn parse(file: &str, text: &str, outputs: &[&str]) -> Result<Expressions, String> {
        use toml::de::{DeTable, DeValue};
        let at = |offset: usize, msg: &str| {
            let (l, c) = line_col(text, offset);
            format!("{file}:{l}:{c}: {msg}")
        };
        let doc = DeTable::parse(text).map_err(|e| {
            let offset = e.span().map_or(0, |s| s.start);
            at(offset, &format!("TOML: {}", e.message().trim()))
        })?;
        let mut exprs: Vec<Option<Expr>> = vec![None; outputs.len()];
        for (key, value) in doc.get_ref() {
            let name: &str = key.get_ref();
            let Some(o) = outputs.iter().position(|n| *n == name) else {
                return Err(at(
                    key.span().start,
                    &format!(
                        "`{name}` is not an output coordinate; expected one expression for each \
                         of {}",
                        outputs.join(", ")
                    ),
                ));
            };
            let span = value.span();
            let expr = match value.get_ref() {
                DeValue::String(s) => {
                    // Where the expression starts in the file: the raw value text holds it
                    // verbatim unless it has escapes (then errors point at the value).
                    let raw = text.get(span.clone()).unwrap_or("");
                    let base = span.start + raw.find(s.as_ref()).unwrap_or(0);
                    Expr::parse(s).map_err(|ExprError { offset, message }| {
                        at(base + offset, &format!("`{name}`: {message}"))
                    })?
                }
                DeValue::Integer(i) => number(i.as_str(), i.radix())
                    .map_err(|m| at(span.start, &format!("`{name}`: {m}")))?,
                DeValue::Float(f) => {
                    number(f.as_str(), 10).map_err(|m| at(span.start, &format!("`{name}`: {m}")))?
                }
                other => {
                    return Err(at(
                        span.start,
                        &format!(
                            "`{name}`: expected an expression in t as a string, e.g. {name} = \
                             \"0.1*cos(pi*t)\", found a {}",
                            other.type_str()
                        ),
                    ));
                }
            };
            exprs[o] = Some(expr);
        }
        let missing: Vec<String> = outputs
            .iter()
            .zip(&exprs)
            .filter(|(_, e)| e.is_none())
            .map(|(n, _)| format!("`{n}`"))
            .collect();
        if !missing.is_empty() {
            return Err(format!(
                "{file}: no expression for {} (the outputs are {})",
                missing.join(", "),
                outputs.join(", ")
            ));
        }
        Ok(Expressions {
            source: file.to_string(),
            exprs: exprs.into_iter().flatten().collect(),
        })
    }
}

/// A TOML number value as a constant expression.
fn number(raw: &str, radix: u32) -> Result<Expr, String> {
    let clean: String = raw.chars().filter(|&c| c != '_').collect();
    let v = if radix == 10 {
        clean.parse::<f64>().ok()
    } else {
        let digits = clean.get(2..).unwrap_or("");
        i64::from_str_radix(digits, radix).ok().map(|i| i as f64)
    };
    match v {
        Some(v) if v.is_finite() => {
            Expr::parse(&format!("{v:?}")).map_err(|e| format!("{} ({v})", e.message))
        }
        _ => Err(format!("`{raw}` is not a finite number")),
    }
}

impl Trajectory for Expressions {
    fn dim(&self) -> usize {
        self.exprs.len()
    }

    fn eval(&self, t: f64, pos: &mut [f64], vel: &mut [f64], acc: &mut [f64]) {
        for (((e, p), v), a) in self.exprs.iter().zip(pos).zip(vel).zip(acc) {
            let r = e.eval(t);
            *p = r.v;
            *v = r.d1;
            *a = r.d2;
        }
    }

    fn describe(&self) -> String {
        format!("expressions from {}", self.source)
    }
}

/// Reads a trajectory file for a robot with output coordinates `outputs`, by its extension:
/// `.csv` samples ([`Samples`]), `.toml` expressions ([`Expressions`]).
pub fn load(path: &Path, outputs: &[&str]) -> Result<Box<dyn Trajectory>, String> {
    match path.extension().and_then(|e| e.to_str()) {
        Some(e) if e.eq_ignore_ascii_case("csv") => Ok(Box::new(Samples::load(path, outputs)?)),
        Some(e) if e.eq_ignore_ascii_case("toml") => {
            Ok(Box::new(Expressions::load(path, outputs)?))
        }
        _ => Err(format!(
            "{}: unknown trajectory format: expected a .csv file of samples or a .toml file of \
             expressions",
            path.display()
        )),
    }
}

// ---------------------------------------------------------------------------------------------
// Inverse kinematics and dynamics along a trajectory

/// The largest `--samples` of `rbss inverse-dynamics` and `rbss paper`. Every sample's
/// coordinates, rates, accelerations, forces and CSV row stay in memory until the files are
/// written: about 1.2 kB per sample for stewart_6ups (24 coordinates), so 1.2 GB at this limit
/// (1e7 samples took 11.5 GB), and an absurd count would overflow the allocation. Longer runs:
/// several time windows (`--t-start`, `--t-end`).
pub const MAX_SAMPLES: usize = 1_000_000;

/// Refuses a sample count outside `2 ..= MAX_SAMPLES`, naming the argument.
pub fn check_samples(samples: usize) -> Result<(), String> {
    if samples < 2 {
        return Err(format!("--samples {samples}: need at least 2"));
    }
    if samples > MAX_SAMPLES {
        return Err(format!(
            "--samples {samples}: at most {MAX_SAMPLES} (every sample is held in memory, about \
             1.2 kB each for stewart_6ups: 1.2 GB at the limit); split a longer run into time \
             windows"
        ));
    }
    Ok(())
}

/// `t_k = t0 + k (t1 - t0) / (samples - 1)`, `k = 0 .. samples` (the last one exactly `t1`).
pub fn sample_times(t0: f64, t1: f64, samples: usize) -> Vec<f64> {
    let last = samples.saturating_sub(1).max(1) as f64;
    let mut t: Vec<f64> = (0..samples)
        .map(|k| t0 + (t1 - t0) * k as f64 / last)
        .collect();
    if samples >= 2 {
        t[samples - 1] = t1;
    }
    t
}

/// A time as people read it: `0.25`, or `5e307` rather than its 308 digits.
fn time(t: f64) -> String {
    rbss_runtime::integrate::Time(t).to_string()
}

/// Inverse kinematics, velocity and acceleration of any robot along `trajectory` (over its
/// `Structure::outputs`), warm-started from one sample to the next. Returns the samples and
/// the largest IK residual.
pub fn inverse_kinematics_along<K: Kernels<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    trajectory: &dyn Trajectory,
    times: &[f64],
) -> Result<(Vec<KinematicSample<N>>, f64), String> {
    use rbss_runtime::{Data, inverse_acceleration, inverse_kinematics, inverse_velocity};
    let s = model.structure();
    let names = output_names(s);
    if trajectory.dim() != names.len() {
        return Err(format!(
            "{} moves {} coordinates, `{}` has {} outputs ({})",
            trajectory.describe(),
            trajectory.dim(),
            s.name,
            names.len(),
            names.join(", ")
        ));
    }
    let k = names.len();
    let (mut pos, mut vel, mut acc) = (vec![0.0; k], vec![0.0; k], vec![0.0; k]);
    let mut data = Data::new(model);
    let mut out = Vec::with_capacity(times.len());
    let mut worst: f64 = 0.0;
    for &t in times {
        trajectory.eval(t, &mut pos, &mut vel, &mut acc);
        for (what, v) in [
            ("position", &pos),
            ("velocity", &vel),
            ("acceleration", &acc),
        ] {
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return Err(format!(
                    "t = {} s: {}: {what} of `{}` is {} (the trajectory's expressions overflow, \
                     or have no digits left, at this time)",
                    time(t),
                    trajectory.describe(),
                    names[i],
                    v[i]
                ));
            }
        }
        // The solvers' errors in the user's terms, as `rbss ik` gives them (the leg by name).
        let explain = |e: SolverError| crate::kinematics::explain_ik_error(s, &e);
        let rep = inverse_kinematics(model, &mut data, &pos)
            .map_err(|e| format!("t = {} s: inverse kinematics: {}", time(t), explain(e)))?;
        worst = worst.max(rep.residual);
        inverse_velocity(model, &mut data, &vel)
            .map_err(|e| format!("t = {} s: inverse velocity: {}", time(t), explain(e)))?;
        inverse_acceleration(model, &mut data, &acc)
            .map_err(|e| format!("t = {} s: inverse acceleration: {}", time(t), explain(e)))?;
        out.push(KinematicSample {
            t,
            x: data.x,
            xdot: data.xdot,
            xddot: data.xddot,
        });
    }
    Ok((out, worst))
}

/// Inverse dynamics of any robot at kinematic samples: the control forces `U` on the actuated
/// coordinates and the multipliers `lambda` (the paper's eqs. 33-36).
pub fn inverse_dynamics_along<K: Dynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    samples: &[KinematicSample<N>],
) -> Result<Vec<ForceSample<N, M>>, String> {
    use rbss_runtime::{Data, inverse_dynamics};
    let mut data = Data::new(model);
    let mut out = Vec::with_capacity(samples.len());
    for s in samples {
        data.x = s.x;
        data.xdot = s.xdot;
        data.xddot = s.xddot;
        let rep = inverse_dynamics(model, &mut data, None)
            .map_err(|e| format!("t = {}: inverse dynamics: {e}", time(s.t)))?;
        out.push(ForceSample {
            t: s.t,
            u: data.u,
            lambda: data.lambda,
            cond: rep.cond,
        });
    }
    Ok(out)
}

/// One kinematic sample of a robot with `N` coordinates (by default the paper's robot).
#[derive(Debug, Clone, Copy)]
pub struct KinematicSample<const N: usize = { stewart_6ups::N }> {
    pub t: f64,
    pub x: [f64; N],
    pub xdot: [f64; N],
    pub xddot: [f64; N],
}

/// One inverse-dynamics sample of a robot with `N` coordinates and `M` constraints (by default
/// the paper's robot): the control forces `U` and the multipliers.
#[derive(Debug, Clone, Copy)]
pub struct ForceSample<const N: usize = { stewart_6ups::N }, const M: usize = { stewart_6ups::M }> {
    pub t: f64,
    /// `U`, packed as `Data::u`: `u[a]` acts on `Structure::actuated[a]` for `a < N - M`
    /// (N or N m); the entries `N - M..` are zero. [`ForceSample::u`] is the used part.
    pub u: [f64; N],
    pub lambda: [f64; M],
    /// Condition estimate of the reduced system solved for `U`.
    pub cond: f64,
}

impl<const N: usize, const M: usize> ForceSample<N, M> {
    /// The control forces on the `N - M` actuated coordinates.
    pub fn u(&self) -> &[f64] {
        &self.u[..N - M]
    }
}

/// `t, U1..Uk, lambda1..lambdaM` rows (`k = N - M` actuated coordinates).
pub fn force_table<const N: usize, const M: usize>(
    forces: &[ForceSample<N, M>],
) -> (Vec<String>, Vec<Vec<f64>>) {
    let mut header = vec!["t".to_string()];
    header.extend(crate::csv::numbered("U", N - M));
    header.extend(crate::csv::numbered("lambda", M));
    let rows = forces
        .iter()
        .map(|f| {
            let mut r = vec![f.t];
            r.extend_from_slice(f.u());
            r.extend_from_slice(&f.lambda);
            r
        })
        .collect();
    (header, rows)
}

/// The longest time step over which the control extrapolates its warm start (s): the
/// integrators' steps and stages are far shorter; a caller that jumps (back to `t = 0`, say, as
/// the energy balance of `rbss bench work-precision` does) restarts from the last solution,
/// which over a jump of a whole period of TraekP is the right branch, where a Taylor step of
/// 2 s is not (measured: it lands Newton on another assembly mode).
const TAYLOR_MAX_STEP: f64 = 0.02;

/// The control of the round trip: `U(t)` by inverse kinematics, velocity, acceleration and
/// inverse dynamics of the trajectory at `t` (exactly, at whatever time the integrator asks; the
/// state is ignored), on a `Data` of its own warm-started from `x0` and then from the previous
/// sample's Taylor polynomial (`x + h ẋ + h²/2 ẍ`; callgrind on the 6-UPS's DOPRI5 1e-9 +
/// Baumgarte run: Newton's instructions -30 %, the integration's -5 %). A `Simulator` control
/// callback.
pub fn control<'a, K, T, const N: usize, const M: usize>(
    model: &'a Model<K, N, M>,
    trajectory: T,
    x0: &[f64; N],
) -> impl FnMut(f64, &[f64; N], &[f64; N], &mut [f64]) -> Result<(), rbss_runtime::SolverError> + 'a
where
    K: Dynamics<N, M>,
    T: Trajectory + 'a,
{
    let mut reference = Data::new(model);
    reference.x = *x0;
    let k = model.structure().outputs.len();
    let (mut p, mut v, mut a) = (vec![0.0; k], vec![0.0; k], vec![0.0; k]);
    // The last sample: the integrators ask for the same time more than once (RK4's two
    // midpoint stages, DOPRI5's last stage and the next step's first).
    let mut last_t = f64::NAN;
    move |t, _, _, u| {
        if t != last_t {
            trajectory.eval(t, &mut p, &mut v, &mut a);
            let h = t - last_t;
            if h > 0.0 && h <= TAYLOR_MAX_STEP {
                // Warm start from the last sample's Taylor polynomial: Newton then starts within
                // O(h³) of the solution instead of O(h).
                for ((x, &xd), &xdd) in reference
                    .x
                    .iter_mut()
                    .zip(&reference.xdot)
                    .zip(&reference.xddot)
                {
                    *x += h * (xd + 0.5 * h * xdd);
                }
            }
            inverse_dynamics_full(model, &mut reference, &p, &v, &a, None)?;
            last_t = t;
        }
        u.copy_from_slice(reference.u());
        Ok(())
    }
}

/// One recorded state of a forward-dynamics run (by default of the paper's robot).
#[derive(Debug, Clone, Copy)]
pub struct SimState<const N: usize = { stewart_6ups::N }> {
    pub t: f64,
    pub x: [f64; N],
    pub xdot: [f64; N],
}

/// A forward-dynamics run of a round trip: every accepted state (the start first), the
/// integrator's statistics and the wall time of the integration alone.
#[derive(Debug, Clone)]
pub struct Integration<const N: usize = { stewart_6ups::N }> {
    pub states: Vec<SimState<N>>,
    pub stats: rbss_runtime::IntegrateStats,
    /// Wall time of `Simulator::run` (s), recording the states included, the start's
    /// projection not.
    pub secs: f64,
}

/// Forward dynamics of any robot from `(x0, xdot0)` at `t0` to `t_end` under the round trip's
/// [`control`] along `trajectory`, with the given integrator settings; writes no file. With
/// `report`, a progress line goes to stderr every quarter of the run once it has taken a
/// second.
#[allow(clippy::too_many_arguments)]
pub fn integrate<K: Dynamics<N, M>, const N: usize, const M: usize>(
    model: &Model<K, N, M>,
    trajectory: &dyn Trajectory,
    t0: f64,
    x0: &[f64; N],
    xdot0: &[f64; N],
    t_end: f64,
    options: rbss_runtime::IntegrateOptions,
    report: bool,
) -> Result<Integration<N>, String> {
    use std::io::Write as _;
    use std::time::Instant;
    let mut control = control(model, trajectory, x0);
    let mut data = Data::new(model);
    let mut sim = rbss_runtime::Simulator::new(model, &mut data, t0, x0, xdot0, options)
        .map_err(|e| format!("forward dynamics: cannot start: {e}"))?;
    let mut states: Vec<SimState<N>> = Vec::with_capacity(1 << 16);
    states.push(SimState {
        t: t0,
        x: *x0,
        xdot: *xdot0,
    });
    let started = Instant::now();
    let mut next_report = 0.25;
    sim.run(model, &mut data, t_end, &mut control, |s| {
        states.push(SimState {
            t: s.t(),
            x: *s.x(),
            xdot: *s.xdot(),
        });
        if report
            && s.t() - t0 >= next_report * (t_end - t0)
            && started.elapsed().as_secs_f64() > 1.0
        {
            // Progress: dropped, not a panic, when stderr is closed.
            let _ = writeln!(
                std::io::stderr().lock(),
                "rbss:   t = {:.2} s of {t_end} s ({} steps)",
                s.t(),
                s.stats().steps
            );
            next_report += 0.25;
        }
    })
    .map_err(|e| format!("forward dynamics: {e}"))?;
    Ok(Integration {
        states,
        stats: *sim.stats(),
        secs: started.elapsed().as_secs_f64(),
    })
}

/// Max |simulated output - trajectory| per output (in `Structure::outputs` order) over the
/// states.
pub fn output_errors<const N: usize>(
    structure: &Structure,
    trajectory: &dyn Trajectory,
    states: &[SimState<N>],
) -> Vec<f64> {
    let k = structure.outputs.len();
    let (mut p, mut v, mut a) = (vec![0.0; k], vec![0.0; k], vec![0.0; k]);
    let mut worst = vec![0.0_f64; k];
    for s in states {
        trajectory.eval(s.t, &mut p, &mut v, &mut a);
        for ((w, &o), r) in worst.iter_mut().zip(structure.outputs).zip(&p) {
            *w = w.max((s.x[o] - r).abs());
        }
    }
    worst
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_col_counts_characters() {
        let text = "ab\ncdé f\n";
        assert_eq!(line_col(text, 0), (1, 1));
        assert_eq!(line_col(text, 3), (2, 1));
        assert_eq!(line_col(text, 8), (2, 5));
    }

    #[test]
    fn sample_times_end_exactly() {
        let t = sample_times(0.1, 0.7, 7);
        assert_eq!((t[0], t[6], t.len()), (0.1, 0.7, 7));
        assert_eq!(sample_times(0.0, 2.0, 11)[5], 1.0);
    }
}
