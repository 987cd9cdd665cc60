//! The article's simplified identification (MODEL.md 5.2), kept for
//! comparison: with the rod horizontal and at the support's height, the
//! ordinary least-squares line `F_A . up = b0 + b1 / a`, streaming, with centred
//! (Welford) sums. Its errors are [`IdentificationError`]'s.

use crate::identification::{IdentificationError, MAX_CONDITION, non_finite, pose_geometry};
use crate::{Calibration, StaticPose, Vec3, check_finite, com_std_m, non_negative};
use nalgebra::ComplexField;

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
