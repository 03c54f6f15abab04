//! Minimal CSV output: a header and rows of numbers in shortest round-trip form, written
//! through a temporary file so a reader never sees half a file.

use std::io::Write;
use std::path::Path;

/// Writes `header` and `rows` to `path` (comma-separated, `\n` line ends).
pub fn write(path: &Path, header: &[String], rows: &[Vec<f64>]) -> Result<(), String> {
    let err = |e: std::io::Error| format!("{}: cannot write: {e}", path.display());
    let tmp = path.with_extension("csv.partial");
    {
        let file = std::fs::File::create(&tmp).map_err(err)?;
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
        w.flush().map_err(err)?;
    }
    std::fs::rename(&tmp, path).map_err(err)
}

/// `prefix1, prefix2, ... prefixN`.
pub fn numbered(prefix: &str, n: usize) -> Vec<String> {
    (1..=n).map(|i| format!("{prefix}{i}")).collect()
}
