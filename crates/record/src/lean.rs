//! The lean recording mode (`[record] mode = "inputs"`): only what replay
//! needs, in `/sar/cycle/batch` ([`CycleBatch`]), beside the snapshots,
//! the guard events (for a quick look), the recorder's drops and the
//! configuration's metadata; `sarctl replay --output` makes the full
//! recording of it, bit for bit.
//!
//! - [`LeanWriter`]: on the recorder's writer thread (never the loop's),
//!   the messages the loop queued for the full recording in, batches out:
//!   `/sar/cycle/input`, `/sar/sensor/wrench` and `/sar/joints` of up to
//!   [`CYCLES_PER_BATCH`] cycles become one batch; the outputs the replay
//!   makes again (`/sar/estimate/*`) and the simulator's truth are left
//!   out; a guard event is written after the batch of its cycle, a
//!   snapshot after the batch before it. A message that does not fit a
//!   batch (its cycle's input was dropped) is written as it is.
//! - [`unbatch`]: a batch back into its cycles ([`LeanCycle`]): the
//!   `/sar/cycle/input` of each (its input fields; the step's decision is
//!   the replay's), its `/sar/sensor/wrench` messages and whether it
//!   recorded `/sar/joints`.
//!
//! Numbers are never rounded: a force, torque or position is stored as the
//! device's counts only when the driver's own formula ([`LeanScales`])
//! gives back the recorded float bit for bit, else as the float.

use super::convert;
use super::file::{RotatingWriter, WriteError};
use sar_msgs::cdr::CdrError;
use sar_msgs::msgs::{
    ActiveJointState, ClockStatusCode, CommandKindCode, CycleBatch, CycleInput as CycleInputMsg,
    DriveStateCode, GuardEvent, Outgoing, RecorderDrops, Topic, WrenchStamped, batch_flags as flag,
};

/// The `sar_replay` metadata key of a lean file: `record_mode = "inputs"`
/// (absent in a full one).
pub const RECORD_MODE_KEY: &str = "record_mode";

/// Cycles per batch at most (100 ms at 1 kHz: what a cut file loses at
/// most beyond its last whole chunk).
pub const CYCLES_PER_BATCH: usize = 100;

/// The devices' scales (`[record]`'s, from the drivers).
pub use sar_config::DeviceScales as LeanScales;

/// `v` as counts when `counts / per` is `v` bit for bit.
fn counts_divided(v: f64, per: f64) -> Option<i32> {
    if per == 0.0 || !v.is_finite() {
        return None;
    }
    let c = (v * per).round();
    if !(c >= f64::from(i32::MIN) && c <= f64::from(i32::MAX)) {
        return None;
    }
    let c = c as i32;
    ((f64::from(c) / per).to_bits() == v.to_bits()).then_some(c)
}

/// `v` as counts when `counts * m` is `v` bit for bit.
fn counts_multiplied(v: f64, m: f64) -> Option<i32> {
    if m == 0.0 || !v.is_finite() {
        return None;
    }
    let c = (v / m).round();
    if !(c >= f64::from(i32::MIN) && c <= f64::from(i32::MAX)) {
        return None;
    }
    let c = c as i32;
    ((f64::from(c) * m).to_bits() == v.to_bits()).then_some(c)
}

fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

/// The wrapping difference `a - b` of two u64 (exact both ways).
fn diff_u64(a: u64, b: u64) -> i64 {
    a.wrapping_sub(b) as i64
}

fn undiff_u64(d: i64, b: u64) -> u64 {
    b.wrapping_add(d as u64)
}

/// What a difference is taken from: the previous cycle's values in the
/// batch (all 0 at its start).
#[derive(Debug, Clone, Copy, Default)]
struct Previous {
    cycle: u64,
    now_ns: u64,
    publisher_idle_ns: u64,
    sensor_counter: u32,
    sensor_stamp_ns: u64,
    joints_stamp_ns: u64,
    /// The last counts stored (raw cycles leave them).
    sensor_counts: [i32; 6],
    joint_counts: [i32; 3],
    /// The previous cycle's floats (`None`: the batch's first cycle).
    wrench: Option<[f64; 6]>,
    joints: Option<[f64; 3]>,
}

fn wrench_of(m: &CycleInputMsg) -> [f64; 6] {
    let [fx, fy, fz] = m.sensor_force_n;
    let [tx, ty, tz] = m.sensor_torque_nm;
    [fx, fy, fz, tx, ty, tz]
}

/// Whether a cycle input carries a command (any of its fields set).
fn has_command(m: &CycleInputMsg) -> bool {
    let none = CycleInputMsg::default();
    m.command_kind != CommandKindCode::None
        || !same_bits(&m.command_values, &none.command_values)
        || m.command_arg != 0
        || !same_bits(&m.move_tip_m, &none.move_tip_m)
        || !same_bits(&m.limits_n, &none.limits_n)
        || m.back_out_m.to_bits() != 0
        || m.move_max_force_n.to_bits() != 0
        || m.command_layout != none.command_layout
        || m.hold_max_force_n.to_bits() != 0
        || m.push_axial_n.to_bits() != 0
        || !same_bits(&m.excite_amplitude_m, &none.excite_amplitude_m)
        || !same_bits(&m.excite_freq_hz, &none.excite_freq_hz)
        || m.excite_duration_s.to_bits() != 0
        || m.excite_fade_s.to_bits() != 0
}

/// Builds one batch, a cycle at a time.
#[derive(Debug)]
struct BatchBuilder {
    batch: CycleBatch,
    cycles: usize,
    prev: Previous,
}

impl BatchBuilder {
    fn new(scales: LeanScales) -> Self {
        let cap = CYCLES_PER_BATCH;
        let batch = CycleBatch {
            stamp_ns: 0,
            force_counts_per_n: scales.force_counts_per_n,
            torque_counts_per_nm: scales.torque_counts_per_nm,
            joint_m_per_count: scales.joint_m_per_count,
            flags: Vec::with_capacity(cap),
            cycle: Vec::with_capacity(cap),
            now_ns: Vec::with_capacity(cap),
            clock_status: Vec::with_capacity(cap),
            publisher_idle_ns: Vec::with_capacity(cap),
            sensor_counter: Vec::with_capacity(cap),
            sensor_status: Vec::with_capacity(cap),
            sensor_stamp_ns: Vec::with_capacity(cap),
            sensor_counts: Vec::with_capacity(6 * cap),
            joints_stamp_ns: Vec::with_capacity(cap),
            joint_counts: Vec::with_capacity(3 * cap),
            drive_state: Vec::with_capacity(cap),
            drive_fault_axis: Vec::with_capacity(cap),
            drive_fault_code: Vec::with_capacity(cap),
            drained_counts: Vec::with_capacity(2 * cap),
            ..CycleBatch::default()
        };
        Self {
            batch,
            cycles: 0,
            prev: Previous::default(),
        }
    }

    /// Empties the batch (its capacity kept).
    fn clear(&mut self) {
        let b = &mut self.batch;
        for v in [&mut b.flags, &mut b.clock_status, &mut b.drive_state] {
            v.clear();
        }
        for v in [
            &mut b.cycle,
            &mut b.now_ns,
            &mut b.publisher_idle_ns,
            &mut b.sensor_stamp_ns,
            &mut b.joints_stamp_ns,
        ] {
            v.clear();
        }
        for v in [
            &mut b.sensor_counts,
            &mut b.joint_counts,
            &mut b.sensor_counter,
        ] {
            v.clear();
        }
        for v in [&mut b.sensor_raw, &mut b.joints_raw, &mut b.extra_wrench] {
            v.clear();
        }
        b.sensor_status.clear();
        b.drive_fault_axis.clear();
        b.drive_fault_code.clear();
        b.drained_counts.clear();
        b.extra_cycles.clear();
        b.extra_stamp_ns.clear();
        b.command_cycles.clear();
        b.commands.clear();
        self.cycles = 0;
        self.prev = Previous::default();
    }

    /// One cycle: its input, its `/sar/sensor/wrench` messages in order,
    /// whether `/sar/joints` was recorded.
    fn add(&mut self, m: &CycleInputMsg, sensors: &[WrenchStamped], joints_message: bool) {
        let at = u32::try_from(self.cycles).unwrap_or(u32::MAX);
        if self.cycles == 0 {
            self.batch.stamp_ns = m.stamp_ns;
        }
        let mut f = 0u8;
        if m.sensor_valid {
            f |= flag::SENSOR_VALID;
        }
        if m.joints_valid {
            f |= flag::JOINTS_VALID;
        }
        if joints_message {
            f |= flag::JOINTS_MESSAGE;
        }
        f |= self.sensor_messages(at, m, sensors);
        f |= self.sensor_values(m);
        f |= self.joint_values(m);
        let (b, p) = (&mut self.batch, &mut self.prev);
        b.flags.push(f);
        b.cycle.push(diff_u64(m.cycle, p.cycle));
        b.now_ns.push(diff_u64(m.now_ns, p.now_ns));
        b.clock_status.push(m.clock_status as u8);
        // The idle time grows with now while the publisher's heartbeat
        // does not change: the difference of both is 0 then.
        b.publisher_idle_ns.push(
            diff_u64(m.publisher_idle_ns, p.publisher_idle_ns)
                .wrapping_sub(diff_u64(m.now_ns, p.now_ns)),
        );
        b.sensor_counter
            .push(m.sensor_counter.wrapping_sub(p.sensor_counter) as i32);
        b.sensor_status.push(m.sensor_status);
        b.sensor_stamp_ns
            .push(diff_u64(m.sensor_stamp_ns, p.sensor_stamp_ns));
        b.joints_stamp_ns
            .push(diff_u64(m.joints_stamp_ns, p.joints_stamp_ns));
        b.drive_state.push(m.drive_state as u8);
        b.drive_fault_axis.push(m.drive_fault_axis);
        b.drive_fault_code.push(m.drive_fault_code);
        b.drained_counts.extend([
            if m.sensor_drained_counted {
                m.sensor_drained_samples.saturating_add(1)
            } else {
                0
            },
            m.sensor_drained_jumps,
        ]);
        if has_command(m) {
            b.command_cycles.push(at);
            b.commands.push(*m);
        }
        p.cycle = m.cycle;
        p.now_ns = m.now_ns;
        p.publisher_idle_ns = m.publisher_idle_ns;
        p.sensor_counter = m.sensor_counter;
        p.sensor_stamp_ns = m.sensor_stamp_ns;
        p.joints_stamp_ns = m.joints_stamp_ns;
        self.cycles += 1;
    }

    /// The cycle's sensor messages: the last one is the cycle's sample
    /// when it is, bit for bit (a flag); the others are extras.
    fn sensor_messages(&mut self, at: u32, m: &CycleInputMsg, sensors: &[WrenchStamped]) -> u8 {
        let own = WrenchStamped::sensor(m.sensor_stamp_ns, m.sensor_force_n, m.sensor_torque_nm);
        let is_own = |w: &WrenchStamped| {
            w.stamp_ns == own.stamp_ns
                && w.frame_id == own.frame_id
                && same_bits(&w.force_n, &own.force_n)
                && same_bits(&w.torque_nm, &own.torque_nm)
        };
        let (extras, f) = match sensors.split_last() {
            Some((last, rest)) if is_own(last) => (rest, flag::SENSOR_MESSAGE),
            _ => (sensors, 0),
        };
        for w in extras {
            self.batch.extra_cycles.push(at);
            self.batch.extra_stamp_ns.push(w.stamp_ns);
            self.batch.extra_wrench.extend_from_slice(&w.force_n);
            self.batch.extra_wrench.extend_from_slice(&w.torque_nm);
        }
        f
    }

    /// Force and torque: repeated, counts, or floats.
    fn sensor_values(&mut self, m: &CycleInputMsg) -> u8 {
        let wrench = wrench_of(m);
        let repeat = self.prev.wrench.is_some_and(|w| same_bits(&w, &wrench));
        self.prev.wrench = Some(wrench);
        if repeat {
            self.batch.sensor_counts.extend_from_slice(&[0; 6]);
            return flag::SENSOR_REPEAT;
        }
        let (per_n, per_nm) = (
            self.batch.force_counts_per_n,
            self.batch.torque_counts_per_nm,
        );
        let mut counts = [0i32; 6];
        for (k, (c, v)) in counts.iter_mut().zip(wrench).enumerate() {
            let per = if k < 3 { per_n } else { per_nm };
            match counts_divided(v, per) {
                Some(x) => *c = x,
                None => {
                    self.batch.sensor_counts.extend_from_slice(&[0; 6]);
                    self.batch.sensor_raw.extend_from_slice(&wrench);
                    return flag::SENSOR_RAW;
                }
            }
        }
        for (c, p) in counts.iter().zip(&self.prev.sensor_counts) {
            self.batch.sensor_counts.push(c.wrapping_sub(*p));
        }
        self.prev.sensor_counts = counts;
        0
    }

    /// The positions: repeated, counts, or floats.
    fn joint_values(&mut self, m: &CycleInputMsg) -> u8 {
        let q = m.joints_q_m;
        let repeat = self.prev.joints.is_some_and(|p| same_bits(&p, &q));
        self.prev.joints = Some(q);
        if repeat {
            self.batch.joint_counts.extend_from_slice(&[0; 3]);
            return flag::JOINTS_REPEAT;
        }
        let m_per_count = self.batch.joint_m_per_count;
        let mut counts = [0i32; 3];
        for (c, v) in counts.iter_mut().zip(q) {
            match counts_multiplied(v, m_per_count) {
                Some(x) => *c = x,
                None => {
                    self.batch.joint_counts.extend_from_slice(&[0; 3]);
                    self.batch.joints_raw.extend_from_slice(&q);
                    return flag::JOINTS_RAW;
                }
            }
        }
        for (c, p) in counts.iter().zip(&self.prev.joint_counts) {
            self.batch.joint_counts.push(c.wrapping_sub(*p));
        }
        self.prev.joint_counts = counts;
        0
    }
}

/// The cycle being gathered: its input and the messages after it.
#[derive(Debug)]
struct Gathering {
    /// Whether a cycle is being gathered (its input came, its outputs not).
    open: bool,
    input: CycleInputMsg,
    sensors: Vec<WrenchStamped>,
    joints_message: bool,
}

/// `/sar/joints` of a cycle as the recorder writes it
/// (`convert::joints_msg` of its input's joint sample).
pub fn joints_msg_of(m: &CycleInputMsg) -> ActiveJointState {
    ActiveJointState {
        stamp_ns: m.joints_stamp_ns,
        q_m: m.joints_q_m,
    }
}

/// The lean mode's writer (on the recorder's writer thread): the full
/// recording's messages in, batches and the rest out (see the module).
#[derive(Debug)]
pub struct LeanWriter {
    builder: BatchBuilder,
    gathering: Gathering,
    /// Guard events waiting for the batch of their cycle.
    events: Vec<GuardEvent>,
}

impl LeanWriter {
    /// A writer with the devices' scales.
    pub fn new(scales: LeanScales) -> Self {
        Self {
            builder: BatchBuilder::new(scales),
            gathering: Gathering {
                open: false,
                input: CycleInputMsg::default(),
                sensors: Vec::with_capacity(16),
                joints_message: false,
            },
            events: Vec::with_capacity(8),
        }
    }

    /// One message of the queue, in order: gathered, left out, or written
    /// (a snapshot after the batch before it).
    pub fn write(
        &mut self,
        files: &mut RotatingWriter,
        msg: &Outgoing,
        status: &RecorderDrops,
    ) -> Result<(), WriteError> {
        match msg {
            Outgoing::CycleInput(m) => {
                self.end_cycle();
                // A stamp beyond the format's range (2^31 s): the cycle is
                // dropped and counted, as the full mode drops its messages,
                // never the batch it would go into.
                if m.stamp_ns / 1_000_000_000 > i32::MAX as u64 {
                    return Err(WriteError::Encode {
                        topic: Topic::CycleInput.name(),
                        source: CdrError::StampTooLarge {
                            stamp_ns: m.stamp_ns,
                        },
                    });
                }
                if self.builder.cycles >= CYCLES_PER_BATCH {
                    self.flush(files, status)?;
                }
                let g = &mut self.gathering;
                g.open = true;
                g.input = *m;
                g.sensors.clear();
                g.joints_message = false;
                Ok(())
            }
            Outgoing::SensorWrench(w) => {
                let g = &mut self.gathering;
                if g.open && !g.joints_message {
                    g.sensors.push(*w);
                    return Ok(());
                }
                files.write(msg, status)
            }
            Outgoing::Joints(j) => {
                let g = &mut self.gathering;
                if g.open && !g.joints_message && *j == joints_msg_of(&g.input) {
                    g.joints_message = true;
                    return Ok(());
                }
                files.write(msg, status)
            }
            // Made again by the replay; the truth is the simulator's.
            Outgoing::EstimatorState(_)
            | Outgoing::TipWrench(_)
            | Outgoing::TipWrenchFiltered(_)
            | Outgoing::PassiveJoints(_)
            | Outgoing::SimTruth(_) => {
                self.end_cycle();
                Ok(())
            }
            Outgoing::GuardEvent(e) => {
                self.end_cycle();
                self.events.push(*e);
                Ok(())
            }
            Outgoing::SnapshotChunk(c) => {
                if c.index == 0 {
                    self.flush(files, status)?;
                }
                files.write(msg, status)
            }
            Outgoing::RecorderDrops(_) => files.write(msg, status),
        }
    }

    /// The cycle gathered goes into the batch (its messages are all in:
    /// an output or the next cycle came).
    fn end_cycle(&mut self) {
        let g = &mut self.gathering;
        if g.open {
            self.builder.add(&g.input, &g.sensors, g.joints_message);
            g.open = false;
        }
    }

    /// Writes the batch (with the cycle gathered) and the guard events
    /// after it; before a snapshot, a close and every
    /// [`CYCLES_PER_BATCH`] cycles.
    pub fn flush(
        &mut self,
        files: &mut RotatingWriter,
        status: &RecorderDrops,
    ) -> Result<(), WriteError> {
        self.end_cycle();
        if self.builder.cycles > 0 {
            files.write_batch(&self.builder.batch, status)?;
            self.builder.clear();
        }
        for e in self.events.drain(..) {
            files.write(&Outgoing::GuardEvent(e), status)?;
        }
        Ok(())
    }
}

/// One cycle of a batch.
#[derive(Debug, Clone, PartialEq)]
pub struct LeanCycle {
    /// Its `/sar/cycle/input` with the input's fields (the decision's are
    /// the replay's; a command cycle's as recorded).
    pub input: CycleInputMsg,
    /// Its `/sar/sensor/wrench` messages, in order.
    pub sensors: Vec<WrenchStamped>,
    /// Whether it recorded `/sar/joints` (its joint sample).
    pub joints_message: bool,
}

/// Why a batch cannot be read back.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("/sar/cycle/batch at {stamp_ns} ns: {why}")]
pub struct BatchError {
    /// The batch's stamp.
    pub stamp_ns: u64,
    /// What is wrong.
    pub why: &'static str,
}

/// Reads arrays in step, refusing a short one.
struct Cursor<'b> {
    b: &'b CycleBatch,
    raw_sensor: usize,
    raw_joints: usize,
    extra: usize,
    command: usize,
}

impl Cursor<'_> {
    fn err(&self, why: &'static str) -> BatchError {
        BatchError {
            stamp_ns: self.b.stamp_ns,
            why,
        }
    }
}

fn at<T: Copy>(v: &[T], i: usize, c: &Cursor<'_>, why: &'static str) -> Result<T, BatchError> {
    v.get(i).copied().ok_or_else(|| c.err(why))
}

fn take<const N: usize>(
    v: &[f64],
    next: &mut usize,
    c: &Cursor<'_>,
    why: &'static str,
) -> Result<[f64; N], BatchError> {
    let s = v
        .get(*next..*next + N)
        .and_then(|s| <[f64; N]>::try_from(s).ok())
        .ok_or_else(|| c.err(why))?;
    *next += N;
    Ok(s)
}

/// The cycles of a batch, in order (the inverse of the lean writer's
/// batching): every field of each cycle's input bit for bit.
pub fn unbatch(b: &CycleBatch) -> Result<Vec<LeanCycle>, BatchError> {
    let n = b.flags.len();
    let mut c = Cursor {
        b,
        raw_sensor: 0,
        raw_joints: 0,
        extra: 0,
        command: 0,
    };
    let mut p = Previous::default();
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        out.push(unbatch_one(b, i, &mut c, &mut p)?);
    }
    if c.extra != b.extra_cycles.len() || c.command != b.command_cycles.len() {
        return Err(c.err("an extra sensor message or a command names no cycle of the batch"));
    }
    Ok(out)
}

fn unbatch_one(
    b: &CycleBatch,
    i: usize,
    c: &mut Cursor<'_>,
    p: &mut Previous,
) -> Result<LeanCycle, BatchError> {
    let short = "an array is shorter than the flags";
    let f = at(&b.flags, i, c, short)?;
    let mut m = match b.command_cycles.get(c.command) {
        Some(&k) if k as usize == i => {
            let whole = b.commands.get(c.command).ok_or_else(|| c.err(short))?;
            c.command += 1;
            *whole
        }
        _ => CycleInputMsg::default(),
    };
    m.cycle = undiff_u64(at(&b.cycle, i, c, short)?, p.cycle);
    m.now_ns = undiff_u64(at(&b.now_ns, i, c, short)?, p.now_ns);
    m.clock_status = ClockStatusCode::from_code(at(&b.clock_status, i, c, short)?)
        .map_err(|_| c.err("a clock status out of range"))?;
    let idle_d = at(&b.publisher_idle_ns, i, c, short)?.wrapping_add(diff_u64(m.now_ns, p.now_ns));
    m.publisher_idle_ns = undiff_u64(idle_d, p.publisher_idle_ns);
    m.sensor_counter = p
        .sensor_counter
        .wrapping_add(at(&b.sensor_counter, i, c, short)? as u32);
    m.sensor_status = at(&b.sensor_status, i, c, short)?;
    m.sensor_stamp_ns = undiff_u64(at(&b.sensor_stamp_ns, i, c, short)?, p.sensor_stamp_ns);
    m.sensor_valid = f & flag::SENSOR_VALID != 0;
    m.joints_stamp_ns = undiff_u64(at(&b.joints_stamp_ns, i, c, short)?, p.joints_stamp_ns);
    m.joints_valid = f & flag::JOINTS_VALID != 0;
    m.drive_state = DriveStateCode::from_code(at(&b.drive_state, i, c, short)?)
        .map_err(|_| c.err("a drive state out of range"))?;
    m.drive_fault_axis = at(&b.drive_fault_axis, i, c, short)?;
    m.drive_fault_code = at(&b.drive_fault_code, i, c, short)?;
    // (None in a lean file older than the counts: not counted.)
    if !b.drained_counts.is_empty() {
        let samples = at(&b.drained_counts, 2 * i, c, short)?;
        m.sensor_drained_counted = samples > 0;
        m.sensor_drained_samples = samples.saturating_sub(1);
        m.sensor_drained_jumps = at(&b.drained_counts, 2 * i + 1, c, short)?;
    }
    let w = sensor_of(b, i, f, c, p)?;
    m.sensor_force_n = [w[0], w[1], w[2]];
    m.sensor_torque_nm = [w[3], w[4], w[5]];
    m.joints_q_m = joints_of(b, i, f, c, p)?;
    p.cycle = m.cycle;
    p.now_ns = m.now_ns;
    p.publisher_idle_ns = m.publisher_idle_ns;
    p.sensor_counter = m.sensor_counter;
    p.sensor_stamp_ns = m.sensor_stamp_ns;
    p.joints_stamp_ns = m.joints_stamp_ns;
    m.stamp_ns = convert::cycle_stamp_ns(&convert::loop_input(&m).cycle_input());
    Ok(LeanCycle {
        sensors: sensor_messages_of(b, i, f, &m, c)?,
        input: m,
        joints_message: f & flag::JOINTS_MESSAGE != 0,
    })
}

/// A cycle's `/sar/sensor/wrench` messages: its extras, then its own
/// sample when it was recorded.
fn sensor_messages_of(
    b: &CycleBatch,
    i: usize,
    f: u8,
    m: &CycleInputMsg,
    c: &mut Cursor<'_>,
) -> Result<Vec<WrenchStamped>, BatchError> {
    let short = "an array is shorter than the flags";
    let mut sensors = Vec::new();
    while let Some(&k) = b.extra_cycles.get(c.extra)
        && k as usize == i
    {
        let stamp_ns = at(&b.extra_stamp_ns, c.extra, c, short)?;
        let mut next = c.extra * 6;
        let w: [f64; 6] = take(&b.extra_wrench, &mut next, c, short)?;
        sensors.push(WrenchStamped::sensor(
            stamp_ns,
            [w[0], w[1], w[2]],
            [w[3], w[4], w[5]],
        ));
        c.extra += 1;
    }
    if f & flag::SENSOR_MESSAGE != 0 {
        sensors.push(WrenchStamped::sensor(
            m.sensor_stamp_ns,
            m.sensor_force_n,
            m.sensor_torque_nm,
        ));
    }
    Ok(sensors)
}

/// One channel of a lean batch (the sensor's wrench, the joints'
/// positions): its flags, its per-cycle count differences and raw values.
struct Channel<'b, const N: usize> {
    /// The flag of a cycle that repeats the previous values.
    repeat: u8,
    /// The flag of a cycle whose values are raw (not counts).
    raw: u8,
    /// Every cycle's count differences, `N` a cycle.
    counts: &'b [i32],
    /// The raw cycles' values, `N` each, in order.
    raw_values: &'b [f64],
}

/// A cycle's values of `ch`: repeated, raw (read at `*raw_at`), or the
/// counts accumulated into `sums` and converted by `convert(component,
/// count)`; kept in `last` for a repeat.
fn channel_of<const N: usize>(
    ch: &Channel<'_, N>,
    (i, f): (usize, u8),
    c: &Cursor<'_>,
    raw_at: &mut usize,
    (last, sums): (&mut Option<[f64; N]>, &mut [i32; N]),
    convert: impl Fn(usize, i32) -> f64,
) -> Result<[f64; N], BatchError> {
    let short = "an array is shorter than the flags";
    let counts: [i32; N] = ch
        .counts
        .get(N * i..N * i + N)
        .and_then(|s| <[i32; N]>::try_from(s).ok())
        .ok_or_else(|| c.err(short))?;
    let v = if f & ch.repeat != 0 {
        last.ok_or_else(|| c.err("the first cycle repeats no cycle"))?
    } else if f & ch.raw != 0 {
        take(ch.raw_values, raw_at, c, short)?
    } else {
        let mut v = [0.0; N];
        for (k, ((v, d), pc)) in v.iter_mut().zip(counts).zip(sums.iter_mut()).enumerate() {
            *pc = pc.wrapping_add(d);
            *v = convert(k, *pc);
        }
        v
    };
    *last = Some(v);
    Ok(v)
}

/// A cycle's force and torque (repeated, raw or counts).
fn sensor_of(
    b: &CycleBatch,
    i: usize,
    f: u8,
    c: &mut Cursor<'_>,
    p: &mut Previous,
) -> Result<[f64; 6], BatchError> {
    let ch = Channel {
        repeat: flag::SENSOR_REPEAT,
        raw: flag::SENSOR_RAW,
        counts: &b.sensor_counts,
        raw_values: &b.sensor_raw,
    };
    let mut raw_at = c.raw_sensor;
    let w = channel_of(
        &ch,
        (i, f),
        c,
        &mut raw_at,
        (&mut p.wrench, &mut p.sensor_counts),
        |k, count| {
            let per = if k < 3 {
                b.force_counts_per_n
            } else {
                b.torque_counts_per_nm
            };
            f64::from(count) / per
        },
    )?;
    c.raw_sensor = raw_at;
    Ok(w)
}

/// A cycle's positions (repeated, raw or counts).
fn joints_of(
    b: &CycleBatch,
    i: usize,
    f: u8,
    c: &mut Cursor<'_>,
    p: &mut Previous,
) -> Result<[f64; 3], BatchError> {
    let ch = Channel {
        repeat: flag::JOINTS_REPEAT,
        raw: flag::JOINTS_RAW,
        counts: &b.joint_counts,
        raw_values: &b.joints_raw,
    };
    let mut raw_at = c.raw_joints;
    let q = channel_of(
        &ch,
        (i, f),
        c,
        &mut raw_at,
        (&mut p.joints, &mut p.joint_counts),
        |_, count| f64::from(count) * b.joint_m_per_count,
    )?;
    c.raw_joints = raw_at;
    Ok(q)
}

/// Why a lean recording's cycles cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum LeanReadError {
    /// The file.
    #[error(transparent)]
    Read(#[from] super::reader::ReadError),
    /// A batch.
    #[error(transparent)]
    Batch(#[from] BatchError),
}

/// Whether the recording `reader` opens is a lean one (its `sar_replay`
/// metadata says `record_mode`; read up to its first message).
pub fn is_lean(mut reader: super::reader::McapReader<'_>) -> bool {
    let _ = reader.next();
    reader
        .metadata()
        .iter()
        .any(|m| m.name == convert::REPLAY_METADATA && m.metadata.contains_key(RECORD_MODE_KEY))
}

/// The cycles of a lean recording, streamed batch by batch (what `sarctl
/// identify` reads of one instead of `/sar/joints` and
/// `/sar/sensor/wrench`).
pub fn cycles<'a>(
    reader: super::reader::McapReader<'a>,
) -> impl Iterator<Item = Result<LeanCycle, LeanReadError>> + 'a {
    reader
        .typed::<CycleBatch>(Topic::CycleBatch.name())
        .flat_map(|item| {
            match item
                .map_err(LeanReadError::from)
                .and_then(|(_, b)| unbatch(&b).map_err(LeanReadError::from))
            {
                Ok(v) => v.into_iter().map(Ok).collect::<Vec<_>>(),
                Err(e) => vec![Err(e)],
            }
        })
}
