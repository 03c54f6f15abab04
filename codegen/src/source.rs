//! Source files: reading a model (or scene) file, and positions in its text.
//!
//! The lowest layer with [`crate::diagnostics`] and [`crate::model`]: the front ends (`parse`,
//! `import`, the scene reader) read their files and turn byte offsets into the 1-based line and
//! column of a [`Pos`] here, so that they need not name each other.

use std::path::Path;

use crate::diagnostics::{Diagnostic, Diagnostics, Elsewhere, Place, Pos};

/// The line starts of a text: byte offset -> [`Pos`] by binary search.
pub struct LineIndex<'s> {
    src: &'s str,
    starts: Vec<usize>,
}

impl<'s> LineIndex<'s> {
    pub fn new(src: &'s str) -> Self {
        let mut starts = vec![0];
        starts.extend(
            src.bytes()
                .enumerate()
                .filter(|(_, b)| *b == b'\n')
                .map(|(i, _)| i + 1),
        );
        LineIndex { src, starts }
    }

    /// `byte` moved back to a character boundary (and into the text).
    pub fn floor(&self, mut byte: usize) -> usize {
        byte = byte.min(self.src.len());
        while byte > 0 && !self.src.is_char_boundary(byte) {
            byte -= 1;
        }
        byte
    }

    /// The line and column (in characters, 1-based) of `byte`.
    pub fn pos(&self, byte: usize) -> Pos {
        let mut byte = self.floor(byte);
        // The `\n` of a CRLF line ending, or the end of a file that ends in a lone `\r`, is
        // reported at the `\r`: one column past the end of the line's text, as for LF files
        // (the `\r` is not shown when the line is quoted).
        let rest = &self.src.as_bytes()[byte..];
        if byte > 0
            && self.src.as_bytes()[byte - 1] == b'\r'
            && (rest.is_empty() || rest[0] == b'\n')
        {
            byte -= 1;
        }
        let line = match self.starts.binary_search(&byte) {
            Ok(i) => i,
            Err(i) => i.saturating_sub(1),
        };
        let start = self.starts.get(line).copied().unwrap_or(0).min(byte);
        let col = self
            .src
            .get(start..byte)
            .map(|s| s.chars().count())
            .unwrap_or(0)
            + 1;
        Pos {
            line: line + 1,
            col,
        }
    }
}

/// The [`Pos`] of one byte offset of `src` (see [`LineIndex::pos`]).
pub fn pos_of(src: &str, byte: usize) -> Pos {
    LineIndex::new(src).pos(byte)
}

/// The text of a model (or scene) file, or a located error: `cannot read` at 1:1, or "not
/// valid UTF-8" at the line and column of the first invalid byte (the line shown with the bad
/// bytes replaced).
pub fn read_source(path: &Path) -> Result<String, Diagnostics> {
    let shown = path.display().to_string();
    match std::fs::read(path) {
        Err(e) => Err(Diagnostics::new(
            shown.clone(),
            String::new(),
            vec![Diagnostic::new(
                Pos { line: 1, col: 1 },
                1,
                format!("cannot read `{shown}`: {e}"),
                "",
            )],
        )),
        Ok(bytes) => match String::from_utf8(bytes) {
            Ok(source) => Ok(source),
            Err(e) => {
                let bytes = e.into_bytes();
                let good =
                    std::str::from_utf8(&bytes).map_or_else(|e| e.valid_up_to(), |s| s.len());
                let text = String::from_utf8_lossy(&bytes).into_owned();
                // The valid prefix is unchanged by the lossy conversion.
                let pos = pos_of(&text, good);
                let d =
                    Diagnostic::new(pos, 1, "the model file is not valid UTF-8", "invalid byte");
                Err(Diagnostics::new(shown, text.clone(), vec![d]))
            }
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn positions_count_characters_and_put_crlf_at_the_cr() {
        let src = "ab\r\nçd\n";
        assert_eq!(pos_of(src, 0), Pos { line: 1, col: 1 });
        // The `\n` of the CRLF is reported at the `\r`.
        assert_eq!(pos_of(src, 3), Pos { line: 1, col: 3 });
        // `d` is the second character of line 2 (`ç` is two bytes).
        assert_eq!(pos_of(src, 6), Pos { line: 2, col: 2 });
        // Inside `ç`: the character's start.
        assert_eq!(pos_of(src, 5), Pos { line: 2, col: 1 });
        assert_eq!(pos_of(src, 99), Pos { line: 3, col: 1 });
    }
}

/// Where the lines of a merged text come from: the model file's own lines are its first ones;
/// each line of the imported model comes from an element of the source (a `[[body]]`'s
/// `inertia` from the link's `<inertia>`, a coordinate from its `<joint>`), or, for the lines no
/// element gave (the header, `coordinates = [`), from the model file's source key.
#[derive(Debug, Clone, Default)]
pub struct SourceMap {
    /// The model file's length in bytes: its text is the merged text's start.
    pub model_len: usize,
    /// The merged text's line (1-based) of the imported model's first line.
    pub(crate) first_line: usize,
    /// Each imported line: its text (its comment cut) and its place in the source.
    pub(crate) lines: Vec<(String, Option<Place>)>,
    /// The model file's source key's value (`"arm.urdf"`): its position and length.
    pub(crate) key: (Pos, usize),
}

impl SourceMap {
    /// `d` (positions in the merged text) with every position in the imported model moved to
    /// the source's element it comes from (the imported line as a note), "(line N)" in its
    /// texts the same, and the model file's own text to quote.
    pub fn relocate(&self, d: Diagnostics, merged: &str) -> Diagnostics {
        let model = merged.get(..self.model_len).unwrap_or(merged).to_string();
        let items = d
            .items
            .into_iter()
            .map(|mut item| {
                if item.elsewhere.is_none()
                    && let Some((text, place)) = self.imported(item.pos.line)
                {
                    let note = format!("imported as `{}`", short(text));
                    match place {
                        Some(p) => {
                            item.pos = p.pos;
                            item.len = p.len;
                            item.elsewhere = Some(Box::new(Elsewhere {
                                path: p.path.clone(),
                                line: p.line.clone(),
                                note: Some(note),
                            }));
                        }
                        None => {
                            item.pos = self.key.0;
                            item.len = self.key.1;
                            item.label = "in the model imported from this file".into();
                            item.help = Some(match item.help.take() {
                                Some(h) => format!("{note}; {h}"),
                                None => note,
                            });
                        }
                    }
                }
                item.message = self.lines_named(&item.message);
                item.label = self.lines_named(&item.label);
                item.help = item.help.map(|h| self.lines_named(&h));
                item
            })
            .collect();
        Diagnostics::new(d.path, model, items)
    }

    /// The imported line at `line` of the merged text, if it is one.
    fn imported(&self, line: usize) -> Option<&(String, Option<Place>)> {
        line.checked_sub(self.first_line)
            .and_then(|k| self.lines.get(k))
    }

    /// `s` with every "line N" of an imported line as "FILE:LINE" of its source ("on line N"
    /// as "at FILE:LINE").
    fn lines_named(&self, s: &str) -> String {
        let mut out = String::new();
        let mut rest = s;
        while let Some(i) = rest.find("line ") {
            let word = i == 0 || rest[..i].ends_with([' ', '(']);
            let after = &rest[i + 5..];
            let digits = after.bytes().take_while(u8::is_ascii_digit).count();
            let place = after[..digits]
                .parse::<usize>()
                .ok()
                .filter(|_| word && !after[digits..].starts_with(|c: char| c.is_alphanumeric()))
                .and_then(|n| self.imported(n))
                .and_then(|(_, p)| p.as_ref());
            match place {
                Some(p) => {
                    let head = &rest[..i];
                    match head.strip_suffix("on ") {
                        Some(h) => {
                            out.push_str(h);
                            out.push_str("at ");
                        }
                        None => out.push_str(head),
                    }
                    out.push_str(&format!("{}:{}", p.path, p.pos.line));
                    rest = &after[digits..];
                }
                None => {
                    out.push_str(&rest[..i + 5]);
                    rest = after;
                }
            }
        }
        out.push_str(rest);
        out
    }
}

/// An imported line as a note shows it: without its comment, at most 120 characters.
fn short(line: &str) -> String {
    let line = match line.find("  # <") {
        Some(i) => &line[..i],
        None => line,
    };
    let line = line.trim();
    if line.chars().count() > 120 {
        let cut: String = line.chars().take(117).collect();
        format!("{cut}...")
    } else {
        line.to_string()
    }
}
