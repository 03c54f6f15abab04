//! Source files: reading a model (or scene) file, and positions in its text.
//!
//! The lowest layer with [`crate::diagnostics`] and [`crate::model`]: the front ends (`parse`,
//! `import`, the scene reader) read their files and turn byte offsets into the 1-based line and
//! column of a [`Pos`] here, so that they need not name each other.

use std::path::Path;

use crate::diagnostics::{Diagnostic, Diagnostics, Pos};

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
