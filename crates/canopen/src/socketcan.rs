//! SocketCAN (Linux, feature `socketcan`): the robot's CAN interface as the
//! bus of [`crate::CanOpenDrives`] (the `socketcan` crate implements
//! `embedded_can::nb::Can` for [`CanSocket`]).

use crate::CanOpenError;
use socketcan::{Socket, SocketOptions};

pub use socketcan::CanSocket;

/// Opens `interface` (e.g. "can0", "vcan0") non-blocking, with every error
/// frame delivered (they come out of `receive` as errors: bus-off, error
/// passive, ...).
pub fn open(interface: &str) -> Result<CanSocket, CanOpenError> {
    let fail = |e: std::io::Error| CanOpenError::Open {
        interface: interface.to_owned(),
        detail: e.to_string(),
    };
    let socket = CanSocket::open(interface).map_err(fail)?;
    socket.set_nonblocking(true).map_err(fail)?;
    socket.set_error_filter_accept_all().map_err(fail)?;
    Ok(socket)
}
