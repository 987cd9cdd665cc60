//! The SAR daemon `sard` (`sar-daemon`), the top of the layering: it wires
//! the devices, the loop, the transport and the recording together. The
//! library holds what `sard` and the tests share:
//!
//! - [`sim`]: the simulated robot of a scenario (sensor, drives, bias).
//! - [`devices`]: the real devices' bring-up (the RDT sensor, the CANopen
//!   drives).
//!
//! The loop is `sar-loop`, the configuration `sar-config`, the transport
//! `sar-shm`, the recording `sar-record`; the operator's tool is `sarctl`.

pub mod devices;
pub mod sim;
