//! The real devices the configuration names (`[drivers.sensor]`,
//! `[drivers.axes]`, INTERFACES.md 2): their driver configurations made from
//! the daemon's, their start with one-line reasons that name the device, and
//! the per-cycle hook of the CANopen drives ([`canopen_cycle`]), which the
//! controller calls once per period in its gather phase.

use sar_config::{AxesDriver, Config, SensorDriver};
use sar_drivers::canopen::{CanOpenConfig, CanOpenDrives};
use sar_drivers::rdt::{RdtConfig, RdtSensor};
use sar_drivers::{AxisDrives, Clock, DriveState, ForceSensor};

/// The RDT driver's configuration for `[drivers.sensor] kind = "rdt"` (an
/// OnRobot sensor with the driver's defaults: 500 Hz, 20 ms silence limit);
/// `None` for another kind.
pub fn rdt_config(config: &Config) -> Option<RdtConfig> {
    match config.sensor_driver {
        SensorDriver::Rdt {
            address,
            counts_per_n,
            counts_per_nm,
        } => Some(RdtConfig::new(address, counts_per_n, counts_per_nm)),
        _ => None,
    }
}

/// Connects the RDT sensor; the error names the sensor's address.
pub fn connect_rdt(config: RdtConfig) -> Result<RdtSensor, String> {
    RdtSensor::connect(config).map_err(|e| format!("RDT sensor at {}: {e}", config.address))
}

/// Waits at most `timeout_ns` for the sensor's first sample: a sensor that is
/// off, unplugged or streaming elsewhere is refused at start (the error
/// names its address) rather than found by the guard.
pub fn first_sample(sensor: &mut RdtSensor, timeout_ns: u64) -> Result<(), String> {
    sensor.wait(timeout_ns).map(|_| ()).map_err(|e| {
        format!(
            "RDT sensor at {}: no sample within {} ms ({e}); is it on, and streaming to this host?",
            sensor.config().address,
            timeout_ns / 1_000_000
        )
    })
}

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
/// - quick stop deceleration (0x6085): `[drivers.axes]
///   quick_stop_decel_mps2` (at least `[axes] max_accel_mps2`);
/// - max torque (0x6072): `[drivers.axes] max_torque_permille`.
pub fn canopen_config(config: &Config) -> Option<(String, CanOpenConfig)> {
    match &config.axes_driver {
        AxesDriver::Canopen {
            interface,
            node_ids,
            lead_m,
            counts_per_turn,
            quick_stop_decel_mps2,
            max_torque_permille,
        } => {
            let mut c = CanOpenConfig::new(*node_ids, *lead_m, *counts_per_turn);
            c.sync_period_ns = config.loop_.period_ns;
            // The TPDOs are awaited within half the period (at 4 kHz the
            // driver's 0.5 ms default would outlast the period).
            c.pdo_wait_ns = c.pdo_wait_ns.min(c.sync_period_ns / 2);
            c.poll_interval_ns = c.poll_interval_ns.min(c.pdo_wait_ns);
            c.max_speed_mps = config.axes.max_speed_mps;
            // The same profile as the loop's plan (its following-error
            // reference).
            c.max_accel_mps2 = config.axes.max_accel_mps2;
            c.travel_m = config.axes.travel_m;
            // Above the planned speed by 25 % and by the host's rounding to
            // whole counts (at most one count per SYNC more; 2 allowed).
            let rounding_mps = 2.0 * c.m_per_count() / (c.sync_period_ns as f64 * 1e-9);
            c.drive_max_speed_mps = drive_max_speed_mps(config, rounding_mps);
            c.following_window_m = 2.0 * config.axes.following_tolerance_m;
            c.quick_stop_decel_mps2 = *quick_stop_decel_mps2;
            c.max_torque_permille = *max_torque_permille;
            Some((interface.clone(), c))
        }
        _ => None,
    }
}

/// The drives' own velocity limit (CiA 402 0x607F), m/s: `[plausibility]
/// max_joint_speed_mps` (the speed sard calls an encoder jump beyond), but
/// at least 1.25 x `[axes] max_speed_mps` (the margin over the planned and
/// streamed speed for the loop's jitter: a set point streamed early asks
/// the drives for more over what is left of the period) and that speed
/// plus `rounding_mps` (a host's rounding to whole counts). The CANopen
/// drives are written it at start; `sard --sim`'s simulated drives refuse a
/// streamed set point beyond it.
pub fn drive_max_speed_mps(config: &Config, rounding_mps: f64) -> f64 {
    config
        .estimator
        .plausibility
        .limits()
        .max_joint_speed_mps
        .max(1.25 * config.axes.max_speed_mps)
        .max((config.axes.max_speed_mps + rounding_mps) * (1.0 + 1e-9))
}

/// The CANopen drives' per-cycle exchange (SYNC, TPDOs, RPDOs, supervision),
/// as the hook of [`sar_loop::control::Controller::with_drives_cycle`].
pub fn canopen_cycle<C: embedded_can::nb::Can, K: Clock>(
    drives: &mut CanOpenDrives<C, K>,
) -> Result<(), &'static str> {
    drives
        .cycle()
        .map(|_| ())
        .map_err(|_| "CANopen drives cycle")
}

/// After [`CanOpenDrives::start`]: runs the drives' cycle (calling `between`
/// before each, which waits one period) until they report `Ready`, at most
/// `max_cycles` times. The error names the interface and the state reached.
pub fn bring_up<C: embedded_can::nb::Can, K: Clock>(
    drives: &mut CanOpenDrives<C, K>,
    interface: &str,
    max_cycles: u32,
    mut between: impl FnMut(),
) -> Result<(), String> {
    let mut state = None;
    for _ in 0..max_cycles {
        between();
        let _ = drives.cycle();
        state = drives.state().ok();
        if matches!(state, Some(DriveState::Ready | DriveState::Enabled)) {
            return Ok(());
        }
    }
    Err(format!(
        "CANopen drives on {interface}: not ready after {max_cycles} cycles (state {state:?})"
    ))
}
