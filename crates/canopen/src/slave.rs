//! A simulated CiA 402 drive: a CANopen slave (NMT, expedited SDO server,
//! SYNC, one TPDO and one RPDO with configurable mapping, heartbeat producer
//! and consumer, EMCY) in front of one axis of the simulator's model (the
//! motion planner and its speed and acceleration limits).
//!
//! Motion: in cyclic synchronous position mode the drive takes the target of
//! the RPDO received since the last SYNC at each SYNC; between SYNCs its
//! interpolator EXTRAPOLATES at the last set-point velocity (the worst case a
//! real drive's interpolator may do: a host that stops sending leaves the axis
//! moving until the drive's own watchdog acts; the extrapolation speed is
//! clamped to the speed limit).
//!
//! The drive's own limits, stored as a real drive stores them (SDO, reset to
//! their defaults by an NMT reset node) and enforced on every set point,
//! whatever the host checked:
//! - software position limits (0x607D sub 1 min, sub 2 max, counts; default
//!   none): a target beyond them is CLAMPED at the limit, and status word
//!   bit 11 (internal limit active, [`STATUS_INTERNAL_LIMIT`]) is set while
//!   it is;
//! - max profile velocity (0x607F, counts/s; default none): a set point
//!   implying a higher speed since the last SYNC is approached at that speed
//!   (bit 11 set while limited); the axis then lags its set point;
//! - following error window and time out (0x6065 counts, default
//!   [`FOLLOWING_WINDOW_M`] or the spec's; 0x6066 ms, default 0): the actual
//!   position farther than the window from the (clamped) set point for the
//!   time out or longer is a following error (EMCY 0x8611, Fault); a set
//!   point that jumps farther than the window from the previous one is one
//!   at once;
//! - quick stop deceleration (0x6085, counts/s^2; default the spec's
//!   acceleration limit): the quick stop ramp;
//! - profile deceleration (0x6084, counts/s^2; default the spec's
//!   acceleration limit): the slow down ramp;
//! - max torque (0x6072, per mille of the rated torque; default 1000):
//!   stored and read back only (this model has no load, so no torque).
//!
//! How it stops, as CiA 402's option codes say (stored as the limits are),
//! each honoured:
//! - quick stop (0x605A; default 2): 0 the motor free (it coasts on at its
//!   speed: this model has no friction), 1 and 5 the slow down ramp, 2 and
//!   6 the quick stop ramp, 3, 4, 7, 8 (current or voltage limit) braking
//!   at the acceleration limit; 0 to 4 then Switch on disabled, 5 to 8 stay
//!   in Quick stop active;
//! - shutdown (0x605B, Operation enabled to Ready to switch on) and
//!   disable operation (0x605C, to Switched on): 0 the motor free
//!   (coasting), 1 the slow down ramp; default 0, as a drive that coasts;
//! - fault reaction (0x605E): 0 the motor free (coasting; the default, as
//!   many drives'), 1 the slow down ramp, 2 the quick stop ramp, 3 and 4
//!   braking at the acceleration limit;
//! - abort connection (0x6007; default 1): with the host's heartbeat
//!   configured in 0x1016, a heartbeat older than the consumer time sends
//!   EMCY 0x8130 and acts: 1 a fault (its reaction as 0x605E says), 2 a
//!   disable voltage, 3 a quick stop (as 0x605A says), 0 nothing.
//!
//! Halt and disable voltage brake at the acceleration limit (the planner's
//! `brake`) and hold (a real drive's disable voltage leaves the motor free;
//! this model keeps the brake the host never relies on).
//!
//! The encoder is absolute and multiturn; the drive reports it referenced in
//! status word bit 15 ([`STATUS_REFERENCED`]), cleared by
//! [`SimCia402Drive::set_referenced`] in tests.
//!
//! Faults on demand: besides the test hooks that act at once
//! ([`SimCia402Drive::inject_fault`], [`SimCia402Drive::set_silent`]), faults
//! scheduled at a time of the drive's clock ([`SimDriveFault`]: a heartbeat
//! producer that stops, an EMCY and Fault), fired by the first tick at or
//! after their time, so that a test on the in-memory bus (or a scenario's
//! `drive_heartbeat_loss` and `drive_emcy`, as `tests/canopen.rs` maps them)
//! is deterministic.

use crate::frame::{
    COB_EMCY, COB_HEARTBEAT, COB_NMT, COB_RPDO1, COB_SDO_RX, COB_SDO_TX, COB_SYNC, COB_TPDO1,
    Cia402State, EMCY_FOLLOWING_ERROR, EMCY_HEARTBEAT, Emcy, MODE_CSP, RawFrame, SDO_ABORT_COMMAND,
    SDO_ABORT_NO_OBJECT, SDO_ABORT_RANGE, SDO_ABORT_STATE, STATUS_INTERNAL_LIMIT,
    STATUS_REFERENCED, STATUS_REMOTE, Sdo, control, heartbeat, mapping, nmt, od,
};
use embedded_can::nb::Can;
use sar_hal::motion::{AxisPlan, AxisState, Limits};

/// The default following error window of the simulated drive (0x6065 at
/// power-on), m: wide enough for a host that runs a few ms late, small beside
/// any real jump. The host writes its own (`CanOpenConfig::following_window_m`).
pub const FOLLOWING_WINDOW_M: f64 = 0.002;

/// A fault of a simulated drive at a time of its clock, ns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum SimDriveFault {
    /// From `at_ns` the drive's heartbeat producer is silent; everything else
    /// (TPDOs, SDO, EMCY, its CiA 402 state) goes on, so only the host's
    /// heartbeat supervision sees it. [`SimCia402Drive::clear_fault_cause`]
    /// brings the heartbeat back.
    HeartbeatLoss {
        /// When, the drive's clock, ns.
        at_ns: u64,
    },
    /// At `at_ns` the drive faults: it brakes, enters Fault and sends an EMCY
    /// with `code`; a `persistent` cause survives fault resets until
    /// [`SimCia402Drive::clear_fault_cause`].
    Emcy {
        /// When, the drive's clock, ns.
        at_ns: u64,
        /// The EMCY error code.
        code: u16,
        /// Whether the cause persists.
        persistent: bool,
    },
}

impl SimDriveFault {
    /// When it fires, ns.
    pub fn at_ns(&self) -> u64 {
        match *self {
            Self::HeartbeatLoss { at_ns } | Self::Emcy { at_ns, .. } => at_ns,
        }
    }
}

/// The simulated drive's parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimDriveSpec {
    /// CANopen node id (1..=127).
    pub node_id: u8,
    /// Carriage travel per motor turn, m.
    pub lead_m: f64,
    /// Encoder counts per turn.
    pub counts_per_turn: u32,
    /// The axis's speed limit, m/s.
    pub max_speed_mps: f64,
    /// The axis's acceleration limit (also the quick stop deceleration), m/s^2.
    pub max_accel_mps2: f64,
    /// Position at power-on, m.
    pub start_m: f64,
    /// The following error window at power-on and after a reset node
    /// (0x6065's default), m ([`FOLLOWING_WINDOW_M`] unless a test on a
    /// non-real-time host needs more); a host that writes 0x6065 replaces it.
    pub following_window_m: f64,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Motion {
    /// CSP: at `x_m` at `at_ns`, extrapolating at `v_mps`.
    Follow { x_m: f64, v_mps: f64, at_ns: u64 },
    /// A planned brake or hold.
    Plan(AxisPlan),
}

#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct PdoParams {
    cob_id: u32,
    transmission: u8,
    map: [u32; 8],
    count: u8,
}

impl PdoParams {
    fn disabled(cob: u16) -> Self {
        Self {
            cob_id: 0x8000_0000 | u32::from(cob),
            transmission: 0xFF,
            ..Self::default()
        }
    }
    fn enabled(&self) -> bool {
        self.cob_id & 0x8000_0000 == 0 && self.count > 0
    }
    fn entries(&self) -> &[u32] {
        self.map.get(..usize::from(self.count)).unwrap_or(&[])
    }
}

/// The option codes of how a drive stops (CiA 402), as a drive stores them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StopOptions {
    /// 0x605A.
    pub quick_stop: i16,
    /// 0x605B.
    pub shutdown: i16,
    /// 0x605C.
    pub disable_operation: i16,
    /// 0x605E.
    pub fault_reaction: i16,
    /// 0x6007.
    pub abort_connection: i16,
}

/// How the axis is brought to rest by an option code's reaction.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Ramp {
    /// The motor free: the axis coasts on.
    Coast,
    /// The slow down ramp (0x6084).
    SlowDown,
    /// The quick stop ramp (0x6085).
    QuickStop,
    /// At the current or voltage limit: the acceleration limit here.
    Limit,
}

/// One simulated CiA 402 drive (see the module doc).
#[derive(Debug, Clone)]
pub struct SimCia402Drive {
    spec: SimDriveSpec,
    limits: Limits,
    nmt_state: u8,
    state: Cia402State,
    tpdo: PdoParams,
    rpdo: PdoParams,
    mode: i8,
    abort_option: i16,
    quick_stop_option: i16,
    /// 0x605B.
    shutdown_option: i16,
    /// 0x605C.
    disable_option: i16,
    /// 0x605E.
    fault_reaction: i16,
    consumer: u32,
    producer_ms: u16,
    controlword: u16,
    controlword_pending: Option<u16>,
    target_counts: i32,
    rpdo_pending: bool,
    motion: Motion,
    referenced: bool,
    silent: bool,
    fault_code: u16,
    fault_persists: bool,
    host_heartbeat_ns: Option<u64>,
    heartbeat_event: bool,
    next_heartbeat_ns: u64,
    boot_pending: bool,
    emcys: Vec<u16>,
    syncs: u64,
    /// Faults scheduled and not yet fired.
    scheduled: Vec<SimDriveFault>,
    /// The heartbeat producer is silent.
    heartbeat_lost: bool,
    /// TPDOs still to hold back (a busy bus: late past their SYNC's window).
    tpdos_to_skip: u32,
    /// The drive's own limits (0x6085, 0x607D, 0x607F, 0x6065, 0x6066, 0x6072).
    own: OwnLimits,
    /// The last set point followed (clamped), m; `None` after a brake or an
    /// enable (the next one is compared with the actual position).
    last_target_m: Option<f64>,
    /// Since when the actual position is beyond the following window, ns.
    following_since_ns: Option<u64>,
    /// Status word bit 11: a set point clamped or speed-limited now.
    internal_limit: bool,
    /// The time of the last SYNC taken in Operation enabled, ns.
    last_sync_ns: Option<u64>,
    /// Test hook: a write of (index, sub) stores this value instead.
    store_instead: Option<(u16, u8, u32)>,
}

/// The drive's own limits as stored in its object dictionary (drive units:
/// counts, counts/s, counts/s^2, ms, per mille).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct OwnLimits {
    quick_stop_decel: u32,
    profile_decel: u32,
    position_min: i32,
    position_max: i32,
    max_velocity: u32,
    following_window: u32,
    following_timeout_ms: u16,
    max_torque: u16,
}

impl OwnLimits {
    /// The defaults at power-on and after an NMT reset node.
    fn defaults(spec: &SimDriveSpec) -> Self {
        let count = spec.lead_m / f64::from(spec.counts_per_turn.max(1));
        // Saturating float-to-int conversions.
        Self {
            quick_stop_decel: ((spec.max_accel_mps2 / count).round() as u32).max(1),
            profile_decel: ((spec.max_accel_mps2 / count).round() as u32).max(1),
            position_min: i32::MIN,
            position_max: i32::MAX,
            max_velocity: u32::MAX,
            following_window: (spec.following_window_m / count).ceil() as u32,
            following_timeout_ms: 0,
            max_torque: 1000,
        }
    }
}

impl SimCia402Drive {
    /// A drive at power-on at `now_ns` (it sends its boot-up at the next tick).
    pub fn new(spec: SimDriveSpec, now_ns: u64) -> Self {
        let node = u16::from(spec.node_id);
        Self {
            spec,
            limits: Limits {
                max_speed_mps: spec.max_speed_mps,
                max_accel_mps2: spec.max_accel_mps2,
            },
            nmt_state: heartbeat::PRE_OPERATIONAL,
            state: Cia402State::SwitchOnDisabled,
            tpdo: PdoParams::disabled(COB_TPDO1 + node),
            rpdo: PdoParams::disabled(COB_RPDO1 + node),
            mode: 0,
            abort_option: 1,
            quick_stop_option: 2,
            shutdown_option: 0,
            disable_option: 0,
            fault_reaction: 0,
            consumer: 0,
            producer_ms: 0,
            controlword: 0,
            controlword_pending: None,
            target_counts: 0,
            rpdo_pending: false,
            motion: Motion::Plan(AxisPlan::hold(now_ns, spec.start_m)),
            referenced: true,
            silent: false,
            fault_code: 0,
            fault_persists: false,
            host_heartbeat_ns: None,
            heartbeat_event: false,
            next_heartbeat_ns: now_ns,
            boot_pending: true,
            emcys: Vec::new(),
            syncs: 0,
            scheduled: Vec::new(),
            heartbeat_lost: false,
            tpdos_to_skip: 0,
            own: OwnLimits::defaults(&spec),
            last_target_m: None,
            following_since_ns: None,
            internal_limit: false,
            last_sync_ns: None,
            store_instead: None,
        }
    }

    /// Test hook: from now on a write of `(index, sub)` stores `value`
    /// instead of what was written (and answers as if it had taken it), as a
    /// drive that clamps a value to its own range or ignores it.
    pub fn store_instead(&mut self, index: u16, sub: u8, value: u32) {
        self.store_instead = Some((index, sub, value));
    }

    /// The quick stop deceleration in force (0x6085), m/s^2.
    pub fn quick_stop_decel_mps2(&self) -> f64 {
        f64::from(self.own.quick_stop_decel) * self.m_per_count()
    }

    /// The slow down ramp in force (0x6084), m/s^2.
    pub fn profile_decel_mps2(&self) -> f64 {
        f64::from(self.own.profile_decel) * self.m_per_count()
    }

    /// How it stops, as stored: the option codes (0x605A, 0x605B, 0x605C,
    /// 0x605E, 0x6007).
    pub fn stop_options(&self) -> StopOptions {
        StopOptions {
            quick_stop: self.quick_stop_option,
            shutdown: self.shutdown_option,
            disable_operation: self.disable_option,
            fault_reaction: self.fault_reaction,
            abort_connection: self.abort_option,
        }
    }

    /// The software position limits in force (0x607D), m.
    pub fn position_limits_m(&self) -> (f64, f64) {
        let c = self.m_per_count();
        (
            f64::from(self.own.position_min) * c,
            f64::from(self.own.position_max) * c,
        )
    }

    /// The speed limit in force (0x607F), m/s.
    pub fn max_velocity_mps(&self) -> f64 {
        f64::from(self.own.max_velocity) * self.m_per_count()
    }

    /// Whether status word bit 11 (internal limit active) is set.
    pub fn internal_limit(&self) -> bool {
        self.internal_limit
    }

    /// The node id.
    pub fn node_id(&self) -> u8 {
        self.spec.node_id
    }

    /// The CiA 402 state.
    pub fn state(&self) -> Cia402State {
        self.state
    }

    /// The NMT state (heartbeat code).
    pub fn nmt_state(&self) -> u8 {
        self.nmt_state
    }

    /// The mode of operation (0x6061).
    pub fn mode(&self) -> i8 {
        self.mode
    }

    /// The EMCY codes sent so far.
    pub fn emcys(&self) -> &[u16] {
        &self.emcys
    }

    /// SYNCs seen.
    pub fn syncs(&self) -> u64 {
        self.syncs
    }

    /// The axis's true position at `now_ns`, m.
    pub fn position_m(&self, now_ns: u64) -> f64 {
        self.axis_state(now_ns).x_m
    }

    /// The axis's true velocity at `now_ns`, m/s.
    pub fn velocity_mps(&self, now_ns: u64) -> f64 {
        self.axis_state(now_ns).v_mps
    }

    /// Test hook: a fault with `code` now (EMCY sent at once); a persistent
    /// one survives fault resets until [`Self::clear_fault_cause`].
    pub fn inject_fault(
        &mut self,
        code: u16,
        persistent: bool,
        now_ns: u64,
        out: &mut Vec<RawFrame>,
    ) {
        self.fault_persists = persistent;
        self.enter_fault(code, now_ns, out);
    }

    /// Test hook: the cause of a persistent fault is gone (and a lost
    /// heartbeat producer sends again).
    pub fn clear_fault_cause(&mut self) {
        self.fault_persists = false;
        self.heartbeat_lost = false;
    }

    /// Test hook: the drive's next `n` TPDOs are not sent, as TPDOs that
    /// miss their SYNC's window on a busy bus (the host keeps the last status
    /// word it read).
    pub fn skip_tpdos(&mut self, n: u32) {
        self.tpdos_to_skip = n;
    }

    /// Schedules a fault; it fires at the first tick at or after its time.
    pub fn schedule(&mut self, fault: SimDriveFault) {
        self.scheduled.push(fault);
    }

    /// Whether the heartbeat producer is silent (a [`SimDriveFault::HeartbeatLoss`] fired).
    pub fn heartbeat_lost(&self) -> bool {
        self.heartbeat_lost
    }

    /// Fires the scheduled faults due at `now_ns`, in the order scheduled
    /// (without allocating: each is removed in place).
    fn fire_scheduled(&mut self, now_ns: u64, out: &mut Vec<RawFrame>) {
        while let Some(i) = self.scheduled.iter().position(|f| f.at_ns() <= now_ns) {
            match self.scheduled.remove(i) {
                SimDriveFault::HeartbeatLoss { .. } => self.heartbeat_lost = true,
                SimDriveFault::Emcy {
                    code, persistent, ..
                } => {
                    self.fault_persists = persistent;
                    self.enter_fault(code, now_ns, out);
                }
            }
        }
    }

    /// Test hook: the drive stops sending (and reacting), as if unplugged.
    pub fn set_silent(&mut self, silent: bool) {
        self.silent = silent;
    }

    /// Test hook: whether the encoder reports itself referenced (bit 15).
    pub fn set_referenced(&mut self, referenced: bool) {
        self.referenced = referenced;
    }

    fn axis_state(&self, now_ns: u64) -> AxisState {
        match self.motion {
            Motion::Follow { x_m, v_mps, at_ns } => {
                let x = x_m + v_mps * sar_hal::convert::ns_to_s(now_ns.saturating_sub(at_ns));
                // The interpolator never extrapolates past a software
                // position limit (from within them).
                let (lo, hi) = self.position_limits_m();
                if (lo..=hi).contains(&x_m) && !(lo..=hi).contains(&x) {
                    AxisState {
                        x_m: x.clamp(lo, hi),
                        v_mps: 0.0,
                    }
                } else {
                    AxisState { x_m: x, v_mps }
                }
            }
            Motion::Plan(plan) => plan.at(now_ns),
        }
    }

    fn m_per_count(&self) -> f64 {
        self.spec.lead_m / f64::from(self.spec.counts_per_turn.max(1))
    }

    fn counts(&self, now_ns: u64) -> i32 {
        let c = (self.position_m(now_ns) / self.m_per_count()).round();
        // Saturating float-to-int conversion: the 32-bit multiturn range.
        c as i32
    }

    fn statusword(&self) -> u16 {
        let mut sw = self.state.statusword_bits() | STATUS_REMOTE;
        if self.referenced {
            sw |= STATUS_REFERENCED;
        }
        if self.internal_limit {
            sw |= STATUS_INTERNAL_LIMIT;
        }
        sw
    }

    /// Halt and disable: braked at the acceleration limit.
    fn brake(&mut self, now_ns: u64) {
        let s = self.axis_state(now_ns);
        self.motion = Motion::Plan(AxisPlan::brake(now_ns, s, self.limits));
        self.stop_following();
    }

    /// Brings the axis to rest by `ramp` from `now_ns` (coasting: it runs
    /// on at its speed).
    fn stop_by(&mut self, ramp: Ramp, now_ns: u64) {
        let decel_mps2 = match ramp {
            Ramp::Coast => {
                let s = self.axis_state(now_ns);
                self.motion = Motion::Follow {
                    x_m: s.x_m,
                    v_mps: s.v_mps,
                    at_ns: now_ns,
                };
                self.stop_following();
                return;
            }
            Ramp::SlowDown => self.profile_decel_mps2(),
            Ramp::QuickStop => self.quick_stop_decel_mps2(),
            Ramp::Limit => self.limits.max_accel_mps2,
        };
        let s = self.axis_state(now_ns);
        let limits = Limits {
            max_speed_mps: self.limits.max_speed_mps,
            max_accel_mps2: decel_mps2,
        };
        self.motion = Motion::Plan(AxisPlan::brake(now_ns, s, limits));
        self.stop_following();
    }

    /// The ramp of the fault reaction (0x605E).
    fn fault_ramp(&self) -> Ramp {
        match self.fault_reaction {
            1 => Ramp::SlowDown,
            2 => Ramp::QuickStop,
            3 | 4 => Ramp::Limit,
            _ => Ramp::Coast,
        }
    }

    /// The ramp of a shutdown (0x605B) or disable operation (0x605C) with
    /// this option code.
    fn disable_ramp(option: i16) -> Ramp {
        if option == 1 {
            Ramp::SlowDown
        } else {
            Ramp::Coast
        }
    }

    fn stop_following(&mut self) {
        self.last_target_m = None;
        self.following_since_ns = None;
        self.internal_limit = false;
    }

    fn send(&self, out: &mut Vec<RawFrame>, cob: u16, data: &[u8]) {
        if !self.silent
            && let Some(f) = RawFrame::new_data(cob, data)
        {
            out.push(f);
        }
    }

    fn emcy(&mut self, code: u16, register: u8, out: &mut Vec<RawFrame>) {
        self.emcys.push(code);
        let data = Emcy { code, register }.encode();
        self.send(out, COB_EMCY + u16::from(self.spec.node_id), &data);
    }

    fn enter_fault(&mut self, code: u16, now_ns: u64, out: &mut Vec<RawFrame>) {
        self.stop_by(self.fault_ramp(), now_ns);
        self.state = Cia402State::Fault;
        self.fault_code = code;
        self.emcy(code, 0x01, out);
    }

    fn reset_communication(&mut self, now_ns: u64) {
        let node = u16::from(self.spec.node_id);
        self.tpdo = PdoParams::disabled(COB_TPDO1 + node);
        self.rpdo = PdoParams::disabled(COB_RPDO1 + node);
        self.consumer = 0;
        self.producer_ms = 0;
        self.host_heartbeat_ns = None;
        self.heartbeat_event = false;
        self.nmt_state = heartbeat::PRE_OPERATIONAL;
        self.boot_pending = true;
        self.next_heartbeat_ns = now_ns;
    }

    /// Takes one frame seen on the bus at `now_ns`; replies go to `out`.
    pub fn on_frame(&mut self, frame: &RawFrame, now_ns: u64, out: &mut Vec<RawFrame>) {
        if self.silent {
            return;
        }
        let node = u16::from(self.spec.node_id);
        let data = frame.payload();
        match frame.cob_id {
            COB_NMT => {
                if let [cs, target] = data
                    && (*target == 0 || *target == self.spec.node_id)
                {
                    self.nmt(*cs, now_ns, out);
                }
            }
            COB_SYNC => self.sync(now_ns, out),
            id if id == COB_SDO_RX + node && self.nmt_state != heartbeat::STOPPED => {
                let reply = self.sdo(data, now_ns);
                self.send(out, COB_SDO_TX + node, &reply.encode());
            }
            id if u32::from(id) == self.rpdo.cob_id
                && self.rpdo.enabled()
                && self.nmt_state == heartbeat::OPERATIONAL =>
            {
                self.take_rpdo(data);
            }
            id if (COB_HEARTBEAT..=COB_HEARTBEAT + 127).contains(&id) => {
                let producer = u32::from(id - COB_HEARTBEAT);
                if self.consumer != 0 && (self.consumer >> 16) & 0xFF == producer {
                    self.host_heartbeat_ns = Some(now_ns);
                    self.heartbeat_event = false;
                }
            }
            _ => {}
        }
        self.supervise(now_ns, out);
    }

    /// Lets time pass to `now_ns`: scheduled faults, boot-up, heartbeat
    /// producer, consumer.
    pub fn tick(&mut self, now_ns: u64, out: &mut Vec<RawFrame>) {
        if self.silent {
            return;
        }
        self.fire_scheduled(now_ns, out);
        let node = u16::from(self.spec.node_id);
        if self.boot_pending {
            self.boot_pending = false;
            self.send(out, COB_HEARTBEAT + node, &[heartbeat::BOOT_UP]);
        }
        if self.producer_ms > 0 && now_ns >= self.next_heartbeat_ns && !self.heartbeat_lost {
            self.send(out, COB_HEARTBEAT + node, &[self.nmt_state]);
            let period = u64::from(self.producer_ms) * 1_000_000;
            self.next_heartbeat_ns = now_ns.max(self.next_heartbeat_ns.saturating_add(period));
        }
        self.supervise(now_ns, out);
    }

    fn supervise(&mut self, now_ns: u64, out: &mut Vec<RawFrame>) {
        let time_ms = u64::from(self.consumer & 0xFFFF);
        let Some(last) = self.host_heartbeat_ns else {
            return;
        };
        if time_ms == 0
            || self.heartbeat_event
            || now_ns.saturating_sub(last) <= time_ms * 1_000_000
        {
            return;
        }
        self.heartbeat_event = true;
        self.emcy(EMCY_HEARTBEAT, 0x11, out);
        match self.abort_option {
            1 if self.state != Cia402State::Fault => {
                self.stop_by(self.fault_ramp(), now_ns);
                self.state = Cia402State::Fault;
                self.fault_code = EMCY_HEARTBEAT;
            }
            2 | 3 => self.quick_stop_or_disable(self.abort_option == 2, now_ns),
            _ => {}
        }
    }

    /// A quick stop (as 0x605A says) or a disable voltage (braked at the
    /// acceleration limit).
    fn quick_stop_or_disable(&mut self, disable: bool, now_ns: u64) {
        use Cia402State::*;
        match self.state {
            OperationEnabled => {
                let ramp = match (disable, self.quick_stop_option) {
                    (true, _) => Ramp::Limit,
                    (false, 1 | 5) => Ramp::SlowDown,
                    (false, 2 | 6) => Ramp::QuickStop,
                    (false, 3 | 4 | 7 | 8) => Ramp::Limit,
                    (false, _) => Ramp::Coast,
                };
                self.stop_by(ramp, now_ns);
                self.state = if disable || !(5..=8).contains(&self.quick_stop_option) {
                    SwitchOnDisabled
                } else {
                    QuickStopActive
                };
            }
            ReadyToSwitchOn | SwitchedOn => self.state = SwitchOnDisabled,
            _ => {}
        }
    }

    fn nmt(&mut self, cs: u8, now_ns: u64, out: &mut Vec<RawFrame>) {
        match cs {
            nmt::START => self.nmt_state = heartbeat::OPERATIONAL,
            nmt::STOP => self.nmt_state = heartbeat::STOPPED,
            nmt::PRE_OPERATIONAL => self.nmt_state = heartbeat::PRE_OPERATIONAL,
            nmt::RESET_NODE => {
                self.reset_communication(now_ns);
                self.brake(now_ns);
                self.state = Cia402State::SwitchOnDisabled;
                self.mode = 0;
                self.abort_option = 1;
                self.quick_stop_option = 2;
                self.shutdown_option = 0;
                self.disable_option = 0;
                self.fault_reaction = 0;
                self.controlword = 0;
                self.own = OwnLimits::defaults(&self.spec);
                if !self.fault_persists {
                    self.fault_code = 0;
                } else {
                    self.state = Cia402State::Fault;
                }
            }
            nmt::RESET_COMMUNICATION => self.reset_communication(now_ns),
            _ => {}
        }
        if matches!(cs, nmt::RESET_NODE | nmt::RESET_COMMUNICATION) {
            self.boot_pending = false;
            let node = u16::from(self.spec.node_id);
            self.send(out, COB_HEARTBEAT + node, &[heartbeat::BOOT_UP]);
        }
    }

    fn take_rpdo(&mut self, data: &[u8]) {
        let mut at = 0usize;
        let mut got = false;
        for entry in self.rpdo.entries() {
            let bytes = usize::try_from((entry & 0xFF) / 8).unwrap_or(0);
            let Some(chunk) = data.get(at..at + bytes) else {
                return;
            };
            let mut raw = [0u8; 4];
            if let Some(dst) = raw.get_mut(..bytes) {
                dst.copy_from_slice(chunk);
            }
            let value = u32::from_le_bytes(raw);
            match *entry {
                mapping::CONTROLWORD => {
                    self.controlword_pending = Some(value as u16);
                }
                mapping::TARGET_POSITION => self.target_counts = value as i32,
                _ => {}
            }
            at += bytes;
            got = true;
        }
        self.rpdo_pending = got;
    }

    fn sync(&mut self, now_ns: u64, out: &mut Vec<RawFrame>) {
        if self.nmt_state != heartbeat::OPERATIONAL {
            return;
        }
        self.syncs += 1;
        let pending = core::mem::take(&mut self.rpdo_pending);
        let mut just_enabled = false;
        if let Some(cw) = self.controlword_pending.take() {
            just_enabled = self.apply_controlword(cw, now_ns, out);
        }
        if pending && !just_enabled && self.state == Cia402State::OperationEnabled {
            self.follow(now_ns, out);
        }
        if self.tpdo.enabled() && (1..=240).contains(&self.tpdo.transmission) {
            let n = u64::from(self.tpdo.transmission);
            if self.tpdos_to_skip > 0 {
                self.tpdos_to_skip -= 1;
            } else if self.syncs.is_multiple_of(n) {
                let data = self.tpdo_data(now_ns);
                let len = usize::from(data.1);
                let cob = (self.tpdo.cob_id & 0x7FF) as u16;
                self.send(out, cob, data.0.get(..len).unwrap_or(&[]));
            }
        }
    }

    /// CSP: the new set point, within the drive's own limits (clamped at
    /// the software position limits, approached at most at the max profile
    /// velocity), with the following checks (see the module doc).
    fn follow(&mut self, now_ns: u64, out: &mut Vec<RawFrame>) {
        let previous_sync_ns = self.last_sync_ns.replace(now_ns);
        if self.mode != MODE_CSP || self.controlword & control::HALT != 0 {
            return;
        }
        let count = self.m_per_count();
        let raw = self.target_counts;
        let clamped = raw.clamp(
            self.own.position_min,
            self.own.position_max.max(self.own.position_min),
        );
        let target_m = f64::from(clamped) * count;
        let window_m = f64::from(self.own.following_window) * count;
        let actual_m = self.axis_state(now_ns).x_m;
        // A set point that jumps beyond the window: a following error at once.
        let reference_m = self.last_target_m.unwrap_or(actual_m);
        if (target_m - reference_m).abs() > window_m {
            self.enter_fault(EMCY_FOLLOWING_ERROR, now_ns, out);
            return;
        }
        self.last_target_m = Some(target_m);
        // Where the drive's demand was at the last SYNC, and how long ago.
        let (from_m, from_ns, v_before) = match self.motion {
            Motion::Follow { x_m, v_mps, at_ns } => (x_m, at_ns, v_mps),
            Motion::Plan(_) => (actual_m, previous_sync_ns.unwrap_or(now_ns), 0.0),
        };
        let dt_s = sar_hal::convert::ns_to_s(now_ns.saturating_sub(from_ns));
        let reach_m = f64::from(self.own.max_velocity) * count * dt_s;
        let step_m = target_m - from_m;
        let speed_limited = step_m.abs() > reach_m + 1e-12;
        let x_m = if speed_limited {
            from_m + reach_m.copysign(step_m)
        } else {
            target_m
        };
        self.internal_limit = clamped != raw || speed_limited;
        let v_max = self.spec.max_speed_mps;
        let v_mps = if dt_s > 0.0 {
            ((x_m - from_m) / dt_s).clamp(-v_max, v_max)
        } else {
            v_before
        };
        self.motion = Motion::Follow {
            x_m,
            v_mps,
            at_ns: now_ns,
        };
        // The actual position against the set point, over the time out.
        if (target_m - x_m).abs() > window_m {
            let since = *self.following_since_ns.get_or_insert(now_ns);
            let timeout_ns = u64::from(self.own.following_timeout_ms) * 1_000_000;
            if now_ns.saturating_sub(since) >= timeout_ns {
                self.enter_fault(EMCY_FOLLOWING_ERROR, now_ns, out);
            }
        } else {
            self.following_since_ns = None;
        }
    }

    /// Applies a control word; true when it enabled operation.
    fn apply_controlword(&mut self, cw: u16, now_ns: u64, out: &mut Vec<RawFrame>) -> bool {
        use Cia402State::*;
        let previous = self.controlword;
        self.controlword = cw;
        let rising_reset = cw & 0x80 != 0 && previous & 0x80 == 0;
        if self.state == Fault {
            if rising_reset && !self.fault_persists {
                self.state = SwitchOnDisabled;
                self.fault_code = 0;
                self.emcy(0, 0, out);
            }
            return false;
        }
        if cw & 0x80 != 0 {
            return false;
        }
        let halt_rising = cw & control::HALT != 0 && previous & control::HALT == 0;
        let next = if cw & 0x02 == 0 {
            // Disable voltage.
            SwitchOnDisabled
        } else if cw & 0x04 == 0 {
            // Quick stop.
            match self.state {
                OperationEnabled => {
                    self.quick_stop_or_disable(false, now_ns);
                    return false;
                }
                ReadyToSwitchOn | SwitchedOn => SwitchOnDisabled,
                s => s,
            }
        } else {
            match (self.state, cw & 0x0F) {
                (SwitchOnDisabled | SwitchedOn | OperationEnabled, 0x06) => ReadyToSwitchOn,
                (ReadyToSwitchOn | OperationEnabled, 0x07) => SwitchedOn,
                (SwitchedOn | QuickStopActive, 0x0F) => OperationEnabled,
                (s, _) => s,
            }
        };
        let was_enabled = self.state == OperationEnabled;
        if was_enabled && next != OperationEnabled {
            match next {
                // Shutdown and disable operation, as their option codes say.
                ReadyToSwitchOn => self.stop_by(Self::disable_ramp(self.shutdown_option), now_ns),
                SwitchedOn => self.stop_by(Self::disable_ramp(self.disable_option), now_ns),
                _ => self.brake(now_ns),
            }
        }
        let enabling = !was_enabled && next == OperationEnabled;
        if enabling {
            let s = self.axis_state(now_ns);
            self.motion = Motion::Follow {
                x_m: s.x_m,
                v_mps: 0.0,
                at_ns: now_ns,
            };
            self.stop_following();
            self.last_sync_ns = Some(now_ns);
        }
        if next == OperationEnabled && halt_rising {
            self.brake(now_ns);
        }
        self.state = next;
        enabling
    }

    fn tpdo_data(&self, now_ns: u64) -> ([u8; 8], u8) {
        let mut buf = [0u8; 8];
        let mut at = 0usize;
        for entry in self.tpdo.entries() {
            let value = match *entry {
                mapping::STATUSWORD => u32::from(self.statusword()),
                mapping::POSITION_ACTUAL => self.counts(now_ns) as u32,
                0x6061_0008 => u32::from(self.mode as u8),
                _ => 0,
            };
            let bytes = usize::try_from((entry & 0xFF) / 8).unwrap_or(0);
            let le = value.to_le_bytes();
            if let (Some(dst), Some(src)) = (buf.get_mut(at..at + bytes), le.get(..bytes)) {
                dst.copy_from_slice(src);
            }
            at += bytes;
        }
        (buf, u8::try_from(at.min(8)).unwrap_or(8))
    }

    fn sdo(&mut self, data: &[u8], now_ns: u64) -> Sdo {
        let Some(request) = Sdo::decode(data) else {
            let (index, sub) = match data {
                [_, lo, hi, sub, ..] => (u16::from_le_bytes([*lo, *hi]), *sub),
                _ => (0, 0),
            };
            return Sdo::Abort {
                index,
                sub,
                code: SDO_ABORT_COMMAND,
            };
        };
        match request {
            Sdo::Upload { index, sub } => match self.read_object(index, sub, now_ns) {
                Ok((value, size)) => Sdo::UploadOk {
                    index,
                    sub,
                    value,
                    size,
                },
                Err(code) => Sdo::Abort { index, sub, code },
            },
            Sdo::Download {
                index, sub, value, ..
            } => match self.write_object(index, sub, value) {
                Ok(()) => Sdo::DownloadOk { index, sub },
                Err(code) => Sdo::Abort { index, sub, code },
            },
            Sdo::DownloadOk { index, sub }
            | Sdo::UploadOk { index, sub, .. }
            | Sdo::Abort { index, sub, .. } => Sdo::Abort {
                index,
                sub,
                code: SDO_ABORT_COMMAND,
            },
        }
    }

    fn pdo_mut(&mut self, index: u16) -> Option<&mut PdoParams> {
        match index {
            od::RPDO1_COMM | od::RPDO1_MAP => Some(&mut self.rpdo),
            od::TPDO1_COMM | od::TPDO1_MAP => Some(&mut self.tpdo),
            _ => None,
        }
    }

    fn read_object(&self, index: u16, sub: u8, now_ns: u64) -> Result<(u32, u8), u32> {
        let pdo = match index {
            od::RPDO1_COMM | od::RPDO1_MAP => Some(&self.rpdo),
            od::TPDO1_COMM | od::TPDO1_MAP => Some(&self.tpdo),
            _ => None,
        };
        Ok(match (index, sub) {
            (0x1000, 0) => (0x0002_0192, 4),
            (0x1001, 0) => (u32::from(self.state == Cia402State::Fault), 1),
            (od::CONSUMER_HEARTBEAT, 0) => (1, 1),
            (od::CONSUMER_HEARTBEAT, 1) => (self.consumer, 4),
            (od::PRODUCER_HEARTBEAT, 0) => (u32::from(self.producer_ms), 2),
            (od::RPDO1_COMM | od::TPDO1_COMM, 1) => (pdo.map_or(0, |p| p.cob_id), 4),
            (od::RPDO1_COMM | od::TPDO1_COMM, 2) => {
                (u32::from(pdo.map_or(0, |p| p.transmission)), 1)
            }
            (od::RPDO1_MAP | od::TPDO1_MAP, 0) => (u32::from(pdo.map_or(0, |p| p.count)), 1),
            (od::RPDO1_MAP | od::TPDO1_MAP, 1..=8) => {
                let entry = pdo.and_then(|p| p.map.get(usize::from(sub - 1)).copied());
                (entry.unwrap_or(0), 4)
            }
            (od::ABORT_CONNECTION, 0) => (u32::from(self.abort_option as u16), 2),
            (od::ERROR_CODE, 0) => (u32::from(self.fault_code), 2),
            (od::CONTROLWORD, 0) => (u32::from(self.controlword), 2),
            (od::STATUSWORD, 0) => (u32::from(self.statusword()), 2),
            (od::QUICK_STOP_OPTION, 0) => (u32::from(self.quick_stop_option as u16), 2),
            (od::SHUTDOWN_OPTION, 0) => (u32::from(self.shutdown_option as u16), 2),
            (od::DISABLE_OPERATION_OPTION, 0) => (u32::from(self.disable_option as u16), 2),
            (od::FAULT_REACTION_OPTION, 0) => (u32::from(self.fault_reaction as u16), 2),
            (od::PROFILE_DECELERATION, 0) => (self.own.profile_decel, 4),
            (od::MODES_OF_OPERATION | od::MODES_OF_OPERATION_DISPLAY, 0) => {
                (u32::from(self.mode as u8), 1)
            }
            (od::POSITION_ACTUAL, 0) => (self.counts(now_ns) as u32, 4),
            (od::TARGET_POSITION, 0) => (self.target_counts as u32, 4),
            (od::QUICK_STOP_DECELERATION, 0) => (self.own.quick_stop_decel, 4),
            (od::SOFTWARE_POSITION_LIMIT, 0) => (2, 1),
            (od::SOFTWARE_POSITION_LIMIT, 1) => (self.own.position_min as u32, 4),
            (od::SOFTWARE_POSITION_LIMIT, 2) => (self.own.position_max as u32, 4),
            (od::MAX_PROFILE_VELOCITY, 0) => (self.own.max_velocity, 4),
            (od::FOLLOWING_ERROR_WINDOW, 0) => (self.own.following_window, 4),
            (od::FOLLOWING_ERROR_TIMEOUT, 0) => (u32::from(self.own.following_timeout_ms), 2),
            (od::MAX_TORQUE, 0) => (u32::from(self.own.max_torque), 2),
            _ => return Err(SDO_ABORT_NO_OBJECT),
        })
    }

    fn write_object(&mut self, index: u16, sub: u8, value: u32) -> Result<(), u32> {
        let pre_op = self.nmt_state == heartbeat::PRE_OPERATIONAL;
        let value = match self.store_instead {
            Some((i, s, v)) if i == index && s == sub => v,
            _ => value,
        };
        match (index, sub) {
            (od::QUICK_STOP_DECELERATION, 0) => {
                if value == 0 {
                    return Err(SDO_ABORT_RANGE);
                }
                self.own.quick_stop_decel = value;
            }
            (od::SOFTWARE_POSITION_LIMIT, 1) => self.own.position_min = value as i32,
            (od::SOFTWARE_POSITION_LIMIT, 2) => self.own.position_max = value as i32,
            (od::MAX_PROFILE_VELOCITY, 0) => self.own.max_velocity = value,
            (od::FOLLOWING_ERROR_WINDOW, 0) => self.own.following_window = value,
            (od::FOLLOWING_ERROR_TIMEOUT, 0) => {
                self.own.following_timeout_ms =
                    u16::try_from(value).map_err(|_| SDO_ABORT_RANGE)?;
            }
            (od::MAX_TORQUE, 0) => {
                self.own.max_torque = u16::try_from(value).map_err(|_| SDO_ABORT_RANGE)?;
            }
            (od::CONSUMER_HEARTBEAT, 1) => {
                self.consumer = value;
                self.host_heartbeat_ns = None;
                self.heartbeat_event = false;
            }
            (od::PRODUCER_HEARTBEAT, 0) => self.producer_ms = value as u16,
            (od::RPDO1_COMM | od::TPDO1_COMM, 1) => {
                let pdo = self.pdo_mut(index).ok_or(SDO_ABORT_NO_OBJECT)?;
                pdo.cob_id = value;
            }
            (od::RPDO1_COMM | od::TPDO1_COMM, 2) => {
                let pdo = self.pdo_mut(index).ok_or(SDO_ABORT_NO_OBJECT)?;
                if pdo.cob_id & 0x8000_0000 == 0 {
                    return Err(SDO_ABORT_STATE);
                }
                pdo.transmission = value as u8;
            }
            (od::RPDO1_MAP | od::TPDO1_MAP, _) => self.write_pdo_map(index, sub, value, pre_op)?,
            (od::ABORT_CONNECTION, 0) => self.abort_option = value as u16 as i16,
            (od::QUICK_STOP_OPTION, 0) => self.quick_stop_option = value as u16 as i16,
            (od::SHUTDOWN_OPTION, 0) => self.shutdown_option = value as u16 as i16,
            (od::DISABLE_OPERATION_OPTION, 0) => self.disable_option = value as u16 as i16,
            (od::FAULT_REACTION_OPTION, 0) => self.fault_reaction = value as u16 as i16,
            (od::PROFILE_DECELERATION, 0) => {
                if value == 0 {
                    return Err(SDO_ABORT_RANGE);
                }
                self.own.profile_decel = value;
            }
            (od::CONTROLWORD, 0) => self.controlword_pending = Some(value as u16),
            (od::MODES_OF_OPERATION, 0) => {
                let mode = value as u8 as i8;
                if mode != MODE_CSP {
                    return Err(SDO_ABORT_RANGE);
                }
                self.mode = mode;
            }
            (od::TARGET_POSITION, 0) => self.target_counts = value as i32,
            _ => return Err(SDO_ABORT_NO_OBJECT),
        }
        Ok(())
    }

    /// A write to a PDO's mapping (`index`: RPDO1's or TPDO1's): its count
    /// (sub 0; in pre-operational with the PDO off, every entry known and at
    /// most 64 bits) or one entry (subs 1 to 8; in pre-operational with the
    /// count 0).
    fn write_pdo_map(&mut self, index: u16, sub: u8, value: u32, pre_op: bool) -> Result<(), u32> {
        match sub {
            0 => {
                let tx = index == od::TPDO1_MAP;
                let pdo = self.pdo_mut(index).ok_or(SDO_ABORT_NO_OBJECT)?;
                if !pre_op || pdo.cob_id & 0x8000_0000 == 0 {
                    return Err(SDO_ABORT_STATE);
                }
                let count = usize::try_from(value).map_err(|_| SDO_ABORT_RANGE)?;
                let entries = pdo.map.get(..count).ok_or(SDO_ABORT_RANGE)?;
                let known: &[u32] = if tx {
                    &[mapping::STATUSWORD, mapping::POSITION_ACTUAL, 0x6061_0008]
                } else {
                    &[mapping::CONTROLWORD, mapping::TARGET_POSITION]
                };
                let bits: u32 = entries.iter().map(|e| e & 0xFF).sum();
                if entries.iter().any(|e| !known.contains(e)) || bits > 64 {
                    return Err(SDO_ABORT_RANGE);
                }
                pdo.count = value as u8;
            }
            1..=8 => {
                let pdo = self.pdo_mut(index).ok_or(SDO_ABORT_NO_OBJECT)?;
                if !pre_op || pdo.count != 0 {
                    return Err(SDO_ABORT_STATE);
                }
                let slot = pdo
                    .map
                    .get_mut(usize::from(sub - 1))
                    .ok_or(SDO_ABORT_NO_OBJECT)?;
                *slot = value;
            }
            _ => return Err(SDO_ABORT_NO_OBJECT),
        }
        Ok(())
    }
}

/// Serves `drives` on a real bus once: takes every frame waiting (at most
/// 256), lets each drive answer, ticks them at `now_ns`, and sends what they
/// produce. Returns the number of frames received, or the bus's error
/// (frames the bus could not take are dropped, as a full controller would).
pub fn serve<C: Can>(
    can: &mut C,
    drives: &mut [SimCia402Drive],
    now_ns: u64,
    out: &mut Vec<RawFrame>,
) -> Result<usize, C::Error> {
    let mut received = 0;
    let mut error = None;
    for _ in 0..256 {
        match can.receive() {
            Ok(frame) => {
                received += 1;
                if let Some(raw) = RawFrame::from_frame(&frame) {
                    for d in drives.iter_mut() {
                        d.on_frame(&raw, now_ns, out);
                    }
                }
            }
            Err(nb::Error::WouldBlock) => break,
            Err(nb::Error::Other(e)) => {
                error = Some(e);
                break;
            }
        }
    }
    for d in drives.iter_mut() {
        d.tick(now_ns, out);
    }
    for raw in out.drain(..) {
        if let Some(frame) = raw.to_frame::<C::Frame>() {
            let _ = can.transmit(&frame);
        }
    }
    match error {
        Some(e) => Err(e),
        None => Ok(received),
    }
}
