//! The error kinds every driver maps its own errors to (as embedded-can's
//! `ErrorKind`): generic code, such as the daemon's loop or the conformance
//! suite, decides by kind without knowing the implementation.

/// What went wrong, in terms generic code can act on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum ErrorKind {
    /// Nothing arrived within the bounded wait.
    Timeout,
    /// The device or link is gone (no heartbeat, socket closed, end of a recording).
    Disconnected,
    /// The device reports a fault of its own.
    DeviceFault,
    /// The command is not valid in the device's present state (targets while
    /// disabled, enable while in fault, ...).
    InvalidState,
    /// The command's arguments are invalid (non-finite, out of travel).
    InvalidArgument,
    /// The device has no such command (a sensor without a device-side tare).
    Unsupported,
    /// Anything else.
    Other,
}

impl core::fmt::Display for ErrorKind {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::Timeout => "timed out",
            Self::Disconnected => "disconnected",
            Self::DeviceFault => "device fault",
            Self::InvalidState => "not allowed in the present state",
            Self::InvalidArgument => "invalid argument",
            Self::Unsupported => "not supported by the device",
            Self::Other => "other error",
        })
    }
}

/// A driver error: any type that can say its [`ErrorKind`].
pub trait Error: core::fmt::Debug + core::fmt::Display {
    /// The kind of this error.
    fn kind(&self) -> ErrorKind;

    /// Its specific cause in a few words, static so that the loop can log it
    /// without allocating ("sensor silent: only duplicate packets"); empty
    /// when the kind says it all.
    fn cause(&self) -> &'static str {
        ""
    }
}
