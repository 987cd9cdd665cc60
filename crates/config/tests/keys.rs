//! Each configuration key is declared once (issue 36): its section's table
//! in `crates/config/src/keys` gives its type, default, range, one-line doc
//! and target, and everything else follows from it or is checked against
//! it here: the README's table and `default_config.toml` are the ones the
//! declaration makes, every key has a doc, a default and a range that fits
//! its type and its default, every declared range is checked at load, and no
//! code outside the declaration names a key by a string of its own.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use sar_config::{self as config, Applies, Bounds, KeyDecl, KeyDefault, Kind, docs};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

const FIX: &str = "run `cargo run -p sar-config --example config_docs -- --write`";

/// The README's table of the keys is the one the declaration makes.
#[test]
fn the_readme_lists_every_key_as_declared() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let (_, rest) = readme
        .split_once(docs::README_BEGIN)
        .expect("the README's marker before the keys");
    let (table, _) = rest
        .split_once(docs::README_END)
        .expect("the README's marker after the keys");
    let want = docs::readme_table();
    let got = table.trim_start_matches('\n');
    if got != want {
        let first = got
            .lines()
            .zip(want.lines())
            .find(|(g, w)| g != w)
            .map(|(g, w)| format!("README: {g}\ndeclared: {w}"))
            .unwrap_or_else(|| "the tables differ in length".to_owned());
        panic!("the README's table of the keys is not the declaration's ({FIX}):\n{first}");
    }
}

/// `default_config.toml` is the one the declaration makes: every key, its
/// doc as its comment, its default (or the example robot's value, or a
/// commented-out example), the DEMO keys marked.
#[test]
fn the_builtin_configuration_is_the_declaration() {
    let want = docs::default_toml();
    if config::DEFAULT_TOML != want {
        let first = config::DEFAULT_TOML
            .lines()
            .zip(want.lines())
            .find(|(g, w)| g != w)
            .map(|(g, w)| format!("file: {g}\ndeclared: {w}"))
            .unwrap_or_else(|| "the files differ in length".to_owned());
        panic!("default_config.toml is not the declaration's ({FIX}):\n{first}");
    }
}

/// The numbers of a TOML value (an array's, each).
fn numbers(v: &toml::Value) -> Vec<f64> {
    match v {
        toml::Value::Float(x) => vec![*x],
        toml::Value::Integer(i) => vec![*i as f64],
        toml::Value::Array(a) => a.iter().flat_map(numbers).collect(),
        _ => Vec::new(),
    }
}

/// `rendered` (a declaration's default or example, as TOML) within `d`'s
/// range, else why not.
fn within_range(d: &KeyDecl, rendered: &str) -> Result<(), String> {
    let table: toml::Table = toml::from_str(&format!("v = {rendered}"))
        .map_err(|e| format!("{rendered:?} is not TOML: {e}"))?;
    let v = &table["v"];
    let (lo, hi, applies) = match d.range.bounds {
        Bounds::Number {
            lo, hi, applies, ..
        } => (lo, hi, applies),
        Bounds::Integer {
            lo, hi, applies, ..
        } => (lo as f64, hi as f64, applies),
        Bounds::Choice(words) => {
            return match v.as_str() {
                Some(w) if words.contains(&w) => Ok(()),
                _ => Err(format!("{rendered} is not one of {words:?}")),
            };
        }
        _ => return Ok(()),
    };
    let xs = numbers(v);
    let xs = match applies {
        Applies::Magnitude => vec![xs.iter().map(|x| x * x).sum::<f64>().sqrt()],
        _ => xs,
    };
    match xs.iter().find(|x| !(lo..=hi).contains(*x)) {
        Some(x) => Err(format!("{x} (of {rendered}) is outside {lo}..={hi}")),
        None => Ok(()),
    }
}

/// Every key has a one-line doc, a default (a value, required with an
/// example, or absent with its meaning and an example) within its range,
/// and a range that fits its type; every section a doc.
#[test]
fn every_key_has_a_doc_a_default_and_a_range_that_fit() {
    let mut problems = Vec::new();
    for d in config::keys() {
        let doc = d.doc.trim();
        if doc.is_empty() || doc.contains('\n') || doc.chars().count() > 120 {
            problems.push(format!(
                "{}: a doc of one line (at most 120 characters)",
                d.key
            ));
        }
        let fits = match (d.kind, d.range.bounds) {
            (Kind::Number, Bounds::Number { lo, hi, .. }) => {
                lo < hi && lo.is_finite() && hi.is_finite()
            }
            (Kind::Integer, Bounds::Integer { lo, hi, .. }) => lo < hi,
            (Kind::Switch, Bounds::Switch) => true,
            (Kind::Text, Bounds::Choice(words)) => !words.is_empty(),
            (Kind::Text, Bounds::Text(what)) => !what.trim().is_empty(),
            _ => false,
        };
        if !fits {
            problems.push(format!(
                "{}: a range that fits its type ({:?}), got {:?}",
                d.key, d.kind, d.range.bounds
            ));
        }
        let (what, rendered) = match d.default {
            KeyDefault::Value(v) => ("its default", v()),
            KeyDefault::Required(example) => ("its example", example()),
            KeyDefault::Absent(meaning, example) => {
                if meaning.trim().is_empty() {
                    problems.push(format!("{}: what its absence means", d.key));
                }
                ("its example", example())
            }
            _ => ("?", String::new()),
        };
        if let Err(why) = within_range(d, &rendered) {
            problems.push(format!("{}: {what} within its range: {why}", d.key));
        }
    }
    for section in config::SECTIONS {
        assert!(!section.keys.is_empty(), "[{}]: no keys", section.name);
        let doc = section.doc.trim();
        assert!(
            !doc.is_empty() && !doc.contains('\n'),
            "[{}]: a doc of one line",
            section.name
        );
        assert!(
            section.keys.iter().all(|d| d.section == section.name),
            "[{}]: a key of another section",
            section.name
        );
    }
    let mut names: Vec<&str> = config::keys().map(|d| d.key).collect();
    let all = names.len();
    names.sort_unstable();
    names.dedup();
    assert_eq!(names.len(), all, "a key declared twice");
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

/// The line of `d` in `text` (the built-in configuration), in `d`'s
/// section, replaced by `name = value` (a nested array's other rows
/// dropped).
fn with_value(text: &str, d: &KeyDecl, value: &str) -> String {
    let mut out = Vec::new();
    let mut section = String::new();
    let mut replacing = false;
    for line in text.lines() {
        if let Some(s) = line.strip_prefix('[') {
            section = s.trim_end_matches(']').to_owned();
        }
        let is_key = line.starts_with(&format!("{} = ", d.name))
            || line.starts_with(&format!("# {} = ", d.name));
        if section == d.section && is_key {
            out.push(format!("{} = {value}", d.name));
            replacing = true;
            continue;
        }
        if replacing && line.starts_with(' ') {
            continue;
        }
        replacing = false;
        out.push(line.to_owned());
    }
    out.join("\n")
}

/// A value of `d`'s type outside its range (None: a range of text, checked
/// where the section is read).
fn outside(d: &KeyDecl) -> Option<String> {
    let rendered = match d.default {
        KeyDefault::Value(v) => v(),
        KeyDefault::Required(example) | KeyDefault::Absent(_, example) => example(),
        _ => return None,
    };
    let array = rendered.starts_with('[');
    let one = match d.range.bounds {
        Bounds::Number { hi, applies, .. } => {
            let bad = format!("{:?}", 2.0 * hi.abs() + 1.0);
            if applies == Applies::Magnitude {
                return Some(format!("[0.0, {bad}, 0.0]"));
            }
            bad
        }
        Bounds::Integer { hi, .. } => format!("{}", hi + 1),
        Bounds::Choice(_) => "\"no-such-word\"".to_owned(),
        _ => return None,
    };
    if !array {
        return Some(one);
    }
    // Every number of the array replaced by `one`.
    let mut out = String::new();
    let mut number = false;
    for c in rendered.chars() {
        let part_of_number = c.is_ascii_digit() || matches!(c, '.' | '-' | 'e');
        if part_of_number {
            if !number {
                out.push_str(&one);
            }
            number = true;
        } else {
            number = false;
            out.push(c);
        }
    }
    Some(out)
}

/// Every declared range is checked at load: a value outside it is refused
/// under the key (its first component for an array) by the range itself,
/// whatever the other keys say (the built-in configuration with that one
/// value changed).
#[test]
fn every_declared_range_is_checked() {
    let mut checked = 0;
    for d in config::keys() {
        let Some(value) = outside(d) else { continue };
        let text = with_value(config::DEFAULT_TOML, d, &value);
        assert_ne!(
            text,
            config::DEFAULT_TOML,
            "{}: not found in the file",
            d.key
        );
        let e = match config::parse(&text, "robot.toml") {
            Ok(_) => panic!("{} = {value}: accepted", d.key),
            Err(e) => e,
        };
        let key = e.key().unwrap_or("");
        assert!(
            key == d.key || key.starts_with(&format!("{}[", d.key)),
            "{} = {value}: refused under another key: {e}",
            d.key
        );
        // Refused by the range itself, not by a relation or a domain check
        // that happens to catch this value too.
        let words = match d.range.bounds {
            Bounds::Choice(_) => "must be \"",
            _ => "must be within",
        };
        assert!(
            e.to_string().contains(words),
            "{} = {value}: not refused by its range: {e}",
            d.key
        );
        checked += 1;
    }
    assert!(checked > 100, "{checked} keys checked");
}

/// The string literals of Rust source `text` (outside comments), with
/// the 1-based line each starts on.
fn string_literals(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let code = line.trim_start();
        if code.starts_with("//") {
            continue;
        }
        let mut chars = line.chars().peekable();
        let mut current: Option<String> = None;
        let mut prev = ' ';
        while let Some(c) = chars.next() {
            match (&mut current, c) {
                (None, '"') if prev != '\'' => current = Some(String::new()),
                (None, '/') if chars.peek() == Some(&'/') => break,
                (Some(s), '\\') => {
                    s.push(c);
                    if let Some(next) = chars.next() {
                        s.push(next);
                    }
                }
                (Some(s), '"') => {
                    out.push((n + 1, std::mem::take(s)));
                    current = None;
                }
                (Some(s), _) => s.push(c),
                (None, _) => {}
            }
            prev = c;
        }
    }
    out
}

/// `text` without its `crate::section! { ... }` block (the declaration,
/// whose docs and "also" notes name keys).
fn without_declaration(text: &str) -> String {
    let Some(start) = text.find("crate::section! {") else {
        return text.to_owned();
    };
    let end = text[start..]
        .find("\n}\n")
        .map_or(text.len(), |i| start + i + 3);
    format!("{}{}", &text[..start], &text[end..])
}

/// Whether `literal` names `key` (not as a part of a longer key).
fn names(literal: &str, key: &str) -> bool {
    literal.match_indices(key).any(|(i, _)| {
        let before = literal[..i].chars().next_back();
        let after = literal[i + key.len()..].chars().next();
        let word = |c: Option<char>| c.is_some_and(|c| c.is_ascii_alphanumeric() || c == '_');
        !word(before) && before != Some('.') && !word(after)
    })
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// No code of the configuration outside the declaration names a key by a
/// string of its own: errors and messages take `KEY.name.key` (a typo does
/// not compile). The scenario files (`scenario.rs`, `scenario/`) are another
/// format with keys of their own.
#[test]
fn each_key_is_written_once() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut found = Vec::new();
    for file in files {
        let rel = file
            .strip_prefix(&src)
            .unwrap()
            .to_string_lossy()
            .to_string();
        if rel == "scenario.rs" || rel.starts_with("scenario/") {
            continue;
        }
        let text = without_declaration(&std::fs::read_to_string(&file).unwrap());
        for (line, literal) in string_literals(&text) {
            for d in config::keys() {
                if names(&literal, d.key) {
                    found.push(format!("{rel}:{line}: {:?} names {}", literal, d.key));
                }
            }
        }
    }
    assert!(found.is_empty(), "{}", found.join("\n"));
}

/// The guard's six force limits are declared under the names the wire,
/// `sarctl` and the log give them (`ForceLimits::NAMES`), in their order.
#[test]
fn the_guard_keys_are_the_force_limits_names() {
    let guard: Vec<&str> = config::keys()
        .filter(|d| d.section == "guard")
        .map(|d| d.name)
        .take(6)
        .collect();
    assert_eq!(guard, sar_estimator::guard::ForceLimits::NAMES);
}
