//! `sarctl retreat [--distance D]`: the way back from a Stop. It checks `D`
//! first (0 < D <= `sar_loop::step::MAX_BACK_OUT_M`, as the loop does: a
//! bad distance used to be refused only after the reset had cleared the
//! latched Stop and released the drives), then resets the guard when the
//! daemon is halted (into Retreat while the force persists), waits until
//! the drives are enabled (at most 5 s), then backs the tip out `D` m along
//! the rod at the retreat speed.

use super::request::Daemon;
use sar_msgs::command::Request;
use sar_msgs::wire::{StateMsg, flags, guard_state_name, reason_name};
use sar_shm::StateSubscription;
use std::time::{Duration, Instant};

/// How long the drives may take to come back after the reset.
const DRIVES_WAIT: Duration = Duration::from_secs(5);

/// Runs the command.
pub fn run(daemon: &Daemon<'_>, distance_m: f64) -> Result<(), String> {
    check_distance(distance_m)?;
    let sub = daemon.client.subscribe().map_err(|e| e.to_string())?;
    if latest(&sub, "start")?.flags & flags::HALTED != 0 {
        let r = daemon.send(Request::Reset)?;
        daemon.report("retreat: reset", &r)?;
    }
    let s = wait_for_drives(&sub)?;
    if !daemon.json {
        println!(
            "retreat: guard {} ({}), backing out {distance_m:?} m along the rod",
            guard_state_name(s.guard_state),
            reason_name(s.guard_reason)
        );
    }
    daemon.report(
        "retreat: back out",
        &daemon.send(Request::BackOut { distance_m })?,
    )
}

/// The back-out distance, checked before anything is sent: the loop's own
/// bound (its refusal came after the reset); the value echoed as typed, in
/// its shortest form (`1e-320`, never 320 digits).
pub fn check_distance(distance_m: f64) -> Result<(), String> {
    let max = sar_loop::step::MAX_BACK_OUT_M;
    if distance_m > 0.0 && distance_m <= max {
        Ok(())
    } else {
        Err(format!(
            "retreat: --distance must be within 0 < d <= {max:?} m, got {distance_m:?} m (nothing was sent: the guard and the drives are as they were)"
        ))
    }
}

/// The daemon's latest state; `what` names the step that waited for it.
fn latest(sub: &StateSubscription, what: &str) -> Result<StateMsg, String> {
    sub.latest(Duration::from_secs(2))
        .ok_or_else(|| format!("retreat: the daemon published nothing within 2 s ({what})"))
}

/// Waits until the drives are enabled and the daemon not halted (they come
/// back within a few cycles after the reset); that state.
fn wait_for_drives(sub: &StateSubscription) -> Result<StateMsg, String> {
    let deadline = Instant::now() + DRIVES_WAIT;
    loop {
        let s = latest(sub, "waiting for the drives")?;
        if s.drives_enabled() && s.flags & flags::HALTED == 0 {
            return Ok(s);
        }
        if Instant::now() > deadline {
            return Err(format!(
                "retreat: the drives are not enabled after 5 s (guard {}: {})",
                guard_state_name(s.guard_state),
                reason_name(s.guard_reason)
            ));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The distances the loop refuses are refused here, before the reset,
    /// in one short line.
    #[test]
    fn a_bad_distance_is_refused_before_anything_is_sent() {
        for bad in [0.5, 0.0, -0.01, f64::NAN, f64::INFINITY, 1e300] {
            let e = check_distance(bad).err().unwrap_or_default();
            assert!(
                e.starts_with("retreat: --distance must be within 0 < d <= 0.1 m"),
                "{bad}: {e}"
            );
            assert!(e.len() < 200, "{e}");
        }
        let e = check_distance(-1e-320).err().unwrap_or_default();
        assert!(e.contains("got -1e-320 m"), "{e}");
        for good in [0.01, 0.1, 1e-320] {
            assert_eq!(check_distance(good), Ok(()), "{good}");
        }
    }
}
