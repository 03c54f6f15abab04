//! The XML side of the importers: parsing with limits, positions, located errors, attributes
//! read as numbers.

use std::cell::Cell;
use std::ops::Range;

use roxmltree::{Document, Node, ParsingOptions};

use super::{MAX_DEPTH, MAX_NODES};
use crate::diagnostics::{Diagnostic, Diagnostics, Place};
use crate::model::Pos;
use crate::source::LineIndex;

/// One file: its path as shown, its text, where its lines start.
struct File<'t> {
    path: String,
    text: &'t str,
    lines: LineIndex<'t>,
}

/// The source files (the source and the files it includes) and the errors and warnings found
/// in them. Positions are in the current file: the one of the node last asked about
/// ([`Cx::tag`], [`Cx::attr_range`], [`Cx::numbers`] ... take the node).
pub(crate) struct Cx<'t> {
    /// The source's path as shown.
    pub(crate) path: String,
    files: Vec<File<'t>>,
    current: Cell<usize>,
    errors: Vec<(usize, Diagnostic)>,
    warnings: Vec<(usize, Diagnostic)>,
    /// The model file's renames; the source's names seen.
    pub(crate) renames: super::Renames,
}

impl<'t> Cx<'t> {
    pub(crate) fn new(path: &str, text: &'t str) -> Self {
        let mut cx = Cx {
            path: path.to_string(),
            files: Vec::new(),
            current: Cell::new(0),
            errors: Vec::new(),
            warnings: Vec::new(),
            renames: super::Renames::default(),
        };
        cx.add_file(path, text);
        cx
    }

    /// The identifier of the source's joint `name`: the model file's rename, else [`super::ident`].
    pub(crate) fn joint_name(&mut self, name: &str) -> String {
        self.renames.joint(name)
    }

    /// The identifier of the source's body (link) `name`: as [`Cx::joint_name`].
    pub(crate) fn body_name(&mut self, name: &str) -> String {
        self.renames.body(name)
    }

    /// Adds an included file; its index.
    pub(crate) fn add_file(&mut self, path: &str, text: &'t str) -> usize {
        self.files.push(File {
            path: path.to_string(),
            text,
            lines: LineIndex::new(text),
        });
        self.files.len() - 1
    }

    /// The path (as shown) of the file `node` is in.
    pub(crate) fn path_of(&self, node: Node<'_, '_>) -> &str {
        let ptr = node.document().input_text().as_ptr();
        self.files
            .iter()
            .find(|f| f.text.as_ptr() == ptr)
            .map_or(self.path.as_str(), |f| f.path.as_str())
    }

    /// The texts of the included files (hashed with the source).
    pub(crate) fn included(&self) -> Vec<&'t str> {
        self.files[1..].iter().map(|f| f.text).collect()
    }

    fn text(&self) -> &'t str {
        self.files[self.current.get()].text
    }

    /// Makes the file of `node` the current one.
    fn enter(&self, node: Node<'_, '_>) {
        let ptr = node.document().input_text().as_ptr();
        if let Some(k) = self.files.iter().position(|f| f.text.as_ptr() == ptr) {
            self.current.set(k);
        }
    }

    /// The document of the source, or its one XML error.
    pub(crate) fn parse(&mut self) -> Result<Document<'t>, Diagnostics> {
        self.parse_file(0)
    }

    /// The document of file `k`, or its one XML error. DTDs are refused (no entity is expanded), and the
    /// number of nodes and the depth are bounded.
    pub(crate) fn parse_file(&mut self, k: usize) -> Result<Document<'t>, Diagnostics> {
        self.current.set(k);
        let opts = ParsingOptions {
            allow_dtd: false,
            nodes_limit: MAX_NODES,
            ..ParsingOptions::default()
        };
        let fail = |cx: &Self, pos: Pos, msg: String, help: &str| {
            let mut d = Diagnostic::new(pos, 1, msg, "");
            if !help.is_empty() {
                d = d.with_help(help);
            }
            let f = &cx.files[k];
            Err(Diagnostics::new(
                f.path.clone(),
                f.text.to_string(),
                vec![d],
            ))
        };
        let doc = match Document::parse_with_options(self.text(), opts) {
            Ok(doc) => doc,
            Err(e) => {
                let mut p = e.pos();
                if matches!(e, roxmltree::Error::DtdDetected)
                    && let Some(at) = self.text().find("<!DOCTYPE")
                {
                    let q = self.pos(at);
                    p = roxmltree::TextPos::new(q.line as u32, q.col as u32);
                }
                let help = match e {
                    roxmltree::Error::DtdDetected => {
                        "a robot description needs no DTD: entities are not expanded, remove the `<!DOCTYPE ...>`"
                    }
                    roxmltree::Error::NodesLimitReached => {
                        "the file has more nodes than a robot description may have"
                    }
                    _ => "",
                };
                let pos = Pos {
                    line: p.row as usize,
                    col: p.col as usize,
                };
                // roxmltree's message ends with the position, which the report gives already.
                let msg = e.to_string();
                let msg = match msg.rsplit_once(" at ") {
                    Some((m, at)) if at.split(':').all(|n| n.parse::<u32>().is_ok()) => {
                        m.to_string()
                    }
                    _ => msg,
                };
                return fail(self, pos, format!("XML: {msg}"), help);
            }
        };
        // Depth, without recursion: a node's depth is its parent's plus one.
        let mut depth = vec![0usize; doc.descendants().count() + 1];
        for n in doc.descendants() {
            let d = n.parent().map_or(0, |p| depth[p.id().get_usize()] + 1);
            depth[n.id().get_usize()] = d;
            if d > MAX_DEPTH {
                let pos = self.pos(n.range().start);
                return fail(
                    self,
                    pos,
                    format!("XML: elements nested more than {MAX_DEPTH} deep"),
                    "a robot description is not this deep: is the file what it should be?",
                );
            }
        }
        Ok(doc)
    }

    /// Line and column (1-based, in characters) of a byte offset.
    pub(crate) fn pos(&self, byte: usize) -> Pos {
        self.files[self.current.get()].lines.pos(byte)
    }

    fn diag(&self, range: &Range<usize>, msg: String, label: &str, help: &str) -> Diagnostic {
        let len = self
            .text()
            .get(range.clone())
            .map_or(1, |s| s.lines().next().unwrap_or("").chars().count());
        let d = Diagnostic::new(self.pos(range.start), len, msg, label);
        if help.is_empty() {
            d
        } else {
            d.with_help(help)
        }
    }

    pub(crate) fn error(
        &mut self,
        range: &Range<usize>,
        msg: impl Into<String>,
        label: &str,
        help: &str,
    ) {
        let d = self.diag(range, msg.into(), label, help);
        self.errors.push((self.current.get(), d));
    }

    pub(crate) fn warn(
        &mut self,
        range: &Range<usize>,
        msg: impl Into<String>,
        label: &str,
        help: &str,
    ) {
        let d = self.diag(range, msg.into(), label, help);
        self.warnings.push((self.current.get(), d));
    }

    /// The errors of the first file that has any (the source first), and every warning (each
    /// file's apart: the source's with its own).
    pub(crate) fn finish(self) -> (Option<Diagnostics>, Vec<Diagnostics>) {
        let of = |list: &[(usize, Diagnostic)], k: usize| -> Vec<Diagnostic> {
            list.iter()
                .filter(|(f, _)| *f == k)
                .map(|(_, d)| d.clone())
                .collect()
        };
        let errors = (0..self.files.len()).find_map(|k| {
            let items = of(&self.errors, k);
            (!items.is_empty())
                .then(|| Diagnostics::new(self.files[k].path.clone(), self.files[k].text, items))
        });
        let warnings = (0..self.files.len())
            .map(|k| {
                Diagnostics::new(
                    self.files[k].path.clone(),
                    self.files[k].text,
                    of(&self.warnings, k),
                )
            })
            .collect();
        (errors, warnings)
    }

    /// `FILE:LINE` of a node, for the written model's comments.
    pub(crate) fn at(&self, node: Node<'_, '_>) -> String {
        self.enter(node);
        let f = &self.files[self.current.get()];
        format!("{}:{}", f.path, self.pos(node.range().start).line)
    }

    /// The place of an element's tag name (where an error of what it imports to is reported).
    pub(crate) fn place(&self, node: Node<'_, '_>) -> Place {
        let r = self.tag(node);
        let f = &self.files[self.current.get()];
        let pos = f.lines.pos(r.start);
        let line = f.text.split('\n').nth(pos.line - 1).unwrap_or("");
        Place {
            path: f.path.clone(),
            pos,
            len: r.len(),
            line: line.strip_suffix('\r').unwrap_or(line).to_string(),
        }
    }

    /// The origin of what `node` imports to: the element, its line, its place.
    pub(crate) fn origin(&self, node: Node<'_, '_>) -> super::Origin {
        super::Origin {
            element: element(node),
            at: self.at(node),
            place: Some(self.place(node)),
        }
    }

    /// The range of an element's tag name.
    pub(crate) fn tag(&self, node: Node<'_, '_>) -> Range<usize> {
        self.enter(node);
        let s = node.range().start + 1;
        s..s + node.tag_name().name().len()
    }

    /// The range of an attribute's value, or of the element's tag when it has none.
    pub(crate) fn attr_range(&self, node: Node<'_, '_>, name: &str) -> Range<usize> {
        self.enter(node);
        node.attribute_node(name)
            .map_or_else(|| self.tag(node), |a| a.range_value())
    }

    /// A required attribute, or an error at the element.
    pub(crate) fn required<'a>(&mut self, node: Node<'a, '_>, name: &str) -> Option<&'a str> {
        let v = node.attribute(name);
        if v.is_none() {
            let tag = node.tag_name().name().to_string();
            self.error(
                &self.tag(node),
                format!("`<{tag}>` has no `{name}`"),
                &format!("`{name}=\"...\"` missing"),
                "",
            );
        }
        v
    }

    /// Attribute `name` as `n` numbers (`n == 0`: any count), each `(text, value)`; an
    /// error at the first bad number or at the value of the wrong count.
    pub(crate) fn numbers(
        &mut self,
        node: Node<'_, '_>,
        name: &str,
        n: usize,
    ) -> Option<Vec<(String, f64)>> {
        let attr = node.attribute_node(name)?;
        self.enter(node);
        let value = attr.value();
        let range = attr.range_value();
        // The value's text in the file (entities are expanded in `value`; positions are only
        // exact when the two agree, which they do for numbers).
        let raw = &self.text()[range.clone()];
        let mut out = Vec::new();
        let mut ok = true;
        let mut offset = 0usize;
        for tok in value.split_ascii_whitespace() {
            let at = raw[offset..]
                .find(tok)
                .map_or(range.start, |i| range.start + offset + i);
            if raw.get(offset..).is_some_and(|r| r.contains(tok)) {
                offset = at - range.start + tok.len();
            }
            match tok.parse::<f64>() {
                Ok(v) if v.is_finite() => out.push((tok.to_string(), v)),
                _ => {
                    self.error(
                        &(at..at + tok.len()),
                        format!(
                            "`{name}` of `<{}>`: `{tok}` is not a finite number",
                            node.tag_name().name()
                        ),
                        "not a number",
                        "",
                    );
                    ok = false;
                }
            }
        }
        if ok && n > 0 && out.len() != n {
            self.error(
                &range,
                format!(
                    "`{name}` of `<{}>` has {} number{}, not {n}",
                    node.tag_name().name(),
                    out.len(),
                    if out.len() == 1 { "" } else { "s" }
                ),
                &format!("{n} numbers expected"),
                "",
            );
            ok = false;
        }
        ok.then_some(out)
    }

    /// The text of element `node` as `n` numbers (`<pose>0 0 1 0 0 0</pose>`), each located.
    pub(crate) fn text_numbers(
        &mut self,
        node: Node<'_, '_>,
        n: usize,
    ) -> Option<Vec<(String, f64)>> {
        self.enter(node);
        let what = format!("`<{}>`", node.tag_name().name());
        let (range, value) = match node.first_child().filter(|c| c.is_text()) {
            Some(t) => (t.range(), t.text().unwrap_or("")),
            None => (self.tag(node), ""),
        };
        let raw = self.text().get(range.clone()).unwrap_or("");
        let mut out = Vec::new();
        let mut ok = true;
        let mut offset = 0usize;
        for tok in value.split_ascii_whitespace() {
            let at = match raw.get(offset..).and_then(|r| r.find(tok)) {
                Some(i) => {
                    offset += i + tok.len();
                    range.start + offset - tok.len()
                }
                None => range.start,
            };
            match tok.parse::<f64>() {
                Ok(v) if v.is_finite() => out.push((tok.to_string(), v)),
                _ => {
                    self.error(
                        &(at..at + tok.len()),
                        format!("{what}: `{tok}` is not a finite number"),
                        "not a number",
                        "",
                    );
                    ok = false;
                }
            }
        }
        if ok && n > 0 && out.len() != n {
            self.error(
                &range,
                format!(
                    "{what} has {} number{}, not {n}",
                    out.len(),
                    if out.len() == 1 { "" } else { "s" }
                ),
                &format!("{n} numbers expected"),
                "",
            );
            ok = false;
        }
        ok.then_some(out)
    }

    /// One number (attribute `name`), `None` when absent or bad (reported).
    pub(crate) fn number(&mut self, node: Node<'_, '_>, name: &str) -> Option<(String, f64)> {
        self.numbers(node, name, 1).map(|mut v| v.remove(0))
    }
}

/// `<joint name="q2">`: an element as the written model's comments name it.
pub(crate) fn element(node: Node<'_, '_>) -> String {
    match node.attribute("name") {
        Some(n) => format!("<{} name=\"{n}\">", node.tag_name().name()),
        None => format!("<{}>", node.tag_name().name()),
    }
}

/// The child elements of `node` named `tag`.
pub(crate) fn children<'a, 'i>(
    node: Node<'a, 'i>,
    tag: &'a str,
) -> impl Iterator<Item = Node<'a, 'i>> + 'a {
    node.children()
        .filter(move |c| c.is_element() && c.tag_name().name() == tag)
}

/// The first child element named `tag`.
pub(crate) fn child<'a, 'i>(node: Node<'a, 'i>, tag: &str) -> Option<Node<'a, 'i>> {
    node.children()
        .find(|c| c.is_element() && c.tag_name().name() == tag)
}
