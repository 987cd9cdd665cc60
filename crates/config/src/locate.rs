//! Where a key is in a TOML file: maps toml's byte spans to dotted keys
//! (`motion[3].hold_s`, `guard.warn_total_n`) and dotted keys to line numbers,
//! so that every error of the scenario loader and of the daemon's
//! configuration names the key and, where the file has it, the line.

use std::ops::Range;
use toml::Spanned;
use toml::de::{DeTable, DeValue};

/// One key or array element of the document.
#[derive(Debug, Clone)]
struct Node {
    /// Dotted key, e.g. `motion[3].hold_s`.
    key: String,
    /// Span of the key itself (of the value for an array element).
    key_span: Range<usize>,
    /// Span of the value.
    value_span: Range<usize>,
    /// A float that is NaN or infinite.
    non_finite: bool,
}

/// Every key and array element of a parsed document, with its spans.
#[derive(Debug, Clone)]
pub struct Locator<'a> {
    text: &'a str,
    nodes: Vec<Node>,
}

fn contains(outer: &Range<usize>, inner: &Range<usize>) -> bool {
    outer.start <= inner.start && inner.end <= outer.end
}

/// The dotted key of `key` inside `parent` ("" for the top level).
pub fn join(parent: &str, key: &str) -> String {
    if parent.is_empty() {
        key.to_owned()
    } else {
        format!("{parent}.{key}")
    }
}

fn is_non_finite(value: &DeValue<'_>) -> bool {
    match value {
        DeValue::Float(f) => {
            let s = f.as_str().trim_start_matches(['+', '-']);
            s == "nan" || s == "inf"
        }
        _ => false,
    }
}

impl<'a> Locator<'a> {
    /// Indexes a parsed document.
    pub fn new(text: &'a str, root: &Spanned<DeTable<'a>>) -> Self {
        let mut nodes = Vec::new();
        collect_table(root.get_ref(), "", &mut nodes);
        Self { text, nodes }
    }

    /// The dotted key of the innermost key or value at `span` ("" for the whole
    /// document, and for an empty span). A span that is exactly a key's or a value's wins; otherwise
    /// the smallest value that contains it.
    pub fn key_at(&self, span: &Range<usize>) -> String {
        // toml gives the document itself (a missing top-level key) an empty span.
        if span.is_empty() {
            return String::new();
        }
        let exact = self
            .nodes
            .iter()
            .filter(|n| n.key_span == *span || n.value_span == *span)
            .max_by_key(|n| n.key.len());
        if let Some(n) = exact {
            return n.key.clone();
        }
        self.nodes
            .iter()
            .filter(|n| contains(&n.value_span, span) || contains(&n.key_span, span))
            .min_by_key(|n| n.value_span.len())
            .map(|n| n.key.clone())
            .unwrap_or_default()
    }

    /// The 1-based line where `key` is written, when the file writes it.
    pub fn line_of_key(&self, key: &str) -> Option<usize> {
        self.nodes
            .iter()
            .find(|n| n.key == key)
            .map(|n| self.line_at(n.key_span.start))
    }

    /// The 1-based line of byte `offset`.
    pub fn line_at(&self, offset: usize) -> usize {
        let end = offset.min(self.text.len());
        1 + self.text.bytes().take(end).filter(|&b| b == b'\n').count()
    }

    /// The line of `key`, or where the file does not write it (a missing or
    /// defaulted key, a generated one), of its nearest enclosing key.
    pub fn line_near(&self, key: &str) -> Option<usize> {
        let mut probe = key;
        while !probe.is_empty() {
            if let Some(line) = self.line_of_key(probe) {
                return Some(line);
            }
            probe = match probe.rfind(['.', '[']) {
                Some(i) => probe.get(..i).unwrap_or(""),
                None => "",
            };
        }
        None
    }

    /// A serde error of the file as (dotted key, line, problem): "missing
    /// key" names the missing key, "unknown key" keeps serde's list of the
    /// expected ones.
    pub fn serde_problem(&self, e: &toml::de::Error) -> (String, Option<usize>, String) {
        let message = e.message().trim_end();
        let mut key = e.span().map(|span| self.key_at(&span)).unwrap_or_default();
        let line = if key.is_empty() {
            None
        } else {
            e.span().map(|span| self.line_at(span.start))
        };
        let problem = if let Some(field) = message
            .strip_prefix("missing field `")
            .and_then(|rest| rest.split('`').next())
        {
            key = join(&key, field);
            "missing key".to_owned()
        } else if let Some(rest) = message.strip_prefix("unknown field") {
            format!("unknown key{rest}")
        } else {
            message.to_owned()
        };
        (key, line, problem)
    }

    /// The first (in file order) float that is NaN or infinite: its key and line.
    pub fn first_non_finite(&self) -> Option<(String, usize)> {
        self.nodes
            .iter()
            .filter(|n| n.non_finite)
            .min_by_key(|n| n.value_span.start)
            .map(|n| (n.key.clone(), self.line_at(n.value_span.start)))
    }
}

fn collect_table(table: &DeTable<'_>, parent: &str, nodes: &mut Vec<Node>) {
    for (k, v) in table.iter() {
        let key = join(parent, k.get_ref());
        nodes.push(Node {
            key: key.clone(),
            key_span: k.span(),
            value_span: v.span(),
            non_finite: is_non_finite(v.get_ref()),
        });
        collect_value(v.get_ref(), &key, nodes);
    }
}

fn collect_value(value: &DeValue<'_>, key: &str, nodes: &mut Vec<Node>) {
    match value {
        DeValue::Table(t) => collect_table(t, key, nodes),
        DeValue::Array(a) => {
            for (i, e) in a.iter().enumerate() {
                let key = format!("{key}[{i}]");
                nodes.push(Node {
                    key: key.clone(),
                    key_span: e.span(),
                    value_span: e.span(),
                    non_finite: is_non_finite(e.get_ref()),
                });
                collect_value(e.get_ref(), &key, nodes);
            }
        }
        _ => {}
    }
}
