//! The layering of ARCHITECTURE.md is checked, not promised (issue 18): its
//! table says, for every crate of the workspace, which of the workspace's
//! crates it may depend on and which external crates it must never link.
//! Every `Cargo.toml` is read: each workspace crate has a row; its
//! dependency sections (of every kind and target) name only the workspace crates
//! its row allows; nothing it links, itself or through the workspace crates
//! below it, is one its row forbids.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// One row of the table.
#[derive(Debug)]
struct Rule {
    /// Workspace crates it may depend on.
    may: BTreeSet<String>,
    /// Of those, the ones only its tests and benches may use ("(tests
    /// only)" in the table): allowed in dev-dependencies alone.
    tests_only: BTreeSet<String>,
    must_not: BTreeSet<String>,
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn names(cell: &str) -> BTreeSet<String> {
    cell.split(',')
        .filter_map(|n| n.split_whitespace().next())
        .map(str::to_owned)
        .collect()
}

/// The names of a cell marked "(tests only)".
fn tests_only(cell: &str) -> BTreeSet<String> {
    cell.split(',')
        .filter(|n| n.contains("(tests only)"))
        .filter_map(|n| n.split_whitespace().next())
        .map(str::to_owned)
        .collect()
}

/// The table's rows, by crate name.
fn rules(architecture: &str) -> BTreeMap<String, Rule> {
    let mut rules = BTreeMap::new();
    for line in architecture.lines() {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        // "| name | may | must not |" splits into 5 cells, empty at the ends.
        if cells.len() != 5 || !(cells[1].starts_with("sar-") || cells[1] == "sarctl") {
            continue;
        }
        let rule = Rule {
            may: names(cells[2]),
            tests_only: tests_only(cells[2]),
            must_not: names(cells[3]),
        };
        assert!(
            rules.insert(cells[1].to_owned(), rule).is_none(),
            "{} has two rows",
            cells[1]
        );
    }
    rules
}

/// A manifest's package name and its dependencies: what it links (every
/// `dependencies` and `build-dependencies` section, `[target.'cfg(..)'.*]`
/// ones included, and the `[dependencies.NAME]` form) and what only its
/// tests and benches link (`dev-dependencies`).
#[derive(Debug)]
struct Manifest {
    name: String,
    dependencies: BTreeSet<String>,
    dev_dependencies: BTreeSet<String>,
    /// Dependencies marked `optional = true`: linked only with the feature
    /// that names them (what a build really links is CI's `cargo tree`
    /// check).
    optional: BTreeSet<String>,
}

/// The kind of a section's dependencies, and the name of a
/// `[dependencies.NAME]` section (`None`: not a dependency section).
fn dependency_section(section: &str) -> Option<(bool, Option<String>)> {
    // `target.'cfg(unix)'.dependencies` is read as `dependencies`.
    let rest = match section.strip_prefix("target.") {
        Some(t) => t
            .rsplit_once("'.")
            .or_else(|| t.split_once('.'))
            .map(|(_, r)| r)?,
        None => section,
    };
    let (kind, name) = match rest.split_once('.') {
        Some((kind, name)) => (kind, Some(name.trim_matches('"').to_owned())),
        None => (rest, None),
    };
    match kind {
        "dependencies" | "build-dependencies" => Some((false, name)),
        "dev-dependencies" => Some((true, name)),
        _ => None,
    }
}

fn manifest(text: &str) -> Manifest {
    let mut section = String::new();
    let mut m = Manifest {
        name: String::new(),
        dependencies: BTreeSet::new(),
        dev_dependencies: BTreeSet::new(),
        optional: BTreeSet::new(),
    };
    for line in text.lines().map(str::trim) {
        if line.starts_with('[') {
            section = line.trim_matches(['[', ']']).to_owned();
            if let Some((dev, Some(name))) = dependency_section(&section) {
                if dev {
                    &mut m.dev_dependencies
                } else {
                    &mut m.dependencies
                }
                .insert(name);
            }
            continue;
        }
        let Some((key, value)) = line.split_once('=') else {
            continue;
        };
        let key = key.trim();
        if section == "package" && key == "name" {
            m.name = value.trim().trim_matches('"').to_owned();
            continue;
        }
        // `name.workspace = true` and `name = ...` alike.
        let dep = key.split('.').next().unwrap_or(key).to_owned();
        let compact = value.replace(' ', "");
        match dependency_section(&section) {
            Some((dev, None)) => {
                if !dev && compact.contains("optional=true") {
                    m.optional.insert(dep.clone());
                }
                if dev {
                    &mut m.dev_dependencies
                } else {
                    &mut m.dependencies
                }
                .insert(dep);
            }
            Some((false, Some(name))) if key == "optional" && compact == "true" => {
                m.optional.insert(name);
            }
            _ => {}
        }
    }
    m
}

/// Every workspace member's manifest (and the no_std proof's, which is not a
/// member but is a crate of the repository).
fn manifests() -> Vec<(PathBuf, Manifest)> {
    let mut paths: Vec<PathBuf> = std::fs::read_dir(root().join("crates"))
        .unwrap()
        .map(|e| e.unwrap().path().join("Cargo.toml"))
        .filter(|p| p.exists())
        .collect();
    paths.push(root().join("tests/Cargo.toml"));
    paths.sort();
    paths
        .into_iter()
        .map(|p| {
            let m = manifest(&std::fs::read_to_string(&p).unwrap());
            (p, m)
        })
        .collect()
}

/// Every crate `name` links, directly or through the workspace crates it
/// depends on, each with the workspace crate it comes through (`None`:
/// named by `name` itself). Dev-dependencies are not linked into the crate.
fn linked(name: &str, by_name: &BTreeMap<&str, &Manifest>) -> BTreeMap<String, Option<String>> {
    let mut out = BTreeMap::new();
    let mut todo = vec![name.to_owned()];
    let mut seen = BTreeSet::new();
    while let Some(krate) = todo.pop() {
        if !seen.insert(krate.clone()) {
            continue;
        }
        let Some(m) = by_name.get(krate.as_str()) else {
            continue;
        };
        for dep in m.dependencies.difference(&m.optional) {
            // Said as the workspace crate that names it.
            out.entry(dep.clone())
                .or_insert_with(|| (krate != name).then(|| krate.clone()));
            if by_name.contains_key(dep.as_str()) {
                todo.push(dep.clone());
            }
        }
    }
    out
}

/// What is wrong with the manifests against the table (empty: nothing).
fn violations(rules: &BTreeMap<String, Rule>, manifests: &[(PathBuf, Manifest)]) -> Vec<String> {
    let by_name: BTreeMap<&str, &Manifest> = manifests
        .iter()
        .map(|(_, m)| (m.name.as_str(), m))
        .collect();
    let mut wrong = Vec::new();
    for (path, m) in manifests {
        // The no_std proof is checked by its own build (ARCHITECTURE.md).
        if m.name == "sar-nostd-check" {
            continue;
        }
        let Some(rule) = rules.get(&m.name) else {
            wrong.push(format!(
                "{}: {} has no row in ARCHITECTURE.md's table",
                path.display(),
                m.name
            ));
            continue;
        };
        for (section, deps) in [
            ("dependencies", &m.dependencies),
            ("dev-dependencies", &m.dev_dependencies),
        ] {
            for dep in deps {
                let ours = by_name.contains_key(dep.as_str());
                let allowed = match section {
                    "dependencies" => rule.may.contains(dep) && !rule.tests_only.contains(dep),
                    _ => rule.may.contains(dep),
                };
                if ours && !allowed {
                    wrong.push(format!(
                        "{}: [{section}] {dep}: {} may not depend on it",
                        path.display(),
                        m.name
                    ));
                }
            }
        }
        for (dep, via) in linked(&m.name, &by_name) {
            if rule.must_not.contains(&dep) {
                let through = via.map(|v| format!(" (through {v})")).unwrap_or_default();
                wrong.push(format!(
                    "{}: {dep}{through}: {} must not link it",
                    path.display(),
                    m.name
                ));
            }
        }
    }
    wrong
}

#[test]
fn every_crate_depends_only_on_what_architecture_md_allows() {
    let architecture = std::fs::read_to_string(root().join("ARCHITECTURE.md")).unwrap();
    let rules = rules(&architecture);
    let manifests = manifests();
    // The table and the manifests are both read: the check has something
    // to check.
    assert!(rules.len() >= 8, "{rules:?}");
    assert!(manifests.len() >= 8, "{manifests:?}");
    let wrong = violations(&rules, &manifests);
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    // Every row names a crate that exists (a stale row is a stale map).
    let names: BTreeSet<&str> = manifests.iter().map(|(_, m)| m.name.as_str()).collect();
    for name in rules.keys() {
        assert!(names.contains(name.as_str()), "row {name}: no such crate");
    }
}

#[test]
fn the_check_refuses_a_dependency_pointing_up_and_a_forbidden_one() {
    let architecture = std::fs::read_to_string(root().join("ARCHITECTURE.md")).unwrap();
    let rules = rules(&architecture);
    let mut manifests = manifests();
    let (_, estimator) = manifests
        .iter_mut()
        .find(|(_, m)| m.name == "sar-estimator")
        .unwrap();
    // The estimator naming the loop (up), and the loop linking mcap.
    estimator.dependencies.insert("sar-loop".to_owned());
    let (_, the_loop) = manifests
        .iter_mut()
        .find(|(_, m)| m.name == "sar-loop")
        .unwrap();
    the_loop.dependencies.insert("mcap".to_owned());
    let wrong = violations(&rules, &manifests);
    // Both are found; the circle also makes the estimator link what the
    // loop links, which is said as well.
    let found = |s: &str| wrong.iter().filter(|w| w.contains(s)).count();
    assert_eq!(
        found("sar-loop: sar-estimator may not depend on it"),
        1,
        "{wrong:?}"
    );
    assert_eq!(found("mcap: sar-loop must not link it"), 1, "{wrong:?}");
    assert_eq!(
        found("mcap (through sar-loop): sar-estimator must not link it"),
        1,
        "{wrong:?}"
    );
}

#[test]
fn the_check_follows_workspace_crates_and_reads_every_dependency_section() {
    let architecture = std::fs::read_to_string(root().join("ARCHITECTURE.md")).unwrap();
    let rules = rules(&architecture);
    let mut manifests = manifests();
    // A forbidden crate two workspace crates down is found, and said where
    // it comes through.
    let (_, kinematics) = manifests
        .iter_mut()
        .find(|(_, m)| m.name == "sar-kinematics")
        .unwrap();
    kinematics.dependencies.insert("mcap".to_owned());
    let wrong = violations(&rules, &manifests);
    assert!(
        wrong
            .iter()
            .any(|w| w.contains("mcap (through sar-kinematics): sar-loop must not link it")),
        "{wrong:?}"
    );
    // A crate allowed to tests only is refused in [dependencies].
    let (_, sarctl) = manifests
        .iter_mut()
        .find(|(_, m)| m.name == "sarctl")
        .unwrap();
    assert!(sarctl.dev_dependencies.contains("sar-daemon"));
    sarctl.dependencies.insert("sar-daemon".to_owned());
    let wrong = violations(&rules, &manifests);
    assert!(
        wrong
            .iter()
            .any(|w| w.contains("[dependencies] sar-daemon: sarctl may not depend on it")),
        "{wrong:?}"
    );
    // Target-specific, build and `[dependencies.NAME]` sections are read.
    let m = manifest(
        "[package]\nname = \"x\"\n[target.'cfg(target_os = \"linux\")'.dependencies]\na = \"1\"\n\
         [build-dependencies]\nb.workspace = true\n[dependencies.c]\nversion = \"1\"\noptional = true\n\
         [dependencies]\nf = { version = \"1\", optional = true }\n\
         [target.'cfg(unix)'.dev-dependencies]\nd = \"1\"\n[features]\ne = []\n",
    );
    assert_eq!(m.name, "x");
    assert_eq!(
        m.dependencies
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
        ["a", "b", "c", "f"]
    );
    assert_eq!(
        m.optional.iter().map(String::as_str).collect::<Vec<_>>(),
        ["c", "f"]
    );
    assert_eq!(
        m.dev_dependencies
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
        ["d"]
    );
}

// ---------------------------------------------------------------------------
// The names ARCHITECTURE.md gives (issue 27): every back-quoted crate, file,
// module, type, function and macro exists where the text puts it, and each
// crate's "Links:" line is its external dependencies, exactly.

/// Back-quoted words that are not this project's names (std, the C library,
/// other crates' items, keywords): not checked.
const NOT_OURS: &[&str] = &[
    "clock_nanosleep",
    "ZeroCopySend",
    "unwrap",
    "expect",
    "panic!",
    "optional",
    "unsafe",
    "dev-dependencies",
    "Cargo.toml",
    "..",
    "sar",
    "Debug",
    "ros2",
];

/// What the source defines: each name with the files that define it (items,
/// enum variants, `mod` blocks, `pub use` re-exports) and the files that
/// `impl` something for it.
#[derive(Debug, Default)]
struct Defined {
    /// Name -> files (relative to the root) defining it.
    items: BTreeMap<String, BTreeSet<String>>,
    /// Type name -> files holding an `impl` block of it.
    impls: BTreeMap<String, BTreeSet<String>>,
    /// Module name -> the files of the module (`m.rs`, `m/mod.rs`, `m/*`).
    modules: BTreeMap<String, BTreeSet<String>>,
    /// Crate name as code writes it (`sar_loop`) -> its source files.
    crates: BTreeMap<String, BTreeSet<String>>,
    /// Enum variant -> the enums that have it.
    variants: BTreeMap<String, BTreeSet<String>>,
    /// Package names and binary names.
    packages: BTreeSet<String>,
    /// External crates some manifest depends on.
    external: BTreeSet<String>,
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The library and binary sources of every crate (`crates/NAME/src/...`),
/// each with its path from the root.
fn source_files() -> Vec<(PathBuf, String)> {
    let root = root();
    let mut files = Vec::new();
    rust_files(&root.join("crates"), &mut files);
    files
        .into_iter()
        .map(|path| {
            let rel = path
                .strip_prefix(&root)
                .unwrap()
                .to_string_lossy()
                .into_owned();
            (path, rel)
        })
        .filter(|(_, rel)| rel.split('/').nth(2) == Some("src") && rel.split('/').count() >= 4)
        .collect()
}

fn is_ident(s: &str) -> bool {
    let mut c = s.chars();
    c.next()
        .is_some_and(|f| f.is_ascii_alphabetic() || f == '_')
        && c.all(|x| x.is_ascii_alphanumeric() || x == '_')
}

/// The identifier after `keyword ` in `line`, if `line` has one.
fn after<'a>(line: &'a str, keyword: &str) -> Option<&'a str> {
    let at = line.find(keyword)?;
    let before = &line[..at];
    if !(before.is_empty() || before.ends_with([' ', '(', '{'])) {
        return None;
    }
    let rest = &line[at + keyword.len()..];
    let end = rest
        .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
        .unwrap_or(rest.len());
    let name = &rest[..end];
    is_ident(name).then_some(name)
}

fn defined() -> Defined {
    let root = root();
    let mut d = Defined::default();
    for (_, m) in manifests() {
        d.packages.insert(m.name.clone());
        d.external
            .extend(m.dependencies.iter().chain(&m.dev_dependencies).cloned());
    }
    d.packages.insert("sard".to_owned());
    for (path, rel) in source_files() {
        let parts: Vec<&str> = rel.split('/').collect();
        let manifest = manifest(
            &std::fs::read_to_string(root.join("crates").join(parts[1]).join("Cargo.toml"))
                .unwrap(),
        );
        d.crates
            .entry(manifest.name.replace('-', "_"))
            .or_default()
            .insert(rel.clone());
        // The module a file is: its stem, or its folder for mod.rs, and every
        // folder above it below src/.
        for (i, part) in parts.iter().enumerate().skip(3) {
            let name = part.trim_end_matches(".rs");
            if i + 1 == parts.len() && (name == "mod" || name == "lib" || name == "main") {
                continue;
            }
            d.modules
                .entry(name.to_owned())
                .or_default()
                .insert(rel.clone());
        }
        let text = std::fs::read_to_string(&path).unwrap();
        let mut in_enum = 0usize;
        let mut enum_name = String::new();
        let mut depth = 0isize;
        for line in text.lines() {
            let t = line.trim_start();
            if t.starts_with("//") {
                continue;
            }
            for kw in [
                "fn ",
                "struct ",
                "enum ",
                "trait ",
                "type ",
                "const ",
                "static ",
                "mod ",
                "union ",
                "macro_rules! ",
            ] {
                for (i, _) in t.match_indices(kw) {
                    if let Some(name) = after(&t[i..], kw)
                        .filter(|_| i == 0 || t[..i].ends_with([' ', '(', '{', '$']))
                    {
                        d.items
                            .entry(name.to_owned())
                            .or_default()
                            .insert(rel.clone());
                        if kw == "mod " {
                            d.modules
                                .entry(name.to_owned())
                                .or_default()
                                .insert(rel.clone());
                        }
                    }
                }
            }
            if let Some(rest) = t.strip_prefix("impl") {
                // `impl X`, `impl<T> X<T>`, `impl Trait for X`.
                let rest = rest.trim_start_matches(|c: char| c != ' ').trim();
                let target = rest.rsplit(" for ").next().unwrap_or(rest);
                let name: String = target
                    .chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect();
                if is_ident(&name) {
                    d.impls.entry(name).or_default().insert(rel.clone());
                }
            }
            if t.starts_with("pub use") || t.starts_with("pub(crate) use") {
                for name in t.split(|c: char| !(c.is_ascii_alphanumeric() || c == '_')) {
                    if is_ident(name) && name != "pub" && name != "use" && name != "crate" {
                        d.items
                            .entry(name.to_owned())
                            .or_default()
                            .insert(rel.clone());
                    }
                }
            }
            // Enum variants: the first identifier of a line one level inside
            // an `enum` body.
            if in_enum > 0 && depth == in_enum as isize {
                let name: String = t
                    .chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect();
                if is_ident(&name) && name.starts_with(|c: char| c.is_ascii_uppercase()) {
                    d.variants
                        .entry(name)
                        .or_default()
                        .insert(enum_name.clone());
                }
            }
            if let Some(name) = t.find("enum ").and_then(|i| after(&t[i..], "enum ")) {
                in_enum = (depth + 1) as usize;
                enum_name = name.to_owned();
            }
            depth += line.matches('{').count() as isize - line.matches('}').count() as isize;
            if in_enum > 0 && depth < in_enum as isize {
                in_enum = 0;
            }
        }
    }
    d
}

/// Files that hold `name`'s items: a module's files, a crate's files, a
/// type's defining and `impl` files.
fn scope(d: &Defined, name: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for map in [&d.modules, &d.crates, &d.impls] {
        if let Some(files) = map.get(name) {
            out.extend(files.iter().cloned());
        }
    }
    if let Some(files) = d.items.get(name) {
        out.extend(files.iter().cloned());
    }
    // A module's folder holds its submodules' files too.
    let folders: Vec<String> = out
        .iter()
        .filter(|f| f.ends_with(&format!("/{name}.rs")) || f.ends_with(&format!("/{name}/mod.rs")))
        .map(|f| {
            f.trim_end_matches(".rs")
                .trim_end_matches("/mod")
                .to_owned()
                + "/"
        })
        .collect();
    for (_, files) in d.modules.iter().chain(d.items.iter()) {
        for f in files {
            if folders.iter().any(|dir| f.starts_with(dir.as_str())) {
                out.insert(f.clone());
            }
        }
    }
    out
}

/// Why the back-quoted `word` is not a true name (None: it is, or it is
/// not a name of ours). `crate_files`: the files of the section's crate.
fn check_word(d: &Defined, word: &str) -> Option<String> {
    let root = root();
    if NOT_OURS.contains(&word) {
        return None;
    }
    // A path of the repository (or of the shared spec beside it).
    if word.contains('/') && !word.contains(' ') {
        let first = word.split('/').next().unwrap_or("");
        let ours = [
            "crates",
            "tests",
            "scripts",
            "deploy",
            "scenarios",
            ".ci",
            "..",
        ]
        .contains(&first);
        if ours && !root.join(word).exists() {
            return Some(format!("`{word}`: no such file or folder"));
        }
        return None;
    }
    if word.ends_with(".md") && !word.contains(' ') {
        return (!root.join(word).exists()).then(|| format!("`{word}`: no such file"));
    }
    if d.external.contains(word) {
        return None; // another crate, named as a dependency
    }
    if (word.starts_with("sar-") || word == "sarctl" || word == "sard") && !word.contains(' ') {
        return (!d.packages.contains(word)).then(|| format!("`{word}`: no such crate"));
    }
    let bare = word.trim_end_matches("()").trim_end_matches('!');
    let segments: Vec<&str> = bare.split("::").collect();
    if !segments.iter().all(|s| is_ident(s)) {
        return None; // not a name: a command, a key, an expression
    }
    let single_lower = segments.len() == 1
        && !word.ends_with("()")
        && !word.ends_with('!')
        && !bare.starts_with(|c: char| c.is_ascii_uppercase());
    let last = segments[segments.len() - 1];
    if single_lower {
        // A module or function of ours, or not a code name at all (a word).
        let known = d.modules.contains_key(last)
            || d.items.contains_key(last)
            || d.crates.contains_key(last);
        return (!known).then(|| format!("`{word}`: no module, function or item of that name"));
    }
    if segments.len() == 1 {
        return (!d.items.contains_key(last) && !d.variants.contains_key(last))
            .then(|| format!("`{word}`: not defined anywhere in crates/*/src"));
    }
    for pair in segments.windows(2) {
        let (outer, inner) = (pair[0], pair[1]);
        let files = scope(d, outer);
        if files.is_empty() {
            return Some(format!(
                "`{word}`: `{outer}` is no crate, module or type of ours"
            ));
        }
        let inside = d
            .items
            .get(inner)
            .into_iter()
            .chain(d.modules.get(inner))
            .flatten()
            .any(|f| files.contains(f))
            || d.variants
                .get(inner)
                .is_some_and(|enums| enums.contains(outer));
        if !inside {
            return Some(format!("`{word}`: `{inner}` is not defined in `{outer}`"));
        }
    }
    None
}

/// Every back-quoted span of `text` outside code blocks, with its line.
fn quoted(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    let mut fenced = false;
    for (i, line) in text.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if fenced {
            continue;
        }
        // Odd pieces between back-quotes are the quoted spans.
        for (k, q) in line.split('`').enumerate() {
            if k % 2 == 1 {
                out.push((i + 1, q.to_owned()));
            }
        }
    }
    out
}

/// The "Links:" line of each crate section: crate name -> the names listed.
fn links_lines(text: &str) -> BTreeMap<String, BTreeSet<String>> {
    let mut out = BTreeMap::new();
    let mut krate: Option<String> = None;
    let mut collecting: Option<String> = None;
    for line in text.lines() {
        if line.starts_with("### ") {
            krate = line
                .split('(')
                .nth(1)
                .and_then(|r| r.split(')').next())
                .map(|s| s.trim_matches('`').to_owned());
            collecting = None;
            continue;
        }
        let t = line.trim();
        if let Some(rest) = t.strip_prefix("- Links:") {
            collecting = Some(rest.to_owned());
        } else if let Some(c) = collecting.as_mut() {
            if t.is_empty() || t.starts_with("- ") || t.starts_with('#') {
                let names = std::mem::take(c);
                collecting = None;
                if let Some(k) = &krate {
                    out.insert(k.clone(), parse_links(&names));
                }
            } else {
                c.push(' ');
                c.push_str(t);
            }
        }
    }
    if let (Some(c), Some(k)) = (collecting, krate) {
        out.insert(k, parse_links(&c));
    }
    out
}

fn parse_links(s: &str) -> BTreeSet<String> {
    // "none ...": no external dependency.
    if s.trim().starts_with("none") {
        return BTreeSet::new();
    }
    // Up to the first full stop; "(...)" remarks dropped.
    let mut clean = String::new();
    let mut depth = 0;
    for c in s.chars() {
        match c {
            '(' => depth += 1,
            ')' => depth -= 1,
            '.' if depth == 0 => break,
            _ if depth == 0 => clean.push(c),
            _ => {}
        }
    }
    clean
        .split(',')
        .map(|n| n.trim().trim_matches('`').to_owned())
        .filter(|n| !n.is_empty())
        .collect()
}

#[test]
fn every_name_in_architecture_md_exists_where_it_says() {
    let text = std::fs::read_to_string(root().join("ARCHITECTURE.md")).unwrap();
    let d = defined();
    let words = quoted(&text);
    let mut wrong = Vec::new();
    let mut checked = 0;
    for (line, word) in &words {
        let counts = !NOT_OURS.contains(&word.as_str());
        if let Some(why) = check_word(&d, word) {
            wrong.push(format!("ARCHITECTURE.md:{line}: {why}"));
        } else if counts {
            checked += 1;
        }
    }
    println!(
        "{checked} back-quoted names checked of {} spans",
        words.len()
    );
    assert!(
        checked >= 100,
        "only {checked} names checked: the parser lost them"
    );
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

#[test]
fn each_crates_links_line_is_its_external_dependencies() {
    let text = std::fs::read_to_string(root().join("ARCHITECTURE.md")).unwrap();
    let lines = links_lines(&text);
    let mut wrong = Vec::new();
    let mut seen = 0;
    for (_, m) in manifests() {
        if m.name == "sar-nostd-check" || m.name == "sar-tests" {
            continue;
        }
        let external: BTreeSet<String> = m
            .dependencies
            .iter()
            .filter(|d| !(d.starts_with("sar-") || *d == "sarctl"))
            .cloned()
            .collect();
        match lines.get(&m.name) {
            None => wrong.push(format!("{}: no \"- Links:\" line in its section", m.name)),
            Some(listed) => {
                seen += 1;
                for d in external.difference(listed) {
                    wrong.push(format!(
                        "{}: links {d}, which its Links: line omits",
                        m.name
                    ));
                }
                for d in listed.difference(&external) {
                    wrong.push(format!(
                        "{}: its Links: line names {d}, which it does not depend on",
                        m.name
                    ));
                }
            }
        }
    }
    assert!(seen >= 10, "{lines:?}");
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

#[test]
fn the_name_check_refuses_a_stale_name() {
    let d = defined();
    // Real ones pass...
    for ok in [
        "LoopStep::step",
        "sar_hal::motion",
        "Estimator::cycle",
        "crates/loop/src/step/mod.rs",
        "sar-loop",
        "snap_struct!",
        "GuardState",
        "runloop::run",
    ] {
        assert_eq!(check_word(&d, ok), None, "{ok}");
    }
    // ...and made-up or misplaced ones fail.
    for bad in [
        "LoopStep::cycle_following",
        "sar_loop::Estimator",
        "crates/loop/src/nothing.rs",
        "sar-nothing",
        "NoSuchType",
        "guard::state_msg",
        "no_such_macro!",
    ] {
        assert!(check_word(&d, bad).is_some(), "{bad} passed");
    }
    let links = parse_links(" nalgebra, foxglove (optional), socketcan.\n");
    assert_eq!(
        links.into_iter().collect::<Vec<_>>(),
        ["foxglove", "nalgebra", "socketcan"]
    );
}

/// The top-level modules of each crate and the ones each imports
/// (`crate::NAME` in code, outside comments and `#[cfg(test)]` modules).
fn module_imports() -> BTreeMap<String, BTreeMap<String, BTreeSet<String>>> {
    let mut out: BTreeMap<String, BTreeMap<String, BTreeSet<String>>> = BTreeMap::new();
    for (path, rel) in source_files() {
        let parts: Vec<&str> = rel.split('/').collect();
        let module = parts[3].trim_end_matches(".rs");
        if matches!(module, "lib" | "main" | "bin") {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        let code = text.split("#[cfg(test)]\nmod tests").next().unwrap_or("");
        let imports = out
            .entry(parts[1].to_owned())
            .or_default()
            .entry(module.to_owned())
            .or_default();
        for line in code.lines() {
            let line = line.split("//").next().unwrap_or("");
            for (i, _) in line.match_indices("crate::") {
                let name: String = line[i + 7..]
                    .chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect();
                if name != module && !name.is_empty() {
                    imports.insert(name);
                }
            }
        }
    }
    out
}

/// An import circle among `graph`'s modules, as the path that closes it.
fn circle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        n: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(at) = path.iter().position(|p| p == n) {
            let mut c = path[at..].to_vec();
            c.push(n.to_owned());
            return Some(c);
        }
        if done.contains(n) {
            return None;
        }
        path.push(n.to_owned());
        for next in graph.get(n).into_iter().flatten() {
            // Only modules of this crate (a re-exported item is not a module).
            if graph.contains_key(next)
                && let Some(c) = visit(next, graph, path, done)
            {
                return Some(c);
            }
        }
        path.pop();
        done.insert(n.to_owned());
        None
    }
    let mut done = BTreeSet::new();
    graph
        .keys()
        .find_map(|n| visit(n, graph, &mut Vec::new(), &mut done))
}

#[test]
fn no_crate_has_an_import_circle_between_its_modules() {
    let all = module_imports();
    assert!(all.len() >= 10, "{:?}", all.keys());
    let circles: Vec<String> = all
        .iter()
        .filter_map(|(krate, graph)| {
            circle(graph).map(|c| format!("crates/{krate}: {}", c.join(" -> ")))
        })
        .collect();
    assert!(
        circles.is_empty(),
        "import circles:\n{}",
        circles.join("\n")
    );
    // The check finds one when there is one.
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    graph.insert("a".into(), ["b".into()].into());
    graph.insert("b".into(), ["c".into()].into());
    graph.insert("c".into(), ["a".into()].into());
    assert_eq!(circle(&graph).unwrap(), ["a", "b", "c", "a"]);
    graph.insert("c".into(), BTreeSet::new());
    assert_eq!(circle(&graph), None);
}

/// The submodules of each module directory (`crates/K/src/A/B.rs` and
/// `crates/K/src/A/B/mod.rs` are `B` of `K/A`) and the siblings each
/// imports (`super::NAME` or `crate::A::NAME` in code, outside comments and
/// `#[cfg(test)]` modules).
fn submodule_imports() -> BTreeMap<String, BTreeMap<String, BTreeSet<String>>> {
    let mut out: BTreeMap<String, BTreeMap<String, BTreeSet<String>>> = BTreeMap::new();
    for (path, rel) in source_files() {
        let parts: Vec<&str> = rel.split('/').collect();
        if parts.len() < 5 || parts[4] == "mod.rs" {
            continue;
        }
        let parent = format!("{}/{}", parts[1], parts[3]);
        let module = parts[4].trim_end_matches(".rs").to_owned();
        let text = std::fs::read_to_string(&path).unwrap();
        let code = text.split("#[cfg(test)]\nmod tests").next().unwrap_or("");
        let absolute = format!("crate::{}::", parts[3]);
        let imports = out
            .entry(parent)
            .or_default()
            .entry(module.clone())
            .or_default();
        for line in code.lines() {
            let line = line.split("//").next().unwrap_or("");
            for prefix in ["super::", absolute.as_str()] {
                for (i, _) in line.match_indices(prefix) {
                    let name: String = line[i + prefix.len()..]
                        .chars()
                        .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                        .collect();
                    if name != module && !name.is_empty() {
                        imports.insert(name);
                    }
                }
            }
        }
    }
    out
}

#[test]
fn no_module_has_an_import_circle_between_its_submodules() {
    let all = submodule_imports();
    assert!(
        all.keys().any(|k| k == "sarctl/cli") && all.keys().any(|k| k == "estimator/cycle"),
        "{:?}",
        all.keys()
    );
    let circles: Vec<String> = all
        .iter()
        .filter_map(|(dir, graph)| {
            circle(graph).map(|c| format!("crates/{dir}: {}", c.join(" -> ")))
        })
        .collect();
    assert!(
        circles.is_empty(),
        "import circles between submodules:\n{}",
        circles.join("\n")
    );
}

/// The sections of ARCHITECTURE.md's crates, by their `crates/NAME`
/// heading, each with its text on one line (whitespace folded).
fn crate_sections(text: &str) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    for part in text.split("\n### `crates/").skip(1) {
        let name: String = part.chars().take_while(|c| *c != '`').collect();
        let body = part.split("\n## ").next().unwrap_or("");
        out.insert(name, body.split_whitespace().collect::<Vec<_>>().join(" "));
    }
    out
}

/// What may call a section's crate, and why its boundary is where it is,
/// the rust-analyzer way (issue 36): missing from a section, named.
fn sections_without_callers(text: &str) -> Vec<String> {
    crate_sections(text)
        .into_iter()
        .filter(|(_, body)| {
            let lower = body.to_lowercase();
            !(lower.contains("who calls it") || lower.contains("who may call it"))
                || !lower.contains("why the boundary is here")
        })
        .map(|(name, _)| name)
        .collect()
}

/// Every crate's section says who calls it and why its boundary is where
/// it is; the check finds a section without them.
#[test]
fn each_crates_section_says_who_calls_it_and_why_its_boundary_is_there() {
    let text = std::fs::read_to_string(root().join("ARCHITECTURE.md")).unwrap();
    let sections = crate_sections(&text);
    let crates_dir: BTreeSet<String> = std::fs::read_dir(root().join("crates"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        sections.keys().cloned().collect::<BTreeSet<_>>(),
        crates_dir,
        "a section per crate"
    );
    assert_eq!(sections_without_callers(&text), Vec::<String>::new());
    let bare = "x\n### `crates/a` (`a`)\nWhat it is.\n- Links: none.\n";
    assert_eq!(sections_without_callers(bare), ["a"]);
}
