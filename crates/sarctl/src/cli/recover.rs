//! `sarctl recover FILE [--output OUT]`: rewrites a recording cut short (a
//! crash, a full disk) with its summary and index, up to its last complete
//! chunk; a corrupt chunk on the way is passed over (named: where, how many
//! bytes) and the good chunks after it are kept. Never overwrites the
//! input (compared as files: a hard or symbolic link is the input), and
//! writes a temporary file renamed over the output at the end; the
//! default output is `FILE` with `.recovered.mcap` in place of `.mcap`.
//! Recovering nothing (a file cut before its first complete chunk, a
//! magic-only file) is an error: nothing is left in the output's place,
//! the exit is non-zero.

use sar_record::reader::recover;
use serde_json::json;
use std::path::{Path, PathBuf};

/// The default output beside `input`.
pub fn default_output(input: &Path) -> PathBuf {
    let stem = input
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "recording".to_owned());
    input.with_file_name(format!("{stem}.recovered.mcap"))
}

/// Runs the command; `json` prints one JSON object.
pub fn run(input: &Path, output: Option<&Path>, json: bool) -> Result<(), String> {
    let output = output.map_or_else(|| default_output(input), Path::to_path_buf);
    // (recover refuses an output that is the input by any name, and
    // writes nothing in its place when it recovers nothing.)
    let r = recover(input, &output).map_err(|e| e.to_string())?;
    if r.messages == 0 {
        return Err(format!(
            "{}: recovered nothing: no complete chunk with a message{}",
            input.display(),
            match (&r.stopped, r.skipped.is_empty()) {
                (Some(e), true) => format!(" ({e})"),
                (Some(e), false) => format!(" ({e}; {})", r.skipped.summary()),
                (None, false) => format!(" ({})", r.skipped.summary()),
                (None, true) => " (the file holds none)".to_owned(),
            }
        ));
    }
    let skipped: Vec<String> = r.skipped.shown.iter().map(|s| s.describe()).collect();
    if json {
        println!(
            "{}",
            json!({"input": input.display().to_string(), "output": output.display().to_string(),
                   "messages": r.messages, "channels": r.channels,
                   "input_complete": r.input_complete,
                   "skipped": skipped,
                   "skipped_records": r.skipped.records,
                   "skipped_bytes": r.skipped.bytes,
                   "skipped_parts": r.skipped.parts,
                   "stopped": r.stopped.as_ref().map(ToString::to_string)})
        );
    } else {
        println!(
            "{}: {} messages on {} channels written to {}{}",
            input.display(),
            r.messages,
            r.channels,
            output.display(),
            match &r.stopped {
                Some(e) => format!(" (input cut short: {e})"),
                None if r.skipped.is_empty() => " (input was complete)".to_owned(),
                None => " (input read to its end)".to_owned(),
            }
        );
        for s in &skipped {
            println!("corrupt, passed over (its messages are lost): {s}");
        }
        if !r.skipped.is_empty() {
            println!("{}", r.skipped.summary());
        }
    }
    Ok(())
}
