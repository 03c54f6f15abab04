//! Error reports for model files, rendered in the rustc/codespan style.
//!
//! Warnings (a model that compiles but probably says something else than meant, such as an
//! angle of 120 taken as radians) render the same way with `warning:` ([`Diagnostics::render_warnings`]).
//!
//! Every error of a file is collected into one [`Diagnostics`], sorted by position. The first
//! line of each error is the one-line short form `path:line:col: error: message` that tools and
//! editors grep for (as lalrpop prints it); the source line with a caret underline and an
//! optional help line follow:
//!
//! ```text
//! models/stewart_6ups.toml:41:10: error: body `leg3_upper` names unknown parent `leg3_lowr`
//!    |
//! 41 | parent = "leg3_lowr"
//!    |          ^^^^^^^^^^^ not defined in this model
//!    = help: did you mean `leg3_lower` (line 33)?
//!
//! error: could not compile `models/stewart_6ups.toml`: 1 error
//! ```

use std::fmt;

/// A position in a model (or scene) file (1-based line and column, in characters).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Default)]
pub struct Pos {
    pub line: usize,
    pub col: usize,
}

/// One error in a model file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Diagnostic {
    /// Where the underline starts (1-based line and column, in characters).
    pub pos: Pos,
    /// How many characters are underlined (at least 1; cut at the end of the line).
    pub len: usize,
    /// The error, one line, without the `error: ` prefix.
    pub message: String,
    /// Text written after the carets; may be empty.
    pub label: String,
    /// A `= help: ...` line.
    pub help: Option<String>,
    /// The file the error is in when it is not the report's: the source a model file imports
    /// (`pos` and `len` are then in that file).
    pub elsewhere: Option<Box<Elsewhere>>,
}

/// A diagnostic's file when it is not the report's (see [`Diagnostic::elsewhere`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Elsewhere {
    /// The file's path as shown.
    pub path: String,
    /// The text of the diagnostic's line, quoted under the short form.
    pub line: String,
    /// A `= note: ...` line (what the model made of the place).
    pub note: Option<String>,
}

/// A place in a source file: its path as shown, the line and column of the place, how many
/// characters it spans on that line, and the line's text (to quote it).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Place {
    pub path: String,
    pub pos: Pos,
    pub len: usize,
    pub line: String,
}

impl Diagnostic {
    /// A diagnostic without help.
    pub fn new(pos: Pos, len: usize, message: impl Into<String>, label: impl Into<String>) -> Self {
        Diagnostic {
            pos,
            len: len.max(1),
            message: message.into(),
            label: label.into(),
            help: None,
            elsewhere: None,
        }
    }

    /// The same diagnostic with a help line.
    pub fn with_help(mut self, help: impl Into<String>) -> Self {
        self.help = Some(help.into());
        self
    }
}

/// Every error found in one model file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Diagnostics {
    /// The file's path as it is shown in messages.
    pub path: String,
    /// The file's text (to quote the offending lines).
    pub source: String,
    /// The errors, sorted by position.
    pub items: Vec<Diagnostic>,
}

/// Width of a tab when a source line is quoted.
const TAB_WIDTH: usize = 4;

impl Diagnostics {
    /// Collects `items`, sorted by position (a stable sort: errors at the same place keep the
    /// order they were found in; the report's file first, then the others' by path) and
    /// without exact duplicates.
    pub fn new(
        path: impl Into<String>,
        source: impl Into<String>,
        mut items: Vec<Diagnostic>,
    ) -> Self {
        items.sort_by(|a, b| {
            let file = |d: &Diagnostic| d.elsewhere.as_ref().map(|e| e.path.clone());
            file(a).cmp(&file(b)).then(a.pos.cmp(&b.pos))
        });
        items.dedup();
        Diagnostics {
            path: path.into(),
            source: source.into(),
            items,
        }
    }

    /// The full report: every error, then `error: could not compile `PATH`: N errors`.
    pub fn render(&self) -> String {
        let mut out = String::new();
        for d in &self.items {
            self.render_one(d, "error", &mut out);
            out.push('\n');
        }
        let n = self.items.len();
        out.push_str(&format!(
            "error: could not compile `{}`: {} error{}\n",
            self.path,
            n,
            if n == 1 { "" } else { "s" }
        ));
        out
    }

    /// The items rendered as warnings (`path:line:col: warning: ...`, the source line, the help),
    /// then `warning: `PATH`: N warnings`; empty when there are none.
    pub fn render_warnings(&self) -> String {
        let mut out = String::new();
        if self.items.is_empty() {
            return out;
        }
        for d in &self.items {
            self.render_one(d, "warning", &mut out);
            out.push('\n');
        }
        let n = self.items.len();
        out.push_str(&format!(
            "warning: `{}`: {} warning{}\n",
            self.path,
            n,
            if n == 1 { "" } else { "s" }
        ));
        out
    }

    /// The text of line `line` (1-based), without its line ending; empty past the end.
    fn line_text(&self, line: usize) -> &str {
        let text = self
            .source
            .split('\n')
            .nth(line.saturating_sub(1))
            .unwrap_or("");
        text.strip_suffix('\r').unwrap_or(text)
    }

    fn render_one(&self, d: &Diagnostic, severity: &str, out: &mut String) {
        let line = d.pos.line.max(1);
        let col = d.pos.col.max(1);
        let (path, full) = match &d.elsewhere {
            Some(e) => (
                e.path.as_str(),
                e.line.strip_suffix('\r').unwrap_or(&e.line),
            ),
            None => (self.path.as_str(), self.line_text(line)),
        };
        out.push_str(&format!(
            "{}:{}:{}: {severity}: {}\n",
            path,
            line,
            col,
            one_line(&d.message)
        ));
        let num = line.to_string();
        let pad = " ".repeat(num.len());
        // A long line (a 2 MB line of generated text) is quoted around the column only.
        let (text, skipped, cut) = window(full, col, d.len);
        let col = col - skipped;

        // Quote the line, tabs expanded and other control characters made visible.
        let mut shown = String::new();
        // Display width of the text before the caret and of the underlined text.
        let mut before = 0usize;
        let mut under = 0usize;
        let end_col = col.saturating_add(d.len.max(1));
        for (i, c) in text.chars().enumerate() {
            let c_col = i + 1;
            let w = if c == '\t' { TAB_WIDTH } else { 1 };
            if c == '\t' {
                shown.push_str(&" ".repeat(TAB_WIDTH));
            } else if c.is_control() {
                shown.push('\u{FFFD}');
            } else {
                shown.push(c);
            }
            if c_col < col {
                before += w;
            } else if c_col < end_col {
                under += w;
            }
        }
        let line_len = text.chars().count();
        if col > line_len {
            // The position is at (or past) the end of the line: one caret after the text.
            before += col - 1 - line_len.min(col - 1);
            under = 1;
        }
        let under = under.max(1);
        if skipped > 0 {
            shown.insert_str(0, ELLIPSIS);
            before += ELLIPSIS.chars().count();
        }
        if cut {
            shown.push_str(ELLIPSIS);
        }

        out.push_str(&format!("{pad} |\n"));
        if shown.is_empty() {
            out.push_str(&format!("{num} |\n"));
        } else {
            out.push_str(&format!("{num} | {shown}\n"));
        }
        let mut caret_line = format!("{pad} | {}{}", " ".repeat(before), "^".repeat(under));
        let label = one_line(&d.label);
        if !label.is_empty() {
            caret_line.push(' ');
            caret_line.push_str(&label);
        }
        out.push_str(&caret_line);
        out.push('\n');
        if let Some(note) = d.elsewhere.as_ref().and_then(|e| e.note.as_ref()) {
            out.push_str(&format!("{pad} = note: {}\n", one_line(note)));
        }
        if let Some(help) = &d.help {
            out.push_str(&format!("{pad} = help: {}\n", one_line(help)));
        }
    }
}

/// Characters of a quoted line shown on each side of the reported column.
const CONTEXT: usize = 80;
/// Marks a quoted line cut short.
const ELLIPSIS: &str = "...";

/// The part of `text` quoted for column `col` (1-based) and `len` underlined characters: the
/// whole line when it is short, else `CONTEXT` characters each side; with the characters
/// skipped before it and whether the end was cut.
fn window(text: &str, col: usize, len: usize) -> (&str, usize, bool) {
    let chars = text.chars().count();
    if chars <= 2 * CONTEXT + len.min(CONTEXT) + 40 {
        return (text, 0, false);
    }
    let first = col.saturating_sub(CONTEXT + 1).min(chars);
    let last = col
        .saturating_add(len.min(CONTEXT))
        .saturating_add(CONTEXT)
        .min(chars);
    let byte = |c: usize| text.char_indices().nth(c).map_or(text.len(), |(b, _)| b);
    (&text[byte(first)..byte(last)], first, last < chars)
}

/// Keeps a message on one line (the short form must stay greppable).
fn one_line(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c == '\n' || c == '\r' || c == '\t' {
                ' '
            } else {
                c
            }
        })
        .collect()
}

/// Levenshtein distance, `None` when either string is too long to bother.
pub fn edit_distance(a: &str, b: &str) -> Option<usize> {
    let a: Vec<char> = a.chars().collect();
    let b: Vec<char> = b.chars().collect();
    if a.len() > 64 || b.len() > 64 {
        return None;
    }
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    let mut cur = vec![0; b.len() + 1];
    for i in 1..=a.len() {
        cur[0] = i;
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            cur[j] = (prev[j] + 1).min(cur[j - 1] + 1).min(prev[j - 1] + cost);
        }
        std::mem::swap(&mut prev, &mut cur);
    }
    Some(prev[b.len()])
}

/// `did you mean `x` (line N)?` for the closest candidate (name, line) within edit distance 2,
/// or one that differs only in case.
pub fn suggest<'c>(
    name: &str,
    candidates: impl IntoIterator<Item = (&'c str, Option<usize>)>,
) -> Option<String> {
    let mut best: Option<(usize, &str, Option<usize>)> = None;
    for (cand, line) in candidates {
        if cand == name || cand.is_empty() {
            continue;
        }
        let Some(d) = edit_distance(name, cand) else {
            continue;
        };
        let close = d <= 2 && d < name.chars().count().max(cand.chars().count());
        // A difference in case only is the closest match of all.
        let d = if name.to_lowercase() == cand.to_lowercase() {
            0
        } else {
            d
        };
        if (close || d == 0) && best.is_none_or(|(bd, _, _)| d < bd) {
            best = Some((d, cand, line));
        }
    }
    best.map(|(_, cand, line)| match line {
        Some(l) => format!("did you mean `{cand}` (line {l})?"),
        None => format!("did you mean `{cand}`?"),
    })
}

impl fmt::Display for Diagnostics {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.render())
    }
}

impl std::error::Error for Diagnostics {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn renders_like_rustc() {
        let mut source = String::new();
        for i in 1..=40 {
            source.push_str(&format!("# line {i}\n"));
        }
        source.push_str("parent = \"leg3_lowr\"\n");
        let d = Diagnostic::new(
            Pos { line: 41, col: 10 },
            11,
            "body `leg3_upper` names unknown parent `leg3_lowr`",
            "not defined in this model",
        )
        .with_help("did you mean `leg3_lower` (line 33)?");
        let ds = Diagnostics::new("models/stewart_6ups.toml", source, vec![d]);
        assert_eq!(
            ds.render(),
            "models/stewart_6ups.toml:41:10: error: body `leg3_upper` names unknown parent `leg3_lowr`\n\
             \x20  |\n\
             41 | parent = \"leg3_lowr\"\n\
             \x20  |          ^^^^^^^^^^^ not defined in this model\n\
             \x20  = help: did you mean `leg3_lower` (line 33)?\n\
             \n\
             error: could not compile `models/stewart_6ups.toml`: 1 error\n"
        );
        assert_eq!(ds.to_string(), ds.render());
    }

    #[test]
    fn sorts_and_handles_odd_positions() {
        let items = vec![
            Diagnostic::new(Pos { line: 3, col: 1 }, 1, "b", ""),
            Diagnostic::new(Pos { line: 1, col: 50 }, 100, "a", "x"),
            Diagnostic::new(Pos { line: 0, col: 0 }, 0, "z", ""),
        ];
        let ds = Diagnostics::new("f.toml", "ab\tc\n", items);
        let r = ds.render();
        assert!(r.starts_with("f.toml:1:1: error: z\n"), "{r}");
        assert!(r.contains("f.toml:1:50: error: a\n"));
        assert!(r.contains("f.toml:3:1: error: b\n"));
        assert!(r.ends_with("error: could not compile `f.toml`: 3 errors\n"));
        assert!(r.contains("1 | ab    c\n"));
    }
}
