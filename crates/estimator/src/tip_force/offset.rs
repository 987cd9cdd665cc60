//! d != 0: the six equilibrium equations of MODEL.md 4.3 eliminated by hand
//! into a closed form, with the variance the sensor's noise gives it.

use super::{POSE_UNIT_TOLERANCE, Raw, TipForceError, TipForceEstimator};
use crate::{Pose, Vec3};

impl TipForceEstimator {
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
    pub(super) fn with_offset(
        &self,
        pose: &Pose,
        u: &Vec3,
        f_a: &Vec3,
    ) -> Result<Raw, TipForceError> {
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
    pub(super) fn offset_variance_n2(
        &self,
        u: &Vec3,
        v: &Vec3,
        beta: f64,
        p: [f64; 3],
        q: [f64; 3],
    ) -> Vec3 {
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
}
