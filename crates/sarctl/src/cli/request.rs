//! A request to the daemon's command service and its answer printed
//! ([`Daemon`]), and the subcommands that are one such request: `tare`,
//! `hold`, `push`, `position` and `move-tip`. An accepted request prints
//! `WHAT: STATUS (cycle N)` (`--format json`: one object); a refused one
//! exits non-zero with the daemon's cause.

use sar_estimator::Vec3;
use sar_msgs::command::{Request, WireCommand};
use sar_msgs::wire::{CommandMsg, ReplyMsg, reason_name, status_name};
use sar_shm::Client;
use serde_json::json;
use std::time::Duration;

/// How long a request waits for the daemon's answer.
const ANSWER_WAIT: Duration = Duration::from_secs(2);

/// A command of this process on the wire (the command table's encoder,
/// `sar_msgs::command`), its id this process's.
pub fn command_msg(command: impl Into<WireCommand>) -> CommandMsg {
    command.into().to_wire(u64::from(std::process::id()))
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
    /// Sends `command`; the daemon's answer.
    pub fn send(&self, command: impl Into<WireCommand>) -> Result<ReplyMsg, String> {
        self.client
            .command(command_msg(command), ANSWER_WAIT)
            .map_err(|e| e.to_string())
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

    /// Sends `command` and prints its answer as `what`.
    pub fn request(&self, what: &str, command: impl Into<WireCommand>) -> Result<(), String> {
        self.report(what, &self.send(command)?)
    }
}

/// `sarctl tare`: the model-based tare of the force sensor.
pub fn tare(daemon: &Daemon<'_>) -> Result<(), String> {
    daemon.request("tare", Request::Tare)
}

/// `sarctl hold --max-force N`: force control holding the tip below N.
pub fn hold(daemon: &Daemon<'_>, max_force_n: f64) -> Result<(), String> {
    daemon.request("hold", Request::Hold { max_force_n })
}

/// `sarctl push --axial N`: force control regulating the axial force to N.
pub fn push(daemon: &Daemon<'_>, axial_n: f64) -> Result<(), String> {
    daemon.request("push", Request::Push { axial_n })
}

/// `sarctl position`: the end of force control.
pub fn position(daemon: &Daemon<'_>) -> Result<(), String> {
    daemon.request("position", Request::Position)
}

/// `sarctl move-tip X Y Z [--max-force N]`: a move of the tip, guarded
/// when `max_force_n` is given.
pub fn move_tip(
    daemon: &Daemon<'_>,
    [x, y, z]: [f64; 3],
    max_force_n: Option<f64>,
) -> Result<(), String> {
    let tip_m = Vec3::new(x, y, z);
    match max_force_n {
        None => daemon.request("move-tip", Request::MoveTip { tip_m }),
        Some(max_force_n) => daemon.request(
            "move-tip (guarded)",
            Request::GuardedMove { tip_m, max_force_n },
        ),
    }
}
