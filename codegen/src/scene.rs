//! Scenes: which tasks a program needs from a robot, and which parameters it folds into the code.
//!
//! A scene file (`scenes/NAME.toml`):
//!
//! ```toml
//! model = "../models/stewart_6ups.toml"   # relative to this file
//! tasks = ["ik"]                         # ik, fk, velocity, acceleration, inverse_dynamics,
//!                                        # forward_dynamics, simulate, energy, derivatives
//! freeze = "all"                         # or a list of parameter names; default: none
//! name = "stewart_6ups_ik"               # the crate's name; default: the file's stem
//! ```
//!
//! `rbss-codegen --scene FILE --out DIR` writes a crate with exactly the kernels the tasks'
//! solvers call (see [`Task::kernels`] in the catalogue, checked against `rbss_runtime::tasks`); the runtime
//! offers such a crate only the solvers of its tasks. Every error of the file is reported at
//! once, at its line and column, like the errors of a model file.

use std::path::{Component, Path, PathBuf};

use toml::Spanned;
use toml::de::{DeTable, DeValue};

use crate::diagnostics::{Diagnostic, Diagnostics, suggest};
use crate::model::{Model, Pos};
use crate::source::pos_of;

pub use crate::catalog::Task;

/// Which parameters a scene folds into the code.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Freeze {
    /// None: every parameter is read at run time (the default).
    None,
    /// `freeze = "all"`.
    All,
    /// `freeze = ["a", "b"]`: these names, each with where it is written (position, length).
    Names(Vec<(String, Pos, usize)>),
}

/// A parsed scene.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The scene's path as shown in messages and the header (e.g. `scenes/stewart_6ups_ik.toml`).
    pub path: String,
    /// The scene file's text.
    pub source: String,
    /// The generated crate's (and module's) name.
    pub name: String,
    /// The model file as written in the scene.
    pub model: String,
    /// Where the model's path is written (position, length).
    pub model_at: (Pos, usize),
    /// The directory `model` is relative to.
    pub base_dir: PathBuf,
    /// The tasks asked for, in the order written, without repeats.
    pub tasks: Vec<Task>,
    /// Where each task is written.
    pub task_at: Vec<(Pos, usize)>,
    pub freeze: Freeze,
}

const KEYS: [&str; 4] = ["model", "tasks", "freeze", "name"];

impl Scene {
    /// The model file's path: `model` resolved against the scene's directory, with `.` and
    /// `..` removed where they can be (so `scenes/../models/x.toml` is `models/x.toml`).
    pub fn model_path(&self) -> PathBuf {
        normalise(&self.base_dir.join(&self.model))
    }

    /// Every task the generated crate offers: those asked for and those they imply, in
    /// [`Task::ALL`] order.
    pub fn all_tasks(&self) -> Vec<Task> {
        let mut all: Vec<Task> = Vec::new();
        let mut stack = self.tasks.clone();
        while let Some(t) = stack.pop() {
            if !all.contains(&t) {
                all.push(t);
                stack.extend_from_slice(t.implies());
            }
        }
        all.sort();
        all
    }

    /// The kernels to generate, in the order of the full crate (the catalogue's).
    pub fn kernels(&self) -> Vec<&'static str> {
        let tasks = self.all_tasks();
        crate::catalog::KERNELS
            .iter()
            .map(|k| k.name)
            .filter(|k| tasks.iter().any(|t| t.kernels().contains(k)))
            .collect()
    }

    /// Whether any task needs the dynamics kernels.
    pub fn needs_dynamics(&self) -> bool {
        self.all_tasks().iter().any(|t| t.needs_dynamics())
    }

    /// Checks the scene against its model: every frozen name must be a parameter, and a task
    /// that needs masses needs a model with masses. Gives the per-parameter frozen flags.
    pub fn check(&self, model: &Model) -> Result<Vec<bool>, Diagnostics> {
        let mut items = Vec::new();
        let mut frozen = vec![false; model.parameters.len()];
        match &self.freeze {
            Freeze::None => {}
            Freeze::All => frozen.fill(true),
            Freeze::Names(names) => {
                for (name, pos, len) in names {
                    match model.parameters.iter().position(|p| &p.name == name) {
                        Some(j) => frozen[j] = true,
                        None => {
                            let mut d = Diagnostic::new(
                                *pos,
                                *len,
                                format!(
                                    "unknown parameter `{name}` in `freeze`: the model `{}` has no such parameter",
                                    model.name
                                ),
                                format!("not a parameter of {}", self.model_path().display()),
                            );
                            let hint = suggest(
                                name,
                                model
                                    .parameters
                                    .iter()
                                    .map(|p| (p.name.as_str(), Some(p.pos.line))),
                            )
                            .map(|h| h.replacen("(line", "(model line", 1))
                            .unwrap_or_else(|| {
                                format!(
                                    "the parameters are {}",
                                    quoted_list(model.parameters.iter().map(|p| p.name.as_str()))
                                )
                            });
                            d = d.with_help(hint);
                            items.push(d);
                        }
                    }
                }
            }
        }
        let has_masses = model.bodies.iter().any(|b| b.inertia.is_some());
        if !has_masses {
            for (t, &(pos, len)) in self.tasks.iter().zip(&self.task_at) {
                if t.needs_dynamics() {
                    items.push(
                        Diagnostic::new(
                            pos,
                            len,
                            format!(
                                "task `{}` needs the dynamics, but no body of the model `{}` has a mass",
                                t.name(),
                                model.name
                            ),
                            "needs masses",
                        )
                        .with_help(
                            "give the bodies `mass` and `inertia` in the model, or ask only for kinematics (ik, fk, velocity, acceleration)",
                        ),
                    );
                }
            }
        }
        // Passive degrees of freedom (fewer actuated coordinates than outputs): forward
        // kinematics and inverse dynamics need one actuator per degree of freedom, and the
        // runtime would refuse them at every call (`SolverError::Underactuated`).
        let m: usize = model.loops.iter().map(|l| l.equations()).sum();
        let dof = model.coordinates.len().saturating_sub(m);
        let actuated = model.actuated.len();
        if actuated < dof {
            for (t, &(pos, len)) in self.tasks.iter().zip(&self.task_at) {
                if matches!(t, Task::Fk | Task::InverseDynamics) {
                    let passive = dof - actuated;
                    items.push(
                        Diagnostic::new(
                            pos,
                            len,
                            format!(
                                "task `{}` needs one actuated coordinate per degree of freedom, but the model `{}` has {dof} degrees of freedom and {actuated} actuated ({passive} passive)",
                                t.name(),
                                model.name
                            ),
                            "needs square actuation",
                        )
                        .with_help(
                            "a model with passive degrees of freedom offers ik, the inverse rates (velocity, acceleration), forward_dynamics, simulate (projecting onto the constraints) and energy; for this task, list one coordinate per degree of freedom in the model's `actuated`",
                        ),
                    );
                }
            }
        }
        // Inverse kinematics solves for the other coordinates given the outputs.
        if model.outputs.is_empty() {
            for (t, &(pos, len)) in self.tasks.iter().zip(&self.task_at) {
                if *t == Task::Ik {
                    items.push(
                        Diagnostic::new(
                            pos,
                            len,
                            format!(
                                "task `ik` needs outputs, but the model `{}` names none",
                                model.name
                            ),
                            "needs `outputs`",
                        )
                        .with_help(
                            "inverse kinematics solves for the other coordinates given the outputs: name them in the model's `[robot] outputs` (forward and inverse dynamics, simulate and energy need none)",
                        ),
                    );
                }
            }
        }
        if items.is_empty() {
            Ok(frozen)
        } else {
            Err(Diagnostics::new(&self.path, &self.source, items))
        }
    }

    /// The scene as one header line: `tasks: ik, velocity (+ fk)  freeze: all`.
    pub fn summary(&self) -> String {
        let asked: Vec<&str> = self.tasks.iter().map(|t| t.name()).collect();
        let implied: Vec<&str> = self
            .all_tasks()
            .into_iter()
            .filter(|t| !self.tasks.contains(t))
            .map(|t| t.name())
            .collect();
        let mut s = format!("tasks: {}", asked.join(", "));
        if !implied.is_empty() {
            s.push_str(&format!(" (implied: {})", implied.join(", ")));
        }
        let freeze = match &self.freeze {
            Freeze::None => "none".to_string(),
            Freeze::All => "all".to_string(),
            Freeze::Names(n) => n
                .iter()
                .map(|(s, _, _)| s.as_str())
                .collect::<Vec<_>>()
                .join(", "),
        };
        s.push_str(&format!("  freeze: {freeze}"));
        s
    }
}

fn normalise(p: &Path) -> PathBuf {
    let mut out: Vec<Component> = Vec::new();
    for c in p.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => match out.last() {
                Some(Component::Normal(_)) => {
                    out.pop();
                }
                _ => out.push(c),
            },
            _ => out.push(c),
        }
    }
    if out.is_empty() {
        PathBuf::from(".")
    } else {
        out.iter().collect()
    }
}

fn quoted_list<'a>(names: impl Iterator<Item = &'a str>) -> String {
    let v: Vec<String> = names.map(|n| format!("`{n}`")).collect();
    match v.len() {
        0 => "none".to_string(),
        _ => v.join(", "),
    }
}

/// Span -> (position, length in characters, at least 1).
fn at(src: &str, span: std::ops::Range<usize>) -> (Pos, usize) {
    let pos = pos_of(src, span.start);
    let end = span.end.min(src.len()).max(span.start.min(src.len()));
    let len = src
        .get(span.start.min(src.len())..end)
        .map_or(1, |s| s.chars().take_while(|&c| c != '\n').count());
    (pos, len.max(1))
}

/// Parses a scene file. `path` is shown in messages; the model path is resolved against its
/// directory.
pub fn parse_scene(path: &str, source: &str) -> Result<Scene, Diagnostics> {
    let base_dir = Path::new(path)
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default();
    parse_scene_in(path, source, base_dir)
}

/// [`parse_scene`] with the model path relative to `base_dir`.
pub fn parse_scene_in(path: &str, source: &str, base_dir: PathBuf) -> Result<Scene, Diagnostics> {
    let err = |items: Vec<Diagnostic>| Diagnostics::new(path, source, items);
    let doc = match DeTable::parse(source) {
        Ok(doc) => doc,
        Err(e) => {
            let (pos, len) = at(source, e.span().unwrap_or(0..0));
            let msg = e.message().trim();
            let first = msg.lines().next().unwrap_or("invalid TOML").trim();
            return Err(err(vec![Diagnostic::new(
                pos,
                len,
                format!("invalid TOML: {first}"),
                "",
            )]));
        }
    };
    let mut items = Vec::new();
    let table = doc.get_ref();
    let mut model: Option<(String, (Pos, usize))> = None;
    let mut name: Option<(String, (Pos, usize))> = None;
    let mut tasks: Vec<Task> = Vec::new();
    let mut task_at: Vec<(Pos, usize)> = Vec::new();
    let mut tasks_seen = false;
    let mut freeze = Freeze::None;
    let string = |v: &Spanned<DeValue<'_>>| match v.get_ref() {
        DeValue::String(s) => Some(s.to_string()),
        _ => None,
    };
    for (key, value) in table.iter() {
        let k = key.get_ref().as_ref();
        let key_at = at(source, key.span());
        let val_at = at(source, value.span());
        match k {
            "model" => match string(value) {
                Some(s) if !s.is_empty() => model = Some((s, val_at)),
                _ => items.push(Diagnostic::new(
                    val_at.0,
                    val_at.1,
                    "`model` must be the path of a model file, a non-empty string",
                    "expected a string",
                )),
            },
            "name" => match string(value) {
                Some(s) if is_crate_name(&s) => match crate::parse::scene_name_conflict(&s) {
                    None => name = Some((s, val_at)),
                    Some(why) => items.push(
                        Diagnostic::new(
                            val_at.0,
                            val_at.1,
                            format!("`{s}` cannot name the scene's crate"),
                            "reserved by the generated crate",
                        )
                        .with_help(format!("{why}: choose another name, e.g. `{s}_scene`")),
                    ),
                },
                Some(s) => items.push(
                    Diagnostic::new(
                        val_at.0,
                        val_at.1,
                        format!("`{s}` is not a crate name"),
                        "not a crate name",
                    )
                    .with_help("use lower-case letters, digits and `_`, starting with a letter"),
                ),
                None => items.push(Diagnostic::new(
                    val_at.0,
                    val_at.1,
                    "`name` must be a string",
                    "expected a string",
                )),
            },
            "tasks" => {
                tasks_seen = true;
                let DeValue::Array(list) = value.get_ref() else {
                    items.push(
                        Diagnostic::new(
                            val_at.0,
                            val_at.1,
                            "`tasks` must be a list of task names",
                            "expected a list",
                        )
                        .with_help(format!("for example `tasks = [\"ik\"]`; {}", tasks_help())),
                    );
                    continue;
                };
                if list.is_empty() {
                    items.push(
                        Diagnostic::new(
                            val_at.0,
                            val_at.1,
                            "`tasks` is empty: a scene needs at least one task",
                            "no task",
                        )
                        .with_help(tasks_help()),
                    );
                }
                for item in list.iter() {
                    let (pos, len) = at(source, item.span());
                    let Some(s) = string(item) else {
                        items.push(Diagnostic::new(
                            pos,
                            len,
                            "a task must be a string",
                            "expected a string",
                        ));
                        continue;
                    };
                    match Task::from_name(&s) {
                        Some(t) if tasks.contains(&t) => items.push(Diagnostic::new(
                            pos,
                            len,
                            format!("task `{s}` is listed twice"),
                            "listed before",
                        )),
                        Some(t) => {
                            tasks.push(t);
                            task_at.push((pos, len));
                        }
                        None => items.push(
                            Diagnostic::new(
                                pos,
                                len,
                                format!("unknown task `{s}`"),
                                "not a task",
                            )
                            .with_help(task_hint(&s)),
                        ),
                    }
                }
            }
            "freeze" => match value.get_ref() {
                DeValue::String(s) if s == "all" => freeze = Freeze::All,
                DeValue::String(s) => items.push(
                    Diagnostic::new(
                        val_at.0,
                        val_at.1,
                        format!("`freeze = \"{s}\"`: the only string allowed is \"all\""),
                        "expected \"all\" or a list of parameter names",
                    )
                    .with_help(format!("to freeze one parameter, write `freeze = [\"{s}\"]`")),
                ),
                DeValue::Array(list) => {
                    let mut names: Vec<(String, Pos, usize)> = Vec::new();
                    for item in list.iter() {
                        let (pos, len) = at(source, item.span());
                        match string(item) {
                            Some(s) if names.iter().any(|(n, _, _)| *n == s) => {
                                items.push(Diagnostic::new(
                                    pos,
                                    len,
                                    format!("parameter `{s}` is listed twice in `freeze`"),
                                    "listed before",
                                ))
                            }
                            Some(s) => names.push((s, pos, len)),
                            None => items.push(Diagnostic::new(
                                pos,
                                len,
                                "a frozen parameter must be a string (its name)",
                                "expected a string",
                            )),
                        }
                    }
                    freeze = Freeze::Names(names);
                }
                _ => items.push(Diagnostic::new(
                    val_at.0,
                    val_at.1,
                    "`freeze` must be \"all\" or a list of parameter names",
                    "expected \"all\" or a list",
                )),
            },
            "outputs" => items.push(
                Diagnostic::new(key_at.0, key_at.1, "a scene cannot choose `outputs`", "not supported")
                    .with_help(
                        "the outputs are the model's: the inverse-kinematics blocks are built around them and need as many outputs as degrees of freedom",
                    ),
            ),
            _ => {
                let mut d = Diagnostic::new(
                    key_at.0,
                    key_at.1,
                    format!("unknown key `{k}` in a scene"),
                    "not a scene key",
                );
                d = d.with_help(suggest(k, KEYS.iter().map(|k| (*k, None))).unwrap_or_else(|| {
                    format!("a scene has the keys {}", quoted_list(KEYS.into_iter()))
                }));
                items.push(d);
            }
        }
    }
    let end = pos_of(source, source.trim_end().len());
    if model.is_none() && !items.iter().any(|d| d.message.contains("`model`")) {
        items.push(
            Diagnostic::new(end, 1, "the scene names no `model`", "")
                .with_help("add `model = \"../models/NAME.toml\"` (relative to the scene file)"),
        );
    }
    if !tasks_seen {
        items.push(
            Diagnostic::new(end, 1, "the scene names no `tasks`", "").with_help(format!(
                "add for example `tasks = [\"ik\"]`; {}",
                tasks_help()
            )),
        );
    }
    let name = match name {
        Some((n, _)) => n,
        None => {
            let stem = Path::new(path)
                .file_stem()
                .and_then(|s| s.to_str())
                .unwrap_or("")
                .to_string();
            if is_crate_name(&stem) {
                stem
            } else {
                items.push(
                    Diagnostic::new(
                        Pos { line: 1, col: 1 },
                        1,
                        format!("the scene file's name `{stem}` is not a crate name"),
                        "",
                    )
                    .with_help("add `name = \"my_scene\"` (lower-case letters, digits and `_`)"),
                );
                String::new()
            }
        }
    };
    match model {
        Some((model, model_at)) if items.is_empty() => Ok(Scene {
            path: path.to_string(),
            source: source.to_string(),
            name,
            model,
            model_at,
            base_dir,
            tasks,
            task_at,
            freeze,
        }),
        _ => Err(err(items)),
    }
}

fn is_crate_name(s: &str) -> bool {
    let mut chars = s.chars();
    matches!(chars.next(), Some(c) if c.is_ascii_lowercase())
        && chars.all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
}

fn tasks_help() -> String {
    format!(
        "the tasks are {}",
        quoted_list(Task::ALL.iter().map(|t| t.name()))
    )
}

/// `did you mean ...` for an unknown task: the closest name, or the short name of a solver's
/// long name (`inverse_kinematics` -> `ik`).
fn task_hint(s: &str) -> String {
    let long = [
        ("inverse_kinematics", Task::Ik),
        ("forward_kinematics", Task::Fk),
        ("simulation", Task::Simulate),
        ("integrate", Task::Simulate),
        ("dynamics", Task::ForwardDynamics),
    ];
    if let Some((_, t)) = long.iter().find(|(l, _)| *l == s) {
        return format!("did you mean `{}`?", t.name());
    }
    suggest(s, Task::ALL.iter().map(|t| (t.name(), None))).unwrap_or_else(tasks_help)
}

/// Reads a scene file (`path` as shown in messages), reports an unreadable file at 1:1.
pub fn read_scene(path: &str) -> Result<Scene, Diagnostics> {
    match std::fs::read_to_string(path) {
        Ok(source) => parse_scene(path, &source),
        Err(e) => Err(Diagnostics::new(
            path,
            String::new(),
            vec![Diagnostic::new(
                Pos { line: 1, col: 1 },
                1,
                format!("cannot read the scene file: {e}"),
                "",
            )],
        )),
    }
}

/// Reads the scene's model file; an unreadable one is reported at the scene's `model` value.
pub fn read_model_source(scene: &Scene) -> Result<(String, String), Diagnostics> {
    let path = scene.model_path();
    let shown = path.to_string_lossy().replace('\\', "/");
    std::fs::read_to_string(&path)
        .map(|s| (shown.clone(), s))
        .map_err(|e| {
            Diagnostics::new(
                &scene.path,
                &scene.source,
                vec![
                    Diagnostic::new(
                        scene.model_at.0,
                        scene.model_at.1,
                        format!("cannot read the model file `{shown}`: {e}"),
                        "this file",
                    )
                    .with_help("the path is relative to the scene file's directory"),
                ],
            )
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernels_of_each_task() {
        let scene = |tasks: Vec<Task>| Scene {
            path: "s.toml".into(),
            source: String::new(),
            name: "s".into(),
            model: "m.toml".into(),
            model_at: (Pos { line: 1, col: 1 }, 1),
            base_dir: PathBuf::from("scenes"),
            task_at: vec![(Pos { line: 1, col: 1 }, 1); tasks.len()],
            tasks,
            freeze: Freeze::None,
        };
        assert_eq!(
            scene(vec![Task::Ik]).kernels(),
            [
                "constraints",
                "closure_check",
                "constraints_jacobian_ik",
                "ik_block_solve"
            ]
        );
        let sim = scene(vec![Task::Simulate]);
        assert_eq!(
            sim.all_tasks(),
            [
                Task::Fk,
                Task::Velocity,
                Task::ForwardDynamics,
                Task::Simulate
            ]
        );
        assert_eq!(
            sim.kernels(),
            [
                "constraints",
                "closure_check",
                "jacobian",
                "constraints_jacobian_p",
                "dynamics_terms",
                "ik_block_solve",
                "forward_rates_solve",
                "forward_dynamics_solve"
            ]
        );
        assert_eq!(
            scene(vec![Task::Energy, Task::Acceleration]).kernels(),
            [
                "jacobian",
                "gamma",
                "energy",
                "ik_block_solve",
                "forward_rates_solve"
            ]
        );
        // The derivatives only where asked for: with forward dynamics (implied), not in `sim`.
        assert!(!sim.kernels().contains(&"dynamics_derivatives"));
        assert_eq!(
            scene(vec![Task::Derivatives]).kernels(),
            [
                "constraints",
                "dynamics_terms",
                "dynamics_derivatives",
                "forward_dynamics_solve"
            ]
        );
        assert_eq!(
            sim.model_path(),
            PathBuf::from("scenes/m.toml"),
            "relative to the scene's directory"
        );
        let up = Scene {
            model: "../models/x.toml".into(),
            ..sim
        };
        assert_eq!(up.model_path(), PathBuf::from("models/x.toml"));
    }

    #[test]
    fn parses_a_scene() {
        let s = parse_scene(
            "scenes/a.toml",
            "model = \"../models/five_bar.toml\"\ntasks = [\"ik\", \"simulate\"]\nfreeze = [\"L1\"]\n",
        )
        .unwrap();
        assert_eq!(s.name, "a");
        assert_eq!(s.tasks, [Task::Ik, Task::Simulate]);
        assert_eq!(
            s.freeze,
            Freeze::Names(vec![("L1".into(), Pos { line: 3, col: 11 }, 4)])
        );
        assert_eq!(
            s.summary(),
            "tasks: ik, simulate (implied: fk, velocity, forward_dynamics)  freeze: L1"
        );
    }
}
