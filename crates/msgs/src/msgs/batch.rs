//! `sar_msgs/msg/CycleBatch` (`msg/CycleBatch.msg`), the lean recording's
//! message: consecutive cycles' inputs in typed arrays. Its fields are one
//! list (`batch_message!`, in the style of `ros_message!`): the struct, its
//! CDR and `MSG_FIELDS`, which `crates/msgs/tests/layout.rs` compares with
//! the `.msg` file. What the arrays mean (differences, counts) is
//! `sar_record::lean`'s business; this is the data.

use super::{CycleInput, MsgField, RosMessage};
use crate::cdr::{CdrError, CdrReader, CdrWriter};

/// The most entries a decoded array may hold (bounded again by the bytes
/// left: a length is never trusted).
pub const BATCH_SEQ_MAX: usize = 1 << 20;

/// An element of a `CycleBatch` array: its `.msg` type, its CDR.
pub trait SeqElem: Sized {
    /// The `.msg` type of the array (`int32[]`).
    const ROS_SEQ: &'static str;
    /// The fewest bytes one element takes (the bound of a decoded length).
    const MIN_BYTES: usize;
    /// Writes one element.
    fn put(&self, w: &mut CdrWriter<'_>) -> Result<(), CdrError>;
    /// Reads one element.
    fn get(r: &mut CdrReader<'_>) -> Result<Self, CdrError>;
}

macro_rules! seq_elem {
    ($($t:ident, $ros:literal;)*) => {$(
        impl SeqElem for $t {
            const ROS_SEQ: &'static str = $ros;
            const MIN_BYTES: usize = core::mem::size_of::<$t>();
            #[inline]
            fn put(&self, w: &mut CdrWriter<'_>) -> Result<(), CdrError> {
                w.$t(*self);
                Ok(())
            }
            #[inline]
            fn get(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
                r.$t()
            }
        }
    )*};
}

seq_elem! {
    u8, "uint8[]";
    i8, "int8[]";
    u16, "uint16[]";
    u32, "uint32[]";
    i32, "int32[]";
    u64, "uint64[]";
    i64, "int64[]";
    f64, "float64[]";
}

/// A nested `sar_msgs/CycleInput`: its fields without an encapsulation
/// header, as CDR nests a message.
impl SeqElem for CycleInput {
    const ROS_SEQ: &'static str = "sar_msgs/CycleInput[]";
    const MIN_BYTES: usize = 64;
    fn put(&self, w: &mut CdrWriter<'_>) -> Result<(), CdrError> {
        self.encode_fields(w)
    }
    fn get(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        CycleInput::decode_fields(r)
    }
}

fn put_seq<T: SeqElem>(w: &mut CdrWriter<'_>, v: &[T]) -> Result<(), CdrError> {
    w.seq_len(v.len());
    v.iter().try_for_each(|x| x.put(w))
}

fn get_seq<T: SeqElem>(r: &mut CdrReader<'_>) -> Result<Vec<T>, CdrError> {
    let n = r.seq_len(BATCH_SEQ_MAX, T::MIN_BYTES)?;
    let mut v = Vec::with_capacity(n);
    for _ in 0..n {
        v.push(T::get(r)?);
    }
    Ok(v)
}

/// Defines the batch message from one list of its fields in wire order
/// (after the header, whose frame id is empty): scalars (`float64`), then
/// arrays (`Vec<T>`, `T[]`), then arrays added later (a message that ends
/// before one reads it empty).
macro_rules! batch_message {
    (
        $(#[$m:meta])*
        pub struct $name:ident: $type_name:literal, $schema:expr;
        $(#[$sm:meta])* $stamp:ident;
        scalars { $( $(#[$fm:meta])* $field:ident: f64, )* }
        arrays { $( $(#[$am:meta])* $array:ident: Vec<$elem:ty>, )* }
        later { $( $(#[$lm:meta])* $later:ident: Vec<$lelem:ty>, )* }
    ) => {
        $(#[$m])*
        pub struct $name {
            $(#[$sm])*
            pub $stamp: u64,
            $( $(#[$fm])* pub $field: f64, )*
            $( $(#[$am])* pub $array: Vec<$elem>, )*
            $( $(#[$lm])* pub $later: Vec<$lelem>, )*
        }

        impl $name {
            /// The fields in wire order as the `.msg` file declares them,
            /// the header first.
            pub const MSG_FIELDS: &'static [MsgField] = &[
                MsgField::HEADER,
                $( MsgField { ros_type: "float64", array_len: None, name: stringify!($field) }, )*
                $( MsgField {
                    ros_type: <$elem as SeqElem>::ROS_SEQ,
                    array_len: None,
                    name: stringify!($array),
                }, )*
                $( MsgField {
                    ros_type: <$lelem as SeqElem>::ROS_SEQ,
                    array_len: None,
                    name: stringify!($later),
                }, )*
            ];
        }

        impl RosMessage for $name {
            const TYPE_NAME: &'static str = $type_name;
            const SCHEMA: &'static str = $schema;
            fn encode_fields(&self, w: &mut CdrWriter<'_>) -> Result<(), CdrError> {
                w.time(self.$stamp)?;
                w.string("");
                $( w.f64(self.$field); )*
                $( put_seq(w, &self.$array)?; )*
                $( put_seq(w, &self.$later)?; )*
                Ok(())
            }
            fn decode_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
                let $stamp = r.time()?;
                let _frame_id = r.str()?;
                $( let $field = r.f64()?; )*
                $( let $array = get_seq(r)?; )*
                // Added later: a message that ends before one reads it empty.
                $( let $later = if r.remaining() == 0 { Vec::new() } else { get_seq(r)? }; )*
                Ok(Self { $stamp, $( $field, )* $( $array, )* $( $later, )* })
            }
        }
    };
}

batch_message! {
    /// `sar_msgs/msg/CycleBatch` (`msg/CycleBatch.msg`): consecutive
    /// cycles' inputs, the lean recording's `/sar/cycle/batch`.
    #[derive(Debug, Clone, PartialEq, Default)]
    pub struct CycleBatch: "sar_msgs/msg/CycleBatch", concat!(
        include_str!("../../msg/CycleBatch.msg"),
        header_sections!(),
        sep!(),
        "MSG: sar_msgs/CycleInput\n",
        include_str!("../../msg/CycleInput.msg"),
    );
    /// `header.stamp`: the first cycle's stamp, ns.
    stamp_ns;
    scalars {
        /// Counts per newton of the forces (0: floats).
        force_counts_per_n: f64,
        /// Counts per newton metre of the torques (0: floats).
        torque_counts_per_nm: f64,
        /// Metres per count of the positions (0: floats).
        joint_m_per_count: f64,
    }
    arrays {
        /// `FLAG_*` per cycle.
        flags: Vec<u8>,
        /// Differences of the cycle number.
        cycle: Vec<i64>,
        /// Differences of now, ns.
        now_ns: Vec<i64>,
        /// The clock's status per cycle.
        clock_status: Vec<u8>,
        /// Differences of the publisher's idle time less those of now, ns.
        publisher_idle_ns: Vec<i64>,
        /// Differences of the sample counter.
        sensor_counter: Vec<i32>,
        /// The device's status word per cycle.
        sensor_status: Vec<u32>,
        /// Differences of the sample's stamp, ns.
        sensor_stamp_ns: Vec<i64>,
        /// Six per cycle: differences of the counts.
        sensor_counts: Vec<i32>,
        /// Six per raw sample.
        sensor_raw: Vec<f64>,
        /// Differences of the positions' stamp, ns.
        joints_stamp_ns: Vec<i64>,
        /// Three per cycle: differences of the counts.
        joint_counts: Vec<i32>,
        /// Three per raw cycle, m.
        joints_raw: Vec<f64>,
        /// The drives' state per cycle.
        drive_state: Vec<u8>,
        /// The faulted axis per cycle (-1: none).
        drive_fault_axis: Vec<i8>,
        /// The fault code per cycle.
        drive_fault_code: Vec<u16>,
        /// The place of each command's cycle.
        command_cycles: Vec<u32>,
        /// The cycles with a command, whole.
        commands: Vec<CycleInput>,
        /// The place of each extra sensor message's cycle.
        extra_cycles: Vec<u32>,
        /// Each extra sensor message's stamp, ns.
        extra_stamp_ns: Vec<u64>,
        /// Six per extra sensor message.
        extra_wrench: Vec<f64>,
    }
    later {
        /// Issue 35 (empty in older lean files): two per cycle, the samples
        /// the loop drained plus one (0: not counted) and the jumps among
        /// them (`CycleInput`'s `sensor_drained_*`).
        drained_counts: Vec<u16>,
    }
}

/// `CycleBatch.msg`'s flags.
pub mod batch_flags {
    /// The driver's word that the sample is good.
    pub const SENSOR_VALID: u8 = 1;
    /// The driver's word that the positions are good.
    pub const JOINTS_VALID: u8 = 2;
    /// `/sar/joints` recorded in this cycle.
    pub const JOINTS_MESSAGE: u8 = 4;
    /// The cycle's sample recorded on `/sar/sensor/wrench`.
    pub const SENSOR_MESSAGE: u8 = 8;
    /// The sample's floats in `sensor_raw`.
    pub const SENSOR_RAW: u8 = 16;
    /// The positions' floats in `joints_raw`.
    pub const JOINTS_RAW: u8 = 32;
    /// Force and torque are the previous cycle's.
    pub const SENSOR_REPEAT: u8 = 64;
    /// The positions are the previous cycle's.
    pub const JOINTS_REPEAT: u8 = 128;
}
