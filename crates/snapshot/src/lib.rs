//! Exact snapshots of the loop's decision state (issue 17): the format, the
//! two traits every part of that state implements, and the macros that
//! implement them from a field list.
//!
//! A snapshot is a plain fixed-size value ([`Snapshot`], [`CAPACITY`] bytes)
//! written and read without allocation, so the loop can take one between two
//! cycles. Restoring it into a step built from the same configuration makes
//! that step decide, from the next cycle on, exactly what the original
//! decided: every `f64` is stored as its bits.
//!
//! Layout (little-endian):
//!
//! | bytes | field |
//! |-------|-------|
//! | 8 | magic `SARSNAP\0` |
//! | 2 | format version ([`VERSION`]) |
//! | 2 | kind: what the snapshot is of (the caller's number) |
//! | 4 | body length, bytes |
//! | 8 | fingerprint of the configuration the state was taken under |
//! | n | body: the state's fields, in declaration order |
//! | 4 | CRC-32 (IEEE) of everything before it |
//!
//! Invariants:
//! - Every struct that takes part lists **every** field in its macro call
//!   ([`snap_struct!`], [`snap_state!`]): the macros destructure `Self`
//!   without `..`, so a field added later fails to compile until it is
//!   placed in `state`, `nested`, `config` or `output`.
//! - `config` fields are not stored: they come from the configuration the
//!   step is built from, and their names and values are hashed into the
//!   fingerprint ([`ConfigHash`]; never their `Debug` text: what changes a
//!   fingerprint and what does not is the [`fingerprint`](mod@fingerprint)
//!   module's documentation), so a snapshot is refused by a step built
//!   differently.
//! - `output` fields are rewritten by every cycle before they are read (the
//!   last cycle's result); they are neither stored nor fingerprinted.
//! - A snapshot is never trusted on its face: magic, version, kind, length,
//!   checksum, every enum tag and bool, and the fingerprint are checked, and
//!   a restore that fails leaves the target unchanged ([`restore`]).
#![no_std]

use core::fmt;

use nalgebra::{Matrix3, Vector3};

pub mod fingerprint;
pub use fingerprint::{ConfigHash, Fingerprint};

/// Bytes in a snapshot at most (header and checksum included): 8192
/// since version 7 (issue 34: the servo model's 8 streamed set points,
/// the servo observer's filters and the inertia and support watches took
/// the loop step's snapshot past half of 4096; a recording stores only
/// the bytes used).
pub const CAPACITY: usize = 8192;

/// The format's version: raise it when the layout of any snapshotted type
/// changes (a field added, removed or reordered), or the meaning of the
/// fingerprint (what [`ConfigHash`] hashes, and how). 1: the fingerprint
/// hashed the configuration's `Debug` text; 2: it hashes the fields'
/// names and values explicitly ([`fingerprint`](mod@fingerprint)); 3: the
/// estimator's tare over a mean at rest (its running mean and the last
/// tare's time) is part of the snapshotted state; 4: the loop's model of
/// the axes' motion (issue 26: the servo model, the drives' quick stop); 5:
/// the clock of the last streamed set point (issue 33: a late cycle delays
/// the streamed trajectory); 6: 8 streamed set points kept, not 4 (issue
/// 34: the servo model's reference delay, `[axes] servo_delay_s`); 7 (issue
/// 34): the servo observer (each axis's filter, the encoders' samples
/// pending, the fit), the inertia watch's window
/// (`sar_estimator::inertia_watch`) and the support watch's sums, slide
/// sign, acknowledged shift and status: an older snapshot is refused by
/// its version, never restored with these guessed.
pub const VERSION: u16 = 7;

/// The first eight bytes of every snapshot.
pub const MAGIC: [u8; 8] = *b"SARSNAP\0";

/// Header bytes before the body.
pub const HEADER_BYTES: usize = 8 + 2 + 2 + 4 + 8;

/// Why a snapshot could not be taken or restored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SnapshotError {
    /// The state does not fit in [`CAPACITY`] bytes.
    #[error("the state needs more than the {capacity} bytes of a snapshot")]
    TooLarge {
        /// [`CAPACITY`].
        capacity: usize,
    },
    /// The bytes end before the snapshot does.
    #[error("the snapshot is truncated: {needed} bytes needed at byte {at}, {len} present")]
    Truncated {
        /// Where the read was.
        at: usize,
        /// How many bytes it needed.
        needed: usize,
        /// How many bytes there are.
        len: usize,
    },
    /// The first bytes are not [`MAGIC`].
    #[error("not a snapshot (its first bytes are not SARSNAP)")]
    BadMagic,
    /// Another format version.
    #[error("snapshot format version {got}; this build reads version {expected}")]
    Version {
        /// The snapshot's version.
        got: u16,
        /// [`VERSION`].
        expected: u16,
    },
    /// A snapshot of something else.
    #[error("snapshot of kind {got}, {expected} expected")]
    Kind {
        /// The snapshot's kind.
        got: u16,
        /// The kind asked for.
        expected: u16,
    },
    /// The header's length does not match the bytes.
    #[error("snapshot length {declared} does not match its {actual} bytes")]
    Length {
        /// Body length in the header plus header and checksum.
        declared: usize,
        /// Bytes given.
        actual: usize,
    },
    /// The checksum does not match: the bytes were changed.
    #[error(
        "snapshot checksum mismatch (stored {stored:#010x}, computed {computed:#010x}): corrupted"
    )]
    Checksum {
        /// The stored CRC-32.
        stored: u32,
        /// The CRC-32 of the bytes.
        computed: u32,
    },
    /// A tag (enum variant, option, bool) with no meaning.
    #[error("invalid {what} tag {value} at byte {at}")]
    BadTag {
        /// The type being read.
        what: &'static str,
        /// The tag.
        value: u8,
        /// Its byte offset in the body.
        at: usize,
    },
    /// The body holds more than the state.
    #[error("{extra} bytes left over after the state")]
    Trailing {
        /// Bytes not read.
        extra: usize,
    },
    /// The state was taken under another configuration.
    #[error(
        "the snapshot was taken under another configuration (fingerprint {snapshot:#018x}, this step's {step:#018x})"
    )]
    ConfigMismatch {
        /// The snapshot's fingerprint.
        snapshot: u64,
        /// The fingerprint of the step it was to be restored into.
        step: u64,
    },
}

/// Writes a snapshot's body into a fixed buffer; remembers an overflow
/// instead of failing at each field (checked once, at the end).
pub struct Writer<'a> {
    buf: &'a mut [u8],
    pos: usize,
    overflow: bool,
}

impl<'a> Writer<'a> {
    /// A writer at the start of `buf`.
    pub fn new(buf: &'a mut [u8]) -> Self {
        Self {
            buf,
            pos: 0,
            overflow: false,
        }
    }

    /// Appends `bytes` (or marks the overflow).
    pub fn put_bytes(&mut self, bytes: &[u8]) {
        let end = self.pos.saturating_add(bytes.len());
        match self.buf.get_mut(self.pos..end) {
            Some(dst) if !self.overflow => {
                dst.copy_from_slice(bytes);
                self.pos = end;
            }
            _ => self.overflow = true,
        }
    }

    /// Appends one byte.
    pub fn put_u8(&mut self, v: u8) {
        self.put_bytes(&[v]);
    }

    /// Bytes written so far.
    pub fn position(&self) -> usize {
        self.pos
    }

    /// Whether a write did not fit.
    pub fn overflowed(&self) -> bool {
        self.overflow
    }
}

/// Reads a snapshot's body; every read is bounds-checked.
pub struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    /// A reader at the start of `buf`.
    pub fn new(buf: &'a [u8]) -> Self {
        Self { buf, pos: 0 }
    }

    /// The next `N` bytes.
    pub fn get_array<const N: usize>(&mut self) -> Result<[u8; N], SnapshotError> {
        let end = self.pos.saturating_add(N);
        let src = self
            .buf
            .get(self.pos..end)
            .ok_or(SnapshotError::Truncated {
                at: self.pos,
                needed: N,
                len: self.buf.len(),
            })?;
        let mut out = [0u8; N];
        out.copy_from_slice(src);
        self.pos = end;
        Ok(out)
    }

    /// The next byte.
    pub fn get_u8(&mut self) -> Result<u8, SnapshotError> {
        let [b] = self.get_array::<1>()?;
        Ok(b)
    }

    /// Where the next read starts.
    pub fn position(&self) -> usize {
        self.pos
    }

    /// Bytes not read yet.
    pub fn remaining(&self) -> usize {
        self.buf.len().saturating_sub(self.pos)
    }
}

/// A value stored whole in a snapshot.
pub trait Snap: Sized {
    /// Writes the value.
    fn put(&self, w: &mut Writer<'_>);
    /// Reads a value written by [`Snap::put`]; checks every tag.
    fn get(r: &mut Reader<'_>) -> Result<Self, SnapshotError>;
}

/// A part of the decision state built from the configuration: only its
/// state is stored; its configuration is fingerprinted.
pub trait SnapState {
    /// Writes the state fields (and the nested parts' state).
    fn put_state(&self, w: &mut Writer<'_>);
    /// Hashes the configuration fields (and the nested parts').
    fn fingerprint_config(&self, h: &mut Fingerprint);
    /// Reads the state written by [`SnapState::put_state`] into `self`. On
    /// an error `self` may be partly overwritten: use [`restore`], which
    /// works on a copy.
    fn load_state(&mut self, r: &mut Reader<'_>) -> Result<(), SnapshotError>;
}

// Indexing in a const fn (no `get_mut` there); `i < 256` by the loop.
#[allow(clippy::indexing_slicing)]
const fn crc32_table() -> [u32; 256] {
    let mut table = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = i as u32;
        let mut k = 0;
        while k < 8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
            k += 1;
        }
        table[i] = c;
        i += 1;
    }
    table
}

// A static, not a const: a const array indexed in a loop may be copied at
// each use.
static CRC32_TABLE: [u32; 256] = crc32_table();

/// CRC-32 (IEEE 802.3, the one of zip and PNG).
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut c = !0u32;
    for b in bytes {
        let i = usize::from((c as u8) ^ *b);
        c = CRC32_TABLE.get(i).copied().unwrap_or(0) ^ (c >> 8);
    }
    !c
}

/// A snapshot: [`CAPACITY`] bytes, of which `len` are used. A plain value
/// (no allocation); [`Snapshot::as_bytes`] is what is recorded.
#[derive(Clone)]
pub struct Snapshot {
    bytes: [u8; CAPACITY],
    len: usize,
}

impl fmt::Debug for Snapshot {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Snapshot")
            .field("len", &self.len)
            .field("kind", &self.kind())
            .field("fingerprint", &self.fingerprint())
            .finish()
    }
}

impl Default for Snapshot {
    fn default() -> Self {
        Self::new()
    }
}

impl Snapshot {
    /// An empty snapshot (no valid content until [`take`] fills it).
    pub const fn new() -> Self {
        Self {
            bytes: [0; CAPACITY],
            len: 0,
        }
    }

    /// The snapshot's bytes (empty before [`take`]).
    pub fn as_bytes(&self) -> &[u8] {
        self.bytes.get(..self.len).unwrap_or(&[])
    }

    /// Its kind (0 when empty).
    pub fn kind(&self) -> u16 {
        u16::from_le_bytes([
            self.bytes.get(10).copied().unwrap_or(0),
            self.bytes.get(11).copied().unwrap_or(0),
        ])
    }

    /// The fingerprint of the configuration it was taken under.
    pub fn fingerprint(&self) -> u64 {
        let mut b = [0u8; 8];
        if let Some(src) = self.bytes.get(16..24) {
            b.copy_from_slice(src);
        }
        u64::from_le_bytes(b)
    }
}

/// The fingerprint of `value`'s configuration.
pub fn fingerprint<T: SnapState>(value: &T) -> u64 {
    let mut h = Fingerprint::new();
    value.fingerprint_config(&mut h);
    h.value()
}

/// Writes `value`'s state into `out` as a snapshot of `kind`. No allocation.
/// Hashes the configuration each time: a caller on a real-time path caches
/// [`fingerprint()`] and uses [`take_with`].
pub fn take<T: SnapState>(value: &T, kind: u16, out: &mut Snapshot) -> Result<(), SnapshotError> {
    take_with(value, kind, fingerprint(value), out)
}

/// [`take`] with `value`'s configuration fingerprint already known (it
/// must be [`fingerprint()`] of `value`, computed once).
pub fn take_with<T: SnapState>(
    value: &T,
    kind: u16,
    fingerprint: u64,
    out: &mut Snapshot,
) -> Result<(), SnapshotError> {
    out.len = 0;
    let (header, rest) = out.bytes.split_at_mut(HEADER_BYTES);
    // The body, leaving four bytes for the checksum.
    let body_room = rest.len().saturating_sub(4);
    let body_len = {
        let mut w = Writer::new(rest.get_mut(..body_room).unwrap_or(&mut []));
        value.put_state(&mut w);
        if w.overflowed() {
            return Err(SnapshotError::TooLarge { capacity: CAPACITY });
        }
        w.position()
    };
    let mut h = Writer::new(header);
    h.put_bytes(&MAGIC);
    h.put_bytes(&VERSION.to_le_bytes());
    h.put_bytes(&kind.to_le_bytes());
    // body_len <= CAPACITY, which fits in u32.
    h.put_bytes(&u32::try_from(body_len).unwrap_or(u32::MAX).to_le_bytes());
    h.put_bytes(&fingerprint.to_le_bytes());
    let end = HEADER_BYTES + body_len;
    let crc = crc32(out.bytes.get(..end).unwrap_or(&[]));
    match out.bytes.get_mut(end..end + 4) {
        Some(dst) => dst.copy_from_slice(&crc.to_le_bytes()),
        None => return Err(SnapshotError::TooLarge { capacity: CAPACITY }),
    }
    out.len = end + 4;
    Ok(())
}

/// Checks `bytes` as a snapshot of `kind` (magic, version, kind, length,
/// checksum) and returns its fingerprint and body.
pub fn open(bytes: &[u8], kind: u16) -> Result<(u64, &[u8]), SnapshotError> {
    let mut r = Reader::new(bytes);
    if r.get_array::<8>()? != MAGIC {
        return Err(SnapshotError::BadMagic);
    }
    let version = u16::from_le_bytes(r.get_array()?);
    if version != VERSION {
        return Err(SnapshotError::Version {
            got: version,
            expected: VERSION,
        });
    }
    let got_kind = u16::from_le_bytes(r.get_array()?);
    let body_len = u32::from_le_bytes(r.get_array()?) as usize;
    let fingerprint = u64::from_le_bytes(r.get_array()?);
    let declared = HEADER_BYTES.saturating_add(body_len).saturating_add(4);
    if declared != bytes.len() {
        return Err(SnapshotError::Length {
            declared,
            actual: bytes.len(),
        });
    }
    let (covered, stored) = bytes.split_at(bytes.len() - 4);
    let mut s = [0u8; 4];
    s.copy_from_slice(stored);
    let stored = u32::from_le_bytes(s);
    let computed = crc32(covered);
    if stored != computed {
        return Err(SnapshotError::Checksum { stored, computed });
    }
    if got_kind != kind {
        return Err(SnapshotError::Kind {
            got: got_kind,
            expected: kind,
        });
    }
    Ok((fingerprint, covered.get(HEADER_BYTES..).unwrap_or(&[])))
}

/// Restores the state in `bytes` (a snapshot of `kind`) into `value`, which
/// must have been built from the same configuration. Works on a copy: on any
/// error `value` is unchanged.
pub fn restore<T: SnapState + Clone>(
    value: &mut T,
    kind: u16,
    bytes: &[u8],
) -> Result<(), SnapshotError> {
    let step_fp = fingerprint(value);
    restore_with(value, kind, step_fp, bytes)
}

/// [`restore`] with `value`'s configuration fingerprint already known.
pub fn restore_with<T: SnapState + Clone>(
    value: &mut T,
    kind: u16,
    step_fp: u64,
    bytes: &[u8],
) -> Result<(), SnapshotError> {
    let (snapshot_fp, body) = open(bytes, kind)?;
    if snapshot_fp != step_fp {
        return Err(SnapshotError::ConfigMismatch {
            snapshot: snapshot_fp,
            step: step_fp,
        });
    }
    let mut next = value.clone();
    let mut r = Reader::new(body);
    next.load_state(&mut r)?;
    if r.remaining() != 0 {
        return Err(SnapshotError::Trailing {
            extra: r.remaining(),
        });
    }
    *value = next;
    Ok(())
}

macro_rules! snap_le {
    ($($t:ty),*) => {$(
        impl Snap for $t {
            fn put(&self, w: &mut Writer<'_>) {
                w.put_bytes(&self.to_le_bytes());
            }
            fn get(r: &mut Reader<'_>) -> Result<Self, SnapshotError> {
                Ok(<$t>::from_le_bytes(r.get_array()?))
            }
        }
    )*};
}
snap_le!(u8, u16, u32, u64, i8, i16, i32, i64);

impl Snap for f64 {
    fn put(&self, w: &mut Writer<'_>) {
        w.put_bytes(&self.to_bits().to_le_bytes());
    }
    fn get(r: &mut Reader<'_>) -> Result<Self, SnapshotError> {
        Ok(f64::from_bits(u64::from_le_bytes(r.get_array()?)))
    }
}

impl Snap for bool {
    fn put(&self, w: &mut Writer<'_>) {
        w.put_u8(u8::from(*self));
    }
    fn get(r: &mut Reader<'_>) -> Result<Self, SnapshotError> {
        let at = r.position();
        match r.get_u8()? {
            0 => Ok(false),
            1 => Ok(true),
            value => Err(SnapshotError::BadTag {
                what: "bool",
                value,
                at,
            }),
        }
    }
}

impl<T: Snap> Snap for Option<T> {
    fn put(&self, w: &mut Writer<'_>) {
        match self {
            None => w.put_u8(0),
            Some(v) => {
                w.put_u8(1);
                v.put(w);
            }
        }
    }
    fn get(r: &mut Reader<'_>) -> Result<Self, SnapshotError> {
        let at = r.position();
        match r.get_u8()? {
            0 => Ok(None),
            1 => Ok(Some(T::get(r)?)),
            value => Err(SnapshotError::BadTag {
                what: "Option",
                value,
                at,
            }),
        }
    }
}

impl<A: Snap, B: Snap> Snap for (A, B) {
    fn put(&self, w: &mut Writer<'_>) {
        self.0.put(w);
        self.1.put(w);
    }
    fn get(r: &mut Reader<'_>) -> Result<Self, SnapshotError> {
        let a = A::get(r)?;
        Ok((a, B::get(r)?))
    }
}

macro_rules! snap_array {
    ($($n:literal: [$($i:ident),*]),*) => {$(
        impl<T: Snap> Snap for [T; $n] {
            fn put(&self, w: &mut Writer<'_>) {
                for v in self {
                    v.put(w);
                }
            }
            fn get(r: &mut Reader<'_>) -> Result<Self, SnapshotError> {
                // Array expressions are evaluated left to right.
                $( let $i = T::get(r)?; )*
                Ok([$($i),*])
            }
        }
    )*};
}
snap_array!(
    2: [a, b],
    3: [a, b, c],
    4: [a, b, c, d],
    6: [a, b, c, d, e, f],
    8: [a, b, c, d, e, f, g, h]
);

impl Snap for Vector3<f64> {
    fn put(&self, w: &mut Writer<'_>) {
        for v in self.iter() {
            v.put(w);
        }
    }
    fn get(r: &mut Reader<'_>) -> Result<Self, SnapshotError> {
        let x = f64::get(r)?;
        let y = f64::get(r)?;
        Ok(Vector3::new(x, y, f64::get(r)?))
    }
}

impl Snap for Matrix3<f64> {
    fn put(&self, w: &mut Writer<'_>) {
        // Column-major, nalgebra's storage order.
        for v in self.iter() {
            v.put(w);
        }
    }
    fn get(r: &mut Reader<'_>) -> Result<Self, SnapshotError> {
        let mut m = Matrix3::zeros();
        for v in m.iter_mut() {
            *v = f64::get(r)?;
        }
        Ok(m)
    }
}

impl<T: SnapState> SnapState for Option<T> {
    fn put_state(&self, w: &mut Writer<'_>) {
        match self {
            None => w.put_u8(0),
            Some(v) => {
                w.put_u8(1);
                v.put_state(w);
            }
        }
    }
    fn fingerprint_config(&self, h: &mut Fingerprint) {
        h.option(self.is_some());
        if let Some(v) = self {
            v.fingerprint_config(h);
        }
    }
    fn load_state(&mut self, r: &mut Reader<'_>) -> Result<(), SnapshotError> {
        // Whether the part exists is configuration (fingerprinted): the tag
        // must agree with `self`.
        let at = r.position();
        match (r.get_u8()?, self) {
            (0, None) => Ok(()),
            (1, Some(v)) => v.load_state(r),
            (value, _) => Err(SnapshotError::BadTag {
                what: "optional part",
                value,
                at,
            }),
        }
    }
}

/// Implements [`Snap`] for a struct stored whole. Lists every field (a
/// missing one fails to compile).
///
/// `snap_struct!(Bias { force_n, torque_nm });`
#[macro_export]
macro_rules! snap_struct {
    ($t:ty { $($f:ident),* $(,)? }) => {
        impl $crate::Snap for $t {
            fn put(&self, w: &mut $crate::Writer<'_>) {
                let Self { $($f),* } = self;
                $( $crate::Snap::put($f, w); )*
            }
            fn get(r: &mut $crate::Reader<'_>) -> Result<Self, $crate::SnapshotError> {
                Ok(Self { $( $f: $crate::Snap::get(r)? ),* })
            }
        }
    };
}

/// Implements [`Snap`] for an enum whose variants are units or have named
/// fields: one tag byte per variant (the literal), then the fields. Lists
/// every variant (the `match` is exhaustive) and every field.
///
/// `snap_enum!(GuardState { 0 => Ok, 1 => Warn, 2 => Stop { why } });`
#[macro_export]
macro_rules! snap_enum {
    ($t:ty { $($tag:literal => $v:ident $({ $($f:ident),* $(,)? })?),* $(,)? }) => {
        impl $crate::Snap for $t {
            fn put(&self, w: &mut $crate::Writer<'_>) {
                match self {
                    $( Self::$v $({ $($f),* })? => {
                        w.put_u8($tag);
                        $($( $crate::Snap::put($f, w); )*)?
                    } )*
                }
            }
            fn get(r: &mut $crate::Reader<'_>) -> Result<Self, $crate::SnapshotError> {
                let at = r.position();
                match r.get_u8()? {
                    $( $tag => Ok(Self::$v $({ $( $f: $crate::Snap::get(r)? ),* })?), )*
                    value => Err($crate::SnapshotError::BadTag {
                        what: stringify!($t),
                        value,
                        at,
                    }),
                }
            }
        }
    };
}

/// Implements [`SnapState`] for a struct built from the configuration. Every
/// field is in exactly one list:
/// - `state`: stored ([`Snap`]);
/// - `nested`: a part with its own [`SnapState`];
/// - `config`: from the configuration, fingerprinted ([`ConfigHash`]: each
///   field's name and value, in the listed order, then the nested parts'),
///   not stored;
/// - `output`: rewritten by every cycle before it is read; neither;
/// - `derived` (optional): computed once from the configuration at
///   construction (e.g. the fingerprint itself, cached); neither.
#[macro_export]
macro_rules! snap_state {
    ($t:ty {
        state: [$($s:ident),* $(,)?],
        nested: [$($n:ident),* $(,)?],
        config: [$($c:ident),* $(,)?],
        output: [$($o:ident),* $(,)?]
        $(, derived: [$($d:ident),* $(,)?])? $(,)?
    }) => {
        impl $crate::SnapState for $t {
            fn put_state(&self, w: &mut $crate::Writer<'_>) {
                let Self { $($s,)* $($n,)* $($c: _,)* $($o: _,)* $($($d: _,)*)? } = self;
                $( $crate::Snap::put($s, w); )*
                $( $crate::SnapState::put_state($n, w); )*
            }
            fn fingerprint_config(&self, h: &mut $crate::Fingerprint) {
                let Self { $($s: _,)* $($n,)* $($c,)* $($o: _,)* $($($d: _,)*)? } = self;
                $( $crate::ConfigHash::hash_field($c, stringify!($c), h); )*
                $( $crate::SnapState::fingerprint_config($n, h); )*
            }
            fn load_state(&mut self, r: &mut $crate::Reader<'_>) -> Result<(), $crate::SnapshotError> {
                let Self { $($s,)* $($n,)* $($c: _,)* $($o: _,)* $($($d: _,)*)? } = self;
                $( *$s = $crate::Snap::get(r)?; )*
                $( $crate::SnapState::load_state($n, r)?; )*
                Ok(())
            }
        }
    };
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]
    use super::*;

    #[derive(Debug, Clone, Copy, PartialEq)]
    enum Mode {
        Idle,
        Push { axial_n: f64, count: u32 },
    }
    snap_enum!(Mode { 0 => Idle, 1 => Push { axial_n, count } });

    #[derive(Debug, Clone, Copy, PartialEq)]
    struct Inner {
        v: Vector3<f64>,
        m: Option<Mode>,
    }
    snap_struct!(Inner { v, m });

    #[derive(Debug, Clone, PartialEq)]
    struct Part {
        gain: f64,
        x: f64,
        inner: Inner,
        last: u64,
    }
    snap_state!(Part {
        state: [x, inner],
        nested: [],
        config: [gain],
        output: [last]
    });

    #[derive(Debug, Clone, PartialEq)]
    struct Whole {
        a: Part,
        b: Option<Part>,
        on: bool,
        arr: [f64; 3],
    }
    snap_state!(Whole {
        state: [on, arr],
        nested: [a, b],
        config: [],
        output: []
    });

    fn whole(gain: f64, x: f64) -> Whole {
        let p = Part {
            gain,
            x,
            inner: Inner {
                v: Vector3::new(1.0, -0.0, f64::NAN),
                m: Some(Mode::Push {
                    axial_n: 3.0,
                    count: 7,
                }),
            },
            last: 9,
        };
        Whole {
            a: p.clone(),
            b: Some(Part { x: -x, ..p }),
            on: true,
            arr: [1e-300, f64::INFINITY, -2.5],
        }
    }

    #[test]
    fn round_trip_is_exact_and_skips_config_and_output() {
        let src = whole(2.0, 0.125);
        let mut snap = Snapshot::new();
        take(&src, 7, &mut snap).unwrap();
        let mut dst = whole(2.0, 99.0);
        dst.a.last = 1;
        dst.on = false;
        restore(&mut dst, 7, snap.as_bytes()).unwrap();
        assert_eq!(dst.a.x.to_bits(), src.a.x.to_bits());
        assert_eq!(dst.b.as_ref().unwrap().x.to_bits(), (-0.125f64).to_bits());
        assert!(dst.a.inner.v.z.is_nan());
        assert_eq!(dst.a.inner.v.y.to_bits(), (-0.0f64).to_bits());
        assert!(dst.on);
        // Output is not restored.
        assert_eq!(dst.a.last, 1);
    }

    #[test]
    fn another_configuration_is_refused_and_the_target_unchanged() {
        let mut snap = Snapshot::new();
        take(&whole(2.0, 1.0), 7, &mut snap).unwrap();
        let mut dst = whole(2.5, 3.0);
        let e = restore(&mut dst, 7, snap.as_bytes()).unwrap_err();
        assert!(matches!(e, SnapshotError::ConfigMismatch { .. }), "{e}");
        assert_eq!((dst.a.x, dst.on), (3.0, true));
        dst.on = false;
        assert!(restore(&mut dst, 7, snap.as_bytes()).is_err());
        assert!(!dst.on);
        // The part's presence is configuration too.
        let mut dst = whole(2.0, 3.0);
        dst.b = None;
        assert!(matches!(
            restore(&mut dst, 7, snap.as_bytes()).unwrap_err(),
            SnapshotError::ConfigMismatch { .. }
        ));
    }

    #[test]
    fn every_corruption_is_refused() {
        let mut snap = Snapshot::new();
        take(&whole(2.0, 1.0), 7, &mut snap).unwrap();
        let good = snap.as_bytes();
        for i in 0..good.len() {
            for bit in 0..8 {
                let mut bad = [0u8; CAPACITY];
                let bad = &mut bad[..good.len()];
                bad.copy_from_slice(good);
                bad[i] ^= 1 << bit;
                let mut dst = whole(2.0, 5.0);
                assert!(restore(&mut dst, 7, bad).is_err(), "byte {i} bit {bit}");
                assert_eq!(dst.a.x, 5.0);
            }
        }
        for len in 0..good.len() {
            let mut dst = whole(2.0, 5.0);
            assert!(restore(&mut dst, 7, &good[..len]).is_err(), "length {len}");
        }
        let mut dst = whole(2.0, 5.0);
        assert_eq!(
            restore(&mut dst, 8, good).unwrap_err(),
            SnapshotError::Kind {
                got: 7,
                expected: 8
            }
        );
    }

    #[test]
    fn a_bad_tag_under_a_good_checksum_is_refused() {
        // A writer bug (or a forged checksum) must still not yield a value.
        let mut snap = Snapshot::new();
        take(&whole(2.0, 1.0), 7, &mut snap).unwrap();
        let mut bytes = [0u8; CAPACITY];
        let n = snap.as_bytes().len();
        bytes[..n].copy_from_slice(snap.as_bytes());
        // Body: on (bool) first.
        bytes[HEADER_BYTES] = 2;
        let crc = crc32(&bytes[..n - 4]);
        bytes[n - 4..n].copy_from_slice(&crc.to_le_bytes());
        let mut dst = whole(2.0, 5.0);
        let e = restore(&mut dst, 7, &bytes[..n]).unwrap_err();
        assert_eq!(
            e,
            SnapshotError::BadTag {
                what: "bool",
                value: 2,
                at: 0
            }
        );
    }

    #[test]
    fn a_version_1_snapshot_is_refused_as_another_format() {
        // Version 1 fingerprinted the configuration's `Debug` text: its
        // fingerprint means something else, so it is refused by version,
        // before its fingerprint or body are looked at, even under a good
        // checksum.
        let mut snap = Snapshot::new();
        take(&whole(2.0, 1.0), 7, &mut snap).unwrap();
        let n = snap.as_bytes().len();
        let mut bytes = [0u8; CAPACITY];
        bytes[..n].copy_from_slice(snap.as_bytes());
        assert_eq!(bytes[8..10], VERSION.to_le_bytes());
        bytes[8..10].copy_from_slice(&1u16.to_le_bytes());
        let crc = crc32(&bytes[..n - 4]);
        bytes[n - 4..n].copy_from_slice(&crc.to_le_bytes());
        let mut dst = whole(2.0, 5.0);
        let e = restore(&mut dst, 7, &bytes[..n]).unwrap_err();
        assert_eq!(
            e,
            SnapshotError::Version {
                got: 1,
                expected: VERSION
            }
        );
        assert_eq!(dst.a.x, 5.0);
        let mut text = Text::default();
        fmt::write(&mut text, format_args!("{e}")).unwrap();
        assert_eq!(
            text.as_str(),
            "snapshot format version 1; this build reads version 7"
        );
    }

    /// A fixed buffer for an error's text (no alloc in this crate).
    struct Text {
        buf: [u8; 128],
        len: usize,
    }
    impl Default for Text {
        fn default() -> Self {
            Self {
                buf: [0; 128],
                len: 0,
            }
        }
    }
    impl Text {
        fn as_str(&self) -> &str {
            core::str::from_utf8(&self.buf[..self.len]).unwrap()
        }
    }
    impl fmt::Write for Text {
        fn write_str(&mut self, s: &str) -> fmt::Result {
            let end = self.len + s.len();
            self.buf
                .get_mut(self.len..end)
                .ok_or(fmt::Error)?
                .copy_from_slice(s.as_bytes());
            self.len = end;
            Ok(())
        }
    }

    #[test]
    fn crc32_matches_the_standard_check_value() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    }
}
