//! Error measures of MODEL.md 6: the article's absolute relative error (Eq. 31)
//! between computed and measured series, and the relative error of an
//! identified value.

/// Why an error measure could not be computed.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ErrorMeasureError {
    /// The two series differ in length.
    #[error("computed has {computed} values but measured has {measured}")]
    LengthMismatch {
        /// Length of the computed series.
        computed: usize,
        /// Length of the measured series.
        measured: usize,
    },
    /// The series are empty.
    #[error("the series are empty")]
    Empty,
    /// An input is NaN or infinite.
    #[error("{series}[{index}] = {value} is not finite")]
    NonFinite {
        /// Which input ("computed", "measured", "estimate", "truth").
        series: &'static str,
        /// Its index (0 for a scalar).
        index: usize,
        /// The value.
        value: f64,
    },
    /// Every measured value is the same: sum |y_i - mean(y)| is zero.
    #[error("all {count} measured values equal {value}: the denominator is zero")]
    ZeroDenominator {
        /// How many values.
        count: usize,
        /// Their common value.
        value: f64,
    },
    /// The true value is zero: the relative error is not defined.
    #[error("the true value is zero: relative error undefined")]
    ZeroTruth,
    /// The result overflows (inputs too large or a denominator too small).
    #[error("the result is not a finite number ({value})")]
    Overflow {
        /// The non-finite result.
        value: f64,
    },
}

fn check_finite(series: &'static str, values: &[f64]) -> Result<(), ErrorMeasureError> {
    match values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        Some((index, &value)) => Err(ErrorMeasureError::NonFinite {
            series,
            index,
            value,
        }),
        None => Ok(()),
    }
}

/// The absolute relative error (article Eq. 31, MODEL.md 6), as a fraction
/// (multiply by 100 for per cent):
///
/// `e_ra = sum |x_i - y_i| / sum |y_i - mean(y)|`
///
/// with `x = computed` and `y = measured`.
pub fn absolute_relative_error(
    computed: &[f64],
    measured: &[f64],
) -> Result<f64, ErrorMeasureError> {
    if computed.len() != measured.len() {
        return Err(ErrorMeasureError::LengthMismatch {
            computed: computed.len(),
            measured: measured.len(),
        });
    }
    let Some(&first) = measured.first() else {
        return Err(ErrorMeasureError::Empty);
    };
    check_finite("computed", computed)?;
    check_finite("measured", measured)?;
    // Checked directly: a rounded mean of equal values need not equal them.
    if measured.iter().all(|&y| y == first) {
        return Err(ErrorMeasureError::ZeroDenominator {
            count: measured.len(),
            value: first,
        });
    }
    // Running mean (no overflow of a plain sum of large values).
    let mut mean = 0.0;
    let mut count = 0.0;
    for &y in measured {
        count += 1.0;
        mean += (y - mean) / count;
    }
    let numerator: f64 = computed
        .iter()
        .zip(measured)
        .map(|(x, y)| (x - y).abs())
        .sum();
    let denominator: f64 = measured.iter().map(|y| (y - mean).abs()).sum();
    let value = numerator / denominator;
    if value.is_finite() && denominator > 0.0 {
        Ok(value)
    } else {
        Err(ErrorMeasureError::Overflow { value })
    }
}

/// The relative error of an identified value, as a fraction:
/// `(estimate - truth) / truth` (MODEL.md 6).
pub fn relative_error(estimate: f64, truth: f64) -> Result<f64, ErrorMeasureError> {
    check_finite("estimate", &[estimate])?;
    check_finite("truth", &[truth])?;
    if truth == 0.0 {
        return Err(ErrorMeasureError::ZeroTruth);
    }
    let value = (estimate - truth) / truth;
    if value.is_finite() {
        Ok(value)
    } else {
        Err(ErrorMeasureError::Overflow { value })
    }
}
