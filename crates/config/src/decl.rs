//! How a configuration key is declared: once, in its section's
//! [`section!`](crate::section) table (`crate::keys`), with its type, default,
//! range, one-line doc and the domain field it sets. From that one line come
//! the serde mirror of the section (unknown keys refused), its defaults and
//! missing-key errors, the range check of every key (a key is checked because
//! it is declared), the table of every key ([`SECTIONS`](crate::SECTIONS), the
//! README's table and the comments of `default_config.toml`, `crate::docs`)
//! and the mapping of a domain type's error back to the key that set the
//! field ([`key_of_field`]).
//!
//! The relations between keys (a speed at most another key's) are not
//! ranges: `crate::relations` checks them, in one place.

use crate::ConfigError;
use crate::toml_file::{Ctx, num as shown};
mod section;
mod value;

pub use value::Kind;
pub(crate) use value::{Checked, IntoKey, KeyType, Number, render};

/// What a numeric range bounds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Applies {
    /// The value.
    Value,
    /// Each number of an array (each bound of each axis for
    /// `axes.travel_m`).
    EachComponent,
    /// The vector's magnitude.
    Magnitude,
}

/// The values a key takes.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub enum Bounds {
    /// A number (or each number of an array, or the array's magnitude)
    /// within `lo..=hi`, in `unit`: a plausible range (issue 25), so that a
    /// unit mistake is refused with the likely unit.
    Number {
        /// The smallest plausible value.
        lo: f64,
        /// The largest plausible value.
        hi: f64,
        /// The unit, as the key's name says it ("" for a ratio or a count).
        unit: &'static str,
        /// What the range bounds.
        applies: Applies,
    },
    /// An integer (or each integer of a list) within `lo..=hi`.
    Integer {
        /// The smallest value.
        lo: i64,
        /// The largest value.
        hi: i64,
        /// What it counts ("" when the name says it).
        unit: &'static str,
        /// What the range bounds ([`Applies::Magnitude`]: never).
        applies: Applies,
    },
    /// One of these words.
    Choice(&'static [&'static str]),
    /// Text: what it must be (checked where the section is read).
    Text(&'static str),
    /// `true` or `false`.
    Switch,
}

/// A key's range: its [`Bounds`] and what else bounds it (the relations
/// `crate::relations` checks; "" when nothing).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    /// The values the key takes.
    pub bounds: Bounds,
    /// What other keys bound it ("" when none).
    pub also: &'static str,
}

impl Range {
    /// This range, also bounded by `what` (a relation to other keys).
    pub const fn also(self, what: &'static str) -> Self {
        Self { also: what, ..self }
    }
}

const fn number(lo: f64, hi: f64, unit: &'static str, applies: Applies) -> Range {
    Range {
        bounds: Bounds::Number {
            lo,
            hi,
            unit,
            applies,
        },
        also: "",
    }
}

/// A number within `lo..=hi` `unit`.
pub const fn num(lo: f64, hi: f64, unit: &'static str) -> Range {
    number(lo, hi, unit, Applies::Value)
}

/// Each number of an array within `lo..=hi` `unit`.
pub const fn each(lo: f64, hi: f64, unit: &'static str) -> Range {
    number(lo, hi, unit, Applies::EachComponent)
}

/// A vector whose magnitude is within `lo..=hi` `unit`.
pub const fn magnitude(lo: f64, hi: f64, unit: &'static str) -> Range {
    number(lo, hi, unit, Applies::Magnitude)
}

/// An integer within `lo..=hi`.
pub const fn int(lo: i64, hi: i64, unit: &'static str) -> Range {
    Range {
        bounds: Bounds::Integer {
            lo,
            hi,
            unit,
            applies: Applies::Value,
        },
        also: "",
    }
}

/// Each integer of a list within `lo..=hi`.
pub const fn int_each(lo: i64, hi: i64, unit: &'static str) -> Range {
    Range {
        bounds: Bounds::Integer {
            lo,
            hi,
            unit,
            applies: Applies::EachComponent,
        },
        also: "",
    }
}

/// One of `words`.
pub const fn choice(words: &'static [&'static str]) -> Range {
    Range {
        bounds: Bounds::Choice(words),
        also: "",
    }
}

/// Text that must be `what`.
pub const fn text(what: &'static str) -> Range {
    Range {
        bounds: Bounds::Text(what),
        also: "",
    }
}

/// `true` or `false`.
pub const fn switch() -> Range {
    Range {
        bounds: Bounds::Switch,
        also: "",
    }
}

/// A key's default.
#[derive(Debug, Clone, Copy)]
#[non_exhaustive]
pub enum KeyDefault {
    /// This value (written as TOML).
    Value(fn() -> String),
    /// None: the file must give the key; an example value (TOML), the
    /// example robot's (INTERFACES.md 2).
    Required(fn() -> String),
    /// Absent, which means `meaning`; an example value (TOML).
    Absent(&'static str, fn() -> String),
}

/// One key of the configuration, as its section declares it.
#[derive(Debug, Clone, Copy)]
pub struct KeyDecl {
    /// The section, dotted (`guard`, `drivers.axes`).
    pub section: &'static str,
    /// The key's name in its section.
    pub name: &'static str,
    /// The dotted key (`guard.warn_total_n`), as errors name it.
    pub key: &'static str,
    /// What it is, one line.
    pub doc: &'static str,
    /// Its default.
    pub default: KeyDefault,
    /// What kind of value its type holds.
    pub kind: Kind,
    /// The values it takes.
    pub range: Range,
    /// The domain field it sets (`GuardLimits.force.warn_total_n`), a path
    /// the compiler checks (`Type.field`, `Type::Variant.field`,
    /// `Type::setter` or `Type`).
    pub target: &'static str,
}

/// One section of the configuration: its name, its one-line doc and its
/// keys, in the file's order.
#[derive(Debug, Clone, Copy)]
pub struct SectionDecl {
    /// The section, dotted (`guard`, `drivers.axes`).
    pub name: &'static str,
    /// What it is, one line (`default_config.toml` writes it above the
    /// section).
    pub doc: &'static str,
    /// Its keys.
    pub keys: &'static [KeyDecl],
}

impl KeyDecl {
    /// `[section] name`, as prose names a key of another section.
    pub fn in_section(&self) -> String {
        format!("[{}] {}", self.section, self.name)
    }

    /// The target's field path (`force.warn_total_n`; the key's name for a
    /// setter or a whole type), as a domain type's errors name the field.
    pub fn target_field(&self) -> &'static str {
        match self.target.split_once('.') {
            Some((_, field)) => field,
            None => self.name,
        }
    }
}

/// The smaller units a value of `unit` is often written in by mistake, with
/// their size in `unit`.
fn smaller_units(unit: &str) -> &'static [(&'static str, f64)] {
    match unit {
        "m" => &[("cm", 0.01), ("mm", 0.001)],
        "kg" => &[("g", 0.001)],
        "N" => &[("mN", 0.001)],
        "N m" => &[("N mm", 0.001)],
        "m/s" => &[("mm/s", 0.001)],
        "m/s^2" => &[("cm/s^2", 0.01), ("mm/s^2", 0.001), ("g", 9.80665)],
        "s" => &[("ms", 0.001)],
        _ => &[],
    }
}

/// " (a value in cm? 35 cm is 0.35 m)" when `v` in a smaller unit lands in
/// `lo..=hi`, else "".
fn unit_hint(v: f64, lo: f64, hi: f64, unit: &str) -> String {
    smaller_units(unit)
        .iter()
        .find(|(_, size)| (lo..=hi).contains(&(v * size)) && v != 0.0)
        .map(|(name, size)| {
            format!(
                " (a value in {name}? {} {name} is {} {unit})",
                shown(v),
                // Rounded to 1e-9: "0.35", not "0.35000000000000003".
                shown((v * size * 1e9).round() / 1e9)
            )
        })
        .unwrap_or_default()
}

/// " unit", or "" without one.
fn spaced(unit: &str) -> String {
    if unit.is_empty() {
        String::new()
    } else {
        format!(" {unit}")
    }
}

/// `"a"`, `"a" or "b"`, `"a", "b" or "c"`.
pub(crate) fn or_list(words: &[&str]) -> String {
    let quoted: Vec<String> = words.iter().map(|w| format!("{w:?}")).collect();
    match quoted.split_last() {
        Some((last, [])) => last.clone(),
        Some((last, rest)) => format!("{} or {last}", rest.join(", ")),
        None => String::new(),
    }
}

/// Refuses the number `v` at `key` outside `lo..=hi` `unit`.
fn within(
    ctx: &Ctx<'_>,
    key: &str,
    v: f64,
    (lo, hi, unit): (f64, f64, &str),
    what: &str,
) -> Result<(), ConfigError> {
    if (lo..=hi).contains(&v) {
        return Ok(());
    }
    Err(ctx.err(
        key,
        format!(
            "{what} within {}..={}{}, got {}{}",
            shown(lo),
            shown(hi),
            spaced(unit),
            shown(v),
            unit_hint(v, lo, hi, unit)
        ),
    ))
}

/// Refuses `v` (the value of the key `d` declares) outside its declared
/// range: each number, the magnitude, the integer or the word.
pub(crate) fn check(ctx: &Ctx<'_>, d: &KeyDecl, v: &impl Checked) -> Result<(), ConfigError> {
    let mut numbers = Vec::new();
    v.numbers(&mut numbers);
    match d.range.bounds {
        Bounds::Number {
            lo,
            hi,
            unit,
            applies: Applies::Magnitude,
        } => {
            if numbers.is_empty() {
                return Ok(());
            }
            let m = numbers.iter().map(|(_, x)| x.as_f64().powi(2)).sum::<f64>();
            let what = "its magnitude must be";
            within(ctx, d.key, m.sqrt(), (lo, hi, unit), what)
        }
        Bounds::Number { lo, hi, unit, .. } => {
            for (index, x) in numbers {
                let key = format!("{}{index}", d.key);
                within(ctx, &key, x.as_f64(), (lo, hi, unit), "must be")?;
            }
            Ok(())
        }
        Bounds::Integer { lo, hi, unit, .. } => {
            for (index, x) in numbers {
                let Number::Int(x) = x else { continue };
                if !(lo..=hi).contains(&x) {
                    let key = format!("{}{index}", d.key);
                    let problem = format!("must be within {lo}..={hi}{}, got {x}", spaced(unit));
                    return Err(ctx.err(&key, problem));
                }
            }
            Ok(())
        }
        Bounds::Choice(words) => match v.text() {
            Some(t) if !words.contains(&t) => {
                Err(ctx.err(d.key, format!("must be {}, got {t:?}", or_list(words))))
            }
            _ => Ok(()),
        },
        Bounds::Text(_) | Bounds::Switch => Ok(()),
    }
}

/// The error of a required key the file does not give.
pub(crate) fn missing(ctx: &Ctx<'_>, d: &KeyDecl) -> ConfigError {
    ctx.err(d.key, "missing key")
}

/// The key of `sections` that sets the field a domain type's error names
/// (`max_sensor_age_ns`, `torque.noise_nm`, `axial.mass_kg`): the key whose
/// target's field path is `field`, else whose name is, else whose target's
/// last part is `field`'s last part.
pub(crate) fn key_of_field(
    sections: &[&'static [KeyDecl]],
    field: &str,
) -> Option<&'static KeyDecl> {
    let keys = || sections.iter().flat_map(|s| s.iter());
    let last = |path: &str| path.rsplit('.').next().unwrap_or(path).to_owned();
    keys()
        .find(|d| d.target_field() == field)
        .or_else(|| keys().find(|d| d.name == field))
        .or_else(|| keys().find(|d| last(d.target_field()) == last(field)))
}

/// A domain type's setting error under the key of `sections` that set the
/// field (else under the first section).
pub(crate) fn setting_error(
    ctx: &Ctx<'_>,
    sections: &[&'static [KeyDecl]],
    e: &sar_estimator::SettingError,
) -> ConfigError {
    let field = match e {
        sar_estimator::SettingError::Invalid { field, .. } => *field,
        _ => "",
    };
    let key = key_of_field(sections, field)
        .map(|d| d.key)
        .or_else(|| sections.first().and_then(|s| s.first()).map(|d| d.section))
        .unwrap_or("");
    ctx.err(key, e.to_string())
}
