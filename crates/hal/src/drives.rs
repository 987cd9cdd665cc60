//! The three axis drives (q1 along Z0, q2 along Y0, q3 along X0): positions,
//! state and commands.

use crate::Error;
use sar_kinematics::ActiveJoints;

/// The fault code of a drive lost on the bus (its heartbeat or PDOs
/// missing): CiA 301's life-guard EMCY code, shared by the CANopen host and
/// the simulator's drives.
pub const FAULT_HEARTBEAT_LOST: u16 = 0x8130;

/// The state of the three drives taken together, a reduced CiA 402 state machine.
///
/// `Ready --enable--> Enabled`; `Enabled --disable--> Ready`;
/// `Ready`, `Enabled` or `QuickStop --quick_stop--> QuickStop` (decelerate at
/// the limit, then hold); `QuickStop --disable--> Ready`; a fault from any state
/// `--> Fault`; `Fault --fault_reset--> Ready` once the cause is gone.
///
/// A fault is only ever cleared by `fault_reset`: in `Fault`, `quick_stop` is
/// accepted (the axes are already braking or stopped) but the state stays
/// `Fault`, and `disable` and `enable` are `ErrorKind::InvalidState`.
///
/// `QuickStop` is a latch: it is left only through `disable`, even where the
/// device itself would allow more (a CiA 402 adapter keeps it in software).
/// A fault on ANY axis is a fault of all three: the implementation brings the
/// other axes to a quick stop itself (a real driver must, the drives will not).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DriveState {
    /// Powered, not following targets.
    Ready,
    /// Following targets.
    Enabled,
    /// Stopped by a quick stop; holds position; targets are refused.
    QuickStop,
    /// Faulted, with the device's fault code; targets are refused.
    Fault {
        /// The axis that faulted (0 = q1, 1 = q2, 2 = q3), `None` when the
        /// device cannot tell or the fault is not an axis's own.
        axis: Option<u8>,
        /// Device-specific fault code.
        code: u16,
    },
}

/// The axes' positions at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointPositions {
    /// q1, q2, q3, metres.
    pub joints: ActiveJoints,
    /// Host monotonic time at which the positions were MEASURED (for a real
    /// drive: the receive time less the known transport delay), ns.
    pub stamp_ns: u64,
    /// The drives' word that the positions are good (encoders healthy, no fault).
    /// A position is valid only once every drive reports its absolute encoder
    /// referenced (the CANopen driver reads status word bit 15, see
    /// `sar_canopen::frame::STATUS_REFERENCED`); before, `valid` is false
    /// whatever the numbers say.
    pub valid: bool,
}

/// The three axis drives.
///
/// Commands are requests: a real drive needs several exchanges (CiA 402
/// controlword/statusword round trips) before its state changes, so a command
/// may return before `state()` shows the result. No call blocks beyond the
/// implementation's own bounded exchange time (a bus-based implementation such
/// as `sar_canopen::CanOpenDrives` exchanges with the devices only in its
/// own per-period `cycle`, which the caller runs). Targets are positions the drives
/// plan a limited-speed, limited-acceleration move to (profile position mode),
/// never set points they jump to.
pub trait AxisDrives {
    /// The implementation's error.
    type Error: Error;

    /// The latest positions. Never blocks.
    fn positions(&mut self) -> Result<JointPositions, Self::Error>;

    /// The drives' state.
    fn state(&mut self) -> Result<DriveState, Self::Error>;

    /// `Ready -> Enabled`; `ErrorKind::InvalidState` from `Fault` or `QuickStop`.
    fn enable(&mut self) -> Result<(), Self::Error>;

    /// `Enabled` or `QuickStop -> Ready` (the axes brake and stop following
    /// targets); `ErrorKind::InvalidState` in `Fault`.
    fn disable(&mut self) -> Result<(), Self::Error>;

    /// New target positions (q1, q2, q3 in metres). Only while `Enabled`
    /// (`ErrorKind::InvalidState` otherwise); non-finite or out-of-travel
    /// targets are `ErrorKind::InvalidArgument`.
    fn set_targets(&mut self, targets: ActiveJoints) -> Result<(), Self::Error>;

    /// Cyclic synchronous position (CiA 402 CSP): the axes are to be at
    /// `targets` `period_ns` from now, moving at constant speed, and hold
    /// there until the next set point; the caller streams one set point per
    /// period (force control, retreat moves at a reduced speed). Only while
    /// `Enabled`; non-finite or out-of-travel set points are
    /// `ErrorKind::InvalidArgument`, and so is a set point farther than an
    /// axis's speed limit allows in the period (a real drive would lose it
    /// and fault on its following error).
    fn stream(&mut self, targets: ActiveJoints, period_ns: u64) -> Result<(), Self::Error>;

    /// Quick stop: decelerate at the limit and hold. Accepted in every state;
    /// in `Fault` the state stays `Fault`.
    fn quick_stop(&mut self) -> Result<(), Self::Error>;

    /// `Fault -> Ready` once the cause is gone; `ErrorKind::InvalidState` in
    /// another state, `ErrorKind::DeviceFault` while the cause persists.
    fn fault_reset(&mut self) -> Result<(), Self::Error>;
}

// Snapshots (issue 17): the loop remembers the drives' previous state.
sar_snapshot::snap_enum!(DriveState {
    0 => Ready,
    1 => Enabled,
    2 => QuickStop,
    3 => Fault { axis, code },
});
