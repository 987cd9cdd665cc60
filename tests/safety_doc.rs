//! SAFETY.md is kept true: every guard reason of the estimator's one table
//! (`REASONS`) is named in it, every row of its failure-mode tables has all
//! ten columns (the tenth: what a control outside `sard` still catches),
//! and every test a row names exists (a `fn` of that name in the
//! workspace's sources).
//!
//! Its risk evaluation in ISO 14971's form ("## Risk evaluation (ISO
//! 14971)") is kept whole: the scales are stated (five severity levels with
//! the harm figure 17.9 N, five probability levels, the three control
//! types, the acceptability matrix); the risk table has one row for every
//! row of the failure-mode tables, in their order, every cell filled: the
//! chain hazard → sequence of events → hazardous situation → harm, a
//! severity S1..S5, probabilities P1..P5 before and after (after never
//! above before), a control type of the three (or a " + " combination), a
//! test that exists, a figure with a digit; no residual is unacceptable by
//! the matrix, and the rows named ALARP are exactly those the matrix makes
//! ALARP.

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

/// The heading of the risk evaluation: everything before it is the
/// failure-mode tables and their sections.
const RISK: &str = "## Risk evaluation (ISO 14971)";

/// The part of SAFETY.md before the risk evaluation (the failure-mode
/// tables); the whole document if the risk evaluation is missing (its own
/// test says so).
fn fmea_part(doc: &str) -> &str {
    doc.find(&format!("\n{RISK}\n"))
        .map_or(doc, |at| &doc[..at])
}

/// The section under `heading` (a whole line, e.g. "### Severity"): from
/// the line after it to the next heading of the same or a higher level.
fn section<'a>(doc: &'a str, heading: &str) -> &'a str {
    let level = heading.chars().take_while(|c| *c == '#').count();
    let start = doc
        .find(&format!("\n{heading}\n"))
        .unwrap_or_else(|| panic!("SAFETY.md has no section \"{heading}\""))
        + heading.len()
        + 2;
    let rest = &doc[start..];
    let end = rest
        .match_indices('\n')
        .map(|(i, _)| i + 1)
        .find(|&i| {
            let hashes = rest[i..].chars().take_while(|c| *c == '#').count();
            (1..=level).contains(&hashes) && rest[i + hashes..].starts_with(' ')
        })
        .unwrap_or(rest.len());
    &rest[..end]
}

/// The sources of the workspace (`crates/` and `tests/`), joined: where a
/// test named in SAFETY.md must be defined.
fn workspace_text() -> String {
    let mut files = Vec::new();
    sources(&root().join("crates"), &mut files);
    sources(&root().join("tests"), &mut files);
    files
        .iter()
        .map(|f| std::fs::read_to_string(f).unwrap())
        .collect::<Vec<_>>()
        .join("\n")
}

/// Whether the workspace's sources define a `fn` of this name.
fn test_exists(text: &str, name: &str) -> bool {
    text.contains(&format!("fn {name}("))
}

/// The rows of a table in `doc`: the lines of the table whose first cell
/// is an id (S1, E2, ...), split into cells.
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
    let table = rows(fmea_part(&doc));
    assert!(table.len() >= 30, "only {} rows", table.len());
    let text = workspace_text();
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
                test_exists(&text, &t),
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

/// The three types of risk control of ISO 14971, in its order of preference.
const CONTROL_TYPES: [&str; 3] = [
    "inherent safety by design",
    "protective measure",
    "information for safety",
];

/// A level `S1`..`S5` or `P1`..`P5`: its number, if `cell` is one.
fn level(cell: &str, letter: char) -> Option<usize> {
    let digits = cell.strip_prefix(letter)?;
    match digits {
        "1" | "2" | "3" | "4" | "5" => digits.parse().ok(),
        _ => None,
    }
}

/// Whether a cell says nothing.
fn empty(cell: &str) -> bool {
    matches!(cell.trim(), "" | "—" | "-" | "--") || cell.contains("TODO")
}

/// The first ids of the rows of a section's tables.
fn ids(rows: &[Vec<String>]) -> Vec<String> {
    rows.iter().map(|r| r[0].clone()).collect()
}

/// The acceptability matrix: for each severity 1..=5, the verdict at P1..P5.
fn matrix(risk: &str) -> [[String; 5]; 5] {
    let text = section(risk, "### Acceptability");
    let mut m: [[String; 5]; 5] = Default::default();
    let mut seen = [false; 5];
    for row in rows(text) {
        let s = level(&row[0], 'S')
            .unwrap_or_else(|| panic!("the acceptability matrix has a row {:?}", row[0]));
        assert_eq!(
            row.len(),
            6,
            "the acceptability matrix's row {} has {} cells, not a severity and 5 verdicts",
            row[0],
            row.len()
        );
        for (p, verdict) in row[1..].iter().enumerate() {
            assert!(
                matches!(verdict.as_str(), "acceptable" | "ALARP" | "unacceptable"),
                "the acceptability matrix's row {} at P{}: {verdict:?} is not \
                 acceptable, ALARP or unacceptable",
                row[0],
                p + 1
            );
            m[s - 1][p] = verdict.clone();
        }
        assert!(
            !seen[s - 1],
            "the acceptability matrix has {} twice",
            row[0]
        );
        seen[s - 1] = true;
    }
    assert!(
        seen.iter().all(|s| *s),
        "the acceptability matrix lacks a severity: rows {seen:?} for S1..S5"
    );
    m
}

#[test]
fn the_risk_evaluation_states_its_scales() {
    let doc = std::fs::read_to_string(root().join("SAFETY.md")).unwrap();
    assert!(
        doc.contains(&format!("\n{RISK}\n")),
        "SAFETY.md has no section \"{RISK}\""
    );
    let risk = section(&doc, RISK);
    let severity = section(risk, "### Severity");
    let levels = rows(severity);
    assert_eq!(
        ids(&levels),
        ["S1", "S2", "S3", "S4", "S5"],
        "the severity scale is not the five levels S1..S5 in order"
    );
    for row in &levels {
        assert!(
            row.len() >= 3 && row[1..].iter().all(|c| !empty(c)),
            "severity level {} is not named and defined: {row:?}",
            row[0]
        );
    }
    assert!(
        severity.contains("17.9"),
        "the severity scale does not state the harm figure 17.9 N (ex-vivo perforation)"
    );
    let levels = rows(section(risk, "### Probability"));
    assert_eq!(
        ids(&levels),
        ["P1", "P2", "P3", "P4", "P5"],
        "the probability scale is not the five levels P1..P5 in order"
    );
    for row in &levels {
        assert!(
            row.len() >= 3 && row[1..].iter().all(|c| !empty(c)),
            "probability level {} is not named and defined: {row:?}",
            row[0]
        );
    }
    let types = section(risk, "### Control types");
    for t in CONTROL_TYPES {
        assert!(types.contains(t), "the control types do not state \"{t}\"");
    }
    matrix(risk);
}

#[test]
fn every_failure_mode_has_its_risk_row_in_order() {
    let doc = std::fs::read_to_string(root().join("SAFETY.md")).unwrap();
    let expected = ids(&rows(fmea_part(&doc)));
    let found = ids(&rows(section(section(&doc, RISK), "### The risk table")));
    for id in &found {
        assert!(
            expected.contains(id),
            "the risk table has a row {id}, which no failure-mode table has"
        );
    }
    for id in &expected {
        assert!(found.contains(id), "row {id} has no row in the risk table");
    }
    for (k, (e, f)) in expected.iter().zip(&found).enumerate() {
        assert_eq!(
            e,
            f,
            "the risk table's row {} is {f}; the failure-mode tables have {e} there \
             (the same order, please)",
            k + 1
        );
    }
    assert_eq!(
        expected.len(),
        found.len(),
        "the risk table has {} rows for {} failure modes (an id twice?)",
        found.len(),
        expected.len()
    );
}

#[test]
fn every_risk_row_has_every_cell() {
    let doc = std::fs::read_to_string(root().join("SAFETY.md")).unwrap();
    let risk = section(&doc, RISK);
    let table = rows(section(risk, "### The risk table"));
    assert!(!table.is_empty(), "the risk table has no rows");
    let matrix = matrix(risk);
    let text = workspace_text();
    let mut alarp = Vec::new();
    for row in &table {
        let id = &row[0];
        assert_eq!(
            row.len(),
            8,
            "risk row {id} has {} cells, not 8: {row:?}",
            row.len()
        );
        for (cell, name) in row.iter().zip([
            "id",
            "hazard → sequence of events → hazardous situation → harm",
            "severity",
            "P before",
            "control type",
            "P after",
            "verification of implementation",
            "verification of effectiveness",
        ]) {
            assert!(!empty(cell), "risk row {id}: the cell \"{name}\" is empty");
        }
        let chain = &row[1];
        let parts: Vec<&str> = chain.split('→').map(str::trim).collect();
        assert!(
            parts.len() == 4 && parts.iter().all(|p| !p.is_empty()),
            "risk row {id}: the chain is not hazard → sequence of events → hazardous \
             situation → harm (three arrows between four parts): {chain:?}"
        );
        let severity = level(&row[2], 'S').unwrap_or_else(|| {
            panic!(
                "risk row {id}: the severity {:?} is not one of S1..S5",
                row[2]
            )
        });
        let before = level(&row[3], 'P')
            .unwrap_or_else(|| panic!("risk row {id}: P before {:?} is not one of P1..P5", row[3]));
        let after = level(&row[5], 'P')
            .unwrap_or_else(|| panic!("risk row {id}: P after {:?} is not one of P1..P5", row[5]));
        assert!(
            after <= before,
            "risk row {id}: P after ({}) is above P before ({})",
            row[5],
            row[3]
        );
        let types: Vec<&str> = row[4].split(" + ").collect();
        for t in &types {
            assert!(
                CONTROL_TYPES.contains(t),
                "risk row {id}: the control type {t:?} is not one of {CONTROL_TYPES:?} \
                 (combine them with \" + \")"
            );
        }
        for (k, t) in types.iter().enumerate() {
            assert!(
                !types[..k].contains(t),
                "risk row {id}: the control type {t:?} twice"
            );
        }
        let tests = names(&row[6]);
        assert!(
            !tests.is_empty(),
            "risk row {id}: the verification of implementation names no test in backticks"
        );
        for t in tests {
            assert!(
                test_exists(&text, &t),
                "risk row {id}: the verification of implementation names the test `{t}`, \
                 which does not exist"
            );
        }
        assert!(
            row[7].chars().any(|c| c.is_ascii_digit()),
            "risk row {id}: the verification of effectiveness gives no figure (no digit): {:?}",
            row[7]
        );
        let verdict = &matrix[severity - 1][after - 1];
        assert_ne!(
            verdict, "unacceptable",
            "risk row {id}: its residual ({}, {}) is unacceptable by the matrix",
            row[2], row[5]
        );
        if verdict == "ALARP" {
            alarp.push(id.clone());
        }
    }
    // The rows named ALARP, each with why, are those the matrix makes so.
    let named = rows(section(risk, "### The rows whose residual is ALARP"));
    for row in &named {
        assert!(
            row.len() == 2 && !empty(&row[1]),
            "ALARP row {} does not say why: {row:?}",
            row[0]
        );
        assert!(
            alarp.contains(&row[0]),
            "row {} is named ALARP, but its residual is not ALARP by the matrix",
            row[0]
        );
    }
    let named = ids(&named);
    for id in &alarp {
        assert!(
            named.contains(id),
            "risk row {id}: its residual is ALARP by the matrix, but it is not named \
             among the ALARP rows with why"
        );
    }
}
