//! SAFETY.md is kept true: every guard reason of the estimator's one table
//! (`REASONS`) is named in it, every row of its failure-mode tables has all
//! ten columns (the tenth: what a control outside `sard` still catches),
//! and every test a row names exists (a `fn` of that name in the
//! workspace's sources).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use sar_estimator::guard::REASONS;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// Every `.rs` file under `dir`.
fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        if path.is_dir() {
            if name != "target" && !name.starts_with('.') {
                sources(&path, out);
            }
        } else if name.ends_with(".rs") {
            out.push(path);
        }
    }
}

/// The rows of the failure-mode table: the lines of the table whose first
/// cell is an id (S1, E2, ...), split into cells.
fn rows(doc: &str) -> Vec<Vec<String>> {
    doc.lines()
        .filter(|l| l.starts_with("| "))
        .map(|l| {
            l.trim()
                .trim_matches('|')
                .split(" | ")
                .map(|c| c.trim().to_owned())
                .collect::<Vec<_>>()
        })
        .filter(|cells| {
            let id = &cells[0];
            id.len() >= 2
                && id.chars().next().unwrap().is_ascii_uppercase()
                && id[1..].chars().all(|c| c.is_ascii_digit())
        })
        .collect()
}

/// The `backticked` names of a cell.
fn names(cell: &str) -> Vec<String> {
    cell.split('`')
        .enumerate()
        .filter(|(i, _)| i % 2 == 1)
        .map(|(_, s)| s.to_owned())
        .collect()
}

#[test]
fn safety_md_names_every_reason_and_only_tests_that_exist() {
    let doc = std::fs::read_to_string(root().join("SAFETY.md")).unwrap();
    for (code, name) in REASONS {
        assert!(
            doc.contains(&format!("`{name}`")),
            "SAFETY.md does not name the reason `{name}` (code {code})"
        );
    }
    let table = rows(&doc);
    assert!(table.len() >= 30, "only {} rows", table.len());
    let mut files = Vec::new();
    sources(&root().join("crates"), &mut files);
    sources(&root().join("tests"), &mut files);
    let text: String = files
        .iter()
        .map(|f| std::fs::read_to_string(f).unwrap())
        .collect::<Vec<_>>()
        .join("\n");
    let mut ids = std::collections::BTreeSet::new();
    for row in &table {
        assert_eq!(
            row.len(),
            10,
            "row {} has {} columns: {row:?}",
            row[0],
            row.len()
        );
        assert!(ids.insert(row[0].clone()), "row id {} twice", row[0]);
        // The tenth column: what a control outside `sard` (the drives' own
        // limits and heartbeat consumer, systemd, the kernel, the sensor)
        // still catches; "nothing" is an answer, an empty cell is not.
        assert!(
            row[9].len() >= 7 && !row[9].contains("TODO"),
            "row {} does not say what still catches it outside sard: {:?}",
            row[0],
            row[9]
        );
        let tests = names(&row[8]);
        assert!(!tests.is_empty(), "row {} names no test", row[0]);
        for t in tests {
            assert!(
                text.contains(&format!("fn {t}(")),
                "row {} names the test `{t}`, which does not exist",
                row[0]
            );
        }
        // A snake-case name of the detection column is a reason of the
        // table, or a setting or item of the code.
        for name in names(&row[4]) {
            let snake = name
                .chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_');
            if snake {
                let known = REASONS.iter().any(|(_, n)| *n == name) || text.contains(&name);
                assert!(
                    known,
                    "row {}: `{name}` is neither a reason nor in the code",
                    row[0]
                );
            }
        }
    }
}
