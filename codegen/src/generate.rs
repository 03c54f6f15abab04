//! The whole pipeline: parse -> derive -> emit -> format, and the generated crate's files.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use proc_macro2::{Ident, Literal, Span, TokenStream};
use quote::{format_ident, quote};
use sha2::{Digest, Sha256};

use crate::derive::{self, Derivation};
use crate::diagnostics::{Diagnostic, Diagnostics};
use crate::emit::{self, Consts, KernelSpec, Ops, OutArg, Target, doc_attrs, f64_tokens};
use crate::graph::{Graph, Id, Node};
use crate::model::Model;
use crate::parse;
use crate::scene::{Scene, Task};
pub use crate::write::write_crate;

/// Generation options.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Options {
    /// Fold the model's parameter values into the kernels (exactly where they can be: `cos` of
    /// a frozen zero angle is 1) instead of reading them from `Params` at run time.
    pub freeze: bool,
    /// Emit only the kinematics kernels (no `M`, `psi`, energies), for scenes that need no
    /// dynamics. Models without masses are always kinematics-only.
    pub kinematics_only: bool,
}

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

/// Per-kernel figures.
#[derive(Debug, Clone)]
pub struct KernelReport {
    pub name: &'static str,
    pub shape: String,
    pub nonzeros: usize,
    pub ops: Ops,
}

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

/// What a scene selects: its frozen parameters and kernels, and where the crate finds the
/// runtime.
struct Selection<'a> {
    scene: &'a Scene,
    frozen: Vec<bool>,
    kernels: Vec<&'static str>,
    runtime_dep: String,
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
        Error::Model(Diagnostics {
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
                })
                .collect(),
        })
    };
    let d = derive::derive(&model, with_dynamics, &frozen, &mut stage).map_err(model_error)?;
    let assembly = match crate::assemble::assemble(&model, &d) {
        Ok(a) => a,
        Err(e) => {
            // A Jacobian deficient everywhere stops Newton at once: say which equation or
            // coordinate makes it so, when the states near the guess show it.
            let guess: Vec<f64> = model.coordinates.iter().map(|c| c.home).collect();
            let states = crate::rank::states(&model, &d, &guess);
            let found = crate::rank::diagnose(&model, &d, &states, "near the home guess");
            return Err(model_error(if found.is_empty() { vec![e] } else { found }));
        }
    };
    // The rank of G, J_p and the IK Jacobian at the home and at random assembled states.
    let states = crate::rank::states(&model, &d, &assembly.home);
    let found = crate::rank::diagnose(&model, &d, &states, "at the assembled home");
    if !found.is_empty() {
        return Err(model_error(found));
    }
    crate::assemble::check_mass(&model, &d, &assembly.home).map_err(|e| model_error(vec![e]))?;
    let (cond_p, cond_ik) =
        crate::assemble::check_regular(&model, &d, &assembly.home).map_err(|mut e| {
            if let Some((cp, ck)) = crate::rank::regular_nearby(&model, &d, &states) {
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
    let derive_time = t1.elapsed();

    let t2 = Instant::now();
    let (tokens, kernels) = module_tokens(
        &model,
        &d,
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
    let body = space_items(&prettyplease::unparse(&file));
    let format_time = t3.elapsed();

    // The model file's hash (the text as written: `source` may have the import appended).
    let model_text = &source[..model.import.as_ref().map_or(source.len(), |i| i.model_len)];
    let normalised = model_text.replace("\r\n", "\n");
    let sha = hex(&Sha256::digest(normalised.as_bytes()));
    let regenerate = if opts.freeze {
        format!("cargo run --release -p rbss-codegen -- --freeze {model_path}")
    } else {
        format!("cargo run --release -p rbss-codegen -- {model_path}")
    };
    let options = if opts.freeze {
        "  options: --freeze"
    } else {
        ""
    };
    // A scene's crate records the scene: its file's hash, its tasks and frozen parameters.
    let (scene_line, regenerate) = match sel {
        Some(s) => (
            format!(
                "// scene: {}  sha256: {}  {}\n",
                s.scene.path,
                hex(&Sha256::digest(
                    s.scene.source.replace("\r\n", "\n").as_bytes()
                )),
                s.scene.summary()
            ),
            format!(
                "cargo run --release -p rbss-codegen -- --scene {} --out <this crate>",
                s.scene.path
            ),
        ),
        None => (String::new(), regenerate),
    };
    // An imported model records its source's hash too: a changed source makes the crate stale.
    let import_line = match &model.import {
        Some(i) => format!(
            "// source: {}  sha256: {}\n",
            i.source.path, i.source.sha256
        ),
        None => String::new(),
    };
    let header = format!(
        "// @generated by rbss-codegen {}. Do not edit.\n// model: {model_path}  sha256: {sha}{options}\n{import_line}{scene_line}// regenerate: {regenerate}\n\n",
        env!("CARGO_PKG_VERSION")
    );
    let module = format!("{header}{body}");
    let lines = module.lines().count();

    let cargo_toml = format!(
        "# @generated by rbss-codegen {ver}. Do not edit.\n\
         # regenerate: {regenerate}\n\
         [package]\n\
         name = \"{name}\"\n\
         description = {description}\n\
         version = \"0.1.0\"\n\
         edition = \"2024\"\n\
         publish = false\n\
         \n\
         [dependencies]\n\
         rbss-runtime = {{ path = \"{runtime}\" }}\n\
         libm = \"0.2\"\n{workspace}",
        ver = env!("CARGO_PKG_VERSION"),
        // Quoted: a path may hold `"` or `\\`.
        description = toml_str(&match sel {
            Some(s) => format!(
                "Generated kernels of the robot `{}` ({model_path}) for the scene `{name}` ({})",
                model.name, s.scene.path
            ),
            None => format!("Generated kinematics kernels of the robot `{name}` ({model_path})"),
        }),
        runtime = match (sel, runtime_dep) {
            (Some(s), _) => s.runtime_dep.as_str(),
            (None, Some(r)) => r,
            (None, None) => "../../runtime",
        }
        // A TOML basic string: an absolute path may hold `\` or `"`.
        .replace('\\', "\\\\")
        .replace('"', "\\\""),
        // A scene's crate is built on its own, wherever it is written.
        workspace = if sel.is_some() { "\n[workspace]\n" } else { "" },
    );
    let lib_rs = format!(
        "//! Generated kernels of the robot `{name}`, from `{model_path}`: see [`{name}`](self) below.\n\
         //! Regenerate with `{regenerate}`.\n\
         #![no_std]\n\
         \n\
         // Parameter defaults are exact values such as 45 degrees in rad, not approximations.\n\
         #[allow(clippy::approx_constant)]\n\
         #[rustfmt::skip]\n\
         mod {name};\n\
         pub use self::{name}::*;\n"
    );

    let manifest = manifest(&Manifest {
        name: &name,
        model_path,
        model_sha256: &sha,
        scene: sel.map(|s| s.scene.path.as_str()),
        module_sha256: &hex(&Sha256::digest(module.as_bytes())),
        n: d.n,
        m: d.m,
        actuated: model.actuated.len(),
        dynamics: with_dynamics,
        freeze: opts.freeze,
    });

    Ok(Generated {
        name: name.clone(),
        files: vec![
            (PathBuf::from("Cargo.toml"), cargo_toml),
            (PathBuf::from(MANIFEST), manifest),
            (PathBuf::from("src/lib.rs"), lib_rs),
            (PathBuf::from(format!("src/{name}.rs")), module),
        ],
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

/// Refuses a path that the generated crate would show (its header comments, `Cargo.toml`, the
/// manifest) when it holds a control character: a newline would end a comment and make the
/// rest of the path code (issue 37). `"` and `\\` are fine: they are escaped where the path is
/// quoted.
fn check_shown_path(what: &str, path: &str) -> Result<(), Error> {
    let Some(c) = path.chars().find(|c| c.is_control()) else {
        return Ok(());
    };
    Err(Error::Model(Diagnostics::new(
        format!("{path:?}"),
        String::new(),
        vec![Diagnostic::new(
            crate::model::Pos { line: 1, col: 1 },
            1,
            format!(
                "the {what}'s path {path:?} holds the control character {c:?}, which the \
                 generated crate cannot show in its comments: rename or move the file"
            ),
            "",
        )],
    )))
}

/// The manifest's file name in a generated crate.
pub const MANIFEST: &str = "rbss-manifest.toml";

/// What the manifest of a generated crate says (see [`manifest`]).
struct Manifest<'a> {
    name: &'a str,
    model_path: &'a str,
    model_sha256: &'a str,
    scene: Option<&'a str>,
    module_sha256: &'a str,
    n: usize,
    m: usize,
    actuated: usize,
    dynamics: bool,
    freeze: bool,
}

/// The crate's manifest, `rbss-manifest.toml`: what the `rbss` command's registry (its
/// build.rs), the cache of `--model-file` and the loader of robot libraries read instead of
/// the generated source. Flat `key = value` lines of TOML (strings, integers, booleans), so
/// that a build script reads it without a TOML parser.
fn manifest(m: &Manifest<'_>) -> String {
    let mut s = format!(
        "# @generated by rbss-codegen {ver}. Do not edit.\n\
         # The crate's manifest, read by the `rbss` command's registry and its robot cache.\n\
         generator = \"rbss-codegen {ver}\"\n\
         name = \"{name}\"\n\
         type = \"{ty}\"\n\
         module = \"src/{name}.rs\"\n\
         model = {model}\n\
         model_sha256 = \"{model_sha}\"\n",
        ver = env!("CARGO_PKG_VERSION"),
        name = m.name,
        ty = camel(m.name),
        model = toml_str(m.model_path),
        model_sha = m.model_sha256,
    );
    if let Some(scene) = m.scene {
        s.push_str(&format!("scene = {}\n", toml_str(scene)));
    }
    s.push_str(&format!(
        "module_sha256 = \"{}\"\n\
         n = {}\n\
         m = {}\n\
         actuated = {}\n\
         dynamics = {}\n\
         freeze = {}\n",
        m.module_sha256, m.n, m.m, m.actuated, m.dynamics, m.freeze
    ));
    s
}

/// `s` as a TOML basic string.
fn toml_str(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if c.is_control() => out.push_str(&format!("\\u{:04X}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// Puts a blank line between top-level items (prettyplease writes them back to back).
fn space_items(src: &str) -> String {
    let mut out = String::with_capacity(src.len() + src.len() / 50);
    let mut prev_end = false;
    for line in src.lines() {
        let starts_item = line.starts_with("///")
            || line.starts_with("#[")
            || line.starts_with("pub ")
            || line.starts_with("impl")
            || line.starts_with("use ");
        if prev_end && starts_item {
            out.push('\n');
        }
        prev_end = line == "}" || line == "};" || (line.ends_with(';') && !line.starts_with(' '));
        out.push_str(line);
        out.push('\n');
    }
    out
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// `stewart_6ups` -> `Stewart6Ups`.
pub fn camel(name: &str) -> String {
    let mut out = String::new();
    let mut upper = true;
    for ch in name.chars() {
        if ch == '_' {
            upper = true;
            continue;
        }
        if upper && ch.is_ascii_alphabetic() {
            out.push(ch.to_ascii_uppercase());
            upper = false;
        } else {
            out.push(ch);
            upper = ch.is_ascii_digit();
        }
    }
    out
}

fn usize_list(xs: &[usize]) -> TokenStream {
    let l = xs.iter().map(|&x| Literal::usize_unsuffixed(x));
    quote!(&[#(#l),*])
}

fn names_list(xs: &[String]) -> String {
    xs.join(", ")
}

fn module_tokens(
    model: &Model,
    d: &Derivation,
    home: &[f64],
    opts: &Options,
    sel: Option<&Selection<'_>>,
    model_path: &str,
    progress: &mut dyn FnMut(&str),
) -> (TokenStream, Vec<KernelReport>) {
    let n = d.n;
    let m = d.m;
    let robot = format_ident!("{}", camel(&model.name));
    let coord_names: Vec<String> = model.coordinates.iter().map(|c| c.name.clone()).collect();
    let coord_of = |js: &[usize]| -> String {
        js.iter()
            .map(|&j| coord_names[j].clone())
            .collect::<Vec<_>>()
            .join(", ")
    };

    // --- constants, Params ---
    let n_lit = Literal::usize_unsuffixed(n);
    let m_lit = Literal::usize_unsuffixed(m);
    let doc_n = doc_attrs(&format!(
        "Number of coordinates: `X = [{}]`.",
        names_list(&coord_names)
    ));
    let doc_m = doc_attrs(&format!(
        "Number of loop-closure equations `f(X) = 0`: [{}].",
        d.constraint_names.join(", ")
    ));
    let doc_k = doc_attrs("Number of constants the kernels read (see [`Params::consts`]).");

    let mut fields = Vec::new();
    let mut defaults = Vec::new();
    let mut lets = Vec::new();
    for (j, p) in model.parameters.iter().enumerate() {
        let id = Ident::new(&p.name, Span::call_site());
        let is_literal = !mentions_param(&p.expr);
        if is_literal {
            let unit = if p.unit.is_empty() {
                String::new()
            } else {
                format!(" \\[{}\\]", if p.unit == "deg" { "rad" } else { &p.unit })
            };
            // The model's text in a doc comment: brackets escaped, or rustdoc reads `[m]` as a
            // link.
            let mut doc = format!(
                "{}{unit}, {model_path}:{}",
                if p.doc.is_empty() {
                    format!("`{}`", p.name)
                } else {
                    p.doc.replace('[', "\\[").replace(']', "\\]")
                },
                p.pos.line
            );
            if p.unit == "deg" {
                doc.push_str(&format!(
                    " (written in degrees: {})",
                    emit::expr_string(&p.expr, model)
                ));
            }
            let doc = doc_attrs(&doc);
            fields.push(quote!(#doc pub #id: f64,));
            let v = f64_tokens(p.value);
            defaults.push(quote!(#id: #v,));
            lets.push((j, quote!(let #id = self.#id;)));
        } else {
            let e = emit::expr_tokens(&p.expr, model);
            lets.push((j, quote!(let #id = #e;)));
        }
    }
    let derived_note = if model.parameters.iter().any(|p| mentions_param(&p.expr)) {
        "\n\nParameters whose value in the model is an expression of other parameters are not fields: \
         they are recomputed from the fields in [`Params::consts`]."
    } else {
        ""
    };
    let frozen_note = if let Some(s) = sel {
        match &s.scene.freeze {
            crate::scene::Freeze::None => String::new(),
            _ => format!(
                "\n\nScene `{}` freezes {}: their values are folded into the kernels, which do not \
                 read them; their fields only document them.",
                s.scene.name,
                model
                    .parameters
                    .iter()
                    .zip(&s.frozen)
                    .filter(|(_, f)| **f)
                    .map(|(p, _)| format!("`{}`", p.name))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    } else if opts.freeze {
        "\n\nGenerated with `--freeze`: the model's values are folded into the kernels, which read \
         no parameter; these fields only document them."
            .to_string()
    } else {
        String::new()
    };
    let params_doc = doc_attrs(&format!(
        "Parameters of `{}` in SI units (angles in rad). `Params::default()` holds the model file's values; \
         the line numbers point into the model file.{derived_note}{frozen_note}",
        model.name
    ));

    // --- structure ---
    let name_str = &model.name;
    let coords_ts = coord_names.iter().map(|s| quote!(#s));
    let cons_ts = d.constraint_names.iter().map(|s| quote!(#s));
    let act = usize_list(&model.actuated);
    let pas = usize_list(&d.passive);
    let outs = usize_list(&model.outputs);
    let ik_order = proc_macro2::Literal::usize_unsuffixed(ik_block_order(&d.ik_blocks));
    let ik_order_doc = ik_order_doc();
    let blocks = d.ik_blocks.iter().map(|(r, c)| {
        let r = usize_list(r);
        let c = usize_list(c);
        quote!(IkBlock { rows: #r, cols: #c })
    });
    let homes = home.iter().map(|&h| f64_tokens(h));
    // The actuators' gear ratios, where the model gives any (`U` in the motors' units).
    let geared = model
        .actuated
        .iter()
        .any(|&j| model.coordinates[j].gear.is_some());
    let gears: Vec<TokenStream> = model
        .actuated
        .iter()
        .filter(|_| geared)
        .map(|&j| f64_tokens(model.coordinates[j].gear.unwrap_or(1.0)))
        .collect();
    let structure_doc = doc_attrs(&format!(
        "Structure of `{}`: q = [{}], p = [{}], outputs = [{}], {} independent IK blocks.",
        model.name,
        coord_of(&model.actuated),
        coord_of(&d.passive),
        coord_of(&model.outputs),
        d.ik_blocks.len()
    ));

    // --- kernels ---
    let mut is_output = vec![false; n];
    for &o in &model.outputs {
        is_output[o] = true;
    }
    let ik_cols: Vec<usize> = (0..n).filter(|&j| !is_output[j]).collect();
    let mat_outputs = |cols: &[usize]| -> Vec<(Target, Id)> {
        let mut v = Vec::new();
        for &col in cols {
            for row in 0..m {
                v.push((Target::Mat { row, col }, d.g[row][col]));
            }
        }
        v
    };
    let all_cols: Vec<usize> = (0..n).collect();
    let mat_ty = quote!([[f64; M]; N]);
    let vec_ty = quote!([f64; M]);
    let g_note = "Column-major (`out[col][row]`, the storage of nalgebra's `SMatrix<f64, M, N>`). \
                  Writes only the structural non-zeros listed above; the other entries of `out` are never \
                  written, so a buffer that starts at zero stays correct.";
    let specs = vec![
        KernelSpec {
            name: "constraints",
            doc: format!(
                "Loop closure `f(X)` (M = {m}): for each loop, the world components of origin(a) - origin(b).\n\
                 Rows: [{}].",
                d.constraint_names.join(", ")
            ),
            uses_velocity: false,
            outs: vec![OutArg::new(
                "out",
                vec_ty.clone(),
                d.f.iter()
                    .enumerate()
                    .map(|(i, a)| (Target::Vec(i), *a))
                    .collect(),
            )],
        },
        KernelSpec {
            name: "jacobian",
            doc: format!("Constraint Jacobian `G = ∂f/∂X` ({m} × {n}).\n\n{}", g_note),
            uses_velocity: false,
            outs: vec![OutArg::new("out", mat_ty.clone(), mat_outputs(&all_cols))],
        },
        KernelSpec {
            name: "jacobian_p",
            doc: format!(
                "`J_p`: the columns of `G` for the passive coordinates p = [{}] ({m} × {}), written into the \
                 full {m} × {n} layout.\n\n{}",
                coord_of(&d.passive),
                d.passive.len(),
                g_note
            ),
            uses_velocity: false,
            outs: vec![OutArg::new("out", mat_ty.clone(), mat_outputs(&d.passive))],
        },
        KernelSpec {
            name: "jacobian_ik",
            doc: format!(
                "The columns of `G` for the inverse-kinematics unknowns (every coordinate but the outputs): [{}], \
                 written into the full {m} × {n} layout.\n\n{}",
                coord_of(&ik_cols),
                g_note
            ),
            uses_velocity: false,
            outs: vec![OutArg::new("out", mat_ty.clone(), mat_outputs(&ik_cols))],
        },
        KernelSpec {
            name: "gamma",
            doc: format!(
                "Acceleration term `gamma(X, Xdot) = -(dG/dt) Xdot` (M = {m}), so that `G Xddot = gamma` \
                 (the paper's eqs. 11-17: `J_p pddot = gamma - J_q qddot`)."
            ),
            uses_velocity: true,
            outs: vec![OutArg::new(
                "out",
                vec_ty.clone(),
                d.gamma
                    .iter()
                    .enumerate()
                    .map(|(i, a)| (Target::Vec(i), *a))
                    .collect(),
            )],
        },
    ];
    let mut specs = specs;
    if !d.checks.is_empty() {
        specs.insert(
            1,
            KernelSpec {
                name: "closure_check",
                doc: format!(
                    "The loop components the model does not solve (MC = {}): [{}]. Each is                      `origin(a) - origin(b)` along a world axis that its loop's `components` leave out;                      zero wherever the loop's two points coincide, so the solvers check it after a                      position solve (a root with one of them away from zero is a mirror root of the                      solved components, refused as spurious).",
                    d.checks.len(),
                    d.check_names.join(", ")
                ),
                uses_velocity: false,
                outs: vec![OutArg::new(
                    "out",
                    quote!([f64; MC]),
                    d.checks
                        .iter()
                        .enumerate()
                        .map(|(i, a)| (Target::Vec(i), *a))
                        .collect(),
                )],
            },
        );
    }
    let nb = model.bodies.len();
    let body_names: Vec<String> = model.bodies.iter().map(|b| b.name.clone()).collect();
    specs.push(KernelSpec {
        name: "body_frames",
        doc: format!(
            "World frames of the bodies [{}] ({nb} of them): `out[b]` = `[R (column-major, 9), p (3)]`, \
             the rotation and origin of body b's frame.",
            body_names.join(", ")
        ),
        uses_velocity: false,
        outs: vec![OutArg::new("out", quote!([[f64; 12]; NB]), d
            .frames
            .iter()
            .enumerate()
            .flat_map(|(b, fr)| {
                let mut v = Vec::new();
                for col in 0..3 {
                    for row in 0..3 {
                        v.push((Target::Mat { row: 3 * col + row, col: b }, fr.r[row][col]));
                    }
                }
                for i in 0..3 {
                    v.push((Target::Mat { row: 9 + i, col: b }, fr.p[i]));
                }
                v
            })
            .collect())],
    });
    if let Some(dy) = &d.dynamics {
        let blocks: Vec<String> = dy
            .mass_blocks
            .iter()
            .map(|b| format!("`[{}]`", coord_of(b)))
            .collect();
        let mut upper = Vec::new();
        for col in 0..n {
            for row in 0..=col {
                upper.push((Target::Sym { row, col }, dy.mass[row][col]));
            }
        }
        specs.push(KernelSpec {
            name: "mass_matrix",
            doc: format!(
                "Mass matrix `M(X) = ∂²T/∂Xdot²` ({n} × {n}, symmetric; the paper's eq. 25), assembled per body \
                 as `m J_rᵀ J_r + J_wᵀ I J_w`. Block-diagonal with the {} blocks {}: each body moves with \
                 its own chain's coordinates only.\n\nWrites both triangles of the structural non-zeros; the \
                 other entries of `out` are never written.",
                dy.mass_blocks.len(),
                blocks.join(" ")
            ),
            uses_velocity: false,
            outs: vec![OutArg::new("out", quote!([[f64; N]; N]), upper)],
    });
        // The joints' own forces (springs, dampers, armatures), named where a model has them.
        let joint_forces: Vec<String> = model
            .coordinates
            .iter()
            .filter(|c| !c.forces.is_empty())
            .map(|c| format!("`{}`", c.name))
            .collect();
        let (psi_forces, t_forces, pi_forces) = if joint_forces.is_empty() {
            (String::new(), "", "")
        } else {
            (
                format!(
                    " It includes the joints' own forces on {}: `-stiffness (q - rest)` (from `Pi`) \
                     and `-damping q̇`; `M`'s diagonal includes their `armature`.",
                    joint_forces.join(", ")
                ),
                ", plus `½ armature q̇²` per joint",
                " and of the joints' springs (`½ stiffness (q - rest)²` each)",
            )
        };
        specs.push(KernelSpec {
            name: "psi",
            doc: format!(
                "`psi(X, Xdot) = -(Christoffel terms) - ∂Pi/∂X` ({n}; the paper's eq. 21 with the Christoffel \
                 symbols of the first kind), so that `M Xddot = psi + Q + S U - Gᵀ lambda`.{psi_forces}"
            ),
            uses_velocity: true,
            outs: vec![OutArg::new("out", quote!([f64; N]), dy.psi.iter().enumerate().map(|(i, a)| (Target::Vec(i), *a)).collect())],
    });
        specs.push(KernelSpec {
            name: "energy",
            doc: format!(
                "`[T, Pi]`: kinetic energy `T(X, Xdot)` summed from the bodies' centre-of-mass and angular \
                 velocities (independently of `M`){t_forces}, and potential energy `Pi(X)` of gravity{pi_forces}."
            ),
            uses_velocity: true,
            outs: vec![OutArg::new("out", quote!([f64; 2]), vec![(Target::Vec(0), dy.kinetic), (Target::Vec(1), dy.potential)])],
    });
    }
    // Fused kernels: what the solvers need together, in one evaluator each (shared trig/CSE).
    let f_entries: Vec<(Target, Id)> =
        d.f.iter()
            .enumerate()
            .map(|(i, a)| (Target::Vec(i), *a))
            .collect();
    specs.push(KernelSpec {
        name: "constraints_jacobian_ik",
        doc: "`f` and the inverse-kinematics columns of `G` together (one Newton step of inverse \
              kinematics): [`constraints`] and [`jacobian_ik`] fused, sharing their subexpressions."
            .to_string(),
        uses_velocity: false,
        outs: vec![
            OutArg::new("f", vec_ty.clone(), f_entries.clone()),
            OutArg::new("g", mat_ty.clone(), mat_outputs(&ik_cols)),
        ],
    });
    specs.push(KernelSpec {
        name: "constraints_jacobian_p",
        doc: "`f` and `J_p` together (one Newton step of forward kinematics): [`constraints`] and \
              [`jacobian_p`] fused, sharing their subexpressions."
            .to_string(),
        uses_velocity: false,
        outs: vec![
            OutArg::new("f", vec_ty.clone(), f_entries),
            OutArg::new("g", mat_ty.clone(), mat_outputs(&d.passive)),
        ],
    });
    if let Some(dy) = &d.dynamics {
        let mut upper = Vec::new();
        for col in 0..n {
            for row in 0..=col {
                upper.push((Target::Sym { row, col }, dy.mass[row][col]));
            }
        }
        specs.push(KernelSpec {
            name: "dynamics_terms",
            doc: "Everything the equations of motion need at one state: `G`, `gamma`, `M` and `psi` \
                  ([`jacobian`], [`gamma`], [`mass_matrix`], [`psi`] fused, sharing their subexpressions)."
                .to_string(),
            uses_velocity: true,
            outs: vec![
                OutArg::new("g", mat_ty.clone(), mat_outputs(&all_cols)),
                OutArg::new(
                    "gamma",
                    vec_ty.clone(),
                    dy.gamma.iter().enumerate().map(|(i, a)| (Target::Vec(i), *a)).collect(),
                ),
                OutArg::new("mass", quote!([[f64; N]; N]), upper),
                OutArg::new(
                    "psi",
                    quote!([f64; N]),
                    dy.psi.iter().enumerate().map(|(i, a)| (Target::Vec(i), *a)).collect(),
                ),
            ],
        });
    }
    // A scene emits only the kernels its tasks' solvers call.
    if let Some(s) = sel {
        specs.retain(|spec| s.kernels.contains(&spec.name));
        for spec in &mut specs {
            spec.doc = unlink_missing(&spec.doc, &s.kernels);
        }
    }
    let mut kernel_items = Vec::new();
    let mut consts = Consts::default();
    let mut reports = Vec::new();
    for spec in &specs {
        let mut spec_doc = spec.doc.clone();
        let total: usize = spec.outs.iter().map(|o| o.entries.len()).sum();
        let nnz: usize = spec
            .outs
            .iter()
            .map(|o| o.entries.iter().filter(|(_, a)| *a != Graph::ZERO).count())
            .sum();
        spec_doc.push_str(&format!("\n\nNon-zeros written: {nnz} of {total}."));
        let spec2 = KernelSpec {
            name: spec.name,
            doc: spec_doc,
            uses_velocity: spec.uses_velocity,
            outs: spec.outs.clone(),
        };
        let tk = Instant::now();
        let k = emit::emit_kernel(&d.graph, &mut consts, &spec2);
        progress(&format!(
            "emitted `{}` in {:.3} s: {}",
            spec.name,
            tk.elapsed().as_secs_f64(),
            k.ops
        ));
        reports.push(KernelReport {
            name: spec.name,
            shape: spec
                .outs
                .iter()
                .map(|o| o.ty.to_string().replace(' ', ""))
                .collect::<Vec<_>>()
                .join(" + "),
            nonzeros: k.nonzeros,
            ops: k.ops,
        });
        kernel_items.push(k.tokens);
    }

    // The solves emitted over the structure (see `solve`): for a robot, and for a scene whose
    // tasks call them.
    let wants = |k: &str| sel.is_none_or(|s| s.kernels.contains(&k));
    let mut solve_impls = Vec::new();
    let mut ik_solve_impl = quote!();
    let mut kinematic = solve_structure(model, d, None, home);
    let ops_of = |name: &str| reports.iter().find(|r| r.name == name).map(|r| r.ops);
    kinematic.fk_evals = ops_of("constraints").zip(ops_of("constraints_jacobian_p"));
    for (name, emit) in [
        (
            "ik_block_solve",
            crate::solve::ik_block_solve as fn(&crate::solve::Structure<'_>) -> _,
        ),
        ("forward_rates_solve", crate::solve::forward_rates_solve),
    ] {
        let Some(e) = wants(name).then(|| emit(&kinematic)).flatten() else {
            continue;
        };
        progress(&format!("emitted `{name}`: {}", e.flops));
        let ops = e.flops;
        let (item, imp) = kinematic_solve_item(name, e, model, d);
        kernel_items.push(item);
        ik_solve_impl.extend(imp);
        reports.push(KernelReport {
            name,
            shape: "[f64;N] + [f64;2]".to_string(),
            nonzeros: n - model.outputs.len(),
            ops,
        });
    }
    if let Some(dy) = &d.dynamics {
        let s = solve_structure(model, d, Some(dy), home);
        for (name, emitted) in [
            (
                "forward_dynamics_solve",
                wants("forward_dynamics_solve")
                    .then(|| crate::solve::forward_dynamics(&s))
                    .flatten(),
            ),
            (
                "inverse_dynamics_solve",
                wants("inverse_dynamics_solve")
                    .then(|| crate::solve::inverse_dynamics(&s))
                    .flatten(),
            ),
        ] {
            let Some(e) = emitted else { continue };
            progress(&format!("emitted `{name}`: {}", e.flops));
            let ops = e.flops;
            let (item, imp) = solve_item(name, e, model, d);
            kernel_items.push(item);
            solve_impls.push(imp);
            reports.push(KernelReport {
                name,
                shape: if name == "forward_dynamics_solve" {
                    "[f64;N] + [f64;M]".to_string()
                } else {
                    "[f64;N-M] + [f64;M]".to_string()
                },
                nonzeros: n,
                ops,
            });
        }
    }
    let fd_solve_impl = quote!(#(#solve_impls)*);

    let c_arg = quote!(&self.c);
    // The model's parameter names are the fields' names, as written (`R`, `L1`).
    let snake = if model
        .parameters
        .iter()
        .any(|p| p.name.chars().any(|ch| ch.is_ascii_uppercase()))
    {
        quote!(#[allow(non_snake_case)])
    } else {
        quote!()
    };
    let (const_stmts, const_items, consts_doc, k_lit) =
        consts_tokens(model, &d.graph, &consts, lets);
    let nb_lit = Literal::usize_unsuffixed(nb);
    let body_names_ts = body_names.iter().map(|s| quote!(#s));
    let nb_doc = doc_attrs("Number of bodies (frames) in [`BODIES`], the rows of [`body_frames`].");
    let bodies_doc = doc_attrs("Body names, in model order.");
    let has_checks = specs.iter().any(|s| s.name == "closure_check");
    let mc_lit = Literal::usize_unsuffixed(d.checks.len());
    let check_names_ts = d.check_names.iter().map(|s| quote!(#s));
    let mc_doc =
        doc_attrs("Number of loop components checked but not solved (see [`closure_check`]).");
    let checks_doc = doc_attrs("Their names, `loop.axis`.");
    let mc_item = if has_checks {
        quote! {
            #mc_doc
            pub const MC: usize = #mc_lit;
            #checks_doc
            pub const CLOSURE_CHECKS: [&str; MC] = [#(#check_names_ts),*];
        }
    } else {
        quote!()
    };
    let checks_impl = if has_checks {
        quote! {
            fn closure_checks(&self) -> &'static [&'static str] {
                &CLOSURE_CHECKS
            }
            fn closure_check(&self, x: &[f64; N], out: &mut [f64]) {
                if let Some(out) = out.first_chunk_mut::<MC>() {
                    closure_check(#c_arg, x, out)
                }
            }
        }
    } else {
        quote!()
    };
    let nb_item = if specs.iter().all(|s| s.name != "body_frames") {
        quote!()
    } else {
        quote! {
        #nb_doc
        pub const NB: usize = #nb_lit;
        #bodies_doc
        pub const BODIES: [&str; NB] = [#(#body_names_ts),*];
        }
    };
    let dynamics_impl = match &d.dynamics {
        Some(dy) => {
            let blocks = dy.mass_blocks.iter().map(|b| usize_list(b));
            quote! {
                impl rbss_runtime::Dynamics<N, M> for #robot {
                    fn mass_blocks(&self) -> &'static [&'static [usize]] {
                        &[#(#blocks),*]
                    }
                    fn mass_matrix(&self, x: &[f64; N], out: &mut [[f64; N]; N]) {
                        mass_matrix(#c_arg, x, out)
                    }
                    fn psi(&self, x: &[f64; N], xdot: &[f64; N], out: &mut [f64; N]) {
                        psi(#c_arg, x, xdot, out)
                    }
                    fn energy(&self, x: &[f64; N], xdot: &[f64; N], out: &mut [f64; 2]) {
                        energy(#c_arg, x, xdot, out)
                    }
                    fn dynamics_terms(
                        &self,
                        x: &[f64; N],
                        xdot: &[f64; N],
                        g: &mut [[f64; M]; N],
                        gamma: &mut [f64; M],
                        mass: &mut [[f64; N]; N],
                        psi: &mut [f64; N],
                    ) {
                        dynamics_terms(#c_arg, x, xdot, g, gamma, mass, psi)
                    }
                    #fd_solve_impl
                }
            }
        }
        None => quote!(),
    };
    let robot_doc = doc_attrs(&format!(
        "The robot `{}` ({}), with its constants prepared for the kernels.\n\n\
         `{}::default()` uses the model's parameter values; `{}::new(&params)` others.",
        model.name,
        model.description,
        camel(&model.name),
        camel(&model.name)
    ));
    let desc = match sel {
        Some(s) => format!(
            " Kernels of `{}` ({}) for the scene `{}`: {}.",
            model.name,
            model.description,
            s.scene.name,
            s.scene.summary()
        ),
        None => format!(" Kernels of `{}`: {}.", model.name, model.description),
    };
    let (uses, kernels_impl) = match sel {
        Some(s) => (
            quote!(
                use rbss_runtime::{IkBlock, Structure};
            ),
            scene_impls(
                s,
                &robot,
                &d.dynamics,
                ik_order.clone(),
                &checks_impl,
                &fd_solve_impl,
                &ik_solve_impl,
            ),
        ),
        None => (
            quote!(
                use rbss_runtime::{IkBlock, Kernels, Structure};
            ),
            quote! {
                #dynamics_impl

                impl Kernels<N, M> for #robot {
                    #ik_order_doc
                    const IK_BLOCK_ORDER: usize = #ik_order;
                    fn structure(&self) -> &'static Structure {
                        &STRUCTURE
                    }
                    #ik_solve_impl
                    fn constraints(&self, x: &[f64; N], f: &mut [f64; M]) {
                        constraints(#c_arg, x, f)
                    }
                    #checks_impl
                    fn jacobian(&self, x: &[f64; N], g: &mut [[f64; M]; N]) {
                        jacobian(#c_arg, x, g)
                    }
                    fn jacobian_p(&self, x: &[f64; N], g: &mut [[f64; M]; N]) {
                        jacobian_p(#c_arg, x, g)
                    }
                    fn jacobian_ik(&self, x: &[f64; N], g: &mut [[f64; M]; N]) {
                        jacobian_ik(#c_arg, x, g)
                    }
                    fn gamma(&self, x: &[f64; N], xdot: &[f64; N], out: &mut [f64; M]) {
                        gamma(#c_arg, x, xdot, out)
                    }
                    fn constraints_jacobian_ik(&self, x: &[f64; N], f: &mut [f64; M], g: &mut [[f64; M]; N]) {
                        constraints_jacobian_ik(#c_arg, x, f, g)
                    }
                    fn constraints_jacobian_p(&self, x: &[f64; N], f: &mut [f64; M], g: &mut [[f64; M]; N]) {
                        constraints_jacobian_p(#c_arg, x, f, g)
                    }
                }
            },
        ),
    };
    let tokens = quote! {
        #![doc = #desc]

        #uses

        #doc_n
        pub const N: usize = #n_lit;
        #doc_m
        pub const M: usize = #m_lit;
        #doc_k
        pub const K: usize = #k_lit;

        #params_doc
        #snake
        #[derive(Debug, Clone, Copy, PartialEq)]
        pub struct Params {
            #(#fields)*
        }

        impl Default for Params {
            fn default() -> Self {
                Params { #(#defaults)* }
            }
        }

        #snake
        impl Params {
            #consts_doc
            pub fn consts(&self) -> [f64; K] {
                #(#const_stmts)*
                [#(#const_items),*]
            }
        }

        #structure_doc
        pub static STRUCTURE: Structure = Structure {
            name: #name_str,
            coordinates: &[#(#coords_ts),*],
            constraints: &[#(#cons_ts),*],
            actuated: #act,
            passive: #pas,
            outputs: #outs,
            ik_blocks: &[#(#blocks),*],
            home: &[#(#homes),*],
            gear: &[#(#gears),*],
        };

        #robot_doc
        #[derive(Debug, Clone, Copy)]
        pub struct #robot {
            /// Constants read by the kernels, from [`Params::consts`].
            pub c: [f64; K],
        }

        impl #robot {
            /// The robot with the given parameters.
            pub fn new(params: &Params) -> Self {
                #robot { c: params.consts() }
            }
        }

        impl Default for #robot {
            fn default() -> Self {
                Self::new(&Params::default())
            }
        }

        #mc_item

        #nb_item

        #(#kernel_items)*

        #kernels_impl
    };
    (tokens, reports)
}

/// A doc text with the intra-doc links to kernels a scene does not emit made plain code.
fn unlink_missing(doc: &str, kernels: &[&str]) -> String {
    let mut out = doc.to_string();
    for k in [
        "constraints",
        "jacobian",
        "jacobian_p",
        "jacobian_ik",
        "gamma",
        "mass_matrix",
        "psi",
        "energy",
    ] {
        if !kernels.contains(&k) {
            out = out.replace(&format!("[`{k}`]"), &format!("`{k}`"));
        }
    }
    out
}

/// The common order of the inverse-kinematics blocks (`0` when they differ or there are none):
/// the robot's `IK_BLOCK_ORDER`, so that the solvers compile one block size for it.
fn ik_block_order(blocks: &[(Vec<usize>, Vec<usize>)]) -> usize {
    match blocks.first() {
        Some((rows, _)) if blocks.iter().all(|(r, _)| r.len() == rows.len()) => rows.len(),
        _ => 0,
    }
}

fn ik_order_doc() -> TokenStream {
    doc_attrs(
        "The order of every inverse-kinematics block (0: they differ), known at generation: the solvers compile only this size.",
    )
}

/// The `impl`s of a scene's crate: the traits of `rbss_runtime::tasks` for its kernels and
/// its tasks (with those they imply), and nothing else, so a solver of another task does not
/// compile with it.
fn scene_impls(
    sel: &Selection<'_>,
    robot: &Ident,
    dynamics: &Option<derive::Dynamics>,
    ik_order: proc_macro2::Literal,
    checks_impl: &TokenStream,
    fd_solve_impl: &TokenStream,
    ik_solve_impl: &TokenStream,
) -> TokenStream {
    let has = |k: &str| sel.kernels.contains(&k);
    let c = quote!(&self.c);
    let ik_order_doc = ik_order_doc();
    let mut items = vec![quote! {
        impl rbss_runtime::tasks::Robot<N, M> for #robot {
            #ik_order_doc
            const IK_BLOCK_ORDER: usize = #ik_order;
            fn structure(&self) -> &'static Structure {
                &STRUCTURE
            }
            #ik_solve_impl
        }
    }];
    if has("constraints") {
        items.push(quote! {
            impl rbss_runtime::tasks::Constraints<N, M> for #robot {
                fn constraints(&self, x: &[f64; N], f: &mut [f64; M]) {
                    constraints(#c, x, f)
                }
                #checks_impl
            }
        });
    }
    if has("jacobian") {
        items.push(quote! {
            impl rbss_runtime::tasks::Jacobian<N, M> for #robot {
                fn jacobian(&self, x: &[f64; N], g: &mut [[f64; M]; N]) {
                    jacobian(#c, x, g)
                }
            }
        });
    }
    if let (true, Some(dy)) = (has("dynamics_terms"), dynamics) {
        let blocks = dy.mass_blocks.iter().map(|b| usize_list(b));
        items.push(quote! {
            impl rbss_runtime::tasks::EquationsOfMotion<N, M> for #robot {
                fn mass_blocks(&self) -> &'static [&'static [usize]] {
                    &[#(#blocks),*]
                }
                fn dynamics_terms(
                    &self,
                    x: &[f64; N],
                    xdot: &[f64; N],
                    g: &mut [[f64; M]; N],
                    gamma: &mut [f64; M],
                    mass: &mut [[f64; N]; N],
                    psi: &mut [f64; N],
                ) {
                    dynamics_terms(#c, x, xdot, g, gamma, mass, psi)
                }
                #fd_solve_impl
            }
        });
    }
    for task in sel.scene.all_tasks() {
        let tr = format_ident!("{}", task.trait_name());
        let body = match task {
            Task::Ik => quote! {
                fn constraints_jacobian_ik(&self, x: &[f64; N], f: &mut [f64; M], g: &mut [[f64; M]; N]) {
                    constraints_jacobian_ik(#c, x, f, g)
                }
            },
            Task::Fk => quote! {
                fn constraints_jacobian_p(&self, x: &[f64; N], f: &mut [f64; M], g: &mut [[f64; M]; N]) {
                    constraints_jacobian_p(#c, x, f, g)
                }
            },
            Task::Acceleration => quote! {
                fn gamma(&self, x: &[f64; N], xdot: &[f64; N], out: &mut [f64; M]) {
                    gamma(#c, x, xdot, out)
                }
            },
            Task::Energy => quote! {
                fn energy(&self, x: &[f64; N], xdot: &[f64; N], out: &mut [f64; 2]) {
                    energy(#c, x, xdot, out)
                }
            },
            Task::Velocity | Task::InverseDynamics | Task::ForwardDynamics | Task::Simulate => {
                quote!()
            }
        };
        items.push(quote! {
            impl rbss_runtime::tasks::#tr<N, M> for #robot {
                #body
            }
        });
    }
    quote!(#(#items)*)
}

/// What the solves need to know of the robot (`solve::Structure`): the entries of `G` and `M`,
/// with their values at the home (the generator's pivots are chosen there).
fn solve_structure<'a>(
    model: &'a Model,
    d: &'a Derivation,
    dy: Option<&derive::Dynamics>,
    home: &[f64],
) -> crate::solve::Structure<'a> {
    use crate::solve::Entry;
    let (n, m) = (d.n, d.m);
    let p: Vec<f64> = model.parameters.iter().map(|p| p.value).collect();
    let val = d.graph.eval_all(home, &vec![0.0; n], &p);
    let entry = |id: Id| -> Entry {
        match id {
            Graph::ZERO => Entry::Zero,
            _ if d.graph.is_number(id) => Entry::Number(val[id as usize]),
            _ => Entry::Var(val[id as usize]),
        }
    };
    let pattern = |e: &Vec<Vec<Id>>, rows: usize| -> Vec<Vec<Entry>> {
        (0..rows)
            .map(|i| (0..n).map(|j| entry(e[i][j])).collect())
            .collect()
    };
    crate::solve::Structure {
        n,
        m,
        outputs: &model.outputs,
        actuated: &model.actuated,
        ik_blocks: &d.ik_blocks,
        g: pattern(&d.g, m),
        mass: dy.map(|dy| pattern(&dy.mass, n)).unwrap_or_default(),
        fk_evals: None,
    }
}

/// An emitted kinematic solve (`ik_block_solve`, see `solve::rates`, or `forward_rates_solve`,
/// see `solve::forward_rates`) as items, and the trait method that forwards to it (of
/// `Kernels`, or of `tasks::Robot` in a scene's crate).
fn kinematic_solve_item(
    name: &str,
    e: crate::solve::Emitted,
    model: &Model,
    d: &Derivation,
) -> (TokenStream, TokenStream) {
    let orders = d.ik_blocks.iter().map(|(r, _)| r.len()).collect::<Vec<_>>();
    let (body, items) = (e.body, e.items);
    let allow = quote!(#[allow(clippy::neg_multiply, clippy::neg_cmp_op_on_partial_ord)]);
    if name == "ik_block_solve" {
        let doc = doc_attrs(&format!(
            "Solves inverse-kinematics block `block` (of {}, of orders `{orders:?}`): `K x[cols] = \
             rhs[rows] - G[rows, outputs] x[outputs]` (the last term only if `outputs`), `K = \
             G[rows, cols]`, over the structural non-zeros of `G` (see \
             `rbss_runtime::Kernels::ik_block_solve`). Writes `x[cols]` and returns `[cond(K), \
             residual]`: the exact 1-norm condition number for orders up to 3; beyond, `‖K‖₁ \
             max_c 1 / |u_cc|` from the pivots, the Hager/Higham estimate where that passes 1e3; \
             and `max |K x[cols] - rhs'|` over the block's rows. `None` where a \
             pivot fails its threshold test or the block is singular.",
            d.ik_blocks.len()
        ));
        return (
            quote! {
                #items

                #doc
                #allow
                pub fn ik_block_solve(
                    block: usize,
                    g: &[[f64; M]; N],
                    rhs: &[f64; M],
                    outputs: bool,
                    x: &mut [f64; N],
                ) -> Option<[f64; 2]> {
                    #body
                }
            },
            quote! {
                fn ik_block_solve(
                    &self,
                    block: usize,
                    g: &[[f64; M]; N],
                    rhs: &[f64; M],
                    outputs: bool,
                    x: &mut [f64; N],
                ) -> Option<[f64; 2]> {
                    ik_block_solve(block, g, rhs, outputs, x)
                }
            },
        );
    }
    let doc = doc_attrs(&format!(
        "Forward kinematics' linear system `J_p x_p = rhs - J_q x_q` (the actuated entries of `x` \
         given; `x_q = 0` unless `actuated`), solved by elimination onto the {} outputs over the \
         structural non-zeros of `G` ({} inverse-kinematics block(s) of order(s) `{orders:?}`; see \
         `rbss_runtime::Kernels::forward_rates_solve`). Writes the passive entries of `x` and \
         returns `[c, residual]`: `c` the 1-norm condition number of `J_p`, exact if `exact`, \
         else a rigorous upper bound (with the blocks' estimated inverse norms beyond order 3); \
         the residual `max |J_p x_p + J_q x_q - rhs|`. `None` where a block's condition number \
         passes 1e4, a pivot fails its threshold test or the reduced system is singular.",
        model.outputs.len(),
        d.ik_blocks.len()
    ));
    (
        quote! {
            #items

            #doc
            #allow
            pub fn forward_rates_solve(
                g: &[[f64; M]; N],
                rhs: &[f64; M],
                actuated: bool,
                exact: bool,
                x: &mut [f64; N],
            ) -> Option<[f64; 2]> {
                forward_rates_keep(g, rhs, actuated, exact, x, None)
            }

            /// [`forward_rates_solve`], keeping its factors in `store` (its first
            /// [`FR_STORE`] entries, when it has that many) for [`forward_rates_chord`].
            #allow
            fn forward_rates_keep(
                g: &[[f64; M]; N],
                rhs: &[f64; M],
                actuated: bool,
                exact: bool,
                x: &mut [f64; N],
                store: Option<&mut [f64]>,
            ) -> Option<[f64; 2]> {
                #body
            }
        },
        quote! {
            fn forward_rates_solve(
                &self,
                g: &[[f64; M]; N],
                rhs: &[f64; M],
                actuated: bool,
                exact: bool,
                x: &mut [f64; N],
            ) -> Option<[f64; 2]> {
                forward_rates_solve(g, rhs, actuated, exact, x)
            }
            fn forward_rates_keep(
                &self,
                g: &[[f64; M]; N],
                rhs: &[f64; M],
                exact: bool,
                x: &mut [f64; N],
                store: &mut [f64],
            ) -> Option<([f64; 2], bool)> {
                let kept = FR_CHORD && store.len() >= FR_STORE;
                forward_rates_keep(g, rhs, false, exact, x, kept.then_some(store))
                    .map(|r| (r, kept))
            }
            fn forward_rates_chord(
                &self,
                store: &[f64],
                rhs: &[f64; M],
                x: &mut [f64; N],
            ) -> Option<()> {
                forward_rates_chord(store, rhs, x)
            }
        },
    )
}

/// An emitted solve (`forward_dynamics_solve` or `inverse_dynamics_solve`) as items (its
/// per-block functions and the function itself) and the trait method that forwards to it.
fn solve_item(
    name: &str,
    e: crate::solve::Emitted,
    model: &Model,
    d: &Derivation,
) -> (TokenStream, TokenStream) {
    let orders = d.ik_blocks.iter().map(|(r, _)| r.len()).collect::<Vec<_>>();
    let (body, items) = (e.body, e.items);
    let allow = quote! {
        #[allow(
            clippy::too_many_arguments,
            clippy::neg_multiply,
            clippy::neg_cmp_op_on_partial_ord
        )]
    };
    if name == "forward_dynamics_solve" {
        let doc = doc_attrs(&format!(
            "Forward dynamics' saddle-point system `M Ẍ + Gᵀ lambda = force`, `G Ẍ = gamma`, \
             solved by elimination onto the outputs over the structural non-zeros of `G` and `M` \
             (see `rbss_runtime::Dynamics::forward_dynamics_solve`): {} inverse-kinematics \
             block(s) of order(s) `{orders:?}`, a reduced mass matrix of order {}. Returns `None` \
             where a pivot fails its threshold test, a block is singular or the reduced mass \
             matrix is not positive definite.",
            d.ik_blocks.len(),
            model.outputs.len()
        ));
        (
            quote! {
                #items

                #doc
                #allow
                pub fn forward_dynamics_solve(
                    g: &[[f64; M]; N],
                    mass: &[[f64; N]; N],
                    force: &[f64; N],
                    gamma: &[f64; M],
                    xddot: &mut [f64; N],
                    lambda: &mut [f64; M],
                ) -> Option<rbss_runtime::SolveConditioning> {
                    #body
                }
            },
            quote! {
                fn forward_dynamics_solve(
                    &self,
                    g: &[[f64; M]; N],
                    mass: &[[f64; N]; N],
                    force: &[f64; N],
                    gamma: &[f64; M],
                    xddot: &mut [f64; N],
                    lambda: &mut [f64; M],
                ) -> Option<rbss_runtime::SolveConditioning> {
                    forward_dynamics_solve(g, mass, force, gamma, xddot, lambda)
                }
            },
        )
    } else {
        let doc = doc_attrs(&format!(
            "Inverse dynamics' system `[S | Gᵀ] [U; -lambda] = b` (`b = M Ẍ - psi - Q`, formed \
             here over the structural non-zeros of `M`), solved \
             by block elimination onto the {} actuators over the structural non-zeros of `G` \
             (see `rbss_runtime::Dynamics::inverse_dynamics_solve`): {} inverse-kinematics \
             block(s) of order(s) `{orders:?}`. Writes `u` (length `N - M`) and `lambda`. \
             Returns `None` where a pivot fails its threshold test or a block or the reduced \
             system is singular, or `u` has another length.",
            model.actuated.len(),
            d.ik_blocks.len(),
        ));
        (
            quote! {
                #items

                #doc
                #allow
                pub fn inverse_dynamics_solve(
                    g: &[[f64; M]; N],
                    mass: &[[f64; N]; N],
                    psi: &[f64; N],
                    xddot: &[f64; N],
                    q_forces: Option<&[f64; N]>,
                    u: &mut [f64],
                    lambda: &mut [f64; M],
                ) -> Option<rbss_runtime::SolveConditioning> {
                    #body
                }
            },
            quote! {
                fn inverse_dynamics_solve(
                    &self,
                    g: &[[f64; M]; N],
                    mass: &[[f64; N]; N],
                    psi: &[f64; N],
                    xddot: &[f64; N],
                    q_forces: Option<&[f64; N]>,
                    u: &mut [f64],
                    lambda: &mut [f64; M],
                ) -> Option<rbss_runtime::SolveConditioning> {
                    inverse_dynamics_solve(g, mass, psi, xddot, q_forces, u, lambda)
                }
            },
        )
    }
}

/// `Params::consts`: the statements computing every slot of `consts` from the parameters it
/// needs (only those get a `let`), the slots' expressions, their documentation and `K`.
fn consts_tokens(
    model: &Model,
    g: &Graph,
    consts: &Consts,
    lets: Vec<(usize, TokenStream)>,
) -> (Vec<TokenStream>, Vec<TokenStream>, TokenStream, Literal) {
    // The parameters the slots read, and those the derived ones among them read.
    let mut needed = vec![false; model.parameters.len()];
    let mut stack: Vec<Id> = consts.slots.clone();
    let mut seen = std::collections::HashSet::new();
    while let Some(id) = stack.pop() {
        if !seen.insert(id) {
            continue;
        }
        match g.node(id) {
            Node::P(j) => needed[j as usize] = true,
            node => stack.extend(crate::graph::children(node)),
        }
    }
    for j in (0..needed.len()).rev() {
        if needed[j] {
            let mut mark = |k: usize| needed[k] = true;
            model.parameters[j].expr.for_each_param(&mut mark);
        }
    }
    // Temporaries must not shadow a parameter's name.
    let prefix = if model.parameters.iter().any(|p| {
        p.name
            .strip_prefix("k")
            .is_some_and(|r| !r.is_empty() && r.bytes().all(|b| b.is_ascii_digit()))
    }) {
        "k_"
    } else {
        "k"
    };
    let block = emit::emit_block(g, &consts.slots, prefix, &mut |id| match g.node(id) {
        Node::P(j) => {
            let id = Ident::new(&model.parameters[j as usize].name, Span::call_site());
            Some(quote!(#id))
        }
        _ if g.is_number(id) => Some(f64_tokens(g.eval(id, &[], &[], &[]))),
        _ => None,
    });
    let mut stmts: Vec<TokenStream> = lets
        .into_iter()
        .filter(|(j, _)| needed[*j])
        .map(|(_, t)| t)
        .collect();
    stmts.extend(block.stmts);
    let mut doc = String::from(
        "The parameter-only quantities the kernels read, computed once from the parameters:\n",
    );
    for (l, &id) in consts.slots.iter().enumerate() {
        doc.push_str(&format!(
            "\n- `c[{l}]` = {}",
            emit::node_string(g, id, model)
        ));
    }
    if consts.slots.is_empty() {
        doc = "The kernels read no parameter: this table is empty.".to_string();
    }
    (
        stmts,
        block.roots,
        doc_attrs(&doc),
        Literal::usize_unsuffixed(consts.slots.len()),
    )
}

/// True when the expression reads a parameter (a derived parameter).
fn mentions_param(e: &crate::model::Expr) -> bool {
    let mut any = false;
    e.for_each_param(&mut |_| any = true);
    any
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
