//! Identification of the manipulator's mass m and centre of mass c from static
//! poses with nothing touching the tip (MODEL.md 5). The article's simplified
//! straight-line method (MODEL.md 5.2) is [`crate::line_fit`] (re-exported here).
//!
//! [`Identification`] is a streaming weighted least-squares solver: each pose
//! adds three rows (two moment rows about B and the force row along the rod),
//! whitened by the inverse of their noise covariance, to a fixed-size upper
//! triangular factor by Givens rotations (never normal equations). The estimate,
//! its standard errors, the residuals and the condition number are available
//! after every pose.
//!
//! Conventions (MODEL.md 4, 5): `F_A = -R_0s (f_s - b)` is what the robot
//! applies to the rod at A, `a = |B - A|`, `u = (B - A) / a`; the unknowns are
//! m, M = m c, and optionally the support friction f (coefficient: the sign of
//! the last slide) and the force bias across gravity (two components in the
//! sensor frame, basis [`bias_across_gravity_basis`]). The bias along gravity
//! cannot be told from m: the sensor must be tared with the rod detached.
//!
//! A pose whose slide sign is unknown ([`crate::SlideSign::Unknown`]: no slide
//! seen before it) has no friction coefficient. When friction is estimated it
//! contributes only its two moment rows, which do not involve f; its axial row
//! is left out (MODEL.md 5: never a coefficient of 0). Without the friction
//! unknown all three rows are used (the axial row assumes no friction).
//!
//! Layout: the factor always has the five unknowns (m, M, f, bias e1, bias e2)
//! and the right-hand side at fixed columns; an unknown that is not estimated
//! gets the exact row "it is 0" at construction, which leaves it 0 and the
//! others as if it did not exist (the factor stays block diagonal).

pub mod dynamic;

use crate::linalg;
use crate::{
    Calibration, MIN_SUPPORT_DISTANCE_M, Mat3, PoseInputError, SensorNoise, StaticPose, Vec3,
    check_finite, com_std_m, non_negative,
};
use nalgebra::{ComplexField, SMatrix, SVector};
use sar_kinematics::Shown;

/// Largest accepted condition number of the weighted design matrix after its
/// columns are scaled to unit norm. Above it the problem is reported as rank
/// deficient ([`IdentificationError::IllConditioned`]): the poses cannot tell
/// the unknowns apart (e.g. all at one distance and direction, or the friction
/// unknown with no slide recorded). At 1e8 a relative error of 1e-16 in the
/// data still leaves about 8 significant digits in the estimate.
pub const MAX_CONDITION: f64 = 1e8;

/// Most unknowns: m, M, f and two bias components.
const MAX_UNKNOWNS: usize = 5;
/// Width of the augmented factor: the unknowns and the right-hand side.
const WIDTH: usize = MAX_UNKNOWNS + 1;

/// One augmented row: m, M, f, bias e1, bias e2, then the right-hand side.
type Row = [f64; WIDTH];
/// An upper triangular augmented factor T with |T z| = |[A y] z| for every z.
type Factor = [Row; WIDTH];
/// The unknowns' square block of the factor.
type Square = SMatrix<f64, MAX_UNKNOWNS, MAX_UNKNOWNS>;
/// A vector over the unknowns (m, M, f, bias e1, bias e2).
type Unknowns = SVector<f64, MAX_UNKNOWNS>;

/// Why a setting, a pose or a solve was refused.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum IdentificationError {
    /// An input (or a value computed from finite inputs) is NaN or infinite.
    #[error("{field} is not finite ({value})")]
    NonFinite {
        /// Which value.
        field: &'static str,
        /// The offending value.
        value: f64,
    },
    /// A pose's own values are invalid ([`StaticPose::check`]).
    #[error(transparent)]
    Pose(#[from] PoseInputError),
    /// The U-joint centre A is (almost) at the support B: u is undefined.
    #[error(
        "the U-joint centre is {} m from the support, below {min_m} m",
        Shown(*.distance_m)
    )]
    SupportTooClose {
        /// |B - A|, m.
        distance_m: f64,
        /// [`MIN_SUPPORT_DISTANCE_M`].
        min_m: f64,
    },
    /// A sensor noise standard deviation whose square is not a positive normal number.
    #[error("sensor noise std {std_n} N cannot be squared into a usable variance")]
    NoiseOutOfRange {
        /// The standard deviation, N.
        std_n: f64,
    },
    /// The noise covariance of a pose's rows is not positive definite in floating point.
    #[error("the noise covariance of a pose is not positive definite (samples = {samples})")]
    DegenerateNoise {
        /// The pose's sample count.
        samples: u32,
    },
    /// The pose counter would overflow.
    #[error("too many poses: {poses} already accumulated")]
    TooManyPoses {
        /// Poses accumulated so far.
        poses: u32,
    },
    /// Fewer rows (or poses) than unknowns.
    #[error("{rows} rows from {poses} poses cannot determine {needed} unknowns")]
    TooFewRows {
        /// Rows accumulated.
        rows: u32,
        /// Poses accumulated.
        poses: u32,
        /// Rows (or poses, for the line fit) needed at least.
        needed: u32,
    },
    /// The poses cannot tell the unknowns apart: the condition number (after
    /// scaling the columns to unit norm) is above the limit, or infinite.
    #[error("rank deficient or ill conditioned: condition number {condition:e} above {limit:e}")]
    IllConditioned {
        /// The condition number (may be infinite).
        condition: f64,
        /// [`MAX_CONDITION`].
        limit: f64,
    },
    /// The estimated mass is zero or negative: c = M / m is not defined.
    #[error("the estimated mass is {} kg, not positive", Shown(*.mass_kg))]
    NonPositiveMass {
        /// The estimate, kg.
        mass_kg: f64,
    },
    /// The line fit's tolerance on horizontality is not in [0, pi/2).
    #[error("horizontal_tolerance_rad = {tolerance_rad} is not in [0, pi/2)")]
    InvalidTolerance {
        /// The value given.
        tolerance_rad: f64,
    },
    /// The line fit refuses a pose whose rod is not horizontal (with d = 0 this
    /// is the same as A not at the support's height).
    #[error(
        "the rod is tilted {} rad from horizontal, above the tolerance {tolerance_rad} rad",
        Shown(*.tilt_rad)
    )]
    NotHorizontal {
        /// The rod's angle from the horizontal plane, rad.
        tilt_rad: f64,
        /// The tolerance, rad.
        tolerance_rad: f64,
    },
}

/// Which extra unknowns the identification estimates besides m and M.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct IdentificationOptions {
    /// Estimate the force bias across gravity (two components, sensor frame,
    /// basis [`bias_across_gravity_basis`]) on top of the tare.
    pub bias_across_gravity: bool,
    /// Estimate the support's Coulomb friction f (the axial row gets
    /// `slide_sign * f`); without it the axial row assumes a frictionless support.
    pub friction: bool,
}

/// The estimate, with standard errors and fit diagnostics.
///
/// Standard errors come from the inverse of the weighted triangular factor
/// (the noise model's covariance of the estimate), multiplied by
/// `max(1, sqrt(chi2_dof))` when there is at least one degree of freedom: never
/// smaller than the noise model says, and widened when the residuals scatter
/// more than it (a noise model that is too optimistic, or a model that does not
/// fit). With no degree of freedom they are the noise model's alone.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IdentificationResult {
    /// m, kg.
    pub mass_kg: f64,
    /// Standard error of m, kg.
    pub mass_std_kg: f64,
    /// c = M / m, the centre of mass from A along the rod, m.
    pub com_m: f64,
    /// Standard error of c (first order, including the m-M covariance), m.
    pub com_std_m: f64,
    /// M = m c, kg m.
    pub moment_kgm: f64,
    /// Standard error of M, kg m.
    pub moment_std_kgm: f64,
    /// The force bias across gravity, sensor frame, in the basis
    /// [`bias_across_gravity_basis`], N (if estimated). It is added to the tare.
    pub bias_across_n: Option<[f64; 2]>,
    /// Its standard errors, N.
    pub bias_across_std_n: Option<[f64; 2]>,
    /// The support's friction f, N (if estimated; positive for a support that resists).
    pub friction_n: Option<f64>,
    /// Its standard error, N.
    pub friction_std_n: Option<f64>,
    /// RMS of the unweighted row residuals at the estimate, N. The three rows of
    /// a pose are F_A in an orthonormal basis, so this is the RMS per component
    /// of the part of F_A the model does not explain.
    pub residual_rms_n: f64,
    /// Weighted residual sum of squares / (rows - unknowns); 0 when rows == unknowns.
    pub chi2_dof: f64,
    /// Condition number of the weighted design matrix after scaling its columns
    /// to unit norm.
    pub condition: f64,
    /// Poses used.
    pub poses: u32,
    /// Rows used (3 per pose).
    pub rows: u32,
}

/// The basis across gravity, in the sensor frame, in which
/// [`IdentificationResult::bias_across_n`] is written: with `gs = R_0s^T g / |g|`
/// and `h` the sensor axis (x, y, z; the first on a tie) with the smallest
/// `|h . gs|`, `e1 = unit(h - (h . gs) gs)` and `e2 = gs x e1`. For an
/// unrotated sensor and `g` along -Y this is (x, z).
pub fn bias_across_gravity_basis(cal: &Calibration) -> [Vec3; 2] {
    let gravity_s = cal.sensor_rotation().transpose() * cal.gravity_mps2();
    // |g| >= 0.1 for a valid calibration.
    let down = gravity_s / gravity_s.norm();
    let (e1, e2) = basis_across(&down);
    [e1, e2]
}

/// An orthonormal basis (e1, e2) across the unit vector `n`, with
/// e2 = n x e1 and e1 the coordinate axis least aligned with n, made
/// perpendicular to it. Never degenerate for a unit n (|h - (h.n) n| >= sqrt(2/3)).
fn basis_across(n: &Vec3) -> (Vec3, Vec3) {
    let (ax, ay, az) = (n.x.abs(), n.y.abs(), n.z.abs());
    let helper = if ax <= ay && ax <= az {
        Vec3::x()
    } else if ay <= az {
        Vec3::y()
    } else {
        Vec3::z()
    };
    let across = helper - n * n.dot(&helper);
    let e1 = across / across.norm();
    let e2 = n.cross(&e1);
    (e1, e2)
}

/// The error for a non-finite `field`, for [`check_finite`].
pub(crate) fn non_finite(field: &'static str) -> impl FnOnce(f64) -> IdentificationError {
    move |value| IdentificationError::NonFinite { field, value }
}

/// Checks a pose and returns (u, a) with a = |B - A|, u = (B - A) / a.
pub(crate) fn pose_geometry(
    pose: &StaticPose,
    support_m: &Vec3,
) -> Result<(Vec3, f64), IdentificationError> {
    pose.check()?;
    let r = support_m - pose.ujoint_m;
    let a = r.norm();
    check_finite(&[a], non_finite("support distance"))?;
    if a < MIN_SUPPORT_DISTANCE_M {
        return Err(IdentificationError::SupportTooClose {
            distance_m: a,
            min_m: MIN_SUPPORT_DISTANCE_M,
        });
    }
    Ok((r / a, a))
}

/// Adds one augmented row to an upper triangular factor by Givens rotations.
/// Keeps the diagonal >= 0. Index-free: the pivot of factor row k and the
/// incoming entry k are the first pair after skipping k columns.
fn givens_add(factor: &mut Factor, mut row: Row) {
    for (k, factor_row) in factor.iter_mut().enumerate() {
        let mut pairs = factor_row.iter_mut().zip(row.iter_mut()).skip(k);
        // Every factor row has WIDTH columns and k < WIDTH: always a pair.
        let Some((pivot, incoming)) = pairs.next() else {
            break;
        };
        if *incoming == 0.0 {
            continue;
        }
        let radius = ComplexField::hypot(*pivot, *incoming);
        let (cos, sin) = (*pivot / radius, *incoming / radius);
        *pivot = radius;
        *incoming = 0.0;
        for (kept, added) in pairs {
            let (t, r) = (*kept, *added);
            *kept = cos * t + sin * r;
            *added = cos * r - sin * t;
        }
    }
}

/// The factor as a matrix.
fn as_matrix(factor: &Factor) -> SMatrix<f64, WIDTH, WIDTH> {
    // Rows of the array are rows of the matrix.
    SMatrix::<f64, WIDTH, WIDTH>::from_row_iterator(factor.iter().flatten().copied())
}

/// The streaming weighted least-squares identification of MODEL.md 5.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Identification {
    support_m: Vec3,
    gravity_mps2: Vec3,
    /// For R_0s and F_A = [`crate::ujoint_force_n`].
    calibration: Calibration,
    bias_n: Vec3,
    variance_n2: Vec3,
    bias_basis_s: [Vec3; 2],
    options: IdentificationOptions,
    /// Columns: m, M, f, bias e1, bias e2, rhs (see the module's layout).
    weighted: Factor,
    unweighted: Factor,
    poses: u32,
    rows: u32,
}

/// The factor with the exact row "this unknown is 0" for each unknown that is
/// not estimated (f when `!friction`, the two bias components when `!bias`).
fn initial_factor(friction: bool, bias: bool) -> Factor {
    let held = |estimated: bool| if estimated { 0.0 } else { 1.0 };
    let (f, b) = (held(friction), held(bias));
    [
        [0.0; WIDTH],
        [0.0; WIDTH],
        [0.0, 0.0, f, 0.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, b, 0.0, 0.0],
        [0.0, 0.0, 0.0, 0.0, b, 0.0],
        [0.0; WIDTH],
    ]
}

impl Identification {
    /// Starts an empty identification.
    ///
    /// `cal` gives B (the configured support), g and R_0s; `bias_n` is the tare
    /// (sensor frame, N, measured with the rod detached); `noise` weights the rows.
    pub fn new(
        cal: &Calibration,
        noise: &SensorNoise,
        bias_n: Vec3,
        options: IdentificationOptions,
    ) -> Result<Self, IdentificationError> {
        check_finite(&bias_n, non_finite("bias_n"))?;
        let std_n = noise.std_n();
        let variance_n2 = std_n.component_mul(&std_n);
        for (&std, &var) in std_n.iter().zip(variance_n2.iter()) {
            if !(var.is_normal() && var > 0.0) {
                return Err(IdentificationError::NoiseOutOfRange { std_n: std });
            }
        }
        let factor = initial_factor(options.friction, options.bias_across_gravity);
        Ok(Self {
            support_m: cal.support_m(),
            gravity_mps2: cal.gravity_mps2(),
            calibration: *cal,
            bias_n,
            variance_n2,
            bias_basis_s: bias_across_gravity_basis(cal),
            options,
            weighted: factor,
            unweighted: factor,
            poses: 0,
            rows: 0,
        })
    }

    /// The options it was built with.
    pub fn options(&self) -> IdentificationOptions {
        self.options
    }

    /// How many unknowns are estimated (2 to 5).
    pub fn unknowns(&self) -> u32 {
        2 + u32::from(self.options.friction) + 2 * u32::from(self.options.bias_across_gravity)
    }

    /// Adds one static pose: its three rows, or (friction estimated and the
    /// slide sign unknown) its two moment rows. Validates it first; a refused
    /// pose leaves the state unchanged.
    pub fn add(&mut self, pose: &StaticPose) -> Result<(), IdentificationError> {
        let (u, a) = pose_geometry(pose, &self.support_m)?;
        // The axial row carries f: with friction estimated it needs a known sign.
        let (friction_coef, pose_rows) = match (self.options.friction, pose.slide_sign.sigma()) {
            (true, Some(sigma)) => (sigma, 3u32),
            // Unknown sign: the axial row is left out, its f entry never used.
            (true, None) => (0.0, 2),
            // f is not an unknown: its column stays zero.
            (false, _) => (0.0, 3),
        };
        let poses = self
            .poses
            .checked_add(1)
            .ok_or(IdentificationError::TooManyPoses { poses: self.poses })?;
        let rows = self
            .rows
            .checked_add(pose_rows)
            .ok_or(IdentificationError::TooManyPoses { poses: self.poses })?;
        let force_a_n =
            crate::ujoint_force_n(&self.calibration, &pose.mean_reading_n, &self.bias_n);
        check_finite(&force_a_n, non_finite("F_A"))?;
        let (design, g_r) = self.design_rows(&u, a, friction_coef, &force_a_n);
        let whitened = self.whiten(&g_r, &design, pose.samples)?;

        let mut weighted = self.weighted;
        let mut unweighted = self.unweighted;
        let as_row = |r: nalgebra::RowSVector<f64, WIDTH>| -> Row { r.transpose().into() };
        for (whitened_row, plain_row) in whitened
            .row_iter()
            .zip(design.row_iter())
            .take(pose_rows as usize)
        {
            givens_add(&mut weighted, as_row(whitened_row.into_owned()));
            givens_add(&mut unweighted, as_row(plain_row.into_owned()));
        }
        check_finite(
            weighted.iter().chain(unweighted.iter()).flatten(),
            non_finite("accumulated factor"),
        )?;
        self.weighted = weighted;
        self.unweighted = unweighted;
        self.poses = poses;
        self.rows = rows;
        Ok(())
    }

    /// One pose's rows of the design, `[A y]` (columns m, M, f, bias e1,
    /// bias e2, rhs), and `G R` (the rows' map from the sensor frame). G:
    /// rows p1.(u x v), p2.(u x v), u.v; orthonormal. The moment rows carry
    /// M / a, the axial row does not; only the axial row carries f.
    fn design_rows(
        &self,
        u: &Vec3,
        a: f64,
        friction_coef: f64,
        force_a_n: &Vec3,
    ) -> (SMatrix<f64, 3, WIDTH>, Mat3) {
        let (p1, p2) = basis_across(u);
        let g_rows = Mat3::from_rows(&[
            p1.cross(u).transpose(), // p1.(u x v) = v.(p1 x u)
            p2.cross(u).transpose(),
            u.transpose(),
        ]);
        let measured = g_rows * force_a_n;
        let gravity_rows = g_rows * self.gravity_mps2;
        let g_r = g_rows * self.calibration.sensor_rotation();
        let [e1, e2] = self.bias_basis_s;
        let bias = |e: &Vec3| {
            if self.options.bias_across_gravity {
                -(g_r * e)
            } else {
                Vec3::zeros()
            }
        };
        let design = SMatrix::<f64, 3, WIDTH>::from_columns(&[
            -gravity_rows,
            Vec3::new(gravity_rows.x / a, gravity_rows.y / a, 0.0),
            Vec3::new(0.0, 0.0, friction_coef),
            bias(&e1),
            bias(&e2),
            measured,
        ]);
        (design, g_r)
    }

    /// The rows whitened: covariance of the rows = G R diag(std^2 / K) R^T
    /// G^T. Its lower Cholesky factor is lower triangular, so the first two
    /// whitened rows do not depend on the third: dropping the axial row is
    /// exact.
    fn whiten(
        &self,
        g_r: &Mat3,
        design: &SMatrix<f64, 3, WIDTH>,
        samples: u32,
    ) -> Result<SMatrix<f64, 3, WIDTH>, IdentificationError> {
        let per_sample = Mat3::from_diagonal(&(self.variance_n2 / f64::from(samples)));
        let covariance = g_r * per_sample * g_r.transpose();
        let cholesky = covariance
            .cholesky()
            .ok_or(IdentificationError::DegenerateNoise { samples })?;
        cholesky
            .l()
            .solve_lower_triangular(design)
            .ok_or(IdentificationError::DegenerateNoise { samples })
    }

    /// Poses accumulated.
    pub fn poses(&self) -> u32 {
        self.poses
    }

    /// Rows accumulated (3 per pose, 2 for a pose whose axial row was left out).
    pub fn rows(&self) -> u32 {
        self.rows
    }

    /// The estimate from the poses so far.
    pub fn solve(&self) -> Result<IdentificationResult, IdentificationError> {
        let needed = self.unknowns();
        if self.rows < needed {
            return Err(IdentificationError::TooFewRows {
                rows: self.rows,
                poses: self.poses,
                needed,
            });
        }
        let ill = |condition: f64| IdentificationError::IllConditioned {
            condition,
            limit: MAX_CONDITION,
        };
        let weighted = as_matrix(&self.weighted);
        // R (5 x 5): the unknowns that are not estimated have an identity row
        // and column, so they neither change the solution nor (columns of unit
        // norm have singular values around 1) the scaled condition number.
        let r5: Square = weighted
            .fixed_view::<MAX_UNKNOWNS, MAX_UNKNOWNS>(0, 0)
            .into_owned();
        let rhs: Unknowns = weighted
            .fixed_view::<MAX_UNKNOWNS, 1>(0, MAX_UNKNOWNS)
            .into_owned();
        let condition = scaled_condition(&r5).map_err(ill)?;
        let theta = r5.solve_upper_triangular(&rhs).ok_or(ill(condition))?;
        let r_inv = r5
            .solve_upper_triangular(&Square::identity())
            .ok_or(ill(condition))?;
        let unit_covariance = r_inv * r_inv.transpose();

        // Residuals: |T (theta, -1)|^2 = |[A y] (theta, -1)|^2 = |A theta - y|^2.
        let [mass_kg, moment_kgm, friction_n, bias1_n, bias2_n]: [f64; MAX_UNKNOWNS] = theta.into();
        let z = SVector::<f64, WIDTH>::new(mass_kg, moment_kgm, friction_n, bias1_n, bias2_n, -1.0);
        let chi2 = (weighted * z).norm_squared();
        let unweighted_ss = (as_matrix(&self.unweighted) * z).norm_squared();
        let dof = self.rows - needed;
        let chi2_dof = if dof > 0 { chi2 / f64::from(dof) } else { 0.0 };
        // Never claim more than the noise model, nor less than the scatter shows.
        let scale = if dof > 0 { chi2_dof.max(1.0) } else { 1.0 };
        let covariance = unit_covariance * scale;
        let fit = Fit {
            theta: [mass_kg, moment_kgm, friction_n, bias1_n, bias2_n],
            covariance,
            chi2_dof,
            residual_rms_n: ComplexField::sqrt(unweighted_ss / f64::from(self.rows)),
            condition,
        };
        self.result(fit)
    }

    /// The result of a fit: the deviations from its covariance, the centre
    /// of mass from the mass and the moment; refused if the mass is not
    /// positive or a value is not finite.
    fn result(&self, fit: Fit) -> Result<IdentificationResult, IdentificationError> {
        let Fit {
            theta: [mass_kg, moment_kgm, friction_n, bias1_n, bias2_n],
            covariance,
            chi2_dof,
            residual_rms_n,
            condition,
        } = fit;
        let [var_m, var_mm, var_f, var_b1, var_b2]: [f64; MAX_UNKNOWNS] =
            covariance.diagonal().map(non_negative).into();
        // Column 0 of the covariance: (m, m), (M, m), ...
        let [[_, cov_mass_moment, ..], ..]: [[f64; MAX_UNKNOWNS]; MAX_UNKNOWNS] = covariance.into();
        let std = |v: f64| ComplexField::sqrt(v);

        check_finite(&[mass_kg], non_finite("estimated mass"))?;
        if mass_kg <= 0.0 {
            return Err(IdentificationError::NonPositiveMass { mass_kg });
        }
        let com_m = moment_kgm / mass_kg;
        let bias = self.options.bias_across_gravity;
        let friction = self.options.friction;
        let result = IdentificationResult {
            mass_kg,
            mass_std_kg: std(var_m),
            com_m,
            com_std_m: com_std_m(mass_kg, moment_kgm, var_m, var_mm, cov_mass_moment),
            moment_kgm,
            moment_std_kgm: std(var_mm),
            bias_across_n: bias.then_some([bias1_n, bias2_n]),
            bias_across_std_n: bias.then(|| [std(var_b1), std(var_b2)]),
            friction_n: friction.then_some(friction_n),
            friction_std_n: friction.then(|| std(var_f)),
            residual_rms_n,
            chi2_dof,
            condition,
            poses: self.poses,
            rows: self.rows,
        };
        check_result(&result)?;
        Ok(result)
    }
}

/// A solved fit, before its checks: the unknowns (m, M, f, bias e1, bias
/// e2), their covariance (scaled by the scatter), and its figures.
struct Fit {
    theta: [f64; MAX_UNKNOWNS],
    covariance: Square,
    chi2_dof: f64,
    residual_rms_n: f64,
    condition: f64,
}

/// The condition number of the triangular factor `r5` with its columns
/// scaled to unit norm; `Err` with the condition (infinite when a column is
/// zero or not finite, or the factor singular) if it is beyond
/// [`MAX_CONDITION`] or NaN.
fn scaled_condition(r5: &Square) -> Result<f64, f64> {
    let norms = Unknowns::from_iterator(r5.column_iter().map(|c| c.norm()));
    if norms.iter().any(|n| !(n.is_finite() && *n > 0.0)) {
        return Err(f64::INFINITY);
    }
    let scaled = r5 * Square::from_diagonal(&norms.map(|n| 1.0 / n));
    let Some(scaled_inv) = scaled.solve_upper_triangular(&Square::identity()) else {
        return Err(f64::INFINITY);
    };
    let condition = linalg::condition_from_gram(
        &(scaled.transpose() * scaled),
        &(scaled_inv.transpose() * scaled_inv),
    );
    if condition.is_nan() || condition > MAX_CONDITION {
        return Err(condition);
    }
    Ok(condition)
}

fn check_result(r: &IdentificationResult) -> Result<(), IdentificationError> {
    let values = [
        r.mass_kg,
        r.mass_std_kg,
        r.com_m,
        r.com_std_m,
        r.moment_kgm,
        r.moment_std_kgm,
        r.residual_rms_n,
        r.chi2_dof,
        r.condition,
    ];
    // Values not estimated are absent (None), not a 0 standing in for them.
    let optional = r
        .bias_across_n
        .into_iter()
        .chain(r.bias_across_std_n)
        .flatten()
        .chain(r.friction_n)
        .chain(r.friction_std_n);
    for value in values.into_iter().chain(optional) {
        check_finite(&[value], non_finite("identification result"))?;
    }
    Ok(())
}
