//! Frames, calibration and closed-form kinematics of the surgical assistance robot.
//!
//! This crate is the geometric half of `../shared/spec/MODEL.md` (sections 2 and 3):
//! the validated calibration and manipulator profile, the passive U-joint angles
//! q4, q5 in closed form, the named points A, S, C, D, the rod direction u, and the
//! inverse kinematics from a wanted tip position to the active joints.
//!
//! Invariants (see `ARCHITECTURE.md`):
//! - `#![no_std]`, no `alloc`, no I/O, no panics on any input: every degenerate
//!   input is a typed error, never a NaN.
//! - A [`Calibration`] or [`Profile`] that exists is valid: fields are private and
//!   only the validating constructors make them.
//! - SI units everywhere, and the unit is the last part of every name.
#![no_std]

pub mod calibration;
pub mod dh;
pub mod pose;
pub mod shown;
pub mod slide;

pub use calibration::{Calibration, CalibrationSpec, ConfigError, Profile, ProfileSpec};
pub use pose::{ActiveJoints, Pose, PoseError, forward, inverse, rod_frame};
pub use shown::{Shown, ShownAll};
pub use slide::{SLIDE_THRESHOLD_M, SlideDirection, SlideSign, SlideTracker};

/// A 3-vector of `f64` in some named frame (the name of the variable says which).
pub type Vec3 = nalgebra::Vector3<f64>;
/// A 3x3 matrix of `f64`.
pub type Mat3 = nalgebra::Matrix3<f64>;

/// Distances below this are treated as zero by the degenerate-pose checks (1 um).
pub const MIN_DISTANCE_M: f64 = 1e-6;

/// `Err(error(value))` for the first NaN or infinite `value` among `values`
/// (the estimator's per-cycle checks use it too).
#[inline]
pub fn check_finite<'a, E>(
    values: impl IntoIterator<Item = &'a f64>,
    error: impl FnOnce(f64) -> E,
) -> Result<(), E> {
    // A plain loop: `find` on nalgebra's iterators cost 12 ns on the
    // estimator's per-cycle path (tip force, d = 0).
    for &value in values {
        if !value.is_finite() {
            return Err(error(value));
        }
    }
    Ok(())
}
