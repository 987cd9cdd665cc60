//! A request to the daemon's command service and its answer printed
//! ([`Daemon`]), and the subcommands that are one such request: `tare`,
//! `hold`, `push`, `position` and `move-tip`. An accepted request prints
//! `WHAT: STATUS (cycle N)` (`--format json`: one object); a refused one
//! exits non-zero with the daemon's cause.

use sar_msgs::wire::{CommandMsg, ReplyMsg, command_kind, reason_name, status_name};
use sar_shm::Client;
use serde_json::json;
use std::time::Duration;

/// How long a request waits for the daemon's answer.
const ANSWER_WAIT: Duration = Duration::from_secs(2);

/// A command of this process: `kind` with its target and limits.
pub fn command_msg(kind: u32, tip_m: [f64; 3], limits_n: [f64; 6]) -> CommandMsg {
    CommandMsg {
        kind,
        reserved: 0,
        id: u64::from(std::process::id()),
        tip_m,
        limits_n,
    }
}

/// The wire's `limits_n` of a command that carries one force (hold, push,
/// a guarded move): the force first, the rest zero.
pub fn one_force(force_n: f64) -> [f64; 6] {
    [force_n, 0.0, 0.0, 0.0, 0.0, 0.0]
}

/// The daemon's command service, as `sarctl` asks it.
#[derive(Clone, Copy)]
pub struct Daemon<'a> {
    /// The client of the daemon.
    pub client: &'a Client,
    /// `--format json`: one JSON object per answer.
    pub json: bool,
}

impl Daemon<'_> {
    /// Sends `kind` with its target and limits; the daemon's answer.
    pub fn send(&self, kind: u32, tip_m: [f64; 3], limits_n: [f64; 6]) -> Result<ReplyMsg, String> {
        self.client
            .command(command_msg(kind, tip_m, limits_n), ANSWER_WAIT)
            .map_err(|e| e.to_string())
    }

    /// Sends `kind` with a target only.
    pub fn send_tip(&self, kind: u32, tip_m: [f64; 3]) -> Result<ReplyMsg, String> {
        self.send(kind, tip_m, [0.0; 6])
    }

    /// Prints the answer `r` to `what`; `Err` (the daemon's cause) when it
    /// was refused.
    pub fn report(&self, what: &str, r: &ReplyMsg) -> Result<(), String> {
        let accepted = r.status == 0 || r.status == 1;
        if self.json {
            println!(
                "{}",
                json!({"command": what, "accepted": accepted, "status": status_name(r.status),
                       "status_code": r.status, "reason": reason_name(r.reason),
                       "reason_code": r.reason, "detail": r.detail_text(), "cycle": r.cycle})
            );
        } else if accepted {
            println!("{what}: {} (cycle {})", status_name(r.status), r.cycle);
        }
        if accepted {
            Ok(())
        } else {
            // The daemon's exact cause when it gave one, else the reason's name.
            let detail = match r.detail_text() {
                "" => reason_name(r.reason).to_owned(),
                d => d.to_owned(),
            };
            Err(format!("{what}: {}: {detail}", status_name(r.status)))
        }
    }

    /// Sends `kind` and prints its answer as `what`.
    pub fn request(
        &self,
        what: &str,
        kind: u32,
        tip_m: [f64; 3],
        limits_n: [f64; 6],
    ) -> Result<(), String> {
        self.report(what, &self.send(kind, tip_m, limits_n)?)
    }
}

/// `sarctl tare`: the model-based tare of the force sensor.
pub fn tare(daemon: &Daemon<'_>) -> Result<(), String> {
    daemon.request("tare", command_kind::TARE, [0.0; 3], [0.0; 6])
}

/// `sarctl hold --max-force N`: force control holding the tip below N.
pub fn hold(daemon: &Daemon<'_>, max_force_n: f64) -> Result<(), String> {
    daemon.request("hold", command_kind::HOLD, [0.0; 3], one_force(max_force_n))
}

/// `sarctl push --axial N`: force control regulating the axial force to N.
pub fn push(daemon: &Daemon<'_>, axial_n: f64) -> Result<(), String> {
    daemon.request("push", command_kind::PUSH, [0.0; 3], one_force(axial_n))
}

/// `sarctl position`: the end of force control.
pub fn position(daemon: &Daemon<'_>) -> Result<(), String> {
    daemon.request("position", command_kind::POSITION, [0.0; 3], [0.0; 6])
}

/// `sarctl move-tip X Y Z [--max-force N]`: a move of the tip, guarded
/// when `max_force_n` is given.
pub fn move_tip(
    daemon: &Daemon<'_>,
    tip_m: [f64; 3],
    max_force_n: Option<f64>,
) -> Result<(), String> {
    match max_force_n {
        None => daemon.request("move-tip", command_kind::MOVE_TIP, tip_m, [0.0; 6]),
        Some(n) => daemon.request(
            "move-tip (guarded)",
            command_kind::GUARDED_MOVE,
            tip_m,
            one_force(n),
        ),
    }
}
