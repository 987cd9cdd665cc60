//! The one pass-through drive wrapper of the tests: [`Hooked`] forwards every
//! [`AxisDrives`] call to the drives it wraps, except the calls its
//! [`DriveHook`] takes over (each hook method's default forwards). A test's
//! faulty drives are a hook of a few lines: a blocked axis ignores set
//! points, flaky drives refuse a quick stop, a tap records the truth.

use sar_hal::{AxisDrives, DriveState, JointPositions};
use sar_kinematics::ActiveJoints;

/// What a test changes of the drives it wraps: every method forwards to
/// `inner` unless overridden.
pub trait DriveHook<D: AxisDrives> {
    /// [`AxisDrives::positions`].
    fn positions(&mut self, inner: &mut D) -> Result<JointPositions, D::Error> {
        inner.positions()
    }
    /// [`AxisDrives::state`].
    fn state(&mut self, inner: &mut D) -> Result<DriveState, D::Error> {
        inner.state()
    }
    /// [`AxisDrives::enable`].
    fn enable(&mut self, inner: &mut D) -> Result<(), D::Error> {
        inner.enable()
    }
    /// [`AxisDrives::disable`].
    fn disable(&mut self, inner: &mut D) -> Result<(), D::Error> {
        inner.disable()
    }
    /// [`AxisDrives::set_targets`].
    fn set_targets(&mut self, inner: &mut D, targets: ActiveJoints) -> Result<(), D::Error> {
        inner.set_targets(targets)
    }
    /// [`AxisDrives::stream`].
    fn stream(
        &mut self,
        inner: &mut D,
        targets: ActiveJoints,
        period_ns: u64,
    ) -> Result<(), D::Error> {
        inner.stream(targets, period_ns)
    }
    /// [`AxisDrives::quick_stop`].
    fn quick_stop(&mut self, inner: &mut D) -> Result<(), D::Error> {
        inner.quick_stop()
    }
    /// [`AxisDrives::fault_reset`].
    fn fault_reset(&mut self, inner: &mut D) -> Result<(), D::Error> {
        inner.fault_reset()
    }
}

/// Drives `inner` with `hook` taking over some calls.
pub struct Hooked<D, H> {
    /// The wrapped drives.
    pub inner: D,
    /// What the test changes (and counts).
    pub hook: H,
}

impl<D, H> Hooked<D, H> {
    /// `inner` with `hook`.
    pub fn new(inner: D, hook: H) -> Self {
        Self { inner, hook }
    }
}

impl<D: AxisDrives, H: DriveHook<D>> AxisDrives for Hooked<D, H> {
    type Error = D::Error;
    fn positions(&mut self) -> Result<JointPositions, D::Error> {
        self.hook.positions(&mut self.inner)
    }
    fn state(&mut self) -> Result<DriveState, D::Error> {
        self.hook.state(&mut self.inner)
    }
    fn enable(&mut self) -> Result<(), D::Error> {
        self.hook.enable(&mut self.inner)
    }
    fn disable(&mut self) -> Result<(), D::Error> {
        self.hook.disable(&mut self.inner)
    }
    fn stream(&mut self, targets: ActiveJoints, period_ns: u64) -> Result<(), D::Error> {
        self.hook.stream(&mut self.inner, targets, period_ns)
    }
    fn set_targets(&mut self, targets: ActiveJoints) -> Result<(), D::Error> {
        self.hook.set_targets(&mut self.inner, targets)
    }
    fn quick_stop(&mut self) -> Result<(), D::Error> {
        self.hook.quick_stop(&mut self.inner)
    }
    fn fault_reset(&mut self) -> Result<(), D::Error> {
        self.hook.fault_reset(&mut self.inner)
    }
}
