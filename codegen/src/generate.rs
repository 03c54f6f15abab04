//! The whole pipeline: parse -> derive -> the checks at the home -> the back end -> format.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::assemble::Assembly;
pub use crate::backend::{KernelReport, Options, camel, crate_files::MANIFEST};
use crate::backend::{Selection, crate_files, module_tokens};
use crate::derive::{self, Derivation};
use crate::diagnostics::{Diagnostic, Diagnostics};
use crate::model::Model;
use crate::parse;
use crate::scene::Scene;

/// What went wrong.
#[derive(Debug)]
pub enum Error {
    /// The model file has errors (all of them, rendered).
    Model(Diagnostics),
    Io(PathBuf, std::io::Error),
}

impl std::fmt::Display for Error {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Error::Model(d) => write!(f, "{}", d.render()),
            Error::Io(p, e) => write!(f, "{}: error: {e}", p.display()),
        }
    }
}

impl std::error::Error for Error {}

/// Figures of one generation run.
#[derive(Debug, Clone)]
pub struct Report {
    pub robot: String,
    pub n: usize,
    pub m: usize,
    /// The home configuration as assembled from the model's guess (`STRUCTURE.home`).
    pub home: Vec<f64>,
    /// `max |f|` at the assembled home.
    pub home_residual: f64,
    pub kernels: Vec<KernelReport>,
    pub lines: usize,
    pub parse_time: Duration,
    pub derive_time: Duration,
    pub emit_time: Duration,
    pub format_time: Duration,
    /// The model's warnings, rendered (`path:line:col: warning: ...`); empty when none.
    pub warnings: String,
}

/// A generated crate: its files, relative to the crate directory, with their contents.
pub struct Generated {
    pub name: String,
    pub files: Vec<(PathBuf, String)>,
    pub report: Report,
}

/// The generated crate's name for a model file, read without symbolica.
pub fn robot_name(model_path: &str, source: &str) -> Result<String, Error> {
    parse::parse_model(model_path, source)
        .map(|m| m.name)
        .map_err(Error::Model)
}

/// Generates the crate for the model at `model_path` (as it should appear in messages and the
/// header, e.g. `models/stewart_6ups.toml`) with contents `source`.
///
/// `progress` receives one line per stage.
pub fn generate(
    model_path: &str,
    source: &str,
    opts: &Options,
    progress: &mut dyn FnMut(&str),
) -> Result<Generated, Error> {
    generate_impl(model_path, source, opts, None, None, progress)
}

/// [`generate`] for a crate written elsewhere than `generated/NAME` in this workspace: its
/// `Cargo.toml` depends on the runtime at `runtime_dep` (a path relative to the crate's
/// directory, or an absolute one) instead of `../../runtime`.
pub fn generate_with_runtime(
    model_path: &str,
    source: &str,
    opts: &Options,
    runtime_dep: &str,
    progress: &mut dyn FnMut(&str),
) -> Result<Generated, Error> {
    generate_impl(model_path, source, opts, None, Some(runtime_dep), progress)
}

/// Generates the crate of a scene (see [`crate::scene`]): only the kernels its tasks' solvers
/// call, the scene's parameters frozen, and `impl`s of exactly its tasks' traits of
/// `rbss_runtime::tasks`. The crate is named after the scene and depends on the runtime at
/// `runtime_dep` (a path relative to the crate's directory).
pub fn generate_scene(
    scene: &Scene,
    runtime_dep: &str,
    progress: &mut dyn FnMut(&str),
) -> Result<Generated, Error> {
    let (model_path, source) = crate::scene::read_model_source(scene).map_err(Error::Model)?;
    let model = parse::parse_model(&model_path, &source).map_err(Error::Model)?;
    let frozen = scene.check(&model).map_err(Error::Model)?;
    let sel = Selection {
        scene,
        frozen,
        kernels: scene.kernels(),
        runtime_dep: runtime_dep.to_string(),
    };
    generate_impl(
        &model_path,
        &source,
        &Options::default(),
        Some(&sel),
        None,
        progress,
    )
}

fn generate_impl(
    model_path: &str,
    source: &str,
    opts: &Options,
    sel: Option<&Selection<'_>>,
    runtime_dep: Option<&str>,
    progress: &mut dyn FnMut(&str),
) -> Result<Generated, Error> {
    let t0 = Instant::now();
    check_shown_path("model file", model_path)?;
    let (model, warnings) = parse::parse_model_with_warnings(model_path, source);
    let model = model.map_err(Error::Model)?;
    if let Some(i) = &model.import {
        check_shown_path("source", &i.source.path)?;
    }
    if let Some(s) = sel {
        check_shown_path("scene", &s.scene.path)?;
    }
    // An imported model's positions are in the model file followed by the imported model.
    let source = model.import.as_ref().map_or(source, |i| i.text.as_str());
    let warnings = warnings.render_warnings();
    // The short form now, so that it shows even when the derivation fails later (an angle taken
    // as radians may well keep the home from assembling); the full form is in the report.
    for line in warnings.lines().filter(|l| l.contains(": warning: ")) {
        progress(line);
    }
    let parse_time = t0.elapsed();

    let t1 = Instant::now();
    let name = sel.map_or(model.name.clone(), |s| s.scene.name.clone());
    let mut stage = |s: &str| progress(&format!("[{name}] {s}"));
    let has_masses = model.bodies.iter().any(|b| b.inertia.is_some());
    let with_dynamics = match sel {
        Some(s) => s.scene.needs_dynamics() && has_masses,
        None => !opts.kinematics_only && has_masses,
    };
    let frozen = match sel {
        Some(s) => s.frozen.clone(),
        None => vec![opts.freeze; model.parameters.len()],
    };
    let model_error = |errs: Vec<derive::DeriveError>| {
        let d = Diagnostics {
            path: model_path.to_string(),
            source: source.to_string(),
            items: errs
                .into_iter()
                .map(|e| Diagnostic {
                    pos: e.pos,
                    len: 1,
                    message: e.message,
                    label: String::new(),
                    help: None,
                    elsewhere: None,
                })
                .collect(),
        };
        // An imported model's errors at the source's elements.
        Error::Model(match &model.import {
            Some(i) => i.map.relocate(d, source),
            None => d,
        })
    };
    let mut d = derive::derive(&model, with_dynamics, &frozen, &mut stage).map_err(model_error)?;
    let assembly = check_home(&model, &d, &model_error, &mut stage)?;
    let derive_time = t1.elapsed();

    let t2 = Instant::now();
    let (tokens, kernels) = module_tokens(
        &model,
        &mut d,
        &assembly.home,
        opts,
        sel,
        model_path,
        &mut stage,
    );
    let emit_time = t2.elapsed();

    stage("formatting");
    let t3 = Instant::now();
    let file: syn::File = match syn::parse2(tokens.clone()) {
        Ok(f) => f,
        Err(e) => {
            panic!("rbss-codegen emitted invalid Rust ({e}); this is a bug. Tokens:\n{tokens}")
        }
    };
    let body = crate_files::space_items(&prettyplease::unparse(&file));
    let format_time = t3.elapsed();

    let (files, lines) = crate_files::files(
        &crate_files::Crate {
            name: &name,
            model: &model,
            model_path,
            source,
            opts,
            sel,
            runtime_dep,
            n: d.n,
            m: d.m,
            dynamics: with_dynamics,
        },
        &body,
    );
    Ok(Generated {
        name: name.clone(),
        files,
        report: Report {
            robot: name,
            n: d.n,
            m: d.m,
            home: assembly.home,
            home_residual: assembly.residual,
            kernels,
            lines,
            parse_time,
            derive_time,
            emit_time,
            format_time,
            warnings,
        },
    })
}

/// Assembles the home from the model's guess and checks it (see `assemble` and `rank`): the
/// rank of `G`, `J_p` and the inverse-kinematics Jacobian there and at random assembled states
/// near it, the mass matrix, the regularity of the home. Reports the figures as one stage.
fn check_home(
    model: &Model,
    d: &Derivation,
    model_error: &dyn Fn(Vec<derive::DeriveError>) -> Error,
    stage: &mut dyn FnMut(&str),
) -> Result<Assembly, Error> {
    let assembly = match crate::assemble::assemble(model, d) {
        Ok(a) => a,
        Err(e) => {
            // A Jacobian deficient everywhere stops Newton at once: say which equation or
            // coordinate makes it so, when the states near the guess show it.
            let guess: Vec<f64> = model.coordinates.iter().map(|c| c.home).collect();
            let states = crate::rank::states(model, d, &guess);
            let found = crate::rank::diagnose(model, d, &states, "near the home guess");
            return Err(model_error(if found.is_empty() { vec![e] } else { found }));
        }
    };
    // The rank of G, J_p and the IK Jacobian at the home and at random assembled states.
    let states = crate::rank::states(model, d, &assembly.home);
    let found = crate::rank::diagnose(model, d, &states, "at the assembled home");
    if !found.is_empty() {
        return Err(model_error(found));
    }
    crate::assemble::check_mass(model, d, &assembly.home).map_err(|e| model_error(vec![e]))?;
    let (cond_p, cond_ik) =
        crate::assemble::check_regular(model, d, &assembly.home).map_err(|mut e| {
            if let Some((cp, ck)) = crate::rank::regular_nearby(model, d, &states) {
                e.message.push_str(&format!(
                    "; at {} random assembled states near the home both are regular (cond J_p \
                     at most {cp:.2e}, of the IK Jacobian {ck:.2e}): the home alone is singular",
                    states.len() - 1
                ));
            }
            model_error(vec![e])
        })?;
    let (change, worst) = assembly.largest_change;
    let cond_p = if d.passive.len() == d.m {
        format!("cond J_p {cond_p:.2e}")
    } else {
        format!(
            "{} passive degree(s) of freedom (no forward kinematics)",
            d.passive.len() - d.m
        )
    };
    stage(&format!(
        "home assembled in {} Newton steps: max |f| {:.1e} (at the model's values {:.1e}); largest change {change:.1e} ({}); {cond_p}, cond of the IK Jacobian {cond_ik:.2e}; G of full rank {} at the home and {} random assembled states",
        assembly.iterations,
        assembly.residual,
        assembly.residual_guess,
        model.coordinates[worst].name,
        d.m,
        states.len().saturating_sub(1)
    ));
    Ok(assembly)
}

/// Compares a generated crate with what is on disk; returns the paths that differ.
pub fn stale_files(dir: &Path, generated: &Generated) -> Vec<PathBuf> {
    generated
        .files
        .iter()
        .filter(|(rel, contents)| {
            std::fs::read_to_string(dir.join(rel)).ok().as_deref() != Some(contents.as_str())
        })
        .map(|(rel, _)| dir.join(rel))
        .collect()
}

/// Refuses a path that the generated crate would show (its header comments, `Cargo.toml`, the
/// manifest) when it holds a control character: a newline would end a comment and make the
/// rest of the path code. `"` and `\\` are fine: they are escaped where the path is quoted.
fn check_shown_path(what: &str, path: &str) -> Result<(), Error> {
    let Some(c) = path.chars().find(|c| c.is_control()) else {
        return Ok(());
    };
    Err(Error::Model(Diagnostics::new(
        format!("{path:?}"),
        String::new(),
        vec![Diagnostic::new(
            crate::diagnostics::Pos { line: 1, col: 1 },
            1,
            format!(
                "the {what}'s path {path:?} holds the control character {c:?}, which the \
                 generated crate cannot show in its comments: rename or move the file"
            ),
            "",
        )],
    )))
}
