//! The types a key can have (`f64`, `i64`, `bool`, `String`, arrays of an
//! exact length, lists): what serde reads for each, how TOML writes it
//! (`default_config.toml`, the README's table) and the numbers the range
//! check sees.

use serde::de::DeserializeOwned;

/// What kind of value a key's type holds (the declaration's tests match it
/// with the [`Bounds`](super::Bounds)).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Kind {
    /// A number, or an array of numbers.
    Number,
    /// An integer, or a list of integers.
    Integer,
    /// `true` or `false`.
    Switch,
    /// Text, or a list of texts.
    Text,
}

/// One number of a value, as the range check sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Number {
    Float(f64),
    Int(i64),
}

impl Number {
    pub(crate) fn as_f64(self) -> f64 {
        match self {
            Number::Float(v) => v,
            Number::Int(v) => v as f64,
        }
    }
}

/// A type a key can have: what serde reads (`Raw`, fixed-length arrays
/// through `crate::exact`), how it is written in TOML, and its numbers.
pub(crate) trait KeyType: Sized {
    /// What serde reads.
    type Raw: DeserializeOwned;
    /// What kind of value it is.
    const KIND: Kind;
    /// The value read.
    fn from_raw(raw: Self::Raw) -> Self;
    /// As TOML writes it.
    fn render(&self) -> String;
    /// Its numbers, each with its index ("" or "[i]" or "[i][j]").
    fn numbers(&self, _out: &mut Vec<(String, Number)>) {}
    /// Its text, for a [`Bounds::Choice`].
    fn text(&self) -> Option<&str> {
        None
    }
}

impl KeyType for f64 {
    type Raw = f64;
    const KIND: Kind = Kind::Number;
    fn from_raw(raw: f64) -> Self {
        raw
    }
    fn render(&self) -> String {
        format!("{self:?}")
    }
    fn numbers(&self, out: &mut Vec<(String, Number)>) {
        out.push((String::new(), Number::Float(*self)));
    }
}

impl KeyType for i64 {
    type Raw = i64;
    const KIND: Kind = Kind::Integer;
    fn from_raw(raw: i64) -> Self {
        raw
    }
    fn render(&self) -> String {
        format!("{self}")
    }
    fn numbers(&self, out: &mut Vec<(String, Number)>) {
        out.push((String::new(), Number::Int(*self)));
    }
}

impl KeyType for bool {
    type Raw = bool;
    const KIND: Kind = Kind::Switch;
    fn from_raw(raw: bool) -> Self {
        raw
    }
    fn render(&self) -> String {
        format!("{self}")
    }
}

impl KeyType for String {
    type Raw = String;
    const KIND: Kind = Kind::Text;
    fn from_raw(raw: String) -> Self {
        raw
    }
    fn render(&self) -> String {
        format!("{self:?}")
    }
    fn text(&self) -> Option<&str> {
        Some(self)
    }
}

impl<const N: usize> KeyType for [f64; N] {
    type Raw = crate::exact::Exact<f64, N>;
    const KIND: Kind = Kind::Number;
    fn from_raw(raw: Self::Raw) -> Self {
        raw.0
    }
    fn render(&self) -> String {
        list(self.iter().map(KeyType::render))
    }
    fn numbers(&self, out: &mut Vec<(String, Number)>) {
        for (i, v) in self.iter().enumerate() {
            out.push((format!("[{i}]"), Number::Float(*v)));
        }
    }
}

impl<const N: usize, const M: usize> KeyType for [[f64; M]; N] {
    type Raw = crate::exact::Exact<crate::exact::Exact<f64, M>, N>;
    const KIND: Kind = Kind::Number;
    fn from_raw(raw: Self::Raw) -> Self {
        raw.0.map(|row| row.0)
    }
    fn render(&self) -> String {
        list(self.iter().map(KeyType::render))
    }
    fn numbers(&self, out: &mut Vec<(String, Number)>) {
        for (i, row) in self.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                out.push((format!("[{i}][{j}]"), Number::Float(*v)));
            }
        }
    }
}

impl KeyType for Vec<i64> {
    type Raw = Vec<i64>;
    const KIND: Kind = Kind::Integer;
    fn from_raw(raw: Self::Raw) -> Self {
        raw
    }
    fn render(&self) -> String {
        list(self.iter().map(KeyType::render))
    }
    fn numbers(&self, out: &mut Vec<(String, Number)>) {
        for (i, v) in self.iter().enumerate() {
            out.push((format!("[{i}]"), Number::Int(*v)));
        }
    }
}

impl KeyType for Vec<String> {
    type Raw = Vec<String>;
    const KIND: Kind = Kind::Text;
    fn from_raw(raw: Self::Raw) -> Self {
        raw
    }
    fn render(&self) -> String {
        list(self.iter().map(KeyType::render))
    }
}

fn list(items: impl Iterator<Item = String>) -> String {
    format!("[{}]", items.collect::<Vec<_>>().join(", "))
}

/// A key's value as its declaration writes it: the value itself, or text
/// for a `String` (`"recordings"`), or an array for a list.
pub(crate) trait IntoKey<T> {
    fn into_key(self) -> T;
}

impl<T> IntoKey<T> for T {
    fn into_key(self) -> T {
        self
    }
}

impl IntoKey<String> for &str {
    fn into_key(self) -> String {
        self.to_owned()
    }
}

impl<const N: usize> IntoKey<Vec<String>> for [&str; N] {
    fn into_key(self) -> Vec<String> {
        self.iter().map(|s| (*s).to_owned()).collect()
    }
}

impl<const N: usize> IntoKey<Vec<i64>> for [i64; N] {
    fn into_key(self) -> Vec<i64> {
        self.to_vec()
    }
}

/// `value` as TOML writes it (a declaration's default or example).
pub(crate) fn render<T: KeyType>(value: impl IntoKey<T>) -> String {
    value.into_key().render()
}

/// A resolved key's value (or its absence) as the range check sees it.
pub(crate) trait Checked {
    fn numbers(&self, out: &mut Vec<(String, Number)>);
    fn text(&self) -> Option<&str>;
}

impl<T: KeyType> Checked for T {
    fn numbers(&self, out: &mut Vec<(String, Number)>) {
        KeyType::numbers(self, out);
    }
    fn text(&self) -> Option<&str> {
        KeyType::text(self)
    }
}

impl<T: KeyType> Checked for Option<T> {
    fn numbers(&self, out: &mut Vec<(String, Number)>) {
        if let Some(v) = self {
            KeyType::numbers(v, out);
        }
    }
    fn text(&self) -> Option<&str> {
        self.as_ref().and_then(KeyType::text)
    }
}
