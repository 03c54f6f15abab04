//! `--model-file PATH`: a robot from a model file, without rebuilding the command.
//!
//! The first run generates the robot's crate (the generator `rbss_codegen`, in this process),
//! writes the file that includes it in the workspace's library crate `robot-lib/` (the C ABI of
//! `ffi/include/rbss.h` and [`crate::export_command!`] (in `crate::entry`), two lines),
//! compiles that crate with cargo (`-p rbss-robot-lib`, `RBSS_ROBOT_LIB` naming the file), and
//! keeps the library in a cache entry; every run then loads the library (dlopen) and lets it
//! run the subcommand on its robot through [`crate::cli::run_with_model`], the code the robots
//! compiled into the command use. The library crate is a member of the rbss workspace and
//! depends on the rbss crates as the command does, so that in the command's own build
//! directory cargo finds them compiled: a first run compiles the robot alone.
//!
//! The cache entry's key is a SHA-256 of what the library is made from ([`Inputs`]): the model
//! file's canonical path and the bytes of the model file and of every file it includes (the
//! URDF, MJCF or SDF source it names, the MJCF `<include>`s), read once; the sources it is
//! compiled from (the rbss sources this command was built from: runtime, ffi, codegen, the
//! command's library, the generated crates, the lock file), the versions of rbss and of the C
//! ABI, and `rustc -vV`. Another model, another source or another compiler is another entry.
//! The build checks that the generator read the bytes the key hashed (the hashes it records in
//! the crate), so an edit during a build is an error, never an entry of another robot.
//!
//! An entry is complete when its stamp (`ok`: the key, the library's size and SHA-256, written
//! and flushed last, before the entry is renamed in) is there; every load checks the library
//! against its stamp before mapping it, and an entry that does not verify, does not load or
//! loads with another ABI version or key is rebuilt. A verified entry is loaded without a
//! lock (a read-only cache works); builds of one entry are serialised by a file lock, with a
//! progress line while waiting. Without a toolchain or the sources, the most recently used
//! verified entry of the same model files (and rbss version) is used. Each load marks its
//! entry used (the stamp's time); builds prune the least recently used entries beyond the
//! size bound (`RBSS_CACHE_MAX_SIZE`, 2 GiB), and `rbss cache list|prune|clear` shows and
//! shrinks the cache (docs/cache.md).
//!
//! A model has three libraries ([`Variant`]), each built on its first use: the plain one (the
//! robot without its derivative kernel, behind the command alone) for the subcommands that take
//! no derivatives, so that their first run does not compile the largest kernel; the full one
//! (every kernel and the C ABI) for `rbss linearize`, `rbss id-derivatives` and `rbss library`;
//! the studies one for `rbss bench --model-file` (the full one with the command's feature
//! `studies`, so that the other subcommands' first run does not compile the studies: BENCHMARKS.md,
//! issue 22). The key has a part naming the variant.
//!
//! Where: `$RBSS_CACHE`, else `$XDG_CACHE_HOME/rbss`, else `~/.cache/rbss`; cargo's build
//! directory for the entries (shared by all, so the runtime and its dependencies are compiled
//! once) is `$RBSS_CACHE_TARGET`, else the cargo build directory this command was built in
//! (`target/` of the sources: what `cargo run --release` compiled is reused), else `target/`
//! in the cache. The generator runs in this process; `$RBSS_CODEGEN` names a generator
//! command to run instead (`rbss-codegen`'s `--out DIR MODEL`).

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

/// Which library of a model. The subcommands that take no derivatives run in the plain one:
/// the robot generated without its derivative kernel (`rbss-codegen --no-derivatives`) behind
/// the command alone, which compiles in about a third of the time of the full one for a legged
/// robot (the kernel is three quarters of its generated code; BENCHMARKS.md). The full one
/// (every kernel, the C ABI of `ffi/include/rbss.h`) serves `rbss linearize`, `rbss
/// id-derivatives` and `rbss library` (C and Python); the studies one (the full one with the
/// command's feature `studies`) `rbss bench`. Each is built on its first use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Variant {
    Plain,
    Full,
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
    /// A generator command to run (`$RBSS_CODEGEN`, called as `rbss-codegen --out DIR
    /// MODEL`) instead of the generator in this process.
    pub codegen: Option<PathBuf>,
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
        let own = own_target_dir();
        let target = match std::env::var_os("RBSS_CACHE_TARGET") {
            Some(t) if !t.is_empty() => PathBuf::from(t),
            // The build directory this command was built in: the rbss crates and their
            // dependencies are compiled there already, as the library crate (a member of the
            // same workspace, with the command's features) needs them, so a first run compiles
            // the robot only.
            _ => own.unwrap_or_else(|| dir.join("target")),
        };
        let codegen = std::env::var_os("RBSS_CODEGEN")
            .filter(|c| !c.is_empty())
            .map(PathBuf::from);
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

/// The cargo build directory this command runs from, when it was built by cargo from the
/// sources it names (`DIR/release/rbss` with cargo's `DIR/.rustc_info.json`, the sources still
/// there) and the directory is writable: `--model-file`'s builds then reuse what that build
/// compiled. `None` for an installed command (`cargo install`, a package).
fn own_target_dir() -> Option<PathBuf> {
    let exe = std::env::current_exe().ok()?;
    let profile = exe.parent()?;
    if profile.file_name()? != "release" {
        return None;
    }
    let target = profile.parent()?;
    if !target.join(".rustc_info.json").is_file() || !Path::new(SOURCE).join("Cargo.toml").is_file()
    {
        return None;
    }
    // Writable: the builds' lock file lives there.
    fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(target.join(".rbss-build.lock"))
        .ok()?;
    Some(target.to_path_buf())
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

/// The full library of the model file `model` (every kernel and the C ABI: [`Variant::Full`]):
/// loaded from its cache entry, or built into it first
/// (and rebuilt when the entry is incomplete, corrupt or of another version). `progress`
/// gets a line per step of a build, and while another process builds the same entry.
pub fn load(
    cache: &Cache,
    model: &Path,
    progress: &mut dyn FnMut(&str),
) -> Result<Library, String> {
    load_variant(cache, model, Variant::Full, progress)
}

/// The files a model's library is built from, each read once: the model file, the source it
/// names (`urdf = "..."`, `mjcf`, `sdf`: relative to the model file's directory) and the
/// files that source `<include>`s (MJCF: relative to the source's directory, as MuJoCo and
/// the generator read them). The cache key hashes these bytes; the build checks that the
/// generator read the same bytes (the hashes it records), so that an entry never holds a
/// robot made from other files than its key's.
pub struct Inputs {
    /// The model file's canonical path (its directory canonical, then its name: what the
    /// relative paths in it are resolved from).
    pub path: PathBuf,
    /// (path, bytes) of every file: the model first, then the source, then its includes.
    files: Vec<(PathBuf, Vec<u8>)>,
    /// Whether the model names a source (then `files[1]` is it, the rest its includes).
    has_source: bool,
    /// (path, bytes) of the mesh files an MJCF source's `<mesh file>`s name (those that
    /// exist): hashed in the key (a mesh's inertia is in the robot), not in the generator's
    /// hash of the source.
    meshes: Vec<(PathBuf, Vec<u8>)>,
}

impl Inputs {
    /// Reads the model file and the files it includes.
    pub fn read(model: &Path) -> Result<Self, String> {
        let shown = model.display();
        let name = model
            .file_name()
            .ok_or_else(|| format!("{shown}: names no file"))?;
        let parent = match model.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        let dir = fs::canonicalize(parent).map_err(|e| format!("{shown}: cannot read: {e}"))?;
        let path = dir.join(name);
        let bytes = crate::read_input_bytes(&path).map_err(|e| {
            match e.strip_prefix(&format!("{}: ", path.display())) {
                Some(rest) => format!("{shown}: {rest}"),
                None => e,
            }
        })?;
        let mut inputs = Inputs {
            path: path.clone(),
            files: Vec::new(),
            has_source: false,
            meshes: Vec::new(),
        };
        // What the model names; a model that does not parse is the generator's to report.
        let source = std::str::from_utf8(&bytes)
            .ok()
            .and_then(|t| toml::de::DeTable::parse(t).ok())
            .and_then(|doc| {
                doc.get_ref().iter().find_map(|(k, v)| {
                    let key = k.get_ref().as_ref();
                    matches!(key, "urdf" | "mjcf" | "sdf")
                        .then(|| (key.to_string(), v.get_ref().as_str().map(str::to_string)))
                })
            });
        inputs.files.push((path, bytes));
        let Some((key, Some(rel))) = source else {
            return Ok(inputs);
        };
        let (mjcf, sdf) = (key == "mjcf", key == "sdf");
        if rel.trim().is_empty() {
            return Ok(inputs);
        }
        let src_path = dir.join(&rel);
        // A missing source is the generator's to report (located in the model file); one
        // beyond the input bound is refused here.
        let src_bytes = match crate::read_input_bytes(&src_path) {
            Ok(b) => b,
            Err(e) if e.contains("beyond the input limit") => return Err(e),
            Err(_) => return Ok(inputs),
        };
        inputs.has_source = true;
        let src_dir = src_path.parent().unwrap_or(Path::new("")).to_path_buf();
        inputs.files.push((src_path.clone(), src_bytes));
        if sdf {
            // SDF's `<include>`s, resolved as the importer resolves them (relative paths,
            // `file://`, `model://` in SDF_PATH and Gazebo's directories), in its order.
            let text = String::from_utf8_lossy(&inputs.files[1].1).into_owned();
            for p in rbss_codegen::import::sdf_included_files(&src_path, &text) {
                match fs::read(&p) {
                    Ok(b) => inputs.files.push((p, b)),
                    // The generator reports it, located at the `<include>`.
                    Err(_) => return Ok(inputs),
                }
            }
        } else if mjcf {
            // Breadth first, in document order, each `file` once, at most 64: the generator's
            // order (codegen/src/import/mjcf.rs), which its hash of the source follows.
            let mut seen: Vec<String> = Vec::new();
            let mut i = 1;
            while i < inputs.files.len() && seen.len() < 64 {
                let text = String::from_utf8_lossy(&inputs.files[i].1).into_owned();
                i += 1;
                for file in xml_includes(&text) {
                    let p = src_dir.join(&file);
                    if seen.contains(&file) || p == src_path || seen.len() >= 64 {
                        continue;
                    }
                    seen.push(file);
                    match fs::read(&p) {
                        Ok(b) => inputs.files.push((p, b)),
                        // The generator reports it, located at the `<include>`.
                        Err(_) => return Ok(inputs),
                    }
                }
            }
            inputs.read_meshes(&src_dir);
        }
        Ok(inputs)
    }

    /// The mesh files of the MJCF source and its includes: each `<mesh file>` where the
    /// generator reads it (`<compiler meshdir|assetdir|strippath>`,
    /// [`rbss_codegen::import::mesh_path`]), each once, those that exist, at most 4096.
    fn read_meshes(&mut self, src_dir: &Path) {
        let (mut meshdir, mut assetdir, mut strip) = (None, None, false);
        let mut files: Vec<String> = Vec::new();
        for (_, bytes) in &self.files[1..] {
            let text = String::from_utf8_lossy(bytes);
            for (tag, attrs) in xml_tags(
                &text,
                &["compiler", "mesh"],
                &["file", "meshdir", "assetdir", "strippath"],
            ) {
                for (k, v) in attrs {
                    match (tag.as_str(), k.as_str()) {
                        ("compiler", "meshdir") => meshdir = Some(v),
                        ("compiler", "assetdir") => assetdir = Some(v),
                        ("compiler", "strippath") => strip = v == "true",
                        ("mesh", "file") if !files.contains(&v) => files.push(v),
                        _ => {}
                    }
                }
            }
        }
        let dir = meshdir.as_deref().or(assetdir.as_deref());
        for f in files.iter().take(4096) {
            let p = rbss_codegen::import::mesh_path(src_dir, dir, f, strip);
            // A missing mesh is the generator's to report (if a geom needs it); one beyond the
            // generator's bound cannot be in a robot (the generator refuses it).
            let fits =
                fs::metadata(&p).is_ok_and(|m| m.len() <= rbss_codegen::import::MAX_BYTES as u64);
            if let Some(b) = fits.then(|| fs::read(&p).ok()).flatten() {
                self.meshes.push((p, b));
            }
        }
    }

    /// The hash of every file's path and bytes.
    fn hash(&self) -> [u8; 32] {
        let mut h = Sha256::new();
        let mut part = |label: &str, data: &[u8]| {
            h.update(label.as_bytes());
            h.update((data.len() as u64).to_le_bytes());
            h.update(data);
        };
        part("model path", self.path.to_string_lossy().as_bytes());
        for (p, b) in &self.files {
            part("file", p.to_string_lossy().as_bytes());
            part("bytes", b);
        }
        for (p, b) in &self.meshes {
            part("mesh", p.to_string_lossy().as_bytes());
            part("bytes", b);
        }
        h.finalize().into()
    }

    /// The hashes the generator records for what it read (LF-normalised): the model file's
    /// (`model_sha256` of the manifest), and the source's with its includes (the module
    /// header's `// source: ... sha256: ...`), if it has one.
    fn generator_hashes(&self) -> (String, Option<String>) {
        let lf = |b: &[u8]| String::from_utf8_lossy(b).replace("\r\n", "\n");
        let model = hex(&Sha256::digest(lf(&self.files[0].1).as_bytes()));
        let source = self.has_source.then(|| {
            let mut text = String::new();
            for (_, b) in &self.files[1..] {
                text.push_str(&lf(b));
            }
            hex(&Sha256::digest(text.as_bytes()))
        });
        (model, source)
    }
}

/// The `file` of every `<include>` element of an XML text, in document order.
fn xml_includes(text: &str) -> Vec<String> {
    xml_tags(text, &["include"], &["file"])
        .into_iter()
        .filter_map(|(_, attrs)| attrs.into_iter().next().map(|(_, v)| v))
        .collect()
}

/// The elements of an XML text named one of `tags` (local names), each with its attributes
/// named one of `attrs`, in document order (comments, CDATA sections, processing instructions
/// and declarations skipped; entities decoded).
fn xml_tags(text: &str, tags: &[&str], attrs: &[&str]) -> Vec<(String, Vec<(String, String)>)> {
    let mut out = Vec::new();
    let mut i = 0;
    while let Some(off) = text[i..].find('<') {
        let s = i + off;
        let rest = &text[s..];
        let skip = |end: &str| rest.find(end).map_or(text.len(), |e| s + e + end.len());
        if rest.starts_with("<!--") {
            i = skip("-->");
            continue;
        }
        if rest.starts_with("<![CDATA[") {
            i = skip("]]>");
            continue;
        }
        if rest.starts_with("<?") {
            i = skip("?>");
            continue;
        }
        if rest.starts_with("<!") || rest.starts_with("</") {
            i = skip(">");
            continue;
        }
        let name_end = rest[1..]
            .find(|c: char| c.is_whitespace() || c == '/' || c == '>')
            .map_or(rest.len(), |e| e + 1);
        let local = rest[1..name_end].rsplit(':').next().unwrap_or("");
        // The attributes, up to the tag's `>` (outside quotes).
        let mut j = name_end;
        let bytes = rest.as_bytes();
        let mut found: Vec<(String, String)> = Vec::new();
        while j < rest.len() {
            let c = bytes[j];
            if c == b'>' {
                j += 1;
                break;
            }
            if c.is_ascii_whitespace() || c == b'/' {
                j += 1;
                continue;
            }
            let Some(eq) = rest[j..].find('=') else {
                j = rest.len();
                break;
            };
            let attr = rest[j..j + eq].trim();
            let mut k = j + eq + 1;
            while k < rest.len() && bytes[k].is_ascii_whitespace() {
                k += 1;
            }
            let Some(&q) = bytes.get(k).filter(|q| **q == b'"' || **q == b'\'') else {
                j = k + 1;
                continue;
            };
            let Some(len) = rest[k + 1..].find(q as char) else {
                j = rest.len();
                break;
            };
            let value = &rest[k + 1..k + 1 + len];
            if attrs.contains(&attr) {
                found.push((attr.to_string(), xml_unescape(value)));
            }
            j = k + 1 + len + 1;
        }
        if tags.contains(&local) {
            out.push((local.to_string(), found));
        }
        i = s + j.max(1);
    }
    out
}

/// An XML attribute's value: the predefined and numeric entities decoded, white space
/// normalised as XML does.
fn xml_unescape(v: &str) -> String {
    let v = v.replace("\r\n", " ").replace(['\t', '\n', '\r'], " ");
    let mut out = String::new();
    let mut rest = v.as_str();
    while let Some(a) = rest.find('&') {
        out.push_str(&rest[..a]);
        let tail = &rest[a..];
        let Some(semi) = tail.find(';') else {
            out.push_str(tail);
            return out;
        };
        let ent = &tail[1..semi];
        let c = match ent {
            "lt" => Some('<'),
            "gt" => Some('>'),
            "amp" => Some('&'),
            "apos" => Some('\''),
            "quot" => Some('"'),
            _ => ent
                .strip_prefix("#x")
                .and_then(|h| u32::from_str_radix(h, 16).ok())
                .or_else(|| ent.strip_prefix('#').and_then(|d| d.parse().ok()))
                .and_then(char::from_u32),
        };
        match c {
            Some(c) => out.push(c),
            None => out.push_str(&tail[..=semi]),
        }
        rest = &tail[semi + 1..];
    }
    out.push_str(rest);
    out
}

/// Hex of bytes.
fn hex(b: &[u8]) -> String {
    b.iter().map(|b| format!("{b:02x}")).collect()
}

/// [`load`] of the given variant of the model's library.
///
/// A verified entry (its stamp names the key, the library has the stamp's size and SHA-256)
/// is loaded without a lock, so a read-only cache works. Otherwise the entry's lock is taken
/// (a line on `progress` every 10 s while another process holds it), the entry checked again
/// and, when still unusable, built.
pub fn load_variant(
    cache: &Cache,
    model: &Path,
    variant: Variant,
    progress: &mut dyn FnMut(&str),
) -> Result<Library, String> {
    let inputs = Inputs::read(model)?;
    let model_key = model_key(&inputs, variant);
    let key = match key(cache, &model_key) {
        Ok(k) => k,
        Err(e) => {
            // No toolchain or no sources: an entry of this model built by this rbss (its C
            // ABI and version) serves, the most recently used one.
            return match fallback(cache, &model_key) {
                Some((entry, stamp)) => {
                    progress(&format!(
                        "{e}; using the cached library {} (built for this model by rbss {})",
                        entry.display(),
                        stamp.rbss
                    ));
                    let lib = open(&entry, &stamp.key)?;
                    touch(&entry);
                    Ok(lib)
                }
                None => Err(e),
            };
        }
    };
    let robots = cache.dir.join("robots");
    let entry = robots.join(&key);
    let mut why_rebuild = None;
    if entry.join("ok").is_file() {
        match verify(&entry, &key).and_then(|_| open(&entry, &key)) {
            Ok(lib) => {
                touch(&entry);
                return Ok(lib);
            }
            Err(e) => why_rebuild = Some(e),
        }
    }
    fs::create_dir_all(&robots).map_err(|e| {
        format!(
            "{}: cannot create ({e}), and the cache has no usable library of {}",
            robots.display(),
            model.display()
        )
    })?;
    // One build of an entry at a time (another process waits, then finds it built).
    let lock_path = robots.join(format!("{key}.lock"));
    let lock = fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&lock_path)
        .map_err(|e| {
            format!(
                "{}: cannot open ({e}), and the cache has no usable library of {}",
                lock_path.display(),
                model.display()
            )
        })?;
    wait_lock(
        &lock,
        &lock_path,
        &format!("robot {}", model.display()),
        progress,
    )?;
    if entry.join("ok").is_file() {
        match verify(&entry, &key).and_then(|_| open(&entry, &key)) {
            Ok(lib) => {
                touch(&entry);
                return Ok(lib);
            }
            Err(e) => {
                progress(&format!(
                    "cache entry {} unusable ({e}); rebuilding it",
                    entry.display()
                ));
            }
        }
    } else if let Some(e) = why_rebuild {
        progress(&format!(
            "cache entry {} unusable ({e}); rebuilding it",
            entry.display()
        ));
    } else if entry.exists() {
        progress(&format!(
            "cache entry {} incomplete; rebuilding it",
            entry.display()
        ));
    }
    if entry.exists() {
        remove_entry(&entry)?;
    }
    build(
        cache, &inputs, model, &key, &model_key, variant, &entry, progress,
    )?;
    let mut lib = open(&entry, &key)?;
    lib.built = true;
    drop(lock);
    // Keep the cache within its bound (the entry just built stays).
    if let Ok(max) = max_size() {
        let _ = prune(cache, max, Some(&key));
    }
    Ok(lib)
}

/// Takes `lock`, saying on `progress` that (and every 10 s while) another process holds it.
fn wait_lock(
    lock: &fs::File,
    path: &Path,
    what: &str,
    progress: &mut dyn FnMut(&str),
) -> Result<(), String> {
    let t0 = std::time::Instant::now();
    let mut said = 0;
    loop {
        match lock.try_lock() {
            Ok(()) => return Ok(()),
            Err(fs::TryLockError::WouldBlock) => {
                let waited = t0.elapsed().as_secs();
                if said == 0 || waited >= said * 10 {
                    progress(&format!(
                        "waiting for another rbss building the {what} ({}; {waited} s so far)",
                        path.display()
                    ));
                    said = waited / 10 + 1;
                }
                std::thread::sleep(std::time::Duration::from_millis(100));
            }
            Err(fs::TryLockError::Error(e)) => {
                return Err(format!("{}: cannot lock: {e}", path.display()));
            }
        }
    }
}

/// What an entry's stamp (`ok`) records.
#[derive(Debug, Clone)]
struct Stamp {
    key: String,
    model_key: String,
    library_size: u64,
    library_sha256: String,
    rbss: String,
    abi: u32,
    name: String,
    model: String,
}

impl Stamp {
    fn render(&self) -> String {
        format!(
            "# rbss --model-file cache entry: complete once this file is here.\n\
             key = \"{}\"\n\
             model_key = \"{}\"\n\
             library_size = {}\n\
             library_sha256 = \"{}\"\n\
             rbss = \"{}\"\n\
             abi = {}\n\
             name = \"{}\"\n\
             model = {}\n",
            self.key,
            self.model_key,
            self.library_size,
            self.library_sha256,
            self.rbss,
            self.abi,
            self.name,
            toml_str(&self.model)
        )
    }

    fn parse(text: &str) -> Result<Stamp, String> {
        let doc =
            toml::de::DeTable::parse(text).map_err(|_| "its stamp is not TOML".to_string())?;
        let get = |k: &str| {
            doc.get_ref()
                .iter()
                .find(|(key, _)| key.get_ref().as_ref() == k)
                .map(|(_, v)| v.get_ref().clone())
        };
        let s = |k: &str| match get(k) {
            Some(toml::de::DeValue::String(s)) => Ok(s.into_owned()),
            _ => Err(format!("its stamp has no `{k}`")),
        };
        let n = |k: &str| match get(k) {
            Some(toml::de::DeValue::Integer(i)) => i
                .as_str()
                .parse::<u64>()
                .map_err(|_| format!("its stamp's `{k}` is not a size")),
            _ => Err(format!("its stamp has no `{k}`")),
        };
        Ok(Stamp {
            key: s("key")?,
            model_key: s("model_key")?,
            library_size: n("library_size")?,
            library_sha256: s("library_sha256")?,
            rbss: s("rbss")?,
            abi: u32::try_from(n("abi")?).map_err(|_| "its stamp's `abi` is too large")?,
            name: s("name")?,
            model: s("model")?,
        })
    }
}

/// The entry's stamp, checked against the key and the library file (its size and SHA-256):
/// what a crash during the copy, a full disk or an edit leaves is found here, before the
/// library is mapped (a truncated library would crash the process when loaded).
///
/// The size is checked on every load; the SHA-256 (about 0.2 s for an 18 MB library) once per
/// state of the file: a successful check records the library's metadata (size, modification
/// and change times in ns, inode, device) in `verified`, and a later load whose library has
/// the same metadata does not hash it again. Any write to the library through the file
/// system changes its change time (which `touch` cannot set back), so a modified library is
/// hashed again (docs/cache.md says what this does not detect).
fn verify(entry: &Path, key: &str) -> Result<Stamp, String> {
    verify_inner(entry, key).map(|(stamp, _)| stamp)
}

/// The check of a cache entry `entry` against `key` ([`verify`]): `Ok(true)` when the library
/// was hashed, `Ok(false)` when its metadata was the one recorded at its last check (not hashed
/// again). For the tests (tests/model_file.rs).
#[doc(hidden)]
pub fn verify_entry(entry: &Path, key: &str) -> Result<bool, String> {
    verify_inner(entry, key).map(|(_, hashed)| hashed)
}

/// The library's file name in an entry, for the tests.
#[doc(hidden)]
pub fn entry_library_file() -> String {
    library_file()
}

/// [`verify`], and whether it hashed the library (false: its metadata was the recorded one).
fn verify_inner(entry: &Path, key: &str) -> Result<(Stamp, bool), String> {
    let text = fs::read_to_string(entry.join("ok")).map_err(|e| format!("stamp: {e}"))?;
    let stamp = Stamp::parse(&text)?;
    if stamp.key != key {
        return Err("its stamp names another key".to_string());
    }
    let path = entry.join(library_file());
    let meta = fs::metadata(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    if meta.len() != stamp.library_size {
        return Err(format!(
            "{}: {} bytes, its stamp says {}",
            path.display(),
            meta.len(),
            stamp.library_size
        ));
    }
    let record = verified_record(&meta, &stamp.library_sha256);
    let recorded = entry.join(VERIFIED);
    if !record.is_empty() && fs::read_to_string(&recorded).is_ok_and(|r| r == record) {
        return Ok((stamp, false));
    }
    let bytes = fs::read(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    if bytes.len() as u64 != stamp.library_size {
        return Err(format!(
            "{}: {} bytes, its stamp says {}",
            path.display(),
            bytes.len(),
            stamp.library_size
        ));
    }
    if hex(&Sha256::digest(&bytes)) != stamp.library_sha256 {
        return Err(format!(
            "{}: its SHA-256 is not its stamp's",
            path.display()
        ));
    }
    // Recorded only when the file did not change while it was read (else the next load hashes
    // it again); a read-only cache hashes on every load.
    if !record.is_empty()
        && fs::metadata(&path).is_ok_and(|m| verified_record(&m, &stamp.library_sha256) == record)
    {
        let tmp = entry.join(format!("{VERIFIED}.{}", std::process::id()));
        if fs::write(&tmp, &record).is_ok() && fs::rename(&tmp, &recorded).is_err() {
            let _ = fs::remove_file(&tmp);
        }
    }
    Ok((stamp, true))
}

/// The file of an entry recording the library's metadata when its SHA-256 was last checked.
const VERIFIED: &str = "verified";

/// What `verified` holds for a library with the metadata `meta` and the SHA-256 `sha256`.
#[cfg(unix)]
fn verified_record(meta: &fs::Metadata, sha256: &str) -> String {
    use std::os::unix::fs::MetadataExt as _;
    format!(
        "size = {}\nmtime = {}.{:09}\nctime = {}.{:09}\ninode = {}\ndevice = {}\nsha256 = \"{sha256}\"\n",
        meta.len(),
        meta.mtime(),
        meta.mtime_nsec(),
        meta.ctime(),
        meta.ctime_nsec(),
        meta.ino(),
        meta.dev()
    )
}

/// Without the change time and inode (not Unix), nothing is recorded: every load hashes.
#[cfg(not(unix))]
fn verified_record(_meta: &fs::Metadata, _sha256: &str) -> String {
    String::new()
}

/// Marks the entry used now (the stamp's modification time; the cache's LRU order). A
/// read-only cache stays as it is.
fn touch(entry: &Path) {
    if let Ok(f) = fs::File::options().append(true).open(entry.join("ok")) {
        let _ = f.set_modified(std::time::SystemTime::now());
    }
}

/// The most recently used verified entry of `model_key` (for a run without the toolchain or
/// the sources).
fn fallback(cache: &Cache, model_key: &str) -> Option<(PathBuf, Stamp)> {
    let mut best: Option<(std::time::SystemTime, PathBuf, Stamp)> = None;
    for e in list_entries(cache) {
        let Ok(stamp) = fs::read_to_string(e.path.join("ok"))
            .map_err(|e| e.to_string())
            .and_then(|t| Stamp::parse(&t))
        else {
            continue;
        };
        if stamp.model_key != model_key || stamp.abi != ABI_VERSION {
            continue;
        }
        if best.as_ref().is_some_and(|(t, _, _)| *t >= e.used) {
            continue;
        }
        if let Ok(stamp) = verify(&e.path, &stamp.key) {
            best = Some((e.used, e.path, stamp));
        }
    }
    best.map(|(_, p, s)| (p, s))
}

/// Removes an entry: renamed aside first (so no process sees it half removed), then deleted.
fn remove_entry(entry: &Path) -> Result<(), String> {
    let aside = entry.with_extension(format!("removing.{}", std::process::id()));
    fs::rename(entry, &aside).map_err(|e| format!("{}: cannot remove: {e}", entry.display()))?;
    fs::remove_dir_all(&aside).map_err(|e| format!("{}: cannot remove: {e}", aside.display()))
}

/// Loads the entry's library and checks its ABI version and key.
fn open(entry: &Path, key: &str) -> Result<Library, String> {
    let path = entry.join(library_file());
    // SAFETY: a library this module built from the rbss sources (its initialisers are Rust's
    // own), whose size and hash were checked against its stamp; the symbols are checked
    // before use.
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

/// The part of the key that the model decides: its files (paths and bytes), the variant, the
/// versions of rbss and of the C ABI. A run without the toolchain or the sources finds the
/// entries of this model by it.
fn model_key(inputs: &Inputs, variant: Variant) -> String {
    let mut h = Sha256::new();
    let mut part = |label: &str, data: &[u8]| {
        h.update(label.as_bytes());
        h.update((data.len() as u64).to_le_bytes());
        h.update(data);
    };
    part("inputs", &inputs.hash());
    part("rbss", env!("CARGO_PKG_VERSION").as_bytes());
    part("abi", &ABI_VERSION.to_le_bytes());
    // The plain library's key has no such part.
    match variant {
        Variant::Plain => {}
        Variant::Full => part("variant", b"full"),
        Variant::Studies => part("variant", b"studies"),
    }
    hex(&h.finalize()[..16])
}

/// The entry's key: the model's part, the rbss sources and `rustc -vV` (see the module
/// documentation).
fn key(cache: &Cache, model_key: &str) -> Result<String, String> {
    let mut h = Sha256::new();
    let mut part = |label: &str, data: &[u8]| {
        h.update(label.as_bytes());
        h.update((data.len() as u64).to_le_bytes());
        h.update(data);
    };
    part("model", model_key.as_bytes());
    part("sources", &sources_hash(&cache.source)?);
    let rustc = rustc_version(cache)?;
    part("rustc", rustc.as_bytes());
    Ok(hex(&h.finalize()[..16]))
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
        "robot-lib",
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
#[allow(clippy::too_many_arguments)]
fn build(
    cache: &Cache,
    inputs: &Inputs,
    model: &Path,
    key: &str,
    model_key: &str,
    variant: Variant,
    entry: &Path,
    progress: &mut dyn FnMut(&str),
) -> Result<(), String> {
    let tmp = entry.with_extension("building");
    if tmp.exists() {
        fs::remove_dir_all(&tmp).map_err(|e| format!("{}: cannot remove: {e}", tmp.display()))?;
    }
    let built = build_in(
        cache, inputs, model, key, model_key, variant, &tmp, entry, progress,
    );
    if built.is_err() {
        let _ = fs::remove_dir_all(&tmp);
    }
    built
}

/// `file` written and flushed to the disk.
fn write_synced(path: &Path, data: &[u8]) -> Result<(), String> {
    let mut f = fs::File::create(path).map_err(|e| format!("{}: {e}", path.display()))?;
    f.write_all(data)
        .and_then(|()| f.sync_all())
        .map_err(|e| format!("{}: {e}", path.display()))
}

/// A directory's entries flushed to the disk (a no-op where directories cannot be opened).
fn sync_dir(dir: &Path) {
    if let Ok(d) = fs::File::open(dir) {
        let _ = d.sync_all();
    }
}

/// The value of `key = "..."` in a flat TOML text (the generated manifest).
fn manifest_string(manifest: &str, key: &str) -> Option<String> {
    let doc = toml::de::DeTable::parse(manifest).ok()?;
    doc.get_ref()
        .iter()
        .find(|(k, _)| k.get_ref().as_ref() == key)
        .and_then(|(_, v)| v.get_ref().as_str().map(str::to_string))
}

/// Writes the robot's crate of `model` to `dir`: the generator in this process, or the command
/// `$RBSS_CODEGEN` names. Errors are the generator's diagnostics (file, line and column); its
/// warnings (an importer's skipped elements, an angle taken as radians) go to `progress`, one
/// line each, as `rbss-codegen` prints them.
fn generate(
    cache: &Cache,
    model: &Path,
    variant: Variant,
    dir: &Path,
    progress: &mut dyn FnMut(&str),
) -> Result<(), String> {
    let no_derivatives = variant == Variant::Plain;
    if let Some(codegen) = &cache.codegen {
        let mut cmd = Command::new(codegen);
        if no_derivatives {
            cmd.arg("--no-derivatives");
        }
        let out = cmd.arg("--out").arg(dir).arg(model).output().map_err(|e| {
            format!(
                "cannot run the generator `{}` (RBSS_CODEGEN): {e}",
                codegen.display()
            )
        })?;
        let stderr = String::from_utf8_lossy(&out.stderr);
        if !out.status.success() {
            return Err(stderr.trim_end().to_string());
        }
        stderr
            .lines()
            .filter(|l| l.contains(": warning: "))
            .for_each(|l| progress(l.trim_start_matches("rbss-codegen: ")));
        return Ok(());
    }
    let source = rbss_codegen::source::read_source(model).map_err(|d| d.render())?;
    // The crate's Cargo.toml names the runtime by its absolute path (the library crate
    // includes only its module; the crate stays buildable on its own).
    let runtime = cache.source.join("runtime");
    let runtime = runtime.to_string_lossy().replace('\\', "/");
    let model_path = model.to_string_lossy();
    // A panic in the generator is a bug of rbss; it ends this run with an error, not the process.
    let mut warnings = Vec::new();
    let generated = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        rbss_codegen::generate_with_runtime(
            &model_path,
            &source,
            &rbss_codegen::Options {
                no_derivatives,
                ..Default::default()
            },
            &runtime,
            // The generator's progress lines are its command's (the library's build says its
            // own); its warnings are the user's.
            &mut |line: &str| {
                if line.contains(": warning: ") {
                    warnings.push(line.to_string());
                }
            },
        )
    }))
    .map_err(|_| {
        format!(
            "{}: the generator panicked (a bug of rbss-codegen; please report it)",
            model.display()
        )
    })?
    .map_err(|e| e.to_string().trim_end().to_string())?;
    warnings.iter().for_each(|w| progress(w));
    rbss_codegen::write_crate(dir, &generated).map_err(|e| e.to_string())
}

#[allow(clippy::too_many_arguments)]
fn build_in(
    cache: &Cache,
    inputs: &Inputs,
    model: &Path,
    key: &str,
    model_key: &str,
    variant: Variant,
    tmp: &Path,
    entry: &Path,
    progress: &mut dyn FnMut(&str),
) -> Result<(), String> {
    let t0 = std::time::Instant::now();
    let robot_dir = tmp.join("robot");
    progress(&format!("generating {} ...", model.display()));
    generate(cache, model, variant, &robot_dir, progress)?;
    let manifest_text = fs::read_to_string(robot_dir.join("rbss-manifest.toml"))
        .map_err(|e| format!("{}: no manifest: {e}", robot_dir.display()))?;
    let manifest = toml::de::DeTable::parse(&manifest_text)
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
    // The generator read the bytes the key hashed (else a file changed in between: the
    // entry would hold another robot than its key's).
    let (want_model, want_source) = inputs.generator_hashes();
    let module = fs::read_to_string(robot_dir.join(format!("src/{name}.rs"))).unwrap_or_default();
    let got_source = module
        .lines()
        .take(8)
        .find(|l| l.starts_with("// source: "))
        .and_then(|l| l.rsplit("sha256: ").next())
        .map(|s| s.trim().to_string());
    if manifest_string(&manifest_text, "model_sha256").as_deref() != Some(want_model.as_str())
        || got_source != want_source
    {
        return Err(format!(
            "{}: the model or a file it includes changed while it was being compiled; run \
             again",
            model.display()
        ));
    }
    if !matches!(value("dynamics"), Some(toml::de::DeValue::Boolean(true))) {
        return Err(format!(
            "{}: robot `{name}` has no dynamics (no masses): the subcommands of --model-file \
             need them",
            model.display()
        ));
    }
    // The file the workspace's library crate (robot-lib/) includes: the robot's module by its
    // absolute path (a Rust string literal: a path may hold anything but NUL, issue 37).
    let module_path = robot_dir.join("src").join(format!("{name}.rs"));
    let module_path = module_path.to_str().ok_or_else(|| {
        format!(
            "{}: the cache's path is not UTF-8, which rustc needs to include the robot",
            module_path.display()
        )
    })?;
    let robot_rs = tmp.join("robot-lib.rs");
    fs::write(
        &robot_rs,
        format!(
            "// Written by rbss --model-file: the robot `{name}` ({model}) behind the C ABI \
             (rbss.h) and the command.\n\
             #[path = {module_path:?}]\n\
             pub mod {name};\n\
             {exports}",
            model = inputs.path.display(),
            exports = match variant {
                // The command alone (and the ABI version the loader checks).
                Variant::Plain => format!(
                    "::rbss_ffi::export!({name}::{ty}, version);\n\
                     ::rbss::export_command!({name}::{ty}, \"{key}\", without_derivatives);\n"
                ),
                Variant::Full | Variant::Studies => format!(
                    "::rbss_ffi::export!({name}::{ty}, dynamics);\n\
                     ::rbss::export_command!({name}::{ty}, \"{key}\");\n"
                ),
            },
        ),
    )
    .map_err(|e| format!("{}: {e}", robot_rs.display()))?;

    progress(&format!(
        "compiling robot `{name}`{} (cargo, in {}) ...",
        match variant {
            Variant::Plain => " without derivatives",
            Variant::Full => "",
            Variant::Studies => " with the studies",
        },
        cache.target.display()
    ));
    // One build at a time in the shared build directory (cargo would serialise them anyway,
    // silently): a line while waiting, and this build's own files in it known, to be removed
    // once the library is copied (else every model edit leaves its crate's objects behind).
    fs::create_dir_all(&cache.target)
        .map_err(|e| format!("{}: cannot create: {e}", cache.target.display()))?;
    let build_lock_path = cache.target.join(".rbss-build.lock");
    let build_lock = fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&build_lock_path)
        .map_err(|e| format!("{}: cannot open: {e}", build_lock_path.display()))?;
    wait_lock(
        &build_lock,
        &build_lock_path,
        "robot of another model (the build directory is shared)",
        progress,
    )?;
    let mut cmd = Command::new(&cache.cargo);
    cmd.args(["build", "--release", "--quiet", "-p", "rbss-robot-lib"]);
    if variant == Variant::Studies {
        cmd.args(["--features", "rbss-robot-lib/studies"]);
    }
    let mut child = cmd
        .arg("--manifest-path")
        .arg(cache.source.join("Cargo.toml"))
        .env("RBSS_ROBOT_LIB", &robot_rs)
        .env("CARGO_TARGET_DIR", &cache.target)
        .env_remove("CARGO_BUILD_TARGET_DIR")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .map_err(|e| {
            format!(
                "cannot run cargo `{}` ({e}): --model-file compiles the robot, which needs a \
                 Rust toolchain (https://rustup.rs)",
                cache.cargo.display()
            )
        })?;
    let mut stderr = child.stderr.take();
    let reader = std::thread::spawn(move || {
        let mut s = Vec::new();
        if let Some(e) = stderr.as_mut() {
            let _ = std::io::Read::read_to_end(e, &mut s);
        }
        s
    });
    // The next progress line 30 s on (t0 counts the generator's build and run too).
    let mut next = t0.elapsed().as_secs() + 30;
    let status = loop {
        match child.try_wait() {
            Ok(Some(s)) => break s,
            Ok(None) => {
                if t0.elapsed().as_secs() >= next {
                    progress(&format!(
                        "still compiling robot `{name}` ({} s so far)",
                        t0.elapsed().as_secs()
                    ));
                    next += 30;
                }
                std::thread::sleep(std::time::Duration::from_millis(100));
            }
            Err(e) => return Err(format!("cargo: {e}")),
        }
    };
    let err_text = reader.join().unwrap_or_default();
    if !status.success() {
        return Err(format!(
            "compiling robot `{name}` failed:\n{}",
            String::from_utf8_lossy(&err_text).trim_end()
        ));
    }
    let built = cache.target.join("release").join(format!(
        "{}rbss_robot{}",
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    ));
    let library = fs::read(&built).map_err(|e| format!("{}: cannot read: {e}", built.display()))?;
    // The library of this build, not of another cargo build of the workspace's library crate
    // run in the same directory since (which the build lock does not hold off): it holds the
    // key its `rbss_cache_key` returns.
    let key_bytes = format!("{key}\0");
    if !library
        .windows(key_bytes.len())
        .any(|w| w == key_bytes.as_bytes())
    {
        return Err(format!(
            "{}: not the library of robot `{name}` (another cargo build in {} at the same \
             time?); run again",
            built.display(),
            cache.target.display()
        ));
    }
    write_synced(&tmp.join(library_file()), &library)?;
    // The stamp last, flushed, then the directory: the entry is complete once it is renamed in.
    let stamp = Stamp {
        key: key.to_string(),
        model_key: model_key.to_string(),
        library_size: library.len() as u64,
        library_sha256: hex(&Sha256::digest(&library)),
        rbss: env!("CARGO_PKG_VERSION").to_string(),
        abi: ABI_VERSION,
        name: name.clone(),
        model: inputs.path.to_string_lossy().into_owned(),
    };
    write_synced(&tmp.join("ok"), stamp.render().as_bytes())?;
    sync_dir(tmp);
    fs::rename(tmp, entry).map_err(|e| format!("{}: cannot rename: {e}", entry.display()))?;
    if let Some(parent) = entry.parent() {
        sync_dir(parent);
    }
    // The copy in cargo's directory is not needed any more (the library crate's objects are
    // the same files for every model: the next build overwrites them).
    let _ = fs::remove_file(&built);
    drop(build_lock);
    progress(&format!(
        "robot `{name}` compiled in {:.1} s; cached in {}",
        t0.elapsed().as_secs_f64(),
        entry.display()
    ));
    Ok(())
}

/// One cache entry, as `rbss cache list` shows it.
pub struct EntryInfo {
    pub path: PathBuf,
    pub key: String,
    /// The robot's name and model file (from the stamp; empty for an incomplete entry).
    pub name: String,
    pub model: String,
    /// Bytes on disk.
    pub size: u64,
    /// Last use (the stamp's modification time).
    pub used: std::time::SystemTime,
    /// Whether its stamp is there and readable (the library is verified when loaded).
    pub complete: bool,
}

/// The cache's entries (`DIR/robots/KEY/`), least recently used first.
pub fn list_entries(cache: &Cache) -> Vec<EntryInfo> {
    let mut out = Vec::new();
    let Ok(rd) = fs::read_dir(cache.dir.join("robots")) else {
        return out;
    };
    for e in rd.flatten() {
        let path = e.path();
        let key = e.file_name().to_string_lossy().into_owned();
        if !path.is_dir() || key.contains('.') {
            continue;
        }
        let stamp = fs::read_to_string(path.join("ok"))
            .ok()
            .and_then(|t| Stamp::parse(&t).ok());
        let used = fs::metadata(path.join("ok"))
            .or_else(|_| fs::metadata(&path))
            .and_then(|m| m.modified())
            .unwrap_or(std::time::UNIX_EPOCH);
        out.push(EntryInfo {
            size: dir_size(&path),
            key,
            name: stamp.as_ref().map_or(String::new(), |s| s.name.clone()),
            model: stamp.as_ref().map_or(String::new(), |s| s.model.clone()),
            complete: stamp.is_some(),
            used,
            path,
        });
    }
    out.sort_by(|a, b| a.used.cmp(&b.used).then(a.key.cmp(&b.key)));
    out
}

fn dir_size(p: &Path) -> u64 {
    let Ok(rd) = fs::read_dir(p) else {
        return fs::metadata(p).map_or(0, |m| m.len());
    };
    rd.flatten()
        .map(|e| match e.file_type() {
            Ok(t) if t.is_dir() => dir_size(&e.path()),
            _ => e.metadata().map_or(0, |m| m.len()),
        })
        .sum()
}

/// The cache's size bound: `$RBSS_CACHE_MAX_SIZE` (bytes, or with a suffix K, M, G), else
/// 2 GiB.
pub fn max_size() -> Result<u64, String> {
    match std::env::var("RBSS_CACHE_MAX_SIZE") {
        Ok(s) if !s.trim().is_empty() => {
            parse_size(&s).map_err(|e| format!("RBSS_CACHE_MAX_SIZE: {e}"))
        }
        _ => Ok(DEFAULT_MAX_SIZE),
    }
}

/// The default bound of the entries' total size.
pub const DEFAULT_MAX_SIZE: u64 = 2 << 30;

/// `123`, `500K`, `300M`, `2G` (powers of 1024) as bytes.
pub fn parse_size(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let (num, mult) = match t.char_indices().last() {
        Some((i, 'K' | 'k')) => (&t[..i], 1u64 << 10),
        Some((i, 'M' | 'm')) => (&t[..i], 1 << 20),
        Some((i, 'G' | 'g')) => (&t[..i], 1 << 30),
        _ => (t, 1),
    };
    num.trim()
        .parse::<u64>()
        .ok()
        .and_then(|n| n.checked_mul(mult))
        .ok_or_else(|| format!("`{s}` is not a size (bytes, or a number with K, M or G)"))
}

/// Removes the least recently used entries until the entries' total size is at most `max`
/// bytes (never `keep`, nor an entry another process is building or loading for a build);
/// also the leftovers of builds that were killed. Returns the removed entries.
pub fn prune(cache: &Cache, max: u64, keep: Option<&str>) -> Result<Vec<EntryInfo>, String> {
    let robots = cache.dir.join("robots");
    // Leftovers: `KEY.building` of a killed build (its lock is free), `KEY.removing.PID`.
    if let Ok(rd) = fs::read_dir(&robots) {
        for e in rd.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            if let Some(key) = name.strip_suffix(".building") {
                if let Some(_l) = try_entry_lock(&robots, key) {
                    let _ = fs::remove_dir_all(e.path());
                }
            } else if name.contains(".removing.") {
                let _ = fs::remove_dir_all(e.path());
            }
        }
    }
    let entries = list_entries(cache);
    let mut total: u64 = entries.iter().map(|e| e.size).sum();
    let mut removed = Vec::new();
    for e in entries {
        if total <= max {
            break;
        }
        if keep == Some(e.key.as_str()) {
            continue;
        }
        let Some(_lock) = try_entry_lock(&robots, &e.key) else {
            continue;
        };
        remove_entry(&e.path)?;
        let _ = fs::remove_file(robots.join(format!("{}.lock", e.key)));
        total -= e.size;
        removed.push(e);
    }
    Ok(removed)
}

/// The entry's build lock if no other process holds it (`None` when one does, or the lock
/// cannot be opened).
fn try_entry_lock(robots: &Path, key: &str) -> Option<fs::File> {
    let f = fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(robots.join(format!("{key}.lock")))
        .ok()?;
    f.try_lock().ok()?;
    Some(f)
}

/// `s` as a TOML basic string (control characters escaped).
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

/// `42 s`, `5 min`, `3 h`, `2 d`.
pub(crate) fn age_text(s: u64) -> String {
    match s {
        0..120 => format!("{s} s"),
        120..7200 => format!("{} min", s / 60),
        7200..172_800 => format!("{} h", s / 3600),
        _ => format!("{} d", s / 86_400),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A mesh file the MJCF source names (in an included file, under `<compiler meshdir>`) is in
    /// the key: editing it changes the key; the generator's hashes (the model's, the source's
    /// with its includes) do not cover it and stay.
    #[test]
    fn mesh_files_are_in_the_key() {
        let tmp = tempfile::tempdir().unwrap();
        let d = tmp.path();
        std::fs::create_dir_all(d.join("parts")).unwrap();
        std::fs::write(d.join("robot.toml"), "mjcf = \"robot.xml\"\n").unwrap();
        std::fs::write(
            d.join("robot.xml"),
            "<mujoco><compiler meshdir=\"parts\"/><include file=\"assets.xml\"/>\
             <worldbody/></mujoco>",
        )
        .unwrap();
        std::fs::write(
            d.join("assets.xml"),
            "<mujoco><asset><!-- <mesh file=\"commented.obj\"/> -->\
             <mesh name=\"m\" file=\"a.obj\"/></asset></mujoco>",
        )
        .unwrap();
        let obj = d.join("parts/a.obj");
        std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n").unwrap();
        let read = || Inputs::read(&d.join("robot.toml")).unwrap();
        let first = read();
        assert_eq!(first.meshes.len(), 1, "{:?}", first.meshes);
        assert_eq!(
            first.meshes[0].0,
            d.canonicalize().unwrap().join("parts/a.obj")
        );
        std::fs::write(&obj, "v 0 0 0\nv 2 0 0\nv 0 1 0\nv 0 0 1\n").unwrap();
        let second = read();
        assert_ne!(
            first.hash(),
            second.hash(),
            "an edited mesh must change the key"
        );
        assert_eq!(first.generator_hashes(), second.generator_hashes());
        // A mesh file that is missing is not in the key (the generator reports it if used).
        std::fs::remove_file(&obj).unwrap();
        assert!(read().meshes.is_empty());
    }
}
