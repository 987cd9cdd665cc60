//! `sarctl recover FILE [--output OUT]`: rewrites a recording cut short (a
//! crash, a full disk) with its summary and index, up to its last complete
//! chunk. Never overwrites the input; the default output is `FILE` with
//! `.recovered.mcap` in place of `.mcap`.

use sar_record::reader::recover;
use sar_record::replay::same_file;
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
    if output == input || same_file(input, &output) {
        return Err(format!(
            "{}: refusing to overwrite the input; give another --output",
            output.display()
        ));
    }
    let r = recover(input, &output).map_err(|e| e.to_string())?;
    if json {
        println!(
            "{}",
            json!({"input": input.display().to_string(), "output": output.display().to_string(),
                   "messages": r.messages, "channels": r.channels,
                   "input_complete": r.input_complete,
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
                None => " (input was complete)".to_owned(),
            }
        );
    }
    Ok(())
}
