//! Numbers as a person reads them: [`Shown`] prints an `f64` with at most six
//! significant digits, without trailing zeros (`0.1`, not
//! `0.10000000000000003`), in fixed notation from 1e-5 to below 1e6 and with an
//! exponent outside (`1.5e-7`, `2.5e9`). Every message that shows a computed
//! number to an operator (refusals, errors) prints it through [`Shown`] or
//! [`ShownAll`]; a number the user typed (a configuration value) is echoed as
//! typed instead.
//!
//! No allocation (a stack buffer), no panic, `no_std`: the rounding is
//! `core::fmt`'s own (`{:.5e}`, correctly rounded), so `Shown(x)` parsed back is
//! within half a unit of the sixth significant digit of `x`.

use core::fmt;

/// Significant digits shown.
pub const SIGNIFICANT_DIGITS: usize = 6;

/// An `f64` shown with at most [`SIGNIFICANT_DIGITS`] significant digits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shown(pub f64);

/// A list of `f64`, each as [`Shown`], in brackets: `[0.45, 0.2, 0]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShownAll<'a>(pub &'a [f64]);

/// A fixed buffer that `core::fmt` writes into (long enough for any `f64` in
/// the forms used here: at most 1 + 1 + 1 + 10 + 1 + 5 bytes).
struct Buffer {
    bytes: [u8; 40],
    len: usize,
}

impl Buffer {
    const fn new() -> Self {
        Self {
            bytes: [0; 40],
            len: 0,
        }
    }

    fn as_str(&self) -> &str {
        // Only whole `&str`s are written (`write_str`), so the bytes are UTF-8.
        self.bytes
            .get(..self.len)
            .and_then(|b| core::str::from_utf8(b).ok())
            .unwrap_or("")
    }
}

impl fmt::Write for Buffer {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        let end = self.len.checked_add(s.len()).ok_or(fmt::Error)?;
        let dst = self.bytes.get_mut(self.len..end).ok_or(fmt::Error)?;
        dst.copy_from_slice(s.as_bytes());
        self.len = end;
        Ok(())
    }
}

/// `digits` without trailing zeros after a decimal point, nor the point.
fn trimmed(digits: &str) -> &str {
    if digits.contains('.') {
        digits.trim_end_matches('0').trim_end_matches('.')
    } else {
        digits
    }
}

impl fmt::Display for Shown {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use fmt::Write as _;
        let x = self.0;
        if !x.is_finite() || x == 0.0 {
            // NaN, inf, -inf, 0 (a negative zero shows as 0).
            return if x == 0.0 {
                f.write_str("0")
            } else {
                write!(f, "{x}")
            };
        }
        // The decimal exponent after rounding to six significant digits.
        let mut sci = Buffer::new();
        write!(sci, "{:.*e}", SIGNIFICANT_DIGITS - 1, x)?;
        let (mantissa, exponent) = sci.as_str().split_once('e').ok_or(fmt::Error)?;
        let exponent: i32 = exponent.parse().map_err(|_| fmt::Error)?;
        if (-5..6).contains(&exponent) {
            let decimals = usize::try_from(5 - exponent).unwrap_or(0);
            let mut fixed = Buffer::new();
            write!(fixed, "{x:.decimals$}")?;
            f.write_str(trimmed(fixed.as_str()))
        } else {
            write!(f, "{}e{exponent}", trimmed(mantissa))
        }
    }
}

impl fmt::Display for ShownAll<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("[")?;
        for (i, x) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            write!(f, "{}", Shown(*x))?;
        }
        f.write_str("]")
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::format;
    use std::string::ToString;

    #[test]
    fn the_operators_case_and_the_forms() {
        // `sarctl move-tip 0.9 0.2 0` printed "0.10000000000000003".
        assert_eq!(Shown(0.9 - 0.8).to_string(), "0.1");
        assert_eq!(Shown(0.10000000000000003).to_string(), "0.1");
        for (x, s) in [
            (0.0, "0"),
            (-0.0, "0"),
            (1.0, "1"),
            (-0.5, "-0.5"),
            (15.0, "15"),
            (0.45, "0.45"),
            (2.593, "2.593"),
            (123_456.4, "123456"),
            (999_999.6, "1e6"),
            (1_000_000.0, "1e6"),
            (2.5e9, "2.5e9"),
            (0.000_012_345_67, "0.0000123457"),
            (1.5e-7, "1.5e-7"),
            (9.999_996, "10"),
            (-1.234_567_89e-300, "-1.23457e-300"),
            (f64::MAX, "1.79769e308"),
            (f64::MIN_POSITIVE, "2.22507e-308"),
            (5e-324, "4.94066e-324"),
            (f64::NAN, "NaN"),
            (f64::INFINITY, "inf"),
            (f64::NEG_INFINITY, "-inf"),
        ] {
            assert_eq!(Shown(x).to_string(), s, "{x:e}");
        }
        assert_eq!(ShownAll(&[0.45, 0.2, 0.0]).to_string(), "[0.45, 0.2, 0]");
        assert_eq!(ShownAll(&[]).to_string(), "[]");
        // A width of the caller is not applied (a plain number).
        assert_eq!(format!("{}", Shown(1.25)), "1.25");
    }

    /// Over many numbers of every magnitude (seeded): what is shown parses
    /// back within half a unit of the sixth significant digit, has at most
    /// six significant digits, and no trailing zero after a point.
    #[test]
    fn shown_numbers_parse_back_within_six_significant_digits() {
        let mut state: u64 = 0x5eed_2028;
        for i in 0..200_000 {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            // Every other number: any bit pattern (mostly far from 1); else
            // one between 1e-8 and 1e8, where the fixed form is used.
            let x = if i % 2 == 0 {
                f64::from_bits(state)
            } else {
                let mut x = (state >> 11) as f64 / (1u64 << 53) as f64 * 1e-8;
                for _ in 0..(state % 17) {
                    x *= 10.0;
                }
                if state & (1 << 5) == 0 { x } else { -x }
            };
            if !x.is_finite() {
                continue;
            }
            let s = Shown(x).to_string();
            let back: f64 = s.parse().unwrap_or(f64::NAN);
            let tolerance = x.abs() * 5.000_001e-6;
            assert!(
                (back - x).abs() <= tolerance,
                "{x:e} shown as {s} (back {back:e})"
            );
            let mantissa = s.split('e').next().unwrap_or("");
            let digits = mantissa
                .trim_start_matches('-')
                .replace('.', "")
                .trim_start_matches('0')
                .len();
            assert!(digits <= SIGNIFICANT_DIGITS, "{x:e} shown as {s}");
            if mantissa.contains('.') {
                assert!(!mantissa.ends_with('0'), "{x:e} shown as {s}");
            }
        }
    }
}
