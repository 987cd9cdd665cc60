//! The layering of ARCHITECTURE.md is checked, not promised (issue 18): its
//! table says, for every crate of the workspace, which of the workspace's
//! crates it may depend on and which external crates it must never link.
//! Every `Cargo.toml` is read: each workspace crate has a row; its
//! `[dependencies]` and `[dev-dependencies]` name only the workspace crates
//! its row allows; none of its dependencies is one its row forbids.

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
    may: BTreeSet<String>,
    must_not: BTreeSet<String>,
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn names(cell: &str) -> BTreeSet<String> {
    cell.split(',')
        .map(|n| n.trim().to_owned())
        .filter(|n| !n.is_empty())
        .collect()
}

/// The table's rows, by crate name.
fn rules(architecture: &str) -> BTreeMap<String, Rule> {
    let mut rules = BTreeMap::new();
    for line in architecture.lines() {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        // "| name | may | must not |" splits into 5 cells, empty at the ends.
        if cells.len() != 5 || !cells[1].starts_with("sar-") {
            continue;
        }
        let rule = Rule {
            may: names(cells[2]),
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

/// A manifest's package name and its dependencies, per section.
#[derive(Debug)]
struct Manifest {
    name: String,
    dependencies: BTreeSet<String>,
    dev_dependencies: BTreeSet<String>,
}

fn manifest(text: &str) -> Manifest {
    let mut section = String::new();
    let mut m = Manifest {
        name: String::new(),
        dependencies: BTreeSet::new(),
        dev_dependencies: BTreeSet::new(),
    };
    for line in text.lines().map(str::trim) {
        if line.starts_with('[') {
            section = line.trim_matches(['[', ']']).to_owned();
            continue;
        }
        let Some((key, value)) = line.split_once('=') else {
            continue;
        };
        let key = key.trim();
        // `name.workspace = true` and `name = ...` alike.
        let dep = key.split('.').next().unwrap_or(key).to_owned();
        match section.as_str() {
            "package" if key == "name" => m.name = value.trim().trim_matches('"').to_owned(),
            "dependencies" => {
                m.dependencies.insert(dep);
            }
            "dev-dependencies" => {
                m.dev_dependencies.insert(dep);
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

/// What is wrong with the manifests against the table (empty: nothing).
fn violations(rules: &BTreeMap<String, Rule>, manifests: &[(PathBuf, Manifest)]) -> Vec<String> {
    let ours: BTreeSet<&str> = manifests.iter().map(|(_, m)| m.name.as_str()).collect();
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
                if ours.contains(dep.as_str()) && !rule.may.contains(dep) {
                    wrong.push(format!(
                        "{}: [{section}] {dep}: {} may not depend on it",
                        path.display(),
                        m.name
                    ));
                }
                if section == "dependencies" && rule.must_not.contains(dep) {
                    wrong.push(format!(
                        "{}: [{section}] {dep}: {} must not link it",
                        path.display(),
                        m.name
                    ));
                }
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
    assert_eq!(wrong.len(), 2, "{wrong:?}");
    assert!(wrong[0].contains("sar-loop: sar-estimator may not depend on it"));
    assert!(wrong[1].contains("mcap: sar-loop must not link it"));
}
