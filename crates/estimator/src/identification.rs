//! Identification of the manipulator's mass m and centre of mass c from static
//! poses with nothing touching the tip (MODEL.md 5), and the article's
//! simplified straight-line method (MODEL.md 5.2) for comparison.
//!
//! [`Identification`] is a streaming weighted least-squares solver: each pose
//! adds three rows (two moment rows about B and the force row along the rod),
//! whitened by the inverse of their noise covariance, to a fixed-size upper
//! triangular factor by Givens rotations (never normal equations). The estimate,
//! its standard errors, the residuals and the condition number are available
//! after every pose. [`LineFit`] is the article's ordinary least-squares line
//! `F_A . up = b0 + b1 / a` on horizontal poses, with centred (Welford) sums.
//!
//! Conventions (MODEL.md 4, 5): `F_A = -R_0s (f_s - b)` is what the robot
//! applies to the rod at A, `a = |B - A|`, `u = (B - A) / a`; the unknowns are
//! m, M = m c, and optionally the support friction f (coefficient: the sign of
//! the last slide) and the force bias across gravity (two components in the
//! sensor frame, basis [`bias_across_gravity_basis`]). The bias along gravity
//! cannot be told from m: the sensor must be tared with the rod detached.

use crate::{
    Calibration, MIN_SUPPORT_DISTANCE_M, Mat3, PoseInputError, SensorNoise, StaticPose, Vec3,
    check_finite, com_std_m, non_negative,
};
use nalgebra::{ComplexField, SMatrix, SVector};

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
/// Iteration cap of the symmetric eigensolver on the (at most 5x5) scaled
/// factor; it converges in a few dozen.
const EIGEN_MAX_ITERATIONS: usize = 1000;

/// One augmented row: coefficients of the unknowns, then the right-hand side.
type Row = [f64; WIDTH];
/// An upper triangular augmented factor T with |T z| = |[A y] z| for every z.
type Factor = [Row; WIDTH];

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
    #[error("the U-joint centre is {distance_m:e} m from the support, below {min_m} m")]
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
    #[error("the estimated mass is {mass_kg} kg, not positive")]
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
        "the rod is tilted {tilt_rad} rad from horizontal, above the tolerance {tolerance_rad} rad"
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
fn non_finite(field: &'static str) -> impl FnOnce(f64) -> IdentificationError {
    move |value| IdentificationError::NonFinite { field, value }
}

/// Checks a pose and returns (u, a) with a = |B - A|, u = (B - A) / a.
fn pose_geometry(pose: &StaticPose, support_m: &Vec3) -> Result<(Vec3, f64), IdentificationError> {
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

/// Adds one augmented row to an upper triangular factor by Givens rotations,
/// over the first `width` columns. Keeps the diagonal >= 0.
fn givens_add(factor: &mut Factor, width: usize, mut row: Row) {
    for (k, factor_row) in factor.iter_mut().enumerate().take(width) {
        let pivot = factor_row.get(k).copied().unwrap_or(0.0);
        let incoming = row.get(k).copied().unwrap_or(0.0);
        if incoming == 0.0 {
            continue;
        }
        let radius = ComplexField::hypot(pivot, incoming);
        let (cos, sin) = (pivot / radius, incoming / radius);
        for (kept, added) in factor_row
            .iter_mut()
            .zip(row.iter_mut())
            .take(width)
            .skip(k)
        {
            let (t, r) = (*kept, *added);
            *kept = cos * t + sin * r;
            *added = cos * r - sin * t;
        }
    }
}

fn entry(factor: &Factor, i: usize, j: usize) -> f64 {
    factor.get(i).and_then(|r| r.get(j)).copied().unwrap_or(0.0)
}

fn at<const N: usize>(v: &SVector<f64, N>, i: usize) -> f64 {
    v.get(i).copied().unwrap_or(0.0)
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
    /// 2 to 5; column layout: m, M, [f], [bias e1, bias e2], then the rhs.
    unknowns: usize,
    friction_col: Option<usize>,
    bias_col: Option<usize>,
    weighted: Factor,
    unweighted: Factor,
    poses: u32,
    rows: u32,
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
        let mut unknowns = 2;
        let friction_col = if options.friction {
            unknowns += 1;
            Some(unknowns - 1)
        } else {
            None
        };
        let bias_col = if options.bias_across_gravity {
            unknowns += 2;
            Some(unknowns - 2)
        } else {
            None
        };
        Ok(Self {
            support_m: cal.support_m(),
            gravity_mps2: cal.gravity_mps2(),
            calibration: *cal,
            bias_n,
            variance_n2,
            bias_basis_s: bias_across_gravity_basis(cal),
            options,
            unknowns,
            friction_col,
            bias_col,
            weighted: [[0.0; WIDTH]; WIDTH],
            unweighted: [[0.0; WIDTH]; WIDTH],
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
        // At most MAX_UNKNOWNS = 5.
        self.unknowns as u32
    }

    /// Adds one static pose. Validates it first; a refused pose leaves the
    /// state unchanged.
    pub fn add(&mut self, pose: &StaticPose) -> Result<(), IdentificationError> {
        let (u, a) = pose_geometry(pose, &self.support_m)?;
        let poses = self
            .poses
            .checked_add(1)
            .ok_or(IdentificationError::TooManyPoses { poses: self.poses })?;
        let rows = self
            .rows
            .checked_add(3)
            .ok_or(IdentificationError::TooManyPoses { poses: self.poses })?;
        let force_a_n =
            crate::ujoint_force_n(&self.calibration, &pose.mean_reading_n, &self.bias_n);
        check_finite(&force_a_n, non_finite("F_A"))?;

        // G: rows p1.(u x v), p2.(u x v), u.v; orthonormal.
        let (p1, p2) = basis_across(&u);
        let g_rows = Mat3::from_rows(&[
            p1.cross(&u).transpose(), // p1.(u x v) = v.(p1 x u)
            p2.cross(&u).transpose(),
            u.transpose(),
        ]);
        let measured: [f64; 3] = (g_rows * force_a_n).into();
        let gravity_rows: [f64; 3] = (g_rows * self.gravity_mps2).into();
        let moment_coef = [1.0 / a, 1.0 / a, 0.0];
        let friction_coef = [0.0, 0.0, pose.slide_sign];
        let g_r = g_rows * self.calibration.sensor_rotation();
        let [e1, e2] = self.bias_basis_s;
        let bias1: [f64; 3] = (-(g_r * e1)).into();
        let bias2: [f64; 3] = (-(g_r * e2)).into();

        let rhs_col = self.unknowns;
        let mut design_rows = [[0.0; WIDTH]; 3];
        for (i, row) in design_rows.iter_mut().enumerate() {
            let pick = |v: &[f64; 3]| v.get(i).copied().unwrap_or(0.0);
            let g_i = pick(&gravity_rows);
            let mut set = |col: usize, value: f64| {
                if let Some(slot) = row.get_mut(col) {
                    *slot = value;
                }
            };
            set(0, -g_i);
            set(1, g_i * pick(&moment_coef));
            if let Some(col) = self.friction_col {
                set(col, pick(&friction_coef));
            }
            if let Some(col) = self.bias_col {
                set(col, pick(&bias1));
                set(col + 1, pick(&bias2));
            }
            set(rhs_col, pick(&measured));
        }

        // Whitening: covariance of the rows = G R diag(std^2 / K) R^T G^T.
        let per_sample = Mat3::from_diagonal(&(self.variance_n2 / f64::from(pose.samples)));
        let covariance = g_r * per_sample * g_r.transpose();
        let cholesky = covariance
            .cholesky()
            .ok_or(IdentificationError::DegenerateNoise {
                samples: pose.samples,
            })?;
        let design = SMatrix::<f64, 3, WIDTH>::from_fn(|i, j| {
            design_rows
                .get(i)
                .and_then(|r| r.get(j))
                .copied()
                .unwrap_or(0.0)
        });
        let whitened = cholesky.l().solve_lower_triangular(&design).ok_or(
            IdentificationError::DegenerateNoise {
                samples: pose.samples,
            },
        )?;

        let width = self.unknowns + 1;
        let mut weighted = self.weighted;
        let mut unweighted = self.unweighted;
        for (whitened_row, plain_row) in whitened.row_iter().zip(design_rows.iter()) {
            let mut row = [0.0; WIDTH];
            for (dst, src) in row.iter_mut().zip(whitened_row.iter()) {
                *dst = *src;
            }
            givens_add(&mut weighted, width, row);
            givens_add(&mut unweighted, width, *plain_row);
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

    /// Poses accumulated.
    pub fn poses(&self) -> u32 {
        self.poses
    }

    /// Rows accumulated (3 per pose).
    pub fn rows(&self) -> u32 {
        self.rows
    }

    /// The estimate from the poses so far.
    pub fn solve(&self) -> Result<IdentificationResult, IdentificationError> {
        let p = self.unknowns;
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
        // R (p x p), padded to 5x5 with the identity: block-diagonal, so the
        // padding neither changes the solution nor (columns of unit norm have
        // singular values around 1) the scaled condition number.
        let r5 = SMatrix::<f64, MAX_UNKNOWNS, MAX_UNKNOWNS>::from_fn(|i, j| {
            if i < p && j < p {
                entry(&self.weighted, i, j)
            } else if i == j {
                1.0
            } else {
                0.0
            }
        });
        let norms = SVector::<f64, MAX_UNKNOWNS>::from_fn(|j, _| r5.column(j).norm());
        if norms.iter().any(|n| !(n.is_finite() && *n > 0.0)) {
            return Err(ill(f64::INFINITY));
        }
        let scaled = SMatrix::<f64, MAX_UNKNOWNS, MAX_UNKNOWNS>::from_fn(|i, j| {
            r5.get((i, j)).copied().unwrap_or(0.0) / at(&norms, j)
        });
        // cond2(S) = sigma_max(S) sigma_max(S^-1), each from the LARGEST
        // eigenvalue of a symmetric matrix (accurate, unlike the smallest).
        // No SVD: nalgebra's SVD returned wrong decompositions for some 5x5
        // triangular matrices (reconstruction errors up to 1e-2 in a test of
        // 200 000 random ones); its symmetric eigensolver did not (5e-15).
        let Some(scaled_inv) =
            scaled.solve_upper_triangular(&SMatrix::<f64, MAX_UNKNOWNS, MAX_UNKNOWNS>::identity())
        else {
            return Err(ill(f64::INFINITY));
        };
        let largest_eigenvalue = |m: SMatrix<f64, MAX_UNKNOWNS, MAX_UNKNOWNS>| {
            m.try_symmetric_eigen(f64::EPSILON, EIGEN_MAX_ITERATIONS)
                .map_or(f64::INFINITY, |e| e.eigenvalues.max())
        };
        let condition = ComplexField::sqrt(
            largest_eigenvalue(scaled.transpose() * scaled)
                * largest_eigenvalue(scaled_inv.transpose() * scaled_inv),
        );
        if condition.is_nan() || condition > MAX_CONDITION {
            return Err(ill(condition));
        }

        let rhs = SVector::<f64, MAX_UNKNOWNS>::from_fn(|i, _| {
            if i < p {
                entry(&self.weighted, i, p)
            } else {
                0.0
            }
        });
        let theta = r5.solve_upper_triangular(&rhs).ok_or(ill(condition))?;
        let r_inv = r5
            .solve_upper_triangular(&SMatrix::<f64, MAX_UNKNOWNS, MAX_UNKNOWNS>::identity())
            .ok_or(ill(condition))?;
        let unit_covariance = r_inv * r_inv.transpose();

        // Residuals: |T (theta, -1)|^2 = |[A y] (theta, -1)|^2 = |A theta - y|^2.
        let z = SVector::<f64, WIDTH>::from_fn(|i, _| {
            if i < p {
                at(&theta, i)
            } else if i == p {
                -1.0
            } else {
                0.0
            }
        });
        let as_matrix =
            |factor: &Factor| SMatrix::<f64, WIDTH, WIDTH>::from_fn(|i, j| entry(factor, i, j));
        let chi2 = (as_matrix(&self.weighted) * z).norm_squared();
        let unweighted_ss = (as_matrix(&self.unweighted) * z).norm_squared();
        let dof = self.rows - needed;
        let chi2_dof = if dof > 0 { chi2 / f64::from(dof) } else { 0.0 };
        // Never claim more than the noise model, nor less than the scatter shows.
        let scale = if dof > 0 { chi2_dof.max(1.0) } else { 1.0 };
        let covariance = unit_covariance * scale;
        let var = |i: usize| non_negative(covariance.get((i, i)).copied().unwrap_or(0.0));
        let std = |i: usize| ComplexField::sqrt(var(i));

        let mass_kg = at(&theta, 0);
        let moment_kgm = at(&theta, 1);
        check_finite(&[mass_kg], non_finite("estimated mass"))?;
        if mass_kg <= 0.0 {
            return Err(IdentificationError::NonPositiveMass { mass_kg });
        }
        let com_m = moment_kgm / mass_kg;
        let cov_mass_moment = covariance.get((0, 1)).copied().unwrap_or(0.0);
        let result = IdentificationResult {
            mass_kg,
            mass_std_kg: std(0),
            com_m,
            com_std_m: com_std_m(mass_kg, moment_kgm, var(0), var(1), cov_mass_moment),
            moment_kgm,
            moment_std_kgm: std(1),
            bias_across_n: self
                .bias_col
                .map(|col| [at(&theta, col), at(&theta, col + 1)]),
            bias_across_std_n: self.bias_col.map(|col| [std(col), std(col + 1)]),
            friction_n: self.friction_col.map(|col| at(&theta, col)),
            friction_std_n: self.friction_col.map(std),
            residual_rms_n: ComplexField::sqrt(unweighted_ss / f64::from(self.rows)),
            chi2_dof,
            condition,
            poses: self.poses,
            rows: self.rows,
        };
        check_result(&result)?;
        Ok(result)
    }
}

fn check_result(r: &IdentificationResult) -> Result<(), IdentificationError> {
    let [b1, b2] = r.bias_across_n.unwrap_or([0.0; 2]);
    let [s1, s2] = r.bias_across_std_n.unwrap_or([0.0; 2]);
    let values = [
        r.mass_kg,
        r.mass_std_kg,
        r.com_m,
        r.com_std_m,
        r.moment_kgm,
        r.moment_std_kgm,
        b1,
        b2,
        s1,
        s2,
        r.friction_n.unwrap_or(0.0),
        r.friction_std_n.unwrap_or(0.0),
        r.residual_rms_n,
        r.chi2_dof,
        r.condition,
    ];
    check_finite(&values, non_finite("identification result"))
}

/// The article's simplified method (MODEL.md 5.2): with the rod horizontal and
/// at the support's height, `Y = F_A . up = b0 + b1 X` with `X = 1/a`,
/// `b0 = m |g|`, `b1 = -M |g|` (the article prints b1 without the minus sign).
/// Ordinary (unweighted) least squares, streaming, with centred sums.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineFit {
    support_m: Vec3,
    gravity_norm_mps2: f64,
    /// Unit vector against gravity, {0}.
    up: Vec3,
    /// For F_A = [`crate::ujoint_force_n`].
    calibration: Calibration,
    bias_n: Vec3,
    tolerance_rad: f64,
    sin_tolerance: f64,
    count: u32,
    mean_x: f64,
    mean_y: f64,
    sxx: f64,
    sxy: f64,
    syy: f64,
}

/// The line fit's estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineFitResult {
    /// b0 = m |g|, N.
    pub b0_n: f64,
    /// Standard error of b0, N.
    pub b0_std_n: f64,
    /// b1 = -M |g|, N m.
    pub b1_nm: f64,
    /// Standard error of b1, N m.
    pub b1_std_nm: f64,
    /// m = b0 / |g|, kg.
    pub mass_kg: f64,
    /// Standard error of m, kg.
    pub mass_std_kg: f64,
    /// c = -b1 / b0, m.
    pub com_m: f64,
    /// Standard error of c (first order, including the b0-b1 covariance), m.
    pub com_std_m: f64,
    /// RMS of the residuals of Y, N.
    pub residual_rms_n: f64,
    /// Condition number of the design [1, X] after scaling its columns to unit norm.
    pub condition: f64,
    /// Poses used.
    pub poses: u32,
}

impl LineFit {
    /// Starts an empty line fit. `bias_n` is the tare (sensor frame, N);
    /// `horizontal_tolerance_rad` in [0, pi/2) is how far from horizontal a
    /// rod may be.
    pub fn new(
        cal: &Calibration,
        bias_n: Vec3,
        horizontal_tolerance_rad: f64,
    ) -> Result<Self, IdentificationError> {
        check_finite(&bias_n, non_finite("bias_n"))?;
        if !(0.0..core::f64::consts::FRAC_PI_2).contains(&horizontal_tolerance_rad) {
            return Err(IdentificationError::InvalidTolerance {
                tolerance_rad: horizontal_tolerance_rad,
            });
        }
        let gravity = cal.gravity_mps2();
        let gravity_norm_mps2 = gravity.norm();
        Ok(Self {
            support_m: cal.support_m(),
            gravity_norm_mps2,
            up: -gravity / gravity_norm_mps2,
            calibration: *cal,
            bias_n,
            tolerance_rad: horizontal_tolerance_rad,
            sin_tolerance: ComplexField::sin(horizontal_tolerance_rad),
            count: 0,
            mean_x: 0.0,
            mean_y: 0.0,
            sxx: 0.0,
            sxy: 0.0,
            syy: 0.0,
        })
    }

    /// Adds one pose; refuses (leaving the state unchanged) an invalid pose or
    /// one whose rod is not horizontal: |u . g_hat| > sin(tolerance). With the
    /// rod through B (d = 0) that is also the test that A is at the support's
    /// height: (B - A) . g_hat = a (u . g_hat).
    pub fn add(&mut self, pose: &StaticPose) -> Result<(), IdentificationError> {
        let (u, a) = pose_geometry(pose, &self.support_m)?;
        let tilt_sin = u.dot(&self.up).abs();
        if tilt_sin > self.sin_tolerance {
            return Err(IdentificationError::NotHorizontal {
                tilt_rad: ComplexField::asin(tilt_sin.min(1.0)),
                tolerance_rad: self.tolerance_rad,
            });
        }
        let count = self
            .count
            .checked_add(1)
            .ok_or(IdentificationError::TooManyPoses { poses: self.count })?;
        let force_a_n =
            crate::ujoint_force_n(&self.calibration, &pose.mean_reading_n, &self.bias_n);
        let x = 1.0 / a;
        let y = force_a_n.dot(&self.up);
        check_finite(&[y], non_finite("vertical force"))?;
        let n = f64::from(count);
        let dx = x - self.mean_x;
        let dy = y - self.mean_y;
        let mean_x = self.mean_x + dx / n;
        let mean_y = self.mean_y + dy / n;
        let sxx = self.sxx + dx * (x - mean_x);
        let sxy = self.sxy + dx * (y - mean_y);
        let syy = self.syy + dy * (y - mean_y);
        check_finite(
            &[mean_x, mean_y, sxx, sxy, syy],
            non_finite("line fit sums"),
        )?;
        self.count = count;
        self.mean_x = mean_x;
        self.mean_y = mean_y;
        self.sxx = sxx;
        self.sxy = sxy;
        self.syy = syy;
        Ok(())
    }

    /// Poses accumulated.
    pub fn poses(&self) -> u32 {
        self.count
    }

    /// The line and m, c from it. Needs 3 poses (one degree of freedom for the
    /// standard errors) at no fewer than 2 distinct distances.
    pub fn solve(&self) -> Result<LineFitResult, IdentificationError> {
        if self.count < 3 {
            return Err(IdentificationError::TooFewRows {
                rows: self.count,
                poses: self.count,
                needed: 3,
            });
        }
        let n = f64::from(self.count);
        let centre = n * self.mean_x * self.mean_x;
        // Scaled design [1, X]: Gram matrix [[1, rho], [rho, 1]] with
        // rho = n mean_x / sqrt(n sum X^2); condition = (1 + rho) / sqrt(1 - rho^2).
        let condition = if self.sxx > 0.0 {
            let rho = ComplexField::sqrt(centre / (self.sxx + centre));
            (1.0 + rho) * ComplexField::sqrt((self.sxx + centre) / self.sxx)
        } else {
            f64::INFINITY
        };
        if condition.is_nan() || condition > MAX_CONDITION {
            return Err(IdentificationError::IllConditioned {
                condition,
                limit: MAX_CONDITION,
            });
        }
        let b1 = self.sxy / self.sxx;
        let b0 = self.mean_y - b1 * self.mean_x;
        let ssr = non_negative(self.syy - b1 * self.sxy);
        let s2 = ssr / (n - 2.0);
        let var_b1 = s2 / self.sxx;
        let var_b0 = s2 * (1.0 / n + self.mean_x * self.mean_x / self.sxx);
        let cov_b0_b1 = -self.mean_x * s2 / self.sxx;
        check_finite(&[b0], non_finite("b0"))?;
        if b0 <= 0.0 {
            return Err(IdentificationError::NonPositiveMass {
                mass_kg: b0 / self.gravity_norm_mps2,
            });
        }
        let com_m = -b1 / b0;
        let result = LineFitResult {
            b0_n: b0,
            b0_std_n: ComplexField::sqrt(var_b0),
            b1_nm: b1,
            b1_std_nm: ComplexField::sqrt(var_b1),
            mass_kg: b0 / self.gravity_norm_mps2,
            mass_std_kg: ComplexField::sqrt(var_b0) / self.gravity_norm_mps2,
            com_m,
            // c = (-b1) / b0 = M / m: the ratio of (m, M) scaled by |g|, which
            // does not change it, nor its first-order standard error.
            com_std_m: com_std_m(b0, -b1, var_b0, var_b1, -cov_b0_b1),
            residual_rms_n: ComplexField::sqrt(ssr / n),
            condition,
            poses: self.count,
        };
        let values = [
            result.b0_std_n,
            result.b1_nm,
            result.b1_std_nm,
            result.mass_kg,
            result.mass_std_kg,
            result.com_m,
            result.com_std_m,
            result.residual_rms_n,
        ];
        check_finite(&values, non_finite("line fit result"))?;
        Ok(result)
    }
}
