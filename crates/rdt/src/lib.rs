//! The real force/torque sensor: OnRobot HEX (through its Compute Box) and
//! ATI Net F/T, which stream samples over UDP with the same RDT framing.
//!
//! - [`codec`]: the wire format (pure, no allocation, no panic on any bytes).
//! - [`RdtSensor`]: the [`sar_hal::ForceSensor`] driver, without a thread:
//!   the loop's `drain` and `poll` take what the socket holds without
//!   waiting (one `recvmmsg` a cycle, `socket`), into a fixed ring (`ring`)
//!   and the newest sample; no wake-up per packet. Duplicate and reordered
//!   packets are dropped, sequence gaps
//!   counted ([`RdtStats`]), a non-zero status makes the sample invalid, a
//!   silence longer than [`RdtConfig::silence_limit_ns`] makes `poll` fail
//!   (kind `Disconnected`) until samples come back, and the driver restarts
//!   the stream while silent.
//! - `emulator` (feature `emulator`, for tests; the daemon's too): a device
//!   emulator on a loopback UDP port, with scripted loss, reordering,
//!   duplicates, status faults and silence. Never in `sard`.
//!
//! Facts about the protocol come from public drivers and vendor sample code
//! (ATI's `NetFTRDTPacket`/`NetFTRDTCommand`, OnRobot's C++ examples): header
//! 0x1234, start 0x0002, stop 0x0000, bias 0x0042, OnRobot's filter 0x0081 and
//! rate 0x0082. Whether an OnRobot Compute Box accepts filter and rate while
//! it streams is not documented there; the driver sends them before each
//! start and whenever asked.

pub mod codec;
mod driver;
#[cfg(feature = "emulator")]
pub mod emulator;
mod ring;
mod socket;

pub use codec::Filter;
pub use driver::{
    COUNTER_WINDOW, MAX_DATAGRAMS_PER_READ, MIN_RECEIVE_BUFFER_BYTES, RECEIVE_BUFFER_REQUEST_BYTES,
    REORDER_WINDOW, RdtSensor,
};

use sar_hal::ErrorKind;
use std::net::SocketAddr;

/// Which vendor's dialect of RDT the sensor speaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Flavour {
    /// OnRobot HEX-E/H: bias on/off (0x0042 with 0xFF/0x00), filter (0x0081)
    /// and rate (0x0082) commands.
    #[default]
    OnRobot,
    /// ATI Net F/T: 0x0042 is a one-shot bias (no "bias off": `clear_tare` is
    /// unsupported); filter and rate are set on the sensor's web page, not
    /// over RDT.
    Ati,
}

/// The driver's configuration. `address`, `counts_per_n` and `counts_per_nm`
/// are the keys of INTERFACES.md 2 (`[drivers.sensor]`); the rest have the
/// defaults of [`RdtConfig::new`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RdtConfig {
    /// The sensor's address (port 49152, [`codec::DEFAULT_PORT`]).
    pub address: SocketAddr,
    /// Counts per newton (OnRobot: 10 000; ATI: per sensor, on its
    /// calibration page).
    pub counts_per_n: f64,
    /// Counts per newton metre (OnRobot: 100 000; ATI: per sensor).
    pub counts_per_nm: f64,
    /// The vendor's dialect. Default OnRobot.
    pub flavour: Flavour,
    /// Without an accepted packet for longer than this, the sensor is silent:
    /// `poll` and `wait` fail with kind `Disconnected` and the driver
    /// restarts the stream. Default 20 ms (10 periods at 500 Hz).
    pub silence_limit_ns: u64,
    /// While silent, the start request is sent again this often. Default
    /// 100 ms.
    pub restart_interval_ns: u64,
    /// OnRobot's filter, sent before each start; `None` leaves the device's
    /// own setting. Default `None`. Must be `None` for ATI.
    pub filter: Option<Filter>,
    /// OnRobot's output rate, Hz, 1 to 1000, sent before each start as the
    /// period 1000 / rate_hz ms (integer division: 300 Hz gives 3 ms, i.e.
    /// 333 Hz); `None` leaves the device's own setting. Default 500 Hz for
    /// OnRobot. Must be `None` for ATI.
    pub rate_hz: Option<u32>,
    /// Samples kept for [`sar_hal::ForceSensor::drain`] between two drains;
    /// the newest beyond are dropped and counted. 1 to 2^20. Default 4096
    /// (0.58 s at ATI's 7 kHz).
    pub ring_capacity: usize,
    /// The local address to bind; `None`: the loopback address for a sensor
    /// on loopback, the unspecified address otherwise, any port.
    pub local_address: Option<SocketAddr>,
}

/// Default of [`RdtConfig::silence_limit_ns`].
pub const DEFAULT_SILENCE_LIMIT_NS: u64 = 20_000_000;
/// Default of [`RdtConfig::restart_interval_ns`].
pub const DEFAULT_RESTART_INTERVAL_NS: u64 = 100_000_000;
/// Default of [`RdtConfig::rate_hz`] for OnRobot.
pub const DEFAULT_ONROBOT_RATE_HZ: u32 = 500;
/// Default of [`RdtConfig::ring_capacity`].
pub const DEFAULT_RING_CAPACITY: usize = 4096;
/// Largest [`RdtConfig::ring_capacity`].
pub const MAX_RING_CAPACITY: usize = 1 << 20;

impl RdtConfig {
    /// An OnRobot sensor at `address` with the documented defaults.
    pub fn new(address: SocketAddr, counts_per_n: f64, counts_per_nm: f64) -> Self {
        Self {
            address,
            counts_per_n,
            counts_per_nm,
            flavour: Flavour::OnRobot,
            silence_limit_ns: DEFAULT_SILENCE_LIMIT_NS,
            restart_interval_ns: DEFAULT_RESTART_INTERVAL_NS,
            filter: None,
            rate_hz: Some(DEFAULT_ONROBOT_RATE_HZ),
            ring_capacity: DEFAULT_RING_CAPACITY,
            local_address: None,
        }
    }

    /// An ATI Net F/T at `address` (no filter or rate commands).
    pub fn ati(address: SocketAddr, counts_per_n: f64, counts_per_nm: f64) -> Self {
        Self {
            flavour: Flavour::Ati,
            rate_hz: None,
            ..Self::new(address, counts_per_n, counts_per_nm)
        }
    }

    /// Checks every field (what the types do not).
    pub fn validate(&self) -> Result<(), RdtError> {
        for (field, value) in [
            ("counts_per_n", self.counts_per_n),
            ("counts_per_nm", self.counts_per_nm),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(RdtError::InvalidConfig { field, value });
            }
        }
        for (field, value) in [
            ("silence_limit_ns", self.silence_limit_ns),
            ("restart_interval_ns", self.restart_interval_ns),
        ] {
            if value == 0 {
                return Err(RdtError::InvalidConfig { field, value: 0.0 });
            }
        }
        if !(1..=MAX_RING_CAPACITY).contains(&self.ring_capacity) {
            return Err(RdtError::InvalidConfig {
                field: "ring_capacity",
                value: self.ring_capacity as f64,
            });
        }
        if let Some(rate) = self.rate_hz
            && !(1..=1000).contains(&rate)
        {
            return Err(RdtError::InvalidConfig {
                field: "rate_hz",
                value: f64::from(rate),
            });
        }
        if self.flavour == Flavour::Ati {
            if self.rate_hz.is_some() {
                return Err(RdtError::Unsupported {
                    command: "rate_hz",
                    flavour: self.flavour,
                });
            }
            if self.filter.is_some() {
                return Err(RdtError::Unsupported {
                    command: "filter",
                    flavour: self.flavour,
                });
            }
        }
        Ok(())
    }
}

/// What the driver's reads of its socket have counted since it started.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RdtStats {
    /// Packets accepted as samples (each handed to `poll` and the ring).
    pub accepted: u64,
    /// Of those, with a non-zero status (invalid samples).
    pub faults: u64,
    /// Packets missing: gaps in the RDT sequence (a late packet counted here
    /// is dropped, so it stays lost).
    pub lost: u64,
    /// Packets dropped as duplicates (same RDT sequence, or same counter).
    pub duplicates: u64,
    /// Packets dropped as late (RDT sequence or counter behind the last
    /// accepted one, within a window of [`REORDER_WINDOW`]).
    pub reordered: u64,
    /// Packets accepted after a jump back beyond that window: taken as a new
    /// stream of the device (e.g. after it rebooted).
    pub resyncs: u64,
    /// Datagrams that are not a 36-byte response.
    pub malformed: u64,
    /// Times the sensor went silent (no accepted packet within the limit).
    pub silences: u64,
    /// Start requests sent again while silent.
    pub restarts: u64,
    /// Samples dropped because the drain ring was full.
    pub ring_overflows: u64,
    /// Socket errors other than timeouts (e.g. ICMP port unreachable).
    pub io_errors: u64,
    /// Packets dropped because the host's clock could not be read to stamp
    /// them (never stamped with a made-up time); a clock that stays unreadable
    /// makes the sensor silent.
    pub clock_errors: u64,
}

/// Why a sensor is silent: the last thing the driver's reads saw since the
/// last accepted packet. (A sequence gap is never a cause: a packet after a
/// gap is accepted, the gap counted in [`RdtStats::lost`] and judged by the
/// loop's counter check.)
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum SilenceCause {
    /// Nothing arrived from the sensor's address: the device is off,
    /// unplugged, not streaming, or streaming to another host. The socket is
    /// connected to the sensor's address, so datagrams from any other
    /// address (a sensor configured at another address, another device) are
    /// never received: they look like this too.
    NothingReceived,
    /// Only datagrams of the wrong length came (`got` bytes, not 36): a
    /// short or long packet, not an RDT response.
    WrongLength {
        /// The last one's length, bytes.
        got: usize,
    },
    /// Only repeats of the last accepted sample came (same RDT sequence, or
    /// same sample counter).
    Duplicates,
    /// Only packets behind the last accepted one came (late, reordered).
    Late,
    /// The socket reported an error (`ConnectionRefused`: an ICMP port
    /// unreachable, the sensor's port is closed).
    Socket {
        /// The error's kind.
        kind: std::io::ErrorKind,
    },
    /// Packets came, but the host's clock could not be read to stamp them.
    Clock,
}

impl SilenceCause {
    /// The cause in a few words (static: for the loop's log, no allocation).
    pub fn short(&self) -> &'static str {
        match self {
            Self::NothingReceived => "sensor silent: nothing received from its address",
            Self::WrongLength { .. } => "sensor silent: only datagrams of the wrong length",
            Self::Duplicates => "sensor silent: only duplicate packets",
            Self::Late => "sensor silent: only late packets",
            Self::Socket { .. } => "sensor silent: socket error",
            Self::Clock => "sensor silent: the clock cannot be read to stamp packets",
        }
    }

    /// The cause in a sentence, with the sensor's address.
    pub fn text(&self, address: &SocketAddr) -> String {
        match self {
            Self::NothingReceived => format!(
                "nothing received from {address} (off, unplugged, not streaming, or streaming to another host; datagrams from other addresses are not received)"
            ),
            Self::WrongLength { got } => format!(
                "only datagrams of the wrong length from {address} (the last {got} bytes, not {})",
                codec::RESPONSE_LEN
            ),
            Self::Duplicates => format!(
                "only duplicates of the last sample from {address} (same RDT sequence or counter)"
            ),
            Self::Late => format!("only late packets from {address} (behind the last sample)"),
            Self::Socket { kind } => {
                format!("socket error ({kind}) receiving from {address}")
            }
            Self::Clock => {
                "packets came, but the monotonic clock cannot be read to stamp them".to_owned()
            }
        }
    }
}

/// An error of the RDT driver.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum RdtError {
    /// A configuration field is out of range.
    #[error("RDT configuration: {field} = {value} is out of range")]
    InvalidConfig {
        /// The field.
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// The flavour has no such command.
    #[error("{command} is not available on {flavour:?} sensors over RDT")]
    Unsupported {
        /// The command or setting.
        command: &'static str,
        /// The sensor's flavour.
        flavour: Flavour,
    },
    /// A socket operation failed.
    #[error("RDT socket: {op} failed: {kind}")]
    Io {
        /// The operation.
        op: &'static str,
        /// The I/O error's kind.
        kind: std::io::ErrorKind,
    },
    /// No packet accepted for longer than the silence limit.
    #[error(
        "sensor silent: no sample accepted for more than {limit_ns} ns (last at {last_received_ns} ns): {}",
        cause.text(address)
    )]
    Silent {
        /// Host time of the last accepted packet (or of the first start
        /// request, when none came), ns.
        last_received_ns: u64,
        /// The configured limit, ns.
        limit_ns: u64,
        /// Why: what the driver's reads last saw since then.
        cause: SilenceCause,
        /// The sensor's address.
        address: SocketAddr,
    },
    /// `wait` saw no new sample within its timeout.
    #[error("no sample within {timeout_ns} ns")]
    Timeout {
        /// The timeout, ns.
        timeout_ns: u64,
    },
    /// The kernel granted the socket a receive buffer too small for
    /// several cycles of packets between two reads (`net.core.rmem_max`
    /// caps it at twice its value).
    #[error(
        "the RDT socket's receive buffer is {granted_bytes} bytes, at least {needed_bytes} are needed (raise net.core.rmem_max)"
    )]
    ReceiveBuffer {
        /// What the kernel granted, bytes.
        granted_bytes: usize,
        /// The least the driver accepts, bytes.
        needed_bytes: usize,
    },
    /// The host's monotonic clock cannot be read.
    #[error("the monotonic clock cannot be read")]
    Clock,
}

impl sar_hal::Error for RdtError {
    fn cause(&self) -> &'static str {
        match self {
            Self::Silent { cause, .. } => cause.short(),
            Self::ReceiveBuffer { .. } => "the socket's receive buffer is too small",
            Self::Timeout { .. } => "no sample within the wait",
            Self::Io { .. } => "socket error",
            Self::Clock => "the monotonic clock cannot be read",
            Self::InvalidConfig { .. } => "invalid configuration",
            Self::Unsupported { .. } => "not supported by this sensor",
        }
    }

    fn kind(&self) -> ErrorKind {
        match self {
            Self::InvalidConfig { .. } => ErrorKind::InvalidArgument,
            Self::Unsupported { .. } => ErrorKind::Unsupported,
            Self::Io { .. } | Self::Silent { .. } => ErrorKind::Disconnected,
            Self::ReceiveBuffer { .. } => ErrorKind::Other,
            Self::Timeout { .. } => ErrorKind::Timeout,
            Self::Clock => ErrorKind::Other,
        }
    }
}
