//! The simulator's own forward statics (MODEL.md 4, 4.3, 5): given the true pose,
//! the loads on the rod and the support's friction, what the robot applies to the
//! rod at A and what the sensor reads.
//!
//! This is the forward direction (loads -> F_A), solved as the six equilibrium
//! equations of the rod with a dense LU, whatever the offset d: it shares no code
//! with the estimator's inverse solutions, so that each checks the other.
//!
//! Unknowns: F_A (3), the support's reaction across u in the basis (w, u x w) (2),
//! and the U-joint torsion M_T along n = -(s4, 0, c4) (1). Equations: the force
//! balance (3) and the moments about A (3):
//!
//! ```text
//! F_A + F_B + m g + m_x g + F_D + F_fr = 0
//! (B - A) x (F_B + F_fr) + (C - A) x m g + (D - A) x (F_D + m_x g) + M_T n = 0
//! ```
//!
//! with F_D = -F_tip, m_x the mass hung at the tip and F_fr = -slide f u the
//! support's friction on the rod. In motion ([`equilibrium_in_motion`]) the
//! same six equations are Newton-Euler's, the inertial terms of
//! [`super::dynamics`] on the known side.

use super::dynamics::Inertial;
use nalgebra::{Matrix6, Vector6};
use sar_hal::Vec3;
use sar_kinematics::{Calibration, Pose, Profile};

/// The loads on the rod besides the support and the U-joint, in {0}.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Loads {
    /// F_tip: what the tip applies to the tissue (F_D = -F_tip), N.
    pub tip_force_n: Vec3,
    /// A known mass hung at the tip, kg.
    pub tip_mass_kg: f64,
    /// The support's friction on the rod, along u, N.
    pub friction_n: Vec3,
}

/// The solution of the equilibrium, in {0}.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Equilibrium {
    /// F_A: what the robot applies to the rod at A, N.
    pub ujoint_force_n: Vec3,
    /// The support's reaction across u, N (without the friction).
    pub support_reaction_n: Vec3,
    /// M_T: the U-joint's torsion on the rod along `torsion_axis`, N m.
    pub torsion_nm: f64,
    /// n = -(s4, 0, c4).
    pub torsion_axis: Vec3,
}

/// Solves the six equilibrium equations; `None` when the system is singular
/// or the result is not finite.
pub(crate) fn equilibrium(
    cal: &Calibration,
    profile: &Profile,
    pose: &Pose,
    loads: &Loads,
) -> Option<Equilibrium> {
    // The rod at rest: the equations in motion with nothing added (every
    // inertial term an exact zero, so the same numbers bit for bit).
    equilibrium_in_motion(cal, profile, pose, loads, &Inertial::NONE)
}

/// The Newton-Euler equations of the rod in motion (MODEL.md 10), as the
/// six equations of [`equilibrium`] with the inertial terms moved to the
/// known side (d'Alembert): the rod's `m a_C` and `H_C' + (C - A) x m a_C`,
/// and the inertia of the mass hung at the tip. `None` as [`equilibrium`].
pub(crate) fn equilibrium_in_motion(
    cal: &Calibration,
    profile: &Profile,
    pose: &Pose,
    loads: &Loads,
    inertial: &Inertial,
) -> Option<Equilibrium> {
    let g = cal.gravity_mps2();
    let r_b = cal.support_m() - pose.ujoint_m;
    let r_c = pose.com_m - pose.ujoint_m;
    let r_d = pose.tip_m - pose.ujoint_m;
    let rod_weight = g * profile.mass_kg();
    let tip_load = -loads.tip_force_n + (g - inertial.tip_accel_mps2) * loads.tip_mass_kg;
    let known_force = rod_weight + tip_load + loads.friction_n - inertial.force_n;
    let known_moment = r_c.cross(&rod_weight) + r_d.cross(&tip_load) + r_b.cross(&loads.friction_n)
        - inertial.moment_a_nm;
    solve(cal, pose, &known_force, &known_moment)
}

/// Solves for F_A, the support's reaction across u and M_T given the sum
/// of the known forces on the rod and of their moments about A.
fn solve(
    cal: &Calibration,
    pose: &Pose,
    known_force: &Vec3,
    known_moment: &Vec3,
) -> Option<Equilibrium> {
    let u = pose.rod_dir;
    let e1 = pose.rod_normal;
    let e2 = u.cross(&e1);
    let n = -Vec3::new(pose.q4_rad().sin(), 0.0, pose.q4_rad().cos());
    let r_b = cal.support_m() - pose.ujoint_m;
    let m1 = r_b.cross(&e1);
    let m2 = r_b.cross(&e2);
    let stack = |f: &Vec3, m: &Vec3| Vector6::new(f.x, f.y, f.z, m.x, m.y, m.z);
    let zero = Vec3::zeros();
    let k = Matrix6::from_columns(&[
        stack(&Vec3::x(), &zero),
        stack(&Vec3::y(), &zero),
        stack(&Vec3::z(), &zero),
        stack(&e1, &m1),
        stack(&e2, &m2),
        stack(&zero, &n),
    ]);
    let rhs = -stack(known_force, known_moment);
    let x = k.lu().solve(&rhs)?;
    if !x.iter().all(|v| v.is_finite()) {
        return None;
    }
    Some(Equilibrium {
        ujoint_force_n: Vec3::new(x.x, x.y, x.z),
        support_reaction_n: e1 * x.w + e2 * x.a,
        torsion_nm: x.b,
        torsion_axis: n,
    })
}

/// What an ideal sensor (no bias, no noise) reads for an equilibrium: the
/// wrench the tool side applies to it, in the sensor frame, about S:
/// `f = R_0s^T (-F_A)`, `t = R_0s^T ((A - S) x (-F_A) - M_T n)`.
pub(crate) fn ideal_wrench(cal: &Calibration, pose: &Pose, eq: &Equilibrium) -> (Vec3, Vec3) {
    let r_t = cal.sensor_rotation().transpose();
    let on_sensor = -eq.ujoint_force_n;
    let lever = pose.ujoint_m - pose.sensor_m;
    let torque = lever.cross(&on_sensor) - eq.torsion_axis * eq.torsion_nm;
    (r_t * on_sensor, r_t * torque)
}

/// [`ideal_wrench`] with the adapter's inertia: the adapter (lumped at A)
/// adds `adapter_force_n` (-m_s A'') to the force on the sensor, and its
/// moment about S.
pub(crate) fn ideal_wrench_in_motion(
    cal: &Calibration,
    pose: &Pose,
    eq: &Equilibrium,
    adapter_force_n: &Vec3,
) -> (Vec3, Vec3) {
    let r_t = cal.sensor_rotation().transpose();
    let on_sensor = -eq.ujoint_force_n + adapter_force_n;
    let lever = pose.ujoint_m - pose.sensor_m;
    let torque = lever.cross(&on_sensor) - eq.torsion_axis * eq.torsion_nm;
    (r_t * on_sensor, r_t * torque)
}
