//! The rod in motion (MODEL.md 10): what the rod's inertia adds to the
//! equilibrium of [`super::statics`], for any offset d.
//!
//! The carriage only translates, so A' and A'' are the axes' velocity and
//! acceleration. The passive joints follow from r = B - A in closed form
//! (MODEL.md 3: q4 = atan2(rx, rz), q5 = atan2(ry, r_h) + asin(d / rho));
//! their first and second time derivatives come from the same closed form
//! carried through second-order jets (value, d/dt, d2/dt2), exact to
//! round-off, with no finite difference. The rod turns with the U-joint's
//! second member: omega = q4' Y0 + q5' a5, a5 = (-c4, 0, s4) the q5 axis
//! (a5 x u = du/dq5), and every vector of the rod's frame (u, w) moves as
//! v' = omega x v. Then, with I_C = I_perp (E - u u^T) + I_axial u u^T:
//!
//! ```text
//! a_C  = A'' + d w'' + c u''
//! H_C' = I_C omega' + omega x (I_C omega)
//! sum of forces on the rod       = m a_C
//! sum of moments about A on it   = H_C' + (C - A) x m a_C
//! ```
//!
//! (the moment equation about the moving point A, A being fixed in the rod).
//! [`super::statics::equilibrium_in_motion`] moves these to the known side
//! (d'Alembert), so the same six unknowns are solved; with q' = q'' = 0 every
//! inertial term is an exact zero and the solution is the statics'.

use super::spec::RodInertia;
use sar_hal::Vec3;
use sar_kinematics::{Calibration, Pose, Profile};

/// A quantity with its first and second time derivatives.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Jet {
    v: f64,
    d1: f64,
    d2: f64,
}

impl Jet {
    const fn new(v: f64, d1: f64, d2: f64) -> Self {
        Self { v, d1, d2 }
    }

    fn add(self, o: Self) -> Self {
        Self::new(self.v + o.v, self.d1 + o.d1, self.d2 + o.d2)
    }

    fn mul(self, o: Self) -> Self {
        Self::new(
            self.v * o.v,
            self.d1 * o.v + self.v * o.d1,
            self.d2 * o.v + 2.0 * self.d1 * o.d1 + self.v * o.d2,
        )
    }

    /// f(self) for f with f(v) = `f0`, f'(v) = `f1`, f''(v) = `f2`.
    fn chain(self, f0: f64, f1: f64, f2: f64) -> Self {
        Self::new(f0, f1 * self.d1, f2 * self.d1 * self.d1 + f1 * self.d2)
    }

    fn sqrt(self) -> Self {
        let r = self.v.sqrt();
        self.chain(r, 0.5 / r, -0.25 / (r * self.v))
    }

    fn recip(self) -> Self {
        let r = 1.0 / self.v;
        self.chain(r, -r * r, 2.0 * r * r * r)
    }

    fn asin(self) -> Self {
        let k = 1.0 - self.v * self.v;
        let s = k.sqrt();
        self.chain(self.v.asin(), 1.0 / s, self.v / (k * s))
    }

    /// atan2(y, x): theta' = (x y' - y x') / (x^2 + y^2), and its derivative.
    fn atan2(y: Self, x: Self) -> Self {
        let den = x.v * x.v + y.v * y.v;
        let num = x.v * y.d1 - y.v * x.d1;
        let num_d = x.v * y.d2 - y.v * x.d2;
        let den_d = 2.0 * (x.v * x.d1 + y.v * y.d1);
        Self::new(
            y.v.atan2(x.v),
            num / den,
            (num_d * den - num * den_d) / (den * den),
        )
    }
}

/// What the rod's motion adds, in {0}.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Inertial {
    /// m a_C, N.
    pub force_n: Vec3,
    /// H_C' + (C - A) x m a_C: the moment about A that the motion needs, N m.
    pub moment_a_nm: Vec3,
    /// a_D, the tip's acceleration (for a mass hung at the tip), m/s^2.
    pub tip_accel_mps2: Vec3,
    /// -m_s A'': what the adapter's inertia adds to the force on the sensor, N.
    pub adapter_force_n: Vec3,
}

impl Inertial {
    /// At rest: nothing added (the statics, bit for bit).
    pub const NONE: Self = Self {
        force_n: Vec3::new(0.0, 0.0, 0.0),
        moment_a_nm: Vec3::new(0.0, 0.0, 0.0),
        tip_accel_mps2: Vec3::new(0.0, 0.0, 0.0),
        adapter_force_n: Vec3::new(0.0, 0.0, 0.0),
    };
}

/// The rod's angular velocity and acceleration and the rates of u and w.
struct Turning {
    omega: Vec3,
    omega_dot: Vec3,
}

/// omega and omega' from the passive joints' jets (MODEL.md 3 and 10).
fn turning(r: [Jet; 3], d_m: f64) -> Turning {
    let [rx, ry, rz] = r;
    let q4 = Jet::atan2(rx, rz);
    let r_h = rx.mul(rx).add(rz.mul(rz)).sqrt();
    let rho = r_h.mul(r_h).add(ry.mul(ry)).sqrt();
    let alpha = Jet::atan2(ry, r_h);
    let q5 = if d_m == 0.0 {
        alpha
    } else {
        alpha.add(rho.recip().mul(Jet::new(d_m, 0.0, 0.0)).asin())
    };
    let (s4, c4) = q4.v.sin_cos();
    let y0 = Vec3::y();
    let a5 = Vec3::new(-c4, 0.0, s4);
    // da5/dq4 = (s4, 0, c4).
    let a5_dq4 = Vec3::new(s4, 0.0, c4);
    Turning {
        omega: y0 * q4.d1 + a5 * q5.d1,
        omega_dot: y0 * q4.d2 + a5 * q5.d2 + a5_dq4 * (q5.d1 * q4.d1),
    }
}

/// The inertial terms at `pose` for the carriage's velocity `a_dot_mps`
/// (A') and acceleration `a_ddot_mps2` (A''), {0}.
pub(crate) fn inertial(
    cal: &Calibration,
    profile: &Profile,
    pose: &Pose,
    a_dot_mps: &Vec3,
    a_ddot_mps2: &Vec3,
    inertia: &RodInertia,
) -> Inertial {
    let r = cal.support_m() - pose.ujoint_m;
    let jet = |x: f64, v: f64, a: f64| Jet::new(x, -v, -a);
    let t = turning(
        [
            jet(r.x, a_dot_mps.x, a_ddot_mps2.x),
            jet(r.y, a_dot_mps.y, a_ddot_mps2.y),
            jet(r.z, a_dot_mps.z, a_ddot_mps2.z),
        ],
        profile.offset_m(),
    );
    let (u, w) = (pose.rod_dir, pose.rod_normal);
    let second = |v: &Vec3| t.omega_dot.cross(v) + t.omega.cross(&t.omega.cross(v));
    let (u_dd, w_dd) = (second(&u), second(&w));
    let (d, c, l) = (profile.offset_m(), profile.com_m(), profile.length_m());
    let com_accel = a_ddot_mps2 + w_dd * d + u_dd * c;
    let tip_accel = a_ddot_mps2 + w_dd * d + u_dd * l;
    let inertia_c = |v: &Vec3| {
        let along = u.dot(v);
        (v - u * along) * inertia.inertia_perp_kgm2 + u * (along * inertia.inertia_axial_kgm2)
    };
    let h_dot = inertia_c(&t.omega_dot) + t.omega.cross(&inertia_c(&t.omega));
    let m_a_c = com_accel * profile.mass_kg();
    Inertial {
        force_n: m_a_c,
        moment_a_nm: h_dot + (pose.com_m - pose.ujoint_m).cross(&m_a_c),
        tip_accel_mps2: tip_accel,
        adapter_force_n: -a_ddot_mps2 * inertia.adapter_mass_kg,
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// The jets against the closed forms' own derivatives along a
    /// polynomial path, by central differences of the values.
    #[test]
    fn jets_agree_with_differences_of_their_values() {
        let path = |t: f64| {
            let x = Jet::new(0.2 + 0.1 * t + 0.3 * t * t, 0.1 + 0.6 * t, 0.6);
            let y = Jet::new(0.05 - 0.2 * t + 0.1 * t * t, -0.2 + 0.2 * t, 0.2);
            let z = Jet::new(0.1 + 0.05 * t - 0.4 * t * t, 0.05 - 0.8 * t, -0.8);
            let r_h = x.mul(x).add(z.mul(z)).sqrt();
            let rho = r_h.mul(r_h).add(y.mul(y)).sqrt();
            Jet::atan2(y, r_h).add(rho.recip().mul(Jet::new(0.01, 0.0, 0.0)).asin())
        };
        let h = 1e-4;
        for k in 0..5 {
            let t = 0.1 * f64::from(k);
            let (a, b, c) = (path(t - h).v, path(t).v, path(t + h).v);
            let j = path(t);
            assert!((j.d1 - (c - a) / (2.0 * h)).abs() < 1e-7, "{j:?}");
            assert!((j.d2 - (c - 2.0 * b + a) / (h * h)).abs() < 1e-5, "{j:?}");
        }
    }
}
