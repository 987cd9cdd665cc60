//! Identification of the rod's inertia I_perp, with m and c again, from a
//! motion of the carriage with nothing touching the tip (MODEL.md 10, "What
//! it needs to know"; d = 0, I_axial does not enter).
//!
//! With J_A = I_perp + m c^2 (the inertia about A) and M = m c, the
//! Newton-Euler equations of MODEL.md 10 with F_D = 0 give F_A linear in
//! (m, M, J_A): with r = B - A, rho = |r|, u = r / rho, v_perp = v - (v.u) u,
//!
//! ```text
//! F_B = (J_A u''_perp + M (A'' - g)_perp) / rho
//! F_A = m (A'' - g) + M (u'' - (A'' - g)_perp / rho) - J_A u''_perp / rho
//!       + sigma f u                                  (friction, optional)
//! ```
//!
//! (with A'' = 0 this is MODEL.md 5.1). Afterwards c = M / m and
//! I_perp = J_A - M^2 / m, with first-order standard errors.
//!
//! [`DynamicIdentification`] is a fixed-size accumulator of the normal
//! equations (no alloc, no panic), fed sample by sample: each sample's three
//! force rows, whitened by the sensor's noise in the sensor frame (its
//! covariance is diagonal there), and the same rows unweighted (for the
//! residual RMS in newtons). The sensor reading has the tare removed as in
//! MODEL.md 5; the adapter between the sensor and the U-joint (mass m_s) adds
//! m_s A'' to the measured F_A, which is taken off first at the given m_s.
//! With [`DynamicIdentification::estimating_adapter`] the adapter's mass is
//! a fifth unknown (issue 34): its column is A'' (what m_s - given adds to
//! -R_0s (f - b)), told apart from m's column A'' - g by the weight m g
//! (the tare is the sensor's own bias, the rod detached; the adapter's weight
//! is in it) and from J_A's and M's by the part of A'' along the rod. Torque
//! rows are not used (MODEL.md 10: they would cut the standard errors to about
//! 0.6x).

use super::IdentificationError;
use crate::{
    Calibration, MIN_SUPPORT_DISTANCE_M, Mat3, SensorNoise, Vec3, check_finite, com_std_m,
    non_negative,
};
use nalgebra::{ComplexField, SMatrix, SVector};

/// Unknowns: m, M, J_A, the support's friction f and the adapter's mass
/// beyond the given one, dm_s.
const UNKNOWNS: usize = 5;
/// The adapter's column.
const ADAPTER: usize = 4;
/// The augmented Gram matrix's size: the unknowns and the right-hand side.
const WIDTH: usize = UNKNOWNS + 1;
/// An augmented Gram matrix [X y]^T [X y].
type Gram = SMatrix<f64, WIDTH, WIDTH>;
/// The unknowns' block.
type Square = SMatrix<f64, UNKNOWNS, UNKNOWNS>;
/// A vector over the unknowns.
type Unknowns = SVector<f64, UNKNOWNS>;

/// Below this sliding speed |A' . u| a sample's friction coefficient is 0
/// (the sign of the slide is not known while the rod reverses), m/s.
pub const MIN_SLIDE_SPEED_MPS: f64 = 1e-4;

/// One sample of a motion: where the carriage is, how it moves, what the
/// sensor reads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionSample {
    /// A, the U-joint centre, {0}, m.
    pub ujoint_m: Vec3,
    /// A', {0}, m/s.
    pub velocity_mps: Vec3,
    /// A'', {0}, m/s^2.
    pub accel_mps2: Vec3,
    /// The sensor's force reading, sensor frame, N, before bias removal.
    pub reading_n: Vec3,
}

/// The rod's kinematics at a sample: u, rho and u'' (MODEL.md 10).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RodMotion {
    /// u = (B - A) / rho.
    pub dir: Vec3,
    /// rho = |B - A|, m.
    pub distance_m: f64,
    /// u'', 1/s^2.
    pub dir_accel: Vec3,
    /// The rod's sliding speed along u, A' . u, m/s.
    pub slide_speed_mps: f64,
}

/// u, rho, u'' and A' . u from A, A', A'' (MODEL.md 10: r' = -A', r'' = -A'').
pub fn rod_motion(
    support_m: &Vec3,
    ujoint_m: &Vec3,
    velocity_mps: &Vec3,
    accel_mps2: &Vec3,
) -> Result<RodMotion, IdentificationError> {
    let r = support_m - ujoint_m;
    let rho = r.norm();
    check_finite(&[rho], super::non_finite("support distance"))?;
    if rho < MIN_SUPPORT_DISTANCE_M {
        return Err(IdentificationError::SupportTooClose {
            distance_m: rho,
            min_m: MIN_SUPPORT_DISTANCE_M,
        });
    }
    let u = r / rho;
    let (r_d, r_dd) = (-velocity_mps, -accel_mps2);
    let rho_d = u.dot(&r_d);
    let u_d = (r_d - u * rho_d) / rho;
    let rho_dd = u_d.dot(&r_d) + u.dot(&r_dd);
    let u_dd = (r_dd - u * rho_dd - u_d * (2.0 * rho_d)) / rho;
    Ok(RodMotion {
        dir: u,
        distance_m: rho,
        dir_accel: u_dd,
        slide_speed_mps: velocity_mps.dot(&u),
    })
}

/// The regressor of F_A ({0}, N): columns m, M, J_A, f (see the module's doc).
pub fn regressor(rod: &RodMotion, accel_mps2: &Vec3, gravity_mps2: &Vec3) -> SMatrix<f64, 3, 4> {
    let u = rod.dir;
    let perp = |v: Vec3| v - u * u.dot(&v);
    let rho = rod.distance_m;
    let a_g = accel_mps2 - gravity_mps2;
    let sigma = if rod.slide_speed_mps.abs() < MIN_SLIDE_SPEED_MPS {
        0.0
    } else {
        rod.slide_speed_mps.signum()
    };
    SMatrix::<f64, 3, 4>::from_columns(&[
        a_g,
        rod.dir_accel - perp(a_g) / rho,
        -perp(rod.dir_accel) / rho,
        u * sigma,
    ])
}

/// The parameters, in the regressor's order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InertialParameters {
    /// m, kg.
    pub mass_kg: f64,
    /// c, m.
    pub com_m: f64,
    /// I_perp about the COM, kg m^2.
    pub inertia_perp_kgm2: f64,
    /// The support's Coulomb friction f, N (0 when not estimated).
    pub friction_n: f64,
}

impl InertialParameters {
    /// (m, M = m c, J_A = I_perp + m c^2, f, 0): the regressor's four.
    fn theta(&self) -> Unknowns {
        let moment = self.mass_kg * self.com_m;
        Unknowns::new(
            self.mass_kg,
            moment,
            self.inertia_perp_kgm2 + moment * self.com_m,
            self.friction_n,
            0.0,
        )
    }
}

/// F_A that the model predicts for a sample, {0}, N (before the adapter).
pub fn model_force_n(
    params: &InertialParameters,
    rod: &RodMotion,
    accel_mps2: &Vec3,
    gravity_mps2: &Vec3,
) -> Vec3 {
    regressor(rod, accel_mps2, gravity_mps2) * params.theta().fixed_rows::<4>(0)
}

/// The estimate with standard errors and fit diagnostics.
///
/// Standard errors are the noise model's (`*_model_*`, what the excitation
/// promises: the expected accuracy) times `max(1, sqrt(chi2_dof))`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DynamicResult {
    /// m, kg.
    pub mass_kg: f64,
    /// Its standard error, kg.
    pub mass_std_kg: f64,
    /// c = M / m, m.
    pub com_m: f64,
    /// Its standard error, m.
    pub com_std_m: f64,
    /// I_perp = J_A - M^2 / m, kg m^2.
    pub inertia_perp_kgm2: f64,
    /// Its standard error, kg m^2.
    pub inertia_perp_std_kgm2: f64,
    /// The noise model's standard error of I_perp (no chi-square scaling), kg m^2.
    pub inertia_perp_model_std_kgm2: f64,
    /// J_A = I_perp + m c^2, kg m^2.
    pub inertia_a_kgm2: f64,
    /// The support's friction f, N (if estimated).
    pub friction_n: Option<f64>,
    /// Its standard error, N.
    pub friction_std_n: Option<f64>,
    /// m_s, the adapter's mass between the sensor and the U-joint, kg: the
    /// given one, or the estimate when it was estimated.
    pub adapter_mass_kg: f64,
    /// Its standard error when estimated, kg (`None`: held at the given one).
    pub adapter_mass_std_kg: Option<f64>,
    /// When estimated: the largest |correlation| of m_s's estimate with any
    /// other unknown's (near 1: the excitation does not separate them).
    pub adapter_correlation: Option<f64>,
    /// RMS of the unweighted force residuals per component, N.
    pub residual_rms_n: f64,
    /// Weighted residual sum of squares / (rows - unknowns).
    pub chi2_dof: f64,
    /// Condition number of the weighted design with unit-norm columns.
    pub condition: f64,
    /// Samples used.
    pub samples: u32,
}

impl DynamicResult {
    /// The parameters as estimated.
    pub fn parameters(&self) -> InertialParameters {
        InertialParameters {
            mass_kg: self.mass_kg,
            com_m: self.com_m,
            inertia_perp_kgm2: self.inertia_perp_kgm2,
            friction_n: self.friction_n.unwrap_or(0.0),
        }
    }
}

/// One sample's F_A, measured and modelled ([`DynamicIdentification::forces`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SampleForces {
    /// F_A measured (tare and the given adapter removed), {0}, N.
    pub measured_n: Vec3,
    /// F_A of the fitted model, {0}, N.
    pub model_n: Vec3,
}

/// The streaming least squares over motion samples (see the module's doc).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DynamicIdentification {
    calibration: Calibration,
    bias_n: Vec3,
    inv_std_n: Vec3,
    adapter_mass_kg: f64,
    friction: bool,
    adapter: bool,
    weighted: Gram,
    unweighted: Gram,
    samples: u32,
}

impl DynamicIdentification {
    /// Starts an empty identification: `cal` gives B, g and R_0s; `bias_n`
    /// is the tare (sensor frame, N); `noise` weights the rows;
    /// `adapter_mass_kg` is m_s; `friction` adds the support's friction as
    /// a fourth unknown.
    pub fn new(
        cal: &Calibration,
        noise: &SensorNoise,
        bias_n: Vec3,
        adapter_mass_kg: f64,
        friction: bool,
    ) -> Result<Self, IdentificationError> {
        check_finite(&bias_n, super::non_finite("bias_n"))?;
        check_finite(&[adapter_mass_kg], super::non_finite("adapter_mass_kg"))?;
        let std_n = noise.std_n();
        for &std in std_n.iter() {
            if !(std * std).is_normal() {
                return Err(IdentificationError::NoiseOutOfRange { std_n: std });
            }
        }
        Ok(Self {
            calibration: *cal,
            bias_n,
            inv_std_n: std_n.map(|s| 1.0 / s),
            adapter_mass_kg,
            friction,
            adapter: false,
            weighted: Gram::zeros(),
            unweighted: Gram::zeros(),
            samples: 0,
        })
    }

    /// The adapter's mass becomes an unknown (issue 34): the given
    /// `adapter_mass_kg` is where the fit starts, and its result is the
    /// given one plus what the fit adds. Call before the first sample.
    pub fn estimating_adapter(mut self) -> Self {
        self.adapter = true;
        self
    }

    /// Samples accumulated.
    pub fn samples(&self) -> u32 {
        self.samples
    }

    /// How many unknowns are estimated (3, one more with friction, one more
    /// with the adapter's mass).
    pub fn unknowns(&self) -> usize {
        3 + usize::from(self.friction) + usize::from(self.adapter)
    }

    /// Adds one sample; a refused sample leaves the state unchanged.
    pub fn add(&mut self, s: &MotionSample) -> Result<(), IdentificationError> {
        for v in [&s.ujoint_m, &s.velocity_mps, &s.accel_mps2, &s.reading_n] {
            check_finite(v, super::non_finite("motion sample"))?;
        }
        let samples = self
            .samples
            .checked_add(1)
            .ok_or(IdentificationError::TooManyPoses {
                poses: self.samples,
            })?;
        let (x, force_a_n) = self.rows(s)?;
        let cal = &self.calibration;
        let plain = SMatrix::<f64, 3, WIDTH>::from_columns(&[
            x.column(0).into_owned(),
            x.column(1).into_owned(),
            x.column(2).into_owned(),
            x.column(3).into_owned(),
            x.column(4).into_owned(),
            force_a_n,
        ]);
        // The sensor frame, where the noise is diagonal: rows R^T [X y] / std.
        let rotation_t: Mat3 = cal.sensor_rotation().transpose();
        let whitened = Mat3::from_diagonal(&self.inv_std_n) * rotation_t * plain;
        let weighted = self.weighted + whitened.transpose() * whitened;
        let unweighted = self.unweighted + plain.transpose() * plain;
        check_finite(
            weighted.iter().chain(unweighted.iter()),
            super::non_finite("accumulated normal equations"),
        )?;
        self.weighted = weighted;
        self.unweighted = unweighted;
        self.samples = samples;
        Ok(())
    }

    /// A sample's three force rows as the fit takes them: the regressor X
    /// ({0}; f's column zero without friction, the adapter's (A'') zero
    /// unless estimated) and the measured F_A, the tare and the given
    /// adapter's m_s A'' taken off, {0}, N.
    fn rows(
        &self,
        s: &MotionSample,
    ) -> Result<(SMatrix<f64, 3, UNKNOWNS>, Vec3), IdentificationError> {
        let cal = &self.calibration;
        let rod = rod_motion(
            &cal.support_m(),
            &s.ujoint_m,
            &s.velocity_mps,
            &s.accel_mps2,
        )?;
        let four = regressor(&rod, &s.accel_mps2, &cal.gravity_mps2());
        let mut x = SMatrix::<f64, 3, UNKNOWNS>::zeros();
        x.fixed_columns_mut::<4>(0).copy_from(&four);
        if !self.friction {
            x.set_column(3, &Vec3::zeros());
        }
        if self.adapter {
            x.set_column(ADAPTER, &s.accel_mps2);
        }
        let force_a_n = crate::ujoint_force_n(cal, &s.reading_n, &self.bias_n)
            - s.accel_mps2 * self.adapter_mass_kg;
        Ok((x, force_a_n))
    }

    /// A sample's F_A as the fit saw it and as its result models it, {0},
    /// N: the same rows [`Self::add`] accumulates, at `fit`'s parameters
    /// (their difference is the sample's residual). For a figure of the fit.
    pub fn forces(
        &self,
        s: &MotionSample,
        fit: &DynamicResult,
    ) -> Result<SampleForces, IdentificationError> {
        let (x, measured_n) = self.rows(s)?;
        let mut theta = fit.parameters().theta();
        theta.a = fit.adapter_mass_kg - self.adapter_mass_kg;
        Ok(SampleForces {
            measured_n,
            model_n: x * theta,
        })
    }

    /// The estimate from the samples so far; refused above `max_condition`.
    pub fn solve(&self, max_condition: f64) -> Result<DynamicResult, IdentificationError> {
        let n = self.unknowns();
        let rows = u64::from(self.samples) * 3;
        if rows < n as u64 + 1 {
            return Err(IdentificationError::TooFewRows {
                rows: u32::try_from(rows).unwrap_or(u32::MAX),
                poses: self.samples,
                needed: n as u32 + 1,
            });
        }
        let ill = |condition: f64| IdentificationError::IllConditioned {
            condition,
            limit: max_condition,
        };
        let mut gram: Square = self
            .weighted
            .fixed_view::<UNKNOWNS, UNKNOWNS>(0, 0)
            .into_owned();
        // An unknown held (f at 0, dm_s at 0): its (zero) row and column
        // become the identity.
        if !self.friction {
            gram.m44 = 1.0;
        }
        if !self.adapter {
            gram.m55 = 1.0;
        }
        let rhs: Unknowns = self
            .weighted
            .fixed_view::<UNKNOWNS, 1>(0, UNKNOWNS)
            .into_owned();
        let scale = gram.diagonal().map(|d| {
            if d > 0.0 {
                1.0 / ComplexField::sqrt(d)
            } else {
                f64::INFINITY
            }
        });
        if scale.iter().any(|s| !s.is_finite()) {
            return Err(ill(f64::INFINITY));
        }
        let d = Square::from_diagonal(&scale);
        let scaled = d * gram * d;
        let scaled_inv = scaled.try_inverse().ok_or(ill(f64::INFINITY))?;
        let condition = crate::linalg::condition_from_gram(&scaled, &scaled_inv);
        if condition.is_nan() || condition > max_condition {
            return Err(ill(condition));
        }
        let covariance = d * scaled_inv * d;
        let theta = covariance * rhs;
        let yy = self.weighted.m66;
        let chi2 = non_negative(yy - theta.dot(&rhs));
        let dof = rows - n as u64;
        let chi2_dof = chi2 / dof as f64;
        let widen = chi2_dof.max(1.0);
        let residual_rms_n = self.residual_rms_n(&theta, rows);
        self.result(
            &theta,
            &covariance,
            widen,
            chi2_dof,
            condition,
            residual_rms_n,
        )
    }

    /// sqrt(|X theta - y|^2 / rows) from the unweighted normal equations, N.
    fn residual_rms_n(&self, theta: &Unknowns, rows: u64) -> f64 {
        let u = &self.unweighted;
        let gram: Square = u.fixed_view::<UNKNOWNS, UNKNOWNS>(0, 0).into_owned();
        let xy: Unknowns = u.fixed_view::<UNKNOWNS, 1>(0, UNKNOWNS).into_owned();
        let rss = u.m66 - 2.0 * theta.dot(&xy) + (gram * theta).dot(theta);
        ComplexField::sqrt(non_negative(rss) / rows as f64)
    }

    fn result(
        &self,
        theta: &Unknowns,
        covariance: &Square,
        widen: f64,
        chi2_dof: f64,
        condition: f64,
        residual_rms_n: f64,
    ) -> Result<DynamicResult, IdentificationError> {
        let [m, moment, j_a, f, dm_s]: [f64; UNKNOWNS] = (*theta).into();
        if m.is_nan() || m <= 0.0 {
            return Err(IdentificationError::NonPositiveMass { mass_kg: m });
        }
        let c = moment / m;
        // Gradient of I_perp = J_A - M^2 / m over (m, M, J_A, f, dm_s).
        let grad = Unknowns::new(c * c, -2.0 * c, 1.0, 0.0, 0.0);
        let var_i_model = non_negative((covariance * grad).dot(&grad));
        let std = |var: f64| ComplexField::sqrt(non_negative(var) * widen);
        let model_std = ComplexField::sqrt(var_i_model);
        let r = DynamicResult {
            mass_kg: m,
            mass_std_kg: std(covariance.m11),
            com_m: c,
            com_std_m: com_std_m(
                m,
                moment,
                covariance.m11 * widen,
                covariance.m22 * widen,
                covariance.m12 * widen,
            ),
            inertia_perp_kgm2: j_a - moment * c,
            inertia_perp_std_kgm2: model_std * ComplexField::sqrt(widen),
            inertia_perp_model_std_kgm2: model_std,
            inertia_a_kgm2: j_a,
            friction_n: self.friction.then_some(f),
            friction_std_n: self.friction.then(|| std(covariance.m44)),
            adapter_mass_kg: self.adapter_mass_kg + dm_s,
            adapter_mass_std_kg: self.adapter.then(|| std(covariance.m55)),
            adapter_correlation: self.adapter.then(|| adapter_correlation(covariance)),
            residual_rms_n,
            chi2_dof,
            condition,
            samples: self.samples,
        };
        check_finite(
            &[
                r.mass_std_kg,
                r.com_m,
                r.com_std_m,
                r.inertia_perp_kgm2,
                r.inertia_perp_std_kgm2,
                r.residual_rms_n,
                r.chi2_dof,
            ],
            super::non_finite("dynamic identification result"),
        )?;
        Ok(r)
    }
}

/// The largest |correlation| of the adapter's estimate with the other
/// unknowns' (from the covariance; 0 where a variance is 0).
fn adapter_correlation(covariance: &Square) -> f64 {
    let var_s = covariance.m55;
    covariance
        .row(ADAPTER)
        .iter()
        .zip(covariance.diagonal().iter())
        .take(ADAPTER)
        .map(|(cov, var)| {
            let denom = ComplexField::sqrt(non_negative(var_s * var));
            if denom > 0.0 {
                (cov / denom).abs()
            } else {
                0.0
            }
        })
        .fold(0.0, f64::max)
}
