//! The host side: [`CanOpenDrives`], the three CiA 402 drives as one
//! [`AxisDrives`].
//!
//! Start-up ([`CanOpenDrives::start`]): per drive an NMT reset node and its
//! boot-up, then over expedited SDO: TPDO1 = status word + position actual,
//! RPDO1 = control word + target position, both synchronous (every SYNC);
//! mode 8 (CSP) written in 0x6060 and checked in 0x6061; how the drive
//! stops ([`CanOpenConfig::safe_stop_objects`]: 0x6007 = 3, a quick stop on
//! loss of the host; 0x605A = 6, the quick stop ramp, then hold; 0x605B =
//! 0x605C = 1, the host's disable ramps at 0x6084; 0x605E = 2, the fault
//! reaction ramps at 0x6085, never coasts);
//! the drive's heartbeat producer; the host as its heartbeat consumer; the
//! drive's own limits ([`CanOpenConfig::drive_limit_objects`]: quick stop
//! deceleration 0x6085, software position limits 0x607D, max profile
//! velocity 0x607F, following error window and time out 0x6065/0x6066, max
//! torque 0x6072); every one of these safety settings is read back, and a
//! drive that stores another value refuses the start
//! ([`CanOpenError::LimitMismatch`]), so the drives are never enabled
//! without them; then NMT start. Every wait is bounded (`sdo_timeout_ns`,
//! `boot_timeout_ns`). (They are written here, at start-up, not in
//! `enable`, which runs on the loop's path and never touches the bus; a
//! drive that reboots loses them, but also leaves operational, which the
//! host latches as a lost drive whose fault cannot be reset: it is never
//! enabled again without a new start.)
//!
//! Each control period the caller calls [`CanOpenDrives::cycle`]: it takes
//! what has arrived (heartbeats, EMCY), sends SYNC, waits (at most
//! `pdo_wait_ns`) for the three TPDOs of that SYNC, updates the positions
//! (stamped with the SYNC's time, when the drives sampled them) and the state,
//! and writes the RPDOs, which the drives apply at the next SYNC: the control
//! word of the CiA 402 sequence the host is steering towards, and the next
//! set point of the move planned by the `motion` planner (one per SYNC, CSP).
//! The other calls of [`AxisDrives`] never touch the bus.
//!
//! Faults: a drive in Fault, an EMCY with a non-zero code, a drive's heartbeat
//! missing for `drive_heartbeat_timeout_ms` or a drive leaving Operation
//! enabled on its own latch `DriveState::Fault { axis, code }` (the EMCY's
//! code; 0x8130 for a lost drive) and quick-stop the other axes. A fault
//! reset completes only on the TPDOs of one SYNC read after its rising edge
//! reached the drives, each saying no Fault (a TPDO late on a busy bus leaves
//! an older status word, which never completes it). Bus errors
//! (error frames, bus-off, overrun) are returned by `cycle` as
//! `CanOpenError::Bus`; a bus that stays off loses the heartbeats, a Fault.

use crate::frame::{
    COB_EMCY, COB_HEARTBEAT, COB_NMT, COB_RPDO1, COB_SDO_RX, COB_SDO_TX, COB_SYNC, COB_TPDO1,
    Cia402State, Emcy, FAULT_GENERIC, FAULT_LOST, MODE_CSP, RawFrame, STATUS_REFERENCED, Sdo,
    control, encode_rpdo, heartbeat, mapping, nmt, od,
};
use crate::{CanOpenConfig, CanOpenError};
use embedded_can::Error as _;
use embedded_can::nb::Can;
use sar_hal::Clock;
use sar_hal::motion::{AxisPlan, Limits};
use sar_hal::{AxisDrives, DriveState, JointPositions};
use sar_kinematics::ActiveJoints;

/// Frames taken in one drain of the receive queue, at most.
const DRAIN_MAX: usize = 512;

/// The cycles of a fault reset before its result can show: the first sends
/// disable voltage, the second the rising edge of fault reset, which the
/// drives apply at the next SYNC, whose TPDOs the third cycle reads.
const RESET_CYCLES_TO_COMPLETE: u8 = 2;

/// What the host wants of the drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Want {
    Ready,
    Enabled,
    QuickStop,
}

#[derive(Debug, Clone, Copy)]
struct Axis {
    node: u8,
    statusword: Option<u16>,
    counts: i32,
    tpdo_sync: u64,
    heartbeat_ns: u64,
    nmt_state: u8,
    emcy_code: Option<u16>,
    plan: AxisPlan,
    was_enabled: bool,
}

impl Axis {
    fn cia402(&self) -> Option<Cia402State> {
        self.statusword.map(Cia402State::from_statusword)
    }
}

/// What one [`CanOpenDrives::cycle`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CycleReport {
    /// The SYNC's time, ns.
    pub sync_ns: u64,
    /// The SYNC's number (from 1).
    pub sync_count: u64,
    /// The TPDOs of that SYNC received (0..=3).
    pub tpdos: u8,
}

/// The three CiA 402 drives on one CAN bus.
#[derive(Debug)]
pub struct CanOpenDrives<C: Can, K: Clock> {
    can: C,
    clock: K,
    config: CanOpenConfig,
    limits: Limits,
    axes: [Axis; 3],
    want: Want,
    fault: Option<DriveState>,
    reset_cycles: Option<u8>,
    sync_count: u64,
    sync_ns: u64,
    next_heartbeat_ns: u64,
    positions: JointPositions,
    bus_error: Option<CanOpenError>,
    bus_errors: u64,
    halted: bool,
    goal_m: Option<[f64; 3]>,
}

impl<C: Can, K: Clock> CanOpenDrives<C, K> {
    /// Configures the drives and starts them (see the module doc). The drives
    /// end in NMT operational, CiA 402 Switch on disabled; the first
    /// [`Self::cycle`] brings them to `Ready`.
    pub fn start(can: C, clock: K, config: CanOpenConfig) -> Result<Self, CanOpenError> {
        config.validate()?;
        let now = clock.now_ns().map_err(|_| CanOpenError::Clock)?;
        let axis = |node| Axis {
            node,
            statusword: None,
            counts: 0,
            tpdo_sync: 0,
            heartbeat_ns: now,
            nmt_state: heartbeat::PRE_OPERATIONAL,
            emcy_code: None,
            plan: AxisPlan::hold(now, 0.0),
            was_enabled: false,
        };
        let ids = config.node_ids;
        let mut me = Self {
            can,
            clock,
            limits: Limits {
                max_speed_mps: config.max_speed_mps,
                max_accel_mps2: config.max_accel_mps2,
            },
            axes: [axis(ids[0]), axis(ids[1]), axis(ids[2])],
            config,
            want: Want::Ready,
            fault: None,
            reset_cycles: None,
            sync_count: 0,
            sync_ns: now,
            next_heartbeat_ns: now,
            positions: JointPositions {
                joints: ActiveJoints {
                    q1_m: 0.0,
                    q2_m: 0.0,
                    q3_m: 0.0,
                },
                stamp_ns: 0,
                valid: false,
            },
            bus_error: None,
            bus_errors: 0,
            halted: false,
            goal_m: None,
        };
        for node in ids {
            me.boot(node)?;
            me.configure(node)?;
        }
        me.go_operational()?;
        Ok(me)
    }

    /// Starts the configured drives (NMT start, after the host's first
    /// heartbeat) and waits, at most a drive heartbeat time-out, until each
    /// drive's heartbeat says operational.
    fn go_operational(&mut self) -> Result<(), CanOpenError> {
        self.send_heartbeat()?;
        for node in self.config.node_ids {
            self.send(COB_NMT, &[nmt::START, node])?;
        }
        // The start is confirmed by each drive's heartbeat saying operational.
        for a in &mut self.axes {
            a.nmt_state = heartbeat::PRE_OPERATIONAL;
        }
        let timeout_ns = u64::from(self.config.drive_heartbeat_timeout_ms) * 1_000_000;
        let operational = |me: &Self| {
            me.axes
                .iter()
                .all(|a| a.nmt_state == heartbeat::OPERATIONAL)
        };
        if !operational(self) && !self.wait(timeout_ns, |me, _| operational(me)) {
            let node = self
                .axes
                .iter()
                .find(|a| a.nmt_state != heartbeat::OPERATIONAL)
                .map_or(0, |a| a.node);
            return Err(CanOpenError::NotOperational { node, timeout_ns });
        }
        Ok(())
    }

    /// The configuration.
    pub fn config(&self) -> &CanOpenConfig {
        &self.config
    }

    /// Halt (control word bit 8) while `Enabled`: the drives brake at their
    /// limit and hold, staying in Operation enabled; on release the move to
    /// the last target resumes from where they stopped. Targets set while
    /// halted are kept for the release. `ErrorKind::InvalidState` outside
    /// `Enabled`.
    pub fn set_halt(&mut self, halt: bool) -> Result<(), CanOpenError> {
        let state = self.logical_state();
        if state != DriveState::Enabled {
            return Err(CanOpenError::InvalidState { state });
        }
        if self.halted
            && !halt
            && let Some(goal) = self.goal_m
        {
            self.plan_to(goal);
        }
        self.halted = halt;
        Ok(())
    }

    /// Whether the drives are halted.
    pub fn halted(&self) -> bool {
        self.halted
    }

    fn plan_to(&mut self, goal: [f64; 3]) {
        let start_ns = self.sync_ns.saturating_add(self.config.sync_period_ns);
        for (a, target) in self.axes.iter_mut().zip(goal) {
            let from = a.plan.at(start_ns);
            a.plan = AxisPlan::to_target(start_ns, from, target, self.limits);
        }
    }

    /// Bus errors seen since start.
    pub fn bus_errors(&self) -> u64 {
        self.bus_errors
    }

    /// The CiA 402 state of each axis in its last status word.
    pub fn axis_states(&self) -> [Option<Cia402State>; 3] {
        self.axes.map(|a| a.cia402())
    }

    fn send(&mut self, cob_id: u16, data: &[u8]) -> Result<(), CanOpenError> {
        let frame = RawFrame::new_data(cob_id, data)
            .and_then(|f| f.to_frame::<C::Frame>())
            .ok_or(CanOpenError::Transmit { cob_id })?;
        match self.can.transmit(&frame) {
            Ok(_) => Ok(()),
            Err(nb::Error::WouldBlock) => Err(CanOpenError::Transmit { cob_id }),
            Err(nb::Error::Other(e)) => Err(self.note_bus_error(&e)),
        }
    }

    fn note_bus_error(&mut self, e: &C::Error) -> CanOpenError {
        self.bus_errors += 1;
        let err = CanOpenError::Bus { kind: e.kind() };
        self.bus_error = Some(err.clone());
        err
    }

    /// Host time, ns, or [`CanOpenError::Clock`].
    fn now(&self) -> Result<u64, CanOpenError> {
        self.clock.now_ns().map_err(|_| CanOpenError::Clock)
    }

    fn send_heartbeat(&mut self) -> Result<(), CanOpenError> {
        let id = COB_HEARTBEAT + u16::from(self.config.host_node_id);
        self.next_heartbeat_ns = self
            .now()?
            .saturating_add(u64::from(self.config.host_heartbeat_ms) * 1_000_000);
        self.send(id, &[heartbeat::OPERATIONAL])
    }

    /// Polls the bus until `done` says so or `timeout_ns` passes; every frame
    /// is handled. Returns whether `done` was reached.
    fn wait(&mut self, timeout_ns: u64, mut done: impl FnMut(&Self, &RawFrame) -> bool) -> bool {
        // A clock that cannot be read ends the wait at once, not reached.
        let Ok(start) = self.clock.now_ns() else {
            return false;
        };
        let deadline = start.saturating_add(timeout_ns);
        let polls = timeout_ns / self.config.poll_interval_ns.max(1) + 16;
        for _ in 0..polls {
            for _ in 0..DRAIN_MAX {
                match self.can.receive() {
                    Ok(frame) => {
                        if let Some(raw) = RawFrame::from_frame(&frame) {
                            self.handle(&raw);
                            if done(self, &raw) {
                                return true;
                            }
                        }
                    }
                    Err(nb::Error::WouldBlock) => break,
                    Err(nb::Error::Other(e)) => {
                        self.note_bus_error(&e);
                        break;
                    }
                }
            }
            let Ok(now) = self.clock.now_ns() else {
                return false;
            };
            if now >= deadline {
                return false;
            }
            self.clock
                .sleep_until_ns(deadline.min(now.saturating_add(self.config.poll_interval_ns)));
        }
        false
    }

    fn boot(&mut self, node: u8) -> Result<(), CanOpenError> {
        self.send(COB_NMT, &[nmt::RESET_NODE, node])?;
        let id = COB_HEARTBEAT + u16::from(node);
        if self.wait(self.config.boot_timeout_ns, |_, f| {
            f.cob_id == id && f.payload() == [heartbeat::BOOT_UP]
        }) {
            Ok(())
        } else {
            Err(CanOpenError::NoBootUp {
                node,
                timeout_ns: self.config.boot_timeout_ns,
            })
        }
    }

    fn sdo(&mut self, node: u8, request: Sdo) -> Result<Sdo, CanOpenError> {
        let (index, sub) = match request {
            Sdo::Download { index, sub, .. } | Sdo::Upload { index, sub } => (index, sub),
            _ => (0, 0),
        };
        self.send(COB_SDO_RX + u16::from(node), &request.encode())?;
        let id = COB_SDO_TX + u16::from(node);
        let mut reply = None;
        self.wait(self.config.sdo_timeout_ns, |_, f| {
            if f.cob_id != id {
                return false;
            }
            match Sdo::decode(f.payload()) {
                Some(
                    r @ (Sdo::DownloadOk { index: i, sub: s }
                    | Sdo::UploadOk {
                        index: i, sub: s, ..
                    }
                    | Sdo::Abort {
                        index: i, sub: s, ..
                    }),
                ) if i == index && s == sub => {
                    reply = Some(r);
                    true
                }
                _ => false,
            }
        });
        match reply {
            Some(Sdo::Abort { code, .. }) => Err(CanOpenError::SdoAbort {
                node,
                index,
                sub,
                code,
            }),
            Some(r) => Ok(r),
            None => Err(CanOpenError::SdoTimeout {
                node,
                index,
                sub,
                timeout_ns: self.config.sdo_timeout_ns,
            }),
        }
    }

    fn write(
        &mut self,
        node: u8,
        index: u16,
        sub: u8,
        value: u32,
        size: u8,
    ) -> Result<(), CanOpenError> {
        self.sdo(
            node,
            Sdo::Download {
                index,
                sub,
                value,
                size,
            },
        )
        .map(|_| ())
    }

    fn read(&mut self, node: u8, index: u16, sub: u8) -> Result<u32, CanOpenError> {
        match self.sdo(node, Sdo::Upload { index, sub })? {
            Sdo::UploadOk { value, .. } => Ok(value),
            _ => Err(CanOpenError::SdoTimeout {
                node,
                index,
                sub,
                timeout_ns: self.config.sdo_timeout_ns,
            }),
        }
    }

    fn configure(&mut self, node: u8) -> Result<(), CanOpenError> {
        let n = u16::from(node);
        let tpdo = u32::from(COB_TPDO1 + n);
        let rpdo = u32::from(COB_RPDO1 + n);
        let off = 0x8000_0000;
        // TPDO1: status word + position actual, sent at every SYNC.
        self.write(node, od::TPDO1_COMM, 1, off | tpdo, 4)?;
        self.write(node, od::TPDO1_COMM, 2, 1, 1)?;
        self.write(node, od::TPDO1_MAP, 0, 0, 1)?;
        self.write(node, od::TPDO1_MAP, 1, mapping::STATUSWORD, 4)?;
        self.write(node, od::TPDO1_MAP, 2, mapping::POSITION_ACTUAL, 4)?;
        self.write(node, od::TPDO1_MAP, 0, 2, 1)?;
        self.write(node, od::TPDO1_COMM, 1, tpdo, 4)?;
        // RPDO1: control word + target position, applied at the next SYNC.
        self.write(node, od::RPDO1_COMM, 1, off | rpdo, 4)?;
        self.write(node, od::RPDO1_COMM, 2, 1, 1)?;
        self.write(node, od::RPDO1_MAP, 0, 0, 1)?;
        self.write(node, od::RPDO1_MAP, 1, mapping::CONTROLWORD, 4)?;
        self.write(node, od::RPDO1_MAP, 2, mapping::TARGET_POSITION, 4)?;
        self.write(node, od::RPDO1_MAP, 0, 2, 1)?;
        self.write(node, od::RPDO1_COMM, 1, rpdo, 4)?;
        // Cyclic synchronous position, checked.
        self.write(
            node,
            od::MODES_OF_OPERATION,
            0,
            u32::from(MODE_CSP as u8),
            1,
        )?;
        let mode = self.read(node, od::MODES_OF_OPERATION_DISPLAY, 0)? as u8 as i8;
        if mode != MODE_CSP {
            return Err(CanOpenError::WrongMode { node, mode });
        }
        // How the drive stops (a ramp, never coasting: the quick stop, the
        // host's disable, its own fault reaction, and a quick stop when the
        // host's heartbeat is lost), each read back.
        for (index, sub, value, size) in self.config.safe_stop_objects() {
            self.write_checked(node, index, sub, value, size)?;
        }
        self.write(
            node,
            od::PRODUCER_HEARTBEAT,
            0,
            u32::from(self.config.drive_heartbeat_ms),
            2,
        )?;
        let consumer = (u32::from(self.config.host_node_id) << 16)
            | u32::from(self.config.host_heartbeat_timeout_ms);
        self.write_checked(node, od::CONSUMER_HEARTBEAT, 1, consumer, 4)?;
        // The drive's own limits, the second channel outside the host: each
        // written and read back; any other value refuses the start (the
        // drives are never enabled).
        let axis = self.axes.iter().position(|a| a.node == node).unwrap_or(0);
        for (index, sub, value, size) in self.config.drive_limit_objects(axis) {
            self.write_checked(node, index, sub, value, size)?;
        }
        Ok(())
    }

    /// Writes an object and reads it back: a drive that stores another value
    /// (clamped to its own range, or ignored) is
    /// [`CanOpenError::LimitMismatch`].
    fn write_checked(
        &mut self,
        node: u8,
        index: u16,
        sub: u8,
        value: u32,
        size: u8,
    ) -> Result<(), CanOpenError> {
        self.write(node, index, sub, value, size)?;
        let read = self.read(node, index, sub)?;
        if read != value {
            let signed = index == od::SOFTWARE_POSITION_LIMIT;
            let show = |v: u32| {
                if signed {
                    i64::from(v as i32)
                } else {
                    i64::from(v)
                }
            };
            return Err(CanOpenError::LimitMismatch {
                node,
                index,
                sub,
                name: od::name(index),
                written: show(value),
                read: show(read),
            });
        }
        Ok(())
    }

    /// Takes one received frame.
    fn handle(&mut self, f: &RawFrame) {
        let id = f.cob_id;
        let sync = self.sync_count;
        for (i, a) in self.axes.iter_mut().enumerate() {
            let n = u16::from(a.node);
            if id == COB_TPDO1 + n {
                if let Some((sw, counts)) = crate::frame::decode_tpdo(f.payload()) {
                    a.statusword = Some(sw);
                    a.counts = counts;
                    a.tpdo_sync = sync;
                }
            } else if id == COB_HEARTBEAT + n {
                if let [state] = f.payload() {
                    // Without a readable clock the heartbeat is not renewed:
                    // the drive soon counts as lost (a fault), never as alive.
                    if let Ok(now) = self.clock.now_ns() {
                        a.heartbeat_ns = now;
                    }
                    a.nmt_state = *state;
                }
            } else if id == COB_EMCY + n
                && let Some(e) = Emcy::decode(f.payload())
                && e.code != 0
            {
                a.emcy_code = Some(e.code);
                if self.fault.is_none() {
                    self.fault = Some(DriveState::Fault {
                        axis: u8::try_from(i).ok(),
                        code: e.code,
                    });
                }
            }
        }
    }

    fn m(&self, counts: i32) -> f64 {
        f64::from(counts) * self.config.m_per_count()
    }

    fn counts(&self, m: f64) -> i32 {
        // Saturating: targets are checked within travel before.
        (m / self.config.m_per_count()).round() as i32
    }

    /// One control period: SYNC, the TPDOs of that SYNC, supervision, RPDOs,
    /// the host's heartbeat when due. Returns the first bus error seen (after
    /// doing all of the above that the bus allowed).
    pub fn cycle(&mut self) -> Result<CycleReport, CanOpenError> {
        self.bus_error = None;
        // What arrived since the last cycle (heartbeats, EMCY, late TPDOs).
        self.wait(0, |_, _| false);
        let sync_sent = self.send(COB_SYNC, &[]);
        self.sync_ns = self.now()?;
        self.sync_count += 1;
        let sync = self.sync_count;
        if sync_sent.is_ok() {
            self.wait(self.config.pdo_wait_ns, |me, _| {
                me.axes.iter().all(|a| a.tpdo_sync == sync)
            });
        }
        let tpdos = self.axes.iter().filter(|a| a.tpdo_sync == sync).count();
        self.supervise();
        let complete = tpdos == 3;
        if complete {
            let q = self.axes.map(|a| self.m(a.counts));
            let referenced = self
                .axes
                .iter()
                .all(|a| a.statusword.is_some_and(|s| s & STATUS_REFERENCED != 0));
            self.positions = JointPositions {
                joints: ActiveJoints {
                    q1_m: q[0],
                    q2_m: q[1],
                    q3_m: q[2],
                },
                stamp_ns: self.sync_ns,
                valid: referenced,
            };
        }
        self.write_rpdos(complete);
        if self
            .clock
            .now_ns()
            .is_ok_and(|now| now >= self.next_heartbeat_ns)
        {
            let _ = self.send_heartbeat();
        }
        match self.bus_error.take() {
            Some(e) => Err(e),
            None => Ok(CycleReport {
                sync_ns: self.sync_ns,
                sync_count: sync,
                tpdos: u8::try_from(tpdos).unwrap_or(3),
            }),
        }
    }

    fn latch(&mut self, axis: usize, code: u16) {
        if self.fault.is_none() {
            self.fault = Some(DriveState::Fault {
                axis: u8::try_from(axis).ok(),
                code,
            });
        }
    }

    fn lost(&self, a: &Axis) -> bool {
        let timeout = u64::from(self.config.drive_heartbeat_timeout_ms) * 1_000_000;
        // A clock that cannot be read counts as a lost heartbeat.
        self.clock
            .now_ns()
            .map_or(true, |now| now.saturating_sub(a.heartbeat_ns) > timeout)
            || a.nmt_state != heartbeat::OPERATIONAL
    }

    fn supervise(&mut self) {
        for i in 0..3 {
            let Some(a) = self.axes.get(i).copied() else {
                continue;
            };
            if self.lost(&a) {
                self.latch(i, FAULT_LOST);
            }
            match a.cia402() {
                Some(Cia402State::Fault | Cia402State::FaultReactionActive) => {
                    self.latch(i, a.emcy_code.unwrap_or(FAULT_GENERIC));
                }
                Some(s)
                    if a.was_enabled
                        && self.want == Want::Enabled
                        && s != Cia402State::OperationEnabled =>
                {
                    self.latch(i, a.emcy_code.unwrap_or(FAULT_GENERIC));
                }
                _ => {}
            }
        }
        // A fault reset completes once no axis is in Fault or lost, as the
        // TPDOs of this SYNC say, and only once the reset's rising edge has
        // reached the drives (sent in the reset's second cycle, applied at
        // the next SYNC): a status word from before (a TPDO late on a busy
        // bus) never completes it.
        if self.fault.is_some()
            && self
                .reset_cycles
                .is_some_and(|c| c >= RESET_CYCLES_TO_COMPLETE)
        {
            let sync = self.sync_count;
            let clear = self.axes.iter().all(|a| {
                a.tpdo_sync == sync
                    && !self.lost(a)
                    && !matches!(
                        a.cia402(),
                        Some(Cia402State::Fault | Cia402State::FaultReactionActive) | None
                    )
            });
            if clear {
                self.fault = None;
                self.reset_cycles = None;
                self.want = Want::Ready;
                self.halted = false;
                self.goal_m = None;
                for a in &mut self.axes {
                    a.emcy_code = None;
                    a.was_enabled = false;
                }
            }
        }
    }

    fn write_rpdos(&mut self, complete: bool) {
        let next_ns = self.sync_ns.saturating_add(self.config.sync_period_ns);
        let reset_phase = self.reset_cycles.inspect(|c| {
            self.reset_cycles = Some(c.saturating_add(1));
        });
        for i in 0..3 {
            let Some(a) = self.axes.get(i).copied() else {
                continue;
            };
            let state = a.cia402();
            let actual_m = self.m(a.counts);
            let enabled = self.fault.is_none()
                && self.want == Want::Enabled
                && state == Some(Cia402State::OperationEnabled);
            let streaming = enabled && !self.halted;
            let cw = if self.fault.is_some() {
                match (state, reset_phase) {
                    (Some(Cia402State::Fault), Some(0)) => control::DISABLE_VOLTAGE,
                    (Some(Cia402State::Fault), Some(_)) => control::FAULT_RESET,
                    (Some(Cia402State::Fault), None) => control::DISABLE_VOLTAGE,
                    _ => control::QUICK_STOP,
                }
            } else {
                match (self.want, state) {
                    (Want::QuickStop, _) => control::QUICK_STOP,
                    (_, Some(Cia402State::QuickStopActive)) => control::DISABLE_VOLTAGE,
                    (Want::Ready, _) => control::SHUTDOWN,
                    (Want::Enabled, Some(Cia402State::ReadyToSwitchOn)) => control::SWITCH_ON,
                    (
                        Want::Enabled,
                        Some(Cia402State::SwitchedOn | Cia402State::OperationEnabled),
                    ) if self.halted => control::ENABLE_OPERATION | control::HALT,
                    (
                        Want::Enabled,
                        Some(Cia402State::SwitchedOn | Cia402State::OperationEnabled),
                    ) => control::ENABLE_OPERATION,
                    (Want::Enabled, _) => control::SHUTDOWN,
                }
            };
            let fresh = complete || a.tpdo_sync == self.sync_count;
            // Not streaming: hold where the drive is (or, without a fresh
            // position this SYNC, where the host last held it).
            let mut target_m = a.plan.at(next_ns).x_m;
            if let Some(axis) = self.axes.get_mut(i) {
                if streaming {
                    axis.was_enabled = true;
                } else if fresh {
                    axis.plan = AxisPlan::hold(next_ns, actual_m);
                    target_m = actual_m;
                }
            }
            let counts = self.counts(target_m);
            let data = encode_rpdo(cw, counts);
            let _ = self.send(COB_RPDO1 + u16::from(a.node), &data);
        }
    }

    fn check_target(&self, targets: &ActiveJoints) -> Result<[f64; 3], CanOpenError> {
        let q = [targets.q1_m, targets.q2_m, targets.q3_m];
        for (i, (x, (lo, hi))) in q.iter().zip(self.config.travel_m).enumerate() {
            if !(x.is_finite() && *x >= lo && *x <= hi) {
                return Err(CanOpenError::InvalidTarget {
                    axis: u8::try_from(i).unwrap_or(0),
                    value_m: *x,
                    min_m: lo,
                    max_m: hi,
                });
            }
        }
        Ok(q)
    }

    fn logical_state(&self) -> DriveState {
        if let Some(f) = self.fault {
            return f;
        }
        match self.want {
            Want::QuickStop => DriveState::QuickStop,
            Want::Ready => DriveState::Ready,
            Want::Enabled => {
                if self
                    .axes
                    .iter()
                    .all(|a| a.cia402() == Some(Cia402State::OperationEnabled))
                {
                    DriveState::Enabled
                } else {
                    DriveState::Ready
                }
            }
        }
    }
}

impl<C: Can, K: Clock> AxisDrives for CanOpenDrives<C, K> {
    type Error = CanOpenError;

    /// The positions of the last SYNC whose three TPDOs arrived, stamped with
    /// that SYNC's time; valid only with every encoder referenced (status
    /// word bit 15), no fault, and not older than two SYNC periods.
    fn positions(&mut self) -> Result<JointPositions, CanOpenError> {
        let mut p = self.positions;
        let age = self.now()?.saturating_sub(p.stamp_ns);
        p.valid = p.valid
            && self.fault.is_none()
            && age
                <= self
                    .config
                    .sync_period_ns
                    .saturating_mul(2)
                    .saturating_add(self.config.pdo_wait_ns);
        Ok(p)
    }

    fn state(&mut self) -> Result<DriveState, CanOpenError> {
        Ok(self.logical_state())
    }

    fn enable(&mut self) -> Result<(), CanOpenError> {
        match self.logical_state() {
            s @ (DriveState::Fault { .. } | DriveState::QuickStop) => {
                Err(CanOpenError::InvalidState { state: s })
            }
            _ => {
                if self.want != Want::Enabled {
                    self.halted = false;
                    self.goal_m = None;
                }
                self.want = Want::Enabled;
                Ok(())
            }
        }
    }

    fn disable(&mut self) -> Result<(), CanOpenError> {
        match self.logical_state() {
            s @ DriveState::Fault { .. } => Err(CanOpenError::InvalidState { state: s }),
            _ => {
                self.want = Want::Ready;
                self.halted = false;
                self.goal_m = None;
                for a in &mut self.axes {
                    a.was_enabled = false;
                }
                Ok(())
            }
        }
    }

    fn set_targets(&mut self, targets: ActiveJoints) -> Result<(), CanOpenError> {
        let state = self.logical_state();
        if state != DriveState::Enabled {
            return Err(CanOpenError::InvalidState { state });
        }
        let q = self.check_target(&targets)?;
        self.goal_m = Some(q);
        if !self.halted {
            self.plan_to(q);
        }
        Ok(())
    }

    fn stream(&mut self, targets: ActiveJoints, period_ns: u64) -> Result<(), CanOpenError> {
        let state = self.logical_state();
        if state != DriveState::Enabled {
            return Err(CanOpenError::InvalidState { state });
        }
        let q = self.check_target(&targets)?;
        // The set point of the next SYNC: each axis at constant speed from
        // its commanded position there, held until the next set point.
        let start_ns = self.sync_ns.saturating_add(self.config.sync_period_ns);
        let reach_m = self.limits.max_speed_mps * (period_ns.max(1) as f64 * 1e-9) * (1.0 + 1e-9);
        for (i, (a, target)) in self.axes.iter().zip(q).enumerate() {
            let from = a.plan.at(start_ns).x_m;
            if (target - from).abs() > reach_m {
                return Err(CanOpenError::InvalidTarget {
                    axis: u8::try_from(i).unwrap_or(0),
                    value_m: target,
                    min_m: from - reach_m,
                    max_m: from + reach_m,
                });
            }
        }
        self.goal_m = Some(q);
        if !self.halted {
            for (a, target) in self.axes.iter_mut().zip(q) {
                let from = a.plan.at(start_ns).x_m;
                a.plan = AxisPlan::segment(start_ns, from, target, period_ns);
            }
        }
        Ok(())
    }

    fn quick_stop(&mut self) -> Result<(), CanOpenError> {
        if self.fault.is_none() {
            self.want = Want::QuickStop;
            self.halted = false;
            self.goal_m = None;
            for a in &mut self.axes {
                a.was_enabled = false;
            }
        }
        Ok(())
    }

    fn fault_reset(&mut self) -> Result<(), CanOpenError> {
        let state = self.logical_state();
        let DriveState::Fault { .. } = state else {
            return Err(CanOpenError::InvalidState { state });
        };
        for (i, a) in self.axes.iter().enumerate() {
            if self.lost(a) {
                return Err(CanOpenError::FaultPersists {
                    axis: u8::try_from(i).unwrap_or(0),
                    code: FAULT_LOST,
                });
            }
        }
        // Each call makes a new rising edge of bit 7 (low for one SYNC, then high).
        self.reset_cycles = Some(0);
        Ok(())
    }
}
