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
