//! The recorded messages (INTERFACES.md 1): plain fixed-size Rust structs, their
//! ROS 2 CDR encoding and decoding, and their `ros2msg` schemas (the definition
//! text with a `====\nMSG: pkg/Type` section per nested type, spelled as the
//! fields spell it: `std_msgs/Header`, no `/msg/`, as ROS 2's recorder writes it).
//!
//! The structs are `Copy` and hold no heap data, so the recorder's queue carries
//! them as they are; they do not depend on the estimator's types (a conversion
//! from `sar_estimator::cycle` is the daemon's business). Units are the last part
//! of each name; stamps are ns of the daemon's monotonic clock.
//!
//! Each message but the joint states is one list of its fields in wire order
//! (`ros_message!`): the struct, its encoding and its decoding are made from
//! it, and a test checks it against the `.msg` file, which is the `sar_msgs`
//! types' schema. The joint states (`sensor_msgs/msg/JointState`, a name per
//! position, read in any order) are written out by hand.

use crate::cdr::{CdrError, CdrField, CdrReader, CdrWriter, FixedLayout, FixedStr};

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

/// One field as the `.msg` file declares it (`float64[3] joints_q_m`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MsgField {
    /// Its type (`uint64`, `string`, `uint8[]`, `std_msgs/Header`), without
    /// a fixed array's length.
    pub ros_type: &'static str,
    /// A fixed array's length.
    pub array_len: Option<usize>,
    /// Its name.
    pub name: &'static str,
}

impl MsgField {
    /// `std_msgs/Header header`.
    pub const HEADER: MsgField = MsgField {
        ros_type: "std_msgs/Header",
        array_len: None,
        name: "header",
    };
}

/// The `.msg` line, `float64[3] joints_q_m`.
impl core::fmt::Display for MsgField {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.ros_type)?;
        if let Some(n) = self.array_len {
            write!(f, "[{n}]")?;
        }
        write!(f, " {}", self.name)
    }
}

/// Defines a message from one list of its fields in wire order: the struct
/// (the list's docs and types), its [`RosMessage`] encoding and decoding,
/// and `MSG_FIELDS`, the list as `.msg` lines (a test checks them against
/// the `.msg` file).
///
/// ```text
/// ros_message! {
///     /// Docs, derives.
///     pub struct Name: "pkg/msg/Name", SCHEMA;
///     header {
///         /// Docs.
///         stamp_ns,              // header.stamp: builtin_interfaces/Time from ns
///         frame_id = FRAME_BASE, // a constant frame id (read, checked, dropped)
///      or /// Docs.
///         frame_id: FrameId,     // the frame id a field
///     }
///     fields {
///         /// Docs.
///         name: Type,               // a `CdrField`: number, bool, [f64; N], text, code
///         data: Vec<u8> [<= MAX],   // uint8[], at most MAX bytes
///     }
///     since { ... } // fields added later, all or none: a message that ends
///                   // before them reads them as their `Default` (0)
/// }
/// ```
///
/// Decoding reads the fields after the header in one window (one bounds
/// check, [`CdrReader::fixed_run`]) when they are all fixed-size and the
/// message holds them all, the `since` ones too; otherwise (an older message,
/// a cut one, a string among the fields), or when a value is refused, one by
/// one as they are listed, so that an error names the same offset.
macro_rules! ros_message {
    // A field's read, write, layout and `.msg` line: by its `CdrField` type,
    // or a `uint8[]` of at most `$max` bytes.
    (@read $r:ident, $ty:ty) => { <$ty as CdrField>::read($r)? };
    (@read $r:ident, $ty:ty, $max:expr) => { $r.byte_seq($max)?.to_vec() };
    (@write $w:ident, $v:expr, $ty:ty) => { <$ty as CdrField>::write(&$v, $w) };
    (@write $w:ident, $v:expr, $ty:ty, $max:expr) => { $w.byte_seq(&$v) };
    (@layout $ty:ty) => { <$ty as CdrField>::LAYOUT };
    (@layout $ty:ty, $max:expr) => { None };
    (@msg_field $f:ident: $ty:ty) => {
        MsgField {
            ros_type: <$ty as CdrField>::ROS_TYPE,
            array_len: <$ty as CdrField>::ARRAY_LEN,
            name: stringify!($f),
        }
    };
    (@msg_field $f:ident: $ty:ty, $max:expr) => {
        MsgField { ros_type: "uint8[]", array_len: None, name: stringify!($f) }
    };
    // The header's frame id: a constant (read, checked and dropped) or a field.
    (@frame $self:ident [const $e:expr]) => { $e };
    (@frame $self:ident [field $f:ident]) => { $self.$f.as_str() };
    (@new [$stamp:ident = $s:ident] [$f:ident = const $e:expr] { $($field:ident: $v:expr,)* }) => {{
        let _ = $f;
        Self { $stamp: $s, $($field: $v,)* }
    }};
    (@new [$stamp:ident = $s:ident] [$f:ident = field $frame:ident] { $($field:ident: $v:expr,)* }) => {
        Self { $stamp: $s, $frame: $f, $($field: $v,)* }
    };
    // The struct, `MSG_FIELDS`, and the encoding and decoding.
    (@message [$(#[$m:meta])*] $name:ident $type_name:literal [$schema:expr]
        [$(#[$sm:meta])* $stamp:ident] [$($frame:tt)*] [$($frame_decl:tt)*]
        fields {
            $( $(#[$fm:meta])* $field:ident: $ty:ty $([<= $max:expr])? ),* $(,)?
        }
        $( since {
            $( $(#[$om:meta])* $ofield:ident: $oty:ty ),* $(,)?
        } )*
    ) => {
        $(#[$m])*
        pub struct $name {
            $(#[$sm])*
            pub $stamp: u64,
            $($frame_decl)*
            $( $(#[$fm])* pub $field: $ty, )*
            $($( $(#[$om])* pub $ofield: $oty, )*)*
        }

        impl $name {
            /// The fields in wire order as the `.msg` file declares them,
            /// the header first.
            pub const MSG_FIELDS: &'static [MsgField] = &[
                MsgField::HEADER,
                $( ros_message!(@msg_field $field: $ty $(, $max)?), )*
                $($( ros_message!(@msg_field $ofield: $oty), )*)*
            ];

            /// The fields after the header, one by one.
            #[inline(always)]
            fn decode_body(
                r: &mut CdrReader<'_>,
                stamp_ns: u64,
                frame_id: FrameId,
            ) -> Result<Self, CdrError> {
                #[allow(unused_mut)]
                let mut m = ros_message!(@new [$stamp = stamp_ns] [frame_id = $($frame)*] {
                    $( $field: ros_message!(@read r, $ty $(, $max)?), )*
                    $($( $ofield: Default::default(), )*)*
                });
                $(
                    if r.remaining() > 0 {
                        $( m.$ofield = CdrField::read(r)?; )*
                    }
                )*
                Ok(m)
            }
        }

        impl RosMessage for $name {
            const TYPE_NAME: &'static str = $type_name;
            const SCHEMA: &'static str = $schema;
            fn encode_fields(&self, w: &mut CdrWriter<'_>) -> Result<(), CdrError> {
                w.time(self.$stamp)?;
                w.string(ros_message!(@frame self [$($frame)*]));
                $( ros_message!(@write w, self.$field, $ty $(, $max)?); )*
                $($( CdrField::write(&self.$ofield, w); )*)*
                Ok(())
            }
            fn decode_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
                const RUN: Option<FixedLayout> = FixedLayout::run(&[
                    $( ros_message!(@layout $ty $(, $max)?), )*
                    $($( <$oty as CdrField>::LAYOUT, )*)*
                ]);
                let stamp_ns = r.time()?;
                let frame_id: FrameId = r.fixed_str()?;
                if let Some(run) = RUN
                    && let Some(m) = r.fixed_run(run.align, run.size, |window| {
                        Self::decode_body(window, stamp_ns, frame_id)
                    })
                {
                    return Ok(m);
                }
                Self::decode_body(r, stamp_ns, frame_id)
            }
        }
    };
    // The frame id a constant.
    (
        $(#[$m:meta])*
        pub struct $name:ident: $type_name:literal, $schema:expr;
        header {
            $(#[$sm:meta])* $stamp:ident,
            frame_id = $frame:expr $(,)?
        }
        $($rest:tt)*
    ) => {
        ros_message!(@message [$(#[$m])*] $name $type_name [$schema]
            [$(#[$sm])* $stamp] [const $frame] [] $($rest)*);
    };
    // The frame id a field.
    (
        $(#[$m:meta])*
        pub struct $name:ident: $type_name:literal, $schema:expr;
        header {
            $(#[$sm:meta])* $stamp:ident,
            $(#[$fm:meta])* $frame:ident: FrameId $(,)?
        }
        $($rest:tt)*
    ) => {
        ros_message!(@message [$(#[$m])*] $name $type_name [$schema]
            [$(#[$sm])* $stamp] [field $frame] [$(#[$fm])* pub $frame: FrameId,] $($rest)*);
    };
}

/// The frame id of the base frame {0}.
pub const FRAME_BASE: &str = "base";
/// The frame id of the force/torque sensor's frame.
pub const FRAME_SENSOR: &str = "sensor";

fn frame(s: &str) -> FrameId {
    FrameId::truncating(s)
}

ros_message! {
    /// `geometry_msgs/msg/WrenchStamped`.
    #[derive(Debug, Clone, Copy, PartialEq, Default)]
    pub struct WrenchStamped: "geometry_msgs/msg/WrenchStamped", concat!(
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
    header {
        /// `header.stamp`, ns.
        stamp_ns,
        /// `header.frame_id`.
        frame_id: FrameId,
    }
    // `wrench.force` and `wrench.torque`: a Vector3 is three float64.
    fields {
        /// Force, N.
        force_n: [f64; 3],
        /// Torque, N m.
        torque_nm: [f64; 3],
    }
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
            /// Every value, in code order (a test checks each against the
            /// `.msg` file's constant of its name).
            pub const ALL: &'static [Self] = &[Self::$first $(, Self::$v)*];
            /// The value's name as written (`QuickStop`; the `.msg`
            /// constant's is its upper snake case, `DRIVE_QUICK_STOP`).
            pub const fn name(self) -> &'static str {
                match self {
                    Self::$first => stringify!($first),
                    $(Self::$v => stringify!($v),)*
                }
            }
            /// The numeric code of the `.msg` file.
            #[inline]
            pub fn code(self) -> u8 {
                self as u8
            }
            /// The value of a code, or `BadValue`.
            #[inline]
            pub fn from_code(code: u8) -> Result<Self, CdrError> {
                match code {
                    $fc => Ok(Self::$first),
                    $($c => Ok(Self::$v),)*
                    _ => Err(CdrError::BadValue { field: $field, value: i64::from(code) }),
                }
            }
        }
        /// A `uint8` code.
        impl CdrField for $name {
            const ROS_TYPE: &'static str = "uint8";
            const LAYOUT: Option<FixedLayout> = <u8 as CdrField>::LAYOUT;
            #[inline]
            fn write(&self, w: &mut CdrWriter<'_>) {
                w.u8(self.code());
            }
            #[inline(always)]
            fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
                Self::from_code(r.u8()?)
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
        // 3..=8 (`COMMAND_CLEAR_TARE`, `COMMAND_ENABLE`, `COMMAND_DISABLE`,
        // `COMMAND_QUICK_STOP`, `COMMAND_FAULT_RESET`, `COMMAND_MOVE_TO` of
        // the .msg) are reserved: no version of `sard` wrote them.
        /// Set the sensor's bias (values: force x, y, z in N, then torque
        /// x, y, z in N m; sensor frame). Written by older versions of
        /// `sard`; read, it gives no request.
        SetBias = 9,
        /// Move the tip (`move_tip_m`, base frame, m).
        MoveTip = 10,
        /// Set the force limits (`limits_n`).
        SetLimits = 11,
        /// Back the tip out along the rod (`back_out_m`).
        BackOut = 12,
        /// Force control, compliant hold (`values[0]`: the force, N).
        Hold = 13,
        /// Force control, axial push (`values[0]`: the axial force, N).
        Push = 14,
        /// End force control: position control again.
        Position = 15,
        /// The dynamic identification's excitation about where the axes
        /// rest (`move_tip_m`: each axis's amplitude, m; `limits_n`: each
        /// axis's frequency, Hz, then the duration and the fade, s).
        Excite = 16,
        /// The operator confirms the support as it is now (issue 34: a
        /// named shift of the support acknowledged; `sarctl support confirm`).
        SupportConfirm = 17,
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
/// one table (`sar_estimator::guard::REASONS`, `Reason::code`, and
/// `Reason::recorded_code` for this `uint8`), which the wire and `sarctl`
/// use too; the `.msg` constants are checked against it by a test
/// (`tests/messages.rs`). Here only what the table has not.
pub mod reason {
    /// A code too large for the recording's `uint8` (none today).
    pub const OTHER: u8 = sar_estimator::guard::CODE_OTHER;
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

ros_message! {
    /// `sar_msgs/msg/EstimatorState` (`msg/EstimatorState.msg`): one cycle.
    #[derive(Debug, Clone, Copy, PartialEq, Default)]
    pub struct EstimatorState: "sar_msgs/msg/EstimatorState", concat!(
        include_str!("../msg/EstimatorState.msg"),
        header_sections!()
    );
    header {
        /// `header.stamp` = `now_ns`, frame `base`.
        stamp_ns,
        frame_id = FRAME_BASE,
    }
    fields {
        /// The cycle number.
        cycle: u64,
        /// The cycle's now, ns.
        now_ns: u64,
        /// The sensor sample's stamp, ns.
        sensor_stamp_ns: u64,
        /// The joint sample's stamp, ns.
        joints_stamp_ns: u64,
        /// now - sensor stamp, ns.
        sensor_age_ns: u64,
        /// now - joints stamp, ns.
        joints_age_ns: u64,
        /// What became of the tip force.
        tip_outcome: TipOutcomeCode,
        /// A, m.
        ujoint_m: [f64; 3],
        /// D, m.
        tip_m: [f64; 3],
        /// a = |B - A|, m.
        support_distance_m: f64,
        /// F_A, N.
        ujoint_force_n: [f64; 3],
        /// F_tip, N.
        tip_force_n: [f64; 3],
        /// Its standard deviation per axis, N.
        tip_force_std_n: [f64; 3],
        /// Axial part of F_tip, N.
        axial_n: f64,
        /// Lateral part of F_tip, N.
        lateral_n: f64,
        /// Torsion about the rod, N m.
        torsion_nm: f64,
        /// The causal filtered F_tip, N.
        tip_force_filtered_n: [f64; 3],
        /// The guard's state after the cycle.
        guard_state: GuardStateCode,
        /// Why ([`reason`]).
        guard_reason_code: u8,
        /// Why, in words.
        guard_reason_text: ReasonText,
        /// [`flags`] or-ed.
        flags: u32,
    }
}

ros_message! {
    /// `sar_msgs/msg/GuardEvent` (`msg/GuardEvent.msg`): one guard transition.
    #[derive(Debug, Clone, Copy, PartialEq, Default)]
    pub struct GuardEvent: "sar_msgs/msg/GuardEvent",
        concat!(include_str!("../msg/GuardEvent.msg"), header_sections!());
    header {
        /// `header.stamp` = now of the cycle, frame `base`.
        stamp_ns,
        frame_id = FRAME_BASE,
    }
    fields {
        /// The cycle.
        cycle: u64,
        /// The state left.
        from_state: GuardStateCode,
        /// The state entered.
        to_state: GuardStateCode,
        /// Why ([`reason`]).
        reason_code: u8,
        /// Why, in words.
        reason_text: ReasonText,
    }
}

ros_message! {
    /// `sar_msgs/msg/SceneStatus` (`msg/SceneStatus.msg`): the guard's
    /// figures at the 3D scene's rate (`/sar/scene/status`).
    #[derive(Debug, Clone, Copy, PartialEq, Default)]
    pub struct SceneStatus: "sar_msgs/msg/SceneStatus",
        concat!(include_str!("../msg/SceneStatus.msg"), header_sections!());
    header {
        /// `header.stamp` = now of the cycle, frame `base`.
        stamp_ns,
        frame_id = FRAME_BASE,
    }
    fields {
        /// The cycle.
        cycle: u64,
        /// The guard's state.
        guard_state: GuardStateCode,
        /// Its name.
        guard: ReasonText,
        /// The guard's reason, in words.
        reason: ReasonText,
        /// |F_tip|, N (NaN without an estimate).
        force_total_n: f64,
        /// F_tip along the rod, N.
        axial_n: f64,
        /// F_tip across the rod, N.
        lateral_n: f64,
        /// The warn limit on |F_tip|, N.
        warn_total_n: f64,
        /// The stop limit on |F_tip|, N.
        stop_total_n: f64,
        /// The warn limit on the axial part, N.
        warn_axial_n: f64,
        /// The stop limit on the axial part, N.
        stop_axial_n: f64,
        /// The warn limit on the lateral part, N.
        warn_lateral_n: f64,
        /// The stop limit on the lateral part, N.
        stop_lateral_n: f64,
        /// The simulator's true F_tip, base frame, N (NaN on a robot).
        truth_tip_force_n: [f64; 3],
    }
}

ros_message! {
    /// `sar_msgs/msg/CycleInput` (`msg/CycleInput.msg`): what one cycle consumed.
    #[derive(Debug, Clone, Copy, PartialEq, Default)]
    pub struct CycleInput: "sar_msgs/msg/CycleInput",
        concat!(include_str!("../msg/CycleInput.msg"), header_sections!());
    header {
        /// `header.stamp` = `now_ns`, frame `base`.
        stamp_ns,
        frame_id = FRAME_BASE,
    }
    fields {
        /// The cycle number.
        cycle: u64,
        /// Host monotonic time now, ns.
        now_ns: u64,
        /// The clock's status.
        clock_status: ClockStatusCode,
        /// Force, sensor frame, N.
        sensor_force_n: [f64; 3],
        /// Torque, sensor frame, N m.
        sensor_torque_nm: [f64; 3],
        /// The device's sample counter.
        sensor_counter: u32,
        /// The device's status word.
        sensor_status: u32,
        /// Receive time, ns.
        sensor_stamp_ns: u64,
        /// The driver's word that the sample is good.
        sensor_valid: bool,
        /// q1, q2, q3, m.
        joints_q_m: [f64; 3],
        /// Measure time, ns.
        joints_stamp_ns: u64,
        /// The driver's word that the positions are good.
        joints_valid: bool,
        /// The drives' state.
        drive_state: DriveStateCode,
        /// The faulted axis (0..=2), -1 for none.
        drive_fault_axis: i8,
        /// The device's fault code (0 unless faulted).
        drive_fault_code: u16,
        /// Commanded q1..q3, m.
        target_q_m: [f64; 3],
        /// Whether a target is commanded.
        target_valid: bool,
        /// The operator command applied.
        command_kind: CommandKindCode,
        /// Its real arguments.
        command_values: [f64; 6],
        /// Its integer argument.
        command_arg: u64,
        /// MOVE_TIP: the wanted tip, base frame, m.
        move_tip_m: [f64; 3],
        /// SET_LIMITS: warn, stop of total, axial, lateral, N.
        limits_n: [f64; 6],
        /// The step's decision: what the drives were told.
        drive_action: DriveActionCode,
        /// With `Setpoint`: q1..q3 one period ahead, m.
        setpoint_q_m: [f64; 3],
        /// The reply's status code, [`REPLY_NONE`] without a request.
        reply_status: u8,
        /// The guard's reason code behind a refusal.
        reply_reason: u16,
        /// The force limits in use after the cycle, N.
        limits_in_use_n: [f64; 6],
    }
    // Added with issue 14: an older recording ends before them.
    since {
        /// How long the publishing thread had made no progress, ns (0 in
        /// recordings older than this field).
        publisher_idle_ns: u64,
        /// BACK_OUT: how far to back the tip out along the rod, m.
        back_out_m: f64,
    }
    // Added with issue 15 (guarded moves).
    since {
        /// MOVE_TIP: a guarded move's force limit, N (0: unguarded; 0 in
        /// recordings older than this field).
        move_max_force_n: f64,
    }
    // Added with issue 35 (the spike check sees every sample).
    since {
        /// Whether the loop counted the samples it drained this cycle
        /// (false in recordings older than this field: the step then
        /// compares new samples itself).
        sensor_drained_counted: bool,
        /// Samples the driver received since the previous cycle.
        sensor_drained_samples: u16,
        /// Steps between consecutive ones beyond the spike threshold.
        sensor_drained_jumps: u16,
    }
}

ros_message! {
    /// `sar_msgs/msg/RecorderDrops` (`msg/RecorderDrops.msg`): the recorder's
    /// account of dropped messages.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
    pub struct RecorderDrops: "sar_msgs/msg/RecorderDrops",
        concat!(include_str!("../msg/RecorderDrops.msg"), header_sections!());
    header {
        /// `header.stamp`: the log time of the newest message seen, ns.
        stamp_ns,
        frame_id = "",
    }
    fields {
        /// Messages dropped since the recorder started (queue full or writer failed).
        dropped: u64,
        /// Messages written since the recorder started.
        written: u64,
        /// The queue's capacity.
        queue_capacity: u64,
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

ros_message! {
    /// `sar_msgs/msg/StateSnapshot` (`msg/StateSnapshot.msg`): the loop's
    /// decision state after a cycle, as written (the reader's form: owns its
    /// bytes).
    #[derive(Debug, Clone, PartialEq, Eq)]
    pub struct StateSnapshot: "sar_msgs/msg/StateSnapshot",
        concat!(include_str!("../msg/StateSnapshot.msg"), header_sections!());
    header {
        /// `header.stamp`: the cycle's `now`, ns.
        stamp_ns,
        frame_id = "",
    }
    fields {
        /// The last cycle stepped before it was taken.
        after_cycle: u64,
        /// The sar-snapshot format's version.
        format_version: u16,
        /// The snapshot's bytes.
        data: Vec<u8> [<= sar_snapshot::CAPACITY],
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
    /// `/sar/cycle/batch`, [`CycleBatch`]: consecutive cycles' inputs (the
    /// lean recording's form of `/sar/cycle/input`, `/sar/sensor/wrench`
    /// and `/sar/joints`).
    CycleBatch,
}

impl Topic {
    /// Every topic, in channel order.
    pub const ALL: [Topic; 12] = [
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
        Topic::CycleBatch,
    ];

    /// The channels of a full recording: every topic but the lean mode's
    /// `/sar/cycle/batch` (only a lean file has that channel).
    pub const FULL: [Topic; 11] = [
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
            Topic::CycleBatch => "/sar/cycle/batch",
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
            Topic::CycleBatch => CycleBatch::TYPE_NAME,
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
            Topic::CycleBatch => CycleBatch::SCHEMA,
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
            // Variable-length: read them with `StateSnapshot::decode`,
            // `CycleBatch::decode`.
            Topic::StateSnapshot | Topic::CycleBatch => return Err(CdrError::NotAMessage),
        })
    }
}

mod batch;
pub use batch::{BATCH_SEQ_MAX, CycleBatch, SeqElem, batch_flags};
