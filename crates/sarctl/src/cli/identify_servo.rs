//! `sarctl identify --servo` (issue 34 section 1): the drives' position loop
//! as measured. `--input REC` fits a recording ([`crate::identify::servo`]);
//! `--live` first makes one on the running daemon: from where the axes
//! rest, each axis alone moves [`STEP_M`] out and back [`REPEATS`] times
//! (a move-tip to the forward kinematics of the joints with that axis
//! stepped: the loop's inverse kinematics moves that axis alone, at the
//! configured speed and acceleration, within the travel: the step is taken
//! inward where outward would leave it), each move given its planned time
//! and [`SETTLE_S`] to settle, the whole recorded (`record start`/`stop`,
//! replayable like any recording). The fit then writes `[axes]
//! servo_bandwidth_hz`, `servo_damping` and `servo_delay_s` back (unless
//! `--dry-run`).

use super::identify_excite::move_joints_to;
use super::record;
use crate::identify::servo::{self, ServoResult};
use sar_config::Config;
use sar_msgs::wire::{guard_code, guard_state_name, reason_name};
use sar_shm::Client;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Each axis's step, m: short moves (at the built-in 0.2 m/s^2 a
/// triangular profile of 0.2 s, whose acceleration jumps by twice the
/// limit at its middle) excite the servo more per second than long ones.
pub const STEP_M: f64 = 0.002;

/// Out-and-back moves per axis.
pub const REPEATS: usize = 3;

/// Time left to settle after each move's planned end, s (the slowest servo
/// the fit is meant for, 5 Hz at damping 0.3, settles to 1 % in about 0.5
/// s; 12 Hz, 0.45: 0.14 s).
pub const SETTLE_S: f64 = 0.15;

/// The cycles given to each move with the built-in configuration (0.2 s
/// planned, [`SETTLE_S`]), for the tests that replay the procedure.
pub const MOVE_S_DEFAULT_MS: u64 = 350;

/// The planned time of a move of `distance_m` at the configuration's
/// speed and acceleration (trapezoid or triangle), s.
pub fn move_s(config: &Config, distance_m: f64) -> f64 {
    let (v, a) = (config.axes.max_speed_mps, config.axes.max_accel_mps2);
    if distance_m * a <= v * v {
        2.0 * (distance_m / a).sqrt()
    } else {
        distance_m / v + v / a
    }
}

/// The joints of each move of the procedure from `q0_m`: every axis in
/// turn, [`REPEATS`] times out by [`STEP_M`] (inward where outward would
/// leave the travel) and back.
pub fn targets(config: &Config, q0_m: [f64; 3]) -> Vec<[f64; 3]> {
    let mut out = Vec::new();
    for (axis, (lo, hi)) in config.axes.travel_m.iter().enumerate() {
        let mut step = q0_m;
        if let Some(q) = step.get_mut(axis) {
            *q += if *q + STEP_M <= *hi || *q - STEP_M < *lo {
                STEP_M
            } else {
                -STEP_M
            };
        }
        for _ in 0..REPEATS {
            out.push(step);
            out.push(q0_m);
        }
    }
    out
}

/// `identify --servo`: fits `--input` (or the recording `--live` makes).
pub fn identify(
    config: &Config,
    prefix: &str,
    input: Option<&Path>,
) -> Result<ServoResult, String> {
    let input = match input {
        Some(p) => p.to_path_buf(),
        None => record_moves(config, prefix)?,
    };
    servo::identify_file(&input).map_err(|e| format!("{}: {e}", input.display()))
}

/// Runs the moves on the daemon and records them; the recording's file.
fn record_moves(config: &Config, prefix: &str) -> Result<PathBuf, String> {
    let client = Client::new(prefix).map_err(|e| e.to_string())?;
    let sub = client.subscribe().map_err(|e| e.to_string())?;
    let s = sub
        .latest(Duration::from_secs(2))
        .ok_or("no state from the daemon within 2 s: is sard running (with this --prefix)?")?;
    if s.guard_state != guard_code::OK || !s.drives_enabled() {
        return Err(format!(
            "the guard is {} ({}) and the drives {}: identify --servo needs Ok and enabled drives (sarctl reset)",
            guard_state_name(s.guard_state),
            reason_name(s.guard_reason),
            if s.drives_enabled() {
                "enabled"
            } else {
                "not enabled"
            }
        ));
    }
    let moves = targets(config, s.q_m);
    let each_s = move_s(config, STEP_M) + SETTLE_S;
    eprintln!(
        "identify --servo --live: {} moves of {} mm (each axis alone, out and back), about {:.0} s",
        moves.len(),
        STEP_M * 1e3,
        moves.len() as f64 * each_s
    );
    record::start(&client)?;
    let ran = moves.iter().try_for_each(|q| {
        let what = format!("the joints {q:?} m");
        let times = (Duration::from_secs_f64(each_s), Duration::from_secs(5));
        move_joints_to(config, (&client, &sub), *q, &what, times)
    });
    let stopped = record::stop(&client);
    ran?;
    let path = stopped?;
    if path.is_empty() {
        return Err("record stop named no file: the moves were not recorded".into());
    }
    eprintln!("identify --servo --live: recorded in {path}; fitting");
    Ok(PathBuf::from(path))
}
