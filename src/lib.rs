//! The `rbss` command's library: the robots this build knows, and the JSON kernel evaluation
//! behind `rbss eval`.

/// `println!` for results the studies print as they go (`rbss bench`, `rbss stress`): a closed
/// stdout drops them and the run goes on to write its files, instead of a panic (exit 101).
/// The other commands collect their results and write them once (src/main.rs).
#[macro_export]
macro_rules! outln {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout().lock(), $($t)*);
    }};
}

/// `print!` likewise ([`outln!`]).
#[macro_export]
macro_rules! outp {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = write!(std::io::stdout().lock(), $($t)*);
    }};
}

/// `eprintln!` likewise: progress is dropped when stderr is closed.
#[macro_export]
macro_rules! errln {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr().lock(), $($t)*);
    }};
}

// First: its `with_robot!` is in textual scope in the modules after it.
#[macro_use]
pub mod robots;

#[cfg(feature = "studies")]
pub mod bench;
pub mod cli;
pub mod csv;
pub mod describe;
pub mod entry;
pub mod inverse_dynamics;
pub mod kinematics;
pub mod model_file;
pub mod output;
pub mod paper;
pub mod plot;
pub mod robot_arg;
pub mod roundtrip;
pub mod simulate;
#[cfg(feature = "studies")]
pub mod solver_table;
#[cfg(feature = "studies")]
pub mod stress;
pub mod trajectory;

use rbss_runtime::Dynamics;
use serde::{Deserialize, Serialize};

/// The default bound of an input file's size ([`read_input`]): 256 MiB. A JSON or CSV file is
/// held with its parsed values, 2.5 to 3.5 times its size (a 1 GB states file took 2.5-3.5 GB),
/// so the bound keeps a run within about 1 GB.
pub const DEFAULT_MAX_INPUT_SIZE: u64 = 256 << 20;

/// The bound of an input file's size: `$RBSS_MAX_INPUT_SIZE` (bytes, or with K, M, G), else
/// [`DEFAULT_MAX_INPUT_SIZE`].
pub fn max_input_size() -> Result<u64, String> {
    match std::env::var("RBSS_MAX_INPUT_SIZE") {
        Ok(s) if !s.trim().is_empty() => {
            model_file::parse_size(&s).map_err(|e| format!("RBSS_MAX_INPUT_SIZE: {e}"))
        }
        _ => Ok(DEFAULT_MAX_INPUT_SIZE),
    }
}

/// Reads an input file (state, states, samples, expressions, model) as text, at most
/// [`max_input_size`] bytes: a larger file is an error naming it and the bound, before it is
/// read (and a file that grows, or a device without end such as `/dev/zero`, stops at the
/// bound). Errors name `path`.
pub fn read_input(path: &std::path::Path) -> Result<String, String> {
    let bytes = read_input_bytes(path)?;
    String::from_utf8(bytes).map_err(|e| format!("{}: not UTF-8 text: {e}", path.display()))
}

/// [`read_input`] as bytes.
pub fn read_input_bytes(path: &std::path::Path) -> Result<Vec<u8>, String> {
    use std::io::Read as _;
    let max = max_input_size()?;
    let too_large = |size: String| {
        format!(
            "{}: {size}, beyond the input limit of {max} bytes (set \
             RBSS_MAX_INPUT_SIZE, e.g. 1G, to read a larger file; it is held in memory 2.5 to \
             3.5 times its size)",
            path.display()
        )
    };
    let file =
        std::fs::File::open(path).map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
    let len = file.metadata().map(|m| m.len()).unwrap_or(0);
    if len > max {
        return Err(too_large(format!("{len} bytes")));
    }
    let mut bytes = Vec::with_capacity(usize::try_from(len).unwrap_or(0));
    file.take(max.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
    if bytes.len() as u64 > max {
        return Err(too_large(format!("more than {max} bytes")));
    }
    Ok(bytes)
}

/// The argument parser of every output path (`--out DIR`, `--csv FILE`): an empty or blank path
/// is refused, since it would mean the current directory (an unset shell variable,
/// `--out "$DIR"`, would otherwise write into whatever directory the command runs in).
pub fn output_path(s: &str) -> Result<String, String> {
    if s.trim().is_empty() {
        return Err(
            "an empty path names no file or directory (an unset shell variable?): \
                    give the path to write to"
                .into(),
        );
    }
    Ok(s.to_string())
}

/// Creates the output directory `out` (and its parents), refusing an empty path as
/// [`output_path`] does: the commands' library functions are called with paths that no
/// argument parser has seen.
pub fn create_output_dir(out: &std::path::Path) -> Result<(), String> {
    if out.as_os_str().is_empty() {
        return Err(output_path("").unwrap_err());
    }
    std::fs::create_dir_all(out).map_err(|e| format!("{}: cannot create: {e}", out.display()))
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct StatesIn {
    states: Vec<StateIn>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct StateIn {
    #[serde(rename = "X")]
    x: Vec<f64>,
    #[serde(rename = "Xdot")]
    xdot: Vec<f64>,
    /// Optional: the control forces on the actuated coordinates; then forward dynamics too.
    #[serde(rename = "U", default)]
    u: Option<Vec<f64>>,
}

#[derive(Serialize)]
struct StatesOut {
    states: Vec<StateOut>,
}

#[derive(Serialize)]
struct StateOut {
    f: Vec<f64>,
    #[serde(rename = "G")]
    g: Vec<Vec<f64>>,
    gamma: Vec<f64>,
    #[serde(rename = "M")]
    mass: Vec<Vec<f64>>,
    psi: Vec<f64>,
    /// With `U`: forward dynamics at the state, `Xddot` (N) and `lambda` (M).
    #[serde(rename = "Xddot", skip_serializing_if = "Option::is_none")]
    xddot: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    lambda: Option<Vec<f64>>,
    /// With `U`, when forward dynamics fails at the state (a singular saddle-point system):
    /// the error's message, in place of `Xddot` and `lambda`; the kernels are still given.
    #[serde(skip_serializing_if = "Option::is_none")]
    error: Option<String>,
}

/// A command's JSON result and the states whose forward dynamics failed: their index (in the
/// file's order) and the error's message, which the JSON also carries as the state's `"error"`.
/// The commands succeed with such states (exit status 0), unless `--strict`.
#[derive(Debug)]
pub struct Evaluation {
    pub json: String,
    pub failed: Vec<(usize, String)>,
}

impl Evaluation {
    /// The `--strict` error naming the first failed state (and how many others failed), or
    /// `None` when every state succeeded.
    pub fn strict_error(&self) -> Option<String> {
        let (i, e) = self.failed.first()?;
        let more = match self.failed.len() - 1 {
            0 => String::new(),
            1 => " (and 1 other state)".to_string(),
            k => format!(" (and {k} other states)"),
        };
        Some(format!("state {i}: {e}{more} (--strict)"))
    }
}

/// `rbss eval --model NAME --states FILE`: [`eval_states`] on the robot of that name and the
/// JSON file's states (dispatched in the library, as [`kinematics::ik_named`]).
pub fn eval_named(model: &str, path: &str) -> Result<Evaluation, String> {
    let text = read_input(std::path::Path::new(path))?;
    with_robot!(model, |m| eval_states(&m, &text)).map_err(|e| format!("{path}: {e}"))
}

/// Evaluates `f`, `G` (M rows of N), `gamma`, `M` (N rows of N) and `psi` at every state of a
/// JSON document `{"states":[{"X":[..N..],"Xdot":[..N..]}, ...]}` and returns the JSON result.
/// A state with `"U":[..]` (the control forces on the actuated coordinates, model order) also
/// gets forward dynamics there: `Xddot` and `lambda` solving `M Xddot = psi + S U - Gᵀ lambda`,
/// `G Xddot = gamma` (`rbss_runtime::forward_dynamics`, no Baumgarte term: the state is taken
/// as given, on the constraint manifold or not). A state whose forward dynamics fails gets
/// `"error"` (the message) instead, keeps its kernels, and is listed in
/// [`Evaluation::failed`]; the other states are unaffected.
///
/// Conventions: `f = origin(a) - origin(b)` per loop component; `G = ∂f/∂X`;
/// `gamma = -(dG/dt) Xdot`, so that a motion that keeps `f = 0` has `G Xddot = gamma`.
pub fn eval_states<K: Dynamics<N, M>, const N: usize, const M: usize>(
    model: &rbss_runtime::Model<K, N, M>,
    json: &str,
) -> Result<Evaluation, String> {
    let kernels = model.kernels();
    let input: StatesIn =
        serde_json::from_str(json).map_err(|e| format!("bad states file: {e}"))?;
    let mut out = StatesOut {
        states: Vec::with_capacity(input.states.len()),
    };
    let mut failed = Vec::new();
    let n_act = model.structure().actuated.len();
    for (i, st) in input.states.iter().enumerate() {
        let x: [f64; N] = st.x.as_slice().try_into().map_err(|_| {
            format!(
                "state {i}: \"X\" has {} values, the robot has {N} coordinates",
                st.x.len()
            )
        })?;
        let xdot: [f64; N] = st.xdot.as_slice().try_into().map_err(|_| {
            format!(
                "state {i}: \"Xdot\" has {} values, the robot has {N} coordinates",
                st.xdot.len()
            )
        })?;
        if let Some(u) = &st.u
            && u.len() != n_act
        {
            return Err(format!(
                "state {i}: \"U\" has {} values, the robot has {n_act} actuated coordinates",
                u.len()
            ));
        }
        let u_vals = st.u.iter().flatten();
        if let Some(v) = x.iter().chain(&xdot).chain(u_vals).find(|v| !v.is_finite()) {
            return Err(format!("state {i}: {v} is not a finite number"));
        }
        let mut f = [0.0; M];
        let mut g = [[0.0; M]; N];
        let mut gamma = [0.0; M];
        kernels.constraints(&x, &mut f);
        kernels.jacobian(&x, &mut g);
        kernels.gamma(&x, &xdot, &mut gamma);
        let mut mass = [[0.0; N]; N];
        let mut psi = [0.0; N];
        kernels.mass_matrix(&x, &mut mass);
        kernels.psi(&x, &xdot, &mut psi);
        // JSON has no NaN or infinity (serde_json would write `null`): a state so large that
        // the kernels overflow is an error, not a silent null.
        for (what, vals) in [
            ("f", f.as_slice()),
            ("G", g.as_flattened()),
            ("gamma", gamma.as_slice()),
            ("M", mass.as_flattened()),
            ("psi", psi.as_slice()),
        ] {
            if vals.iter().any(|v| !v.is_finite()) {
                return Err(format!(
                    "state {i}: {what} is not finite (NaN or inf) there: X or Xdot is too large \
                     for the kernels to evaluate in f64"
                ));
            }
        }
        let (xddot, lambda, error) = match &st.u {
            None => (None, None, None),
            Some(u) => {
                let mut data = rbss_runtime::Data::new(model);
                data.x = x;
                data.xdot = xdot;
                match rbss_runtime::forward_dynamics(
                    model,
                    &mut data,
                    u,
                    None,
                    rbss_runtime::Baumgarte::NONE,
                ) {
                    Ok(_) => (Some(data.xddot.to_vec()), Some(data.lambda.to_vec()), None),
                    Err(e) => {
                        let e = format!("forward dynamics: {e}");
                        failed.push((i, e.clone()));
                        (None, None, Some(e))
                    }
                }
            }
        };
        out.states.push(StateOut {
            xddot,
            lambda,
            error,
            f: f.to_vec(),
            g: (0..M).map(|r| (0..N).map(|c| g[c][r]).collect()).collect(),
            gamma: gamma.to_vec(),
            mass: (0..N)
                .map(|r| (0..N).map(|c| mass[c][r]).collect())
                .collect(),
            psi: psi.to_vec(),
        });
    }
    let json = serde_json::to_string(&out).map_err(|e| format!("cannot write JSON: {e}"))?;
    Ok(Evaluation { json, failed })
}
