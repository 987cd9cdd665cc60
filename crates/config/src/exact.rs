//! Arrays of an exact length in the files: serde's `[T; N]` reads the first
//! N elements of a TOML array and ignores the rest, so `support = [0.45,
//! 0.2, 0.0, 7.0]` or a 4-row rotation would pass silently. Every
//! fixed-length array of a configuration or scenario file is read through
//! these functions (`#[serde(deserialize_with = "...")]`): fewer or more
//! elements are refused with serde's wording, "invalid length 4, expected an
//! array of length 3" (the extra elements are counted, never stored).

use serde::de::{Deserialize, Deserializer, Error, IgnoredAny, SeqAccess, Visitor};
use std::marker::PhantomData;

/// An array of exactly N elements (what the configuration's keys of a
/// fixed length read, `crate::decl::KeyType`).
#[derive(Debug)]
pub(crate) struct Exact<T, const N: usize>(pub(crate) [T; N]);

struct ExactVisitor<T, const N: usize>(PhantomData<T>);

impl<'de, T: Deserialize<'de>, const N: usize> Visitor<'de> for ExactVisitor<T, N> {
    type Value = Exact<T, N>;

    fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "an array of length {N}")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let mut items = Vec::with_capacity(N);
        while items.len() < N {
            match seq.next_element::<T>()? {
                Some(x) => items.push(x),
                None => return Err(A::Error::invalid_length(items.len(), &self)),
            }
        }
        let mut extra = 0usize;
        while seq.next_element::<IgnoredAny>()?.is_some() {
            extra = extra.saturating_add(1);
        }
        if extra > 0 {
            return Err(A::Error::invalid_length(N.saturating_add(extra), &self));
        }
        let len = items.len();
        items
            .try_into()
            .map(Exact)
            .map_err(|_| A::Error::invalid_length(len, &self))
    }
}

impl<'de, T: Deserialize<'de>, const N: usize> Deserialize<'de> for Exact<T, N> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_seq(ExactVisitor(PhantomData))
    }
}

/// `[T; N]`, exactly N elements.
pub(crate) fn array<'de, D, T, const N: usize>(d: D) -> Result<[T; N], D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    Exact::<T, N>::deserialize(d).map(|e| e.0)
}

/// `[[T; M]; N]`, exactly N rows of exactly M elements.
pub(crate) fn rows<'de, D, T, const N: usize, const M: usize>(d: D) -> Result<[[T; M]; N], D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    Exact::<Exact<T, M>, N>::deserialize(d).map(|e| e.0.map(|row| row.0))
}

/// An optional `[T; N]` (with `#[serde(default)]`).
pub(crate) fn option_array<'de, D, T, const N: usize>(d: D) -> Result<Option<[T; N]>, D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    array(d).map(Some)
}

/// An optional `[[T; M]; N]` (with `#[serde(default)]`).
pub(crate) fn option_rows<'de, D, T, const N: usize, const M: usize>(
    d: D,
) -> Result<Option<[[T; M]; N]>, D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    rows(d).map(Some)
}
