//! Support calibration (MODEL.md 5.1): a noise-weighted Levenberg-Marquardt fit of
//! the mass m, the first moment M = m c, the support point B and (optionally) the
//! support's friction f from static poses with nothing at the tip (d = 0).
//!
//! Model of the force the robot applies to the rod at A, in {0}:
//!
//! ```text
//! F_A = -m g + (M / a) (g - (g.u) u) + sigma f u,   a = |B - A|,  u = (B - A) / a
//! ```
//!
//! with sigma the pose's slide sign. The measured F_A = -R_0s (f_s - b) uses the
//! tare b given at construction. Each pose is weighted by the inverse of its noise
//! covariance `R_0s diag(std^2) R_0s^T / K`, through the inverse of its Cholesky
//! factor, so that chi-square per degree of freedom is about 1 when the model and
//! the noise figures are right.
//!
//! The components of B that the poses do not determine (their standard error
//! would exceed [`SupportOptions::max_support_std_m`]) are held at the configured
//! value and reported in [`SupportFit::held`]: under the article's protocol (rod
//! horizontal at the support's height) that is B_z.
//!
//! Fixed capacity ([`SUPPORT_CAPACITY`] poses), no allocation, no panics.

use crate::{
    Calibration, MIN_SUPPORT_DISTANCE_M, Mat3, PoseInputError, SensorNoise, SettingError,
    StaticPose, Vec3, check_finite, com_std_m, non_negative, ujoint_force_n,
};
use nalgebra::{Cholesky, ComplexField, SMatrix, SVector};

/// How many static poses a [`SupportCalibration`] holds at most.
pub const SUPPORT_CAPACITY: usize = 64;

/// Largest accepted distance between the fitted and the configured support
/// point, m (B is measured by hand to a few millimetres). Trial steps beyond it
/// are refused, and a fit that ends within 1 % of it has diverged (its minimum
/// lies outside).
pub const MAX_SUPPORT_SHIFT_M: f64 = 0.05;

/// Fraction of [`MAX_SUPPORT_SHIFT_M`] beyond which a final B counts as diverged.
const SHIFT_EDGE: f64 = 0.99;

/// Most Levenberg-Marquardt passes of one fit. A pass ends when it converges or
/// when the set of components of B that the poses determine (re-checked after
/// every accepted step and at the solution) changes; the last pass keeps its set.
pub const MAX_PASSES: u32 = 4;

/// Convergence: the Levenberg-Marquardt step, in units of the column-scaled
/// (whitened) Jacobian, i.e. roughly in standard errors of each unknown.
const STEP_TOL: f64 = 1e-10;
/// Convergence: relative decrease of the cost (chi-square), achieved by an
/// accepted step or predicted for the undamped step.
const COST_TOL: f64 = 1e-12;
/// The cost's rounding floor, relative to the sum of the squared whitened
/// measurements: (64 eps)^2.
const COST_FLOOR: f64 = (64.0 * f64::EPSILON) * (64.0 * f64::EPSILON);
/// Damping of the first step, relative to the unit diagonal of the scaled matrix.
const LAMBDA_START: f64 = 1e-3;
/// Largest damping before the fit gives up on finding a downhill step.
const LAMBDA_MAX: f64 = 1e16;
/// Smallest damping.
const LAMBDA_MIN: f64 = 1e-12;
/// Smallest accepted pivot (squared diagonal of the Cholesky factor) of the
/// column-scaled normal matrix: below it the unknowns are not determined.
const MIN_PIVOT: f64 = 1e-13;

/// Index of m in the unknowns.
const I_MASS: usize = 0;
/// Index of M = m c.
const I_MOMENT: usize = 1;
/// Index of B_x; B_y and B_z follow.
const I_SUPPORT: usize = 2;
/// Index of f.
const I_FRICTION: usize = 5;
/// Number of unknowns (m, M, B_x, B_y, B_z, f).
const N_UNKNOWNS: usize = 6;

type Vec6 = SVector<f64, N_UNKNOWNS>;
type Mat6 = SMatrix<f64, N_UNKNOWNS, N_UNKNOWNS>;
type Jac = SMatrix<f64, 3, N_UNKNOWNS>;

fn sqrt(x: f64) -> f64 {
    ComplexField::sqrt(x)
}

/// Element `k` of a 6-vector (0 out of range; all callers stay in range).
fn at6(v: &Vec6, k: usize) -> f64 {
    v.get(k).copied().unwrap_or(0.0)
}

/// Element (i, j) of a 6x6 matrix (0 out of range; all callers stay in range).
fn at(m: &Mat6, i: usize, j: usize) -> f64 {
    m.get((i, j)).copied().unwrap_or(0.0)
}

/// 1 for the free unknowns, 0 for the held ones.
fn indicator(free: &[bool; N_UNKNOWNS], want: bool) -> Vec6 {
    Vec6::from_fn(|k, _| {
        if free.get(k).copied() == Some(want) {
            1.0
        } else {
            0.0
        }
    })
}

/// `x < limit` or NaN.
fn below_or_nan(x: f64, limit: f64) -> bool {
    x.is_nan() || x < limit
}

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
        "pose {pose}: the U-joint centre is {distance_m} m from the support, below {MIN_SUPPORT_DISTANCE_M} m"
    )]
    UJointAtSupport {
        /// Index of the pose.
        pose: usize,
        /// |B - A|.
        distance_m: f64,
    },
    /// The fit ran away: non-finite values, or B moved further than
    /// [`MAX_SUPPORT_SHIFT_M`] from its configured value.
    #[error("the fit diverged: the support moved {shift_m} m from its configured value")]
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
    #[error("the fitted mass is {mass_kg} kg: not positive")]
    NonPositiveMass {
        /// The fitted m.
        mass_kg: f64,
    },
}

/// What to estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SupportOptions {
    /// Estimate the support's Coulomb friction f (with the slide sign as its
    /// coefficient) as an unknown.
    pub friction: bool,
    /// Estimate B. `false`: hold all of B at the configured value, which gives the
    /// linear (m, M, f) estimate.
    pub calibrate_support: bool,
    /// A component of B whose standard error would exceed this is held at its
    /// configured value, m (finite, > 0).
    pub max_support_std_m: f64,
    /// Largest number of Levenberg-Marquardt iterations per pass (>= 1).
    pub max_iterations: u32,
}

impl Default for SupportOptions {
    /// Friction and support estimated, B components with a standard error above
    /// 1 mm held, 50 iterations.
    fn default() -> Self {
        Self {
            friction: true,
            calibrate_support: true,
            max_support_std_m: 1e-3,
            max_iterations: 50,
        }
    }
}

/// The result of a support calibration.
///
/// Standard errors come from the inverse of the weighted normal matrix at the
/// solution, with the configured sensor noise as the weights, multiplied by
/// `max(1, sqrt(chi2_dof))`: never smaller than the noise model says, and widened
/// when the residuals scatter more than it (the same rule as
/// [`crate::identification`]). A `chi2_dof` far above 1 means the model does not
/// fit (an offset d, an untared sensor, a support that does not pivot about one
/// point): the widened errors are then still only a lower bound of the real ones.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SupportFit {
    /// m, kg.
    pub mass_kg: f64,
    /// Standard error of m, kg.
    pub mass_std_kg: f64,
    /// c = M / m, from A along the rod, m.
    pub com_m: f64,
    /// Standard error of c (first-order propagation from m and M), m.
    pub com_std_m: f64,
    /// M = m c, kg m.
    pub moment_kgm: f64,
    /// Standard error of M, kg m.
    pub moment_std_kgm: f64,
    /// B, {0}, m: fitted components, and the configured value for held ones.
    pub support_m: Vec3,
    /// Standard error of each component of B, m; `None` for a held component.
    pub support_std_m: [Option<f64>; 3],
    /// Which components of B were held at the configured value (the poses do not
    /// determine them, or `calibrate_support` is off).
    pub held: [bool; 3],
    /// f, N (`None` when not estimated). Positive: the support resists sliding.
    pub friction_n: Option<f64>,
    /// Standard error of f, N.
    pub friction_std_n: Option<f64>,
    /// Chi-square per degree of freedom (3 per pose minus the free unknowns).
    pub chi2_dof: f64,
    /// RMS of the force residuals F_A,measured - F_A,model over all components, N.
    pub residual_rms_n: f64,
    /// Condition number of the column-scaled weighted Jacobian at the solution,
    /// over the free unknowns.
    pub condition: f64,
    /// Accepted Levenberg-Marquardt steps, over all passes.
    pub iterations: u32,
    /// Poses used.
    pub poses: u32,
}

/// Collects static poses and fits m, M, B and f (MODEL.md 5.1).
#[derive(Debug, Clone)]
pub struct SupportCalibration {
    poses: [StaticPose; SUPPORT_CAPACITY],
    len: usize,
    calibration: Calibration,
    /// Inverse of the lower Cholesky factor of one sample's covariance of F_A in {0}.
    whitening: Mat3,
    tare_n: Vec3,
    options: SupportOptions,
}

/// The weighted least-squares problem over the poses held.
struct Problem<'a> {
    poses: &'a [StaticPose],
    calibration: &'a Calibration,
    whitening: &'a Mat3,
    tare_n: &'a Vec3,
    gravity: Vec3,
}

/// Normal equations of one linearisation.
struct Normal {
    /// J^T J of the whitened Jacobian, held unknowns' rows and columns zero.
    matrix: Mat6,
    /// J^T r.
    rhs: Vec6,
    /// r^T r (chi-square).
    cost: f64,
    /// Sum of squared unwhitened residuals, N^2.
    raw_sq_n2: f64,
    /// Below this the cost is rounding ([`COST_FLOOR`] times the sum of the
    /// squared whitened measurements).
    cost_floor: f64,
}

/// How a Levenberg-Marquardt pass ended.
enum PassEnd {
    /// Converged with the free set it was given.
    Converged,
    /// The free components of B changed to these; fit again.
    Changed([bool; N_UNKNOWNS]),
}

/// A solved, column-scaled symmetric system.
struct Scaled {
    /// sqrt of the diagonal (1 for held unknowns).
    scale: Vec6,
    /// The scaled matrix with held rows/columns replaced by the identity.
    matrix: Mat6,
}

impl Problem<'_> {
    /// Model F_A and its Jacobian with respect to (m, M, B, f) at one pose.
    /// `None` when A is closer than [`MIN_SUPPORT_DISTANCE_M`] to B.
    fn model(&self, pose: &StaticPose, theta: &Vec6) -> Option<(Vec3, Jac)> {
        let r = support_of(theta) - pose.ujoint_m;
        let a = r.norm();
        if below_or_nan(a, MIN_SUPPORT_DISTANCE_M) {
            return None;
        }
        let u = r / a;
        let g = self.gravity;
        let gu = g.dot(&u);
        let g_perp = g - u * gu;
        let (m, moment, f) = (
            at6(theta, I_MASS),
            at6(theta, I_MOMENT),
            at6(theta, I_FRICTION),
        );
        let sigma = pose.slide_sign;
        let force = -g * m + g_perp * (moment / a) + u * (sigma * f);
        // d u / d B = P / a with P = I - u u^T; d a / d B = u^T.
        let p = Mat3::identity() - u * u.transpose();
        let d_support = -(g_perp * u.transpose() + u * g_perp.transpose() + p * gu)
            * (moment / (a * a))
            + p * (sigma * f / a);
        let jac = Jac::from_columns(&[
            -g,
            g_perp / a,
            d_support.column(0).into_owned(),
            d_support.column(1).into_owned(),
            d_support.column(2).into_owned(),
            u * sigma,
        ]);
        Some((force, jac))
    }

    fn measured_n(&self, pose: &StaticPose) -> Vec3 {
        ujoint_force_n(self.calibration, &pose.mean_reading_n, self.tare_n)
    }

    fn weight(&self, pose: &StaticPose) -> Mat3 {
        self.whitening * sqrt(f64::from(pose.samples))
    }

    /// Chi-square at `theta`; an error when a pose is too close to B.
    fn cost(&self, theta: &Vec6) -> Result<f64, SupportError> {
        let mut cost = 0.0;
        for (index, pose) in self.poses.iter().enumerate() {
            let Some((force, _)) = self.model(pose, theta) else {
                return Err(too_close(index, pose, theta));
            };
            let r = self.weight(pose) * (self.measured_n(pose) - force);
            cost += r.norm_squared();
        }
        Ok(cost)
    }

    /// Normal equations over the free unknowns at `theta`.
    fn normal(&self, theta: &Vec6, free: &[bool; N_UNKNOWNS]) -> Result<Normal, SupportError> {
        let mask = Mat6::from_diagonal(&indicator(free, true));
        let mut out = Normal {
            matrix: Mat6::zeros(),
            rhs: Vec6::zeros(),
            cost: 0.0,
            raw_sq_n2: 0.0,
            cost_floor: 0.0,
        };
        for (index, pose) in self.poses.iter().enumerate() {
            let Some((force, jac)) = self.model(pose, theta) else {
                return Err(too_close(index, pose, theta));
            };
            let w = self.weight(pose);
            let measured = self.measured_n(pose);
            let e = measured - force;
            let r = w * e;
            out.cost_floor += COST_FLOOR * (w * measured).norm_squared();
            let a = w * jac * mask;
            out.matrix += a.transpose() * a;
            out.rhs += a.transpose() * r;
            out.cost += r.norm_squared();
            out.raw_sq_n2 += e.norm_squared();
        }
        Ok(out)
    }
}

fn too_close(index: usize, pose: &StaticPose, theta: &Vec6) -> SupportError {
    SupportError::UJointAtSupport {
        pose: index,
        distance_m: support_of(theta).metric_distance(&pose.ujoint_m),
    }
}

/// The fitted B must stay finite and within `limit_m` of the configured one.
fn check_shift(theta: &Vec6, configured: &Vec3, limit_m: f64) -> Result<(), SupportError> {
    let shift = support_of(theta).metric_distance(configured);
    if theta.iter().all(|x| x.is_finite()) && shift <= limit_m {
        Ok(())
    } else {
        Err(SupportError::Diverged {
            shift_m: if shift.is_finite() {
                shift
            } else {
                f64::INFINITY
            },
        })
    }
}

fn support_of(theta: &Vec6) -> Vec3 {
    Vec3::new(
        at6(theta, I_SUPPORT),
        at6(theta, I_SUPPORT + 1),
        at6(theta, I_SUPPORT + 2),
    )
}

fn unknown_name(k: usize) -> &'static str {
    match k {
        I_MASS => "mass_kg",
        I_MOMENT => "moment_kgm",
        2 => "support_x_m",
        3 => "support_y_m",
        4 => "support_z_m",
        _ => "friction_n",
    }
}

/// Column-scales `matrix` over the free unknowns (unit diagonal) and puts the
/// identity in the held rows and columns. Errors when a free column is zero.
fn scale(matrix: &Mat6, free: &[bool; N_UNKNOWNS]) -> Result<Scaled, SupportError> {
    for (k, &is_free) in free.iter().enumerate() {
        let diag = at(matrix, k, k);
        if is_free && (below_or_nan(diag, f64::MIN_POSITIVE) || !diag.is_finite()) {
            return Err(undetermined(k, 0.0));
        }
    }
    let free_mask = indicator(free, true);
    let held_mask = indicator(free, false);
    // sqrt of the diagonal for free unknowns, 1 for held ones.
    let scale = matrix.diagonal().map(sqrt).component_mul(&free_mask) + held_mask;
    let inv = Mat6::from_diagonal(&scale.map(|s| 1.0 / s).component_mul(&free_mask));
    let scaled = inv * matrix * inv + Mat6::from_diagonal(&held_mask);
    Ok(Scaled {
        scale,
        matrix: scaled,
    })
}

fn undetermined(k: usize, pivot: f64) -> SupportError {
    SupportError::Undetermined {
        unknown: unknown_name(k),
        pivot,
        hint: if k == I_FRICTION {
            " and slide the rod both ways (or turn the friction unknown off)"
        } else if k >= I_SUPPORT {
            ", tilt and turn the rod"
        } else {
            ""
        },
    }
}

/// Cholesky of a scaled matrix, refusing pivots below [`MIN_PIVOT`].
fn factor(matrix: &Mat6) -> Result<Cholesky<f64, nalgebra::Const<N_UNKNOWNS>>, SupportError> {
    let Some(chol) = Cholesky::new(*matrix) else {
        return Err(undetermined(worst_pivot(matrix), 0.0));
    };
    for (k, &diag) in chol.l_dirty().diagonal().iter().enumerate() {
        let pivot = diag * diag;
        if below_or_nan(pivot, MIN_PIVOT) {
            return Err(undetermined(k, pivot));
        }
    }
    Ok(chol)
}

/// For a matrix Cholesky refused: the first unknown whose pivot fails, by a plain
/// elimination that does not stop.
fn worst_pivot(matrix: &Mat6) -> usize {
    let mut m = *matrix;
    for k in 0..N_UNKNOWNS {
        let pivot = at(&m, k, k);
        if below_or_nan(pivot, MIN_PIVOT) {
            return k;
        }
        // Eliminate column k below the pivot: m -= m_col m_row / pivot, restricted
        // to the trailing block (rows and columns after k).
        let col = Vec6::from_fn(|i, _| if i > k { at(&m, i, k) } else { 0.0 });
        let row = Vec6::from_fn(|j, _| if j > k { at(&m, k, j) } else { 0.0 });
        m -= col * row.transpose() / pivot;
    }
    0
}

/// Covariance of the unknowns from a normal matrix (held rows/columns zero).
fn covariance(matrix: &Mat6, free: &[bool; N_UNKNOWNS]) -> Result<(Mat6, f64), SupportError> {
    let scaled = scale(matrix, free)?;
    let chol = factor(&scaled.matrix)?;
    let unscale = Mat6::from_diagonal(
        &scaled
            .scale
            .map(|s| 1.0 / s)
            .component_mul(&indicator(free, true)),
    );
    let cov = unscale * chol.inverse() * unscale;
    // Condition of the scaled Jacobian: sqrt of the eigenvalue ratio of the
    // scaled normal matrix (the identity rows of held unknowns do not change it,
    // since a unit-diagonal matrix's eigenvalues bracket 1).
    let eig = scaled.matrix.symmetric_eigenvalues();
    let (lo, hi) = (eig.min(), eig.max());
    let condition = if lo > 0.0 {
        sqrt(hi / lo)
    } else {
        f64::INFINITY
    };
    Ok((cov, condition))
}

impl SupportCalibration {
    /// A calibration with no poses, for the robot `cal` (its support point is the
    /// configured B), the sensor noise `noise` and the sensor's force tare
    /// `bias_n` (sensor frame, measured with no rod in the U-joint).
    pub fn new(
        cal: &Calibration,
        noise: &SensorNoise,
        bias_n: Vec3,
        options: SupportOptions,
    ) -> Result<Self, SupportError> {
        check_finite(&bias_n, |value| SettingError::Invalid {
            field: "bias_n",
            value,
            why: "each tare component must be finite",
        })?;
        if !(options.max_support_std_m.is_finite() && options.max_support_std_m > 0.0) {
            return Err(SettingError::Invalid {
                field: "max_support_std_m",
                value: options.max_support_std_m,
                why: "must be finite and > 0",
            }
            .into());
        }
        if options.max_iterations == 0 {
            return Err(SettingError::Invalid {
                field: "max_iterations",
                value: 0.0,
                why: "must be >= 1",
            }
            .into());
        }
        let covariance = noise.base_covariance_n2(&cal.sensor_rotation());
        let whitening = Cholesky::new(covariance)
            .and_then(|chol| chol.l().solve_lower_triangular(&Mat3::identity()))
            .filter(|w| w.iter().all(|x| x.is_finite()));
        let Some(whitening) = whitening else {
            return Err(SettingError::Invalid {
                field: "noise_n",
                value: noise.std_n().min(),
                why: "the noise covariance in the base frame is not positive definite",
            }
            .into());
        };
        let empty = StaticPose {
            ujoint_m: Vec3::zeros(),
            mean_reading_n: Vec3::zeros(),
            samples: 1,
            slide_sign: 0.0,
        };
        Ok(Self {
            poses: [empty; SUPPORT_CAPACITY],
            len: 0,
            calibration: *cal,
            whitening,
            tare_n: bias_n,
            options,
        })
    }

    /// Adds one static pose. Errors when full or when the pose has a NaN or
    /// infinite value, no samples, or a slide sign other than -1, 0, +1.
    pub fn push(&mut self, pose: &StaticPose) -> Result<(), SupportError> {
        let index = self.len;
        if index >= SUPPORT_CAPACITY {
            return Err(SupportError::Full {
                capacity: SUPPORT_CAPACITY,
            });
        }
        pose.check()
            .map_err(|error| SupportError::Pose { pose: index, error })?;
        let Some(slot) = self.poses.get_mut(index) else {
            return Err(SupportError::Full {
                capacity: SUPPORT_CAPACITY,
            });
        };
        *slot = *pose;
        self.len = index + 1;
        Ok(())
    }

    /// Number of poses held.
    pub fn len(&self) -> usize {
        self.len
    }

    /// No poses held.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Removes all poses (the settings stay).
    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// The options in use.
    pub fn options(&self) -> &SupportOptions {
        &self.options
    }

    /// Fits m, M, B and f to the poses held (MODEL.md 5.1).
    ///
    /// Starts from the configured B and the linear (m, M, f) estimate at it (one
    /// Gauss-Newton step from zero with B held), decides which components of B
    /// the poses determine, runs Levenberg-Marquardt (analytic Jacobian, column
    /// scaling, at most `max_iterations` iterations per pass), re-checks that
    /// decision along the way and at the solution, and fits again when it
    /// changes (at most [`MAX_PASSES`] passes). A component that becomes held
    /// goes back to its configured value.
    pub fn fit(&self) -> Result<SupportFit, SupportError> {
        let poses = self.poses.get(..self.len).unwrap_or(&[]);
        let problem = Problem {
            poses,
            calibration: &self.calibration,
            whitening: &self.whitening,
            tare_n: &self.tare_n,
            gravity: self.calibration.gravity_mps2(),
        };
        let configured = self.calibration.support_m();
        let mut theta = Vec6::new(0.0, 0.0, configured.x, configured.y, configured.z, 0.0);

        let friction = self.options.friction;
        let base_free = [true, true, false, false, false, friction];
        self.check_count(&base_free)?;
        // Linear estimate at the configured B: the model is linear in (m, M, f),
        // so one Gauss-Newton step from zero solves it exactly.
        let normal = problem.normal(&theta, &base_free)?;
        let step = solve(&normal, &base_free, 0.0)?;
        theta += step;
        let mut iterations = 0u32;

        let mut free = base_free;
        if self.options.calibrate_support {
            free = self.decide(&problem, &theta, friction)?;
            let mut passes = 1u32;
            loop {
                self.check_count(&free)?;
                let last_pass = passes >= MAX_PASSES;
                let (accepted, end) =
                    self.levenberg_marquardt(&problem, &mut theta, &free, !last_pass)?;
                iterations = iterations.saturating_add(accepted);
                let again = match end {
                    PassEnd::Converged if !last_pass => self.decide(&problem, &theta, friction)?,
                    PassEnd::Converged => free,
                    PassEnd::Changed(again) => again,
                };
                if again == free {
                    break;
                }
                // Newly held components go back to their configured value.
                for (k, &value) in configured.iter().enumerate() {
                    let idx = I_SUPPORT + k;
                    if free.get(idx) == Some(&true)
                        && again.get(idx) == Some(&false)
                        && let Some(slot) = theta.get_mut(idx)
                    {
                        *slot = value;
                    }
                }
                free = again;
                passes += 1;
            }
        }
        self.result(&problem, &theta, &free, iterations)
    }

    fn check_count(&self, free: &[bool; N_UNKNOWNS]) -> Result<(), SupportError> {
        let unknowns = free.iter().filter(|&&f| f).count();
        let equations = 3 * self.len;
        if equations <= unknowns {
            return Err(SupportError::TooFewPoses {
                poses: self.len,
                equations,
                unknowns,
            });
        }
        Ok(())
    }

    /// Which unknowns to fit at `theta`: m, M (and f) always; of B, the largest
    /// set of components whose standard errors are all within
    /// `max_support_std_m` (among sets of equal size, the one with the smallest
    /// largest standard error).
    fn decide(
        &self,
        problem: &Problem<'_>,
        theta: &Vec6,
        friction: bool,
    ) -> Result<[bool; N_UNKNOWNS], SupportError> {
        let all = [true, true, true, true, true, friction];
        let normal = problem.normal(theta, &all)?;
        let mut best: Option<([bool; N_UNKNOWNS], usize, f64)> = None;
        for subset in 0u8..8 {
            let mut free = [true, true, false, false, false, friction];
            for k in 0..3 {
                if subset & (1 << k) != 0
                    && let Some(slot) = free.get_mut(I_SUPPORT + k)
                {
                    *slot = true;
                }
            }
            let size = subset.count_ones() as usize;
            let mut masked = normal.matrix;
            for (k, &is_free) in free.iter().enumerate() {
                if !is_free {
                    masked.row_mut(k).fill(0.0);
                    masked.column_mut(k).fill(0.0);
                }
            }
            let Ok((cov, _)) = covariance(&masked, &free) else {
                continue;
            };
            let mut worst = 0.0f64;
            let mut determined = true;
            for k in 0..3 {
                if free.get(I_SUPPORT + k) == Some(&true) {
                    let std = sqrt(non_negative(at(&cov, I_SUPPORT + k, I_SUPPORT + k)));
                    // NaN fails this too (f64::max would drop it).
                    determined &= std <= self.options.max_support_std_m;
                    worst = worst.max(std);
                }
            }
            if !determined {
                continue;
            }
            let better = match best {
                None => true,
                Some((_, best_size, best_worst)) => {
                    size > best_size || (size == best_size && worst < best_worst)
                }
            };
            if better {
                best = Some((free, size, worst));
            }
        }
        match best {
            Some((free, _, _)) => Ok(free),
            // Not even (m, M, f) alone is determined: say which unknown fails.
            None => {
                let base = [true, true, false, false, false, friction];
                let normal = problem.normal(theta, &base)?;
                covariance(&normal.matrix, &base)?;
                Ok(base)
            }
        }
    }

    /// Levenberg-Marquardt from `theta` over the free unknowns; returns the
    /// number of accepted steps and how the pass ended.
    ///
    /// Stops when the undamped Gauss-Newton step predicts a cost decrease below
    /// [`COST_TOL`] times the cost (plus the cost's rounding floor), when an
    /// accepted step lowered the cost by less than that, or when a trial step is
    /// below [`STEP_TOL`] in column-scaled units. With `recheck`, the choice of
    /// the free components of B is re-made after every accepted step, and the pass
    /// ends as soon as it changes (a component can be determined at the configured
    /// B only because of the configured error, e.g. B_z through a tilt that the
    /// fit then removes).
    fn levenberg_marquardt(
        &self,
        problem: &Problem<'_>,
        theta: &mut Vec6,
        free: &[bool; N_UNKNOWNS],
        recheck: bool,
    ) -> Result<(u32, PassEnd), SupportError> {
        let configured = self.calibration.support_m();
        let friction = self.options.friction;
        let mut lambda = LAMBDA_START;
        let mut accepted = 0u32;
        let mut last_step = f64::INFINITY;
        for _ in 0..self.options.max_iterations {
            if recheck && accepted > 0 {
                let again = self.decide(problem, theta, friction)?;
                if again != *free {
                    return Ok((accepted, PassEnd::Changed(again)));
                }
            }
            let normal = problem.normal(theta, free)?;
            let tolerance = COST_TOL * normal.cost + normal.cost_floor;
            if normal.cost <= normal.cost_floor {
                return Ok((accepted, PassEnd::Converged));
            }
            // What the undamped step could gain, to first order.
            let gauss_newton = solve(&normal, free, 0.0)?;
            if gauss_newton.dot(&normal.rhs) <= tolerance {
                return Ok((accepted, PassEnd::Converged));
            }
            let scaled = scale(&normal.matrix, free)?;
            loop {
                let step = solve(&normal, free, lambda)?;
                let scaled_step = step.component_mul(&scaled.scale).norm();
                last_step = scaled_step;
                let trial = *theta + step;
                let cost = check_shift(&trial, &configured, MAX_SUPPORT_SHIFT_M)
                    .and_then(|()| problem.cost(&trial));
                match cost {
                    Ok(cost) if cost.is_finite() && cost < normal.cost => {
                        *theta = trial;
                        accepted = accepted.saturating_add(1);
                        lambda = (lambda * 0.1).max(LAMBDA_MIN);
                        if normal.cost - cost <= tolerance || scaled_step <= STEP_TOL {
                            return Ok((accepted, PassEnd::Converged));
                        }
                        break;
                    }
                    other => {
                        // The fit keeps pushing B out of its allowed region.
                        let out_of_region = other.err();
                        if scaled_step <= STEP_TOL {
                            // Rounding: no smaller step can matter.
                            return match out_of_region {
                                Some(error) => Err(error),
                                None => Ok((accepted, PassEnd::Converged)),
                            };
                        }
                        lambda *= 10.0;
                        if lambda > LAMBDA_MAX {
                            // No downhill step even with the heaviest damping.
                            return Err(out_of_region.unwrap_or(SupportError::NotConverged {
                                iterations: self.options.max_iterations,
                                step: scaled_step,
                            }));
                        }
                    }
                }
            }
        }
        Err(SupportError::NotConverged {
            iterations: self.options.max_iterations,
            step: last_step,
        })
    }

    fn result(
        &self,
        problem: &Problem<'_>,
        theta: &Vec6,
        free: &[bool; N_UNKNOWNS],
        iterations: u32,
    ) -> Result<SupportFit, SupportError> {
        // A solution on the edge of the allowed region is no minimum: the cost
        // still falls outside it.
        check_shift(
            theta,
            &self.calibration.support_m(),
            SHIFT_EDGE * MAX_SUPPORT_SHIFT_M,
        )?;
        let support = support_of(theta);
        let normal = problem.normal(theta, free)?;
        let (cov, condition) = covariance(&normal.matrix, free)?;
        let mass = at6(theta, I_MASS);
        if mass.is_nan() || mass <= 0.0 {
            return Err(SupportError::NonPositiveMass { mass_kg: mass });
        }
        let moment = at6(theta, I_MOMENT);
        let unknowns = free.iter().filter(|&&f| f).count();
        let equations = 3 * self.len;
        let dof = equations.saturating_sub(unknowns).max(1);
        let chi2_dof = normal.cost / dof as f64;
        // Never claim more than the noise model, nor less than the scatter shows.
        let inflation = chi2_dof.max(1.0);
        let std = |k: usize| sqrt(non_negative(at(&cov, k, k) * inflation));
        let var = |i: usize, j: usize| at(&cov, i, j) * inflation;
        let mut held = [true; 3];
        let mut support_std = [None; 3];
        for k in 0..3 {
            if free.get(I_SUPPORT + k) == Some(&true) {
                if let Some(h) = held.get_mut(k) {
                    *h = false;
                }
                if let Some(s) = support_std.get_mut(k) {
                    *s = Some(std(I_SUPPORT + k));
                }
            }
        }
        let friction = self.options.friction;
        let fit = SupportFit {
            mass_kg: mass,
            mass_std_kg: std(I_MASS),
            com_m: moment / mass,
            com_std_m: com_std_m(
                mass,
                moment,
                var(I_MASS, I_MASS),
                var(I_MOMENT, I_MOMENT),
                var(I_MASS, I_MOMENT),
            ),
            moment_kgm: moment,
            moment_std_kgm: std(I_MOMENT),
            support_m: support,
            support_std_m: support_std,
            held,
            friction_n: friction.then_some(at6(theta, I_FRICTION)),
            friction_std_n: friction.then(|| std(I_FRICTION)),
            chi2_dof,
            residual_rms_n: sqrt(normal.raw_sq_n2 / equations.max(1) as f64),
            condition,
            iterations,
            poses: u32::try_from(self.len).unwrap_or(u32::MAX),
        };
        check_result(&fit)?;
        Ok(fit)
    }
}

/// Every number of a fit is finite: finite but huge readings can overflow the
/// cost (then chi2_dof and the standard errors are infinite, or NaN).
fn check_result(fit: &SupportFit) -> Result<(), SupportError> {
    let [sx, sy, sz] = fit.support_std_m.map(|s| s.unwrap_or(0.0));
    let values = [
        ("mass_kg", fit.mass_kg),
        ("mass_std_kg", fit.mass_std_kg),
        ("com_m", fit.com_m),
        ("com_std_m", fit.com_std_m),
        ("moment_kgm", fit.moment_kgm),
        ("moment_std_kgm", fit.moment_std_kgm),
        ("support_m.x", fit.support_m.x),
        ("support_m.y", fit.support_m.y),
        ("support_m.z", fit.support_m.z),
        ("support_std_m.x", sx),
        ("support_std_m.y", sy),
        ("support_std_m.z", sz),
        ("friction_n", fit.friction_n.unwrap_or(0.0)),
        ("friction_std_n", fit.friction_std_n.unwrap_or(0.0)),
        ("chi2_dof", fit.chi2_dof),
        ("residual_rms_n", fit.residual_rms_n),
        ("condition", fit.condition),
    ];
    match values.iter().find(|(_, v)| !v.is_finite()) {
        Some(&(field, value)) => Err(SupportError::NonFiniteResult { field, value }),
        None => Ok(()),
    }
}

/// The damped Gauss-Newton step `(N_s + lambda I) d_s = b_s` in column-scaled
/// unknowns, returned unscaled (zero for held unknowns).
fn solve(normal: &Normal, free: &[bool; N_UNKNOWNS], lambda: f64) -> Result<Vec6, SupportError> {
    let scaled = scale(&normal.matrix, free)?;
    let free_mask = indicator(free, true);
    let damped = scaled.matrix + Mat6::from_diagonal(&(free_mask * lambda));
    let chol = factor(&damped)?;
    let rhs = normal.rhs.component_div(&scaled.scale);
    Ok(chol
        .solve(&rhs)
        .component_div(&scaled.scale)
        .component_mul(&free_mask))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]
    use super::*;

    /// The analytic Jacobian agrees with central differences.
    #[test]
    fn jacobian_matches_finite_differences() {
        let cal = Calibration::new(&crate::CalibrationSpec {
            p_home_m: Vec3::zeros(),
            ujoint_offset_m: Vec3::zeros(),
            sensor_offset_m: Vec3::zeros(),
            sensor_rotation: Mat3::identity(),
            support_m: Vec3::new(0.45, 0.2, 0.0),
            gravity_mps2: Vec3::new(0.0, -9.80665, 0.0),
        })
        .unwrap();
        let whitening = Mat3::identity();
        let tare = Vec3::zeros();
        let pose = StaticPose {
            ujoint_m: Vec3::new(0.36, 0.15, -0.03),
            mean_reading_n: Vec3::zeros(),
            samples: 1,
            slide_sign: -1.0,
        };
        let poses = [pose];
        let problem = Problem {
            poses: &poses,
            calibration: &cal,
            whitening: &whitening,
            tare_n: &tare,
            gravity: cal.gravity_mps2(),
        };
        let theta = Vec6::from_column_slice(&[2.1, 0.23, 0.452, 0.198, 0.003, 0.37]);
        let (_, jac) = problem.model(&pose, &theta).unwrap();
        for k in 0..N_UNKNOWNS {
            let h = 1e-6;
            let mut plus = theta;
            let mut minus = theta;
            plus[k] += h;
            minus[k] -= h;
            let (fp, _) = problem.model(&pose, &plus).unwrap();
            let (fm, _) = problem.model(&pose, &minus).unwrap();
            let numeric = (fp - fm) / (2.0 * h);
            let analytic = jac.column(k).into_owned();
            let err = (numeric - analytic).norm();
            assert!(
                err < 1e-6 * (1.0 + analytic.norm()),
                "column {k}: analytic {analytic:?} numeric {numeric:?}"
            );
        }
    }
}
