//! The code's shape is kept true (issue 27), the way `safety_doc.rs` keeps
//! SAFETY.md true: no function over [`MAX_LINES`] lines (counted from its
//! `fn` line to its closing brace) on the loop's, the recording's or the
//! command line's path unless [`ALLOWED`] names it with its reason (one
//! table, or one match of one idea), and at most [`MAX_LONG`] such
//! functions in all of `crates/*/src`. Test modules (`#[cfg(test)] mod`)
//! are not counted. Every function over the limit is printed with its
//! length (`cargo test -p sar-tests --test code_shape -- --nocapture`), and
//! an entry of [`ALLOWED`] that no longer names a function over the limit
//! fails the test: the list cannot go stale.

#![allow(clippy::unwrap_used, clippy::indexing_slicing)]

use std::path::{Path, PathBuf};

/// A function longer than this many lines is long.
const MAX_LINES: usize = 70;

/// At most this many long functions in all of `crates/*/src` (issue 27's
/// bound was 20; after it, two remained: the scene's drawing, which issue 28
/// rewrites, and the test support's table of generated messages).
const MAX_LONG: usize = 5;

/// The path's sources, where no function may be long unless [`ALLOWED`]
/// says why: a directory (ending in `/`) or a file, from the repository's
/// root. The loop's, the recording's and the command line's crates, and the
/// estimator's files run every cycle.
const ON_THE_PATH: &[&str] = &[
    "crates/loop/src/",
    "crates/record/src/",
    "crates/sarctl/src/",
    "crates/shm/src/",
    "crates/daemon/src/",
    "crates/estimator/src/cycle/",
    "crates/estimator/src/guard/",
    "crates/estimator/src/tip_force.rs",
    "crates/estimator/src/filter.rs",
    "crates/estimator/src/force_control.rs",
    "crates/estimator/src/lib.rs",
];

/// The long functions allowed on the path: (file from the repository's
/// root, function, why it is one piece: one table or one match of one
/// idea). An entry names every function of that name in the file.
const ALLOWED: &[(&str, &str, &str)] = &[];

/// One function: its file (from the root), name, first line (1-based) and
/// length in lines.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Function {
    file: String,
    name: String,
    line: usize,
    lines: usize,
}

/// The repository's root (the parent of this package's directory).
fn root() -> PathBuf {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/..")).to_path_buf()
}

/// Every `.rs` file under `dir`, sorted.
fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    for path in entries {
        if path.is_dir() {
            sources(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The source with every comment, string literal and character literal
/// blanked out (each of their characters but the line ends a space), so
/// that braces and `fn` are only counted in code. Handles nested block
/// comments, raw strings (`r#"..."#`), byte strings and escapes, and tells a
/// character literal (`'{'`, `'\''`) from a lifetime (`'a`).
fn code_only(text: &str) -> String {
    let chars: Vec<char> = text.chars().collect();
    let mut out = String::with_capacity(text.len());
    let blank = |c: char, out: &mut String| out.push(if c == '\n' { '\n' } else { ' ' });
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        let next = chars.get(i + 1).copied();
        let ident_before = i > 0 && (chars[i - 1].is_alphanumeric() || chars[i - 1] == '_');
        if c == '/' && next == Some('/') {
            while i < chars.len() && chars[i] != '\n' {
                blank(chars[i], &mut out);
                i += 1;
            }
        } else if c == '/' && next == Some('*') {
            let mut depth = 0;
            while i < chars.len() {
                if chars[i] == '/' && chars.get(i + 1) == Some(&'*') {
                    depth += 1;
                    out.push_str("  ");
                    i += 2;
                } else if chars[i] == '*' && chars.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    out.push_str("  ");
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    blank(chars[i], &mut out);
                    i += 1;
                }
            }
        } else if !ident_before && (c == 'r' || (c == 'b' && next == Some('r'))) && {
            // A raw string: r"..." or r#"..."# (or br...).
            let start = if c == 'b' { i + 2 } else { i + 1 };
            let hashes = chars[start..].iter().take_while(|&&h| h == '#').count();
            chars.get(start + hashes) == Some(&'"')
        } {
            let start = if c == 'b' { i + 2 } else { i + 1 };
            let hashes = chars[start..].iter().take_while(|&&h| h == '#').count();
            let body = start + hashes + 1;
            let mut j = body;
            loop {
                if j >= chars.len() {
                    break;
                }
                if chars[j] == '"' && chars[j + 1..].iter().take(hashes).all(|&h| h == '#') {
                    j += 1 + hashes;
                    break;
                }
                j += 1;
            }
            for &k in &chars[i..j.min(chars.len())] {
                blank(k, &mut out);
            }
            i = j;
        } else if c == '"' {
            blank(c, &mut out);
            i += 1;
            while i < chars.len() && chars[i] != '"' {
                let step = if chars[i] == '\\' { 2 } else { 1 };
                for &k in chars.iter().skip(i).take(step) {
                    blank(k, &mut out);
                }
                i += step;
            }
            if i < chars.len() {
                blank(chars[i], &mut out);
                i += 1;
            }
        } else if c == '\'' {
            // A character literal closes within a few characters ('x',
            // '\n', '\u{7f}'); a lifetime or a label does not.
            let end = if next == Some('\\') {
                chars[i + 2..]
                    .iter()
                    .position(|&k| k == '\'')
                    .map(|p| i + 2 + p)
            } else if chars.get(i + 2) == Some(&'\'') {
                Some(i + 2)
            } else {
                None
            };
            match end {
                Some(end) if end - i <= 12 => {
                    for &k in &chars[i..=end] {
                        blank(k, &mut out);
                    }
                    i = end + 1;
                }
                _ => {
                    out.push(c);
                    i += 1;
                }
            }
        } else {
            out.push(c);
            i += 1;
        }
    }
    out
}

/// The name of the function a line of code (comments and literals blanked)
/// starts, if it does: `fn name` after visibility and qualifiers only.
fn fn_name(line: &str) -> Option<&str> {
    let mut rest = line.trim_start();
    loop {
        if let Some(after) = rest.strip_prefix("pub(") {
            rest = after.split_once(')')?.1.trim_start();
        } else if let Some(word) = ["pub ", "const ", "async ", "unsafe ", "extern ", "default "]
            .iter()
            .find(|w| rest.starts_with(**w))
        {
            rest = rest[word.len()..].trim_start();
        } else {
            break;
        }
    }
    let after = rest.strip_prefix("fn ")?;
    let end = after
        .find(|c: char| !(c.is_alphanumeric() || c == '_'))
        .unwrap_or(after.len());
    (end > 0).then(|| &after[..end])
}

/// The line (index) that closes the block opening at or after line `start`,
/// or `None` if a `;` ends it first (a declaration without a body).
fn block_end(lines: &[&str], start: usize) -> Option<usize> {
    let mut depth = 0i64;
    let mut opened = false;
    for (i, line) in lines.iter().enumerate().skip(start) {
        for c in line.chars() {
            match c {
                '{' => {
                    depth += 1;
                    opened = true;
                }
                '}' => depth -= 1,
                _ => {}
            }
        }
        if opened && depth <= 0 {
            return Some(i);
        }
        if !opened && line.trim_end().ends_with(';') {
            return None;
        }
    }
    None
}

/// Every function of one file's code outside `#[cfg(test)]` modules.
fn functions(file: &str, text: &str) -> Vec<Function> {
    let code = code_only(text);
    let lines: Vec<&str> = code.lines().collect();
    let mut found = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let line = lines[i];
        let test_mod = line.trim() == "#[cfg(test)]"
            && lines.get(i + 1).is_some_and(|next| {
                let next = next.trim_start();
                let next = next.strip_prefix("pub ").unwrap_or(next);
                next.starts_with("mod ") && next.contains('{')
            });
        if test_mod {
            i = block_end(&lines, i + 1).map_or(lines.len(), |end| end + 1);
            continue;
        }
        if let Some(name) = fn_name(line)
            && let Some(end) = block_end(&lines, i)
        {
            found.push(Function {
                file: file.to_owned(),
                name: name.to_owned(),
                line: i + 1,
                lines: end - i + 1,
            });
        }
        i += 1;
    }
    found
}

/// Every function over [`MAX_LINES`] in `crates/*/src`, longest first.
fn long_functions() -> Vec<Function> {
    let root = root();
    let mut crates: Vec<PathBuf> = std::fs::read_dir(root.join("crates"))
        .unwrap()
        .map(|e| e.unwrap().path().join("src"))
        .filter(|src| src.is_dir())
        .collect();
    crates.sort();
    let mut files = Vec::new();
    for src in &crates {
        sources(src, &mut files);
    }
    let mut long: Vec<Function> = files
        .iter()
        .flat_map(|path| {
            let file = path
                .strip_prefix(&root)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            functions(&file, &std::fs::read_to_string(path).unwrap())
        })
        .filter(|f| f.lines > MAX_LINES)
        .collect();
    long.sort_by(|a, b| b.lines.cmp(&a.lines).then(a.file.cmp(&b.file)));
    long
}

fn on_the_path(file: &str) -> bool {
    ON_THE_PATH.iter().any(|p| {
        if p.ends_with('/') {
            file.starts_with(p)
        } else {
            file == *p
        }
    })
}

#[test]
fn no_long_function_on_the_path_and_few_elsewhere() {
    let long = long_functions();
    println!("functions over {MAX_LINES} lines in crates/*/src:");
    for f in &long {
        let path = if on_the_path(&f.file) {
            " (on the path)"
        } else {
            ""
        };
        println!("{:5} {}:{} {}{path}", f.lines, f.file, f.line, f.name);
    }
    println!("{} functions over {MAX_LINES} lines", long.len());

    let mut problems = Vec::new();
    for f in long.iter().filter(|f| on_the_path(&f.file)) {
        if !ALLOWED
            .iter()
            .any(|(file, name, _)| *file == f.file && *name == f.name)
        {
            problems.push(format!(
                "{}:{} {} is {} lines, on the path, and not in ALLOWED (cut it along its ideas)",
                f.file, f.line, f.name, f.lines
            ));
        }
    }
    for (file, name, why) in ALLOWED {
        assert!(!why.trim().is_empty(), "ALLOWED {file} {name}: say why");
        if !long.iter().any(|f| f.file == *file && f.name == *name) {
            problems.push(format!(
                "ALLOWED names {file} {name}, which is no longer a function over {MAX_LINES} \
                 lines: remove the entry"
            ));
        }
    }
    if long.len() > MAX_LONG {
        problems.push(format!(
            "{} functions over {MAX_LINES} lines, at most {MAX_LONG} allowed",
            long.len()
        ));
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

/// The counting itself: braces and `fn` in comments, strings, raw strings
/// and character literals do not count; lifetimes are not literals; a test
/// module is skipped; a declaration without a body is not a function.
#[test]
fn a_function_is_counted_from_its_fn_line_to_its_closing_brace() {
    let text = r####"
trait T {
    fn declared(&self) -> [u8; 3];
}
pub(crate) fn outer<'a>(s: &'a str) -> char {
    // fn not_a_function() {
    let _ = "} { fn in_a_string() {";
    let _ = r#"}"# ;
    /* { /* nested { */ } */
    let _ = '{';
    let _ = '\'';
    let _: &'a str = s;
    '}'
}
#[cfg(test)]
mod tests {
    fn hidden() {
        let _ = 1;
    }
}
const fn after() {}
"####;
    let found = functions("f.rs", text);
    let summary: Vec<(&str, usize, usize)> = found
        .iter()
        .map(|f| (f.name.as_str(), f.line, f.lines))
        .collect();
    assert_eq!(summary, vec![("outer", 5, 10), ("after", 21, 1)]);
}
