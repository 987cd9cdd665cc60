//! What both identifications refuse alike, before any fit: an option out of
//! range, a recording that cannot be read or lacks a topic, a manipulator
//! with an offset d (MODEL.md 5.1, 10: both model d = 0).
//!
//! The layering: [`InputError`] is the one home of these refusals; the
//! static identification's [`super::IdentifyError`] and the dynamic one's
//! [`super::dynamic::DynamicError`] each wrap it (`Input`, shown as it is)
//! and add only their own fit's refusals, whose advice differs (more static
//! poses; another excitation).

use sar_config::Config;
use sar_record::ReadError;
use sar_record::lean::LeanReadError;

/// Why an identification did not start: one line each.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum InputError {
    /// An option is out of range.
    #[error("{0}")]
    Option(String),
    /// The recording could not be read.
    #[error("the recording cannot be read: {0}")]
    Read(#[from] ReadError),
    /// A lean recording's batches cannot be read.
    #[error("the recording cannot be read: {0}")]
    Lean(#[from] LeanReadError),
    /// The recording lacks a topic.
    #[error(
        "the recording has no {topic} messages: identify needs the sensor's readings and the joints"
    )]
    MissingTopic {
        /// The topic.
        topic: &'static str,
    },
    /// The configured manipulator has an offset d, which identification does
    /// not model (MODEL.md 5.1, 10: d = 0).
    #[error("the configured manipulator has offset_m = {offset_m}: identify models d = 0")]
    Offset {
        /// d, m.
        offset_m: f64,
    },
}

/// Refuses a configured offset d ([`InputError::Offset`]).
pub fn check_offset(config: &Config) -> Result<(), InputError> {
    let offset_m = config.estimator.profile.offset_m();
    if offset_m != 0.0 {
        return Err(InputError::Offset { offset_m });
    }
    Ok(())
}

/// Refuses the options both fits take when out of range: a tare that is not
/// finite, a chi-square limit not above 0, a condition limit below 1.
pub fn check_fit_limits(
    tare_n: &[f64; 3],
    max_chi2_dof: f64,
    max_condition: f64,
) -> Result<(), InputError> {
    if !tare_n.iter().all(|x| x.is_finite()) {
        return Err(InputError::Option(format!(
            "the tare must be finite, got {tare_n:?}"
        )));
    }
    if max_chi2_dof.is_nan() || max_chi2_dof <= 0.0 {
        return Err(InputError::Option(format!(
            "the chi-square limit must be > 0, got {max_chi2_dof}"
        )));
    }
    if max_condition.is_nan() || max_condition < 1.0 {
        return Err(InputError::Option(format!(
            "the condition limit must be >= 1, got {max_condition}"
        )));
    }
    Ok(())
}
