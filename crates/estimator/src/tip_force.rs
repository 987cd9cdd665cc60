//! The tip force from one force-sensor reading (MODEL.md 4.1 and 4.3), with the
//! standard deviation that the sensor's noise gives it.
//!
//! - d = 0 (the default): the closed form of MODEL.md 4.1, no decomposition.
//! - d != 0: the six equilibrium equations of MODEL.md 4.3 (unknowns F_D, the
//!   support's reaction in a basis across u, and the U-joint torsion M_T),
//!   eliminated by hand into a closed form (derived at `with_offset`); the dense
//!   6x6 solve is the tests' reference.
//!
//! - In motion ([`TipForceEstimator::estimate_in_motion`]): the same, plus
//!   what the rod's inertia and the adapter's mass add (MODEL.md 10,
//!   [`crate::inertial`]); at rest, exactly [`TipForceEstimator::estimate`].
//!
//! Both return the number with its standard deviation, and flag it as not
//! observable ([`TipForceEstimate::observable`] false) when a standard deviation
//! exceeds the configured limit: near the singularity (tip at the support) the
//! estimate is dominated by noise; the guard acts on the flag and a recording
//! keeps the number. Only where there is no number at all (the tip at or behind
//! the support, a singular system) is the answer [`TipForceError::NotObservable`].

use crate::inertial::{Compensation, Rod, RodInertia, compensation};
use crate::motion::CarriageMotion;
use crate::{Calibration, Mat3, Pose, Profile, SensorNoise, SettingError, Vec3, check_finite};
use nalgebra::ComplexField;
use sar_kinematics::Shown;

/// How far |u|^2 (and |w|^2, u . w) of a pose may stray from 1 (and 0).
pub const POSE_UNIT_TOLERANCE: f64 = 1e-6;

/// Settings of the tip-force estimator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TipForceConfig {
    /// The observability limit: largest standard deviation of any axis of the
    /// tip force for which the estimate counts as observable, N (finite, > 0).
    /// Above it the estimate is still returned, flagged not observable. Its own
    /// setting, not the guard's: default [`TipForceConfig::DEFAULT_MAX_STD_N`].
    pub max_std_n: f64,
}

impl TipForceConfig {
    /// Default observability limit, N: 2 N, about ten times the HEX-6's lateral
    /// noise carried to the tip at the article's poses (0.2 to 0.6 N at a = 0.15 m
    /// with L = 0.35 m), so that it flags only poses close to the singularity.
    pub const DEFAULT_MAX_STD_N: f64 = 2.0;
}

impl Default for TipForceConfig {
    fn default() -> Self {
        Self {
            max_std_n: Self::DEFAULT_MAX_STD_N,
        }
    }
}

/// Why no tip force was given.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum TipForceError {
    /// An input is NaN or infinite.
    #[error("{input} is not a finite number ({value})")]
    NonFinite {
        /// Which input.
        input: &'static str,
        /// The offending value (the first non-finite component of a vector).
        value: f64,
    },
    /// There is no number: the tip is at or behind the support, or the system is
    /// singular (`std_max_n` is then infinite). A finite number whose standard
    /// deviation is merely above the limit is an estimate flagged
    /// [`TipForceEstimate::observable`] = false, not this error.
    #[error(
        "tip force not observable: standard deviation {} N above the limit \
         (tip {} m beyond the support)",
        Shown(*.std_max_n),
        Shown(*.lever_m)
    )]
    NotObservable {
        /// L - s: the tip's distance beyond the support along the rod, m.
        lever_m: f64,
        /// The largest per-axis standard deviation, N (infinite when singular).
        std_max_n: f64,
    },
    /// The pose is not one the forward kinematics can give.
    #[error("invalid pose: {quantity} = {value}")]
    InvalidPose {
        /// What is wrong: `"|rod_dir|^2 - 1"`, `"|rod_normal|^2 - 1"`,
        /// `"rod_dir . rod_normal"`, `"support_distance_m"`, `"support_along_rod_m"`.
        quantity: &'static str,
        /// Its value.
        value: f64,
    },
    /// The carriage's motion is not one the compensation can use (a
    /// negative or non-finite standard deviation of the acceleration).
    #[error("invalid motion: {quantity} = {value}")]
    InvalidMotion {
        /// Which value: `"accel_std_mps2"`.
        quantity: &'static str,
        /// Its value.
        value: f64,
    },
    /// The inputs are finite but so large that the result overflows.
    #[error("the tip force overflows (inputs far out of range)")]
    NonFiniteResult,
}

/// One tip-force estimate, all in the base frame {0}.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TipForceEstimate {
    /// F_tip = -F_D: what the tip applies to the tissue, N.
    pub force_n: Vec3,
    /// Per-axis standard deviation of `force_n` due to the sensor noise of one
    /// sample, N.
    pub std_n: Vec3,
    /// F_tip . u, N (positive: the tip pushes along the rod, into the tissue).
    pub axial_n: f64,
    /// |F_tip - (F_tip . u) u|, N.
    pub lateral_n: f64,
    /// F_A: what the robot applies to the rod at A, N.
    pub ujoint_force_n: Vec3,
    /// M_T: the U-joint's torsion on the rod along n = -(s4, 0, c4), N m (0 when d = 0).
    pub torsion_nm: f64,
    /// The standard deviation that the carriage's uncertain acceleration
    /// gives `torsion_nm` in motion ([`TipForceEstimator::estimate_in_motion`];
    /// 0 at rest and where the motion does not change M_T), N m.
    pub torsion_std_nm: f64,
    /// Every standard deviation is within the observability limit
    /// ([`TipForceConfig::max_std_n`]). When false the number is still what the
    /// model gives, but the guard must not trust it (a Fault).
    pub observable: bool,
}

/// The tip-force estimator: everything that does not change with the pose is
/// computed once, here.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TipForceEstimator {
    calibration: Calibration,
    /// C = R_0s diag(std^2) R_0s^T: covariance of F_A in {0}, N^2.
    covariance_n2: Symmetric3,
    /// The diagonal of C, N^2.
    covariance_diag_n2: Vec3,
    /// F = R_0s diag(std): C = F F^T (d != 0).
    noise_factor: Mat3,
    /// m g, N.
    weight_n: Vec3,
    /// m, kg.
    mass_kg: f64,
    length_m: f64,
    com_m: f64,
    offset_m: f64,
    max_std_n: f64,
    /// The rod's inertia and the adapter's mass (MODEL.md 10).
    inertia: RodInertia,
}

/// An estimate before its standard deviation is checked.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Raw {
    force_n: Vec3,
    var_n2: Vec3,
    lever_m: f64,
    ujoint_force_n: Vec3,
    torsion_nm: f64,
}

/// A symmetric 3x3 matrix by its six entries: its product with a vector is
/// written out, inline (nalgebra's 3x3 product is a call on the per-cycle path).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Symmetric3 {
    xx: f64,
    yy: f64,
    zz: f64,
    xy: f64,
    xz: f64,
    yz: f64,
}

impl Symmetric3 {
    /// The upper triangle of `m` (symmetric by construction where it is used).
    fn new(m: &Mat3) -> Self {
        Self {
            xx: m.m11,
            yy: m.m22,
            zz: m.m33,
            xy: m.m12,
            xz: m.m13,
            yz: m.m23,
        }
    }

    #[inline(always)]
    fn mul(&self, v: &Vec3) -> Vec3 {
        Vec3::new(
            self.xx * v.x + self.xy * v.y + self.xz * v.z,
            self.xy * v.x + self.yy * v.y + self.yz * v.z,
            self.xz * v.x + self.yz * v.y + self.zz * v.z,
        )
    }
}

/// sqrt(variance); a round-off negative variance gives 0, NaN gives infinity
/// (so that it fails the limit).
fn std_of_variance(var_n2: f64) -> f64 {
    if var_n2 >= 0.0 {
        <f64 as ComplexField>::sqrt(var_n2)
    } else if var_n2.is_nan() {
        f64::INFINITY
    } else {
        0.0
    }
}

/// The largest entry, with NaN counted as infinite.
fn worst(std_n: &Vec3) -> f64 {
    std_n.iter().fold(0.0, |acc: f64, &s| {
        if s.is_nan() {
            f64::INFINITY
        } else {
            acc.max(s)
        }
    })
}

impl TipForceEstimator {
    /// Builds the estimator; `config.max_std_n` must be finite and > 0.
    pub fn new(
        cal: &Calibration,
        profile: &Profile,
        noise: &SensorNoise,
        config: TipForceConfig,
    ) -> Result<Self, SettingError> {
        let max_std_n = config.max_std_n;
        if !(max_std_n.is_finite() && max_std_n > 0.0) {
            return Err(SettingError::Invalid {
                field: "max_std_n",
                value: max_std_n,
                why: "must be finite and > 0",
            });
        }
        let covariance_n2 = noise.base_covariance_n2(&cal.sensor_rotation());
        Ok(Self {
            calibration: *cal,
            covariance_n2: Symmetric3::new(&covariance_n2),
            covariance_diag_n2: covariance_n2.diagonal(),
            noise_factor: cal.sensor_rotation() * Mat3::from_diagonal(&noise.std_n()),
            weight_n: cal.gravity_mps2() * profile.mass_kg(),
            mass_kg: profile.mass_kg(),
            length_m: profile.length_m(),
            com_m: profile.com_m(),
            offset_m: profile.offset_m(),
            max_std_n,
            inertia: RodInertia::slender_rod(profile),
        })
    }

    /// The same estimator with the rod's inertia and the adapter's mass
    /// `inertia` (default [`RodInertia::slender_rod`]); each value must be
    /// finite and >= 0.
    pub fn with_inertia(self, inertia: RodInertia) -> Result<Self, SettingError> {
        inertia.check()?;
        Ok(Self { inertia, ..self })
    }

    /// The same estimator for the calibration `calibration` (another support
    /// point: the support watch's finite differences, [`crate::support`]).
    pub(crate) fn with_calibration(self, calibration: &Calibration) -> Self {
        Self {
            calibration: *calibration,
            ..self
        }
    }

    /// The covariance of one sample's F_A in {0}, N^2 (C = R_0s diag(std^2)
    /// R_0s^T: the support watch's weights).
    pub(crate) fn ujoint_covariance_n2(&self) -> Mat3 {
        self.noise_factor * self.noise_factor.transpose()
    }

    /// The rod's inertia and the adapter's mass in use.
    pub fn inertia(&self) -> &RodInertia {
        &self.inertia
    }

    /// The limit on the standard deviation, N.
    pub fn max_std_n(&self) -> f64 {
        self.max_std_n
    }

    /// The tip force for one reading.
    ///
    /// `pose` must come from [`sar_kinematics::forward`] with the calibration and
    /// profile this estimator was built with. `reading_n`: the raw sensor force,
    /// sensor frame, before bias removal; `bias_n`: the tare, sensor frame.
    pub fn estimate(
        &self,
        pose: &Pose,
        reading_n: &Vec3,
        bias_n: &Vec3,
    ) -> Result<TipForceEstimate, TipForceError> {
        let raw = self.raw(pose, reading_n, bias_n)?;
        self.finish(&pose.rod_dir, raw)
    }

    /// The tip force for one reading taken while the carriage moves with
    /// `motion` (MODEL.md 10): [`TipForceEstimator::estimate`] with the rod's
    /// inertia and the adapter's mass compensated ([`crate::inertial`]), its
    /// variance grown by what the acceleration's and I_perp's standard
    /// deviations give. With [`CarriageMotion::REST`] exactly `estimate`'s
    /// result, to the bit.
    pub fn estimate_in_motion(
        &self,
        pose: &Pose,
        reading_n: &Vec3,
        bias_n: &Vec3,
        motion: &CarriageMotion,
    ) -> Result<TipForceEstimate, TipForceError> {
        if motion.is_rest() {
            return self.estimate(pose, reading_n, bias_n);
        }
        check_motion(motion)?;
        let mut raw = self.raw(pose, reading_n, bias_n)?;
        let rod = Rod {
            mass_kg: self.mass_kg,
            com_m: self.com_m,
            length_m: self.length_m,
            offset_m: self.offset_m,
            inertia: self.inertia,
        };
        let Compensation {
            force_n,
            var_n2,
            adapter_n,
            torsion_nm,
            torsion_std_nm,
        } = compensation(&rod, pose, motion);
        raw.force_n += force_n;
        raw.var_n2 += var_n2;
        raw.ujoint_force_n -= adapter_n;
        raw.torsion_nm += torsion_nm;
        let estimate = self.finish(&pose.rod_dir, raw)?;
        if !torsion_std_nm.is_finite() {
            return Err(TipForceError::NonFiniteResult);
        }
        Ok(TipForceEstimate {
            torsion_std_nm,
            ..estimate
        })
    }

    /// What one kg m^2 more of I_perp and one kg more of the adapter's m_s
    /// add to the tip force at `pose` in `motion`, N per kg m^2 and N per
    /// kg: the compensation is linear in both (MODEL.md 10), so a plant
    /// whose I_perp and m_s are the configured ones plus dI and dm_s reads
    /// `-(dI d_inertia + dm_s d_adapter)` more tip force than it applies
    /// (the inertia watch, `crate::inertia_watch`). Zero at rest.
    pub fn inertia_sensitivity(&self, pose: &Pose, motion: &CarriageMotion) -> (Vec3, Vec3) {
        if motion.is_rest() {
            return (Vec3::zeros(), Vec3::zeros());
        }
        let rod = |inertia_perp_kgm2: f64, adapter_mass_kg: f64| Rod {
            mass_kg: self.mass_kg,
            com_m: self.com_m,
            length_m: self.length_m,
            offset_m: self.offset_m,
            inertia: RodInertia {
                inertia_perp_kgm2,
                inertia_perp_std_kgm2: 0.0,
                adapter_mass_kg,
                ..self.inertia
            },
        };
        let base = compensation(&rod(0.0, 0.0), pose, motion).force_n;
        let inertia = compensation(&rod(1.0, 0.0), pose, motion).force_n;
        let adapter = compensation(&rod(0.0, 1.0), pose, motion).force_n;
        (inertia - base, adapter - base)
    }

    /// The checks of `estimate` and the static model's number and variance.
    fn raw(&self, pose: &Pose, reading_n: &Vec3, bias_n: &Vec3) -> Result<Raw, TipForceError> {
        check_finite(reading_n, |value| TipForceError::NonFinite {
            input: "reading_n",
            value,
        })?;
        check_finite(bias_n, |value| TipForceError::NonFinite {
            input: "bias_n",
            value,
        })?;
        let u = pose.rod_dir;
        check_finite(&u, |value| TipForceError::NonFinite {
            input: "pose.rod_dir",
            value,
        })?;
        let unit_error = u.norm_squared() - 1.0;
        // `contains` is false for NaN.
        if !(-POSE_UNIT_TOLERANCE..=POSE_UNIT_TOLERANCE).contains(&unit_error) {
            return Err(TipForceError::InvalidPose {
                quantity: "|rod_dir|^2 - 1",
                value: unit_error,
            });
        }
        let f_a = crate::ujoint_force_n(&self.calibration, reading_n, bias_n);
        if self.offset_m == 0.0 {
            self.closed_form(pose, &u, &f_a)
        } else {
            self.with_offset(pose, &u, &f_a)
        }
    }

    /// Checks the standard deviation (from the per-axis variance `var_n2`) and
    /// the result, and assembles the estimate.
    fn finish(&self, u: &Vec3, raw: Raw) -> Result<TipForceEstimate, TipForceError> {
        let Raw {
            force_n,
            var_n2,
            lever_m,
            ujoint_force_n,
            torsion_nm,
        } = raw;
        let std_n = var_n2.map(std_of_variance);
        // NaN never counts as within the limit; an infinite deviation means no
        // number at all.
        let std_max_n = worst(&std_n);
        if std_max_n == f64::INFINITY {
            return Err(TipForceError::NotObservable { lever_m, std_max_n });
        }
        let observable = std_n.iter().all(|&s| s <= self.max_std_n);
        check_finite(&force_n, |_| TipForceError::NonFiniteResult)?;
        if !torsion_nm.is_finite() {
            return Err(TipForceError::NonFiniteResult);
        }
        let axial_n = force_n.dot(u);
        let lateral_n = (force_n - u * axial_n).norm();
        if !(axial_n.is_finite() && lateral_n.is_finite()) {
            return Err(TipForceError::NonFiniteResult);
        }
        // What the guard trusts in an estimate: every deviation a finite
        // number >= 0 (NaN and infinity were turned away above), so that the
        // observability flag and the guard's margin compare real numbers.
        debug_assert!(
            std_n.iter().all(|s| s.is_finite() && *s >= 0.0),
            "std_n {std_n:?}"
        );
        Ok(TipForceEstimate {
            force_n,
            std_n,
            axial_n,
            lateral_n,
            ujoint_force_n,
            torsion_nm,
            torsion_std_nm: 0.0,
            observable,
        })
    }

    /// MODEL.md 4.1 (d = 0).
    fn closed_form(&self, pose: &Pose, u: &Vec3, f_a: &Vec3) -> Result<Raw, TipForceError> {
        let a = pose.support_distance_m;
        check_finite(&[a], |value| TipForceError::NonFinite {
            input: "pose.support_distance_m",
            value,
        })?;
        // a and L are finite from here, so are L - a and the comparisons.
        if a <= 0.0 {
            return Err(TipForceError::InvalidPose {
                quantity: "support_distance_m",
                value: a,
            });
        }
        let lever_m = self.length_m - a;
        if lever_m <= 0.0 {
            return Err(TipForceError::NotObservable {
                lever_m,
                std_max_n: f64::INFINITY,
            });
        }
        let k = a / lever_m;
        // F_tip . u = -F_D . u = (F_A + m g) . u
        let axial = (f_a + self.weight_n).dot(u);
        // F_tip_perp = -F_D_perp = -(a F_A_perp + (a - c) m g_perp) / (L - a)
        let moment = f_a * a + self.weight_n * (a - self.com_m);
        let moment_perp = moment - u * moment.dot(u);
        let force_n = u * axial - moment_perp / lever_m;
        // J = dF_tip/dF_A = u u^T - k (I - u u^T) = (1 + k) u u^T - k I, and
        // diag(J C J^T)_i = k^2 C_ii - 2 k (1 + k) u_i (C u)_i + (1 + k)^2 u_i^2 (u . C u).
        let cu = self.covariance_n2.mul(u);
        let ucu = u.dot(&cu);
        let p = 1.0 + k;
        let var_n2 = self.covariance_diag_n2 * (k * k) - u.component_mul(&cu) * (2.0 * k * p)
            + u.component_mul(u) * (p * p * ucu);
        Ok(Raw {
            force_n,
            var_n2,
            lever_m,
            ujoint_force_n: *f_a,
            torsion_nm: 0.0,
        })
    }

    /// MODEL.md 4.3 (d != 0) in closed form: the six equilibrium equations
    /// eliminated by hand.
    ///
    /// Write every vector in the orthonormal basis (u, w, v) of the rod, with
    /// v = u x w the q5 axis (u x w = v, w x v = u, v x u = w); x_u = x . u and
    /// so on. Relative to A: r_B = d w + s u, r_C = d w + c u, r_D = d w + L u.
    /// Unknowns: F_D; the support's reaction across u, F_B = b1 w + b2 v; the
    /// U-joint torsion M_T along n = Y0 x v = -(s4, 0, c4), whose components are
    /// n_u = n . u = w_y (= -c5), n_w = n . w = -u_y (= -s5), n_v = 0. G = m g.
    ///
    /// Force balance, F_A + F_B + G + F_D = 0, by component:
    ///
    /// ```text
    /// u:  F_Au + G_u + D_u = 0          =>  D_u = -(F_Au + G_u)
    /// w:  F_Aw + b1 + G_w + D_w = 0     =>  b1  = -(F_Aw + G_w + D_w)
    /// v:  F_Av + b2 + G_v + D_v = 0     =>  b2  = -(F_Av + G_v + D_v)
    /// ```
    ///
    /// Moments about A (F_A acts at A), r_B x F_B + r_C x G + r_D x F_D + M_T n
    /// = 0. For r = d w + l u and any F: r x F = d F_v u - l F_v w + (l F_w - d F_u) v,
    /// and r_B x F_B = d b2 u - s b2 w + s b1 v. Projected:
    ///
    /// ```text
    /// on u:      d (b2 + G_v + D_v) + n_u M_T = 0
    /// on w:     -s b2 - c G_v - L D_v + n_w M_T = 0
    /// on v:      s b1 + c G_w - d G_u + L D_w - d D_u = 0
    /// ```
    ///
    /// The projection on v holds no torsion: with b1 and D_u from the force
    /// balance (the G_u terms cancel),
    ///
    /// ```text
    /// (L - s) D_w = s F_Aw + (s - c) G_w - d F_Au.
    /// ```
    ///
    /// The projection on u is, with b2 from the force balance, -d F_Av + n_u M_T = 0:
    ///
    /// ```text
    /// M_T = d F_Av / n_u,
    /// ```
    ///
    /// and the projection on w, with b2 and this M_T,
    ///
    /// ```text
    /// (L - s) D_v = (s + d n_w / n_u) F_Av + (s - c) G_v.
    /// ```
    ///
    /// With F_tip = -F_D and 1 / (L - s) = 1 / lever:
    ///
    /// ```text
    /// F_tip = T_u u + T_w w + T_v v,
    /// T_u = F_Au + G_u
    /// T_w = alpha F_Au + beta F_Aw - (s - c) / lever G_w
    /// T_v = gamma F_Av - (s - c) / lever G_v
    /// alpha = d / lever,  beta = -s / lever,  gamma = -(s - d u_y / w_y) / lever.
    /// ```
    ///
    /// With d = 0 this is MODEL.md 4.1 (with a = s). F_tip is affine in F_A, so
    /// its exact Jacobian is J = dF_tip/dF_A = (u + alpha w) u^T + beta w w^T +
    /// gamma v v^T, and the per-axis variance is diag(J C J^T). With
    /// w w^T = I - u u^T - v v^T, J = beta I + p u^T + q v^T where
    /// p = (1 - beta) u + alpha w and q = (gamma - beta) v (alpha and q are of
    /// order d: with d = 0 this is the J of `closed_form`, k = -beta). With
    /// C = F F^T, F = R_0s diag(std) and F_i the rows of F:
    ///
    /// ```text
    /// F_tip = J F_A + G_u u - (s - c) / lever (G - G_u u)
    /// diag(J C J^T)_i = |F^T J^T e_i|^2 = |beta F_i + p_i F^T u + q_i F^T v|^2
    /// ```
    ///
    /// (a sum of squares, never negative; no 3x3 product).
    ///
    /// The system is singular (no number: [`TipForceError::NotObservable`] with
    /// an infinite deviation) exactly where lever <= 0 (the tip at or behind the
    /// support) or n_u = w_y = 0 (a vertical rod: the torsion then has no part
    /// along u, the moment about u says F_Av = 0, and M_T, D_v are free). Close
    /// to either, the deviation grows without bound (1 / lever, 1 / w_y) and the
    /// estimate is flagged by the observability limit; a deviation that
    /// overflows is the singular case too.
    ///
    /// The basis is taken as orthonormal: u and w are checked unit and
    /// perpendicular to [`POSE_UNIT_TOLERANCE`], which the forward kinematics
    /// meet to round-off.
    fn with_offset(&self, pose: &Pose, u: &Vec3, f_a: &Vec3) -> Result<Raw, TipForceError> {
        let w = pose.rod_normal;
        let s = pose.support_along_rod_m;
        // One test each on the way of a good pose; which input is wrong, and
        // how, is sorted out only when one fails (`contains` and `<` are false
        // for NaN, and a NaN or infinite w fails the unit test).
        let tolerance = -POSE_UNIT_TOLERANCE..=POSE_UNIT_TOLERANCE;
        let unit_error = w.norm_squared() - 1.0;
        let cross = u.dot(&w);
        if !(tolerance.contains(&unit_error) && tolerance.contains(&cross)) {
            return Err(Self::bad_normal(w, unit_error, cross));
        }
        let length = self.length_m;
        let lever_m = length - s;
        // n_u = n . u = w_y (n = Y0 x (u x w), MODEL.md 4: right also for the
        // rods with c5 < 0 that the forward kinematics give with d != 0).
        let n_u = w.y;
        if !(s > 0.0 && s < length && n_u != 0.0) {
            return Err(Self::bad_support(s, lever_m));
        }
        let (ux, uy, uz) = (u.x, u.y, u.z);
        let (wx, wy, wz) = (w.x, w.y, w.z);
        // v = u x w
        let (vx, vy, vz) = (uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx);
        let d = self.offset_m;
        let inv_lever = 1.0 / lever_m;
        let inv_n_u = 1.0 / n_u;
        let beta = -s * inv_lever;
        let alpha = d * inv_lever;
        // gamma - beta = d u_y / (w_y lever)
        let delta = d * uy * inv_n_u * inv_lever;
        let weight_arm = (s - self.com_m) * inv_lever;
        // J = beta I + p u^T + q v^T
        let one_beta = 1.0 - beta;
        let (px, py, pz) = (
            one_beta * ux + alpha * wx,
            one_beta * uy + alpha * wy,
            one_beta * uz + alpha * wz,
        );
        let (qx, qy, qz) = (delta * vx, delta * vy, delta * vz);
        let (fx, fy, fz) = (f_a.x, f_a.y, f_a.z);
        let g = &self.weight_n;
        let fa_u = fx * ux + fy * uy + fz * uz;
        let fa_v = fx * vx + fy * vy + fz * vz;
        let g_u = g.x * ux + g.y * uy + g.z * uz;
        // F_tip = J F_A + G_u u - (s - c) / lever (G - G_u u)
        let g_along = g_u * (1.0 + weight_arm);
        let force_n = Vec3::new(
            beta * fx + px * fa_u + qx * fa_v + g_along * ux - weight_arm * g.x,
            beta * fy + py * fa_u + qy * fa_v + g_along * uy - weight_arm * g.y,
            beta * fz + pz * fa_u + qz * fa_v + g_along * uz - weight_arm * g.z,
        );
        let torsion_nm = d * fa_v * inv_n_u;
        let v = Vec3::new(vx, vy, vz);
        let var_n2 = self.offset_variance_n2(u, &v, beta, [px, py, pz], [qx, qy, qz]);
        Ok(Raw {
            force_n,
            var_n2,
            lever_m,
            ujoint_force_n: *f_a,
            torsion_nm,
        })
    }

    /// The per-axis variance of `with_offset`'s F_tip, N^2, for its Jacobian
    /// `J = beta I + p u^T + q v^T`: diag(J C J^T)_i = |F^T J^T e_i|^2 =
    /// |beta F_i + p_i a + q_i b|^2 with F_i the rows of the noise factor F,
    /// a = F^T u, b = F^T v.
    fn offset_variance_n2(&self, u: &Vec3, v: &Vec3, beta: f64, p: [f64; 3], q: [f64; 3]) -> Vec3 {
        let f = &self.noise_factor;
        let a = f.tr_mul(u);
        let b = f.tr_mul(v);
        let row = |fi: Vec3, p: f64, q: f64| (fi * beta + a * p + b * q).norm_squared();
        Vec3::new(
            row(Vec3::new(f.m11, f.m12, f.m13), p[0], q[0]),
            row(Vec3::new(f.m21, f.m22, f.m23), p[1], q[1]),
            row(Vec3::new(f.m31, f.m32, f.m33), p[2], q[2]),
        )
    }

    /// Why w failed the unit tests of `with_offset` (`unit_error` = |w|^2 - 1,
    /// `cross` = u . w): not finite, not unit, or not perpendicular to u.
    #[cold]
    fn bad_normal(w: Vec3, unit_error: f64, cross: f64) -> TipForceError {
        if let Err(e) = check_finite(&w, |value| TipForceError::NonFinite {
            input: "pose.rod_normal",
            value,
        }) {
            return e;
        }
        if !(-POSE_UNIT_TOLERANCE..=POSE_UNIT_TOLERANCE).contains(&unit_error) {
            TipForceError::InvalidPose {
                quantity: "|rod_normal|^2 - 1",
                value: unit_error,
            }
        } else {
            TipForceError::InvalidPose {
                quantity: "rod_dir . rod_normal",
                value: cross,
            }
        }
    }

    /// Why s (with L - s = `lever_m`) or the pose failed `with_offset`'s
    /// range test: s not finite, s <= 0, or singular (the tip at or behind the
    /// support, or a vertical rod).
    #[cold]
    fn bad_support(s: f64, lever_m: f64) -> TipForceError {
        if !s.is_finite() {
            TipForceError::NonFinite {
                input: "pose.support_along_rod_m",
                value: s,
            }
        } else if s <= 0.0 {
            TipForceError::InvalidPose {
                quantity: "support_along_rod_m",
                value: s,
            }
        } else {
            TipForceError::NotObservable {
                lever_m,
                std_max_n: f64::INFINITY,
            }
        }
    }
}

// The snapshot's configuration fingerprint (names and values, never `Debug`).
sar_snapshot::config_struct!(TipForceEstimator {
    calibration,
    covariance_n2,
    covariance_diag_n2,
    noise_factor,
    weight_n,
    length_m,
    com_m,
    offset_m,
    max_std_n,
    mass_kg,
    inertia,
});
sar_snapshot::config_struct!(Symmetric3 {
    xx,
    yy,
    zz,
    xy,
    xz,
    yz
});

/// The motion's values finite, its acceleration's deviation >= 0.
fn check_motion(motion: &CarriageMotion) -> Result<(), TipForceError> {
    check_finite(&motion.velocity_mps, |value| TipForceError::NonFinite {
        input: "motion.velocity_mps",
        value,
    })?;
    check_finite(&motion.accel_mps2, |value| TipForceError::NonFinite {
        input: "motion.accel_mps2",
        value,
    })?;
    let std = motion.accel_std_mps2;
    if std.is_finite() && std >= 0.0 {
        Ok(())
    } else {
        Err(TipForceError::InvalidMotion {
            quantity: "accel_std_mps2",
            value: std,
        })
    }
}
