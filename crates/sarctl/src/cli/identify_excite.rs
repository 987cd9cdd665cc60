//! `sarctl identify --dynamic --live` (issue 26 section 3): the excitation
//! of `[identify]`'s limits ([`crate::identify::excitation::Plan`]), its
//! condition number and expected accuracy printed (stderr) before anything
//! moves; then, on the running daemon: a move of the tip to the
//! excitation's centre, a recording started, the excitation asked of the
//! loop (`Request::Excite`, which the loop judges and streams, the
//! guard on), followed until it ends at rest, the recording stopped. The
//! recording is then identified offline as `--input` would be.

use super::record;
use super::request::command_msg;
use crate::identify::excitation::Plan;
use sar_config::Config;
use sar_kinematics::{ActiveJoints, forward};
use sar_msgs::command::{ExciteRequest, Request};
use sar_msgs::wire::{StateMsg, guard_code, guard_state_name, reason_name, status_name};
use sar_shm::{Client, StateSubscription};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Joints within this of a target count as arrived, m (an encoder count is
/// about 1 um).
const ARRIVED_M: f64 = 20e-6;

/// Plans the excitation about `centre_m` for a sensor sampling at
/// `sensor_rate_hz` (`identify --sensor-rate-hz`), runs it on the daemon
/// and records it; the recording's (first) file.
pub fn record_excitation(
    config: &Config,
    prefix: &str,
    centre_m: [f64; 3],
    sensor_rate_hz: f64,
) -> Result<PathBuf, String> {
    let plan = Plan::new(config, centre_m, sensor_rate_hz)?;
    eprintln!("identify --dynamic --live: {}", plan.to_text());
    let client = Client::new(prefix).map_err(|e| e.to_string())?;
    let sub = client.subscribe().map_err(|e| e.to_string())?;
    let s = sub
        .latest(Duration::from_secs(2))
        .ok_or("no state from the daemon within 2 s: is sard running (with this --prefix)?")?;
    if s.guard_state != guard_code::OK || !s.drives_enabled() {
        return Err(format!(
            "the guard is {} ({}) and the drives {}: the excitation needs Ok and enabled drives (sarctl reset)",
            guard_state_name(s.guard_state),
            reason_name(s.guard_reason),
            if s.drives_enabled() {
                "enabled"
            } else {
                "not enabled"
            }
        ));
    }
    move_joints_to(
        config,
        (&client, &sub),
        centre_m,
        "the excitation's centre",
        (Duration::ZERO, Duration::from_secs(60)),
    )?;
    record::start(&client)?;
    let ran = excite(&client, &sub, &plan);
    let stopped = record::stop(&client);
    ran?;
    let path = stopped?;
    if path.is_empty() {
        return Err("record stop named no file: the excitation was not recorded".into());
    }
    eprintln!("identify --dynamic --live: recorded in {path}; identifying");
    Ok(PathBuf::from(path))
}

/// Moves the tip to where the joints are `q_m` (its forward kinematics: the
/// loop's inverse kinematics brings the joints there), follows the state for
/// `settle`, then waits at most `within` until the joints are there; `what`
/// names the target in the errors. The one move-to-joints of `identify
/// --dynamic --live` (the excitation's centre) and `identify --servo
/// --live` (each axis's steps).
pub(super) fn move_joints_to(
    config: &Config,
    (client, sub): (&Client, &StateSubscription),
    q_m: [f64; 3],
    what: &str,
    (settle, within): (Duration, Duration),
) -> Result<(), String> {
    let [q1_m, q2_m, q3_m] = q_m;
    let est = &config.estimator;
    let pose = forward(
        &est.calibration,
        &est.profile,
        &ActiveJoints { q1_m, q2_m, q3_m },
    )
    .map_err(|e| format!("{what} ({q_m:?} m) has no pose: {e}"))?;
    let reply = client
        .command(
            command_msg(Request::MoveTip { tip_m: pose.tip_m }),
            Duration::from_secs(2),
        )
        .map_err(|e| e.to_string())?;
    if reply.status != 0 {
        return Err(format!(
            "the move to {what} was refused: {}: {}",
            status_name(reply.status),
            reply.detail_text()
        ));
    }
    let arrived = |s: &StateMsg| {
        s.q_m
            .iter()
            .zip(q_m)
            .all(|(a, b)| (a - b).abs() <= ARRIVED_M)
    };
    if !settle.is_zero() {
        let _ = follow(sub, settle, |_| false)?;
    }
    follow(sub, within, arrived)
        .map_err(|e| format!("on the way to {what}: {e}"))?
        .then_some(())
        .ok_or_else(|| format!("{what} was not reached within {} s", within.as_secs_f64()))
}

/// Asks the loop for the excitation and follows it to its end at rest.
fn excite(client: &Client, sub: &StateSubscription, plan: &Plan) -> Result<(), String> {
    let e = &plan.excitation;
    let request = ExciteRequest {
        amplitude_m: e.amplitude_m,
        freq_hz: e.spec.sines.map(|s| s.freq_hz),
        duration_s: e.spec.duration_s,
        fade_s: e.spec.fade_s,
    };
    let reply = client
        .command(
            command_msg(Request::Excite(request)),
            Duration::from_secs(2),
        )
        .map_err(|e| e.to_string())?;
    if reply.status != 0 {
        return Err(format!(
            "the excitation was refused: {}: {}",
            status_name(reply.status),
            reply.detail_text()
        ));
    }
    eprintln!(
        "identify --dynamic --live: excitation running, {} s",
        e.spec.duration_s
    );
    let end = Instant::now() + Duration::from_secs_f64(e.spec.duration_s);
    // A late cycle of the loop delays the excitation by as much (issue 33:
    // its set points never jump), so it may end later than planned.
    let slack_s = (0.5 * e.spec.duration_s).max(10.0);
    follow(
        sub,
        Duration::from_secs_f64(e.spec.duration_s + slack_s),
        |s| {
            Instant::now() >= end
                && s.q_m
                    .iter()
                    .zip(e.spec.centre_m)
                    .all(|(a, b)| (a - b).abs() <= ARRIVED_M)
        },
    )?
    .then_some(())
    .ok_or_else(|| {
        "the excitation did not end at its centre (braked by a Warn or its limits?)".to_owned()
    })
}

/// Reads the state for at most `duration` until `done` holds (`false`:
/// it did not); a Warn, a Stop or a Fault is an error.
pub(super) fn follow(
    sub: &StateSubscription,
    duration: Duration,
    done: impl Fn(&StateMsg) -> bool,
) -> Result<bool, String> {
    let start = Instant::now();
    while start.elapsed() < duration {
        let mut last = None;
        let mut bad = None;
        sub.wait(Duration::from_millis(20), |s| {
            if s.guard_state != guard_code::OK && bad.is_none() {
                bad = Some(*s);
            }
            last = Some(*s);
        });
        if let Some(s) = bad {
            return Err(format!(
                "the guard went to {} ({}): the motion stopped",
                guard_state_name(s.guard_state),
                reason_name(s.guard_reason)
            ));
        }
        if last.as_ref().is_some_and(&done) {
            return Ok(true);
        }
    }
    Ok(false)
}
