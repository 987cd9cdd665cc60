//! A general Denavit-Hartenberg chain, and the SAR's five joints written as one.
//!
//! This is an independent route to the tip: the tests check the closed forms of
//! [`crate::pose`] against it over thousands of random poses. Standard DH
//! convention: link i is `Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)`, with the joint
//! variable added to `theta` (revolute) or `d` (prismatic).

use crate::{Calibration, Profile, Vec3};
use libm::{cos, sin};
use nalgebra::Matrix4;

/// Homogeneous transform (4x4).
pub type Transform = Matrix4<f64>;

/// What a joint moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointKind {
    /// The joint variable (rad) adds to `theta_rad`.
    Revolute,
    /// The joint variable (m) adds to `d_m`.
    Prismatic,
}

/// One standard DH link.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DhLink {
    /// Which parameter the joint variable drives.
    pub kind: JointKind,
    /// Constant rotation about z_{i-1}, rad.
    pub theta_rad: f64,
    /// Constant translation along z_{i-1}, m.
    pub d_m: f64,
    /// Translation along x_i, m.
    pub a_m: f64,
    /// Rotation about x_i, rad.
    pub alpha_rad: f64,
}

impl DhLink {
    /// The link's transform for joint value `q`.
    pub fn transform(&self, q: f64) -> Transform {
        let (theta, d) = match self.kind {
            JointKind::Revolute => (self.theta_rad + q, self.d_m),
            JointKind::Prismatic => (self.theta_rad, self.d_m + q),
        };
        let (st, ct) = (sin(theta), cos(theta));
        let (sa, ca) = (sin(self.alpha_rad), cos(self.alpha_rad));
        Transform::new(
            ct,
            -st * ca,
            st * sa,
            self.a_m * ct, //
            st,
            ct * ca,
            -ct * sa,
            self.a_m * st, //
            0.0,
            sa,
            ca,
            d, //
            0.0,
            0.0,
            0.0,
            1.0,
        )
    }
}

/// A serial chain of `N` DH links between a base and a tool transform.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DhChain<const N: usize> {
    /// World -> DH frame 0.
    pub base: Transform,
    /// The links.
    pub links: [DhLink; N],
    /// DH frame N -> tool.
    pub tool: Transform,
}

impl<const N: usize> DhChain<N> {
    /// World transform of DH frame `k` (0 = base frame, N = last link), k <= N.
    pub fn frame(&self, q: &[f64; N], k: usize) -> Transform {
        let mut t = self.base;
        for (link, qi) in self.links.iter().zip(q.iter()).take(k) {
            t *= link.transform(*qi);
        }
        t
    }

    /// World transform of the tool.
    pub fn tool_frame(&self, q: &[f64; N]) -> Transform {
        self.frame(q, N) * self.tool
    }
}

/// Origin of a homogeneous transform.
pub fn origin(t: &Transform) -> Vec3 {
    Vec3::new(t[(0, 3)], t[(1, 3)], t[(2, 3)])
}

/// Column `i` (0..3) of the rotation part.
pub fn axis(t: &Transform, i: usize) -> Vec3 {
    let i = i.min(2);
    Vec3::new(t[(0, i)], t[(1, i)], t[(2, i)])
}

fn translation(v: Vec3) -> Transform {
    Transform::new(
        1.0, 0.0, 0.0, v.x, //
        0.0, 1.0, 0.0, v.y, //
        0.0, 0.0, 1.0, v.z, //
        0.0, 0.0, 0.0, 1.0,
    )
}

/// The SAR as a DH chain. Joint vector order: `[q3, q2, q1, q4, q5]`.
///
/// Frame 3's origin is A, frame 5 has x5 = u, y5 = -w, z5 = the q5 axis, and the
/// tool frame's origin is the tip D = A + d w + L u.
pub fn sar_chain(cal: &Calibration, profile: &Profile) -> DhChain<5> {
    use core::f64::consts::FRAC_PI_2 as HALF_PI;
    use core::f64::consts::PI;
    let a_home = cal.p_home_m() + cal.ujoint_offset_m();
    // DH frame 0: x0 = Y0, y0 = Z0, z0 = X0 (the q3 axis), origin at A for q = 0.
    // Columns: x0 = Y0, y0 = Z0, z0 = X0.
    let base = Transform::new(
        0.0, 0.0, 1.0, a_home.x, //
        1.0, 0.0, 0.0, a_home.y, //
        0.0, 1.0, 0.0, a_home.z, //
        0.0, 0.0, 0.0, 1.0,
    );
    let prismatic = |theta_rad| DhLink {
        kind: JointKind::Prismatic,
        theta_rad,
        d_m: 0.0,
        a_m: 0.0,
        alpha_rad: HALF_PI,
    };
    let links = [
        prismatic(HALF_PI), // q3 along X0; next axis Y0
        prismatic(HALF_PI), // q2 along Y0; next axis Z0
        prismatic(PI),      // q1 along Z0; next axis Y0
        DhLink {
            kind: JointKind::Revolute, // q4 about Y0; next axis (-c4, 0, s4)
            theta_rad: HALF_PI,
            d_m: 0.0,
            a_m: 0.0,
            alpha_rad: HALF_PI,
        },
        DhLink {
            kind: JointKind::Revolute, // q5: x5 = u
            theta_rad: 0.0,
            d_m: 0.0,
            a_m: profile.length_m(),
            alpha_rad: 0.0,
        },
    ];
    // D = A + L u + d w, and w = -y5.
    let tool = translation(Vec3::new(0.0, -profile.offset_m(), 0.0));
    DhChain { base, links, tool }
}
