//! The shared-memory payloads, used by every process (`sard`, `sarctl`,
//! tests): flat `#[repr(C)]` fixed-size types, numbers only (numeric codes
//! for states and reasons, no enums with payloads, no references). The
//! estimator's types are converted here, at the edge.

use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use sar_estimator::guard::GuardState;

/// Flag bits of [`StateMsg::flags`].
pub mod flags {
    /// The kinematics gave a pose (q4, q5, A, D, a are meaningful).
    pub const POSE: u32 = 1;
    /// The tip force is a number.
    pub const ESTIMATE: u32 = 1 << 1;
    /// The estimate is observable (its deviation below the limit).
    pub const OBSERVABLE: u32 = 1 << 2;
    /// The sensor sample is a new one.
    pub const NEW_SAMPLE: u32 = 1 << 3;
    /// The drives are halted (quick stop sent, no reset since).
    pub const HALTED: u32 = 1 << 4;
    /// `truth_tip_force_n` holds the simulator's truth.
    pub const SIM_TRUTH: u32 = 1 << 5;
    /// The cycle's clock was read: `now_ns` is its time (else 0, and the
    /// recording stamps the cycle with the newer input stamp).
    pub const NOW: u32 = 1 << 6;
    /// The sensor sample was valid (the driver's word).
    pub const SENSOR_VALID: u32 = 1 << 7;
    /// The joint sample was valid (the driver's word).
    pub const JOINTS_VALID: u32 = 1 << 8;
    /// `tip_force_filtered_n` is the filter's output.
    pub const FILTERED: u32 = 1 << 9;
    /// The guard changed state in this cycle (`transition_*`).
    pub const TRANSITION: u32 = 1 << 10;
}

/// Sensor samples a [`StateMsg`] carries at most: every sample the loop
/// drained in the cycle (`sar_loop::control::DRAIN_CAPACITY`, checked at
/// compile time there), as the recorder writes them.
pub const STATE_SENSOR_SAMPLES: usize = 16;

/// A guard reason whole, with its facts: the `sar_snapshot::Snap` bytes of a
/// `sar_estimator::guard::Reason` ([`reason_bytes`]), so that a reader
/// writes the recording's sentence (`Display`) from the shared memory. All
/// zeros: none.
pub type ReasonBytes = [u8; REASON_BYTES];
/// The size of [`ReasonBytes`] (a reason takes at most 26: its tag and
/// three numbers).
pub const REASON_BYTES: usize = 64;

/// A reason as [`ReasonBytes`] (all zeros if it did not fit, which a test
/// rules out for every reason).
pub fn reason_bytes(reason: &sar_estimator::guard::Reason) -> ReasonBytes {
    use sar_snapshot::Snap;
    let mut out = [0u8; REASON_BYTES];
    let mut w = sar_snapshot::Writer::new(&mut out);
    reason.put(&mut w);
    if w.overflowed() {
        return [0u8; REASON_BYTES];
    }
    out
}

/// The reason of [`ReasonBytes`] (`None`: none, or bytes that are not one).
pub fn reason_of(bytes: &ReasonBytes) -> Option<sar_estimator::guard::Reason> {
    use sar_snapshot::Snap;
    if bytes.iter().all(|b| *b == 0) {
        return None;
    }
    sar_estimator::guard::Reason::get(&mut sar_snapshot::Reader::new(bytes)).ok()
}

/// Guard state codes: `GuardState::code` (Ok 0, Warn 1, Stop 2, Fault 3,
/// Retreat 4).
pub mod guard_code {
    use sar_estimator::guard::GuardState;
    /// Ok.
    pub const OK: u32 = GuardState::Ok.code() as u32;
    /// Warn.
    pub const WARN: u32 = GuardState::Warn.code() as u32;
    /// Stop (latched).
    pub const STOP: u32 = GuardState::Stop.code() as u32;
    /// Fault (latched).
    pub const FAULT: u32 = GuardState::Fault.code() as u32;
    /// Retreat.
    pub const RETREAT: u32 = GuardState::Retreat.code() as u32;
}

/// The guard state's code.
pub fn guard_state_code(s: GuardState) -> u32 {
    u32::from(s.code())
}

/// The guard state's name for a code.
pub fn guard_state_name(code: u32) -> &'static str {
    match u8::try_from(code).ok().and_then(GuardState::from_code) {
        Some(GuardState::Ok) => "ok",
        Some(GuardState::Warn) => "warn",
        Some(GuardState::Stop) => "stop",
        Some(GuardState::Fault) => "fault",
        Some(GuardState::Retreat) => "retreat",
        None => "unknown",
    }
}

/// The reason code's name (the estimator's table,
/// `sar_estimator::guard::REASONS`; 0 is "none").
pub fn reason_name(code: u32) -> &'static str {
    match u16::try_from(code) {
        Ok(0) => "none",
        Ok(code) => sar_estimator::guard::reason_name(code),
        Err(_) => "unknown",
    }
}

/// Drive state codes: the recording's (`DRIVE_*` of `CycleInput.msg`,
/// [`crate::msgs::DriveStateCode`]), one numbering for the wire, the recording and
/// `sarctl`.
pub mod drive_code {
    use crate::msgs::DriveStateCode;
    /// Powered, not following targets.
    pub const READY: u32 = DriveStateCode::Ready as u32;
    /// Following targets.
    pub const ENABLED: u32 = DriveStateCode::Enabled as u32;
    /// Quick stop.
    pub const QUICK_STOP: u32 = DriveStateCode::QuickStop as u32;
    /// Fault.
    pub const FAULT: u32 = DriveStateCode::Fault as u32;
    /// Unknown: not read in this cycle.
    pub const UNREAD: u32 = DriveStateCode::Unread as u32;
}

/// The name of a [`drive_code`] (the loop's `publish::drive_state_code`):
/// "unknown", "ready", "enabled", "quick_stop", "fault" (anything else:
/// "invalid").
pub fn drive_state_name(code: u32) -> &'static str {
    match code {
        drive_code::UNREAD => "unknown",
        drive_code::READY => "ready",
        drive_code::ENABLED => "enabled",
        drive_code::QUICK_STOP => "quick_stop",
        drive_code::FAULT => "fault",
        _ => "invalid",
    }
}

/// Force control modes of [`StateMsg::force_mode`].
pub mod force_mode {
    /// Position control (no force control).
    pub const POSITION: u32 = 0;
    /// A compliant hold.
    pub const HOLD: u32 = 1;
    /// An axial push.
    pub const PUSH: u32 = 2;

    /// The mode's name: "position", "hold", "push" (anything else:
    /// "position").
    pub fn name(mode: u32) -> &'static str {
        match mode {
            HOLD => "hold",
            PUSH => "push",
            _ => "position",
        }
    }
}

/// The state of one control cycle, published once per cycle.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
pub struct StateMsg {
    /// The cycle number.
    pub cycle: u64,
    /// The cycle's monotonic time, ns (0: the clock failed).
    pub now_ns: u64,
    /// The sensor sample's receive stamp, ns.
    pub sensor_stamp_ns: u64,
    /// The joint sample's stamp, ns.
    pub joints_stamp_ns: u64,
    /// Sensor age, ns (`u64::MAX`: unknown).
    pub sensor_age_ns: u64,
    /// Joints age, ns (`u64::MAX`: unknown).
    pub joints_age_ns: u64,
    /// q1, q2, q3, m.
    pub q_m: [f64; 3],
    /// q4, q5, rad.
    pub q45_rad: [f64; 2],
    /// A, the U-joint centre, base frame, m.
    pub ujoint_m: [f64; 3],
    /// D, the tip, base frame, m.
    pub tip_m: [f64; 3],
    /// a = |B - A|, m.
    pub support_distance_m: f64,
    /// F_A, N.
    pub ujoint_force_n: [f64; 3],
    /// F_tip, the force the tip applies to tissue, base frame, N.
    pub tip_force_n: [f64; 3],
    /// Its standard deviation per axis, N.
    pub tip_std_n: [f64; 3],
    /// Axial and lateral parts, N.
    pub tip_axial_lateral_n: [f64; 2],
    /// The simulator's true F_tip (with [`flags::SIM_TRUTH`]), N.
    pub truth_tip_force_n: [f64; 3],
    /// [`flags`] bits.
    pub flags: u32,
    /// [`guard_code`].
    pub guard_state: u32,
    /// The guard's reason code.
    pub guard_reason: u32,
    /// The drives' state, a [`drive_code`].
    pub drive_state: u32,
    /// Warn and stop limits: total, axial, lateral (warn, stop each), N:
    /// `sar_estimator::guard::ForceLimits::to_array`, named by its `NAMES`.
    pub limits_n: [f64; 6],
    /// Wake-up latency p50, p99, max, ns.
    pub wakeup_ns: [u64; 3],
    /// Compute time p50, p99, max, ns.
    pub compute_ns: [u64; 3],
    /// Overruns so far.
    pub overruns: u64,
    /// Quick stops sent so far.
    pub quick_stops: u64,
    /// States the loop dropped so far because the publishing thread's queue
    /// was full (those states were never published).
    pub publish_queue_drops: u64,
    /// States the publishing thread failed to send so far.
    pub publish_errors: u64,
    /// Messages the recorder dropped so far (queue full or disk failed).
    pub recorder_drops: u64,
    /// The recording's state ([`recording_code`]): 1 while a recording
    /// runs, 0 when none does; a failed recording (a write error, e.g. a
    /// full disk, which stopped it) until the next start.
    pub recording: u64,
    /// The simulator's time of `truth_tip_force_n` (ns from the simulator's
    /// start, the time axis of the scenario file), when `SIM_TRUTH`; else 0.
    /// Lets a test measure a detection time from a scripted fault's onset.
    pub truth_elapsed_ns: u64,
    /// The cycle of the last guarded move's stop (0: none yet).
    pub guarded_stop_cycle: u64,
    /// Where the tip was then, base frame, m.
    pub guarded_stop_tip_m: [f64; 3],
    /// The tip force that stopped it, base frame, N.
    pub guarded_stop_force_n: [f64; 3],
    /// Force control: [`force_mode`].
    pub force_mode: u32,
    /// Its setpoint, N (hold: the force; push: the axial force).
    pub force_setpoint_n: f64,

    // What the recorder writes of the cycle beyond the above (issue 37: a
    // reader such as `sar-ros2` makes the recording's messages of it, bit
    // for bit; `sar_scene::topics::messages`).
    /// The torsion about the rod, N m (with [`flags::ESTIMATE`]).
    pub torsion_nm: f64,
    /// The causal filtered F_tip, base frame, N (with [`flags::FILTERED`]).
    pub tip_force_filtered_n: [f64; 3],
    /// The support's friction on the rod in the simulator's truth, N (with
    /// [`flags::SIM_TRUTH`]): `truth_tip_force_n` less it is what the
    /// recording's `/sar/sim/tip_wrench_truth` holds.
    pub truth_friction_n: [f64; 3],
    /// The cycle the guard's transition names (with [`flags::TRANSITION`]).
    pub transition_cycle: u64,
    /// The state it left ([`guard_code`]).
    pub transition_from: u32,
    /// The state it entered ([`guard_code`]).
    pub transition_to: u32,
    /// What became of the tip force, the recording's `TIP_*` code
    /// (`sar_msgs::msgs::TipOutcomeCode`).
    pub tip_outcome: u32,
    /// How many of `sensor_*` hold samples: every sensor sample received
    /// since the previous cycle, oldest first.
    pub sensor_samples: u32,
    /// Each sample's receive stamp, ns.
    pub sensor_received_ns: [u64; STATE_SENSOR_SAMPLES],
    /// Each sample's force, sensor frame, N.
    pub sensor_force_n: [[f64; 3]; STATE_SENSOR_SAMPLES],
    /// Each sample's torque, sensor frame, N m.
    pub sensor_torque_nm: [[f64; 3]; STATE_SENSOR_SAMPLES],
    /// The guard's reason, whole ([`reason_of`]).
    pub guard_reason_bytes: ReasonBytes,
    /// The transition's reason, whole ([`reason_of`]).
    pub transition_reason_bytes: ReasonBytes,
    /// The cycle time (`now_ns`) of the guard's newest transition since
    /// `sard` started (0: none yet). With `now_ns` and `truth_elapsed_ns`
    /// it times a detection exactly from any later state, whichever states
    /// a reader missed.
    pub guard_changed_ns: u64,
    /// The inertia watch (issue 34): what it has named, bit 0 I_perp, bit 1
    /// the adapter's mass (0: nothing).
    pub inertia_named: u32,
    /// What the free motion implies: I_perp and its standard error, kg m^2;
    /// the adapter's mass m_s and its standard error, kg (the configured
    /// values and infinite errors before any free motion).
    pub inertia_implied: [f64; 4],

    // The support watch (issue 34 section 3): the support's shift that the
    // free-tip samples at varying poses show.
    /// B_true - B_configured as estimated, base frame, m.
    pub support_shift_m: [f64; 3],
    /// Its standard error per base axis, m (a component above
    /// `support_max_std_m` is not determined).
    pub support_std_m: [f64; 3],
    /// The verdict: 0 not run, 1 could not run (not a free tip), 2 within
    /// the limit, 3 shifted beyond it (force control refused until `sarctl
    /// support confirm`).
    pub support_verdict: u32,
    /// Chi-square per degree of freedom of the fit.
    pub support_chi2_dof: f64,
    /// Forgetting-weighted free samples behind it.
    pub support_samples: f64,
    /// `[support] max_shift_m` and `max_std_m`, m.
    pub support_limits_m: [f64; 2],

    // The servo observer (issue 34 section 1): how far the axes follow the
    // loop's servo model.
    /// The encoders less the model's position, RMS per axis (q1, q2, q3)
    /// over the last `sar_loop::observer::FIT_WINDOW_S` of motion, m.
    pub servo_follow_rms_m: [f64; 3],
    /// The acceleration the observer adds to the model's, per axis, m/s^2.
    pub servo_disturbance_mps2: [f64; 3],
    /// [`servo_fit`] bits: named (the drives do not follow the model: run
    /// `sarctl identify --servo`), and the axes the observer is engaged on.
    pub servo_fit: u32,
}

/// The bits of [`StateMsg::servo_fit`].
pub mod servo_fit {
    /// The servo mismatch is named: the drives do not follow the loop's
    /// servo model (run `sarctl identify --servo`).
    pub const NAMED: u32 = 1;
    /// The observer's motion is handed on for q1 (the encoder left the
    /// model); `ENGAGED_Q1 << 1` for q2, `<< 2` for q3.
    pub const ENGAGED_Q1: u32 = 2;
}

impl Default for StateMsg {
    fn default() -> Self {
        Self {
            cycle: 0,
            now_ns: 0,
            sensor_stamp_ns: 0,
            joints_stamp_ns: 0,
            sensor_age_ns: u64::MAX,
            joints_age_ns: u64::MAX,
            q_m: [0.0; 3],
            q45_rad: [0.0; 2],
            ujoint_m: [0.0; 3],
            tip_m: [0.0; 3],
            support_distance_m: 0.0,
            ujoint_force_n: [0.0; 3],
            tip_force_n: [0.0; 3],
            tip_std_n: [0.0; 3],
            tip_axial_lateral_n: [0.0; 2],
            truth_tip_force_n: [0.0; 3],
            flags: 0,
            guard_state: guard_code::FAULT,
            guard_reason: 0,
            drive_state: drive_code::UNREAD,
            limits_n: [0.0; 6],
            wakeup_ns: [0; 3],
            compute_ns: [0; 3],
            overruns: 0,
            quick_stops: 0,
            publish_queue_drops: 0,
            publish_errors: 0,
            recorder_drops: 0,
            recording: 0,
            truth_elapsed_ns: 0,
            guarded_stop_cycle: 0,
            guarded_stop_tip_m: [0.0; 3],
            guarded_stop_force_n: [0.0; 3],
            force_mode: 0,
            force_setpoint_n: 0.0,
            torsion_nm: 0.0,
            tip_force_filtered_n: [0.0; 3],
            truth_friction_n: [0.0; 3],
            transition_cycle: 0,
            transition_from: 0,
            transition_to: 0,
            tip_outcome: 0,
            sensor_samples: 0,
            sensor_received_ns: [0; STATE_SENSOR_SAMPLES],
            sensor_force_n: [[0.0; 3]; STATE_SENSOR_SAMPLES],
            sensor_torque_nm: [[0.0; 3]; STATE_SENSOR_SAMPLES],
            guard_reason_bytes: [0; REASON_BYTES],
            transition_reason_bytes: [0; REASON_BYTES],
            guard_changed_ns: 0,
            inertia_named: 0,
            inertia_implied: [0.0; 4],
            support_shift_m: [0.0; 3],
            support_std_m: [0.0; 3],
            support_verdict: 0,
            support_chi2_dof: 0.0,
            support_samples: 0.0,
            support_limits_m: [0.0; 2],
            servo_follow_rms_m: [0.0; 3],
            servo_disturbance_mps2: [0.0; 3],
            servo_fit: 0,
        }
    }
}

impl StateMsg {
    /// |F_tip|, the total tip force, N.
    pub fn tip_force_norm_n(&self) -> f64 {
        let [x, y, z] = self.tip_force_n;
        (x * x + y * y + z * z).sqrt()
    }

    /// The guard's limits in use, named (from [`StateMsg::limits_n`]).
    pub fn limits(&self) -> sar_estimator::guard::ForceLimits {
        sar_estimator::guard::ForceLimits::from_array(self.limits_n)
    }

    /// The drives follow targets ([`drive_code::ENABLED`]).
    pub fn drives_enabled(&self) -> bool {
        self.drive_state == drive_code::ENABLED
    }
}

pub use crate::msgs::command::{
    COMMAND_MSG_TYPE_NAME, COMMAND_MSG_VERSION, CommandMsg, command_kind,
};

/// What became of a request. The numbers are the wire codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u16)]
pub enum ReplyStatus {
    /// Done.
    Accepted = 0,
    /// A reset while nothing was latched.
    NothingToReset = 1,
    /// A reset refused: its cause persists (the reason code says which).
    ResetRefused = 2,
    /// A tare outside `Ok`.
    NotOk = 3,
    /// A tare with a force above a warn limit.
    AboveWarn = 4,
    /// A tare without an estimate, or whose bias cannot be solved.
    NoEstimate = 5,
    /// A move while the drives are halted (Stop or Fault not yet reset).
    Halted = 6,
    /// A move the kinematics cannot reach, or outside the travel.
    Unreachable = 7,
    /// A move deeper along the tip force while it is above the warn limit.
    TowardForce = 8,
    /// A move while the drives are not enabled (they report another state,
    /// or could not be read).
    DrivesRefused = 9,
    /// Refused for another reason.
    Refused = 10,
    /// Force limits that are invalid or above their configured ceiling.
    LimitsRefused = 11,
    /// A reset while the axes still move (braking after a quick stop, or
    /// drives that have not stopped): the trajectory to hold would not be
    /// theirs. Wait until they are at rest.
    AxesMoving = 12,
    /// A move in Retreat that does not reduce the tip force.
    NotReducing = 13,
    /// A move that was judged acceptable but could not be given to the
    /// drives in the same cycle (it was not carried out).
    NotCarriedOut = 14,
    /// A request whose argument is not valid (e.g. a back-out distance).
    BadArgument = 15,
    /// A reset while the drives are in Fault: their fault was reset (their
    /// positions are invalid while they are faulted, so the guard could not
    /// judge the reset); reset again once they report Ready.
    DrivesFaultReset = 16,
}

/// Reply status codes beyond [`ReplyStatus`] (whose numbers are kept).
pub mod reply_code {
    /// The command kind is unknown.
    pub const UNKNOWN_COMMAND: u32 = 100;
    /// The loop's request queue is full.
    pub const BUSY: u32 = 101;
    /// `record start|stop`: the start was refused, or the recording failed
    /// (the detail says why).
    pub const RECORD_FAILED: u32 = 102;
}

/// The values of [`StateMsg::recording`].
pub mod recording_code {
    /// No recording runs (the last one, if any, was closed complete).
    pub const OFF: u64 = 0;
    /// A recording runs.
    pub const ON: u64 = 1;
    /// The last recording failed (a write error stopped it; its file is
    /// incomplete); the OS error number (errno, 0: none) is in the upper
    /// 32 bits.
    pub const FAILED: u64 = 2;

    /// The code of a recording failed with OS error `errno`.
    pub const fn failed(errno: u32) -> u64 {
        FAILED | ((errno as u64) << 32)
    }
    /// The state of a code: [`OFF`], [`ON`] or [`FAILED`].
    pub const fn state(code: u64) -> u64 {
        code & 0xffff_ffff
    }
    /// Whether a recording runs.
    pub const fn is_on(code: u64) -> bool {
        state(code) == ON
    }
    /// Whether the last recording failed.
    pub const fn is_failed(code: u64) -> bool {
        state(code) == FAILED
    }
    /// The OS error of a failed recording's code (0: none named).
    pub const fn errno(code: u64) -> u32 {
        (code >> 32) as u32
    }
}

/// The reply to a command.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
pub struct ReplyMsg {
    /// The command's id.
    pub id: u64,
    /// The cycle that judged it.
    pub cycle: u64,
    /// [`ReplyStatus`] as a number, or a [`reply_code`].
    pub status: u32,
    /// The guard's reason code behind a refusal.
    pub reason: u32,
    /// The guard's limits (warn, stop for total, axial, lateral), N.
    pub limits_n: [f64; 6],
    /// The exact cause, UTF-8, zero-padded (cut at a character boundary).
    pub detail: [u8; DETAIL_LEN],
}

/// Bytes of [`ReplyMsg::detail`].
pub const DETAIL_LEN: usize = 256;

impl Default for ReplyMsg {
    fn default() -> Self {
        Self {
            id: 0,
            cycle: 0,
            status: 0,
            reason: 0,
            limits_n: [0.0; 6],
            detail: [0; DETAIL_LEN],
        }
    }
}

/// Writes text into a fixed buffer, cutting at a character boundary (no
/// allocation).
struct FixedText<'a> {
    buf: &'a mut [u8],
    len: usize,
}

impl std::fmt::Write for FixedText<'_> {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        for c in s.chars() {
            let mut tmp = [0u8; 4];
            let bytes = c.encode_utf8(&mut tmp).as_bytes();
            let end = self.len + bytes.len();
            let Some(slot) = self.buf.get_mut(self.len..end) else {
                return Err(std::fmt::Error);
            };
            slot.copy_from_slice(bytes);
            self.len = end;
        }
        Ok(())
    }
}

impl ReplyMsg {
    /// A reply with its detail written from `detail` (cut at a character
    /// boundary when longer than [`DETAIL_LEN`] bytes; no allocation).
    pub fn with_detail(
        id: u64,
        cycle: u64,
        status: u32,
        reason: u32,
        limits_n: [f64; 6],
        detail: core::fmt::Arguments<'_>,
    ) -> Self {
        let mut reply = Self {
            id,
            cycle,
            status,
            reason,
            limits_n,
            detail: [0u8; DETAIL_LEN],
        };
        reply.write_detail(detail);
        reply
    }

    /// Sets the detail to `text` (cut at a character boundary when longer
    /// than [`DETAIL_LEN`] bytes).
    pub fn set_detail(&mut self, text: &str) {
        self.write_detail(format_args!("{text}"));
    }

    /// The one writer of the fixed detail buffer: cleared, then filled with
    /// what fits (a cut detail is fine; no allocation).
    fn write_detail(&mut self, detail: core::fmt::Arguments<'_>) {
        self.detail = [0u8; DETAIL_LEN];
        let mut w = FixedText {
            buf: &mut self.detail,
            len: 0,
        };
        let _ = std::fmt::Write::write_fmt(&mut w, detail);
    }

    /// The exact cause as text ("" when none).
    pub fn detail_text(&self) -> &str {
        let end = self
            .detail
            .iter()
            .position(|b| *b == 0)
            .unwrap_or(DETAIL_LEN);
        let bytes = self.detail.get(..end).unwrap_or(&[]);
        std::str::from_utf8(bytes).unwrap_or("")
    }
}

/// The name of a reply status code.
pub fn status_name(code: u32) -> &'static str {
    match code {
        x if x == ReplyStatus::Accepted as u32 => "accepted",
        x if x == ReplyStatus::NothingToReset as u32 => "nothing to reset",
        x if x == ReplyStatus::ResetRefused as u32 => "reset refused: the cause persists",
        x if x == ReplyStatus::NotOk as u32 => "refused: the guard is not ok",
        x if x == ReplyStatus::AboveWarn as u32 => "refused: the tip force is above a warn limit",
        x if x == ReplyStatus::NoEstimate as u32 => "refused: no tip-force estimate",
        x if x == ReplyStatus::Halted as u32 => "refused: the drives are halted (reset first)",
        x if x == ReplyStatus::Unreachable as u32 => "refused: the tip position cannot be reached",
        x if x == ReplyStatus::TowardForce as u32 => {
            "refused: the move pushes deeper along the tip force above the warn limit"
        }
        x if x == ReplyStatus::DrivesRefused as u32 => "refused: the drives are not enabled",
        x if x == ReplyStatus::LimitsRefused as u32 => {
            "refused: limits invalid or above their configured ceiling"
        }
        x if x == ReplyStatus::AxesMoving as u32 => {
            "reset refused: the axes are still moving (wait until they stop)"
        }
        x if x == ReplyStatus::NotReducing as u32 => {
            "refused: in retreat only motions that reduce the tip force are accepted"
        }
        x if x == ReplyStatus::NotCarriedOut as u32 => "refused: the move was not carried out",
        x if x == ReplyStatus::BadArgument as u32 => "refused: invalid argument",
        x if x == ReplyStatus::DrivesFaultReset as u32 => {
            "the drives' fault was reset: reset again once they are ready"
        }
        reply_code::UNKNOWN_COMMAND => "unknown command",
        reply_code::BUSY => "refused: the daemon's command queue is full",
        reply_code::RECORD_FAILED => "the recording failed",
        _ => "refused",
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]
    use super::*;

    #[test]
    fn a_detail_is_cut_at_a_character_boundary_and_replaced_whole() {
        // 255 ASCII bytes then a 2-byte character: the character does not
        // fit and is left out whole.
        let long = format!("{}é", "a".repeat(DETAIL_LEN - 1));
        let mut reply = ReplyMsg::with_detail(1, 2, 0, 0, [0.0; 6], format_args!("{long}"));
        assert_eq!(reply.detail_text(), "a".repeat(DETAIL_LEN - 1));
        // A shorter detail leaves nothing of the longer one behind.
        reply.set_detail("ré");
        assert_eq!(reply.detail_text(), "ré");
        assert!(reply.detail[3..].iter().all(|b| *b == 0));
        assert_eq!((reply.id, reply.cycle), (1, 2));
    }

    #[test]
    fn a_reason_travels_whole_and_its_sentence_is_the_same() {
        use sar_estimator::guard::{Axis, ForcePart, Reason, RestResidual, SensorChannel};
        // The reasons with the most facts (a tag and up to three numbers),
        // extreme values, and one without facts.
        let reasons = [
            Reason::TorqueImplausible {
                axis: Axis::Z,
                residual_nm: -f64::MAX,
                std_nm: f64::MIN_POSITIVE,
                max_sigma: 7.0,
            },
            Reason::MountingMismatch {
                residual: RestResidual::Torque(Axis::Y),
                value: 8.2,
                allowed: 1.2,
            },
            Reason::SensorSaturated {
                channel: SensorChannel::Tx,
                value: f64::INFINITY,
                range: 1e300,
            },
            Reason::AboveStop {
                part: ForcePart::Lateral,
                force_n: 12.345_678_9,
                limit_n: 10.0,
            },
            Reason::CycleOutOfOrder {
                previous: u64::MAX,
                got: 0,
            },
            Reason::Reset,
        ];
        for r in reasons {
            let bytes = reason_bytes(&r);
            assert!(bytes.iter().any(|b| *b != 0), "{r:?} did not fit");
            let back = reason_of(&bytes).unwrap();
            assert_eq!(back, r);
            assert_eq!(format!("{back}"), format!("{r}"));
        }
        assert_eq!(reason_of(&[0; REASON_BYTES]), None);
        assert_eq!(StateMsg::default().guard_reason_bytes, [0; REASON_BYTES]);
    }
}
