//! Forward kinematics in closed form (MODEL.md 3): active joints and the fixed
//! support B give the passive joints q4, q5, the rod direction u and the named
//! points; and inverse kinematics from a wanted tip position to the active joints.
//!
//! Degenerate poses are typed errors: the U-joint at the support, the support
//! within the rod offset, a vertical rod, the tip at the support, a support the
//! rod does not reach.

use crate::shown::Shown;
use crate::{Calibration, MIN_DISTANCE_M, Profile, Vec3, check_finite};
use libm::{atan2, cos, sin, sqrt};

/// Why a pose has no (unique, finite) kinematic solution.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum PoseError {
    /// An input joint or position is NaN or infinite.
    #[error("{input} is not a finite number ({value})")]
    NonFinite {
        /// Which input.
        input: &'static str,
        /// The offending value (the first non-finite component).
        value: f64,
    },
    /// A (the U-joint centre) is at the support B.
    #[error("the U-joint centre is at the support ({} m away)", Shown(*.distance_m))]
    UJointAtSupport {
        /// |B - A|.
        distance_m: f64,
    },
    /// rho = |B - A| <= |d|: no rod line through B at offset d from A.
    #[error(
        "the support is {} m from the U-joint, within the rod offset {} m",
        Shown(*.distance_m),
        Shown(*.offset_m)
    )]
    SupportWithinOffset {
        /// |B - A|.
        distance_m: f64,
        /// d.
        offset_m: f64,
    },
    /// B is straight above or below A: q4 is undefined. From [`inverse`] with
    /// d != 0 also: the rod is so near vertical that A to B heads against it.
    #[error(
        "the rod is vertical (horizontal distance {} m): heading undefined",
        Shown(*.horizontal_m)
    )]
    VerticalRod {
        /// Horizontal distance from A to B along the rod's heading, m:
        /// sqrt(rx^2 + rz^2) from [`forward`]; s c5 + d s5 (negative on the
        /// other branch) from [`inverse`].
        horizontal_m: f64,
    },
    /// The tip is at the support: the statics are singular there.
    #[error("the tip is at the support ({} m away)", Shown(*.margin_m))]
    TipAtSupport {
        /// L - s, the distance from the support to the tip along the rod.
        margin_m: f64,
    },
    /// The support lies beyond the tip: the rod does not pass through it.
    #[error("the rod does not reach the support: tip {} m short of it", Shown(*.short_m))]
    SupportBeyondTip {
        /// s - L.
        short_m: f64,
    },
}

/// The three active (prismatic) joints, metres: q3 along X0, q2 along Y0, q1 along Z0.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ActiveJoints {
    /// Along Z0, m.
    pub q1_m: f64,
    /// Along Y0, m.
    pub q2_m: f64,
    /// Along X0, m.
    pub q3_m: f64,
}

impl ActiveJoints {
    /// The displacement (q3, q2, q1) in base X, Y, Z order.
    pub fn displacement_m(&self) -> Vec3 {
        Vec3::new(self.q3_m, self.q2_m, self.q1_m)
    }
}

/// Everything the closed-form kinematics gives for one pose. All in {0}.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// P, the carriage point, m.
    pub carriage_m: Vec3,
    /// S, the sensor frame's origin, m.
    pub sensor_m: Vec3,
    /// A, the U-joint centre, m.
    pub ujoint_m: Vec3,
    /// C, the manipulator's centre of mass, m.
    pub com_m: Vec3,
    /// D, the tip, m.
    pub tip_m: Vec3,
    /// u, unit, from A along the rod towards the tip.
    pub rod_dir: Vec3,
    /// w, unit, perpendicular to u in u's vertical plane (MODEL.md 3).
    pub rod_normal: Vec3,
    /// a = |B - A|, m.
    pub support_distance_m: f64,
    /// s = sqrt(a^2 - d^2): from the foot of A on the rod axis to B, along u, m.
    pub support_along_rod_m: f64,
    /// L - s: from the support to the tip along u, m (> 0).
    pub tip_beyond_support_m: f64,
}

impl Pose {
    /// q4, about Y0, rad, in (-pi, pi]. Computed on demand (an atan2) from u
    /// and w, whose cross product is (c4, 0, -s4): the per-cycle path that
    /// needs only u does not pay for the angles.
    pub fn q4_rad(&self) -> f64 {
        let (u, w) = (&self.rod_dir, &self.rod_normal);
        // (u x w).x = c4, -(u x w).z = s4.
        atan2(u.y * w.x - u.x * w.y, u.y * w.z - u.z * w.y)
    }

    /// q5, tilt out of the horizontal plane, rad, in (-pi, pi]: s5 = u.y,
    /// c5 = -w.y. Computed on demand.
    pub fn q5_rad(&self) -> f64 {
        atan2(self.rod_dir.y, -self.rod_normal.y)
    }
}

/// u and w from the passive joints (MODEL.md 3).
pub fn rod_frame(q4_rad: f64, q5_rad: f64) -> (Vec3, Vec3) {
    let (s4, c4) = (sin(q4_rad), cos(q4_rad));
    let (s5, c5) = (sin(q5_rad), cos(q5_rad));
    (
        Vec3::new(s4 * c5, s5, c4 * c5),
        Vec3::new(s4 * s5, -c5, c4 * s5),
    )
}

/// Below this ratio r_h / rho the rod counts as vertical.
const VERTICAL_RATIO: f64 = 1e-9;

/// The rod's u and w, and s (from A's foot to the support along u, m), from
/// r (the U-joint to the support), rho = |r|, its horizontal part r_h and
/// the offset d. q4 = atan2(rx, rz); q5 = alpha + beta with alpha =
/// atan2(ry, r_h) and beta = asin(d / rho) (MODEL.md 3). Their sines and
/// cosines follow from r without trigonometry; the angles themselves are
/// Pose::q4_rad/q5_rad.
#[inline]
fn rod_axes(r: &Vec3, rho: f64, r_h: f64, d: f64) -> (Vec3, Vec3, f64) {
    let (inv_rho, inv_r_h) = (1.0 / rho, 1.0 / r_h);
    let (s4, c4) = (r.x * inv_r_h, r.z * inv_r_h);
    let (s_alpha, c_alpha) = (r.y * inv_rho, r_h * inv_rho);
    let s = sqrt(rho * rho - d * d);
    let (s_beta, c_beta) = (d * inv_rho, s * inv_rho);
    let s5 = s_alpha * c_beta + c_alpha * s_beta;
    let c5 = c_alpha * c_beta - s_alpha * s_beta;
    let rod_dir = Vec3::new(s4 * c5, s5, c4 * c5);
    let rod_normal = Vec3::new(s4 * s5, -c5, c4 * s5);
    (rod_dir, rod_normal, s)
}

/// Closed-form forward kinematics: active joints -> passive joints, points, u.
#[inline]
pub fn forward(cal: &Calibration, profile: &Profile, q: &ActiveJoints) -> Result<Pose, PoseError> {
    // The plain test first, the offending value only when it fails: the loop
    // of check_finite alone, here, slowed the estimator's cycle by 10 ns.
    if !(q.q1_m.is_finite() && q.q2_m.is_finite() && q.q3_m.is_finite()) {
        check_finite(&[q.q1_m, q.q2_m, q.q3_m], |value| PoseError::NonFinite {
            input: "active joints",
            value,
        })?;
    }
    let carriage_m = cal.p_home_m() + q.displacement_m();
    let sensor_m = carriage_m + cal.sensor_offset_m();
    let ujoint_m = carriage_m + cal.ujoint_offset_m();
    let r = cal.support_m() - ujoint_m;
    let rho = r.norm();
    let d = profile.offset_m();
    if rho < MIN_DISTANCE_M {
        return Err(PoseError::UJointAtSupport { distance_m: rho });
    }
    if rho <= d.abs() + MIN_DISTANCE_M {
        return Err(PoseError::SupportWithinOffset {
            distance_m: rho,
            offset_m: d,
        });
    }
    let r_h = sqrt(r.x * r.x + r.z * r.z);
    if r_h <= VERTICAL_RATIO * rho {
        return Err(PoseError::VerticalRod { horizontal_m: r_h });
    }
    let (rod_dir, rod_normal, s) = rod_axes(&r, rho, r_h, d);
    let margin_m = profile.length_m() - s;
    if margin_m.abs() < MIN_DISTANCE_M {
        return Err(PoseError::TipAtSupport { margin_m });
    }
    if margin_m < 0.0 {
        return Err(PoseError::SupportBeyondTip { short_m: -margin_m });
    }
    // What the statics rely on: (u, w) orthonormal to round-off (they are
    // built from one (s4, c4) and one (s5, c5) pair, each unit), and the
    // support strictly between A's foot and the tip.
    debug_assert!(
        (rod_dir.norm_squared() - 1.0).abs() < 1e-9
            && (rod_normal.norm_squared() - 1.0).abs() < 1e-9
            && rod_dir.dot(&rod_normal).abs() < 1e-9,
        "u {rod_dir:?}, w {rod_normal:?} not orthonormal"
    );
    debug_assert!(
        s > 0.0 && margin_m >= MIN_DISTANCE_M,
        "s {s}, L - s {margin_m}"
    );
    let axis_m = ujoint_m + rod_normal * d;
    Ok(Pose {
        carriage_m,
        sensor_m,
        ujoint_m,
        com_m: axis_m + rod_dir * profile.com_m(),
        tip_m: axis_m + rod_dir * profile.length_m(),
        rod_dir,
        rod_normal,
        support_distance_m: rho,
        support_along_rod_m: s,
        tip_beyond_support_m: margin_m,
    })
}

/// Inverse kinematics: the active joints that put the tip at `tip_m` ({0}, m),
/// with the rod through the calibrated support B. Valid for any offset d; with
/// d != 0, a rod so near vertical that [`forward`] would give the other branch
/// is refused as [`PoseError::VerticalRod`].
pub fn inverse(
    cal: &Calibration,
    profile: &Profile,
    tip_m: &Vec3,
) -> Result<ActiveJoints, PoseError> {
    check_finite(tip_m, |value| PoseError::NonFinite {
        input: "tip position",
        value,
    })?;
    let to_tip = tip_m - cal.support_m();
    let beyond_m = to_tip.norm();
    if beyond_m < MIN_DISTANCE_M {
        return Err(PoseError::TipAtSupport { margin_m: beyond_m });
    }
    let length_m = profile.length_m();
    // s = L - |D - B| is where B sits along the rod; it must leave A behind B.
    let s = length_m - beyond_m;
    let d = profile.offset_m();
    if s < MIN_DISTANCE_M
        || s * s + d * d <= (d.abs() + MIN_DISTANCE_M) * (d.abs() + MIN_DISTANCE_M)
    {
        return Err(PoseError::SupportBeyondTip {
            short_m: beyond_m - length_m,
        });
    }
    let u = to_tip / beyond_m;
    let c5 = sqrt(u.x * u.x + u.z * u.z);
    // B - A = s u + d w has the horizontal part (s c5 + d s5) (s4, 0, c4). The
    // forward kinematics take the heading from it, so it must point along the
    // rod's heading: otherwise (rods within asin(|d| / rho) of vertical) the
    // joints below would put the rod on the other branch (MODEL.md 3), with the
    // tip far from `tip_m`.
    let horizontal_m = s * c5 + d * u.y;
    let rho = sqrt(s * s + d * d);
    if c5 <= VERTICAL_RATIO || horizontal_m <= VERTICAL_RATIO * rho {
        return Err(PoseError::VerticalRod { horizontal_m });
    }
    // w = (s4 s5, -c5, c4 s5) with s4 = ux / c5, c4 = uz / c5, s5 = uy.
    let w = Vec3::new(u.x * u.y / c5, -c5, u.z * u.y / c5);
    let ujoint_m = tip_m - u * length_m - w * d;
    let q = ujoint_m - cal.ujoint_offset_m() - cal.p_home_m();
    Ok(ActiveJoints {
        q1_m: q.z,
        q2_m: q.y,
        q3_m: q.x,
    })
}

sar_snapshot::snap_struct!(ActiveJoints { q1_m, q2_m, q3_m });
