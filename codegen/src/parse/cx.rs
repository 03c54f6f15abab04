//! Positions in the model file and the collected errors.

use super::*;
use crate::source::LineIndex;

// Positions and error collection

pub(super) struct Cx<'s> {
    pub(super) src: &'s str,
    lines: LineIndex<'s>,
    pub(super) diags: Vec<Diagnostic>,
}

impl<'s> Cx<'s> {
    pub(super) fn new(src: &'s str) -> Self {
        Cx {
            src,
            lines: LineIndex::new(src),
            diags: Vec::new(),
        }
    }

    pub(super) fn floor(&self, byte: usize) -> usize {
        self.lines.floor(byte)
    }

    pub(super) fn pos(&self, byte: usize) -> Pos {
        self.lines.pos(byte)
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
