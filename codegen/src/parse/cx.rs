//! Positions in the model file and the collected errors.

use super::*;

// Positions and error collection

pub(super) struct Cx<'s> {
    pub(super) src: &'s str,
    pub(super) line_starts: Vec<usize>,
    pub(super) diags: Vec<Diagnostic>,
}

impl<'s> Cx<'s> {
    pub(super) fn new(src: &'s str) -> Self {
        let mut line_starts = vec![0];
        line_starts.extend(
            src.bytes()
                .enumerate()
                .filter(|(_, b)| *b == b'\n')
                .map(|(i, _)| i + 1),
        );
        Cx {
            src,
            line_starts,
            diags: Vec::new(),
        }
    }

    pub(super) fn floor(&self, mut byte: usize) -> usize {
        byte = byte.min(self.src.len());
        while byte > 0 && !self.src.is_char_boundary(byte) {
            byte -= 1;
        }
        byte
    }

    pub(super) fn pos(&self, byte: usize) -> Pos {
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
        let line = match self.line_starts.binary_search(&byte) {
            Ok(i) => i,
            Err(i) => i.saturating_sub(1),
        };
        let start = self.line_starts.get(line).copied().unwrap_or(0).min(byte);
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

    pub(super) fn text(&self, span: &Span) -> &'s str {
        let (a, b) = (self.floor(span.start), self.floor(span.end));
        self.src.get(a..b.max(a)).unwrap_or("")
    }

    /// Characters in `span` (at least 1).
    pub(super) fn len(&self, span: &Span) -> usize {
        self.text(span).chars().count().max(1)
    }

    pub(super) fn line(&self, span: &Span) -> usize {
        self.pos(span.start).line
    }

    pub(super) fn error(
        &mut self,
        span: &Span,
        message: impl Into<String>,
        label: impl Into<String>,
    ) -> &mut Diagnostic {
        let d = Diagnostic::new(self.pos(span.start), self.len(span), message, label);
        self.push(d)
    }

    pub(super) fn error_at(
        &mut self,
        pos: Pos,
        len: usize,
        message: impl Into<String>,
        label: impl Into<String>,
    ) -> &mut Diagnostic {
        self.push(Diagnostic::new(pos, len, message, label))
    }

    pub(super) fn push(&mut self, d: Diagnostic) -> &mut Diagnostic {
        self.diags.push(d);
        let last = self.diags.len() - 1;
        &mut self.diags[last]
    }
}

/// "a string", "an integer"...
pub(super) fn type_name(v: &DeValue<'_>) -> &'static str {
    match v {
        DeValue::String(_) => "a string",
        DeValue::Integer(_) => "an integer",
        DeValue::Float(_) => "a float",
        DeValue::Boolean(_) => "a boolean",
        DeValue::Datetime(_) => "a date-time",
        DeValue::Array(_) => "an array",
        DeValue::Table(_) => "a table",
    }
}

pub(super) fn get<'b, 'a>(t: &'b DeTable<'a>, key: &str) -> Option<&'b Value<'a>> {
    t.iter()
        .find(|(k, _)| k.get_ref().as_ref() == key)
        .map(|(_, v)| v)
}

pub(super) fn key_span(t: &DeTable<'_>, key: &str) -> Option<Span> {
    t.iter()
        .find(|(k, _)| k.get_ref().as_ref() == key)
        .map(|(k, _)| k.span())
}

pub(super) fn list(items: &[&str]) -> String {
    let quoted: Vec<String> = items.iter().map(|s| format!("`{s}`")).collect();
    match quoted.len() {
        0 => String::new(),
        1 => quoted[0].clone(),
        n => format!("{} or {}", quoted[..n - 1].join(", "), quoted[n - 1]),
    }
}
