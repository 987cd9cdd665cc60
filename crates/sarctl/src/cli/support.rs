//! `sarctl support status|check|confirm` (issue 34 section 3): the support
//! point B as the daemon's support watch sees it. `status` prints the
//! published estimate (the shift per base axis with its standard error, or
//! "not determined", and the verdict); `check` moves the tip through the
//! short pose sequence `sar_loop::step::SUPPORT_CHECK_OFFSETS_M` about where
//! it is (plain moves, within the limits and recorded as any move; the tip
//! must be free: the daemon uses only samples whose tip force is small and
//! says when the forces do not follow the poses as a shift would), back to
//! the start, then prints the result; `confirm` tells the daemon the
//! support is as it is now (a named shift no longer refuses force
//! control). `check` exits non-zero when the support is shifted beyond the
//! limit or the check could not run.

use super::request::Daemon;
use sar_loop::step::{SUPPORT_CHECK_OFFSETS_M, SUPPORT_CHECK_ROUNDS};
use sar_msgs::command::Request;
use sar_msgs::wire::{StateMsg, flags, force_mode, guard_code, guard_state_name};
use sar_shm::StateSubscription;
use serde_json::json;
use std::time::{Duration, Instant};

/// The longest a move of the check may take, s.
const MOVE_WAIT: Duration = Duration::from_secs(20);
/// How close the tip must come to each pose, m.
const AT_POSE_M: f64 = 5e-4;
/// The wait at each pose once there.
const SETTLE: Duration = Duration::from_millis(300);

/// What `sarctl support` does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SupportAction {
    /// The support watch's estimate now.
    Status,
    /// The pose sequence, then the estimate.
    Check,
    /// The support is as it is now: a named shift acknowledged.
    Confirm,
}

/// Runs the command.
pub fn run(daemon: &Daemon<'_>, action: SupportAction) -> Result<(), String> {
    match action {
        SupportAction::Confirm => daemon.request("support confirm", Request::SupportConfirm),
        SupportAction::Status => {
            let sub = daemon.client.subscribe().map_err(|e| e.to_string())?;
            print_status(daemon.json, "support", &latest(&sub)?);
            Ok(())
        }
        SupportAction::Check => check(daemon),
    }
}

/// The pose sequence and its result.
fn check(daemon: &Daemon<'_>) -> Result<(), String> {
    let sub = daemon.client.subscribe().map_err(|e| e.to_string())?;
    let start = latest(&sub)?;
    ready(&start)?;
    let home = start.tip_m;
    for _ in 0..SUPPORT_CHECK_ROUNDS {
        for off in SUPPORT_CHECK_OFFSETS_M {
            let target = [home[0] + off[0], home[1] + off[1], home[2] + off[2]];
            let r = daemon.send(Request::MoveTip {
                tip_m: target.into(),
            })?;
            if r.status != 0 {
                return Err(format!(
                    "support check: a move of the sequence was refused ({}): {}; the check did not run",
                    sar_msgs::wire::status_name(r.status),
                    r.detail_text()
                ));
            }
            wait_at(&sub, target)?;
        }
    }
    let s = latest(&sub)?;
    print_status(daemon.json, "support check", &s);
    match s.support_verdict {
        3 => Err("support check: the support has shifted beyond its limit; re-calibrate (sarctl identify) or confirm (sarctl support confirm) before force control".into()),
        0 | 1 => Err(format!(
            "support check: {}",
            verdict_words(s.support_verdict)
        )),
        _ => Ok(()),
    }
}

/// The daemon's latest state.
fn latest(sub: &StateSubscription) -> Result<StateMsg, String> {
    sub.latest(Duration::from_secs(2))
        .ok_or_else(|| "support: the daemon published nothing within 2 s".to_owned())
}

/// The check starts only in Ok, the drives enabled, in position control.
fn ready(s: &StateMsg) -> Result<(), String> {
    if s.guard_state != guard_code::OK || s.flags & flags::HALTED != 0 {
        return Err(format!(
            "support check: the guard is {}, not ok; nothing was moved",
            guard_state_name(s.guard_state)
        ));
    }
    if !s.drives_enabled() {
        return Err("support check: the drives are not enabled; nothing was moved".into());
    }
    if s.force_mode != force_mode::POSITION {
        return Err(
            "support check: force control runs (sarctl position first: the tip must be free); nothing was moved"
                .into(),
        );
    }
    Ok(())
}

/// Waits until the tip is at `target` (then [`SETTLE`] more); an error when
/// the guard leaves Ok or the move takes longer than [`MOVE_WAIT`].
fn wait_at(sub: &StateSubscription, target: [f64; 3]) -> Result<(), String> {
    let deadline = Instant::now() + MOVE_WAIT;
    loop {
        let s = latest(sub)?;
        if s.guard_state != guard_code::OK {
            return Err(format!(
                "support check: the guard left ok ({}) during the sequence; the check did not finish",
                guard_state_name(s.guard_state)
            ));
        }
        let d: f64 = s
            .tip_m
            .iter()
            .zip(target)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt();
        if d < AT_POSE_M {
            std::thread::sleep(SETTLE);
            return Ok(());
        }
        if Instant::now() > deadline {
            return Err(format!(
                "support check: the tip did not reach a pose of the sequence within {} s",
                MOVE_WAIT.as_secs()
            ));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The published verdict in words.
pub fn verdict_words(code: u32) -> &'static str {
    match code {
        0 => "not run (too few poses with the tip free)",
        1 => {
            "could not run: the tip force does not follow the poses as a support shift's would (a contact?)"
        }
        2 => "within the limit",
        3 => "SHIFTED beyond the limit (force control refused until confirmed or re-calibrated)",
        _ => "unknown",
    }
}

/// One axis: "+1.23 +- 0.05 mm", or "not determined".
fn axis_text(shift_m: f64, std_m: f64, max_std_m: f64) -> String {
    if std_m <= max_std_m {
        format!("{:+.2} +- {:.2} mm", shift_m * 1e3, std_m * 1e3)
    } else {
        "not determined".into()
    }
}

/// Prints the published support estimate.
fn print_status(json: bool, what: &str, s: &StateMsg) {
    let [max_shift_m, max_std_m] = s.support_limits_m;
    if json {
        println!(
            "{}",
            json!({"command": what, "verdict": verdict_words(s.support_verdict),
                   "verdict_code": s.support_verdict, "shift_m": s.support_shift_m,
                   "std_m": s.support_std_m, "max_shift_m": max_shift_m,
                   "max_std_m": max_std_m, "chi2_dof": s.support_chi2_dof,
                   "samples": s.support_samples})
        );
        return;
    }
    let axes: Vec<String> = ["X0", "Y0", "Z0"]
        .iter()
        .zip(s.support_shift_m.iter().zip(s.support_std_m))
        .map(|(name, (v, sd))| format!("{name} {}", axis_text(*v, sd, max_std_m)))
        .collect();
    println!(
        "{what}: {}; shift of B {} (limit {:.1} mm; chi2/dof {:.2}, {:.0} free samples)",
        verdict_words(s.support_verdict),
        axes.join(", "),
        max_shift_m * 1e3,
        s.support_chi2_dof,
        s.support_samples
    );
}
