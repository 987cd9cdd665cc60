//! The axis drives over CANopen: three CiA 402 drives in cyclic synchronous
//! position mode (CSP), driven by [`CanOpenDrives`], which implements
//! [`sar_hal::AxisDrives`] and is generic over the `embedded-can` non-blocking
//! [`embedded_can::nb::Can`] trait: SocketCAN on the robot (feature
//! `socketcan`, Linux), the in-memory `MemBus` in tests.
//!
//! - [`frame`]: the wire (COB-IDs, NMT, expedited SDO, PDO, EMCY, heartbeat,
//!   control and status words).
//! - [`CanOpenDrives`]: start-up, the per-cycle SYNC / TPDO / RPDO exchange,
//!   the CiA 402 state machine, EMCY and heartbeat supervision.
//! - The test doubles, behind the feature `sim` (turned on only by
//!   dev-dependencies, never by `sard`): `MemBus`, a deterministic in-memory
//!   bus stepped by hand, carrying `SimCia402Drive`s, simulated CANopen
//!   slaves built on the hardware layer's axis model (the motion planner and
//!   its limits), which enforce the limits the host writes; `serve`, which
//!   serves them on a real bus (vcan0).
//!
//! Positions: the encoders are absolute multiturn (12 bits per turn, 20 bits
//! of turns, so a 32-bit count); metres = counts x `lead_m` / `counts_per_turn`.
//! A position is valid only while the drive reports its encoder referenced,
//! which this project reads in status word bit 15 (manufacturer specific,
//! [`frame::STATUS_REFERENCED`]).

#[cfg(feature = "sim")]
mod bus;
pub mod frame;
mod host;
#[cfg(feature = "sim")]
mod slave;
#[cfg(all(feature = "socketcan", target_os = "linux"))]
pub mod socketcan;

#[cfg(feature = "sim")]
pub use bus::{MemBus, MemBusError, MemCan};
pub use host::{CanOpenDrives, CycleReport};
#[cfg(feature = "sim")]
pub use slave::{
    FOLLOWING_WINDOW_M, SimCia402Drive, SimDriveFault, SimDriveSpec, StopOptions, serve,
};

use sar_hal::{Error, ErrorKind};

/// The configuration of the CANopen axis drives (INTERFACES.md 2
/// `[drivers.axes]`: `node_ids`, `lead_m`, `counts_per_turn`; the rest has
/// defaults, see [`CanOpenConfig::new`]).
#[derive(Debug, Clone, PartialEq)]
pub struct CanOpenConfig {
    /// Node ids of q1, q2, q3 (1..=127, distinct).
    pub node_ids: [u8; 3],
    /// Carriage travel per motor turn, m.
    pub lead_m: f64,
    /// Encoder counts per turn (4096 for 12 bits).
    pub counts_per_turn: u32,
    /// The host's own node id, for its heartbeat (1..=127, not a drive's).
    pub host_node_id: u8,
    /// SYNC period = control loop period, ns.
    pub sync_period_ns: u64,
    /// Speed limit of the planned moves, m/s.
    pub max_speed_mps: f64,
    /// Acceleration limit of the planned moves, m/s^2.
    pub max_accel_mps2: f64,
    /// Travel of q1, q2, q3 (min, max), m; targets outside are refused.
    pub travel_m: [(f64, f64); 3],
    /// The host's heartbeat period, ms.
    pub host_heartbeat_ms: u16,
    /// The drives' consumer time for the host's heartbeat, ms: a host silent
    /// longer than this makes every drive quick stop (0x6007 = 3).
    pub host_heartbeat_timeout_ms: u16,
    /// The drives' heartbeat period, ms.
    pub drive_heartbeat_ms: u16,
    /// A drive whose heartbeat is older than this is lost (a fault), ms.
    pub drive_heartbeat_timeout_ms: u16,
    /// Bound on one SDO exchange, ns.
    pub sdo_timeout_ns: u64,
    /// Bound on the wait for the TPDOs of a SYNC, ns.
    pub pdo_wait_ns: u64,
    /// Bound on the wait for a drive's boot-up after an NMT reset, ns.
    pub boot_timeout_ns: u64,
    /// How long the host sleeps between polls of the bus while waiting, ns.
    pub poll_interval_ns: u64,
    /// The drives' own quick stop deceleration (0x6085), m/s^2: the ramp of
    /// every quick stop, the host's and the drive's own when the host goes
    /// silent. At least `max_accel_mps2`.
    pub quick_stop_decel_mps2: f64,
    /// The drives' own speed limit (max profile velocity, 0x607F), m/s: a set
    /// point implying more is limited by the drive. Above `max_speed_mps` by
    /// more than two counts per SYNC period (the host's own plans never reach
    /// it).
    pub drive_max_speed_mps: f64,
    /// The drives' following error window (0x6065), m: the actual position
    /// farther than this from the set point for longer than
    /// `following_timeout_ms` is a drive fault (EMCY 0x8611); a set point
    /// farther than this from the previous one is one at once.
    pub following_window_m: f64,
    /// The drives' following error time out (0x6066), ms.
    pub following_timeout_ms: u16,
    /// The drives' max torque (0x6072), per thousand of the motor's rated
    /// torque (1..=10000).
    pub max_torque_permille: u16,
}

/// A number as an operator reads it (six significant digits).
fn shown(v: f64) -> String {
    sar_kinematics::Shown(v).to_string()
}

/// The error naming a bad setting, its value and what it must be.
fn invalid(field: &'static str, value: String, why: &'static str) -> Result<(), CanOpenError> {
    Err(CanOpenError::InvalidConfig { field, value, why })
}

impl CanOpenConfig {
    /// The configuration with the file's keys and defaults for the rest:
    /// host node 127, 1 kHz SYNC, 0.05 m/s and 0.5 m/s^2, travel ±1 m, host
    /// heartbeat 10 ms (consumer time 50 ms), drive heartbeat 10 ms (timeout
    /// 50 ms), SDO 20 ms, PDO wait 0.5 ms, boot-up 2 s, polls every 20 µs;
    /// the drives' own limits: quick stop at 1 m/s^2, 0.1 m/s, following
    /// window 2 mm for 10 ms, max torque 1000 per mille (the rated torque),
    /// software position limits = the travel.
    pub fn new(node_ids: [u8; 3], lead_m: f64, counts_per_turn: u32) -> Self {
        Self {
            node_ids,
            lead_m,
            counts_per_turn,
            host_node_id: 127,
            sync_period_ns: 1_000_000,
            max_speed_mps: 0.05,
            max_accel_mps2: 0.5,
            travel_m: [(-1.0, 1.0); 3],
            host_heartbeat_ms: 10,
            host_heartbeat_timeout_ms: 50,
            drive_heartbeat_ms: 10,
            drive_heartbeat_timeout_ms: 50,
            sdo_timeout_ns: 20_000_000,
            pdo_wait_ns: 500_000,
            boot_timeout_ns: 2_000_000_000,
            poll_interval_ns: 20_000,
            quick_stop_decel_mps2: 1.0,
            drive_max_speed_mps: 0.1,
            following_window_m: 0.002,
            following_timeout_ms: 10,
            max_torque_permille: 1000,
        }
    }

    /// Checks the values; the first bad one is named, with what it must be.
    /// What the drivers' start runs (`CanOpenDrives::start`), and what
    /// `sar_config` runs on every configuration that names CANopen drives
    /// (so `sard --check-config` refuses what the start would).
    pub fn validate(&self) -> Result<(), CanOpenError> {
        self.check_nodes()?;
        self.check_scale()?;
        self.check_timing()?;
        self.check_motion()?;
        self.check_heartbeats()?;
        self.check_drive_limits()
    }

    /// Three distinct drive node ids and the host's, all 1 to 127.
    fn check_nodes(&self) -> Result<(), CanOpenError> {
        let ids = self.node_ids;
        if ids.iter().any(|&n| n == 0 || n > 127)
            || ids[0] == ids[1]
            || ids[1] == ids[2]
            || ids[0] == ids[2]
        {
            return invalid(
                "node_ids",
                format!("{ids:?}"),
                "three distinct node ids, 1 to 127",
            );
        }
        if self.host_node_id == 0 || self.host_node_id > 127 || ids.contains(&self.host_node_id) {
            return invalid(
                "host_node_id",
                self.host_node_id.to_string(),
                "1 to 127, none of the drives'",
            );
        }
        Ok(())
    }

    /// A positive lead and counts per turn.
    fn check_scale(&self) -> Result<(), CanOpenError> {
        if !(self.lead_m.is_finite() && self.lead_m > 0.0) {
            return invalid("lead_m", self.lead_m.to_string(), "a finite lead > 0 m");
        }
        if self.counts_per_turn == 0 {
            return invalid("counts_per_turn", "0".into(), "at least 1");
        }
        Ok(())
    }

    /// The SYNC period (0.1 ms to 1 s), the TPDOs' wait within it, the bus polled
    /// at least once in that wait.
    fn check_timing(&self) -> Result<(), CanOpenError> {
        if !(100_000..=1_000_000_000).contains(&self.sync_period_ns) {
            return invalid(
                "sync_period_ns",
                self.sync_period_ns.to_string(),
                "0.1 ms to 1 s (the loop's period)",
            );
        }
        // The TPDOs of a SYNC are awaited within its period, or positions of
        // two SYNCs could mix; the bus is polled at least once in that wait.
        if !(1..self.sync_period_ns).contains(&self.pdo_wait_ns) {
            return invalid(
                "pdo_wait_ns",
                self.pdo_wait_ns.to_string(),
                "within the SYNC period",
            );
        }
        if !(1..=self.pdo_wait_ns).contains(&self.poll_interval_ns) {
            return invalid(
                "poll_interval_ns",
                self.poll_interval_ns.to_string(),
                "within the PDOs' wait",
            );
        }
        Ok(())
    }

    /// The host's speed and acceleration positive; each travel finite, not
    /// empty, and within the drives' i32 counts.
    fn check_motion(&self) -> Result<(), CanOpenError> {
        if !(self.max_speed_mps.is_finite() && self.max_speed_mps > 0.0) {
            return invalid("max_speed_mps", self.max_speed_mps.to_string(), "> 0 m/s");
        }
        if !(self.max_accel_mps2.is_finite() && self.max_accel_mps2 > 0.0) {
            return invalid(
                "max_accel_mps2",
                self.max_accel_mps2.to_string(),
                "> 0 m/s^2",
            );
        }
        for (lo, hi) in self.travel_m {
            // Every target in travel must fit the drives' i32 counts (a cast
            // would saturate silently).
            let widest_counts = lo.abs().max(hi.abs()) / self.m_per_count();
            if !(lo.is_finite() && hi.is_finite() && lo < hi) || widest_counts > f64::from(i32::MAX)
            {
                return invalid(
                    "travel_m",
                    format!(
                        "{:?} m ({} counts of {} m)",
                        self.travel_m,
                        shown(widest_counts),
                        shown(self.m_per_count())
                    ),
                    "each bound within the drives' 32-bit position (2^31 - 1 counts), min < max",
                );
            }
        }
        Ok(())
    }

    /// Each heartbeat period non-zero and below its time-out.
    fn check_heartbeats(&self) -> Result<(), CanOpenError> {
        if self.host_heartbeat_ms == 0 || self.host_heartbeat_timeout_ms <= self.host_heartbeat_ms {
            return invalid(
                "host_heartbeat_timeout_ms",
                self.host_heartbeat_timeout_ms.to_string(),
                "above the host's heartbeat period",
            );
        }
        if self.drive_heartbeat_ms == 0
            || self.drive_heartbeat_timeout_ms <= self.drive_heartbeat_ms
        {
            return invalid(
                "drive_heartbeat_timeout_ms",
                self.drive_heartbeat_timeout_ms.to_string(),
                "above the drives' heartbeat period",
            );
        }
        Ok(())
    }

    /// The drive's own limits: its quick stop at least the host's acceleration,
    /// its speed above the host's plans, a following window of at least one
    /// count, all within the drive's u32 units; the torque 1 to 10000 per mille.
    fn check_drive_limits(&self) -> Result<(), CanOpenError> {
        let per_s = |v: f64| v / self.m_per_count();
        let with_counts = |v: f64, unit: &str| {
            format!(
                "{} {unit} ({} counts{})",
                shown(v),
                shown(per_s(v)),
                unit.trim_start_matches('m')
            )
        };
        if !(self.quick_stop_decel_mps2.is_finite()
            && self.quick_stop_decel_mps2 >= self.max_accel_mps2
            && per_s(self.quick_stop_decel_mps2) <= f64::from(u32::MAX))
        {
            return invalid(
                "quick_stop_decel_mps2",
                with_counts(self.quick_stop_decel_mps2, "m/s^2"),
                "at least the planned acceleration, and at most 2^32 - 1 counts/s^2 (0x6085 is 32 bits)",
            );
        }
        // The host's plans, rounded to whole counts, move at most
        // max_speed + 1 count per SYNC: the drive's limit is above that.
        let rounding_mps = 2.0 * self.m_per_count() / (self.sync_period_ns as f64 * 1e-9);
        if !(self.drive_max_speed_mps.is_finite()
            && self.drive_max_speed_mps >= self.max_speed_mps + rounding_mps
            && per_s(self.drive_max_speed_mps) <= f64::from(u32::MAX))
        {
            return invalid(
                "drive_max_speed_mps",
                with_counts(self.drive_max_speed_mps, "m/s"),
                "above the planned speed by two counts a SYNC, and at most 2^32 - 1 counts/s (0x607F is 32 bits)",
            );
        }
        if !(self.following_window_m.is_finite()
            && self.following_window_m >= self.m_per_count()
            // 0xFFFF_FFFF switches a CiA 402 drive's following check off.
            && per_s(self.following_window_m) < f64::from(u32::MAX))
        {
            return invalid(
                "following_window_m",
                with_counts(self.following_window_m, "m"),
                "at least one count, and below 2^32 - 1 counts (that value switches the drive's check off)",
            );
        }
        if !(1..=10_000).contains(&self.max_torque_permille) {
            return invalid(
                "max_torque_permille",
                self.max_torque_permille.to_string(),
                "1 to 10000 per mille of the rated torque",
            );
        }
        Ok(())
    }

    /// The drive's own limits of axis `axis` (0 = q1) as the objects written
    /// at start-up and read back, `(index, sub, value, bytes)`, in the
    /// drive's units (position units = encoder counts): quick stop
    /// deceleration 0x6085 (counts/s^2, to the nearest), software position
    /// limits 0x607D sub 1/2 (the travel, rounded outwards to whole counts:
    /// a target within the travel is never clamped), max profile velocity
    /// 0x607F (counts/s, rounded up), following error window 0x6065 (counts,
    /// rounded up) and time out 0x6066 (ms), max torque 0x6072 (per mille).
    pub fn drive_limit_objects(&self, axis: usize) -> [(u16, u8, u32, u8); 7] {
        use frame::od;
        let count = self.m_per_count();
        let (lo, hi) = self.travel_m.get(axis).copied().unwrap_or((0.0, 0.0));
        // Saturating float-to-int conversions; `validate` keeps them in range.
        let counts_u32 = |v: f64| v.max(0.0) as u32;
        let min = (lo / count).floor() as i32;
        let max = (hi / count).ceil() as i32;
        [
            (
                od::QUICK_STOP_DECELERATION,
                0,
                counts_u32((self.quick_stop_decel_mps2 / count).round()),
                4,
            ),
            (od::SOFTWARE_POSITION_LIMIT, 1, min as u32, 4),
            (od::SOFTWARE_POSITION_LIMIT, 2, max as u32, 4),
            (
                od::MAX_PROFILE_VELOCITY,
                0,
                counts_u32((self.drive_max_speed_mps / count).ceil()),
                4,
            ),
            (
                od::FOLLOWING_ERROR_WINDOW,
                0,
                counts_u32((self.following_window_m / count).ceil()),
                4,
            ),
            (
                od::FOLLOWING_ERROR_TIMEOUT,
                0,
                u32::from(self.following_timeout_ms),
                2,
            ),
            (od::MAX_TORQUE, 0, u32::from(self.max_torque_permille), 2),
        ]
    }

    /// How each drive stops, written at start-up and read back beside its
    /// limits, `(index, sub, value, bytes)`: a control outside the software
    /// (SAFETY.md), each a ramp, never the motor left to coast:
    /// - 0x605A quick stop option = 6: the quick stop ramp (0x6085), then
    ///   stay in Quick stop active;
    /// - 0x605B shutdown option = 1 and 0x605C disable operation option =
    ///   1: slow down on the slow down ramp (0x6084), then disable (the
    ///   host's disable is a shutdown);
    /// - 0x605E fault reaction option = 2: the quick stop ramp (0: coast,
    ///   many drives' default);
    /// - 0x6007 abort connection option = 3: a quick stop when the host's
    ///   heartbeat is lost (the drives' consumer of it, 0x1016);
    /// - 0x6084 profile deceleration: the slow down ramp, the quick stop's
    ///   deceleration (counts/s^2, to the nearest).
    pub fn safe_stop_objects(&self) -> [(u16, u8, u32, u8); 6] {
        use frame::od;
        let count = self.m_per_count();
        let code = |v: i16| u32::from(v as u16);
        [
            (
                od::QUICK_STOP_OPTION,
                0,
                code(frame::QUICK_STOP_RAMP_AND_HOLD),
                2,
            ),
            (od::SHUTDOWN_OPTION, 0, code(frame::DISABLE_AFTER_RAMP), 2),
            (
                od::DISABLE_OPERATION_OPTION,
                0,
                code(frame::DISABLE_AFTER_RAMP),
                2,
            ),
            (
                od::FAULT_REACTION_OPTION,
                0,
                code(frame::FAULT_REACTION_QUICK_STOP_RAMP),
                2,
            ),
            (od::ABORT_CONNECTION, 0, code(frame::ABORT_QUICK_STOP), 2),
            (
                od::PROFILE_DECELERATION,
                0,
                // Saturating; `validate` keeps it within u32.
                (self.quick_stop_decel_mps2 / count).round().max(0.0) as u32,
                4,
            ),
        ]
    }

    /// Metres per encoder count.
    pub fn m_per_count(&self) -> f64 {
        self.lead_m / f64::from(self.counts_per_turn)
    }
}

/// An error of the CANopen drives.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum CanOpenError {
    /// A configuration value is wrong.
    #[error("CANopen configuration: {field} = {value}: must be {why}")]
    InvalidConfig {
        /// The field.
        field: &'static str,
        /// Its value.
        value: String,
        /// What it must be.
        why: &'static str,
    },
    /// No SDO response within the bound.
    #[error("node {node}: no SDO response for {index:#06x}:{sub} within {timeout_ns} ns")]
    SdoTimeout {
        /// Node id.
        node: u8,
        /// Index.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// The bound, ns.
        timeout_ns: u64,
    },
    /// The drive aborted an SDO transfer.
    #[error("node {node}: SDO {index:#06x}:{sub} aborted with {code:#010x}")]
    SdoAbort {
        /// Node id.
        node: u8,
        /// Index.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// Abort code.
        code: u32,
    },
    /// No boot-up after an NMT reset within the bound.
    #[error("node {node}: no boot-up within {timeout_ns} ns")]
    NoBootUp {
        /// Node id.
        node: u8,
        /// The bound, ns.
        timeout_ns: u64,
    },
    /// No heartbeat saying operational after the NMT start within the bound.
    #[error("node {node}: not operational within {timeout_ns} ns of the NMT start")]
    NotOperational {
        /// Node id.
        node: u8,
        /// The bound, ns.
        timeout_ns: u64,
    },
    /// The drive did not take cyclic synchronous position mode.
    #[error("node {node}: mode of operation is {mode}, not 8 (CSP)")]
    WrongMode {
        /// Node id.
        node: u8,
        /// Mode read in 0x6061.
        mode: i8,
    },
    /// The CAN controller reported an error (an error frame, bus-off,
    /// overrun, ...): `kind` is embedded-can's.
    /// (Only the kind: the error is noted on the loop's path, where no text is
    /// formatted.)
    #[error("CAN bus error ({kind:?})")]
    Bus {
        /// embedded-can's kind.
        kind: embedded_can::ErrorKind,
    },
    /// The host's monotonic clock cannot be read: no SYNC or position is
    /// stamped with a made-up time.
    #[error("the monotonic clock cannot be read")]
    Clock,
    /// The CAN interface could not be opened.
    #[error("CAN interface {interface}: {detail}")]
    Open {
        /// The interface.
        interface: String,
        /// The system's reason.
        detail: String,
    },
    /// A frame could not be built or sent (queue full).
    #[error("CAN frame {cob_id:#05x} could not be sent")]
    Transmit {
        /// COB-ID.
        cob_id: u16,
    },
    /// Not allowed in the present state.
    #[error("not allowed in state {state:?}")]
    InvalidState {
        /// The state.
        state: sar_hal::DriveState,
    },
    /// A target is not finite or outside the travel.
    #[error(
        "target of axis {axis} = {} m is not finite or outside [{}, {}]",
        sar_kinematics::Shown(*.value_m),
        sar_kinematics::Shown(*.min_m),
        sar_kinematics::Shown(*.max_m)
    )]
    InvalidTarget {
        /// 0 = q1, 1 = q2, 2 = q3.
        axis: u8,
        /// The target, m.
        value_m: f64,
        /// Travel minimum, m.
        min_m: f64,
        /// Travel maximum, m.
        max_m: f64,
    },
    /// A safety setting of a drive (one of its own limits, its watchdog)
    /// reads back other than written (a drive that clamps a value to its own
    /// range, or ignores it): the start is refused, the drives are never
    /// enabled.
    #[error(
        "node {node}: {name} {index:#06x}:{sub} reads {read} after writing {written}; the drive does not hold the configured value: not enabling the drives"
    )]
    LimitMismatch {
        /// Node id.
        node: u8,
        /// Index.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// The object's name.
        name: &'static str,
        /// The value written (signed for 0x607D), drive units.
        written: i64,
        /// The value read back.
        read: i64,
    },
    /// A fault that a reset cannot clear now (a drive still lost).
    #[error("axis {axis}: fault {code:#06x} persists")]
    FaultPersists {
        /// The axis.
        axis: u8,
        /// Its fault code.
        code: u16,
    },
}

impl Error for CanOpenError {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::InvalidConfig { .. } | Self::InvalidTarget { .. } => ErrorKind::InvalidArgument,
            Self::SdoTimeout { .. } | Self::NoBootUp { .. } | Self::NotOperational { .. } => {
                ErrorKind::Timeout
            }
            Self::SdoAbort { .. }
            | Self::WrongMode { .. }
            | Self::FaultPersists { .. }
            | Self::LimitMismatch { .. } => ErrorKind::DeviceFault,
            Self::Bus { .. } | Self::Transmit { .. } | Self::Open { .. } => ErrorKind::Disconnected,
            Self::InvalidState { .. } => ErrorKind::InvalidState,
            Self::Clock => ErrorKind::Other,
        }
    }
}
