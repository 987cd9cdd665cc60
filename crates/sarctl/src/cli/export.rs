//! `sarctl export --rosbag2 DIR REC.mcap...`: a rosbag2 directory of a
//! recording's files ([`sar_record::rosbag2`]), its contents printed
//! (`--format json`: one object).

use sar_record::rosbag2;
use std::path::{Path, PathBuf};

/// Runs the command.
pub fn run(dir: &Path, recordings: &[PathBuf], json: bool) -> Result<(), String> {
    let r = rosbag2::export(dir, recordings).map_err(|e| e.to_string())?;
    if json {
        let v = serde_json::json!({
            "directory": r.directory.display().to_string(),
            "metadata": r.directory.join("metadata.yaml").display().to_string(),
            "files": r.files.iter().map(|f| &f.name).collect::<Vec<_>>(),
            "copied": r.copied,
            "messages": r.messages(),
            "duration_ns": r.duration_ns(),
            "topics": r.topics.iter().map(|t| (t.topic.clone(), serde_json::Value::from(t.messages))).collect::<serde_json::Map<_, _>>(),
        });
        println!("{v}");
    } else {
        println!(
            "{}: rosbag2 directory of {} file(s) ({}), {} messages on {} topics over {:.3} s; metadata.yaml written (ros2 bag info {0})",
            r.directory.display(),
            r.files.len(),
            if r.copied > 0 {
                "copied"
            } else {
                "hard-linked"
            },
            r.messages(),
            r.topics.len(),
            r.duration_ns() as f64 * 1e-9,
        );
    }
    Ok(())
}
