//! The drivers' configurations made from a checked [`Config`]: the CANopen
//! drives' ([`canopen_drives`]) and the RDT sensor's ([`rdt_sensor`]), and
//! `check`, which runs on them the drivers' own checks
//! (`CanOpenConfig::validate`, `RdtConfig::validate`, what the drivers run
//! at start) while the file is loaded. One conversion for `sard`'s start
//! and for every load (`sard --check-config` included): a configuration
//! that loads is one the drivers take (issue 35: `--check-config` said
//! "valid" for a quick stop of 4.3e15 counts/s^2 the drives refused at
//! start).

use crate::decl::key_of_field;
use crate::keys::{axes, drivers_axes, drivers_sensor, loop_, plausibility};
use crate::toml_file::Ctx;
use crate::{AxesDriver, Config, ConfigError, SensorDriver};
use sar_canopen::{CanOpenConfig, CanOpenError};
use sar_rdt::{RdtConfig, RdtError};

/// The CANopen drives' configuration for `[drivers.axes] kind = "canopen"`:
/// the file's node ids, lead and counts per turn, SYNC at the loop's rate,
/// moves at `[axes] max_speed_mps` within `[axes] travel_m`, the driver's
/// defaults for the rest. With the interface's name; `None` for another kind.
///
/// The drives' own limits (written at start-up, read back; the second
/// channel that still holds when `sard` is wrong), each looser than the
/// check of `sard` that acts first, none looser than safe:
/// - software position limits (0x607D): `[axes] travel_m`, rounded outwards
///   to whole counts (sard refuses targets outside the travel itself);
/// - max profile velocity (0x607F): `[plausibility] max_joint_speed_mps`
///   (the speed sard calls an encoder jump beyond), but at least 1.25 x
///   `[axes] max_speed_mps` and that speed plus two counts per SYNC (the
///   planned moves, rounded to counts, never reach it);
/// - following error window (0x6065): 2 x `[axes] following_tolerance_m`
///   for 10 ms (0x6066); sard's own check is the tolerance, at once;
/// - quick stop deceleration (0x6085, also the profile deceleration 0x6084
///   of the drives' disable-operation and fault-reaction ramps):
///   `[drivers.axes] quick_stop_decel_mps2` (at least `[axes]
///   max_accel_mps2`);
/// - max torque (0x6072): `[drivers.axes] max_torque_permille`.
pub fn canopen_drives(config: &Config) -> Option<(String, CanOpenConfig)> {
    let AxesDriver::Canopen {
        interface,
        node_ids,
        lead_m,
        counts_per_turn,
        quick_stop_decel_mps2,
        max_torque_permille,
    } = &config.axes_driver
    else {
        return None;
    };
    let mut c = CanOpenConfig::new(*node_ids, *lead_m, *counts_per_turn);
    c.sync_period_ns = config.loop_.period_ns;
    // The TPDOs are awaited within half the period (at 4 kHz the driver's
    // 0.5 ms default would outlast the period).
    c.pdo_wait_ns = c.pdo_wait_ns.min(c.sync_period_ns / 2);
    c.poll_interval_ns = c.poll_interval_ns.min(c.pdo_wait_ns);
    c.max_speed_mps = config.axes.max_speed_mps;
    // The same profile as the loop's plan (its following-error reference).
    c.max_accel_mps2 = config.axes.max_accel_mps2;
    c.travel_m = config.axes.travel_m;
    // Above the planned speed by 25 % and by the host's rounding to whole
    // counts (at most one count per SYNC more; 2 allowed).
    let rounding_mps = 2.0 * c.m_per_count() / (c.sync_period_ns as f64 * 1e-9);
    c.drive_max_speed_mps = drive_max_speed_mps(config, rounding_mps);
    c.following_window_m = 2.0 * config.axes.following_tolerance_m;
    c.quick_stop_decel_mps2 = *quick_stop_decel_mps2;
    c.max_torque_permille = *max_torque_permille;
    Some((interface.clone(), c))
}

/// The drives' own velocity limit (CiA 402 0x607F), m/s: `[plausibility]
/// max_joint_speed_mps` (the speed sard calls an encoder jump beyond), but
/// at least 1.25 x `[axes] max_speed_mps` (the margin over the planned and
/// streamed speed for the loop's jitter: a set point streamed early asks
/// the drives for more over what is left of the period, issue 33) and that
/// speed plus `rounding_mps` (a host's rounding to whole counts). The
/// CANopen drives are written it at start ([`canopen_drives`]); `sard
/// --sim`'s simulated drives refuse a streamed set point beyond it.
pub fn drive_max_speed_mps(config: &Config, rounding_mps: f64) -> f64 {
    config
        .estimator
        .plausibility
        .limits()
        .max_joint_speed_mps
        .max(1.25 * config.axes.max_speed_mps)
        .max((config.axes.max_speed_mps + rounding_mps) * (1.0 + 1e-9))
}

/// The RDT driver's configuration for `[drivers.sensor] kind = "rdt"` (an
/// OnRobot sensor with the driver's defaults: 500 Hz, 20 ms silence
/// limit); `None` for another kind.
pub fn rdt_sensor(config: &Config) -> Option<RdtConfig> {
    match config.sensor_driver {
        SensorDriver::Rdt {
            address,
            counts_per_n,
            counts_per_nm,
        } => Some(RdtConfig::new(address, counts_per_n, counts_per_nm)),
        SensorDriver::Sim => None,
    }
}

/// The key of the file a field of the CANopen drives' configuration comes
/// from (a field [`canopen_drives`] sets from another key than its own, or
/// the drives' key of the same name).
fn canopen_key(field: &str) -> &'static str {
    let (a, d) = (&axes::KEY, &drivers_axes::KEY);
    match field {
        "host_node_id" => d.node_ids.key,
        "max_speed_mps" => a.max_speed_mps.key,
        "max_accel_mps2" => a.max_accel_mps2.key,
        "travel_m" => a.travel_m.key,
        "following_window_m" => a.following_tolerance_m.key,
        "drive_max_speed_mps" => plausibility::KEY.max_joint_speed_mps.key,
        "sync_period_ns" | "pdo_wait_ns" | "poll_interval_ns" => loop_::KEY.rate_hz.key,
        other => {
            key_of_field(&[drivers_axes::KEYS], other).map_or(drivers_axes::SECTION, |k| k.key)
        }
    }
}

/// Runs the drivers' own checks on what [`canopen_drives`] and
/// [`rdt_sensor`] make of `config`: the first refusal names the key it
/// comes from, with the drives' units (a scale of 1 m per count, a
/// deceleration beyond the drives' 32 bits).
pub(crate) fn check(ctx: &Ctx<'_>, config: &Config) -> Result<(), ConfigError> {
    if let Some((_, c)) = canopen_drives(config)
        && let Err(e) = c.validate()
    {
        let key = match &e {
            CanOpenError::InvalidConfig { field, .. } => canopen_key(field),
            _ => drivers_axes::SECTION,
        };
        return Err(ctx.err(
            key,
            format!("the CANopen drives would refuse it at start: {e}"),
        ));
    }
    if let Some(r) = rdt_sensor(config)
        && let Err(e) = r.validate()
    {
        let key = match &e {
            RdtError::InvalidConfig { field, .. } => key_of_field(&[drivers_sensor::KEYS], field),
            _ => None,
        }
        .map_or(drivers_sensor::SECTION, |k| k.key);
        return Err(ctx.err(
            key,
            format!("the RDT sensor's driver would refuse it at start: {e}"),
        ));
    }
    Ok(())
}
