//! Minimal CSV output: a header and rows of numbers in shortest round-trip form, written
//! through a temporary file (see [`crate::output`]) so a reader never sees half a file.

use std::io::Write;
use std::path::Path;

use crate::output::Outputs;

/// Writes `header` and `rows` to `path` (comma-separated, `\n` line ends) on its own.
pub fn write(path: &Path, header: &[String], rows: &[Vec<f64>]) -> Result<(), String> {
    let mut out = Outputs::new();
    write_to(&mut out, path, header, rows)?;
    out.commit()
}

/// Writes `header` and `rows` as the file `path` of the run `out`: it appears when `out` is
/// committed, with the run's other files.
pub fn write_to(
    out: &mut Outputs,
    path: &Path,
    header: &[String],
    rows: &[Vec<f64>],
) -> Result<(), String> {
    let err = |e: std::io::Error| format!("{}: cannot write: {e}", path.display());
    let file = out.create(path)?;
    let mut w = std::io::BufWriter::new(file);
    writeln!(w, "{}", header.join(",")).map_err(err)?;
    for row in rows {
        let mut first = true;
        for v in row {
            if !first {
                w.write_all(b",").map_err(err)?;
            }
            first = false;
            write!(w, "{v:?}").map_err(err)?;
        }
        w.write_all(b"\n").map_err(err)?;
    }
    w.flush().map_err(err)
}

/// `prefix1, prefix2, ... prefixN`.
pub fn numbered(prefix: &str, n: usize) -> Vec<String> {
    (1..=n).map(|i| format!("{prefix}{i}")).collect()
}
