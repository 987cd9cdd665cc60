//! `sarctl reset`: leaves Stop or Fault. Faulted drives are reset first (the
//! daemon answers "drives fault reset" and is asked again, at most 10 times
//! 100 ms apart), then the guard's reset.

use super::request::Daemon;
use sar_msgs::command::Request;
use std::time::Duration;

/// Resets again after a drives' fault reset, at most this many times.
const DRIVE_RESETS: usize = 10;

/// Runs the command.
pub fn run(daemon: &Daemon<'_>) -> Result<(), String> {
    let mut r = daemon.send(Request::Reset)?;
    for _ in 0..DRIVE_RESETS {
        if r.status != sar_msgs::wire::ReplyStatus::DrivesFaultReset as u32 {
            break;
        }
        std::thread::sleep(Duration::from_millis(100));
        r = daemon.send(Request::Reset)?;
    }
    daemon.report("reset", &r)
}
