//! The configuration fingerprint: an explicit, layout-independent hash of
//! the configuration a snapshot was taken under (issue 18). No allocation.
//!
//! Every configuration type implements [`ConfigHash`], by hand for the
//! primitives, arrays, tuples, `Option` and nalgebra's `Vector3`/`Matrix3`
//! (here), and through [`config_struct!`](crate::config_struct) / [`config_enum!`](crate::config_enum) for the
//! project's own types, beside the type. The macros list **every** field
//! (they destructure `Self` without `..`, so a field added later does not
//! compile until it is listed) and hash each field's name and value.
//!
//! The hashed sequence is a stream of items, each a one-byte marker and its
//! content (integers little-endian), fed to FNV-1a (64 bits):
//!
//! | item | bytes |
//! |------|-------|
//! | field name | `N`, length (u64), UTF-8 |
//! | enum variant (its name is the tag) | `V`, length (u64), UTF-8 |
//! | `f64` | `F`, its bits (u64): `-0.0` is not `0.0`, a NaN's payload counts |
//! | unsigned integer (any width) | `U`, the value as u64 |
//! | signed integer (any width) | `I`, the value as i64 |
//! | `bool` | `B`, 0 or 1 |
//! | `Option` | `O`, 0 (None) or 1 (Some, then the value) |
//! | array, tuple, `Vector3`, `Matrix3` | `A`, element count (u64), then the elements (a matrix column-major) |
//!
//! A struct made by [`config_struct!`](crate::config_struct) is **transparent**: as a field, it
//! hashes its own fields (names and values) and not its name, so wrapping
//! fields in a nested struct (or unwrapping them) does not change the
//! sequence, as long as their names and order stay. An enum made by
//! [`config_enum!`](crate::config_enum) hashes, as a field, the field's name, the variant's name
//! and the variant's fields. A part of the decision state
//! ([`crate::SnapState`], [`crate::snap_state!`]) hashes its `config` fields
//! in their listed order, then its nested parts' (an optional part: `O` and
//! its tag first); a part's type name is not hashed.
//!
//! So a fingerprint changes with:
//! - any configuration value (bit for bit, `f64` included);
//! - a field's or a variant's name, the order of fields in a macro's list,
//!   a field added or removed, an `Option` becoming `Some` or `None`, an
//!   array's length, the order of the nested parts;
//! - the kind of a number (`f64` against integer, signed against unsigned).
//!
//! And does not change with:
//! - `Debug` text (derived or hand-written), derives, the struct's field
//!   order in its declaration (the macro's list decides), visibility, types'
//!   names, the width of an integer;
//! - fields wrapped in (or taken out of) a nested [`config_struct!`](crate::config_struct) struct
//!   with the same names in the same order (e.g. the six force limits as
//!   `ForceLimits` inside the guard's limits).
//!
//! Any change of what this module hashes changes every fingerprint, which
//! refuses every snapshot of every existing recording: raise
//! [`crate::VERSION`] then, so that they are refused as another format
//! rather than as another configuration.

use nalgebra::{Matrix3, Vector3};

/// FNV-1a (64 bits) over the item stream of the module documentation. No
/// allocation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Fingerprint(u64);

impl Default for Fingerprint {
    fn default() -> Self {
        Self::new()
    }
}

impl Fingerprint {
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;

    /// The empty hash.
    pub const fn new() -> Self {
        Self(Self::OFFSET)
    }

    /// Mixes in raw bytes. Private: every item of the stream goes through a
    /// typed method with its marker, so that no caller can hash bytes the
    /// documented table does not describe.
    fn bytes(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.0 ^= u64::from(*b);
            self.0 = self.0.wrapping_mul(Self::PRIME);
        }
    }

    fn text(&mut self, marker: u8, text: &str) {
        self.bytes(&[marker]);
        self.bytes(&(text.len() as u64).to_le_bytes());
        self.bytes(text.as_bytes());
    }

    /// A field's name (`N`).
    pub fn name(&mut self, name: &str) {
        self.text(b'N', name);
    }

    /// An enum variant's name, its tag (`V`).
    pub fn variant(&mut self, name: &str) {
        self.text(b'V', name);
    }

    /// An `f64`, as its bits (`F`).
    pub fn f64(&mut self, v: f64) {
        self.bytes(b"F");
        self.bytes(&v.to_bits().to_le_bytes());
    }

    /// An unsigned integer (`U`).
    pub fn unsigned(&mut self, v: u64) {
        self.bytes(b"U");
        self.bytes(&v.to_le_bytes());
    }

    /// A signed integer (`I`).
    pub fn signed(&mut self, v: i64) {
        self.bytes(b"I");
        self.bytes(&v.to_le_bytes());
    }

    /// A bool (`B`).
    pub fn bool(&mut self, v: bool) {
        self.bytes(&[b'B', u8::from(v)]);
    }

    /// An `Option`'s tag (`O`): whether a value follows.
    pub fn option(&mut self, some: bool) {
        self.bytes(&[b'O', u8::from(some)]);
    }

    /// A sequence's element count (`A`); the elements follow.
    pub fn sequence(&mut self, count: usize) {
        self.bytes(b"A");
        self.bytes(&(count as u64).to_le_bytes());
    }

    /// The hash.
    pub fn value(&self) -> u64 {
        self.0
    }
}

/// A configuration value hashed into the fingerprint explicitly (see the
/// module documentation), never through its `Debug` text.
pub trait ConfigHash {
    /// Mixes in the value alone.
    fn hash_value(&self, h: &mut Fingerprint);

    /// Mixes in the value as the field `name`: the name, then the value. A
    /// struct made by [`config_struct!`](crate::config_struct) overrides it to be transparent (its
    /// fields only).
    fn hash_field(&self, name: &str, h: &mut Fingerprint) {
        h.name(name);
        self.hash_value(h);
    }
}

macro_rules! config_unsigned {
    ($($t:ty),*) => {$(
        impl ConfigHash for $t {
            fn hash_value(&self, h: &mut Fingerprint) {
                h.unsigned(u64::from(*self));
            }
        }
    )*};
}
config_unsigned!(u8, u16, u32, u64);

impl ConfigHash for usize {
    fn hash_value(&self, h: &mut Fingerprint) {
        // usize is at most 64 bits on every target this builds for.
        h.unsigned(*self as u64);
    }
}

macro_rules! config_signed {
    ($($t:ty),*) => {$(
        impl ConfigHash for $t {
            fn hash_value(&self, h: &mut Fingerprint) {
                h.signed(i64::from(*self));
            }
        }
    )*};
}
config_signed!(i8, i16, i32, i64);

impl ConfigHash for f64 {
    fn hash_value(&self, h: &mut Fingerprint) {
        h.f64(*self);
    }
}

impl ConfigHash for bool {
    fn hash_value(&self, h: &mut Fingerprint) {
        h.bool(*self);
    }
}

impl<T: ConfigHash> ConfigHash for Option<T> {
    fn hash_value(&self, h: &mut Fingerprint) {
        h.option(self.is_some());
        if let Some(v) = self {
            v.hash_value(h);
        }
    }
}

impl<T: ConfigHash, const N: usize> ConfigHash for [T; N] {
    fn hash_value(&self, h: &mut Fingerprint) {
        h.sequence(N);
        for v in self {
            v.hash_value(h);
        }
    }
}

impl<A: ConfigHash, B: ConfigHash> ConfigHash for (A, B) {
    fn hash_value(&self, h: &mut Fingerprint) {
        h.sequence(2);
        self.0.hash_value(h);
        self.1.hash_value(h);
    }
}

impl ConfigHash for Vector3<f64> {
    fn hash_value(&self, h: &mut Fingerprint) {
        h.sequence(3);
        for v in self.iter() {
            h.f64(*v);
        }
    }
}

impl ConfigHash for Matrix3<f64> {
    fn hash_value(&self, h: &mut Fingerprint) {
        // Column-major, nalgebra's storage order.
        h.sequence(9);
        for v in self.iter() {
            h.f64(*v);
        }
    }
}

/// Implements [`ConfigHash`] for a configuration struct: every field listed
/// (a missing one fails to compile), each hashed as its name and value, in
/// the listed order. Transparent as a field (see the module documentation).
///
/// `config_struct!(FilterConfig { cutoff_hz, sample_period_s });`
#[macro_export]
macro_rules! config_struct {
    ($t:ty { $($f:ident),* $(,)? }) => {
        impl $crate::ConfigHash for $t {
            fn hash_value(&self, h: &mut $crate::Fingerprint) {
                let Self { $($f),* } = self;
                $( $crate::ConfigHash::hash_field($f, stringify!($f), h); )*
            }
            fn hash_field(&self, _name: &str, h: &mut $crate::Fingerprint) {
                $crate::ConfigHash::hash_value(self, h);
            }
        }
    };
}

/// Implements [`ConfigHash`] for a configuration enum whose variants are
/// units or have named fields: the variant's name (its tag), then its
/// fields' names and values. Lists every variant (the `match` is
/// exhaustive) and every field.
///
/// `config_enum!(FrozenCheck { On { repeats }, Off });`
#[macro_export]
macro_rules! config_enum {
    ($t:ty { $($v:ident $({ $($f:ident),* $(,)? })?),* $(,)? }) => {
        impl $crate::ConfigHash for $t {
            fn hash_value(&self, h: &mut $crate::Fingerprint) {
                match self {
                    $( Self::$v $({ $($f),* })? => {
                        h.variant(stringify!($v));
                        $($( $crate::ConfigHash::hash_field($f, stringify!($f), h); )*)?
                    } )*
                }
            }
        }
    };
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]
    extern crate std;
    use super::*;
    use core::fmt;
    use std::format;

    fn of<T: ConfigHash>(v: &T) -> u64 {
        let mut h = Fingerprint::new();
        v.hash_field("root", &mut h);
        h.value()
    }

    /// The six limits alone.
    #[derive(Debug, Clone, Copy, PartialEq)]
    struct Six {
        warn_n: f64,
        stop_n: f64,
    }
    config_struct!(Six { warn_n, stop_n });

    /// The limits flat, beside the rest.
    #[derive(Debug, Clone, Copy, PartialEq)]
    struct Flat {
        warn_n: f64,
        stop_n: f64,
        debounce_samples: u32,
        mode: Mode,
    }
    config_struct!(Flat {
        warn_n,
        stop_n,
        debounce_samples,
        mode
    });

    /// The same, the limits nested.
    #[derive(Debug, Clone, Copy, PartialEq)]
    struct Nested {
        force: Six,
        debounce_samples: u32,
        mode: Mode,
    }
    config_struct!(Nested {
        force,
        debounce_samples,
        mode
    });

    /// The same fields, listed in another order.
    #[derive(Debug, Clone, Copy, PartialEq)]
    struct Reordered {
        warn_n: f64,
        stop_n: f64,
        debounce_samples: u32,
        mode: Mode,
    }
    config_struct!(Reordered {
        stop_n,
        warn_n,
        debounce_samples,
        mode
    });

    /// One field renamed.
    #[derive(Debug, Clone, Copy, PartialEq)]
    struct Renamed {
        warn_n: f64,
        stop_limit_n: f64,
        debounce_samples: u32,
        mode: Mode,
    }
    config_struct!(Renamed {
        warn_n,
        stop_limit_n,
        debounce_samples,
        mode
    });

    #[derive(Clone, Copy, PartialEq)]
    enum Mode {
        Off,
        On { repeats: u32, gain: Option<f64> },
    }
    config_enum!(Mode {
        Off,
        On { repeats, gain }
    });

    /// A `Debug` that prints nothing of the value, and one that prints
    /// everything differently: neither may matter.
    impl fmt::Debug for Mode {
        fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            f.write_str("a mode")
        }
    }

    #[derive(Clone, Copy, PartialEq)]
    struct LoudFlat(Flat);
    impl fmt::Debug for LoudFlat {
        fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            write!(f, "LOUD {:e} {:e}", self.0.warn_n, self.0.stop_n)
        }
    }
    impl ConfigHash for LoudFlat {
        fn hash_value(&self, h: &mut Fingerprint) {
            self.0.hash_value(h);
        }
        fn hash_field(&self, name: &str, h: &mut Fingerprint) {
            self.0.hash_field(name, h);
        }
    }

    const MODE: Mode = Mode::On {
        repeats: 3,
        gain: Some(0.5),
    };
    const FLAT: Flat = Flat {
        warn_n: 5.0,
        stop_n: 10.0,
        debounce_samples: 4,
        mode: MODE,
    };

    #[test]
    fn the_stream_is_the_documented_one() {
        // Flat { warn_n: 5, stop_n: 10, debounce_samples: 4, mode: On {
        // repeats: 3, gain: Some(0.5) } }, item by item.
        let mut expected = Fingerprint::new();
        for (name, v) in [("warn_n", 5.0f64), ("stop_n", 10.0)] {
            expected.bytes(b"N");
            expected.bytes(&(name.len() as u64).to_le_bytes());
            expected.bytes(name.as_bytes());
            expected.bytes(b"F");
            expected.bytes(&v.to_bits().to_le_bytes());
        }
        expected.bytes(b"N\x10\0\0\0\0\0\0\0debounce_samplesU\x04\0\0\0\0\0\0\0");
        expected.bytes(b"N\x04\0\0\0\0\0\0\0mode");
        expected.bytes(b"V\x02\0\0\0\0\0\0\0On");
        expected.bytes(b"N\x07\0\0\0\0\0\0\0repeatsU\x03\0\0\0\0\0\0\0");
        expected.bytes(b"N\x04\0\0\0\0\0\0\0gainO\x01F");
        expected.bytes(&0.5f64.to_bits().to_le_bytes());
        assert_eq!(of(&FLAT), expected.value());
        // FNV-1a's own check value: "a" from the offset basis.
        let mut a = Fingerprint::new();
        a.bytes(b"a");
        assert_eq!(a.value(), 0xaf63_dc4c_8601_ec8c);
    }

    #[test]
    fn debug_text_does_not_matter() {
        assert_ne!(format!("{:?}", LoudFlat(FLAT)), format!("{FLAT:?}"));
        assert_eq!(of(&LoudFlat(FLAT)), of(&FLAT));
        // Two modes that print alike still hash apart.
        assert_eq!(format!("{:?}", Mode::Off), format!("{MODE:?}"));
        assert_ne!(of(&Mode::Off), of(&MODE));
    }

    #[test]
    fn every_value_changes_it() {
        let base = of(&FLAT);
        let changed = [
            Flat {
                warn_n: 5.000_000_000_000_001,
                ..FLAT
            },
            Flat {
                stop_n: -10.0,
                ..FLAT
            },
            Flat {
                debounce_samples: 5,
                ..FLAT
            },
            Flat {
                mode: Mode::Off,
                ..FLAT
            },
            Flat {
                mode: Mode::On {
                    repeats: 3,
                    gain: None,
                },
                ..FLAT
            },
            Flat {
                mode: Mode::On {
                    repeats: 2,
                    gain: Some(0.5),
                },
                ..FLAT
            },
        ];
        for c in changed {
            assert_ne!(of(&c), base, "{c:?}");
        }
        // Bits, not values: -0.0 is not 0.0.
        assert_ne!(of(&0.0f64), of(&-0.0f64));
    }

    #[test]
    fn a_name_or_the_order_changes_it() {
        let Flat {
            warn_n,
            stop_n,
            debounce_samples,
            mode,
        } = FLAT;
        let renamed = Renamed {
            warn_n,
            stop_limit_n: stop_n,
            debounce_samples,
            mode,
        };
        assert_ne!(of(&renamed), of(&FLAT));
        let reordered = Reordered {
            warn_n,
            stop_n,
            debounce_samples,
            mode,
        };
        assert_ne!(of(&reordered), of(&FLAT));
        // Swapped values in the same fields: another configuration.
        assert_ne!(
            of(&Flat {
                warn_n: stop_n,
                stop_n: warn_n,
                ..FLAT
            }),
            of(&FLAT)
        );
    }

    #[test]
    fn nesting_a_struct_is_transparent() {
        let nested = Nested {
            force: Six {
                warn_n: FLAT.warn_n,
                stop_n: FLAT.stop_n,
            },
            debounce_samples: FLAT.debounce_samples,
            mode: FLAT.mode,
        };
        assert_eq!(of(&nested), of(&FLAT));
        // As a field name too: the struct's own name is not hashed.
        let mut h = Fingerprint::new();
        nested.force.hash_field("anything", &mut h);
        let mut g = Fingerprint::new();
        nested.force.hash_value(&mut g);
        assert_eq!(h, g);
    }

    #[test]
    fn integer_width_does_not_matter_but_kind_does() {
        assert_eq!(of(&3u8), of(&3u64));
        assert_eq!(of(&-3i32), of(&-3i64));
        assert_ne!(of(&3u32), of(&3i32));
        assert_ne!(of(&1u64), of(&f64::from_bits(1)));
        assert_ne!(of(&true), of(&1u8));
        assert_ne!(of(&[1.0f64, 2.0]), of(&[1.0f64, 2.0, 0.0]));
        let v = Vector3::new(1.0, 2.0, 3.0);
        assert_eq!(of(&v), of(&[1.0f64, 2.0, 3.0]));
        let m = Matrix3::new(1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0);
        assert_ne!(of(&m), of(&m.transpose()));
    }
}
