//! The real devices the configuration names (`[drivers.sensor]`,
//! `[drivers.axes]`, INTERFACES.md 2): their driver configurations made from
//! the daemon's, their start with one-line reasons that name the device, and
//! the per-cycle hook of the CANopen drives ([`canopen_cycle`]), which the
//! controller calls once per period in its gather phase.

use sar_canopen::{CanOpenConfig, CanOpenDrives};
use sar_config::Config;
use sar_hal::{AxisDrives, Clock, DriveState, ForceSensor};
use sar_rdt::{RdtConfig, RdtSensor};

/// The RDT driver's configuration for `[drivers.sensor] kind = "rdt"`
/// (`sar_config::devices::rdt_sensor`, checked when the file was loaded);
/// `None` for another kind.
pub fn rdt_config(config: &Config) -> Option<RdtConfig> {
    sar_config::devices::rdt_sensor(config)
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

/// The CANopen drives' configuration for `[drivers.axes] kind = "canopen"`,
/// with the interface's name (`sar_config::devices::canopen_drives`: the
/// one conversion, whose result the file's load already ran the drives'
/// own checks on, so `sard --check-config` refuses what the start would);
/// `None` for another kind.
pub fn canopen_config(config: &Config) -> Option<(String, CanOpenConfig)> {
    sar_config::devices::canopen_drives(config)
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
