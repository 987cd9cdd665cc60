//! `sarctl record start|stop`: starts or stops the daemon's recording (over
//! the command service). The daemon replies once its recorder has acted: a
//! start after the directory's checks (writable, a minute of recording's
//! space free), a stop once the file is closed. A refused start, or a
//! recording that failed (a write error, e.g. a full disk, stops it; its
//! file is incomplete), exits non-zero with the daemon's reason; the file
//! is named as written only when it was closed complete. Then it waits
//! until the published state says the daemon records (or no longer does),
//! at most 2 s. The path is absolute (the daemon resolves `[record]
//! directory` when it starts).

use super::request::command_msg;
use sar_msgs::command::DaemonCommand;
use sar_msgs::wire::{ReplyMsg, StateMsg, recording_code, reply_code, status_name};
use sar_shm::Client;
use serde_json::json;
use std::time::{Duration, Instant};

/// Runs the command; `start` false stops.
pub fn run(client: &Client, start: bool, json: bool) -> Result<(), String> {
    let what = if start { "record start" } else { "record stop" };
    let reply = ask(client, start, what)?;
    // The first file; a rotation continues in -0001.mcap, -0002.mcap, ...
    let path = reply.detail_text().to_owned();
    let s = wait_for_state(client, start, what, reply.cycle)?;
    if json {
        println!(
            "{}",
            json!({"command": what, "recording": start, "cycle": s.cycle,
                   "recorder_drops": s.recorder_drops,
                   "file": (!path.is_empty()).then_some(&path)})
        );
    } else {
        print_text(&s, start, what, &path);
    }
    Ok(())
}

/// Starts the daemon's recording and waits until it records (for another
/// command: nothing printed).
pub fn start(client: &Client) -> Result<(), String> {
    let reply = ask(client, true, "record start")?;
    wait_for_state(client, true, "record start", reply.cycle).map(|_| ())
}

/// Stops the daemon's recording and waits until it no longer records; the
/// recording's first file (empty: none ran).
pub fn stop(client: &Client) -> Result<String, String> {
    let reply = ask(client, false, "record stop")?;
    wait_for_state(client, false, "record stop", reply.cycle)?;
    Ok(reply.detail_text().to_owned())
}

/// Asks the daemon to start (or stop) recording; its answer when it did.
fn ask(client: &Client, start: bool, what: &str) -> Result<ReplyMsg, String> {
    let command = if start {
        DaemonCommand::RecordStart
    } else {
        DaemonCommand::RecordStop
    };
    let reply = client
        .command(
            command_msg(command),
            // The daemon answers once the file is closed (synced to disk).
            sar_shm::RECORD_ANSWER_WAIT + Duration::from_secs(2),
        )
        .map_err(|e| e.to_string())?;
    if reply.status == reply_code::RECORD_FAILED {
        return Err(format!("{what}: {}", reply.detail_text()));
    }
    if reply.status != 0 {
        return Err(format!("{what}: {}", status_name(reply.status)));
    }
    Ok(reply)
}

/// Waits (at most 2 s) until the published state says the daemon records
/// (`start`) or no longer does; that state. A start whose recording failed
/// at once (in a state after `reply_cycle`) is an error naming why.
fn wait_for_state(
    client: &Client,
    start: bool,
    what: &str,
    reply_cycle: u64,
) -> Result<StateMsg, String> {
    let sub = client.subscribe().map_err(|e| e.to_string())?;
    let deadline = Instant::now() + Duration::from_secs(2);
    let mut last = None;
    while Instant::now() < deadline {
        sub.wait(Duration::from_millis(20), |s| last = Some(*s));
        // A recording that failed at once (a full disk) says why, rather
        // than "did not start" (a state of a cycle after the reply: the
        // failure of an earlier recording is cleared before it).
        if start
            && let Some(s) = last
            && s.cycle > reply_cycle
            && recording_code::is_failed(s.recording)
        {
            return Err(format!("{what}: {}", recording_failure(s.recording)));
        }
        if let Some(s) = last
            && recording_code::is_on(s.recording) == start
        {
            return Ok(s);
        }
    }
    Err(format!(
        "{what}: the daemon did not {} within 2 s (see its log)",
        if start {
            "start recording"
        } else {
            "stop recording"
        }
    ))
}

/// The text report of a start (stop) seen in state `s`; `path` is the
/// recording's first file (empty: none).
fn print_text(s: &StateMsg, start: bool, what: &str, path: &str) {
    println!(
        "{what}: {} (cycle {}, {} messages dropped so far)",
        if start { "recording" } else { "stopped" },
        s.cycle,
        s.recorder_drops
    );
    if path.is_empty() && !start {
        println!("(no recording ran)");
    } else if !path.is_empty() {
        println!(
            "{} {path} (after a rotation: -0001.mcap, -0002.mcap, ... beside it)",
            if start { "file:" } else { "written to:" }
        );
    }
}

/// Why the last recording failed: its OS error ("No space left on device
/// (os error 28)"), from `StateMsg::recording`.
pub fn recording_failure(code: u64) -> String {
    match recording_code::errno(code) {
        0 => "a write error (see the daemon's log)".to_owned(),
        e => format!(
            "write error: {}",
            std::io::Error::from_raw_os_error(i32::try_from(e).unwrap_or(i32::MAX))
        ),
    }
}
