//! The model of support calibration (MODEL.md 5.1): the unknowns by name, which
//! of them a fit holds, the force the robot applies at A with its Jacobian, and
//! the weighted least-squares problem over the poses held (cost, normal
//! equations, and the cost with (m, M, f) eliminated for a given B).

use super::SupportError;
use crate::{Calibration, MIN_SUPPORT_DISTANCE_M, Mat3, StaticPose, Vec3, ujoint_force_n};
use nalgebra::{ComplexField, SMatrix, SVector};

/// Number of unknowns (m, M, B_x, B_y, B_z, f).
pub(super) const N_UNKNOWNS: usize = 6;

/// A vector over the unknowns, in the order of [`Unknown::ALL`].
pub(super) type Vec6 = SVector<f64, N_UNKNOWNS>;
/// A matrix over the unknowns.
pub(super) type Mat6 = SMatrix<f64, N_UNKNOWNS, N_UNKNOWNS>;
/// The Jacobian of F_A (3 components) with respect to the unknowns.
type Jac = SMatrix<f64, 3, N_UNKNOWNS>;

/// The cost's rounding floor, relative to the sum of the squared whitened
/// measurements: (64 eps)^2.
const COST_FLOOR: f64 = (64.0 * f64::EPSILON) * (64.0 * f64::EPSILON);

/// One unknown of the fit, in the order of the vectors and matrices.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Unknown {
    Mass,
    Moment,
    SupportX,
    SupportY,
    SupportZ,
    Friction,
}

impl Unknown {
    /// Every unknown, in vector order.
    pub(super) const ALL: [Self; N_UNKNOWNS] = [
        Self::Mass,
        Self::Moment,
        Self::SupportX,
        Self::SupportY,
        Self::SupportZ,
        Self::Friction,
    ];

    /// The name in [`SupportError::Undetermined`].
    pub(super) const fn name(self) -> &'static str {
        match self {
            Self::Mass => "mass_kg",
            Self::Moment => "moment_kgm",
            Self::SupportX => "support_x_m",
            Self::SupportY => "support_y_m",
            Self::SupportZ => "support_z_m",
            Self::Friction => "friction_n",
        }
    }

    /// What may help when this unknown is not determined.
    pub(super) const fn hint(self) -> &'static str {
        match self {
            Self::Mass | Self::Moment => "",
            Self::SupportX | Self::SupportY | Self::SupportZ => ", tilt and turn the rod",
            Self::Friction => " and slide the rod both ways (or turn the friction unknown off)",
        }
    }
}

/// The unknowns by name.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Params {
    /// m, kg.
    pub mass_kg: f64,
    /// M = m c, kg m.
    pub moment_kgm: f64,
    /// B, {0}, m.
    pub support_m: Vec3,
    /// f, N.
    pub friction_n: f64,
}

impl Params {
    /// The vector in [`Unknown::ALL`] order.
    pub(super) fn to_vector(self) -> Vec6 {
        let b = self.support_m;
        Vec6::new(
            self.mass_kg,
            self.moment_kgm,
            b.x,
            b.y,
            b.z,
            self.friction_n,
        )
    }

    /// From a vector in [`Unknown::ALL`] order (destructured: no index).
    pub(super) fn from_vector(v: &Vec6) -> Self {
        let [mass_kg, moment_kgm, x, y, z, friction_n]: [f64; N_UNKNOWNS] = (*v).into();
        Self {
            mass_kg,
            moment_kgm,
            support_m: Vec3::new(x, y, z),
            friction_n,
        }
    }
}

/// Which unknowns a fit estimates; m and M always, the others as set. A held
/// unknown keeps its value (the configured B, f = 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Free {
    /// B_x, B_y, B_z.
    pub support: [bool; 3],
    /// f.
    pub friction: bool,
}

impl Free {
    /// m, M and (if `friction`) f; all of B held.
    pub(super) const fn base(friction: bool) -> Self {
        Self {
            support: [false; 3],
            friction,
        }
    }

    /// 1 for each free unknown, 0 for each held one.
    pub(super) fn mask(&self) -> Vec6 {
        let one = |free: bool| if free { 1.0 } else { 0.0 };
        let [x, y, z] = self.support.map(one);
        Vec6::new(1.0, 1.0, x, y, z, one(self.friction))
    }

    /// How many unknowns are free.
    pub(super) fn count(&self) -> usize {
        2 + self.support.iter().filter(|&&f| f).count() + usize::from(self.friction)
    }

    /// Sets the held components of B in `theta` to `configured`.
    pub(super) fn reset_held(&self, theta: &mut Params, configured: &Vec3) {
        let [fx, fy, fz] = self.support;
        let b = &mut theta.support_m;
        if !fx {
            b.x = configured.x;
        }
        if !fy {
            b.y = configured.y;
        }
        if !fz {
            b.z = configured.z;
        }
    }
}

/// The weighted least-squares problem over the poses held.
pub(super) struct Problem<'a> {
    pub poses: &'a [StaticPose],
    pub calibration: &'a Calibration,
    /// Inverse of the lower Cholesky factor of one sample's covariance of F_A in {0}.
    pub whitening: &'a Mat3,
    pub tare_n: &'a Vec3,
    pub gravity: Vec3,
    /// Whether f is estimated: a pose with an unknown slide sign is then refused.
    pub friction: bool,
}

/// Normal equations of one linearisation, over all unknowns.
#[derive(Debug, Clone, Copy)]
pub(super) struct Normal {
    /// J^T J of the whitened Jacobian.
    pub matrix: Mat6,
    /// J^T r.
    pub rhs: Vec6,
    /// r^T r (chi-square).
    pub cost: f64,
    /// Sum of squared unwhitened residuals, N^2.
    pub raw_sq_n2: f64,
    /// Below this the cost is rounding ([`COST_FLOOR`] times the sum of the
    /// squared whitened measurements).
    pub cost_floor: f64,
}

impl Normal {
    /// The same equations with the held unknowns' rows and columns zero.
    pub(super) fn masked(&self, free: &Free) -> Self {
        let mask = free.mask();
        let diag = Mat6::from_diagonal(&mask);
        Self {
            matrix: diag * self.matrix * diag,
            rhs: self.rhs.component_mul(&mask),
            ..*self
        }
    }
}

/// `x < limit`, or NaN.
pub(super) fn below_or_nan(x: f64, limit: f64) -> bool {
    x.is_nan() || x < limit
}

impl Problem<'_> {
    /// The friction coefficient sigma of pose `index`; an unknown sign is an
    /// error when f is estimated, and contributes no friction term otherwise
    /// (f is then held at 0, so no value of sigma could change the model).
    fn sigma(&self, index: usize, pose: &StaticPose) -> Result<Option<f64>, SupportError> {
        match pose.slide_sign.sigma() {
            Some(sigma) => Ok(Some(sigma)),
            None if self.friction => Err(SupportError::UnknownSlideSign { pose: index }),
            None => Ok(None),
        }
    }

    /// Model F_A and its Jacobian with respect to (m, M, B, f) at one pose.
    /// `None` when A is closer than [`MIN_SUPPORT_DISTANCE_M`] to B.
    fn model(
        pose: &StaticPose,
        sigma: Option<f64>,
        theta: &Params,
        g: &Vec3,
    ) -> Option<(Vec3, Jac)> {
        let r = theta.support_m - pose.ujoint_m;
        let a = r.norm();
        if below_or_nan(a, MIN_SUPPORT_DISTANCE_M) {
            return None;
        }
        let u = r / a;
        let gu = g.dot(&u);
        let g_perp = g - u * gu;
        let moment = theta.moment_kgm;
        let p = Mat3::identity() - u * u.transpose();
        // d u / d B = P / a with P = I - u u^T; d a / d B = u^T.
        let gravity_part =
            -(g_perp * u.transpose() + u * g_perp.transpose() + p * gu) * (moment / (a * a));
        let (force_friction, d_support, d_friction) = match sigma {
            Some(s) => (
                u * (s * theta.friction_n),
                gravity_part + p * (s * theta.friction_n / a),
                u * s,
            ),
            None => (Vec3::zeros(), gravity_part, Vec3::zeros()),
        };
        let force = -g * theta.mass_kg + g_perp * (moment / a) + force_friction;
        let [d_x, d_y, d_z]: [[f64; 3]; 3] = d_support.into();
        let jac = Jac::from_columns(&[
            -g,
            g_perp / a,
            Vec3::from(d_x),
            Vec3::from(d_y),
            Vec3::from(d_z),
            d_friction,
        ]);
        Some((force, jac))
    }

    fn measured_n(&self, pose: &StaticPose) -> Vec3 {
        ujoint_force_n(self.calibration, &pose.mean_reading_n, self.tare_n)
    }

    fn weight(&self, pose: &StaticPose) -> Mat3 {
        self.whitening * ComplexField::sqrt(f64::from(pose.samples))
    }

    /// Normal equations over all unknowns at `theta` (one pass over the poses).
    pub(super) fn normal(&self, theta: &Params) -> Result<Normal, SupportError> {
        let mut out = Normal {
            matrix: Mat6::zeros(),
            rhs: Vec6::zeros(),
            cost: 0.0,
            raw_sq_n2: 0.0,
            cost_floor: 0.0,
        };
        for (index, pose) in self.poses.iter().enumerate() {
            let sigma = self.sigma(index, pose)?;
            let Some((force, jac)) = Self::model(pose, sigma, theta, &self.gravity) else {
                return Err(too_close(index, pose, &theta.support_m));
            };
            let w = self.weight(pose);
            let measured = self.measured_n(pose);
            let e = measured - force;
            let r = w * e;
            out.cost_floor += COST_FLOOR * (w * measured).norm_squared();
            let a = w * jac;
            out.matrix += a.transpose() * a;
            out.rhs += a.transpose() * r;
            out.cost += r.norm_squared();
            out.raw_sq_n2 += e.norm_squared();
        }
        Ok(out)
    }

    /// Chi-square at the support `support_m` with (m, M, f) at their best
    /// values for it (the model is linear in them: variable projection). `None`
    /// when a pose is too close to `support_m` or (m, M, f) are not determined
    /// there. f is eliminated only when the problem estimates it.
    pub(super) fn projected_cost(&self, support_m: &Vec3) -> Option<f64> {
        let mut matrix = SMatrix::<f64, 3, 3>::zeros();
        let mut rhs = Vec3::zeros();
        let mut yy = 0.0;
        let g = self.gravity;
        for pose in self.poses {
            let r = support_m - pose.ujoint_m;
            let a = r.norm();
            if below_or_nan(a, MIN_SUPPORT_DISTANCE_M) {
                return None;
            }
            let u = r / a;
            let g_perp = g - u * g.dot(&u);
            let friction_column = match pose.slide_sign.sigma() {
                Some(s) if self.friction => u * s,
                _ => Vec3::zeros(),
            };
            let w = self.weight(pose);
            let columns = w * Mat3::from_columns(&[-g, g_perp / a, friction_column]);
            let y = w * self.measured_n(pose);
            matrix += columns.transpose() * columns;
            rhs += columns.transpose() * y;
            yy += y.norm_squared();
        }
        if !self.friction {
            // f is not an unknown: a unit pivot keeps the 3x3 solvable (its
            // column and right-hand side are zero, so f = 0).
            matrix.m33 = 1.0;
        }
        let x = matrix.cholesky()?.solve(&rhs);
        let cost = yy - rhs.dot(&x);
        cost.is_finite().then_some(cost.max(0.0))
    }
}

/// The error for a pose closer than [`MIN_SUPPORT_DISTANCE_M`] to `support_m`.
pub(super) fn too_close(index: usize, pose: &StaticPose, support_m: &Vec3) -> SupportError {
    SupportError::UJointAtSupport {
        pose: index,
        distance_m: support_m.metric_distance(&pose.ujoint_m),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]
    use super::*;
    use crate::SlideSign;

    /// The analytic Jacobian agrees with central differences, for each sign.
    #[test]
    fn jacobian_matches_finite_differences() {
        let g = Vec3::new(0.0, -9.80665, 0.0);
        for sign in [SlideSign::Retracting, SlideSign::Inserting] {
            let pose = StaticPose {
                ujoint_m: Vec3::new(0.36, 0.15, -0.03),
                mean_reading_n: Vec3::zeros(),
                samples: 1,
                slide_sign: sign,
            };
            let sigma = sign.sigma();
            let theta = Vec6::from_column_slice(&[2.1, 0.23, 0.452, 0.198, 0.003, 0.37]);
            let (_, jac) = Problem::model(&pose, sigma, &Params::from_vector(&theta), &g).unwrap();
            for k in 0..N_UNKNOWNS {
                let h = 1e-6;
                let mut plus = theta;
                let mut minus = theta;
                plus[k] += h;
                minus[k] -= h;
                let (fp, _) =
                    Problem::model(&pose, sigma, &Params::from_vector(&plus), &g).unwrap();
                let (fm, _) =
                    Problem::model(&pose, sigma, &Params::from_vector(&minus), &g).unwrap();
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

    #[test]
    fn params_round_trip_in_vector_order() {
        let v = Vec6::new(1.0, 2.0, 3.0, 4.0, 5.0, 6.0);
        let p = Params::from_vector(&v);
        assert_eq!(p.mass_kg, 1.0);
        assert_eq!(p.moment_kgm, 2.0);
        assert_eq!(p.support_m, Vec3::new(3.0, 4.0, 5.0));
        assert_eq!(p.friction_n, 6.0);
        assert_eq!(p.to_vector(), v);
        let free = Free {
            support: [true, false, true],
            friction: false,
        };
        assert_eq!(free.mask(), Vec6::new(1.0, 1.0, 1.0, 0.0, 1.0, 0.0));
        assert_eq!(free.count(), 4);
    }
}
