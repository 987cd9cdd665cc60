//! The three axis drives (q1 along Z0, q2 along Y0, q3 along X0): positions,
//! state and commands.

use crate::Error;
use sar_kinematics::ActiveJoints;

/// The drives' state, a reduced CiA 402 state machine.
///
/// `Ready --enable--> Enabled`; `Enabled --disable--> Ready`;
/// `Ready`, `Enabled` or `QuickStop --quick_stop--> QuickStop` (decelerate at
/// the limit, then hold); `QuickStop --disable--> Ready`; a fault from any state
/// `--> Fault`; `Fault --fault_reset--> Ready` once the cause is gone.
///
/// A fault is only ever cleared by `fault_reset`: in `Fault`, `quick_stop` is
/// accepted (the axes are already braking or stopped) but the state stays
/// `Fault`, and `disable` and `enable` are `ErrorKind::InvalidState`.
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
        /// Device-specific fault code.
        code: u16,
    },
}

/// The axes' positions at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointPositions {
    /// q1, q2, q3, metres.
    pub joints: ActiveJoints,
    /// Host monotonic time of the positions, ns.
    pub stamp_ns: u64,
    /// The drives' word that the positions are good (encoders healthy, no fault).
    pub valid: bool,
}

/// The three axis drives.
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

    /// Quick stop: decelerate at the limit and hold. Accepted in every state;
    /// in `Fault` the state stays `Fault`.
    fn quick_stop(&mut self) -> Result<(), Self::Error>;

    /// `Fault -> Ready` once the cause is gone; `ErrorKind::InvalidState` in
    /// another state, `ErrorKind::DeviceFault` while the cause persists.
    fn fault_reset(&mut self) -> Result<(), Self::Error>;
}
