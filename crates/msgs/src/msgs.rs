//! The recorded messages (INTERFACES.md 1): plain fixed-size Rust structs, their
//! ROS 2 CDR encoding and decoding, and their `ros2msg` schemas (the definition
//! text with a `====\nMSG: pkg/Type` section per nested type, spelled as the
//! fields spell it: `std_msgs/Header`, no `/msg/`, as ROS 2's recorder writes it).
//!
//! The structs are `Copy` and hold no heap data, so the recorder's queue carries
//! them as they are; they do not depend on the estimator's types (a conversion
//! from `sar_estimator::cycle` is the daemon's business). Units are the last part
//! of each name; stamps are ns of the daemon's monotonic clock.

use crate::cdr::{CdrError, CdrReader, CdrWriter, FixedStr};

/// A frame id (`header.frame_id`), at most 32 bytes.
pub type FrameId = FixedStr<32>;
/// A guard reason's text, at most 160 bytes (longer text is cut when written
/// with `write!`).
pub type ReasonText = FixedStr<160>;

/// A message with a ROS 2 type, a schema and a CDR form.
pub trait RosMessage: Sized {
    /// The ROS 2 type, `pkg/msg/Type`.
    const TYPE_NAME: &'static str;
    /// The `ros2msg` schema: the definition and its nested types' sections.
    const SCHEMA: &'static str;
    /// Writes the fields (after the encapsulation header).
    fn encode_fields(&self, w: &mut CdrWriter<'_>) -> Result<(), CdrError>;
    /// Reads the fields.
    fn decode_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError>;

    /// Encodes into `buf` (cleared first; a reused buffer does not allocate).
    fn encode(&self, buf: &mut Vec<u8>) -> Result<(), CdrError> {
        let mut w = CdrWriter::new(buf);
        self.encode_fields(&mut w)
    }
    /// Decodes one message; bytes after it are ignored (CDR may pad).
    fn decode(bytes: &[u8]) -> Result<Self, CdrError> {
        let mut r = CdrReader::new(bytes)?;
        Self::decode_fields(&mut r)
    }
}

macro_rules! sep {
    () => {
        "================================================================================\n"
    };
}
macro_rules! header_sections {
    () => {
        concat!(
            sep!(),
            "MSG: std_msgs/Header\n",
            "# Standard metadata for higher-level stamped data types.\n",
            "builtin_interfaces/Time stamp\n",
            "string frame_id\n",
            sep!(),
            "MSG: builtin_interfaces/Time\n",
            "int32 sec\n",
            "uint32 nanosec\n",
        )
    };
}

fn header_out(w: &mut CdrWriter<'_>, stamp_ns: u64, frame_id: &str) -> Result<(), CdrError> {
    w.time(stamp_ns)?;
    w.string(frame_id);
    Ok(())
}

/// The frame id of the base frame {0}.
pub const FRAME_BASE: &str = "base";
/// The frame id of the force/torque sensor's frame.
pub const FRAME_SENSOR: &str = "sensor";

fn frame(s: &str) -> FrameId {
    FrameId::truncating(s)
}

/// `geometry_msgs/msg/WrenchStamped`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct WrenchStamped {
    /// `header.stamp`, ns.
    pub stamp_ns: u64,
    /// `header.frame_id`.
    pub frame_id: FrameId,
    /// Force, N.
    pub force_n: [f64; 3],
    /// Torque, N m.
    pub torque_nm: [f64; 3],
}

impl WrenchStamped {
    /// A raw sensor reading (frame `sensor`).
    pub fn sensor(stamp_ns: u64, force_n: [f64; 3], torque_nm: [f64; 3]) -> Self {
        Self {
            stamp_ns,
            frame_id: frame(FRAME_SENSOR),
            force_n,
            torque_nm,
        }
    }
    /// A tip force in the base frame, torque zero (frame `base`).
    pub fn base_force(stamp_ns: u64, force_n: [f64; 3]) -> Self {
        Self {
            stamp_ns,
            frame_id: frame(FRAME_BASE),
            force_n,
            torque_nm: [0.0; 3],
        }
    }
}

impl RosMessage for WrenchStamped {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/WrenchStamped";
    const SCHEMA: &'static str = concat!(
        "# A wrench with reference coordinate frame and timestamp\n",
        "std_msgs/Header header\n",
        "Wrench wrench\n",
        header_sections!(),
        sep!(),
        "MSG: geometry_msgs/Wrench\n",
        "# This represents force in free space, separated into its linear and angular parts.\n",
        "Vector3  force\n",
        "Vector3  torque\n",
        sep!(),
        "MSG: geometry_msgs/Vector3\n",
        "# This represents a vector in free space.\n",
        "float64 x\n",
        "float64 y\n",
        "float64 z\n",
    );
    fn encode_fields(&self, w: &mut CdrWriter<'_>) -> Result<(), CdrError> {
        header_out(w, self.stamp_ns, self.frame_id.as_str())?;
        w.f64_array(&self.force_n);
        w.f64_array(&self.torque_nm);
        Ok(())
    }
    fn decode_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Ok(Self {
            stamp_ns: r.time()?,
            frame_id: r.fixed_str()?,
            force_n: r.f64_array()?,
            torque_nm: r.f64_array()?,
        })
    }
}

const JOINT_STATE_SCHEMA: &str = concat!(
    "# The state of a set of joints.\n",
    "std_msgs/Header header\n",
    "string[] name\n",
    "float64[] position\n",
    "float64[] velocity\n",
    "float64[] effort\n",
    header_sections!(),
);

/// The most joints a decoded `sensor_msgs/msg/JointState` may name.
pub const MAX_JOINTS: usize = 64;

/// `sensor_msgs/msg/JointState` as any program writes it (decoding side;
/// allocates). The daemon writes [`ActiveJointState`] and [`PassiveJointState`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct JointState {
    /// `header.stamp`, ns.
    pub stamp_ns: u64,
    /// `header.frame_id`.
    pub frame_id: String,
    /// Joint names.
    pub name: Vec<String>,
    /// Positions (m for prismatic, rad for revolute joints).
    pub position: Vec<f64>,
    /// Velocities (may be empty).
    pub velocity: Vec<f64>,
    /// Efforts (may be empty).
    pub effort: Vec<f64>,
}

impl JointState {
    /// The position of the joint named `name`.
    pub fn position_of(&self, name: &'static str) -> Result<f64, CdrError> {
        self.name
            .iter()
            .position(|n| n == name)
            .and_then(|i| self.position.get(i).copied())
            .ok_or(CdrError::MissingJoint { name })
    }
}

impl RosMessage for JointState {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/JointState";
    const SCHEMA: &'static str = JOINT_STATE_SCHEMA;
    fn encode_fields(&self, w: &mut CdrWriter<'_>) -> Result<(), CdrError> {
        header_out(w, self.stamp_ns, &self.frame_id)?;
        w.seq_len(self.name.len());
        for n in &self.name {
            w.string(n);
        }
        w.f64_seq(&self.position);
        w.f64_seq(&self.velocity);
        w.f64_seq(&self.effort);
        Ok(())
    }
    fn decode_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        let stamp_ns = r.time()?;
        let frame_id = r.str()?.to_owned();
        let n = r.seq_len(MAX_JOINTS, 5)?;
        let mut name = Vec::with_capacity(n);
        for _ in 0..n {
            name.push(r.str()?.to_owned());
        }
        Ok(Self {
            stamp_ns,
            frame_id,
            name,
            position: r.f64_seq(MAX_JOINTS)?,
            velocity: r.f64_seq(MAX_JOINTS)?,
            effort: r.f64_seq(MAX_JOINTS)?,
        })
    }
}

/// Writes a fixed-size joint state with names `names` and empty velocity and
/// effort; reads any JointState that names them (in any order).
fn joints_out<const N: usize>(
    w: &mut CdrWriter<'_>,
    stamp_ns: u64,
    names: &[&str; N],
    position: &[f64; N],
) -> Result<(), CdrError> {
    header_out(w, stamp_ns, "")?;
    w.seq_len(N);
    for n in names {
        w.string(n);
    }
    w.f64_seq(position);
    w.seq_len(0);
    w.seq_len(0);
    Ok(())
}

fn joints_in<const N: usize>(
    r: &mut CdrReader<'_>,
    names: &[&'static str; N],
) -> Result<(u64, [f64; N]), CdrError> {
    let js = JointState::decode_fields(r)?;
    let mut out = [0.0; N];
    for (x, name) in out.iter_mut().zip(names) {
        *x = js.position_of(name)?;
    }
    Ok((js.stamp_ns, out))
}

/// The active joints (`/sar/joints`): names `q1`, `q2`, `q3`, positions in m.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ActiveJointState {
    /// `header.stamp`, ns.
    pub stamp_ns: u64,
    /// q1, q2, q3, m.
    pub q_m: [f64; 3],
}

impl ActiveJointState {
    /// The joint names.
    pub const NAMES: [&'static str; 3] = ["q1", "q2", "q3"];
}

impl RosMessage for ActiveJointState {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/JointState";
    const SCHEMA: &'static str = JOINT_STATE_SCHEMA;
    fn encode_fields(&self, w: &mut CdrWriter<'_>) -> Result<(), CdrError> {
        joints_out(w, self.stamp_ns, &Self::NAMES, &self.q_m)
    }
    fn decode_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        let (stamp_ns, q_m) = joints_in(r, &Self::NAMES)?;
        Ok(Self { stamp_ns, q_m })
    }
}

/// The passive joints (`/sar/estimate/passive_joints`): names `q4`, `q5`, rad.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PassiveJointState {
    /// `header.stamp`, ns.
    pub stamp_ns: u64,
    /// q4, q5, rad.
    pub q_rad: [f64; 2],
}

impl PassiveJointState {
    /// The joint names.
    pub const NAMES: [&'static str; 2] = ["q4", "q5"];
}

impl RosMessage for PassiveJointState {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/JointState";
    const SCHEMA: &'static str = JOINT_STATE_SCHEMA;
    fn encode_fields(&self, w: &mut CdrWriter<'_>) -> Result<(), CdrError> {
        joints_out(w, self.stamp_ns, &Self::NAMES, &self.q_rad)
    }
    fn decode_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        let (stamp_ns, q_rad) = joints_in(r, &Self::NAMES)?;
        Ok(Self { stamp_ns, q_rad })
    }
}

macro_rules! code_enum {
    ($(#[$m:meta])* $name:ident, $field:literal {
        $(#[$fm:meta])* $first:ident = $fc:literal
        $(, $(#[$vm:meta])* $v:ident = $c:literal)* $(,)?
    }) => {
        $(#[$m])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
        #[repr(u8)]
        pub enum $name {
            $(#[$fm])*
            #[default]
            $first = $fc,
            $($(#[$vm])* $v = $c),*
        }
        impl $name {
            /// The numeric code of the `.msg` file.
            pub fn code(self) -> u8 {
                self as u8
            }
            /// The value of a code, or `BadValue`.
            pub fn from_code(code: u8) -> Result<Self, CdrError> {
                match code {
                    $fc => Ok(Self::$first),
                    $($c => Ok(Self::$v),)*
                    _ => Err(CdrError::BadValue { field: $field, value: i64::from(code) }),
                }
            }
        }
    };
}

code_enum!(
    /// The guard's state (`GUARD_*`).
    GuardStateCode, "guard_state" {
        /// Below the warn limits.
        Ok = 0,
        /// At or above a warn limit.
        Warn = 1,
        /// Stopped, latched.
        Stop = 2,
        /// Faulted, latched.
        Fault = 3,
        /// Retreating from a Stop whose force persists.
        Retreat = 4,
    }
);

code_enum!(
    /// What became of the cycle's tip force (`TIP_*`).
    TipOutcomeCode, "tip_outcome" {
        /// A number.
        Estimate = 0,
        /// The estimator refused.
        Refused = 1,
        /// The kinematics refused the pose.
        PoseInvalid = 2,
        /// The sensor sample was invalid.
        SensorInvalid = 3,
        /// The joint sample was invalid.
        JointsInvalid = 4,
    }
);

code_enum!(
    /// The monotonic clock's status in a cycle (`CLOCK_*`).
    ClockStatusCode, "clock_status" {
        /// It advanced.
        Ok = 0,
        /// It did not advance (stuck or gone back).
        NotAdvancing = 1,
        /// It could not be read.
        ReadFailed = 2,
    }
);

code_enum!(
    /// The drives' state (`DRIVE_*`).
    DriveStateCode, "drive_state" {
        /// Powered, not following targets.
        Ready = 0,
        /// Following targets.
        Enabled = 1,
        /// Quick stop.
        QuickStop = 2,
        /// Fault (see the fault axis and code).
        Fault = 3,
        /// Not read in this cycle (the drives' `state()` failed).
        Unread = 4,
    }
);

code_enum!(
    /// The operator command applied in a cycle (`COMMAND_*`).
    CommandKindCode, "command_kind" {
        /// None.
        None = 0,
        /// Reset the guard.
        GuardReset = 1,
        /// Tare the sensor (values: the bias, N).
        Tare = 2,
        /// Clear the tare.
        ClearTare = 3,
        /// Enable the drives.
        Enable = 4,
        /// Disable the drives.
        Disable = 5,
        /// Quick stop.
        QuickStop = 6,
        /// Reset a drive fault.
        FaultReset = 7,
        /// Move to a target (values: q1..q3, m).
        MoveTo = 8,
        /// Set the sensor's bias (values: force x, y, z in N, then torque
        /// x, y, z in N m; sensor frame).
        SetBias = 9,
        /// Move the tip (`move_tip_m`, base frame, m).
        MoveTip = 10,
        /// Set the force limits (`limits_n`).
        SetLimits = 11,
        /// Back the tip out along the rod (`back_out_m`).
        BackOut = 12,
        /// Force control, compliant hold (values[0]: the force, N).
        Hold = 13,
        /// Force control, axial push (values[0]: the axial force, N).
        Push = 14,
        /// End force control: position control again.
        Position = 15,
    }
);

code_enum!(
    /// What the step told the drives (`ACTION_*`).
    DriveActionCode, "drive_action" {
        /// Nothing.
        None = 0,
        /// Quick stop.
        QuickStop = 1,
        /// Release after a reset: enable.
        ReleaseEnable = 2,
        /// Release after a reset: disable, then enable.
        ReleaseDisableEnable = 3,
        /// Release after a reset: fault reset, then enable.
        ReleaseFaultResetEnable = 4,
        /// A move's end point (`setpoint_q_m`).
        Setpoint = 5,
        /// A streamed set point one period ahead (`setpoint_q_m`).
        Stream = 6,
        /// The drives' fault reset alone (a reset while they are faulted).
        FaultReset = 7,
    }
);

/// `CycleInput::reply_status` without a reply (`REPLY_NONE`).
pub const REPLY_NONE: u8 = 255;

/// The guard reason codes (`REASON_*` of `GuardEvent.msg`): the estimator's
/// one table (`sar_estimator::guard::REASONS`, `Reason::code`), which the
/// wire and `sarctl` use too; the `.msg` constants are checked against it by
/// a test (`tests/messages.rs`). Here only what the table has not.
pub mod reason {
    /// A code too large for the recording's `uint8` (none today).
    pub const OTHER: u8 = 255;
    /// A code of the table.
    pub fn code(reason: &sar_estimator::guard::Reason) -> u8 {
        u8::try_from(reason.code()).unwrap_or(OTHER)
    }
}

/// Bits of `EstimatorState::flags` (`FLAG_*`).
pub mod flags {
    /// The kinematics gave a pose.
    pub const POSE_VALID: u32 = 1;
    /// The cycle has a tip force number.
    pub const TIP_VALID: u32 = 2;
    /// Its deviation is within the observability limit.
    pub const OBSERVABLE: u32 = 4;
    /// The filtered tip force is valid.
    pub const FILTERED_VALID: u32 = 8;
    /// The sensor sample was accepted.
    pub const SENSOR_VALID: u32 = 16;
    /// The joint sample was accepted.
    pub const JOINTS_VALID: u32 = 32;
    /// The clock advanced.
    pub const CLOCK_ADVANCES: u32 = 64;
}

/// `sar_msgs/msg/EstimatorState` (`msg/EstimatorState.msg`): one cycle.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EstimatorState {
    /// `header.stamp` = `now_ns`, frame `base`.
    pub stamp_ns: u64,
    /// The cycle number.
    pub cycle: u64,
    /// The cycle's now, ns.
    pub now_ns: u64,
    /// The sensor sample's stamp, ns.
    pub sensor_stamp_ns: u64,
    /// The joint sample's stamp, ns.
    pub joints_stamp_ns: u64,
    /// now - sensor stamp, ns.
    pub sensor_age_ns: u64,
    /// now - joints stamp, ns.
    pub joints_age_ns: u64,
    /// What became of the tip force.
    pub tip_outcome: TipOutcomeCode,
    /// A, m.
    pub ujoint_m: [f64; 3],
    /// D, m.
    pub tip_m: [f64; 3],
    /// a = |B - A|, m.
    pub support_distance_m: f64,
    /// F_A, N.
    pub ujoint_force_n: [f64; 3],
    /// F_tip, N.
    pub tip_force_n: [f64; 3],
    /// Its standard deviation per axis, N.
    pub tip_force_std_n: [f64; 3],
    /// Axial part of F_tip, N.
    pub axial_n: f64,
    /// Lateral part of F_tip, N.
    pub lateral_n: f64,
    /// Torsion about the rod, N m.
    pub torsion_nm: f64,
    /// The causal filtered F_tip, N.
    pub tip_force_filtered_n: [f64; 3],
    /// The guard's state after the cycle.
    pub guard_state: GuardStateCode,
    /// Why ([`reason`]).
    pub guard_reason_code: u8,
    /// Why, in words.
    pub guard_reason_text: ReasonText,
    /// [`flags`] or-ed.
    pub flags: u32,
}

impl RosMessage for EstimatorState {
    const TYPE_NAME: &'static str = "sar_msgs/msg/EstimatorState";
    const SCHEMA: &'static str = concat!(
        include_str!("../msg/EstimatorState.msg"),
        header_sections!()
    );
    fn encode_fields(&self, w: &mut CdrWriter<'_>) -> Result<(), CdrError> {
        header_out(w, self.stamp_ns, FRAME_BASE)?;
        w.u64(self.cycle);
        w.u64(self.now_ns);
        w.u64(self.sensor_stamp_ns);
        w.u64(self.joints_stamp_ns);
        w.u64(self.sensor_age_ns);
        w.u64(self.joints_age_ns);
        w.u8(self.tip_outcome.code());
        w.f64_array(&self.ujoint_m);
        w.f64_array(&self.tip_m);
        w.f64(self.support_distance_m);
        w.f64_array(&self.ujoint_force_n);
        w.f64_array(&self.tip_force_n);
        w.f64_array(&self.tip_force_std_n);
        w.f64(self.axial_n);
        w.f64(self.lateral_n);
        w.f64(self.torsion_nm);
        w.f64_array(&self.tip_force_filtered_n);
        w.u8(self.guard_state.code());
        w.u8(self.guard_reason_code);
        w.string(self.guard_reason_text.as_str());
        w.u32(self.flags);
        Ok(())
    }
    fn decode_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        let stamp_ns = r.time()?;
        let _frame: FrameId = r.fixed_str()?;
        Ok(Self {
            stamp_ns,
            cycle: r.u64()?,
            now_ns: r.u64()?,
            sensor_stamp_ns: r.u64()?,
            joints_stamp_ns: r.u64()?,
            sensor_age_ns: r.u64()?,
            joints_age_ns: r.u64()?,
            tip_outcome: TipOutcomeCode::from_code(r.u8()?)?,
            ujoint_m: r.f64_array()?,
            tip_m: r.f64_array()?,
            support_distance_m: r.f64()?,
            ujoint_force_n: r.f64_array()?,
            tip_force_n: r.f64_array()?,
            tip_force_std_n: r.f64_array()?,
            axial_n: r.f64()?,
            lateral_n: r.f64()?,
            torsion_nm: r.f64()?,
            tip_force_filtered_n: r.f64_array()?,
            guard_state: GuardStateCode::from_code(r.u8()?)?,
            guard_reason_code: r.u8()?,
            guard_reason_text: r.fixed_str()?,
            flags: r.u32()?,
        })
    }
}

/// `sar_msgs/msg/GuardEvent` (`msg/GuardEvent.msg`): one guard transition.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GuardEvent {
    /// `header.stamp` = now of the cycle, frame `base`.
    pub stamp_ns: u64,
    /// The cycle.
    pub cycle: u64,
    /// The state left.
    pub from_state: GuardStateCode,
    /// The state entered.
    pub to_state: GuardStateCode,
    /// Why ([`reason`]).
    pub reason_code: u8,
    /// Why, in words.
    pub reason_text: ReasonText,
}

impl RosMessage for GuardEvent {
    const TYPE_NAME: &'static str = "sar_msgs/msg/GuardEvent";
    const SCHEMA: &'static str = concat!(include_str!("../msg/GuardEvent.msg"), header_sections!());
    fn encode_fields(&self, w: &mut CdrWriter<'_>) -> Result<(), CdrError> {
        header_out(w, self.stamp_ns, FRAME_BASE)?;
        w.u64(self.cycle);
        w.u8(self.from_state.code());
        w.u8(self.to_state.code());
        w.u8(self.reason_code);
        w.string(self.reason_text.as_str());
        Ok(())
    }
    fn decode_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        let stamp_ns = r.time()?;
        let _frame: FrameId = r.fixed_str()?;
        Ok(Self {
            stamp_ns,
            cycle: r.u64()?,
            from_state: GuardStateCode::from_code(r.u8()?)?,
            to_state: GuardStateCode::from_code(r.u8()?)?,
            reason_code: r.u8()?,
            reason_text: r.fixed_str()?,
        })
    }
}

/// `sar_msgs/msg/CycleInput` (`msg/CycleInput.msg`): what one cycle consumed.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CycleInput {
    /// `header.stamp` = `now_ns`, frame `base`.
    pub stamp_ns: u64,
    /// The cycle number.
    pub cycle: u64,
    /// Host monotonic time now, ns.
    pub now_ns: u64,
    /// The clock's status.
    pub clock_status: ClockStatusCode,
    /// Force, sensor frame, N.
    pub sensor_force_n: [f64; 3],
    /// Torque, sensor frame, N m.
    pub sensor_torque_nm: [f64; 3],
    /// The device's sample counter.
    pub sensor_counter: u32,
    /// The device's status word.
    pub sensor_status: u32,
    /// Receive time, ns.
    pub sensor_stamp_ns: u64,
    /// The driver's word that the sample is good.
    pub sensor_valid: bool,
    /// q1, q2, q3, m.
    pub joints_q_m: [f64; 3],
    /// Measure time, ns.
    pub joints_stamp_ns: u64,
    /// The driver's word that the positions are good.
    pub joints_valid: bool,
    /// The drives' state.
    pub drive_state: DriveStateCode,
    /// The faulted axis (0..=2), -1 for none.
    pub drive_fault_axis: i8,
    /// The device's fault code (0 unless faulted).
    pub drive_fault_code: u16,
    /// Commanded q1..q3, m.
    pub target_q_m: [f64; 3],
    /// Whether a target is commanded.
    pub target_valid: bool,
    /// The operator command applied.
    pub command_kind: CommandKindCode,
    /// Its real arguments.
    pub command_values: [f64; 6],
    /// Its integer argument.
    pub command_arg: u64,
    /// MOVE_TIP: the wanted tip, base frame, m.
    pub move_tip_m: [f64; 3],
    /// SET_LIMITS: warn, stop of total, axial, lateral, N.
    pub limits_n: [f64; 6],
    /// The step's decision: what the drives were told.
    pub drive_action: DriveActionCode,
    /// With `Setpoint`: q1..q3 one period ahead, m.
    pub setpoint_q_m: [f64; 3],
    /// The reply's status code, [`REPLY_NONE`] without a request.
    pub reply_status: u8,
    /// The guard's reason code behind a refusal.
    pub reply_reason: u16,
    /// The force limits in use after the cycle, N.
    pub limits_in_use_n: [f64; 6],
    /// How long the publishing thread had made no progress, ns (0 in
    /// recordings older than this field).
    pub publisher_idle_ns: u64,
    /// BACK_OUT: how far to back the tip out along the rod, m.
    pub back_out_m: f64,
    /// MOVE_TIP: a guarded move's force limit, N (0: unguarded; 0 in
    /// recordings older than this field).
    pub move_max_force_n: f64,
}

impl RosMessage for CycleInput {
    const TYPE_NAME: &'static str = "sar_msgs/msg/CycleInput";
    const SCHEMA: &'static str = concat!(include_str!("../msg/CycleInput.msg"), header_sections!());
    fn encode_fields(&self, w: &mut CdrWriter<'_>) -> Result<(), CdrError> {
        header_out(w, self.stamp_ns, FRAME_BASE)?;
        w.u64(self.cycle);
        w.u64(self.now_ns);
        w.u8(self.clock_status.code());
        w.f64_array(&self.sensor_force_n);
        w.f64_array(&self.sensor_torque_nm);
        w.u32(self.sensor_counter);
        w.u32(self.sensor_status);
        w.u64(self.sensor_stamp_ns);
        w.bool(self.sensor_valid);
        w.f64_array(&self.joints_q_m);
        w.u64(self.joints_stamp_ns);
        w.bool(self.joints_valid);
        w.u8(self.drive_state.code());
        w.i8(self.drive_fault_axis);
        w.u16(self.drive_fault_code);
        w.f64_array(&self.target_q_m);
        w.bool(self.target_valid);
        w.u8(self.command_kind.code());
        w.f64_array(&self.command_values);
        w.u64(self.command_arg);
        w.f64_array(&self.move_tip_m);
        w.f64_array(&self.limits_n);
        w.u8(self.drive_action.code());
        w.f64_array(&self.setpoint_q_m);
        w.u8(self.reply_status);
        w.u16(self.reply_reason);
        w.f64_array(&self.limits_in_use_n);
        w.u64(self.publisher_idle_ns);
        w.f64(self.back_out_m);
        w.f64(self.move_max_force_n);
        Ok(())
    }
    fn decode_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        let stamp_ns = r.time()?;
        let _frame: FrameId = r.fixed_str()?;
        let mut m = Self {
            stamp_ns,
            cycle: r.u64()?,
            now_ns: r.u64()?,
            clock_status: ClockStatusCode::from_code(r.u8()?)?,
            sensor_force_n: r.f64_array()?,
            sensor_torque_nm: r.f64_array()?,
            sensor_counter: r.u32()?,
            sensor_status: r.u32()?,
            sensor_stamp_ns: r.u64()?,
            sensor_valid: r.bool()?,
            joints_q_m: r.f64_array()?,
            joints_stamp_ns: r.u64()?,
            joints_valid: r.bool()?,
            drive_state: DriveStateCode::from_code(r.u8()?)?,
            drive_fault_axis: r.i8()?,
            drive_fault_code: r.u16()?,
            target_q_m: r.f64_array()?,
            target_valid: r.bool()?,
            command_kind: CommandKindCode::from_code(r.u8()?)?,
            command_values: r.f64_array()?,
            command_arg: r.u64()?,
            move_tip_m: r.f64_array()?,
            limits_n: r.f64_array()?,
            drive_action: DriveActionCode::from_code(r.u8()?)?,
            setpoint_q_m: r.f64_array()?,
            reply_status: r.u8()?,
            reply_reason: r.u16()?,
            limits_in_use_n: r.f64_array()?,
            publisher_idle_ns: 0,
            back_out_m: 0.0,
            move_max_force_n: 0.0,
        };
        // The fields added with issue 14, all or none: an older recording
        // ends before them (they read as 0); part of them is a cut message.
        if r.remaining() > 0 {
            m.publisher_idle_ns = r.u64()?;
            m.back_out_m = r.f64()?;
        }
        // Added with issue 15 (guarded moves): as above.
        if r.remaining() > 0 {
            m.move_max_force_n = r.f64()?;
        }
        Ok(m)
    }
}

/// `sar_msgs/msg/RecorderDrops` (`msg/RecorderDrops.msg`): the recorder's
/// account of dropped messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RecorderDrops {
    /// `header.stamp`: the log time of the newest message seen, ns.
    pub stamp_ns: u64,
    /// Messages dropped since the recorder started (queue full or writer failed).
    pub dropped: u64,
    /// Messages written since the recorder started.
    pub written: u64,
    /// The queue's capacity.
    pub queue_capacity: u64,
}

impl RosMessage for RecorderDrops {
    const TYPE_NAME: &'static str = "sar_msgs/msg/RecorderDrops";
    const SCHEMA: &'static str =
        concat!(include_str!("../msg/RecorderDrops.msg"), header_sections!());
    fn encode_fields(&self, w: &mut CdrWriter<'_>) -> Result<(), CdrError> {
        header_out(w, self.stamp_ns, "")?;
        w.u64(self.dropped);
        w.u64(self.written);
        w.u64(self.queue_capacity);
        Ok(())
    }
    fn decode_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        let stamp_ns = r.time()?;
        let _frame: FrameId = r.fixed_str()?;
        Ok(Self {
            stamp_ns,
            dropped: r.u64()?,
            written: r.u64()?,
            queue_capacity: r.u64()?,
        })
    }
}

/// Snapshot bytes per [`SnapshotChunk`] (a chunk fits the queue's slot,
/// which the largest message sets at about 420 bytes).
pub const SNAPSHOT_CHUNK_BYTES: usize = 384;

/// Chunks of one snapshot at most.
pub const SNAPSHOT_CHUNKS_MAX: usize = sar_snapshot::CAPACITY.div_ceil(SNAPSHOT_CHUNK_BYTES);

/// One part of a [`StateSnapshot`] in the recorder's queue (fixed-size,
/// `Copy`): the loop pushes a snapshot as consecutive chunks, the writer
/// joins them and writes one message; a snapshot with a chunk missing (a
/// full queue) is not written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SnapshotChunk {
    /// The cycle's `now`, ns (the message's stamp).
    pub stamp_ns: u64,
    /// The last cycle stepped before the snapshot was taken.
    pub after_cycle: u64,
    /// This chunk's place, 0-based.
    pub index: u8,
    /// The snapshot's chunks.
    pub count: u8,
    /// Bytes of `bytes` in use.
    pub len: u16,
    /// The snapshot's bytes from `index * SNAPSHOT_CHUNK_BYTES`.
    pub bytes: [u8; SNAPSHOT_CHUNK_BYTES],
}

impl SnapshotChunk {
    /// Splits `snapshot` into chunks, handing each to `push` in order; stops
    /// at the first refused (false). Whether all were taken.
    pub fn split(
        stamp_ns: u64,
        after_cycle: u64,
        snapshot: &[u8],
        mut push: impl FnMut(Outgoing) -> bool,
    ) -> bool {
        let count = snapshot.len().div_ceil(SNAPSHOT_CHUNK_BYTES);
        let Ok(count_u8) = u8::try_from(count) else {
            return false;
        };
        for (i, part) in snapshot.chunks(SNAPSHOT_CHUNK_BYTES).enumerate() {
            let mut bytes = [0u8; SNAPSHOT_CHUNK_BYTES];
            if let Some(dst) = bytes.get_mut(..part.len()) {
                dst.copy_from_slice(part);
            }
            let chunk = SnapshotChunk {
                stamp_ns,
                after_cycle,
                index: u8::try_from(i).unwrap_or(u8::MAX),
                count: count_u8,
                len: u16::try_from(part.len()).unwrap_or(0),
                bytes,
            };
            if !push(Outgoing::SnapshotChunk(chunk)) {
                return false;
            }
        }
        true
    }

    /// The bytes in use.
    pub fn data(&self) -> &[u8] {
        self.bytes.get(..usize::from(self.len)).unwrap_or(&[])
    }
}

/// `sar_msgs/msg/StateSnapshot` (`msg/StateSnapshot.msg`): the loop's
/// decision state after a cycle, as written (the reader's form: owns its
/// bytes).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StateSnapshot {
    /// `header.stamp`: the cycle's `now`, ns.
    pub stamp_ns: u64,
    /// The last cycle stepped before it was taken.
    pub after_cycle: u64,
    /// The sar-snapshot format's version.
    pub format_version: u16,
    /// The snapshot's bytes.
    pub data: Vec<u8>,
}

impl RosMessage for StateSnapshot {
    const TYPE_NAME: &'static str = "sar_msgs/msg/StateSnapshot";
    const SCHEMA: &'static str =
        concat!(include_str!("../msg/StateSnapshot.msg"), header_sections!());
    fn encode_fields(&self, w: &mut CdrWriter<'_>) -> Result<(), CdrError> {
        header_out(w, self.stamp_ns, "")?;
        w.u64(self.after_cycle);
        w.u16(self.format_version);
        w.byte_seq(&self.data);
        Ok(())
    }
    fn decode_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        let stamp_ns = r.time()?;
        let _frame: FrameId = r.fixed_str()?;
        Ok(Self {
            stamp_ns,
            after_cycle: r.u64()?,
            format_version: r.u16()?,
            data: r.byte_seq(sar_snapshot::CAPACITY)?.to_vec(),
        })
    }
}

/// The recorded topics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Topic {
    /// `/sar/sensor/wrench`, [`WrenchStamped`] frame `sensor`.
    SensorWrench,
    /// `/sar/joints`, [`ActiveJointState`].
    Joints,
    /// `/sar/estimate/tip_wrench`, [`WrenchStamped`] frame `base`.
    TipWrench,
    /// `/sar/estimate/tip_wrench_filtered`, [`WrenchStamped`] frame `base`.
    TipWrenchFiltered,
    /// `/sar/estimate/passive_joints`, [`PassiveJointState`].
    PassiveJoints,
    /// `/sar/estimate/state`, [`EstimatorState`].
    EstimatorState,
    /// `/sar/guard/events`, [`GuardEvent`].
    GuardEvents,
    /// `/sar/cycle/input`, [`CycleInput`].
    CycleInput,
    /// `/sar/recorder/drops`, [`RecorderDrops`].
    RecorderDrops,
    /// `/sar/sim/tip_wrench_truth`, [`WrenchStamped`] frame `base`: the
    /// simulator's true F_tip (simulator-made recordings; the reference of
    /// `sarctl replay --compare`).
    SimTipWrenchTruth,
    /// `/sar/cycle/snapshot`, [`StateSnapshot`]: the loop's decision state.
    StateSnapshot,
}

impl Topic {
    /// Every topic, in channel order.
    pub const ALL: [Topic; 11] = [
        Topic::SensorWrench,
        Topic::Joints,
        Topic::TipWrench,
        Topic::TipWrenchFiltered,
        Topic::PassiveJoints,
        Topic::EstimatorState,
        Topic::GuardEvents,
        Topic::CycleInput,
        Topic::RecorderDrops,
        Topic::SimTipWrenchTruth,
        Topic::StateSnapshot,
    ];

    /// The topic name.
    pub fn name(self) -> &'static str {
        match self {
            Topic::SensorWrench => "/sar/sensor/wrench",
            Topic::Joints => "/sar/joints",
            Topic::TipWrench => "/sar/estimate/tip_wrench",
            Topic::TipWrenchFiltered => "/sar/estimate/tip_wrench_filtered",
            Topic::PassiveJoints => "/sar/estimate/passive_joints",
            Topic::EstimatorState => "/sar/estimate/state",
            Topic::GuardEvents => "/sar/guard/events",
            Topic::CycleInput => "/sar/cycle/input",
            Topic::RecorderDrops => "/sar/recorder/drops",
            Topic::SimTipWrenchTruth => "/sar/sim/tip_wrench_truth",
            Topic::StateSnapshot => "/sar/cycle/snapshot",
        }
    }

    /// The topic of a name.
    pub fn from_name(name: &str) -> Option<Topic> {
        Self::ALL.into_iter().find(|t| t.name() == name)
    }

    /// The ROS 2 type name (the schema's name).
    pub fn type_name(self) -> &'static str {
        match self {
            Topic::SensorWrench
            | Topic::TipWrench
            | Topic::TipWrenchFiltered
            | Topic::SimTipWrenchTruth => WrenchStamped::TYPE_NAME,
            Topic::Joints | Topic::PassiveJoints => JointState::TYPE_NAME,
            Topic::EstimatorState => EstimatorState::TYPE_NAME,
            Topic::GuardEvents => GuardEvent::TYPE_NAME,
            Topic::CycleInput => CycleInput::TYPE_NAME,
            Topic::RecorderDrops => RecorderDrops::TYPE_NAME,
            Topic::StateSnapshot => StateSnapshot::TYPE_NAME,
        }
    }

    /// The `ros2msg` schema text.
    pub fn schema(self) -> &'static str {
        match self {
            Topic::SensorWrench
            | Topic::TipWrench
            | Topic::TipWrenchFiltered
            | Topic::SimTipWrenchTruth => WrenchStamped::SCHEMA,
            Topic::Joints | Topic::PassiveJoints => JointState::SCHEMA,
            Topic::EstimatorState => EstimatorState::SCHEMA,
            Topic::GuardEvents => GuardEvent::SCHEMA,
            Topic::CycleInput => CycleInput::SCHEMA,
            Topic::RecorderDrops => RecorderDrops::SCHEMA,
            Topic::StateSnapshot => StateSnapshot::SCHEMA,
        }
    }
}

/// One message for the recorder: fixed-size, `Copy`, no heap data.
///
/// Every queue slot has the size of the largest variant (about 420 bytes);
/// boxing the large ones would allocate on the loop's push, which it must not.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Outgoing {
    /// `/sar/sensor/wrench`.
    SensorWrench(WrenchStamped),
    /// `/sar/joints`.
    Joints(ActiveJointState),
    /// `/sar/estimate/tip_wrench`.
    TipWrench(WrenchStamped),
    /// `/sar/estimate/tip_wrench_filtered`.
    TipWrenchFiltered(WrenchStamped),
    /// `/sar/estimate/passive_joints`.
    PassiveJoints(PassiveJointState),
    /// `/sar/estimate/state`.
    EstimatorState(EstimatorState),
    /// `/sar/guard/events`.
    GuardEvent(GuardEvent),
    /// `/sar/cycle/input`.
    CycleInput(CycleInput),
    /// `/sar/recorder/drops` (the recorder writes these itself).
    RecorderDrops(RecorderDrops),
    /// `/sar/sim/tip_wrench_truth`.
    SimTruth(WrenchStamped),
    /// A part of a `/sar/cycle/snapshot` message (joined by the writer).
    SnapshotChunk(SnapshotChunk),
}

impl Outgoing {
    /// Its topic.
    pub fn topic(&self) -> Topic {
        match self {
            Outgoing::SensorWrench(_) => Topic::SensorWrench,
            Outgoing::Joints(_) => Topic::Joints,
            Outgoing::TipWrench(_) => Topic::TipWrench,
            Outgoing::TipWrenchFiltered(_) => Topic::TipWrenchFiltered,
            Outgoing::PassiveJoints(_) => Topic::PassiveJoints,
            Outgoing::EstimatorState(_) => Topic::EstimatorState,
            Outgoing::GuardEvent(_) => Topic::GuardEvents,
            Outgoing::CycleInput(_) => Topic::CycleInput,
            Outgoing::RecorderDrops(_) => Topic::RecorderDrops,
            Outgoing::SimTruth(_) => Topic::SimTipWrenchTruth,
            Outgoing::SnapshotChunk(_) => Topic::StateSnapshot,
        }
    }

    /// Its `header.stamp`, ns: the recording's `log_time` and `publish_time`.
    pub fn stamp_ns(&self) -> u64 {
        match self {
            Outgoing::SensorWrench(m)
            | Outgoing::TipWrench(m)
            | Outgoing::TipWrenchFiltered(m)
            | Outgoing::SimTruth(m) => m.stamp_ns,
            Outgoing::Joints(m) => m.stamp_ns,
            Outgoing::PassiveJoints(m) => m.stamp_ns,
            Outgoing::EstimatorState(m) => m.stamp_ns,
            Outgoing::GuardEvent(m) => m.stamp_ns,
            Outgoing::CycleInput(m) => m.stamp_ns,
            Outgoing::RecorderDrops(m) => m.stamp_ns,
            Outgoing::SnapshotChunk(m) => m.stamp_ns,
        }
    }

    /// Encodes into `buf` (cleared first).
    pub fn encode(&self, buf: &mut Vec<u8>) -> Result<(), CdrError> {
        match self {
            Outgoing::SensorWrench(m)
            | Outgoing::TipWrench(m)
            | Outgoing::TipWrenchFiltered(m)
            | Outgoing::SimTruth(m) => m.encode(buf),
            Outgoing::Joints(m) => m.encode(buf),
            Outgoing::PassiveJoints(m) => m.encode(buf),
            Outgoing::EstimatorState(m) => m.encode(buf),
            Outgoing::GuardEvent(m) => m.encode(buf),
            Outgoing::CycleInput(m) => m.encode(buf),
            Outgoing::RecorderDrops(m) => m.encode(buf),
            Outgoing::SnapshotChunk(_) => Err(CdrError::NotAMessage),
        }
    }

    /// Decodes a message of `topic`.
    pub fn decode(topic: Topic, bytes: &[u8]) -> Result<Self, CdrError> {
        Ok(match topic {
            Topic::SensorWrench => Outgoing::SensorWrench(WrenchStamped::decode(bytes)?),
            Topic::Joints => Outgoing::Joints(ActiveJointState::decode(bytes)?),
            Topic::TipWrench => Outgoing::TipWrench(WrenchStamped::decode(bytes)?),
            Topic::TipWrenchFiltered => Outgoing::TipWrenchFiltered(WrenchStamped::decode(bytes)?),
            Topic::PassiveJoints => Outgoing::PassiveJoints(PassiveJointState::decode(bytes)?),
            Topic::EstimatorState => Outgoing::EstimatorState(EstimatorState::decode(bytes)?),
            Topic::GuardEvents => Outgoing::GuardEvent(GuardEvent::decode(bytes)?),
            Topic::CycleInput => Outgoing::CycleInput(CycleInput::decode(bytes)?),
            Topic::RecorderDrops => Outgoing::RecorderDrops(RecorderDrops::decode(bytes)?),
            Topic::SimTipWrenchTruth => Outgoing::SimTruth(WrenchStamped::decode(bytes)?),
            // Variable-length: read it with `StateSnapshot::decode`.
            Topic::StateSnapshot => return Err(CdrError::NotAMessage),
        })
    }
}
