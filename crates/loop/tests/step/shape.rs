//! The step's shape (issue 36): one writer of the trajectory (the commit
//! point, `step/commit.rs`), no undo of a decision, queries that take
//! `&self`, and single-idea files of at most about 600 lines.

#![allow(clippy::indexing_slicing)]

use std::path::PathBuf;

/// The step's source files: (name, text).
fn step_files() -> Vec<(String, String)> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("src/step");
    let mut files: Vec<(String, String)> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "rs"))
        .map(|p| {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            (name, std::fs::read_to_string(&p).unwrap())
        })
        .collect();
    files.sort();
    files
}

/// The lines of `text` outside comments that write `self.trajectory`.
fn trajectory_writes(text: &str) -> Vec<String> {
    let writes = [
        "self.trajectory =",
        "self.trajectory.take(",
        "self.trajectory.as_mut(",
        "self.trajectory.replace(",
        "self.trajectory.insert(",
        "self.trajectory.get_or_insert",
        "&mut self.trajectory",
    ];
    text.lines()
        .map(|l| l.split("//").next().unwrap_or(""))
        .filter(|code| writes.iter().any(|w| code.contains(w)))
        .map(str::to_owned)
        .collect()
}

#[test]
fn the_trajectory_has_one_writer_and_no_decision_is_undone() {
    let files = step_files();
    assert!(
        files.len() >= 10,
        "{:?}",
        files.iter().map(|f| &f.0).collect::<Vec<_>>()
    );
    // The check sees a write where there is one.
    assert_eq!(
        trajectory_writes("        self.trajectory = None;").len(),
        1
    );
    assert!(trajectory_writes("    // self.trajectory = None;").is_empty());
    let mut writers = Vec::new();
    for (name, text) in &files {
        let writes = trajectory_writes(text);
        if !writes.is_empty() {
            writers.push((name.as_str(), writes));
        }
        assert!(
            !text.contains("Option<Option<"),
            "{name}: an undo of a decision"
        );
    }
    assert_eq!(
        writers.iter().map(|w| w.0).collect::<Vec<_>>(),
        ["commit.rs"],
        "{writers:?}"
    );
    assert_eq!(writers[0].1.len(), 1, "{writers:?}");
}

#[test]
fn the_queries_take_a_shared_step() {
    let files = step_files();
    let all: String = files.iter().map(|f| f.1.as_str()).collect();
    for query in [
        "host_fault",
        "carriage_motion",
        "following_reference",
        "absorb_late_cycle",
        "held_reset",
        "ready_at_rest",
        "brake_if_due",
        "plan_move",
        "motion_action",
    ] {
        let start = all
            .find(&format!("fn {query}("))
            .unwrap_or_else(|| panic!("no fn {query}"));
        let signature = &all[start..start + all[start..].find(')').unwrap()];
        assert!(signature.contains("&self"), "{signature}");
        assert!(!signature.contains("&mut self"), "{signature}");
    }
}

#[test]
fn each_file_holds_one_idea_of_at_most_about_600_lines() {
    for (name, text) in step_files() {
        let lines = text.lines().count();
        assert!(lines <= 600, "{name}: {lines} lines");
        assert!(text.starts_with("//! "), "{name}: no module doc comment");
    }
}
