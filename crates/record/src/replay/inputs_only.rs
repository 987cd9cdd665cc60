//! Recordings of the inputs alone (`/sar/sensor/wrench`, `/sar/joints`):
//! the window that puts them in log-time order ([`INPUT_WINDOW`]) and the
//! cycles made of them.

use super::options::ReplayError;
use super::replayer::Replayer;
use sar_estimator::Vec3;
use sar_estimator::cycle::{Command, CommandAccepted, CycleInput, JointSample, SensorSample};
use sar_kinematics::ActiveJoints;
use sar_msgs::msgs::ActiveJointState;

/// The most inputs-only messages (`/sar/sensor/wrench`, `/sar/joints`) held
/// to put them in log-time order: a recording whose messages are further out
/// of order than this is refused ([`ReplayError::Order`]), never paired
/// wrongly. 4096 messages are about 2 s of a 1 kHz sensor and joints.
pub const INPUT_WINDOW: usize = 4096;

/// One inputs-only message waiting in the window.
#[derive(Debug)]
pub(super) enum InputItem {
    Joints(ActiveJointState),
    Sensor(sar_msgs::msgs::WrenchStamped),
}

/// Its place in the replay's order: log time, then joints before a sensor
/// sample at the same time (the joint at or before a sample pairs with it),
/// then the order in the file.
#[derive(Debug)]
pub(super) struct Pending {
    pub(super) key: (u64, u8, u64),
    pub(super) item: InputItem,
}

impl PartialEq for Pending {
    fn eq(&self, other: &Self) -> bool {
        self.key == other.key
    }
}
impl Eq for Pending {}
impl PartialOrd for Pending {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Pending {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.key.cmp(&other.key)
    }
}

/// The replay of an inputs-only recording, streamed: messages enter a
/// window of at most [`INPUT_WINDOW`] ordered by [`Pending::key`]; the
/// earliest leaves when the window is full, and its cycle runs. The result
/// is the one of sorting the whole recording (as the replay did when it held
/// it in memory) whenever no message is more than the window out of order;
/// otherwise the replay stops with [`ReplayError::Order`].
pub(super) struct InputsOnly {
    pub(super) window: std::collections::BinaryHeap<std::cmp::Reverse<Pending>>,
    /// Messages pushed, for the order in the file.
    pub(super) sequence: u64,
    /// Sensor messages seen (in any order).
    pub(super) sensors_seen: u64,
    /// The key of the last message out of the window.
    pub(super) last_key: Option<(u64, u8, u64)>,
    /// Whether a message has left the window (a cycle may have run).
    pub(super) started: bool,
    /// The newest joint message out of the window.
    pub(super) latest: Option<ActiveJointState>,
    /// Sensor messages out of the window (the counter given to the cycle).
    pub(super) sensor_index: u64,
    pub(super) cycle: u64,
    pub(super) reset_pending: bool,
}

impl InputsOnly {
    pub(super) fn new() -> Self {
        Self {
            window: std::collections::BinaryHeap::with_capacity(INPUT_WINDOW),
            sequence: 0,
            sensors_seen: 0,
            last_key: None,
            started: false,
            latest: None,
            sensor_index: 0,
            cycle: 0,
            reset_pending: true,
        }
    }

    /// Forget the window: the recording turned out to hold cycle inputs.
    pub(super) fn discard(&mut self) {
        debug_assert!(!self.started, "inputs-only cycles ran before a cycle input");
        self.window.clear();
    }

    /// One message, at its log time; cycles run for those that leave.
    pub(super) fn push(
        &mut self,
        r: &mut Replayer,
        log_time_ns: u64,
        item: InputItem,
    ) -> Result<(), ReplayError> {
        let kind = match item {
            InputItem::Joints(_) => 0,
            InputItem::Sensor(_) => {
                self.sensors_seen += 1;
                1
            }
        };
        let key = (log_time_ns, kind, self.sequence);
        self.sequence += 1;
        if let Some(last) = self.last_key
            && key < last
        {
            return Err(ReplayError::Order {
                log_time_ns,
                window: INPUT_WINDOW,
            });
        }
        if self.window.len() >= INPUT_WINDOW
            && let Some(std::cmp::Reverse(first)) = self.window.pop()
        {
            if !self.started {
                self.started = true;
                r.inputs_only_mode();
            }
            self.run(r, first)?;
        }
        debug_assert!(self.window.len() < INPUT_WINDOW);
        self.window.push(std::cmp::Reverse(Pending { key, item }));
        Ok(())
    }

    /// The messages left in the window, in order.
    pub(super) fn finish(&mut self, r: &mut Replayer) -> Result<(), ReplayError> {
        while let Some(std::cmp::Reverse(first)) = self.window.pop() {
            self.run(r, first)?;
        }
        Ok(())
    }

    /// A message leaves the window: a joint message becomes the newest, a
    /// sensor message runs a cycle with it.
    pub(super) fn run(&mut self, r: &mut Replayer, p: Pending) -> Result<(), ReplayError> {
        debug_assert!(self.last_key.is_none_or(|last| last < p.key));
        self.last_key = Some(p.key);
        let t = p.key.0;
        let w = match p.item {
            InputItem::Joints(j) => {
                self.latest = Some(j);
                return Ok(());
            }
            InputItem::Sensor(w) => w,
        };
        let index = self.sensor_index;
        self.sensor_index += 1;
        let Some(js) = &self.latest else {
            return Ok(());
        };
        self.cycle += 1;
        let finite = w.force_n.iter().chain(&w.torque_nm).all(|v| v.is_finite());
        let [fx, fy, fz] = w.force_n;
        let [tx, ty, tz] = w.torque_nm;
        let [q1_m, q2_m, q3_m] = js.q_m;
        let input = CycleInput {
            cycle: self.cycle,
            now_ns: Some(t),
            sensor: SensorSample {
                force_n: Vec3::new(fx, fy, fz),
                torque_nm: Vec3::new(tx, ty, tz),
                // The index: every message a new sample, no gap.
                counter: (index as u32).wrapping_add(1),
                status: 0,
                stamp_ns: w.stamp_ns,
                valid: finite,
                drained: sar_estimator::cycle::DrainedSamples::default(),
            },
            joints: JointSample {
                joints: ActiveJoints { q1_m, q2_m, q3_m },
                stamp_ns: js.stamp_ns,
                valid: js.q_m.iter().all(|v| v.is_finite()),
            },
            command: self.reset_pending.then_some(Command::Reset),
        };
        r.estimator_cycle(&input)?;
        if let Some(ev) = r.estimator.last().command
            && matches!(ev.result, Ok(CommandAccepted::Reset))
        {
            self.reset_pending = false;
        }
        Ok(())
    }
}
