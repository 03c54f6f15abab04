//! The build-script API: generate a robot's kernel module into `OUT_DIR`.

use std::path::Path;

use crate::generate::{Error, Options, generate};

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
    let source = std::fs::read_to_string(model).map_err(|e| Error::Io(model.into(), e))?;
    let generated = generate(model, &source, opts, &mut |s| {
        eprintln!("rbss-codegen: {s}")
    })?;
    // Warnings reach the user through cargo, one line each.
    for line in generated.report.warnings.lines().filter(|l| !l.is_empty()) {
        println!("cargo:warning={line}");
    }
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
