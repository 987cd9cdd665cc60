//! CANopen (CiA 301) and CiA 402 on the wire: COB-IDs, NMT, SDO (expedited),
//! PDO, SYNC, EMCY and heartbeat frames, the control and status words, and a
//! plain frame type ([`RawFrame`]) that implements `embedded_can::Frame`.

use embedded_can::{Frame, Id, StandardId};

/// NMT command COB-ID.
pub const COB_NMT: u16 = 0x000;
/// SYNC COB-ID.
pub const COB_SYNC: u16 = 0x080;
/// EMCY base (+ node id).
pub const COB_EMCY: u16 = 0x080;
/// TPDO1 base (+ node id).
pub const COB_TPDO1: u16 = 0x180;
/// RPDO1 base (+ node id).
pub const COB_RPDO1: u16 = 0x200;
/// SDO server-to-client base (+ node id).
pub const COB_SDO_TX: u16 = 0x580;
/// SDO client-to-server base (+ node id).
pub const COB_SDO_RX: u16 = 0x600;
/// Heartbeat / boot-up base (+ node id).
pub const COB_HEARTBEAT: u16 = 0x700;

/// NMT command specifiers.
pub mod nmt {
    /// Start remote node (to operational).
    pub const START: u8 = 0x01;
    /// Stop remote node.
    pub const STOP: u8 = 0x02;
    /// Enter pre-operational.
    pub const PRE_OPERATIONAL: u8 = 0x80;
    /// Reset node.
    pub const RESET_NODE: u8 = 0x81;
    /// Reset communication.
    pub const RESET_COMMUNICATION: u8 = 0x82;
}

/// Heartbeat states (byte 0 of a heartbeat frame).
pub mod heartbeat {
    /// Boot-up message.
    pub const BOOT_UP: u8 = 0x00;
    /// Stopped.
    pub const STOPPED: u8 = 0x04;
    /// Operational.
    pub const OPERATIONAL: u8 = 0x05;
    /// Pre-operational.
    pub const PRE_OPERATIONAL: u8 = 0x7F;
}

/// Object dictionary indices used here.
pub mod od {
    /// Consumer heartbeat time (sub 1: node << 16 | ms).
    pub const CONSUMER_HEARTBEAT: u16 = 0x1016;
    /// Producer heartbeat time, ms (u16).
    pub const PRODUCER_HEARTBEAT: u16 = 0x1017;
    /// RPDO1 communication parameter.
    pub const RPDO1_COMM: u16 = 0x1400;
    /// RPDO1 mapping.
    pub const RPDO1_MAP: u16 = 0x1600;
    /// TPDO1 communication parameter.
    pub const TPDO1_COMM: u16 = 0x1800;
    /// TPDO1 mapping.
    pub const TPDO1_MAP: u16 = 0x1A00;
    /// Abort connection option code (i16; 3 = quick stop).
    pub const ABORT_CONNECTION: u16 = 0x6007;
    /// Error code (u16).
    pub const ERROR_CODE: u16 = 0x603F;
    /// Controlword (u16).
    pub const CONTROLWORD: u16 = 0x6040;
    /// Statusword (u16).
    pub const STATUSWORD: u16 = 0x6041;
    /// Quick stop option code (i16; 6 = quick stop ramp, stay in quick stop active).
    pub const QUICK_STOP_OPTION: u16 = 0x605A;
    /// Shutdown option code (i16; 1 = slow down on the slow down ramp, then
    /// disable; 0 = disable at once, the motor free to coast).
    pub const SHUTDOWN_OPTION: u16 = 0x605B;
    /// Disable operation option code (i16; 1 = slow down on the slow down
    /// ramp, then disable; 0 = disable at once, the motor free to coast).
    pub const DISABLE_OPERATION_OPTION: u16 = 0x605C;
    /// Fault reaction option code (i16; 0 = disable at once, the motor free
    /// to coast; 1 = the slow down ramp; 2 = the quick stop ramp).
    pub const FAULT_REACTION_OPTION: u16 = 0x605E;
    /// Profile deceleration (u32, counts/s^2): the slow down ramp.
    pub const PROFILE_DECELERATION: u16 = 0x6084;
    /// Modes of operation (i8; 8 = cyclic synchronous position).
    pub const MODES_OF_OPERATION: u16 = 0x6060;
    /// Modes of operation display (i8).
    pub const MODES_OF_OPERATION_DISPLAY: u16 = 0x6061;
    /// Position actual value (i32, counts).
    pub const POSITION_ACTUAL: u16 = 0x6064;
    /// Target position (i32, counts).
    pub const TARGET_POSITION: u16 = 0x607A;
    /// Following error window (u32, counts).
    pub const FOLLOWING_ERROR_WINDOW: u16 = 0x6065;
    /// Following error time out (u16, ms).
    pub const FOLLOWING_ERROR_TIMEOUT: u16 = 0x6066;
    /// Max torque (u16, per thousand of the motor's rated torque).
    pub const MAX_TORQUE: u16 = 0x6072;
    /// Software position limit (sub 1 min, sub 2 max: i32, counts).
    pub const SOFTWARE_POSITION_LIMIT: u16 = 0x607D;
    /// Max profile velocity (u32, counts/s).
    pub const MAX_PROFILE_VELOCITY: u16 = 0x607F;
    /// Quick stop deceleration (u32, counts/s^2).
    pub const QUICK_STOP_DECELERATION: u16 = 0x6085;

    /// The object's name (CiA 402), for messages.
    pub fn name(index: u16) -> &'static str {
        match index {
            CONSUMER_HEARTBEAT => "consumer heartbeat time",
            PRODUCER_HEARTBEAT => "producer heartbeat time",
            ABORT_CONNECTION => "abort connection option code",
            QUICK_STOP_OPTION => "quick stop option code",
            SHUTDOWN_OPTION => "shutdown option code",
            DISABLE_OPERATION_OPTION => "disable operation option code",
            FAULT_REACTION_OPTION => "fault reaction option code",
            PROFILE_DECELERATION => "profile deceleration",
            MODES_OF_OPERATION => "modes of operation",
            FOLLOWING_ERROR_WINDOW => "following error window",
            FOLLOWING_ERROR_TIMEOUT => "following error time out",
            MAX_TORQUE => "max torque",
            SOFTWARE_POSITION_LIMIT => "software position limit",
            MAX_PROFILE_VELOCITY => "max profile velocity",
            QUICK_STOP_DECELERATION => "quick stop deceleration",
            _ => "object",
        }
    }
}

/// Mapping entries (index << 16 | sub << 8 | bits).
pub mod mapping {
    /// Statusword, 16 bits.
    pub const STATUSWORD: u32 = 0x6041_0010;
    /// Position actual, 32 bits.
    pub const POSITION_ACTUAL: u32 = 0x6064_0020;
    /// Controlword, 16 bits.
    pub const CONTROLWORD: u32 = 0x6040_0010;
    /// Target position, 32 bits.
    pub const TARGET_POSITION: u32 = 0x607A_0020;
}

/// Cyclic synchronous position mode (0x6060 value).
pub const MODE_CSP: i8 = 8;
/// Abort connection option: quick stop (0x6007 value).
pub const ABORT_QUICK_STOP: i16 = 3;
/// Quick stop option: quick stop ramp, then stay in Quick stop active (0x605A).
pub const QUICK_STOP_RAMP_AND_HOLD: i16 = 6;
/// Shutdown option (0x605B) and disable operation option (0x605C): slow
/// down on the slow down ramp (0x6084), then disable the drive function
/// (0: disable at once, the motor coasting).
pub const DISABLE_AFTER_RAMP: i16 = 1;
/// Fault reaction option (0x605E): slow down on the quick stop ramp
/// (0x6085), as the quick stop and the host's loss do (0: the motor free to
/// coast, the default of many drives).
pub const FAULT_REACTION_QUICK_STOP_RAMP: i16 = 2;
/// EMCY code of a heartbeat (life guard) event.
pub const EMCY_HEARTBEAT: u16 = sar_hal::drives::FAULT_HEARTBEAT_LOST;
/// EMCY code of a following error.
pub const EMCY_FOLLOWING_ERROR: u16 = 0x8611;
/// Fault code the host gives a drive it lost on the bus (its heartbeat or
/// PDOs are missing): the CiA 301 life-guard code.
pub const FAULT_LOST: u16 = EMCY_HEARTBEAT;
/// Fault code for a drive in Fault whose EMCY was not seen (generic error).
pub const FAULT_GENERIC: u16 = 0x1000;

/// Controlword commands (CiA 402).
pub mod control {
    /// Shutdown (to Ready to switch on).
    pub const SHUTDOWN: u16 = 0x0006;
    /// Switch on (to Switched on).
    pub const SWITCH_ON: u16 = 0x0007;
    /// Enable operation (to Operation enabled).
    pub const ENABLE_OPERATION: u16 = 0x000F;
    /// Disable voltage (to Switch on disabled).
    pub const DISABLE_VOLTAGE: u16 = 0x0000;
    /// Quick stop (bit 2 low with bit 1 high).
    pub const QUICK_STOP: u16 = 0x0002;
    /// Fault reset (its rising edge).
    pub const FAULT_RESET: u16 = 0x0080;
    /// Halt bit.
    pub const HALT: u16 = 0x0100;
}

/// Status word bit 15, manufacturer specific, used by this project (and the
/// simulated drive) as "encoder referenced": the absolute position is valid.
/// A drive whose encoder is not referenced reports positions that are not
/// valid (`JointPositions::valid` false).
pub const STATUS_REFERENCED: u16 = 0x8000;
/// Status word bit 7: warning.
pub const STATUS_WARNING: u16 = 0x0080;
/// Status word bit 11: internal limit active (the drive clamped a set point
/// at its software position limits or limited its speed at 0x607F).
pub const STATUS_INTERNAL_LIMIT: u16 = 0x0800;
/// Status word bit 9: remote.
pub const STATUS_REMOTE: u16 = 0x0200;

/// The CiA 402 power state machine's states.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Cia402State {
    /// Not ready to switch on (initialising).
    NotReadyToSwitchOn,
    /// Switch on disabled.
    SwitchOnDisabled,
    /// Ready to switch on.
    ReadyToSwitchOn,
    /// Switched on.
    SwitchedOn,
    /// Operation enabled.
    OperationEnabled,
    /// Quick stop active.
    QuickStopActive,
    /// Fault reaction active.
    FaultReactionActive,
    /// Fault.
    Fault,
}

impl Cia402State {
    /// Decodes a status word (CiA 402 table of the state bits).
    pub fn from_statusword(sw: u16) -> Self {
        match (sw & 0x4F, sw & 0x6F) {
            (0x00, _) => Self::NotReadyToSwitchOn,
            (0x40, _) => Self::SwitchOnDisabled,
            (_, 0x21) => Self::ReadyToSwitchOn,
            (_, 0x23) => Self::SwitchedOn,
            (_, 0x27) => Self::OperationEnabled,
            (_, 0x07) => Self::QuickStopActive,
            (0x0F, _) => Self::FaultReactionActive,
            (0x08, _) => Self::Fault,
            _ => Self::NotReadyToSwitchOn,
        }
    }

    /// The state bits of the status word (with voltage enabled, bit 4, where
    /// the power stage is on).
    pub fn statusword_bits(self) -> u16 {
        match self {
            Self::NotReadyToSwitchOn => 0x0000,
            Self::SwitchOnDisabled => 0x0040,
            Self::ReadyToSwitchOn => 0x0031,
            Self::SwitchedOn => 0x0033,
            Self::OperationEnabled => 0x0037,
            Self::QuickStopActive => 0x0017,
            Self::FaultReactionActive => 0x001F,
            Self::Fault => 0x0008,
        }
    }
}

/// A classic CAN frame with an 11-bit identifier, as the in-memory bus and
/// the simulated drive use it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RawFrame {
    /// 11-bit COB-ID.
    pub cob_id: u16,
    len: u8,
    bytes: [u8; 8],
}

impl RawFrame {
    /// A data frame; `None` for more than 8 bytes or an id above 0x7FF.
    pub fn new_data(cob_id: u16, data: &[u8]) -> Option<Self> {
        if data.len() > 8 || cob_id > 0x7FF {
            return None;
        }
        let mut bytes = [0u8; 8];
        bytes.get_mut(..data.len())?.copy_from_slice(data);
        Some(Self {
            cob_id,
            len: u8::try_from(data.len()).ok()?,
            bytes,
        })
    }

    /// The data bytes.
    pub fn payload(&self) -> &[u8] {
        self.bytes.get(..usize::from(self.len)).unwrap_or(&[])
    }

    /// From any `embedded_can::Frame` (standard data frames only).
    pub fn from_frame<F: Frame>(frame: &F) -> Option<Self> {
        if frame.is_remote_frame() {
            return None;
        }
        match frame.id() {
            Id::Standard(id) => Self::new_data(id.as_raw(), frame.data()),
            Id::Extended(_) => None,
        }
    }

    /// Into any `embedded_can::Frame`.
    pub fn to_frame<F: Frame>(&self) -> Option<F> {
        F::new(StandardId::new(self.cob_id)?, self.payload())
    }
}

impl Frame for RawFrame {
    fn new(id: impl Into<Id>, data: &[u8]) -> Option<Self> {
        match id.into() {
            Id::Standard(id) => Self::new_data(id.as_raw(), data),
            Id::Extended(_) => None,
        }
    }
    fn new_remote(_id: impl Into<Id>, _dlc: usize) -> Option<Self> {
        None
    }
    fn is_extended(&self) -> bool {
        false
    }
    fn is_remote_frame(&self) -> bool {
        false
    }
    fn id(&self) -> Id {
        // cob_id <= 0x7FF by construction.
        StandardId::new(self.cob_id).map_or(Id::Standard(StandardId::ZERO), Id::Standard)
    }
    fn dlc(&self) -> usize {
        usize::from(self.len)
    }
    fn data(&self) -> &[u8] {
        self.payload()
    }
}

/// An SDO client request or server response (expedited only, ≤ 4 bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sdo {
    /// Expedited download (write) of `size` bytes (1..=4).
    Download {
        /// Index.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// Value, little-endian in the frame.
        value: u32,
        /// Bytes (1..=4).
        size: u8,
    },
    /// Download confirmed.
    DownloadOk {
        /// Index.
        index: u16,
        /// Sub-index.
        sub: u8,
    },
    /// Upload (read) request.
    Upload {
        /// Index.
        index: u16,
        /// Sub-index.
        sub: u8,
    },
    /// Expedited upload response.
    UploadOk {
        /// Index.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// Value.
        value: u32,
        /// Bytes (1..=4).
        size: u8,
    },
    /// Abort with its abort code.
    Abort {
        /// Index.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// SDO abort code.
        code: u32,
    },
}

/// SDO abort code: object does not exist.
pub const SDO_ABORT_NO_OBJECT: u32 = 0x0602_0000;
/// SDO abort code: command specifier not valid.
pub const SDO_ABORT_COMMAND: u32 = 0x0504_0001;
/// SDO abort code: value range exceeded.
pub const SDO_ABORT_RANGE: u32 = 0x0609_0030;
/// SDO abort code: cannot be stored in the present device state.
pub const SDO_ABORT_STATE: u32 = 0x0800_0022;

impl Sdo {
    /// The 8 data bytes.
    pub fn encode(&self) -> [u8; 8] {
        let (cmd, index, sub, value) = match *self {
            Self::Download {
                index,
                sub,
                value,
                size,
            } => (0x23 | ((4 - size.clamp(1, 4)) << 2), index, sub, value),
            Self::DownloadOk { index, sub } => (0x60, index, sub, 0),
            Self::Upload { index, sub } => (0x40, index, sub, 0),
            Self::UploadOk {
                index,
                sub,
                value,
                size,
            } => (0x43 | ((4 - size.clamp(1, 4)) << 2), index, sub, value),
            Self::Abort { index, sub, code } => (0x80, index, sub, code),
        };
        let i = index.to_le_bytes();
        let v = value.to_le_bytes();
        [cmd, i[0], i[1], sub, v[0], v[1], v[2], v[3]]
    }

    /// Decodes 8 data bytes; `None` for a segmented or unknown command.
    pub fn decode(data: &[u8]) -> Option<Self> {
        let d: &[u8; 8] = data.try_into().ok()?;
        let index = u16::from_le_bytes([d[1], d[2]]);
        let sub = d[3];
        let raw = u32::from_le_bytes([d[4], d[5], d[6], d[7]]);
        let cmd = d[0];
        let size = 4 - ((cmd >> 2) & 0x3);
        let mask = |v: u32| {
            if size >= 4 {
                v
            } else {
                v & ((1u32 << (8 * u32::from(size))) - 1)
            }
        };
        match cmd & 0xE0 {
            0x20 if cmd & 0x03 == 0x03 => Some(Self::Download {
                index,
                sub,
                value: mask(raw),
                size,
            }),
            0x60 => Some(Self::DownloadOk { index, sub }),
            0x40 if cmd == 0x40 => Some(Self::Upload { index, sub }),
            0x40 if cmd & 0x03 == 0x03 => Some(Self::UploadOk {
                index,
                sub,
                value: mask(raw),
                size,
            }),
            0x80 => Some(Self::Abort {
                index,
                sub,
                code: raw,
            }),
            _ => None,
        }
    }
}

/// An EMCY frame's content.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Emcy {
    /// Error code (0 = error reset / no error).
    pub code: u16,
    /// Error register (0x1001).
    pub register: u8,
}

impl Emcy {
    /// Decodes an EMCY payload (at least 3 bytes).
    pub fn decode(data: &[u8]) -> Option<Self> {
        match data {
            [lo, hi, register, ..] => Some(Self {
                code: u16::from_le_bytes([*lo, *hi]),
                register: *register,
            }),
            _ => None,
        }
    }

    /// The 8 bytes of an EMCY frame (manufacturer bytes zero).
    pub fn encode(&self) -> [u8; 8] {
        let c = self.code.to_le_bytes();
        [c[0], c[1], self.register, 0, 0, 0, 0, 0]
    }
}

/// The TPDO of this project's mapping: status word, position actual.
pub fn encode_tpdo(statusword: u16, position_counts: i32) -> [u8; 6] {
    let s = statusword.to_le_bytes();
    let p = position_counts.to_le_bytes();
    [s[0], s[1], p[0], p[1], p[2], p[3]]
}

/// Decodes the TPDO (status word, position actual counts).
pub fn decode_tpdo(data: &[u8]) -> Option<(u16, i32)> {
    match data {
        [s0, s1, p0, p1, p2, p3] => Some((
            u16::from_le_bytes([*s0, *s1]),
            i32::from_le_bytes([*p0, *p1, *p2, *p3]),
        )),
        _ => None,
    }
}

/// The RPDO of this project's mapping: control word, target position.
pub fn encode_rpdo(controlword: u16, target_counts: i32) -> [u8; 6] {
    encode_tpdo(controlword, target_counts)
}

/// Decodes the RPDO (control word, target counts).
pub fn decode_rpdo(data: &[u8]) -> Option<(u16, i32)> {
    decode_tpdo(data)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn sdo_round_trips() {
        for sdo in [
            Sdo::Download {
                index: 0x6060,
                sub: 0,
                value: 8,
                size: 1,
            },
            Sdo::Download {
                index: 0x1A00,
                sub: 1,
                value: 0x6041_0010,
                size: 4,
            },
            Sdo::DownloadOk {
                index: 0x1017,
                sub: 0,
            },
            Sdo::Upload {
                index: 0x6061,
                sub: 0,
            },
            Sdo::UploadOk {
                index: 0x6061,
                sub: 0,
                value: 8,
                size: 1,
            },
            Sdo::Abort {
                index: 0x6061,
                sub: 0,
                code: SDO_ABORT_NO_OBJECT,
            },
        ] {
            assert_eq!(Sdo::decode(&sdo.encode()), Some(sdo));
        }
        // A 2-byte download is 0x2B.
        let d = Sdo::Download {
            index: 0x1017,
            sub: 0,
            value: 20,
            size: 2,
        };
        assert_eq!(d.encode()[0], 0x2B);
        assert_eq!(d.encode()[1..4], [0x17, 0x10, 0]);
    }

    #[test]
    fn status_words_decode_to_their_states() {
        use Cia402State::*;
        for s in [
            NotReadyToSwitchOn,
            SwitchOnDisabled,
            ReadyToSwitchOn,
            SwitchedOn,
            OperationEnabled,
            QuickStopActive,
            FaultReactionActive,
            Fault,
        ] {
            let sw = s.statusword_bits() | STATUS_REFERENCED | STATUS_REMOTE;
            assert_eq!(Cia402State::from_statusword(sw), s, "{sw:#06x}");
        }
        assert_eq!(Cia402State::from_statusword(0x0237), OperationEnabled);
        assert_eq!(Cia402State::from_statusword(0x0250), SwitchOnDisabled);
    }
}
