//! d = 0: the closed form of MODEL.md 4.1 with its covariance, and the
//! errors of a pose or a support that give no number.

use super::{POSE_UNIT_TOLERANCE, Raw, TipForceError, TipForceEstimator};
use crate::{Pose, Vec3, check_finite};

impl TipForceEstimator {
    /// MODEL.md 4.1 (d = 0).
    pub(super) fn closed_form(
        &self,
        pose: &Pose,
        u: &Vec3,
        f_a: &Vec3,
    ) -> Result<Raw, TipForceError> {
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

    /// Why w failed the unit tests of `with_offset` (`unit_error` = |w|^2 - 1,
    /// `cross` = u . w): not finite, not unit, or not perpendicular to u.
    #[cold]
    pub(super) fn bad_normal(w: Vec3, unit_error: f64, cross: f64) -> TipForceError {
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
    pub(super) fn bad_support(s: f64, lever_m: f64) -> TipForceError {
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
