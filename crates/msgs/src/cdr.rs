//! ROS 2 `cdr` encoding: little-endian CDR with the 4-byte encapsulation header
//! `00 01 00 00`. Primitives are aligned to their size relative to the first
//! byte after the header; a string is a u32 length (NUL included), its bytes and
//! a NUL; a sequence is a u32 count and its elements; a fixed array is its
//! elements alone.
//!
//! The writer appends to a caller-owned `Vec<u8>` (reused, it allocates only
//! while it grows); the reader never panics on arbitrary bytes: every fault is a
//! [`CdrError`] naming the byte offset.
//!
//! [`CdrField`] is one field of a message as its type writes and reads it
//! (the recorded messages list their fields once, `msgs.rs`);
//! [`CdrReader::fixed_run`] reads a run of fixed-size fields with one bounds
//! check.

/// The encapsulation header of little-endian plain CDR.
pub const ENCAPSULATION_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Why bytes could not be decoded.
#[non_exhaustive]
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CdrError {
    /// The buffer is shorter than the 4-byte encapsulation header.
    #[error("{len} bytes: too short for the CDR encapsulation header")]
    NoHeader {
        /// The buffer's length.
        len: usize,
    },
    /// The encapsulation header is not little-endian plain CDR.
    #[error("encapsulation header {found:02x?} is not little-endian CDR (00 01 00 00)")]
    BadHeader {
        /// The header found.
        found: [u8; 4],
    },
    /// The data ends inside a value.
    #[error("data ends at byte {offset}: {needed} more bytes needed")]
    UnexpectedEnd {
        /// Offset (after the header) of the value.
        offset: usize,
        /// Bytes the value needs.
        needed: usize,
    },
    /// A string's length is zero (it must count its NUL).
    #[error("string at byte {offset} has length 0 (must include its NUL)")]
    StringWithoutNul {
        /// Offset of the length.
        offset: usize,
    },
    /// A string's last byte is not NUL.
    #[error("string at byte {offset} is not NUL-terminated")]
    StringNotTerminated {
        /// Offset of the length.
        offset: usize,
    },
    /// A string is not UTF-8.
    #[error("string at byte {offset} is not UTF-8")]
    StringNotUtf8 {
        /// Offset of the length.
        offset: usize,
    },
    /// A string is longer than the field holds.
    #[error("string at byte {offset} has {len} bytes, the field holds at most {max}")]
    StringTooLong {
        /// Offset of the length.
        offset: usize,
        /// Its length in bytes (without NUL).
        len: usize,
        /// The field's capacity.
        max: usize,
    },
    /// One part of a larger message (a snapshot chunk), which the writer
    /// joins with the others before encoding; it has no CDR form alone.
    #[error("a snapshot chunk has no CDR form alone (the writer joins the chunks)")]
    NotAMessage,
    /// A sequence has more elements than the field holds.
    #[error("sequence at byte {offset} has {count} elements, the field holds at most {max}")]
    SequenceTooLong {
        /// Offset of the count.
        offset: usize,
        /// The count.
        count: usize,
        /// The field's capacity.
        max: usize,
    },
    /// A bool is neither 0 nor 1.
    #[error("bool at byte {offset} is {value}, not 0 or 1")]
    BadBool {
        /// Offset of the byte.
        offset: usize,
        /// Its value.
        value: u8,
    },
    /// A field holds a value outside its documented set.
    #[error("field {field} = {value} is not a known value")]
    BadValue {
        /// The field.
        field: &'static str,
        /// Its value.
        value: i64,
    },
    /// A joint state does not name a joint the message needs.
    #[error("the joint state has no joint named {name}")]
    MissingJoint {
        /// The joint's name.
        name: &'static str,
    },
    /// A `builtin_interfaces/Time` is not a non-negative time below 2^64 ns, or
    /// its nanosec is 1e9 or more.
    #[error("time {sec} s {nanosec} ns is not a monotonic stamp in u64 ns")]
    BadTime {
        /// Seconds.
        sec: i32,
        /// Nanoseconds.
        nanosec: u32,
    },
    /// A time stamp in ns does not fit `builtin_interfaces/Time` (i32 seconds).
    #[error("stamp {stamp_ns} ns does not fit an int32 of seconds")]
    StampTooLarge {
        /// The stamp.
        stamp_ns: u64,
    },
}

/// Appends CDR to a byte vector; starts with the encapsulation header.
#[derive(Debug)]
pub struct CdrWriter<'a> {
    buf: &'a mut Vec<u8>,
}

impl<'a> CdrWriter<'a> {
    /// Clears `buf` and writes the encapsulation header. `buf` keeps its capacity,
    /// so a reused buffer does not allocate once it has grown to a message's size.
    pub fn new(buf: &'a mut Vec<u8>) -> Self {
        buf.clear();
        buf.extend_from_slice(&ENCAPSULATION_LE);
        Self { buf }
    }

    fn align(&mut self, n: usize) {
        let pos = self.buf.len() - ENCAPSULATION_LE.len();
        let pad = (n - pos % n) % n;
        for _ in 0..pad {
            self.buf.push(0);
        }
    }

    /// A u8.
    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }
    /// An i8.
    pub fn i8(&mut self, v: i8) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    /// A bool (one byte, 0 or 1).
    pub fn bool(&mut self, v: bool) {
        self.buf.push(u8::from(v));
    }
    /// A u16, aligned to 2.
    pub fn u16(&mut self, v: u16) {
        self.align(2);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    /// A u32, aligned to 4.
    pub fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    /// An i32, aligned to 4.
    pub fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    /// An f32, aligned to 4.
    pub fn f32(&mut self, v: f32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    /// A u64, aligned to 8.
    pub fn u64(&mut self, v: u64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    /// An f64, aligned to 8.
    pub fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    /// A fixed array of f64 (no count).
    pub fn f64_array(&mut self, v: &[f64]) {
        for x in v {
            self.f64(*x);
        }
    }
    /// A sequence of f64 (u32 count, elements).
    pub fn f64_seq(&mut self, v: &[f64]) {
        self.seq_len(v.len());
        self.f64_array(v);
    }
    /// A sequence of bytes (`uint8[]`: u32 count, bytes).
    pub fn byte_seq(&mut self, v: &[u8]) {
        self.seq_len(v.len());
        self.buf.extend_from_slice(v);
    }
    /// A sequence's count.
    pub fn seq_len(&mut self, n: usize) {
        self.u32(u32::try_from(n).unwrap_or(u32::MAX));
    }
    /// A string (u32 length with NUL, bytes, NUL).
    pub fn string(&mut self, s: &str) {
        self.u32(u32::try_from(s.len() + 1).unwrap_or(u32::MAX));
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }
    /// A `builtin_interfaces/Time` from ns (i32 sec, u32 nanosec).
    pub fn time(&mut self, stamp_ns: u64) -> Result<(), CdrError> {
        let sec = i32::try_from(stamp_ns / 1_000_000_000)
            .map_err(|_| CdrError::StampTooLarge { stamp_ns })?;
        // < 1e9, fits a u32.
        let nanosec = (stamp_ns % 1_000_000_000) as u32;
        self.i32(sec);
        self.u32(nanosec);
        Ok(())
    }
}

/// Reads CDR from a byte slice, header first.
#[derive(Debug, Clone)]
pub struct CdrReader<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> CdrReader<'a> {
    /// Checks the encapsulation header.
    pub fn new(bytes: &'a [u8]) -> Result<Self, CdrError> {
        let (head, data) = bytes
            .split_first_chunk::<4>()
            .ok_or(CdrError::NoHeader { len: bytes.len() })?;
        if *head != ENCAPSULATION_LE {
            return Err(CdrError::BadHeader { found: *head });
        }
        Ok(Self { data, pos: 0 })
    }

    /// Bytes left after the current position.
    pub fn remaining(&self) -> usize {
        self.data.len().saturating_sub(self.pos)
    }

    #[inline(always)]
    fn align(&mut self, n: usize) -> Result<(), CdrError> {
        let pad = (n - self.pos % n) % n;
        self.take(pad).map(|_| ())
    }

    #[inline(always)]
    fn take(&mut self, n: usize) -> Result<&'a [u8], CdrError> {
        let end = self.pos.checked_add(n).ok_or(CdrError::UnexpectedEnd {
            offset: self.pos,
            needed: n,
        })?;
        let s = self
            .data
            .get(self.pos..end)
            .ok_or(CdrError::UnexpectedEnd {
                offset: self.pos,
                needed: n,
            })?;
        self.pos = end;
        Ok(s)
    }

    #[inline(always)]
    fn array<const N: usize>(&mut self) -> Result<[u8; N], CdrError> {
        let offset = self.pos;
        let s = self.take(N)?;
        s.try_into()
            .map_err(|_| CdrError::UnexpectedEnd { offset, needed: N })
    }

    /// A u8.
    #[inline(always)]
    pub fn u8(&mut self) -> Result<u8, CdrError> {
        Ok(u8::from_le_bytes(self.array()?))
    }
    /// An i8.
    #[inline(always)]
    pub fn i8(&mut self) -> Result<i8, CdrError> {
        Ok(i8::from_le_bytes(self.array()?))
    }
    /// A bool, refusing anything but 0 and 1.
    #[inline(always)]
    pub fn bool(&mut self) -> Result<bool, CdrError> {
        let offset = self.pos;
        match self.u8()? {
            0 => Ok(false),
            1 => Ok(true),
            value => Err(CdrError::BadBool { offset, value }),
        }
    }
    /// A u16.
    #[inline(always)]
    pub fn u16(&mut self) -> Result<u16, CdrError> {
        self.align(2)?;
        Ok(u16::from_le_bytes(self.array()?))
    }
    /// A u32.
    #[inline(always)]
    pub fn u32(&mut self) -> Result<u32, CdrError> {
        self.align(4)?;
        Ok(u32::from_le_bytes(self.array()?))
    }
    /// An i32.
    #[inline(always)]
    pub fn i32(&mut self) -> Result<i32, CdrError> {
        self.align(4)?;
        Ok(i32::from_le_bytes(self.array()?))
    }
    /// An f32.
    #[inline(always)]
    pub fn f32(&mut self) -> Result<f32, CdrError> {
        self.align(4)?;
        Ok(f32::from_le_bytes(self.array()?))
    }
    /// A u64.
    #[inline(always)]
    pub fn u64(&mut self) -> Result<u64, CdrError> {
        self.align(8)?;
        Ok(u64::from_le_bytes(self.array()?))
    }
    /// An f64.
    #[inline(always)]
    pub fn f64(&mut self) -> Result<f64, CdrError> {
        self.align(8)?;
        Ok(f64::from_le_bytes(self.array()?))
    }
    /// A fixed array of N f64.
    #[inline(always)]
    pub fn f64_array<const N: usize>(&mut self) -> Result<[f64; N], CdrError> {
        let mut out = [0.0; N];
        // Fast path: aligned once, the N elements in one bounds check (the
        // replay's hot path). A message cut inside the array takes the
        // element-wise path below, for the same error as before.
        let pad = (8 - self.pos % 8) % 8;
        if let Some(bytes) = self
            .data
            .get(self.pos + pad..)
            .and_then(|rest| rest.get(..N * 8))
        {
            for (x, b) in out.iter_mut().zip(bytes.chunks_exact(8)) {
                let mut le = [0u8; 8];
                le.copy_from_slice(b);
                *x = f64::from_le_bytes(le);
            }
            self.pos += pad + N * 8;
            return Ok(out);
        }
        for x in &mut out {
            *x = self.f64()?;
        }
        Ok(out)
    }
    /// A sequence count, refused above `max` (and above what the bytes left
    /// could hold at `min_elem_size` bytes each).
    pub fn seq_len(&mut self, max: usize, min_elem_size: usize) -> Result<usize, CdrError> {
        self.align(4)?;
        let offset = self.pos;
        let count = self.u32()? as usize;
        let fits = count
            .checked_mul(min_elem_size)
            .is_some_and(|n| n <= self.remaining());
        if count > max || !fits {
            return Err(CdrError::SequenceTooLong {
                offset,
                count,
                max: max.min(self.remaining() / min_elem_size.max(1)),
            });
        }
        Ok(count)
    }
    /// A sequence of f64 (at most `max`).
    pub fn f64_seq(&mut self, max: usize) -> Result<Vec<f64>, CdrError> {
        let n = self.seq_len(max, 8)?;
        let mut out = Vec::with_capacity(n);
        for _ in 0..n {
            out.push(self.f64()?);
        }
        Ok(out)
    }
    /// A sequence of bytes (`uint8[]`, at most `max`), borrowed.
    pub fn byte_seq(&mut self, max: usize) -> Result<&'a [u8], CdrError> {
        let n = self.seq_len(max, 1)?;
        self.take(n)
    }
    /// A string, borrowed.
    pub fn str(&mut self) -> Result<&'a str, CdrError> {
        self.align(4)?;
        let offset = self.pos;
        let len = self.u32()? as usize;
        if len == 0 {
            return Err(CdrError::StringWithoutNul { offset });
        }
        let bytes = self.take(len)?;
        let (last, text) = bytes
            .split_last()
            .ok_or(CdrError::StringWithoutNul { offset })?;
        if *last != 0 {
            return Err(CdrError::StringNotTerminated { offset });
        }
        core::str::from_utf8(text).map_err(|_| CdrError::StringNotUtf8 { offset })
    }
    /// A string into a fixed-capacity text.
    pub fn fixed_str<const N: usize>(&mut self) -> Result<FixedStr<N>, CdrError> {
        let offset = self.pos;
        let s = self.str()?;
        FixedStr::new(s).ok_or(CdrError::StringTooLong {
            offset,
            len: s.len(),
            max: N,
        })
    }
    /// Reads a run of fixed-size values with one bounds check: `read` reads
    /// them from a reader over exactly the `len` bytes that start at the next
    /// multiple of `align` (which every alignment in the run divides, so that
    /// the window lays them out as the whole message does). With the window's
    /// positions constant, the reads fold into loads at fixed offsets.
    ///
    /// `None`, with nothing consumed, when fewer bytes are left or `read`
    /// fails: the caller then reads value by value, for the error at its
    /// offset in the message.
    #[inline]
    pub fn fixed_run<T>(
        &mut self,
        align: usize,
        len: usize,
        read: impl FnOnce(&mut CdrReader<'a>) -> Result<T, CdrError>,
    ) -> Option<T> {
        let align = align.max(1);
        let start = self.pos.checked_add((align - self.pos % align) % align)?;
        let data = self.data.get(start..)?.get(..len)?;
        let mut window = CdrReader { data, pos: 0 };
        let value = read(&mut window).ok()?;
        self.pos = start + window.pos;
        Some(value)
    }
    /// A `builtin_interfaces/Time` as u64 ns.
    pub fn time(&mut self) -> Result<u64, CdrError> {
        let sec = self.i32()?;
        let nanosec = self.u32()?;
        if sec < 0 || nanosec >= 1_000_000_000 {
            return Err(CdrError::BadTime { sec, nanosec });
        }
        // sec < 2^31: the product fits a u64.
        Ok(sec.unsigned_abs() as u64 * 1_000_000_000 + u64::from(nanosec))
    }
}

/// The alignment and size in bytes of a fixed-size CDR value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FixedLayout {
    /// Its alignment, bytes (a power of two).
    pub align: usize,
    /// Its size, bytes.
    pub size: usize,
}

impl FixedLayout {
    /// The alignment and length of `fields` laid out one after the other
    /// from a multiple of the first one's alignment: `None` unless every
    /// field is fixed-size and aligned to a divisor of the first one's
    /// alignment (then the run's layout is the same wherever it starts).
    pub const fn run(fields: &[Option<FixedLayout>]) -> Option<FixedLayout> {
        let Some((Some(first), _)) = fields.split_first() else {
            return None;
        };
        let mut end: usize = 0;
        let mut rest = fields;
        while let Some((field, tail)) = rest.split_first() {
            let Some(f) = field else {
                return None;
            };
            if f.align == 0 || f.align > first.align || first.align % f.align != 0 {
                return None;
            }
            end = end.next_multiple_of(f.align) + f.size;
            rest = tail;
        }
        Some(FixedLayout {
            align: first.align,
            size: end,
        })
    }
}

/// One field of a message: its `.msg` type and how its value is written and
/// read.
pub trait CdrField: Sized {
    /// The `.msg` type (`uint64`, `float64`, `string`), without an array's
    /// length.
    const ROS_TYPE: &'static str;
    /// The length of a fixed array (`float64[3]`), `None` for one value.
    const ARRAY_LEN: Option<usize> = None;
    /// The layout of a fixed-size value, `None` for a string.
    const LAYOUT: Option<FixedLayout>;
    /// Writes the value.
    fn write(&self, w: &mut CdrWriter<'_>);
    /// Reads a value.
    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError>;
}

macro_rules! primitive_field {
    ($($t:ident, $ros:literal;)*) => {$(
        impl CdrField for $t {
            const ROS_TYPE: &'static str = $ros;
            const LAYOUT: Option<FixedLayout> = Some(FixedLayout {
                align: core::mem::size_of::<$t>(),
                size: core::mem::size_of::<$t>(),
            });
            #[inline]
            fn write(&self, w: &mut CdrWriter<'_>) {
                w.$t(*self);
            }
            #[inline(always)]
            fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
                r.$t()
            }
        }
    )*};
}

primitive_field! {
    u8, "uint8";
    i8, "int8";
    bool, "bool";
    u16, "uint16";
    u32, "uint32";
    i32, "int32";
    u64, "uint64";
    f64, "float64";
}

impl<const N: usize> CdrField for [f64; N] {
    const ROS_TYPE: &'static str = "float64";
    const ARRAY_LEN: Option<usize> = Some(N);
    const LAYOUT: Option<FixedLayout> = Some(FixedLayout {
        align: 8,
        size: 8 * N,
    });
    #[inline]
    fn write(&self, w: &mut CdrWriter<'_>) {
        w.f64_array(self);
    }
    #[inline(always)]
    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        r.f64_array()
    }
}

impl<const N: usize> CdrField for FixedStr<N> {
    const ROS_TYPE: &'static str = "string";
    const LAYOUT: Option<FixedLayout> = None;
    #[inline]
    fn write(&self, w: &mut CdrWriter<'_>) {
        w.string(self.as_str());
    }
    #[inline]
    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        r.fixed_str()
    }
}

/// A UTF-8 text of at most N bytes held inline (Copy, no allocation): frame ids
/// and reason texts of the fixed-size messages.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct FixedStr<const N: usize> {
    len: usize,
    bytes: [u8; N],
}

impl<const N: usize> FixedStr<N> {
    /// The empty text.
    pub const EMPTY: Self = Self {
        len: 0,
        bytes: [0; N],
    };

    /// `s` if it fits, else `None`.
    pub fn new(s: &str) -> Option<Self> {
        let mut out = Self::EMPTY;
        let dst = out.bytes.get_mut(..s.len())?;
        dst.copy_from_slice(s.as_bytes());
        out.len = s.len();
        Some(out)
    }

    /// `s` cut at the last character boundary that fits N bytes.
    pub fn truncating(s: &str) -> Self {
        let mut end = s.len().min(N);
        while !s.is_char_boundary(end) {
            end -= 1;
        }
        Self::new(s.get(..end).unwrap_or("")).unwrap_or(Self::EMPTY)
    }

    /// The text.
    pub fn as_str(&self) -> &str {
        self.bytes
            .get(..self.len)
            .and_then(|b| core::str::from_utf8(b).ok())
            .unwrap_or("")
    }
}

impl<const N: usize> Default for FixedStr<N> {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl<const N: usize> core::fmt::Debug for FixedStr<N> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        core::fmt::Debug::fmt(self.as_str(), f)
    }
}

impl<const N: usize> core::fmt::Display for FixedStr<N> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Appends, cutting at the capacity (at a character boundary): `write!` a
/// `Display` into it without allocating.
impl<const N: usize> core::fmt::Write for FixedStr<N> {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        let room = N - self.len;
        let mut end = s.len().min(room);
        while !s.is_char_boundary(end) {
            end -= 1;
        }
        let src = s.get(..end).unwrap_or("");
        if let Some(dst) = self.bytes.get_mut(self.len..self.len + end) {
            dst.copy_from_slice(src.as_bytes());
            self.len += end;
        }
        Ok(())
    }
}
