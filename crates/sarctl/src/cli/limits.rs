//! `sarctl limits [--warn-total N] [--stop-total N] ...`: the guard's force
//! limits; with any `--warn-*`/`--stop-*` option it sets them (the others
//! kept; the daemon holds them within the configuration's ceilings), then
//! prints the limits in force (`--format json`: by name).

use super::request::Daemon;
use sar_estimator::guard::ForceLimits;
use sar_msgs::command::{DaemonCommand, Request};
use sar_msgs::wire::status_name;
use serde_json::json;

/// The options of `sarctl limits`: one per force limit, named after
/// [`ForceLimits::NAMES`] (without `_n`, `-` for `_`; checked by a test).
#[derive(clap::Args, Debug, Clone, Copy, PartialEq)]
pub struct LimitOptions {
    /// Warn limit on |F_tip|, N.
    #[arg(long)]
    warn_total: Option<f64>,
    /// Stop limit on |F_tip|, N.
    #[arg(long)]
    stop_total: Option<f64>,
    /// Warn limit on the axial part, N.
    #[arg(long)]
    warn_axial: Option<f64>,
    /// Stop limit on the axial part, N.
    #[arg(long)]
    stop_axial: Option<f64>,
    /// Warn limit on the lateral part, N.
    #[arg(long)]
    warn_lateral: Option<f64>,
    /// Stop limit on the lateral part, N.
    #[arg(long)]
    stop_lateral: Option<f64>,
}

impl LimitOptions {
    /// The wanted limits in the order of [`ForceLimits::to_array`] (the
    /// wire's `limits_n`); `None` keeps the one in force.
    pub fn wanted(&self) -> [Option<f64>; 6] {
        [
            self.warn_total,
            self.stop_total,
            self.warn_axial,
            self.stop_axial,
            self.warn_lateral,
            self.stop_lateral,
        ]
    }
}

/// The guard's six force limits by name ([`ForceLimits::NAMES`], the order
/// of `limits_n`).
pub fn limits_json(l: &[f64; 6]) -> serde_json::Value {
    let fields = ForceLimits::NAMES
        .iter()
        .zip(l)
        .map(|(name, v)| ((*name).to_owned(), json!(v)));
    serde_json::Value::Object(fields.collect())
}

/// Runs the command.
pub fn run(daemon: &Daemon<'_>, set: &LimitOptions) -> Result<(), String> {
    let mut limits_n = daemon.send(DaemonCommand::Limits)?.limits_n;
    let wanted = set.wanted();
    if wanted.iter().any(Option::is_some) {
        limits_n = set_limits(daemon, limits_n, wanted)?;
    }
    if daemon.json {
        println!("{}", limits_json(&limits_n));
    } else {
        println!("{}", ForceLimits::from_array(limits_n));
    }
    Ok(())
}

/// Sets the `wanted` limits (`None`: the one in `in_force_n` kept); the
/// limits in force afterwards, as the daemon answers them.
fn set_limits(
    daemon: &Daemon<'_>,
    in_force_n: [f64; 6],
    wanted: [Option<f64>; 6],
) -> Result<[f64; 6], String> {
    let mut limits_n = in_force_n;
    for (slot, value) in limits_n.iter_mut().zip(wanted) {
        if let Some(v) = value {
            *slot = v;
        }
    }
    let r = daemon.send(Request::SetLimits(ForceLimits::from_array(limits_n)))?;
    if r.status != 0 {
        return Err(format!(
            "limits: {}: {}",
            status_name(r.status),
            r.detail_text()
        ));
    }
    Ok(daemon.send(DaemonCommand::Limits)?.limits_n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_limits_json_and_text_name_the_six_in_wire_order() {
        let l = [1.0, 2.0, 3.5, 4.0, 5.0, 6.25];
        assert_eq!(
            limits_json(&l),
            json!({"warn_total_n": 1.0, "stop_total_n": 2.0, "warn_axial_n": 3.5,
                   "stop_axial_n": 4.0, "warn_lateral_n": 5.0, "stop_lateral_n": 6.25})
        );
        assert_eq!(
            ForceLimits::from_array(l).to_string(),
            "warn/stop total 1/2 N, axial 3.5/4 N, lateral 5/6.25 N"
        );
    }
}
