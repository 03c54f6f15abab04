//! Repetition for symmetric robots, expanded before the document is walked.
//!
//! - An entry of `coordinates`, `[[body]]` or `[[loop]]`, or a parameter, with `count = N` is
//!   written N times in its place, with `{i}` replaced by 1, 2, ..., N in every string of the
//!   entry (names, parents, transforms, expressions) and, for a parameter, in its name (a
//!   quoted key such as `"alpha{i}"`). A coordinate's `home` and a parameter's `value` may be a
//!   list of N values, one per copy (a parameter's `count` may then be left out).
//! - `[[leg]]` with `count = N` and its own `[[leg.body]]` and `[[leg.loop]]` entries writes
//!   them N times, copy by copy (leg 1's bodies, then leg 2's...), at the place of `[[leg]]`
//!   among the model's `[[body]]` and `[[loop]]` entries.
//!
//! The expansion is exactly what one writes by hand: the walker then sees N ordinary entries,
//! whose positions point back at the template. An error the N copies share is reported once.

use std::borrow::Cow;

use toml::de::DeArray;

use super::*;

/// The text `{i}` stands for in a repeated entry.
pub(super) const INDEX: &str = "{i}";
/// The largest `count` (a model of thousands of legs is a typo, and the expansion is eager).
const MAX_COUNT: i64 = 1000;
const LEG_KEYS: &[&str] = &["count", "body", "loop"];

/// `{i}` replaced by `i` in a string value and, recursively, in arrays and tables (keys stay).
fn substitute<'a>(v: &Value<'a>, i: usize) -> Value<'a> {
    let value = match v.get_ref() {
        DeValue::String(s) if s.contains(INDEX) => {
            DeValue::String(Cow::Owned(s.replace(INDEX, &i.to_string())))
        }
        DeValue::Array(a) => {
            let mut out = DeArray::new();
            for x in a.iter() {
                out.push(substitute(x, i));
            }
            DeValue::Array(out)
        }
        DeValue::Table(t) => {
            let mut out = DeTable::new();
            for (k, x) in t.iter() {
                out.insert(k.clone(), substitute(x, i));
            }
            DeValue::Table(out)
        }
        other => other.clone(),
    };
    Spanned::new(v.span(), value)
}

/// Which kind of entry, for messages and for the key that may hold one value per copy.
#[derive(Clone, Copy)]
enum Entry {
    Coordinate,
    Body,
    Loop,
}

impl Entry {
    fn what(self) -> &'static str {
        match self {
            Entry::Coordinate => "coordinate",
            Entry::Body => "body",
            Entry::Loop => "loop",
        }
    }
    /// The key that may be a list of one value per copy.
    fn per_copy(self) -> Option<&'static str> {
        match self {
            Entry::Coordinate => Some("home"),
            Entry::Body | Entry::Loop => None,
        }
    }
}

impl<'s> Parser<'s> {
    /// The document with every `count` and `[[leg]]` expanded (see the module's doc).
    pub(super) fn expand<'a>(&mut self, root: &DeTable<'a>) -> DeTable<'a> {
        let mut out = DeTable::new();
        // (place in the file, entry) for `[[body]]` and `[[loop]]`, legs' copies included.
        let mut bodies: Vec<(usize, Vec<Value<'a>>)> = Vec::new();
        let mut loops: Vec<(usize, Vec<Value<'a>>)> = Vec::new();
        let mut body_key = None;
        let mut loop_key = None;
        for (k, v) in root.iter() {
            match k.get_ref().as_ref() {
                "coordinates" => {
                    out.insert(k.clone(), self.expand_list(v, Entry::Coordinate));
                }
                "parameters" => {
                    out.insert(k.clone(), self.expand_parameters(v));
                }
                key @ ("body" | "loop") => {
                    let (entry, list, slot) = if key == "body" {
                        (Entry::Body, &mut bodies, &mut body_key)
                    } else {
                        (Entry::Loop, &mut loops, &mut loop_key)
                    };
                    match v.get_ref() {
                        DeValue::Array(items) => {
                            *slot = Some((k.clone(), v.span()));
                            for item in items.iter() {
                                let copies = self.expand_entry(item, entry, false);
                                list.push((item.span().start, copies));
                            }
                        }
                        // Not an array: the walker reports it.
                        _ => {
                            out.insert(k.clone(), v.clone());
                        }
                    }
                }
                "leg" => {
                    let Some(legs) = self.array(v, "`leg`") else {
                        continue;
                    };
                    for leg in legs {
                        let (b, l) = self.expand_leg(leg);
                        if !b.is_empty() {
                            body_key.get_or_insert_with(|| {
                                (Spanned::new(k.span(), Cow::Borrowed("body")), leg.span())
                            });
                            bodies.push((leg.span().start, b));
                        }
                        if !l.is_empty() {
                            loop_key.get_or_insert_with(|| {
                                (Spanned::new(k.span(), Cow::Borrowed("loop")), leg.span())
                            });
                            loops.push((leg.span().start, l));
                        }
                    }
                }
                _ => {
                    self.no_index(v);
                    out.insert(k.clone(), v.clone());
                }
            }
        }
        for (key, list) in [(body_key, bodies), (loop_key, loops)] {
            let Some((key, span)) = key else { continue };
            let mut list = list;
            let imported = self.imported_from;
            list.sort_by_key(|(at, _)| (*at < imported, *at));
            let mut array = DeArray::new();
            for item in list.into_iter().flat_map(|(_, items)| items) {
                array.push(item);
            }
            out.insert(key, Spanned::new(span, DeValue::Array(array)));
        }
        out
    }

    /// An array of entries (`coordinates`), each expanded in its place.
    fn expand_list<'a>(&mut self, v: &Value<'a>, entry: Entry) -> Value<'a> {
        let DeValue::Array(items) = v.get_ref() else {
            return v.clone();
        };
        let mut out = DeArray::new();
        for item in items.iter() {
            for copy in self.expand_entry(item, entry, false) {
                out.push(copy);
            }
        }
        Spanned::new(v.span(), DeValue::Array(out))
    }

    /// One entry: itself, or its `count` copies. `in_leg`: the entry is inside `[[leg]]`,
    /// which does the repeating (a `count` of its own is an error).
    fn expand_entry<'a>(&mut self, item: &Value<'a>, entry: Entry, in_leg: bool) -> Vec<Value<'a>> {
        let DeValue::Table(t) = item.get_ref() else {
            return vec![item.clone()];
        };
        let Some(count_v) = get(t, "count") else {
            if !in_leg {
                self.no_index(item);
            }
            return vec![item.clone()];
        };
        if in_leg {
            let what = entry.what();
            let d = self.cx.error(
                &count_v.span(),
                format!("a {what} inside `[[leg]]` cannot have its own `count`"),
                "the leg's `count` repeats it",
            );
            d.help = Some(format!(
                "remove this `count`, or move the {what} out of the leg to repeat it on its own"
            ));
            return vec![without(item, "count")];
        }
        let count = self.count(count_v);
        if let Some(name) = get(t, "name")
            && let DeValue::String(s) = name.get_ref()
            && !s.contains(INDEX)
        {
            let d = self.cx.error(
                &name.span(),
                format!(
                    "this {} is repeated by `count`, but its name `{s}` has no `{INDEX}`",
                    entry.what()
                ),
                "every copy would have this name",
            );
            d.help = Some(format!(
                "write the index into the name, e.g. `\"{s}{INDEX}\"`: `{INDEX}` becomes 1, 2, ... in every string of the entry"
            ));
            return Vec::new();
        }
        let Some(count) = count else {
            return Vec::new();
        };
        let per_copy = entry
            .per_copy()
            .and_then(|key| Some((key, get(t, key)?)))
            .filter(|(_, v)| v.get_ref().is_array());
        if let Some((key, v)) = per_copy
            && !self.per_copy_len(v, count, key)
        {
            return Vec::new();
        }
        spans_of(item, &mut self.templates);
        (1..=count)
            .map(|i| {
                let mut copy = substitute(&without(item, "count"), i);
                if let Some((key, v)) = per_copy
                    && let (DeValue::Table(t), DeValue::Array(a)) = (copy.get_mut(), v.get_ref())
                    && let Some(k) = t.keys().find(|k| k.get_ref().as_ref() == key).cloned()
                {
                    t.insert(k, substitute(&a[i - 1], i));
                }
                copy
            })
            .collect()
    }

    /// `[[leg]]`: its bodies and its loops, `count` copies of each, leg by leg.
    fn expand_leg<'a>(&mut self, leg: &Value<'a>) -> (Vec<Value<'a>>, Vec<Value<'a>>) {
        let Some(t) = self.table(leg, "a `[[leg]]` entry") else {
            return (Vec::new(), Vec::new());
        };
        let span = leg.span();
        self.check_keys(t, &span, LEG_KEYS, "`[[leg]]`");
        let count = match self.required(t, &span, "count", "`[[leg]]`") {
            Some(v) => self.count(v),
            None => None,
        };
        let mut parts: [Vec<Value<'a>>; 2] = [Vec::new(), Vec::new()];
        // The leg's own span covers its header; its entries are tables of their own.
        let mut template_spans = vec![span.clone()];
        for (slot, (key, entry)) in [("body", Entry::Body), ("loop", Entry::Loop)]
            .into_iter()
            .enumerate()
        {
            let Some(v) = get(t, key) else { continue };
            let Some(items) = self.array(v, &format!("`leg.{key}`")) else {
                continue;
            };
            for item in items {
                spans_of(item, &mut template_spans);
                parts[slot].extend(self.expand_entry(item, entry, true));
            }
        }
        if parts.iter().all(|p| p.is_empty())
            && get(t, "body").is_none()
            && get(t, "loop").is_none()
        {
            let d = self
                .cx
                .error(&span, "this `[[leg]]` has no bodies and no loops", "");
            d.help = Some(
                "write the leg's entries under it as `[[leg.body]]` and `[[leg.loop]]`".to_string(),
            );
        }
        let Some(count) = count else {
            return (Vec::new(), Vec::new());
        };
        self.templates.extend(template_spans);
        let [bodies, loops] = parts;
        let copies = |items: &[Value<'a>]| -> Vec<Value<'a>> {
            (1..=count)
                .flat_map(|i| items.iter().map(move |x| substitute(x, i)))
                .collect()
        };
        (copies(&bodies), copies(&loops))
    }

    /// `[parameters]` with repeated entries (a key containing `{i}`) expanded in place.
    fn expand_parameters<'a>(&mut self, v: &Value<'a>) -> Value<'a> {
        let DeValue::Table(t) = v.get_ref() else {
            return v.clone();
        };
        let mut out = DeTable::new();
        for (k, x) in t.iter() {
            let key = k.get_ref().as_ref();
            let table = x.get_ref().as_table();
            let count_v = table.and_then(|t| get(t, "count"));
            if !key.contains(INDEX) {
                if let Some(c) = count_v {
                    let d = self.cx.error(
                        &c.span(),
                        format!("parameter `{key}` has `count`, but its name has no `{INDEX}`"),
                        "every copy would have this name",
                    );
                    d.help = Some(format!(
                        "name it `\"{key}{INDEX}\"` (a quoted key) to define {key}1, {key}2, ..."
                    ));
                    continue;
                }
                if key != "coordinates" {
                    self.no_index(x);
                }
                out.insert(k.clone(), x.clone());
                continue;
            }
            let Some(table) = table else {
                let d = self.cx.error(
                    &x.span(),
                    format!("the repeated parameter `{key}` must be a table with `value`"),
                    "expected a table",
                );
                d.help = Some(format!(
                    "e.g. `\"{key}\" = {{ value = [1, 2, 3] }}` (one value per copy) or `{{ value = \"...{INDEX}...\", count = 3 }}`"
                ));
                continue;
            };
            let value = get(table, "value");
            let list = value.filter(|v| v.get_ref().is_array());
            let count = match (count_v, list) {
                (Some(c), _) => self.count(c),
                (None, Some(l)) => match l.get_ref() {
                    DeValue::Array(a) if !a.is_empty() => Some(a.len()),
                    _ => {
                        self.cx.error(
                            &l.span(),
                            format!("the repeated parameter `{key}` has no values"),
                            "expected one value per copy",
                        );
                        None
                    }
                },
                (None, None) => {
                    let d = self.cx.error(
                        &k.span(),
                        format!("the parameter `{key}` is repeated (its name has `{INDEX}`), but how often is not given"),
                        "neither `count` nor a list of values",
                    );
                    d.help = Some(
                        "add `count = N`, or give `value` as a list of one value per copy"
                            .to_string(),
                    );
                    None
                }
            };
            let Some(count) = count else { continue };
            if let Some(l) = list
                && !self.per_copy_len(l, count, "value")
            {
                continue;
            }
            self.templates.push(k.span());
            spans_of(x, &mut self.templates);
            for i in 1..=count {
                let name = Spanned::new(k.span(), Cow::Owned(key.replace(INDEX, &i.to_string())));
                let mut copy = substitute(&without(x, "count"), i);
                if let (Some(l), DeValue::Table(t)) = (list, copy.get_mut())
                    && let DeValue::Array(a) = l.get_ref()
                    && let Some(vk) = t.keys().find(|k| k.get_ref().as_ref() == "value").cloned()
                {
                    t.insert(vk, substitute(&a[i - 1], i));
                }
                out.insert(name, copy);
            }
        }
        Spanned::new(v.span(), DeValue::Table(out))
    }

    /// A `count`: an integer from 1 to MAX_COUNT.
    fn count(&mut self, v: &Value<'_>) -> Option<usize> {
        let n = match v.get_ref() {
            DeValue::Integer(i) => i64::from_str_radix(i.as_str(), i.radix()).ok(),
            other => {
                self.cx.error(
                    &v.span(),
                    format!("`count` must be an integer, found {}", type_name(other)),
                    "expected the number of copies",
                );
                return None;
            }
        };
        match n {
            Some(n) if (1..=MAX_COUNT).contains(&n) => Some(n as usize),
            _ => {
                self.cx.error(
                    &v.span(),
                    format!("`count` must be between 1 and {MAX_COUNT}"),
                    "the number of copies",
                );
                None
            }
        }
    }

    /// A per-copy list must have `count` entries.
    fn per_copy_len(&mut self, v: &Value<'_>, count: usize, key: &str) -> bool {
        let DeValue::Array(a) = v.get_ref() else {
            return true;
        };
        if a.len() == count {
            return true;
        }
        let d = self.cx.error(
            &v.span(),
            format!(
                "`{key}` lists {} value{}, but the entry is repeated {count} time{}",
                a.len(),
                if a.len() == 1 { "" } else { "s" },
                if count == 1 { "" } else { "s" }
            ),
            format!("expected {count} values, one per copy"),
        );
        d.help = Some(format!(
            "give one value per copy, or a single value (which may use `{INDEX}`) for all"
        ));
        false
    }

    /// Reports `{i}` in a string that is not inside a repeated entry.
    fn no_index(&mut self, v: &Value<'_>) {
        match v.get_ref() {
            DeValue::String(s) if s.contains(INDEX) => {
                let d = self.cx.error(
                    &v.span(),
                    format!("`{INDEX}` outside a repeated entry"),
                    "nothing repeats this entry",
                );
                d.help = Some(format!(
                    "`{INDEX}` is replaced only in an entry with `count = N` or inside `[[leg]]`"
                ));
            }
            DeValue::Array(a) => a.iter().for_each(|x| self.no_index(x)),
            // Documentation text may say `{i}` literally.
            DeValue::Table(t) => t
                .iter()
                .filter(|(k, _)| !matches!(k.get_ref().as_ref(), "doc" | "description"))
                .for_each(|(_, x)| self.no_index(x)),
            _ => {}
        }
    }
}

/// The spans of `v` and of every value and key inside it (an array of tables such as
/// `[[leg.body]]` has a span of its own header only, so the template is the union).
fn spans_of(v: &Value<'_>, out: &mut Vec<Span>) {
    out.push(v.span());
    match v.get_ref() {
        DeValue::Array(a) => a.iter().for_each(|x| spans_of(x, out)),
        DeValue::Table(t) => {
            for (k, x) in t.iter() {
                out.push(k.span());
                spans_of(x, out);
            }
        }
        _ => {}
    }
}

/// The table `v` without `key`.
fn without<'a>(v: &Value<'a>, key: &str) -> Value<'a> {
    match v.get_ref() {
        DeValue::Table(t) => {
            let mut out = DeTable::new();
            for (k, x) in t.iter() {
                if k.get_ref().as_ref() != key {
                    out.insert(k.clone(), x.clone());
                }
            }
            Spanned::new(v.span(), DeValue::Table(out))
        }
        _ => v.clone(),
    }
}

impl Parser<'_> {
    /// The errors, with those the copies of a repeated entry share (same place, same length:
    /// the same mistake in the template) kept once, for the first copy.
    pub(super) fn once_per_template(&mut self) -> Vec<Diagnostic> {
        let ranges: Vec<(Pos, Pos)> = self
            .templates
            .iter()
            .map(|s| (self.cx.pos(s.start), self.cx.pos(s.end)))
            .collect();
        let mut seen: Vec<(Pos, usize)> = Vec::new();
        let mut out = Vec::new();
        for d in std::mem::take(&mut self.cx.diags) {
            if ranges.iter().any(|(a, b)| *a <= d.pos && d.pos < *b) {
                if seen.contains(&(d.pos, d.len)) {
                    continue;
                }
                seen.push((d.pos, d.len));
            }
            out.push(d);
        }
        out
    }
}
