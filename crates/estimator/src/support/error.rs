//! Why a support calibration could not be set up or did not give a result
//! ([`SupportError`]).

use crate::{MIN_SUPPORT_DISTANCE_M, PoseInputError, SettingError};
use sar_kinematics::Shown;

/// Why a support calibration could not be set up or did not give a result.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SupportError {
    /// A setting (noise, tare, option) is out of range.
    #[error(transparent)]
    Setting(#[from] SettingError),
    /// The calibration holds [`SUPPORT_CAPACITY`] poses already.
    #[error("support calibration is full: it holds {capacity} poses")]
    Full {
        /// The capacity.
        capacity: usize,
    },
    /// A pose's own values are invalid ([`StaticPose::check`]).
    #[error("pose {pose}: {error}")]
    Pose {
        /// Index of the pose (the one being pushed: the current length).
        pose: usize,
        /// What is wrong with it.
        error: PoseInputError,
    },
    /// Fewer equations (3 per pose) than free unknowns plus one.
    #[error("{poses} poses give {equations} equations for {unknowns} unknowns: too few")]
    TooFewPoses {
        /// Poses held.
        poses: usize,
        /// 3 per pose.
        equations: usize,
        /// Free unknowns of the fit.
        unknowns: usize,
    },
    /// The poses do not determine m, M (and f): the scaled normal matrix is singular.
    #[error(
        "the poses do not determine {unknown} (smallest scaled pivot {pivot:e}); vary the rod's distance to the support{hint}"
    )]
    Undetermined {
        /// The first unknown found undetermined.
        unknown: &'static str,
        /// Its pivot in the column-scaled normal matrix (0 for a zero column).
        pivot: f64,
        /// What else may help.
        hint: &'static str,
    },
    /// A U-joint centre is too close to the support point (configured or fitted).
    #[error(
        "pose {pose}: the U-joint centre is {} m from the support, below {MIN_SUPPORT_DISTANCE_M} m",
        Shown(*.distance_m)
    )]
    UJointAtSupport {
        /// Index of the pose.
        pose: usize,
        /// |B - A|.
        distance_m: f64,
    },
    /// The fit ran away: non-finite values, or B moved further than
    /// [`MAX_SUPPORT_SHIFT_M`] from its configured value.
    #[error(
        "the fit diverged: the support moved {} m from its configured value",
        Shown(*.shift_m)
    )]
    Diverged {
        /// |B_fit - B_configured| (NaN-free: infinity when non-finite).
        shift_m: f64,
    },
    /// The fit did not converge within the allowed iterations.
    #[error("the fit did not converge within {iterations} iterations (last scaled step {step:e})")]
    NotConverged {
        /// The iteration limit.
        iterations: u32,
        /// The norm of the last scaled step tried.
        step: f64,
    },
    /// No damped step lowered the cost: the damping of Levenberg-Marquardt
    /// rose above its ceiling, or its counted bound of trials per iteration
    /// ran out.
    #[error(
        "no damped step lowers the fit's cost: {trials} trials, damping {lambda:e} (last scaled step {step:e})"
    )]
    DampingExhausted {
        /// The trials refused in the last iteration.
        trials: u32,
        /// The damping reached (relative to the unit diagonal of the scaled
        /// normal matrix).
        lambda: f64,
        /// The norm of the last scaled step tried.
        step: f64,
    },
    /// A value of the result is NaN or infinite (finite inputs so large that
    /// the cost overflows).
    #[error("the fit's {field} is not finite ({value}): readings far out of range")]
    NonFiniteResult {
        /// Which value.
        field: &'static str,
        /// The value.
        value: f64,
    },
    /// The fitted mass is not positive, so c = M / m is meaningless.
    #[error("the fitted mass is {} kg: not positive", Shown(*.mass_kg))]
    NonPositiveMass {
        /// The fitted m.
        mass_kg: f64,
    },
    /// The best fit does not explain the readings: its chi-square per degree
    /// of freedom is above [`SupportOptions::max_chi2_dof`] (a model error: an
    /// untared sensor, an offset d, a support that does not pivot about one
    /// point, friction not estimated, wrong noise figures; or a configured B
    /// further off than the global search covers).
    #[error(
        "the fit does not explain the readings: chi-square per degree of freedom {chi2_dof} above {limit}"
    )]
    PoorFit {
        /// The fit's chi-square per degree of freedom.
        chi2_dof: f64,
        /// [`SupportOptions::max_chi2_dof`].
        limit: f64,
    },
    /// Friction is estimated and a pose's slide sign is unknown: its force
    /// would need a friction coefficient that nobody knows (MODEL.md 5).
    #[error(
        "pose {pose}: the slide sign is unknown (no slide before it); move into the pose, or turn the friction unknown off"
    )]
    UnknownSlideSign {
        /// Index of the pose.
        pose: usize,
    },
    /// A procedure plans more poses than a calibration holds.
    #[error("a procedure of {planned} poses does not fit: support calibration holds {capacity}")]
    TooManyPlanned {
        /// The poses planned.
        planned: usize,
        /// [`SUPPORT_CAPACITY`].
        capacity: usize,
    },
}
