//! What the configuration's documentation says, made from the keys'
//! declaration (`crate::keys`): the README's table of every key
//! ([`readme_table`]) and the built-in configuration, `default_config.toml`
//! ([`default_toml`]: the example robot's required keys, every other key at
//! its default or, when it may be absent, as a commented-out example, each
//! with its doc; the DEMO keys at the demo's values). The tests compare both
//! with the files (`crates/config/tests/keys.rs`);
//! `cargo run -p sar-config --example config_docs -- --write` writes them.

use crate::decl::{Applies, Bounds, KeyDecl, KeyDefault, or_list};
use crate::keys::{SECTIONS, guard, plausibility};

/// The line before the README's table.
pub const README_BEGIN: &str = "<!-- The keys: made from crates/config/src/keys by `cargo run -p sar-config --example config_docs -- --write`; crates/config/tests/keys.rs compares. -->";

/// The line after the README's table.
pub const README_END: &str = "<!-- The end of the keys. -->";

/// The keys the demo sets otherwise (`sard --sim` on a desktop without
/// real-time scheduling, where the loop can stall for several
/// milliseconds), with the demo's value.
const DEMO: [(KeyDecl, &str); 3] = [
    (guard::KEY.max_sensor_age_s, "0.05"),
    (guard::KEY.max_joints_age_s, "0.05"),
    (plausibility::KEY.max_counter_gap, "25"),
];

/// The head of `default_config.toml`.
const HEAD: &str = "\
# The built-in configuration of `sard --sim`: the example robot of
# INTERFACES.md 2 (the scenarios' true geometry), with every other key at its
# default (commented out where the key may be absent), except those marked
# DEMO: the demo must run on a desktop without real-time scheduling, where
# the loop can stall for several milliseconds (a robot's configuration keeps
# the defaults). Made from the keys' declaration (crates/config/src/keys) by
# `cargo run -p sar-config --example config_docs -- --write`.
";

/// The column of a key line's comment.
const COMMENT_COLUMN: usize = 39;

/// A number as the docs show a bound (`0.0001`, `100000`).
fn bound(v: f64) -> String {
    format!("{v}")
}

/// " unit", or "" without one.
fn spaced(unit: &str) -> String {
    if unit.is_empty() {
        String::new()
    } else {
        format!(" {unit}")
    }
}

/// What a range bounds, as the README's table says it.
fn applies_text(applies: Applies) -> &'static str {
    match applies {
        Applies::Value => "",
        Applies::EachComponent => "each: ",
        Applies::Magnitude => "magnitude: ",
    }
}

/// A key's range as the README's table shows it.
pub fn range_text(d: &KeyDecl) -> String {
    match d.range.bounds {
        Bounds::Number {
            lo,
            hi,
            unit,
            applies,
        } => format!(
            "{}{}..={}{}",
            applies_text(applies),
            bound(lo),
            bound(hi),
            spaced(unit)
        ),
        Bounds::Integer {
            lo,
            hi,
            unit,
            applies,
        } => format!("{}{lo}..={hi}{}", applies_text(applies), spaced(unit)),
        Bounds::Choice(words) => or_list(words),
        Bounds::Text(what) => what.to_owned(),
        Bounds::Switch => "true or false".to_owned(),
    }
}

/// A key's default as the README's table shows it.
pub fn default_text(d: &KeyDecl) -> String {
    match d.default {
        KeyDefault::Value(value) => format!("`{}`", value()),
        KeyDefault::Required(_) => "required".to_owned(),
        KeyDefault::Absent(meaning, _) => format!("absent: {meaning}"),
    }
}

/// Text in a cell of a Markdown table.
fn cell(text: &str) -> String {
    text.replace('|', "\\|")
}

/// The README's table of every key, in the file's order.
pub fn readme_table() -> String {
    let mut out =
        String::from("| key | default | range | also | what it is |\n|---|---|---|---|---|\n");
    for d in crate::keys::keys() {
        out.push_str(&format!(
            "| `{}` | {} | {} | {} | {} |\n",
            d.key,
            cell(&default_text(d)),
            cell(&range_text(d)),
            cell(d.range.also),
            cell(d.doc.trim())
        ));
    }
    out
}

/// `line`, then its comment at [`COMMENT_COLUMN`] (or one space after a
/// longer line).
fn with_comment(line: &str, comment: &str) -> String {
    let pad = COMMENT_COLUMN.saturating_sub(line.chars().count()).max(1);
    format!("{line}{}# {comment}", " ".repeat(pad))
}

/// `name = value # comment`, a nested array one row per line.
fn key_lines(prefix: &str, name: &str, value: &str, comment: &str) -> Vec<String> {
    let head = format!("{prefix}{name} = ");
    let rows: Vec<&str> = match value.strip_prefix("[[") {
        Some(_) => value.split_inclusive("], ").collect(),
        None => vec![value],
    };
    let indent = " ".repeat(head.chars().count() + 1);
    rows.iter()
        .enumerate()
        .map(|(i, row)| {
            let row = row.trim_end();
            if i == 0 {
                with_comment(&format!("{head}{row}"), comment)
            } else {
                format!("{indent}{row}")
            }
        })
        .collect()
}

/// The lines of one key in `default_config.toml`.
fn lines_of(d: &KeyDecl) -> Vec<String> {
    let doc = d.doc.trim();
    match d.default {
        KeyDefault::Value(value) => match DEMO.iter().find(|(k, _)| k.key == d.key) {
            Some((_, demo)) => {
                let comment = format!("DEMO (default {})", value());
                key_lines("", d.name, demo, &comment)
            }
            None => key_lines("", d.name, &value(), doc),
        },
        KeyDefault::Required(example) => key_lines("", d.name, &example(), doc),
        KeyDefault::Absent(meaning, example) => {
            let comment = format!("{doc} (absent: {meaning})");
            key_lines("# ", d.name, &example(), &comment)
        }
    }
}

/// The built-in configuration, `default_config.toml`.
pub fn default_toml() -> String {
    let mut out = String::from(HEAD);
    for section in SECTIONS {
        out.push_str(&format!("\n# {}\n[{}]\n", section.doc.trim(), section.name));
        for d in section.keys {
            for line in lines_of(d) {
                out.push_str(&line);
                out.push('\n');
            }
        }
    }
    out
}
