//! The six-axis force/torque sensor trait and its sample.

use crate::{Error, Vec3};

/// The device's own status word. Zero is "all good"; other bits are
/// device-specific (overload, temperature, ...) and make the sample invalid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct SensorStatus(pub u32);

impl SensorStatus {
    /// All good.
    pub const OK: Self = Self(0);

    /// Whether the device says the sample is good.
    pub fn is_ok(self) -> bool {
        self == Self::OK
    }
}

/// Where a saturated channel sits: an amplifier driven to its limit reads the
/// end of the measuring range, on one side or the other.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Rail {
    /// The positive end (+range).
    Positive,
    /// The negative end (-range).
    Negative,
}

impl Rail {
    /// +1.0 or -1.0.
    pub fn sign(self) -> f64 {
        match self {
            Self::Positive => 1.0,
            Self::Negative => -1.0,
        }
    }
}

/// The six channels of a force/torque sensor in their wire order: Fx, Fy, Fz,
/// Tx, Ty, Tz (sensor frame); `true` selects a channel.
pub type Channels = [bool; 6];

/// The channels' names in wire order, as scenario files and messages write them.
pub const CHANNEL_NAMES: [&str; 6] = ["fx", "fy", "fz", "tx", "ty", "tz"];

/// One force/torque sample, as the driver received it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WrenchSample {
    /// Force, sensor frame, N, after count scaling, before any bias removal.
    pub force_n: Vec3,
    /// Torque, sensor frame, N m.
    pub torque_nm: Vec3,
    /// The device's own sample counter (wraps at u32::MAX); a gap means samples
    /// were lost.
    pub counter: u32,
    /// The device's status for this sample.
    pub status: SensorStatus,
    /// Host monotonic time at which the sample was RECEIVED, ns (it was
    /// measured up to the sensor's latency earlier).
    pub received_ns: u64,
}

impl WrenchSample {
    /// Valid: the device says so and every number is finite.
    pub fn is_valid(&self) -> bool {
        self.status.is_ok()
            && self.force_n.iter().all(|x| x.is_finite())
            && self.torque_nm.iter().all(|x| x.is_finite())
    }

    /// Age of the sample at host time `now_ns` (0 for a sample from the future).
    pub fn age_ns(&self, now_ns: u64) -> u64 {
        now_ns.saturating_sub(self.received_ns)
    }
}

/// A six-axis force/torque sensor.
pub trait ForceSensor {
    /// The implementation's error.
    type Error: Error;

    /// The newest sample received since the last `poll` or `wait`, or `None`
    /// when nothing new arrived. Never blocks. Older unreturned samples are
    /// dropped (their loss shows as a gap in `counter`). An error means the
    /// sensor is known to be failing now (e.g. the RDT driver's silence
    /// beyond its limit, kind `Disconnected`): the caller must treat its last
    /// sample as invalid.
    fn poll(&mut self) -> Result<Option<WrenchSample>, Self::Error>;

    /// Waits at most `timeout_ns` for a sample newer than the last one returned,
    /// and returns it; `ErrorKind::Timeout` when none arrived in time.
    fn wait(&mut self, timeout_ns: u64) -> Result<WrenchSample, Self::Error>;

    /// Device-side tare: the device subtracts its present reading from later
    /// ones. `ErrorKind::Unsupported` where the device has no such command.
    fn tare(&mut self) -> Result<(), Self::Error>;

    /// Undoes the device-side tare. `ErrorKind::Unsupported` likewise.
    fn clear_tare(&mut self) -> Result<(), Self::Error>;

    /// The draining read, for the recorder: hands every sample received since
    /// the last `drain` into `out`, oldest first, and says how many
    /// ([`Drained::count`]). Never blocks.
    ///
    /// - Independent of `poll` and `wait`: those return the newest sample to
    ///   the control loop, this returns all of them to the recorder; neither
    ///   consumes the other's samples (a loop may call both every cycle).
    /// - Samples that do not fit in `out` stay for the next call
    ///   ([`Drained::remaining`] says how many wait); none is lost for that.
    /// - Bounded: an implementation keeps a fixed number of undrained samples.
    ///   Samples it had to drop because that store was full (a caller that
    ///   drains too rarely) are counted in [`Drained::lost`] of the next call,
    ///   never silently; which ones it drops is the implementation's (it says).
    /// - Samples lost before the driver received them show, as ever, as a
    ///   gap in `counter`.
    fn drain(&mut self, out: &mut [WrenchSample]) -> Result<Drained, Self::Error>;
}

/// What one [`ForceSensor::drain`] handed over.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Drained {
    /// Samples written at the start of the caller's buffer, oldest first.
    pub count: usize,
    /// Samples received but dropped since the previous `drain` because the
    /// driver's store of undrained samples was full.
    pub lost: u64,
    /// Samples still waiting after this call (the buffer was too small).
    pub remaining: usize,
}
