//! `--model-file PATH`: a robot from a model file, without rebuilding the command.
//!
//! The first run generates the robot's crate (`rbss-codegen --out`), writes a `cdylib` crate
//! around it (the C ABI of `ffi/include/rbss.h` and [`crate::export_command!`] (in `crate::entry`), two lines),
//! compiles only that with cargo, and keeps the library in a cache entry; every run then loads
//! the library (dlopen) and lets it run the subcommand on its robot through
//! [`crate::cli::run_with_model`], the code the robots compiled into the command use.
//!
//! The cache entry's key is a SHA-256 of what the library is made from: the model file's
//! bytes and path, the sources it is compiled from (the rbss sources this command was built
//! from: runtime, ffi, codegen, the command's library, the generated crates, the lock file),
//! the versions of rbss and of the C ABI, and `rustc -vV`. Another model, another source or
//! another compiler is another entry. An entry is complete when its stamp (`ok`, holding the
//! key, written last) is there; an entry whose library does not load, or loads with another
//! ABI version or key, is rebuilt. Builds of one entry are serialised by a file lock.
//!
//! `rbss bench --model-file` uses the model's studies variant ([`Variant::Studies`]: the
//! command's library with its feature `studies`, the key with a part of its own), built on
//! its first use only, so that the other subcommands' first run does not compile the studies
//! (BENCHMARKS.md, issue 22).
//!
//! Where: `$RBSS_CACHE`, else `$XDG_CACHE_HOME/rbss`, else `~/.cache/rbss`; cargo's build
//! directory for the entries (shared by all, so the runtime and its dependencies are compiled
//! once) is `$RBSS_CACHE_TARGET`, else `target/` in the cache.

use std::ffi::{CString, c_char, c_int};
use std::fs;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

use sha2::{Digest, Sha256};

/// The C ABI version the loader accepts.
pub use rbss_ffi::ABI_VERSION;

/// The rbss sources this command was built from.
const SOURCE: &str = env!("CARGO_MANIFEST_DIR");

/// Which library of a model: the plain one (every subcommand but the studies) or the one
/// that also runs `rbss bench` (the command's library with its feature `studies`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Variant {
    Plain,
    Studies,
}

/// The cache: where entries live, where cargo builds, with which tools.
#[derive(Debug, Clone)]
pub struct Cache {
    /// The entries (`DIR/robots/KEY/`).
    pub dir: PathBuf,
    /// cargo's target directory for the builds.
    pub target: PathBuf,
    /// The rbss sources the libraries are compiled from.
    pub source: PathBuf,
    /// The generator (`rbss-codegen`).
    pub codegen: PathBuf,
    /// cargo.
    pub cargo: PathBuf,
}

impl Cache {
    /// The cache the environment names (see the module documentation).
    pub fn from_env() -> Result<Self, String> {
        let dir = match std::env::var_os("RBSS_CACHE") {
            Some(d) if !d.is_empty() => PathBuf::from(d),
            _ => match (std::env::var_os("XDG_CACHE_HOME"), std::env::var_os("HOME")) {
                (Some(x), _) if !x.is_empty() => PathBuf::from(x).join("rbss"),
                (_, Some(h)) if !h.is_empty() => PathBuf::from(h).join(".cache").join("rbss"),
                _ => {
                    return Err("no cache directory: set RBSS_CACHE (or HOME)".to_string());
                }
            },
        };
        let target = match std::env::var_os("RBSS_CACHE_TARGET") {
            Some(t) if !t.is_empty() => PathBuf::from(t),
            _ => dir.join("target"),
        };
        let codegen = match std::env::var_os("RBSS_CODEGEN") {
            Some(c) if !c.is_empty() => PathBuf::from(c),
            _ => {
                let beside = std::env::current_exe()
                    .ok()
                    .and_then(|e| e.parent().map(|p| p.join("rbss-codegen")));
                match beside {
                    Some(p) if p.is_file() => p,
                    _ => PathBuf::from("rbss-codegen"),
                }
            }
        };
        let cargo = match std::env::var_os("CARGO") {
            Some(c) if !c.is_empty() => PathBuf::from(c),
            _ => PathBuf::from("cargo"),
        };
        Ok(Self {
            dir,
            target,
            source: PathBuf::from(SOURCE),
            codegen,
            cargo,
        })
    }
}

/// A robot's library, loaded.
pub struct Library {
    lib: libloading::Library,
    /// The library file (in its cache entry).
    pub path: PathBuf,
    /// Whether this load built it (false: from the cache).
    pub built: bool,
}

impl Library {
    /// Runs the command line `args` (program name first) in the library: the exit status.
    pub fn command(&self, args: &[String]) -> Result<u8, String> {
        let c_args: Vec<CString> = args
            .iter()
            .map(|a| CString::new(a.as_str()).map_err(|_| format!("argument {a:?} holds a NUL")))
            .collect::<Result<_, _>>()?;
        let ptrs: Vec<*const c_char> = c_args.iter().map(|a| a.as_ptr()).collect();
        let argc = c_int::try_from(ptrs.len()).map_err(|_| "too many arguments".to_string())?;
        // SAFETY: `rbss_command` has this signature in every library `export_command!` makes
        // (the ABI version and key were checked at load); `ptrs` outlives the call.
        let code = unsafe {
            let f = self
                .lib
                .get::<unsafe extern "C" fn(c_int, *const *const c_char) -> c_int>(
                    b"rbss_command\0",
                )
                .map_err(|e| format!("{}: {e}", self.path.display()))?;
            f(argc, ptrs.as_ptr())
        };
        Ok(u8::try_from(code).unwrap_or(1))
    }

    /// The library's raw handle, for the C ABI's functions (`ffi/include/rbss.h`).
    pub fn raw(&self) -> &libloading::Library {
        &self.lib
    }
}

/// `rbss SUBCOMMAND --model-file PATH ...`: the library of PATH (from the cache or built now)
/// runs the command line; the exit status.
pub fn run(path: &str, variant: Variant, args: &[String]) -> Result<u8, String> {
    let cache = Cache::from_env()?;
    let lib = load_variant(&cache, Path::new(path), variant, &mut |m| {
        crate::errln!("rbss: {m}")
    })?;
    lib.command(args)
}

/// The library of the model file `model`: loaded from its cache entry, or built into it first
/// (and rebuilt when the entry is incomplete, corrupt or of another version). `progress`
/// gets a line per step of a build.
pub fn load(
    cache: &Cache,
    model: &Path,
    progress: &mut dyn FnMut(&str),
) -> Result<Library, String> {
    load_variant(cache, model, Variant::Plain, progress)
}

/// [`load`] of the given variant of the model's library.
pub fn load_variant(
    cache: &Cache,
    model: &Path,
    variant: Variant,
    progress: &mut dyn FnMut(&str),
) -> Result<Library, String> {
    let bytes = fs::read(model).map_err(|e| format!("{}: cannot read: {e}", model.display()))?;
    let key = key(cache, model, &bytes, variant)?;
    let entry = cache.dir.join("robots").join(&key);
    fs::create_dir_all(cache.dir.join("robots"))
        .map_err(|e| format!("{}: cannot create: {e}", cache.dir.display()))?;
    // One build of an entry at a time (another process waits, then finds it built).
    let lock_path = cache.dir.join("robots").join(format!("{key}.lock"));
    let lock = fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&lock_path)
        .map_err(|e| format!("{}: cannot open: {e}", lock_path.display()))?;
    lock.lock()
        .map_err(|e| format!("{}: cannot lock: {e}", lock_path.display()))?;
    if entry.join("ok").is_file() {
        match open(&entry, &key) {
            Ok(lib) => return Ok(lib),
            Err(e) => {
                progress(&format!(
                    "cache entry {} unusable ({e}); rebuilding it",
                    entry.display()
                ));
            }
        }
    } else if entry.exists() {
        progress(&format!(
            "cache entry {} incomplete; rebuilding it",
            entry.display()
        ));
    }
    if entry.exists() {
        fs::remove_dir_all(&entry)
            .map_err(|e| format!("{}: cannot remove: {e}", entry.display()))?;
    }
    build(cache, model, &key, variant, &entry, progress)?;
    let mut lib = open(&entry, &key)?;
    lib.built = true;
    Ok(lib)
}

/// Loads the entry's library and checks its ABI version and key.
fn open(entry: &Path, key: &str) -> Result<Library, String> {
    let stamp = fs::read_to_string(entry.join("ok")).map_err(|e| format!("stamp: {e}"))?;
    if stamp.trim() != key {
        return Err("its stamp names another key".to_string());
    }
    let path = entry.join(library_file());
    // SAFETY: a library this module built from the rbss sources (its initialisers are Rust's
    // own); the symbols are checked before use.
    let lib = unsafe { libloading::Library::new(&path) }
        .map_err(|e| format!("{}: {e}", path.display()))?;
    // SAFETY: both functions take nothing and return a value (rbss.h, export_command!).
    unsafe {
        let version = lib
            .get::<unsafe extern "C" fn() -> u32>(b"rbss_abi_version\0")
            .map_err(|e| format!("{}: {e}", path.display()))?();
        if version != ABI_VERSION {
            return Err(format!(
                "{}: C ABI version {version}, this rbss loads {ABI_VERSION}",
                path.display()
            ));
        }
        let got = lib
            .get::<unsafe extern "C" fn() -> *const c_char>(b"rbss_cache_key\0")
            .map_err(|e| format!("{}: {e}", path.display()))?();
        let got = std::ffi::CStr::from_ptr(got).to_string_lossy();
        if got != key {
            return Err(format!("{}: built for the key {got}", path.display()));
        }
    }
    Ok(Library {
        lib,
        path,
        built: false,
    })
}

/// The library's file name in an entry.
fn library_file() -> String {
    format!(
        "{}robot{}",
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    )
}

/// The entry's key: see the module documentation.
fn key(cache: &Cache, model: &Path, bytes: &[u8], variant: Variant) -> Result<String, String> {
    let mut h = Sha256::new();
    let mut part = |label: &str, data: &[u8]| {
        h.update(label.as_bytes());
        h.update((data.len() as u64).to_le_bytes());
        h.update(data);
    };
    part("model", bytes);
    part("path", model.to_string_lossy().as_bytes());
    part("rbss", env!("CARGO_PKG_VERSION").as_bytes());
    part("abi", &ABI_VERSION.to_le_bytes());
    part("sources", &sources_hash(&cache.source)?);
    let rustc = rustc_version(cache)?;
    part("rustc", rustc.as_bytes());
    // The plain library's key has no such part (its entries stay valid).
    if variant == Variant::Studies {
        part("variant", b"studies");
    }
    let digest = h.finalize();
    Ok(digest[..16].iter().map(|b| format!("{b:02x}")).collect())
}

/// The hash of the rbss sources a library is compiled from.
fn sources_hash(root: &Path) -> Result<[u8; 32], String> {
    if !root.join("runtime").is_dir() {
        return Err(format!(
            "{}: the rbss sources this command was built from are gone; --model-file compiles \
             the model against them",
            root.display()
        ));
    }
    let mut files = Vec::new();
    for f in ["Cargo.toml", "Cargo.lock", "build.rs"] {
        files.push(root.join(f));
    }
    for d in [
        "src",
        "runtime",
        "ffi",
        "codegen/src",
        "expr/src",
        "generated",
    ] {
        collect(&root.join(d), &mut files);
    }
    files.sort();
    let mut h = Sha256::new();
    for f in &files {
        // A file that vanished between the listing and the read counts as empty.
        let data = fs::read(f).unwrap_or_default();
        h.update(
            f.strip_prefix(root)
                .unwrap_or(f)
                .to_string_lossy()
                .as_bytes(),
        );
        h.update((data.len() as u64).to_le_bytes());
        h.update(&data);
    }
    Ok(h.finalize().into())
}

/// The `.rs`, `.toml` and `.h` files under `dir` (no `target/`).
fn collect(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(rd) = fs::read_dir(dir) else { return };
    for e in rd.flatten() {
        let p = e.path();
        match e.file_type() {
            Ok(t) if t.is_dir() && e.file_name() != "target" => collect(&p, out),
            Ok(t)
                if t.is_file()
                    && p.extension()
                        .is_some_and(|x| x == "rs" || x == "toml" || x == "h") =>
            {
                out.push(p)
            }
            _ => {}
        }
    }
}

/// `rustc -vV` of the toolchain cargo uses (`$RUSTC`, else `rustc`).
fn rustc_version(cache: &Cache) -> Result<String, String> {
    let rustc = std::env::var_os("RUSTC")
        .filter(|r| !r.is_empty())
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            // The rustc beside cargo when cargo is given by path (a toolchain's bin/).
            match cache.cargo.parent() {
                Some(p) if p.join("rustc").is_file() => p.join("rustc"),
                _ => PathBuf::from("rustc"),
            }
        });
    let out = Command::new(&rustc).arg("-vV").output().map_err(|e| {
        format!(
            "cannot run `{}` ({e}): --model-file compiles the robot, which needs a Rust \
             toolchain (https://rustup.rs)",
            rustc.display()
        )
    })?;
    if !out.status.success() {
        return Err(format!("`{} -vV` failed", rustc.display()));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Generates and compiles the entry: in `KEY.building/`, renamed to `KEY/` when complete
/// (removed when not).
fn build(
    cache: &Cache,
    model: &Path,
    key: &str,
    variant: Variant,
    entry: &Path,
    progress: &mut dyn FnMut(&str),
) -> Result<(), String> {
    let tmp = entry.with_extension("building");
    if tmp.exists() {
        fs::remove_dir_all(&tmp).map_err(|e| format!("{}: cannot remove: {e}", tmp.display()))?;
    }
    let built = build_in(cache, model, key, variant, &tmp, entry, progress);
    if built.is_err() {
        let _ = fs::remove_dir_all(&tmp);
    }
    built
}

fn build_in(
    cache: &Cache,
    model: &Path,
    key: &str,
    variant: Variant,
    tmp: &Path,
    entry: &Path,
    progress: &mut dyn FnMut(&str),
) -> Result<(), String> {
    let t0 = std::time::Instant::now();
    let robot_dir = tmp.join("robot");
    progress(&format!("generating {} ...", model.display()));
    let out = Command::new(&cache.codegen)
        .arg("--out")
        .arg(&robot_dir)
        .arg(model)
        .output()
        .map_err(|e| {
            format!(
                "cannot run the generator `{}` ({e}): build it (`cargo build --release -p \
                 rbss-codegen`) or name it with RBSS_CODEGEN",
                cache.codegen.display()
            )
        })?;
    if !out.status.success() {
        // The generator's own diagnostics name the file, line and column.
        return Err(String::from_utf8_lossy(&out.stderr).trim_end().to_string());
    }
    let manifest = fs::read_to_string(robot_dir.join("rbss-manifest.toml"))
        .map_err(|e| format!("{}: no manifest: {e}", robot_dir.display()))?;
    let manifest = toml::de::DeTable::parse(&manifest)
        .map_err(|e| format!("{}: {}", robot_dir.display(), e.message()))?;
    let value = |k: &str| {
        manifest
            .get_ref()
            .iter()
            .find(|(key, _)| key.get_ref().as_ref() == k)
            .map(|(_, v)| v.get_ref().clone())
    };
    let field = |k: &str| match value(k) {
        Some(toml::de::DeValue::String(s)) => Ok(s.into_owned()),
        _ => Err(format!(
            "{}: the manifest has no `{k}`",
            robot_dir.display()
        )),
    };
    let (name, ty) = (field("name")?, field("type")?);
    if !matches!(value("dynamics"), Some(toml::de::DeValue::Boolean(true))) {
        return Err(format!(
            "{}: robot `{name}` has no dynamics (no masses): the subcommands of --model-file \
             need them",
            model.display()
        ));
    }
    let lib_dir = tmp.join("lib");
    fs::create_dir_all(&lib_dir).map_err(|e| format!("{}: {e}", lib_dir.display()))?;
    let src = |p: &str| toml_path(&cache.source.join(p));
    let cargo_toml = format!(
        "# Written by rbss --model-file: the robot `{name}` ({model}) as a library.\n\
         [package]\n\
         name = \"rbss-robot-{name}\"\n\
         version = \"0.0.0\"\n\
         edition = \"2024\"\n\
         publish = false\n\
         \n\
         [lib]\n\
         name = \"rbss_robot_{key}\"\n\
         path = \"lib.rs\"\n\
         crate-type = [\"cdylib\"]\n\
         \n\
         [dependencies]\n\
         {name} = {{ path = \"../robot\" }}\n\
         # Without the feature `robots`: of the command's built-in robots only stewart_6ups\n\
         # (paper, stress) is compiled in, the others' solvers are not (build.rs).\n\
         rbss = {{ path = {root}, default-features = false{features} }}\n\
         rbss-ffi = {{ path = {ffi} }}\n\
         rbss-runtime = {{ path = {runtime} }}\n\
         \n\
         [workspace]\n\
         \n\
         # The profile of the rbss workspace (its Cargo.toml).\n\
         [profile.release]\n\
         debug = \"line-tables-only\"\n\
         \n\
         [profile.release.package.\"*\"]\n\
         codegen-units = 4\n\
         \n\
         # The library itself without line tables: 0.5 s less of its 6 to 7 s of compile\n\
         # (6-UPS; BENCHMARKS.md, issue 22); its panics are caught at the C boundary anyway.\n\
         [profile.release.package.rbss-robot-{name}]\n\
         debug = false\n",
        model = model.display(),
        root = src(""),
        ffi = src("ffi"),
        runtime = src("runtime"),
        features = match variant {
            Variant::Plain => "",
            Variant::Studies => ", features = [\"studies\"]",
        },
    );
    let lib_rs = format!(
        "//! Written by rbss --model-file: the robot `{name}` behind the C ABI (rbss.h) and the \
         command.\n\
         rbss_ffi::export!({name}::{ty}, dynamics);\n\
         rbss::export_command!({name}::{ty}, \"{key}\");\n"
    );
    fs::write(lib_dir.join("Cargo.toml"), cargo_toml).map_err(|e| e.to_string())?;
    fs::write(lib_dir.join("lib.rs"), lib_rs).map_err(|e| e.to_string())?;
    // The workspace's versions of every dependency (no resolution, no network).
    let lock = cache.source.join("Cargo.lock");
    fs::copy(&lock, lib_dir.join("Cargo.lock"))
        .map_err(|e| format!("{}: cannot copy: {e}", lock.display()))?;

    progress(&format!(
        "compiling robot `{name}`{} (cargo, in {}) ...",
        match variant {
            Variant::Plain => "",
            Variant::Studies => " with the studies",
        },
        cache.target.display()
    ));
    let out = Command::new(&cache.cargo)
        .args(["build", "--release", "--quiet", "--manifest-path"])
        .arg(lib_dir.join("Cargo.toml"))
        .env("CARGO_TARGET_DIR", &cache.target)
        .env_remove("CARGO_BUILD_TARGET_DIR")
        .output()
        .map_err(|e| {
            format!(
                "cannot run cargo `{}` ({e}): --model-file compiles the robot, which needs a \
                 Rust toolchain (https://rustup.rs)",
                cache.cargo.display()
            )
        })?;
    if !out.status.success() {
        return Err(format!(
            "compiling robot `{name}` failed:\n{}",
            String::from_utf8_lossy(&out.stderr).trim_end()
        ));
    }
    let built = cache.target.join("release").join(format!(
        "{}rbss_robot_{key}{}",
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    ));
    fs::copy(&built, tmp.join(library_file()))
        .map_err(|e| format!("{}: cannot copy: {e}", built.display()))?;
    // The stamp last: the entry is complete once it is there.
    let mut stamp = fs::File::create(tmp.join("ok")).map_err(|e| e.to_string())?;
    writeln!(stamp, "{key}").map_err(|e| e.to_string())?;
    drop(stamp);
    fs::rename(tmp, entry).map_err(|e| format!("{}: cannot rename: {e}", entry.display()))?;
    // The copy in cargo's directory is not needed any more.
    let _ = fs::remove_file(&built);
    progress(&format!(
        "robot `{name}` compiled in {:.1} s; cached in {}",
        t0.elapsed().as_secs_f64(),
        entry.display()
    ));
    Ok(())
}

/// `p` as a TOML basic string.
fn toml_path(p: &Path) -> String {
    let s = p.to_string_lossy();
    format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""))
}
