//! The RDT wire format, pure: no I/O, no allocation, no panic on any bytes.
//!
//! Request (host to sensor), 8 bytes, big-endian: `u16` header `0x1234`,
//! `u16` command, `u32` data. Response (sensor to host), 36 bytes, big-endian:
//! `u32` RDT sequence (per packet of one stream), `u32` sensor sample counter,
//! `u32` status (non-zero: fault), then Fx, Fy, Fz, Tx, Ty, Tz as `i32` counts.
//!
//! The data field is a real big-endian `u32` (two public drivers write the low
//! 16 bits twice; a start request for 70 000 samples shows the difference).

/// The first two bytes of every request.
pub const HEADER: u16 = 0x1234;
/// Length of a request, bytes.
pub const REQUEST_LEN: usize = 8;
/// Length of a response, bytes.
pub const RESPONSE_LEN: usize = 36;
/// The UDP port both OnRobot's Compute Box and ATI's Net F/T listen on.
pub const DEFAULT_PORT: u16 = 49152;

/// Stop streaming (data ignored, 0).
pub const CMD_STOP: u16 = 0x0000;
/// Start real-time streaming; data = number of samples, 0 = endless.
pub const CMD_START: u16 = 0x0002;
/// Bias. OnRobot: data [`BIAS_ON`] or [`BIAS_OFF`]; ATI: a one-shot software
/// bias (data ignored, 0).
pub const CMD_BIAS: u16 = 0x0042;
/// OnRobot only: the low-pass filter, data = [`Filter`] code.
pub const CMD_FILTER: u16 = 0x0081;
/// OnRobot only: the output rate, data = 1000 / rate in Hz (the period, ms).
pub const CMD_RATE: u16 = 0x0082;
/// OnRobot bias data: bias on (the present reading becomes zero).
pub const BIAS_ON: u32 = 0xFF;
/// OnRobot bias data: bias off (raw readings).
pub const BIAS_OFF: u32 = 0x00;

/// A wire format error (the offending values inside).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum CodecError {
    /// The datagram does not have the format's length.
    #[error("{got} bytes where the RDT format has {expected}")]
    WrongLength {
        /// The format's length.
        expected: usize,
        /// The datagram's length.
        got: usize,
    },
    /// A request without the 0x1234 header.
    #[error("request header {header:#06x}, not 0x1234")]
    BadHeader {
        /// The header found.
        header: u16,
    },
}

/// OnRobot's low-pass filter settings (the data of [`CMD_FILTER`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Filter {
    /// No filter (code 0).
    None,
    /// 500 Hz (code 1).
    Hz500,
    /// 150 Hz (code 2).
    Hz150,
    /// 50 Hz (code 3).
    Hz50,
    /// 15 Hz (code 4).
    Hz15,
    /// 5 Hz (code 5).
    Hz5,
    /// 1.5 Hz (code 6).
    Hz1_5,
}

impl Filter {
    /// The code sent on the wire.
    pub fn code(self) -> u32 {
        match self {
            Self::None => 0,
            Self::Hz500 => 1,
            Self::Hz150 => 2,
            Self::Hz50 => 3,
            Self::Hz15 => 4,
            Self::Hz5 => 5,
            Self::Hz1_5 => 6,
        }
    }

    /// The filter of a wire code, `None` for an unknown code.
    pub fn from_code(code: u32) -> Option<Self> {
        Some(match code {
            0 => Self::None,
            1 => Self::Hz500,
            2 => Self::Hz150,
            3 => Self::Hz50,
            4 => Self::Hz15,
            5 => Self::Hz5,
            6 => Self::Hz1_5,
            _ => return None,
        })
    }
}

/// A request from the host to the sensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Request {
    /// The command (`CMD_*`).
    pub command: u16,
    /// The command's data.
    pub data: u32,
}

impl Request {
    /// Start streaming `samples` samples (0: endless).
    pub fn start(samples: u32) -> Self {
        Self {
            command: CMD_START,
            data: samples,
        }
    }

    /// Stop streaming.
    pub fn stop() -> Self {
        Self {
            command: CMD_STOP,
            data: 0,
        }
    }

    /// OnRobot's bias on or off.
    pub fn bias(on: bool) -> Self {
        Self {
            command: CMD_BIAS,
            data: if on { BIAS_ON } else { BIAS_OFF },
        }
    }

    /// ATI's one-shot software bias.
    pub fn bias_once() -> Self {
        Self {
            command: CMD_BIAS,
            data: 0,
        }
    }

    /// OnRobot's filter.
    pub fn filter(filter: Filter) -> Self {
        Self {
            command: CMD_FILTER,
            data: filter.code(),
        }
    }

    /// OnRobot's output period, ms (the rate is 1000 / `period_ms` Hz).
    pub fn rate_period_ms(period_ms: u32) -> Self {
        Self {
            command: CMD_RATE,
            data: period_ms,
        }
    }

    /// The 8 bytes on the wire.
    pub fn encode(&self) -> [u8; REQUEST_LEN] {
        let [h0, h1] = HEADER.to_be_bytes();
        let [c0, c1] = self.command.to_be_bytes();
        let [d0, d1, d2, d3] = self.data.to_be_bytes();
        [h0, h1, c0, c1, d0, d1, d2, d3]
    }

    /// The request in `bytes` (exactly [`REQUEST_LEN`] of them, with the header).
    pub fn decode(bytes: &[u8]) -> Result<Self, CodecError> {
        let [h0, h1, c0, c1, d0, d1, d2, d3] = exact::<REQUEST_LEN>(bytes)?;
        let header = u16::from_be_bytes([h0, h1]);
        if header != HEADER {
            return Err(CodecError::BadHeader { header });
        }
        Ok(Self {
            command: u16::from_be_bytes([c0, c1]),
            data: u32::from_be_bytes([d0, d1, d2, d3]),
        })
    }
}

/// A response: one sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Response {
    /// The packet's place in its stream (restarts with each stream).
    pub rdt_sequence: u32,
    /// The sensor's own sample counter (runs at its internal rate).
    pub sample_counter: u32,
    /// The sensor's status; non-zero is a fault.
    pub status: u32,
    /// Fx, Fy, Fz, Tx, Ty, Tz in counts.
    pub counts: [i32; 6],
}

impl Response {
    /// The 36 bytes on the wire.
    pub fn encode(&self) -> [u8; RESPONSE_LEN] {
        let mut out = [0u8; RESPONSE_LEN];
        let words = [self.rdt_sequence, self.sample_counter, self.status]
            .into_iter()
            .chain(
                self.counts
                    .iter()
                    .map(|c| u32::from_be_bytes(c.to_be_bytes())),
            );
        for (chunk, word) in out.chunks_exact_mut(4).zip(words) {
            chunk.copy_from_slice(&word.to_be_bytes());
        }
        out
    }

    /// The response in `bytes` (exactly [`RESPONSE_LEN`] of them; every
    /// content is a valid response).
    pub fn decode(bytes: &[u8]) -> Result<Self, CodecError> {
        let raw = exact::<RESPONSE_LEN>(bytes)?;
        let mut words = [0u32; 9];
        for (word, chunk) in words.iter_mut().zip(raw.chunks_exact(4)) {
            let mut four = [0u8; 4];
            four.copy_from_slice(chunk);
            *word = u32::from_be_bytes(four);
        }
        let [seq, counter, status, c0, c1, c2, c3, c4, c5] = words;
        let counts = [c0, c1, c2, c3, c4, c5].map(|w| i32::from_be_bytes(w.to_be_bytes()));
        Ok(Self {
            rdt_sequence: seq,
            sample_counter: counter,
            status,
            counts,
        })
    }
}

/// `bytes` as an array of exactly `N`.
fn exact<const N: usize>(bytes: &[u8]) -> Result<[u8; N], CodecError> {
    <[u8; N]>::try_from(bytes).map_err(|_| CodecError::WrongLength {
        expected: N,
        got: bytes.len(),
    })
}

#[cfg(test)]
#[allow(clippy::indexing_slicing)]
mod tests {
    use super::*;

    #[test]
    fn data_is_a_real_big_endian_u32() {
        // 70 000 = 0x0001_1170: the low-16-bits-twice packing would give
        // 11 70 11 70.
        let bytes = Request::start(70_000).encode();
        assert_eq!(bytes, [0x12, 0x34, 0x00, 0x02, 0x00, 0x01, 0x11, 0x70]);
        assert_eq!(
            Request::rate_period_ms(1000).encode(),
            [0x12, 0x34, 0x00, 0x82, 0x00, 0x00, 0x03, 0xE8]
        );
        assert_eq!(
            Request::bias(true).encode(),
            [0x12, 0x34, 0x00, 0x42, 0x00, 0x00, 0x00, 0xFF]
        );
        assert_eq!(Request::decode(&bytes), Ok(Request::start(70_000)));
    }

    #[test]
    fn response_layout_and_signs() {
        let r = Response {
            rdt_sequence: 0x0102_0304,
            sample_counter: 0xA0B0_C0D0,
            status: 0x8000_0001,
            counts: [1, -1, i32::MIN, i32::MAX, 0, -10_000],
        };
        let b = r.encode();
        assert_eq!(b[..4], [1, 2, 3, 4]);
        assert_eq!(b[4..8], [0xA0, 0xB0, 0xC0, 0xD0]);
        assert_eq!(b[8..12], [0x80, 0, 0, 1]);
        assert_eq!(b[12..16], [0, 0, 0, 1]);
        assert_eq!(b[16..20], [0xFF; 4]);
        assert_eq!(b[20..24], [0x80, 0, 0, 0]);
        assert_eq!(Response::decode(&b), Ok(r));
    }

    #[test]
    fn wrong_lengths_and_headers_are_errors() {
        assert_eq!(
            Response::decode(&[0; 35]),
            Err(CodecError::WrongLength {
                expected: 36,
                got: 35
            })
        );
        assert_eq!(
            Request::decode(&[0x43, 0x21, 0, 2, 0, 0, 0, 0]),
            Err(CodecError::BadHeader { header: 0x4321 })
        );
        for code in 0..7 {
            assert_eq!(Filter::from_code(code).map(Filter::code), Some(code));
        }
        assert_eq!(Filter::from_code(7), None);
    }
}
