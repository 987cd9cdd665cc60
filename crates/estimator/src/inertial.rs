//! The rod's inertia in the tip force (MODEL.md 10): what the carriage's
//! motion ([`CarriageMotion`]: A', A'' and the standard deviation of A'')
//! adds to the static estimate of [`crate::tip_force`], for d = 0 and
//! d != 0, and what the acceleration's and the inertia's uncertainties add
//! to its variance.
//!
//! **The loads.** The rod's Newton-Euler equations (MODEL.md 10) are the
//! statics of MODEL.md 4 with two changes: the weight G = m g at C becomes
//! G' = m (g - a_C), and the moment equation about A (a point fixed in the
//! rod) gains the couple -H', H the angular momentum about C. An adapter of
//! mass m_s between the sensor and the U-joint (lumped at A, as the
//! simulator has it: `sar_sim::statics::ideal_wrench_in_motion`)
//! makes the sensor read -F_A - m_s A'' (its gravity is in the bias), so
//! -R_0s (f - b_f) = F_A + m_s A'' and the rod's F_A is that minus m_s A''.
//! Every change is linear in the loads, so the tip force in motion is the
//! static one plus
//!
//! ```text
//! dF = -m_s J A'' - m T_G(a_C) + T_H(H')
//! J x   = beta x + p (u . x) + q (v . x)        (tip_force's dF_tip/dF_A)
//! T_G y = y_u u - (s - c) / lever (y - y_u u)   (the weight's map, any d)
//! T_H h = (u x h + (u_y / w_y) h_u v) / lever
//! ```
//!
//! T_H is `with_offset`'s elimination (see there) with the couple -H' added:
//! on u, -d F_Av + n_u M_T - H'_u = 0, so M_T = (d F_Av + H'_u) / w_y; on w,
//! lever D_v = (s - d u_y / w_y) F_Av + (s - c) G'_v - (u_y / w_y) H'_u - H'_w;
//! on v, lever D_w = s F_Aw + (s - c) G'_w - d F_Au + H'_v; F_tip = -F_D and
//! u x h = h_w v - h_v w. With d = 0 and I_axial = 0, H'_u = 0 and this is
//! MODEL.md 10's closed form. The torsion changes by
//! dM_T = (H'_u - d m_s (A'' . v)) / w_y (H'_u = I_axial (omega' . u)).
//!
//! **The rod's motion** (r = B - A = s u + d w, r' = -A', r'' = -A'',
//! rho^2 = s^2 + d^2 so s s' = r . r'). The rod turns with the U-joint:
//! omega = q4' Y0 + q5' v, so omega . n = 0 with n = Y0 x v, and every vector
//! of the rod's frame moves as x' = omega x x. Then r' = s' u + omega x r,
//! and crossing with r (r x u = -d v):
//!
//! ```text
//! omega = (r x r' + s' d v + lambda r) / rho^2,   lambda = -((r x r') . n) / (r . n)
//! ```
//!
//! (lambda = r . omega, fixed by omega . n = 0). Differentiating
//! r' = s' u + omega x r once more, omega' x r = P with
//! P = r'' - s'' u - s' (omega x u) - omega x r' and
//! s s'' = r' . r' + r . r'' - s'^2; with v' = q4' n, omega' . n = q4' q5' =
//! omega_y (omega . v), so
//!
//! ```text
//! omega' = (r x P + mu r) / rho^2,   mu = (rho^2 omega_y (omega . v) - (r x P) . n) / (r . n)
//! u'' = omega' x u + omega x (omega x u)       (w'' likewise)
//! a_C = A'' + c u'' + d w'',   H' = I_C omega' + omega x (I_C omega)
//! ```
//!
//! with I_C = I_perp (E - u u^T) + I_axial u u^T. All closed form: no finite
//! difference. omega' is affine in A'' (P is: r'' enters as r'' - (r . r'' / s) u),
//! so dF is too: dF = K A'' + dF_0, with dF_0 the velocity's part (A'' = 0)
//! and the columns of K the linear part at A'' = e_j. r . n = -r_h (the
//! rod's horizontal reach) is zero only for a vertical rod, where w_y = 0 is
//! singular already.
//!
//! **d = 0, I_axial = 0** (the default rod) in closed form (MODEL.md 10:
//! u' = (r' - rho' u) / a, u'' = (r'' - rho'' u - 2 rho' u') / a): with
//! M = m + m_s, k = a / lever,
//! kappa = (m_s a + m (a - c)^2 / a + I_perp / a) / lever,
//!
//! ```text
//! K = kappa (E - u u^T) - M u u^T
//! dF_0 = -m c u''_0,u u + (m c (a - c) / lever - I_perp / lever) u''_0,perp
//! u''_0 = (-(u' . r') u - 2 rho' u') / a        (u'' at A'' = 0)
//! ```
//!
//! (MODEL.md 10's table: along X0 at the nominal pose K gives m = 2.59 N per
//! m/s^2, across kappa = 0.81 + 33.3 I_perp N per m/s^2).
//!
//! **The variance** (beyond MODEL.md 10). Each component of A'' has the
//! standard deviation `accel_std_mps2`, independently: F_tip being affine in
//! A'', its variance gains sigma_a^2 sum_j K_ij^2 (for d = 0,
//! sigma_a^2 (kappa^2 + (M^2 - kappa^2) u_i^2)). F_tip is linear in I_perp
//! too, dF/dI_perp = T_H(omega'_perp - (u . omega) omega x u) (for d = 0,
//! -u''_perp / lever), so it gains sigma_I^2 (dF_i/dI_perp)^2. The
//! uncertainties of m, c, I_axial and m_s are not counted (MODEL.md 10
//! "Accuracy": m's enters as its error times A''). The torsion's change is
//! affine in A'' too: its standard deviation sigma_a |dM_T/dA''| widens the
//! torque check's (only where it is not 0: d != 0 with I_axial or m_s).
//!
//! As in the static estimate, the support's friction along the rod (MODEL.md
//! 10's f_axial) is not modelled: it reads as an axial tip force.

use crate::motion::CarriageMotion;
use crate::{Pose, Profile, SettingError, Vec3, finite_non_negative};

/// The rod's inertia and the adapter's mass (`[manipulator]
/// inertia_perp_kgm2`, `inertia_perp_std_kgm2`, `inertia_axial_kgm2`,
/// `[sensor] adapter_mass_kg`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RodInertia {
    /// I_perp, about an axis across the rod through C, kg m^2 (finite, >= 0).
    pub inertia_perp_kgm2: f64,
    /// The standard deviation of I_perp, kg m^2 (finite, >= 0).
    pub inertia_perp_std_kgm2: f64,
    /// I_axial, about the rod's axis, kg m^2 (finite, >= 0).
    pub inertia_axial_kgm2: f64,
    /// m_s, the mass between the sensor and the U-joint, kg (finite, >= 0).
    pub adapter_mass_kg: f64,
}

impl RodInertia {
    /// The standard deviation of the slender rod's stated default, as a
    /// fraction of it: 50 %, a guess, not a measurement.
    pub const SLENDER_ROD_STD_FRACTION: f64 = 0.5;
    /// The standard deviation of an I_perp given without one, as a fraction
    /// of it: 5 %.
    pub const GIVEN_STD_FRACTION: f64 = 0.05;

    /// No inertia at all: the static model of MODEL.md 4 even in motion
    /// (only the mass m in a_C remains).
    pub const NONE: Self = Self {
        inertia_perp_kgm2: 0.0,
        inertia_perp_std_kgm2: 0.0,
        inertia_axial_kgm2: 0.0,
        adapter_mass_kg: 0.0,
    };

    /// m L^2 / 12, the slender rod's I_perp, kg m^2.
    pub fn slender_rod_kgm2(profile: &Profile) -> f64 {
        profile.mass_kg() * profile.length_m() * profile.length_m() / 12.0
    }

    /// The stated default: the slender rod's I_perp with
    /// [`RodInertia::SLENDER_ROD_STD_FRACTION`], no axial inertia, no adapter.
    pub fn slender_rod(profile: &Profile) -> Self {
        let inertia_perp_kgm2 = Self::slender_rod_kgm2(profile);
        Self {
            inertia_perp_kgm2,
            inertia_perp_std_kgm2: inertia_perp_kgm2 * Self::SLENDER_ROD_STD_FRACTION,
            inertia_axial_kgm2: 0.0,
            adapter_mass_kg: 0.0,
        }
    }

    /// Every value finite and >= 0.
    pub fn check(&self) -> Result<(), SettingError> {
        finite_non_negative("inertia_perp_kgm2", self.inertia_perp_kgm2)?;
        finite_non_negative("inertia_perp_std_kgm2", self.inertia_perp_std_kgm2)?;
        finite_non_negative("inertia_axial_kgm2", self.inertia_axial_kgm2)?;
        finite_non_negative("adapter_mass_kg", self.adapter_mass_kg)
    }
}

/// What the motion changes in one estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Compensation {
    /// dF, added to the static F_tip, N.
    pub force_n: Vec3,
    /// What A'' and I_perp's uncertainties add to the per-axis variance, N^2.
    pub var_n2: Vec3,
    /// m_s A'': subtracted from -R_0s (f - b_f) to give the rod's F_A, N.
    pub adapter_n: Vec3,
    /// dM_T, added to the static torsion, N m.
    pub torsion_nm: f64,
    /// What A'''s uncertainty gives the torsion: its standard deviation, N m.
    pub torsion_std_nm: f64,
}

/// The rod's constants the compensation needs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Rod {
    pub mass_kg: f64,
    pub com_m: f64,
    pub length_m: f64,
    pub offset_m: f64,
    pub inertia: RodInertia,
}

/// The compensation at `pose` (valid: lever > 0, a > 0) for `motion`
/// (finite, `accel_std_mps2` >= 0).
pub(crate) fn compensation(rod: &Rod, pose: &Pose, motion: &CarriageMotion) -> Compensation {
    if rod.offset_m == 0.0 && rod.inertia.inertia_axial_kgm2 == 0.0 {
        slender(rod, pose, motion)
    } else {
        General::new(rod, pose, motion).compensation(rod, motion)
    }
}

/// d = 0 and I_axial = 0: MODEL.md 10's closed form (module doc).
fn slender(rod: &Rod, pose: &Pose, motion: &CarriageMotion) -> Compensation {
    let u = pose.rod_dir;
    let a = pose.support_distance_m;
    let inv_lever = 1.0 / (rod.length_m - a);
    let (m, c) = (rod.mass_kg, rod.com_m);
    let m_s = rod.inertia.adapter_mass_kg;
    let i_perp = rod.inertia.inertia_perp_kgm2;
    let accel = motion.accel_mps2;
    // u' and the velocity's part of u'' (r' = -A').
    let r1 = -motion.velocity_mps;
    let rho1 = u.dot(&r1);
    let u1 = (r1 - u * rho1) / a;
    let u2_vel = (u * -u1.dot(&r1) - u1 * (2.0 * rho1)) / a;
    let u2_vel_u = u.dot(&u2_vel);
    let u2_vel_perp = u2_vel - u * u2_vel_u;
    let total_mass = m + m_s;
    let kappa = (m_s * a + m * (a - c) * (a - c) / a + i_perp / a) * inv_lever;
    let accel_u = u.dot(&accel);
    let accel_perp = accel - u * accel_u;
    let force_n = u * (-total_mass * accel_u - m * c * u2_vel_u)
        + accel_perp * kappa
        + u2_vel_perp * ((m * c * (a - c) - i_perp) * inv_lever);
    // u''_perp = -A''_perp / a + u''_0,perp; dF/dI_perp = -u''_perp / lever.
    let d_inertia = (accel_perp / a - u2_vel_perp) * inv_lever;
    let sigma_a2 = motion.accel_std_mps2 * motion.accel_std_mps2;
    let sigma_i = rod.inertia.inertia_perp_std_kgm2;
    let spread = total_mass * total_mass - kappa * kappa;
    let var_n2 = Vec3::new(
        sigma_a2 * (kappa * kappa + spread * u.x * u.x),
        sigma_a2 * (kappa * kappa + spread * u.y * u.y),
        sigma_a2 * (kappa * kappa + spread * u.z * u.z),
    ) + (d_inertia * sigma_i).component_mul(&(d_inertia * sigma_i));
    Compensation {
        force_n,
        var_n2,
        adapter_n: accel * m_s,
        torsion_nm: 0.0,
        torsion_std_nm: 0.0,
    }
}

/// The rod's frame and the maps of the module doc, any d and I_axial.
struct General {
    u: Vec3,
    w: Vec3,
    v: Vec3,
    n: Vec3,
    r: Vec3,
    rho2: f64,
    /// r . n.
    r_n: f64,
    s: f64,
    inv_lever: f64,
    beta: f64,
    alpha: f64,
    delta: f64,
    /// (s - c) / lever.
    weight_arm: f64,
    /// u_y / w_y.
    uy_wy: f64,
    inv_wy: f64,
    omega: Vec3,
    /// The velocity's part of omega' (A'' = 0), rad/s^2.
    omega_dot_vel: Vec3,
}

impl General {
    fn new(rod: &Rod, pose: &Pose, motion: &CarriageMotion) -> Self {
        let (u, w) = (pose.rod_dir, pose.rod_normal);
        let v = u.cross(&w);
        let n = Vec3::y().cross(&v);
        let d = rod.offset_m;
        let s = pose.support_along_rod_m;
        let r = u * s + w * d;
        let rho2 = r.dot(&r);
        let r_n = r.dot(&n);
        let inv_lever = 1.0 / (rod.length_m - s);
        let inv_wy = 1.0 / w.y;
        let r1 = -motion.velocity_mps;
        let s1 = r.dot(&r1) / s;
        let r_x_r1 = r.cross(&r1);
        let lambda = -r_x_r1.dot(&n) / r_n;
        let omega = (r_x_r1 + v * (s1 * d) + r * lambda) / rho2;
        // P at A'' = 0.
        let s2_vel = (r1.dot(&r1) - s1 * s1) / s;
        let p_vel = -(u * s2_vel) - omega.cross(&u) * s1 - omega.cross(&r1);
        let r_x_p = r.cross(&p_vel);
        let mu = (rho2 * omega.y * omega.dot(&v) - r_x_p.dot(&n)) / r_n;
        let omega_dot_vel = (r_x_p + r * mu) / rho2;
        Self {
            u,
            w,
            v,
            n,
            r,
            rho2,
            r_n,
            s,
            inv_lever,
            beta: -s * inv_lever,
            alpha: d * inv_lever,
            delta: d * u.y * inv_wy * inv_lever,
            weight_arm: (s - rod.com_m) * inv_lever,
            uy_wy: u.y * inv_wy,
            inv_wy,
            omega,
            omega_dot_vel,
        }
    }

    /// omega' for A'' = `accel` without the velocity's part (linear).
    fn omega_dot_lin(&self, accel: &Vec3) -> Vec3 {
        let r2 = -accel;
        let p = r2 - self.u * (self.r.dot(&r2) / self.s);
        let r_x_p = self.r.cross(&p);
        (r_x_p - self.r * (r_x_p.dot(&self.n) / self.r_n)) / self.rho2
    }

    /// I_C x.
    fn inertia_c(&self, rod: &Rod, x: &Vec3) -> Vec3 {
        let along = self.u.dot(x);
        let i = &rod.inertia;
        (x - self.u * along) * i.inertia_perp_kgm2 + self.u * (along * i.inertia_axial_kgm2)
    }

    /// T_H h (module doc).
    fn couple_map(&self, h: &Vec3) -> Vec3 {
        (self.u.cross(h) + self.v * (self.uy_wy * self.u.dot(h))) * self.inv_lever
    }

    /// (dF, dM_T) for the rod turning at `omega_dot` with the translation
    /// `accel`; with `spin` the terms in omega (the velocity's part) too.
    fn loads(&self, rod: &Rod, omega_dot: &Vec3, accel: &Vec3, spin: bool) -> (Vec3, f64) {
        let (u, w) = (&self.u, &self.w);
        let mut u2 = omega_dot.cross(u);
        let mut w2 = omega_dot.cross(w);
        let mut h1 = self.inertia_c(rod, omega_dot);
        if spin {
            let om = &self.omega;
            u2 += om.cross(&om.cross(u));
            w2 += om.cross(&om.cross(w));
            h1 += om.cross(&self.inertia_c(rod, om));
        }
        let a_c = accel + u2 * rod.com_m + w2 * rod.offset_m;
        let m_s = rod.inertia.adapter_mass_kg;
        // -m_s J A''.
        let p = u * (1.0 - self.beta) + w * self.alpha;
        let j_accel =
            accel * self.beta + p * u.dot(accel) + self.v * (self.delta * self.v.dot(accel));
        // -m T_G(a_C).
        let a_c_u = u.dot(&a_c);
        let t_g = u * a_c_u - (a_c - u * a_c_u) * self.weight_arm;
        let force = -(j_accel * m_s) - t_g * rod.mass_kg + self.couple_map(&h1);
        let torsion = (u.dot(&h1) - rod.offset_m * m_s * self.v.dot(accel)) * self.inv_wy;
        (force, torsion)
    }

    fn compensation(&self, rod: &Rod, motion: &CarriageMotion) -> Compensation {
        let zero = Vec3::zeros();
        let (mut force_n, mut torsion_nm) = self.loads(rod, &self.omega_dot_vel, &zero, true);
        let mut sum_sq = Vec3::zeros();
        let mut torsion_sum_sq = 0.0;
        let mut omega_dot = self.omega_dot_vel;
        let accel = &motion.accel_mps2;
        for (e, a_j) in [Vec3::x(), Vec3::y(), Vec3::z()].iter().zip(accel.iter()) {
            let omega_dot_j = self.omega_dot_lin(e);
            let (col, col_torsion) = self.loads(rod, &omega_dot_j, e, false);
            force_n += col * *a_j;
            torsion_nm += col_torsion * *a_j;
            omega_dot += omega_dot_j * *a_j;
            sum_sq += col.component_mul(&col);
            torsion_sum_sq += col_torsion * col_torsion;
        }
        // dF/dI_perp = T_H(omega'_perp - (u . omega) omega x u).
        let om = &self.omega;
        let u = &self.u;
        let d_h = omega_dot - u * u.dot(&omega_dot) - om.cross(u) * u.dot(om);
        let d_inertia = self.couple_map(&d_h) * rod.inertia.inertia_perp_std_kgm2;
        let sigma_a2 = motion.accel_std_mps2 * motion.accel_std_mps2;
        Compensation {
            force_n,
            var_n2: sum_sq * sigma_a2 + d_inertia.component_mul(&d_inertia),
            adapter_n: accel * rod.inertia.adapter_mass_kg,
            torsion_nm,
            torsion_std_nm: motion.accel_std_mps2 * nalgebra::ComplexField::sqrt(torsion_sum_sq),
        }
    }
}

sar_snapshot::config_struct!(RodInertia {
    inertia_perp_kgm2,
    inertia_perp_std_kgm2,
    inertia_axial_kgm2,
    adapter_mass_kg,
});
