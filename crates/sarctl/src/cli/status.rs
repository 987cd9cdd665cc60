//! `sarctl status`: the daemon's latest state, one line of text
//! ([`state_line`]) or one JSON object ([`state_json`], also `monitor`'s
//! lines); no state within 2 s is an error.

use sar_msgs::wire::{self, StateMsg, flags, guard_state_name, reason_name, recording_code};
use sar_shm::Client;
use serde_json::json;
use std::time::Duration;

/// Runs the command; `json` prints one JSON object.
pub fn run(client: &Client, json: bool) -> Result<(), String> {
    let sub = client.subscribe().map_err(|e| e.to_string())?;
    let s = sub
        .latest(Duration::from_secs(2))
        .ok_or("the daemon published nothing within 2 s")?;
    if json {
        println!("{}", state_json(&s));
    } else {
        println!("{}", state_line(&s));
    }
    Ok(())
}

/// The state as one JSON object (`status` and `monitor` with `--format json`).
pub fn state_json(s: &StateMsg) -> serde_json::Value {
    json!({
        "cycle": s.cycle,
        "now_ns": s.now_ns,
        "sensor_age_ns": (s.sensor_age_ns != u64::MAX).then_some(s.sensor_age_ns),
        "joints_age_ns": (s.joints_age_ns != u64::MAX).then_some(s.joints_age_ns),
        "q_m": s.q_m,
        "q45_rad": (s.flags & flags::POSE != 0).then_some(s.q45_rad),
        "ujoint_m": (s.flags & flags::POSE != 0).then_some(s.ujoint_m),
        "tip_m": (s.flags & flags::POSE != 0).then_some(s.tip_m),
        "support_distance_m": (s.flags & flags::POSE != 0).then_some(s.support_distance_m),
        "ujoint_force_n": (s.flags & flags::ESTIMATE != 0).then_some(s.ujoint_force_n),
        "tip_force_n": (s.flags & flags::ESTIMATE != 0).then_some(s.tip_force_n),
        "tip_std_n": (s.flags & flags::ESTIMATE != 0).then_some(s.tip_std_n),
        "observable": s.flags & flags::OBSERVABLE != 0,
        "truth_tip_force_n": (s.flags & flags::SIM_TRUTH != 0).then_some(s.truth_tip_force_n),
        "sim_elapsed_ns": (s.flags & flags::SIM_TRUTH != 0).then_some(s.truth_elapsed_ns),
        "force_mode": wire::force_mode::name(s.force_mode),
        "force_setpoint_n": (s.force_mode != wire::force_mode::POSITION).then_some(s.force_setpoint_n),
        "guarded_stop": (s.guarded_stop_cycle != 0).then(|| json!({
            "cycle": s.guarded_stop_cycle,
            "tip_m": s.guarded_stop_tip_m,
            "force_n": s.guarded_stop_force_n,
        })),
        "guard": guard_state_name(s.guard_state),
        "reason": reason_name(s.guard_reason),
        "reason_code": s.guard_reason,
        "halted": s.flags & flags::HALTED != 0,
        "drive_state": s.drive_state,
        "drive_state_name": wire::drive_state_name(s.drive_state),
        "limits_n": s.limits_n,
        "limits": super::limits::limits_json(&s.limits_n),
        "wakeup_ns": {"p50": s.wakeup_ns[0], "p99": s.wakeup_ns[1], "max": s.wakeup_ns[2]},
        "compute_ns": {"p50": s.compute_ns[0], "p99": s.compute_ns[1], "max": s.compute_ns[2]},
        "overruns": s.overruns,
        "quick_stops": s.quick_stops,
        "publish_queue_drops": s.publish_queue_drops,
        "publish_errors": s.publish_errors,
        "recording": recording_code::is_on(s.recording),
        "recording_failed": recording_code::is_failed(s.recording)
            .then(|| super::record::recording_failure(s.recording)),
        "recorder_drops": s.recorder_drops,
    })
}

/// The state as one line of text (`status`, `monitor`).
pub fn state_line(s: &StateMsg) -> String {
    let f = s.tip_force_n;
    let norm = s.tip_force_norm_n();
    let force = if s.flags & flags::ESTIMATE != 0 {
        format!(
            "F_tip [{:+7.2} {:+7.2} {:+7.2}] N |F| {:6.2} N (std {:.2})",
            f[0],
            f[1],
            f[2],
            norm,
            s.tip_std_n.iter().fold(0.0f64, |a, b| a.max(*b))
        )
    } else {
        "F_tip -- (no estimate)".to_owned()
    };
    format!(
        "cycle {:>8}  {force}  guard {:5} ({})  latency p99 {} us, {} overruns{}",
        s.cycle,
        guard_state_name(s.guard_state),
        reason_name(s.guard_reason),
        s.wakeup_ns[1] / 1000,
        s.overruns,
        if s.recording != 0 || s.recorder_drops != 0 {
            format!(
                ", recording {}, {} dropped",
                match recording_code::state(s.recording) {
                    recording_code::ON => "on".to_owned(),
                    recording_code::FAILED => format!(
                        "FAILED ({}; its file is incomplete)",
                        super::record::recording_failure(s.recording)
                    ),
                    _ => "off".to_owned(),
                },
                s.recorder_drops
            )
        } else {
            String::new()
        }
    )
}
