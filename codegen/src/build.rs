//! The build-script API: generate a robot's kernel module into `OUT_DIR`, for a whole model
//! ([`compile`]) or for a scene ([`Scene`], [`compile_scene`]).
//!
//! ```no_run
//! // build.rs: a 1 kHz inverse-kinematics loop needs only `ik`, with the geometry folded in.
//! let out = std::path::PathBuf::from(std::env::var("OUT_DIR").unwrap());
//! rbss_codegen::build::Scene::new("models/stewart_6ups.toml")
//!     .tasks(&["ik"])
//!     .freeze_all()
//!     .compile(&out)
//!     .unwrap_or_else(|e| {
//!         eprintln!("{e}");
//!         std::process::exit(1)
//!     });
//! // lib.rs: include!(concat!(env!("OUT_DIR"), "/stewart_6ups_ik.rs"));
//! ```

use std::path::{Path, PathBuf};

use crate::generate::{Error, Generated, Options, generate, generate_scene};
use crate::scene;

/// Generates the kernels of the model at `model` into `out_dir/NAME.rs` and tells cargo to
/// rerun when the model changes. Include the result with
/// `include!(concat!(env!("OUT_DIR"), "/NAME.rs"));` in a crate that depends on
/// `rbss-runtime` and `libm`. Progress goes to stderr; on error, print the returned error
/// (every problem of the model file, rendered) and `exit(1)`.
pub fn compile(model: &str, out_dir: &Path) -> Result<(), Error> {
    compile_with(model, out_dir, &Options::default())
}

/// [`compile`] with options.
pub fn compile_with(model: &str, out_dir: &Path, opts: &Options) -> Result<(), Error> {
    println!("cargo:rerun-if-changed={model}");
    let source = crate::source::read_source(Path::new(model)).map_err(Error::Model)?;
    let generated = generate(model, &source, opts, &mut |s| {
        eprintln!("rbss-codegen: {s}")
    })?;
    // An imported model (`urdf = "..."`) is also rerun when its source changes (the path the
    // header records; an MJCF's included files are hashed, not watched).
    let module = generated.files.iter().map(|(_, text)| text.as_str());
    for text in module {
        let sources = text
            .lines()
            .take(5)
            .filter_map(|l| l.strip_prefix("// source: "));
        for line in sources {
            if let Some((path, _)) = line.split_once("  sha256: ") {
                println!("cargo:rerun-if-changed={path}");
            }
        }
    }
    // Warnings reach the user through cargo, one line each.
    for line in generated.report.warnings.lines().filter(|l| !l.is_empty()) {
        println!("cargo:warning={line}");
    }
    write_module(&generated, out_dir)
}

/// Generates the kernels of the scene file `scene` (see [`crate::scene`]) into
/// `out_dir/NAME.rs` (`NAME` the scene's name) and tells cargo to rerun when the scene or its
/// model changes.
pub fn compile_scene(scene: &str, out_dir: &Path) -> Result<(), Error> {
    println!("cargo:rerun-if-changed={scene}");
    let scene = scene::read_scene(scene).map_err(Error::Model)?;
    compile_parsed(&scene, out_dir)
}

fn compile_parsed(scene: &scene::Scene, out_dir: &Path) -> Result<(), Error> {
    println!("cargo:rerun-if-changed={}", scene.model_path().display());
    // The module is included into the user's crate, which depends on the runtime itself.
    let generated = generate_scene(scene, "rbss-runtime", &mut |s| {
        eprintln!("rbss-codegen: {s}")
    })?;
    write_module(&generated, out_dir)
}

/// A scene written in a build script instead of a file: the same keys, the same checks and
/// errors (reported against the scene as TOML, `build.rs scene NAME`).
#[derive(Debug, Clone)]
pub struct Scene {
    model: String,
    name: Option<String>,
    tasks: Vec<String>,
    freeze: Option<Vec<String>>,
    freeze_all: bool,
}

impl Scene {
    /// A scene of the model file `model` (relative to the build script's directory, the
    /// package root), with no task yet.
    pub fn new(model: &str) -> Self {
        Scene {
            model: model.to_string(),
            name: None,
            tasks: Vec::new(),
            freeze: None,
            freeze_all: false,
        }
    }

    /// The module's name (default: the model's file stem and the tasks, `stewart_6ups_ik`).
    pub fn name(mut self, name: &str) -> Self {
        self.name = Some(name.to_string());
        self
    }

    /// Adds tasks: `ik`, `fk`, `velocity`, `acceleration`, `inverse_dynamics`,
    /// `forward_dynamics`, `simulate`, `energy`.
    pub fn tasks(mut self, tasks: &[&str]) -> Self {
        self.tasks.extend(tasks.iter().map(|t| t.to_string()));
        self
    }

    /// Folds these parameters into the kernels; the others stay run-time `Params`.
    pub fn freeze(mut self, params: &[&str]) -> Self {
        self.freeze
            .get_or_insert_with(Vec::new)
            .extend(params.iter().map(|p| p.to_string()));
        self
    }

    /// Folds every parameter into the kernels.
    pub fn freeze_all(mut self) -> Self {
        self.freeze_all = true;
        self
    }

    /// The scene as a scene file's text.
    pub fn to_toml(&self) -> String {
        let q = |s: &str| format!("{s:?}");
        let list = |v: &[String]| v.iter().map(|s| q(s)).collect::<Vec<_>>().join(", ");
        let name = self.name.clone().unwrap_or_else(|| {
            let stem = Path::new(&self.model)
                .file_stem()
                .and_then(|s| s.to_str())
                .unwrap_or("scene");
            std::iter::once(stem.to_string())
                .chain(self.tasks.iter().cloned())
                .collect::<Vec<_>>()
                .join("_")
        });
        let mut s = format!(
            "model = {}\nname = {}\ntasks = [{}]\n",
            q(&self.model),
            q(&name),
            list(&self.tasks)
        );
        if self.freeze_all {
            s.push_str("freeze = \"all\"\n");
        } else if let Some(f) = &self.freeze {
            s.push_str(&format!("freeze = [{}]\n", list(f)));
        }
        s
    }

    /// Generates the scene's module into `out_dir/NAME.rs`; include it with
    /// `include!(concat!(env!("OUT_DIR"), "/NAME.rs"));` in a crate that depends on
    /// `rbss-runtime` and `libm`.
    pub fn compile(&self, out_dir: &Path) -> Result<(), Error> {
        let text = self.to_toml();
        let scene =
            scene::parse_scene_in("build.rs scene", &text, PathBuf::new()).map_err(Error::Model)?;
        compile_parsed(&scene, out_dir)
    }
}

/// Writes the crate's module file as `out_dir/NAME.rs`, for `include!`.
fn write_module(generated: &Generated, out_dir: &Path) -> Result<(), Error> {
    let module = generated
        .files
        .iter()
        .find(|(p, _)| {
            p.to_string_lossy()
                .ends_with(&format!("{}.rs", generated.name))
        })
        .map(|(_, c)| c.clone())
        .unwrap_or_default();
    // The module file carries an inner doc attribute; strip it so `include!` works anywhere.
    let module: String = module
        .lines()
        .filter(|l| !l.starts_with("//!"))
        .map(|l| format!("{l}\n"))
        .collect();
    let path = out_dir.join(format!("{}.rs", generated.name));
    let tmp = path.with_extension("rbss-tmp");
    std::fs::write(&tmp, module).map_err(|e| Error::Io(tmp.clone(), e))?;
    std::fs::rename(&tmp, &path).map_err(|e| Error::Io(path.clone(), e))?;
    Ok(())
}
