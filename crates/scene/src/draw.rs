//! The 3D scene of the live view and of the recordings: a pure function of
//! one published state ([`StateMsg`]) and the robot's geometry
//! ([`SceneGeometry`]) to a `visualization_msgs/msg/MarkerArray`
//! ([`scene`]), everything in the frame `base` ({0}, MODEL.md 2), and the
//! frames as `tf2_msgs/msg/TFMessage` ([`static_transforms`]: `world` ->
//! `base`; [`moving_transforms`]: `base` -> `carriage`, `base` -> `tip`).
//!
//! Markers (namespace and id in [`ids`]; every scene carries every one of
//! them, and one with nothing to show is sent with action DELETE):
//! - the base frame: X0, Y0, Z0 as red, green, blue arrows at the origin,
//!   with their names;
//! - the carriage P = P_home + (q3, q2, q1) (a cube) and its bracket to A;
//! - the U-joint A (a sphere) and its offset d to the rod axis;
//! - the rod: a line of the configured length L and the rod's diameter from
//!   A's foot on the rod axis (A + d w) along u to the tip D, through B; the
//!   tip a sphere;
//! - the support B as a ring around the rod axis;
//! - F_tip as an arrow from the tip D, `force_scale_m_per_n` metres per
//!   newton (points: tail, head), coloured by the guard's state (ok green,
//!   warn amber, stop red, fault magenta), and its magnitude as text;
//! - the limits as translucent spheres at the tip: radius = the total warn
//!   and stop limits at the same scale (the arrow reaching a sphere is the
//!   force reaching that limit).
//!
//! The rod, the tip and the limits need the pose ([`flags::POSE`]); the
//! arrow needs an estimate ([`flags::ESTIMATE`]). Nothing here allocates.

use crate::geometry::SceneGeometry;
use core::fmt::Write as _;
use sar_msgs::msgs::FrameId;
use sar_msgs::viz::{
    Marker, MarkerArray, MarkerNs, MarkerText, Pose, TfMessage, TransformStamped, marker_action,
    marker_type,
};
use sar_msgs::wire::{StateMsg, flags, guard_code};

/// The frame id of the base frame {0} (as in the recordings).
pub const FRAME_BASE: &str = "base";
/// The frame id of the display frame, Z up (rviz's and Foxglove's
/// convention).
pub const FRAME_WORLD: &str = "world";
/// The carriage's frame (at P, axes of {0}).
pub const FRAME_CARRIAGE: &str = "carriage";
/// The tip's frame (at D, x along the rod axis u).
pub const FRAME_TIP: &str = "tip";

/// The markers' namespaces and ids.
pub mod ids {
    /// The base frame's axes (ids 0..=2: X0, Y0, Z0) and names (3..=5).
    pub const BASE_FRAME: &str = "base_frame";
    /// The carriage P (id 0) and its bracket to A (id 1).
    pub const CARRIAGE: &str = "carriage";
    /// The U-joint A (id 0) and its offset to the rod axis (id 1).
    pub const UJOINT: &str = "ujoint";
    /// The rod (id 0: a line from A's foot to the tip) and the tip (id 1).
    pub const ROD: &str = "rod";
    /// The support B (id 0: a closed line).
    pub const SUPPORT: &str = "support";
    /// The tip force (id 0: an arrow by its points, tail at the tip; id 1:
    /// its magnitude as text).
    pub const TIP_FORCE: &str = "tip_force";
    /// The force limits (id 0: warn, id 1: stop).
    pub const FORCE_LIMITS: &str = "force_limits";
    /// Every namespace, in the array's order, with its number of ids.
    pub const ALL: [(&str, i32); 7] = [
        (BASE_FRAME, 6),
        (CARRIAGE, 2),
        (UJOINT, 2),
        (ROD, 2),
        (SUPPORT, 1),
        (TIP_FORCE, 2),
        (FORCE_LIMITS, 2),
    ];
}

type V3 = [f64; 3];
type Rgba = [f32; 4];

fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
fn scale(a: V3, k: f64) -> V3 {
    [a[0] * k, a[1] * k, a[2] * k]
}
fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}
fn finite(a: V3) -> bool {
    a.iter().all(|x| x.is_finite())
}

/// The rotation taking `from` (unit) onto `to` (unit), as a quaternion
/// (x, y, z, w); a half turn about `across` (unit, perpendicular to `from`)
/// when they are opposite.
fn rotation_between(from: V3, to: V3, across: V3) -> [f64; 4] {
    let w = 1.0 + dot(from, to);
    if w < 1e-9 {
        return [across[0], across[1], across[2], 0.0];
    }
    let c = cross(from, to);
    let n = (w * w + dot(c, c)).sqrt();
    [c[0] / n, c[1] / n, c[2] / n, w / n]
}

/// Rotates `v` by the unit quaternion `q` (x, y, z, w).
pub fn rotate(q: &[f64; 4], v: V3) -> V3 {
    let u = [q[0], q[1], q[2]];
    let t = scale(cross(u, v), 2.0);
    add(add(v, scale(t, q[3])), cross(u, t))
}

/// The colour of a guard state (alpha 1).
pub fn guard_color(code: u32) -> Rgba {
    match code {
        guard_code::OK => [0.1, 0.75, 0.2, 1.0],
        guard_code::WARN => [1.0, 0.65, 0.0, 1.0],
        guard_code::STOP => [0.9, 0.1, 0.1, 1.0],
        _ => [0.8, 0.0, 0.8, 1.0],
    }
}

/// A unit vector perpendicular to `u` (unit).
fn perpendicular(u: V3) -> V3 {
    let other = if u[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let p = cross(u, other);
    scale(p, 1.0 / norm(p))
}

/// Points of the support ring (closed: the first again at the end).
pub const RING_POINTS: usize = 32;

/// u and w of MODEL.md 3 from q4, q5.
fn rod_frame(q45_rad: [f64; 2]) -> (V3, V3) {
    let (u, w) = sar_kinematics::rod_frame(q45_rad[0], q45_rad[1]);
    ([u.x, u.y, u.z], [w.x, w.y, w.z])
}

const GREY: Rgba = [0.6, 0.6, 0.65, 1.0];
const DARK: Rgba = [0.3, 0.3, 0.35, 1.0];
const ROD: Rgba = [0.85, 0.85, 0.9, 1.0];
const RING: Rgba = [0.95, 0.8, 0.2, 1.0];
const WARN_SPHERE: Rgba = [1.0, 0.65, 0.0, 0.08];
const STOP_SPHERE: Rgba = [0.9, 0.1, 0.1, 0.12];

/// What one scene is drawn from, worked out once.
struct Frame<'a> {
    s: &'a StateMsg,
    g: &'a SceneGeometry,
    has_pose: bool,
    has_force: bool,
    u: V3,
    w: V3,
}

impl<'a> Frame<'a> {
    fn new(s: &'a StateMsg, g: &'a SceneGeometry) -> Self {
        let has_pose = s.flags & flags::POSE != 0
            && finite(s.ujoint_m)
            && finite(s.tip_m)
            && s.q45_rad.iter().all(|x| x.is_finite());
        let has_force = has_pose && s.flags & flags::ESTIMATE != 0 && finite(s.tip_force_n);
        let (u, w) = rod_frame(s.q45_rad);
        Self {
            s,
            g,
            has_pose,
            has_force,
            u,
            w,
        }
    }

    /// A marker of `ns`/`id` to add, of `kind`.
    fn marker(&self, ns: &str, id: i32, kind: i32, color: Rgba) -> Marker {
        Marker {
            stamp_ns: self.s.now_ns,
            frame_id: FrameId::truncating(FRAME_BASE),
            ns: MarkerNs::truncating(ns),
            id,
            kind,
            action: marker_action::ADD,
            color,
            ..Marker::default()
        }
    }

    /// The marker of `ns`/`id` deleted (nothing to show).
    fn deleted(&self, ns: &str, id: i32) -> Marker {
        Marker {
            action: marker_action::DELETE,
            ..self.marker(ns, id, marker_type::SPHERE, [0.0; 4])
        }
    }

    /// A sphere of diameter `d` at `at`.
    fn sphere(&self, ns: &str, id: i32, at: V3, d: f64, color: Rgba) -> Marker {
        Marker {
            pose: Pose {
                position_m: at,
                ..Pose::default()
            },
            scale_m: [d; 3],
            ..self.marker(ns, id, marker_type::SPHERE, color)
        }
    }

    /// A line through `points`, `width` wide (`None`: a point did not fit).
    fn line(&self, ns: &str, id: i32, points: &[V3], width: f64, color: Rgba) -> Marker {
        let mut m = Marker {
            scale_m: [width, 0.0, 0.0],
            ..self.marker(ns, id, marker_type::LINE_STRIP, color)
        };
        for p in points {
            if m.points_m.push(*p).is_err() {
                return self.deleted(ns, id);
            }
        }
        m
    }

    /// An arrow from `from` to `to` (points form), shaft `diameter` wide.
    fn arrow(&self, ns: &str, id: i32, from: V3, to: V3, diameter: f64, color: Rgba) -> Marker {
        let mut m = Marker {
            scale_m: [
                diameter,
                2.5 * diameter,
                (0.25 * norm(add(to, scale(from, -1.0)))).min(4.0 * diameter),
            ],
            ..self.marker(ns, id, marker_type::ARROW, color)
        };
        // Two points: within MAX_POINTS.
        let _ = m.points_m.push(from);
        let _ = m.points_m.push(to);
        m
    }

    /// A text at `at`, `height` m tall.
    fn text(
        &self,
        ns: &str,
        id: i32,
        at: V3,
        height: f64,
        text: MarkerText,
        color: Rgba,
    ) -> Marker {
        Marker {
            pose: Pose {
                position_m: at,
                ..Pose::default()
            },
            scale_m: [0.0, 0.0, height],
            text,
            ..self.marker(ns, id, marker_type::TEXT_VIEW_FACING, color)
        }
    }
}

/// Appends `m`: the array holds every marker of [`ids::ALL`] (a test
/// checks), so it never fills.
fn put(out: &mut MarkerArray, m: Marker) {
    let _ = out.markers.push(m);
}

/// X0, Y0, Z0 and their names.
fn base_frame(f: &Frame<'_>, out: &mut MarkerArray) {
    let axes: [(V3, &str, Rgba); 3] = [
        ([1.0, 0.0, 0.0], "X0", [0.9, 0.1, 0.1, 1.0]),
        ([0.0, 1.0, 0.0], "Y0", [0.1, 0.8, 0.1, 1.0]),
        ([0.0, 0.0, 1.0], "Z0", [0.1, 0.3, 0.9, 1.0]),
    ];
    let length = f.g.axis_length_m;
    for (id, (dir, _, c)) in (0..).zip(axes) {
        put(
            out,
            f.arrow(ids::BASE_FRAME, id, [0.0; 3], scale(dir, length), 0.004, c),
        );
    }
    for (id, (dir, name, c)) in (3..).zip(axes) {
        let at = scale(dir, 1.15 * length);
        put(
            out,
            f.text(
                ids::BASE_FRAME,
                id,
                at,
                0.02,
                MarkerText::truncating(name),
                c,
            ),
        );
    }
}

/// The carriage P and its bracket to A.
fn carriage(f: &Frame<'_>, out: &mut MarkerArray) {
    let q = f.s.q_m;
    let p = add(f.g.p_home_m, [q[2], q[1], q[0]]);
    if !finite(p) {
        put(out, f.deleted(ids::CARRIAGE, 0));
        put(out, f.deleted(ids::CARRIAGE, 1));
        return;
    }
    let cube = Marker {
        pose: Pose {
            position_m: p,
            ..Pose::default()
        },
        scale_m: [0.04; 3],
        ..f.marker(ids::CARRIAGE, 0, marker_type::CUBE, GREY)
    };
    put(out, cube);
    let bracket = if f.has_pose {
        f.line(ids::CARRIAGE, 1, &[p, f.s.ujoint_m], 0.006, GREY)
    } else {
        f.deleted(ids::CARRIAGE, 1)
    };
    put(out, bracket);
}

/// A's foot on the rod axis, A + d w.
fn rod_foot(f: &Frame<'_>) -> V3 {
    add(f.s.ujoint_m, scale(f.w, f.g.offset_m))
}

/// The U-joint A, its offset, the rod and the tip.
fn ujoint_and_rod(f: &Frame<'_>, out: &mut MarkerArray) {
    if !f.has_pose {
        for (ns, id) in [
            (ids::UJOINT, 0),
            (ids::UJOINT, 1),
            (ids::ROD, 0),
            (ids::ROD, 1),
        ] {
            put(out, f.deleted(ns, id));
        }
        return;
    }
    let a = f.s.ujoint_m;
    let foot = rod_foot(f);
    put(out, f.sphere(ids::UJOINT, 0, a, 0.02, DARK));
    let offset = if f.g.offset_m != 0.0 {
        f.line(ids::UJOINT, 1, &[a, foot], 0.004, DARK)
    } else {
        f.deleted(ids::UJOINT, 1)
    };
    put(out, offset);
    let end = add(foot, scale(f.u, f.g.length_m));
    put(
        out,
        f.line(ids::ROD, 0, &[foot, end], f.g.rod_diameter_m, ROD),
    );
    let tip = guard_color(f.s.guard_state);
    put(
        out,
        f.sphere(ids::ROD, 1, f.s.tip_m, 1.6 * f.g.rod_diameter_m, tip),
    );
}

/// The support ring around the rod axis (or around X0 without a pose).
fn support(f: &Frame<'_>, out: &mut MarkerArray) {
    let axis = if f.has_pose { f.u } else { [1.0, 0.0, 0.0] };
    let e1 = perpendicular(axis);
    let e2 = cross(axis, e1);
    let mut points = [[0.0; 3]; RING_POINTS + 1];
    for (k, p) in points.iter_mut().enumerate() {
        let t = std::f64::consts::TAU * (k % RING_POINTS) as f64 / RING_POINTS as f64;
        let r = add(scale(e1, t.cos()), scale(e2, t.sin()));
        *p = add(f.g.support_m, scale(r, f.g.support_radius_m));
    }
    put(out, f.line(ids::SUPPORT, 0, &points, 0.004, RING));
}

/// F_tip from the tip, and its magnitude as text.
fn tip_force(f: &Frame<'_>, out: &mut MarkerArray) {
    let force = f.s.tip_force_n;
    let magnitude = norm(force);
    let length = magnitude * f.g.force_scale_m_per_n;
    if !f.has_force {
        put(out, f.deleted(ids::TIP_FORCE, 0));
        put(out, f.deleted(ids::TIP_FORCE, 1));
        return;
    }
    let c = guard_color(f.s.guard_state);
    let arrow = if length > 1e-6 {
        let head = add(f.s.tip_m, scale(force, f.g.force_scale_m_per_n));
        f.arrow(ids::TIP_FORCE, 0, f.s.tip_m, head, 0.005, c)
    } else {
        f.deleted(ids::TIP_FORCE, 0)
    };
    put(out, arrow);
    let observable = if f.s.flags & flags::OBSERVABLE != 0 {
        ""
    } else {
        " (not observable)"
    };
    let mut text = MarkerText::EMPTY;
    let state = sar_msgs::wire::guard_state_name(f.s.guard_state);
    // Cut at the capacity, never fails.
    let _ = write!(text, "|F| {magnitude:.2} N, {state}{observable}");
    let at = add(f.s.tip_m, [0.0, 0.03, 0.0]);
    put(out, f.text(ids::TIP_FORCE, 1, at, 0.02, text, c));
}

/// The total warn and stop limits as spheres at the tip.
fn force_limits(f: &Frame<'_>, out: &mut MarkerArray) {
    let spheres = [
        (f.s.limits_n[0], WARN_SPHERE),
        (f.s.limits_n[1], STOP_SPHERE),
    ];
    for (id, (limit_n, c)) in (0..).zip(spheres) {
        let d = 2.0 * limit_n * f.g.force_scale_m_per_n;
        let m = if f.has_pose && d.is_finite() && d > 0.0 {
            f.sphere(ids::FORCE_LIMITS, id, f.s.tip_m, d, c)
        } else {
            f.deleted(ids::FORCE_LIMITS, id)
        };
        put(out, m);
    }
}

/// The scene of one published state into `out` (cleared first).
pub fn scene(s: &StateMsg, g: &SceneGeometry, out: &mut MarkerArray) {
    out.markers.clear();
    let f = Frame::new(s, g);
    base_frame(&f, out);
    carriage(&f, out);
    ujoint_and_rod(&f, out);
    support(&f, out);
    tip_force(&f, out);
    force_limits(&f, out);
}

fn transform(
    stamp_ns: u64,
    parent: &str,
    child: &str,
    at: V3,
    rotation: [f64; 4],
) -> TransformStamped {
    TransformStamped {
        stamp_ns,
        frame_id: FrameId::truncating(parent),
        child_frame_id: FrameId::truncating(child),
        translation_m: at,
        rotation,
    }
}

/// `/tf_static`: `world` (Z up) -> `base` ({0}, Y up), a quarter turn
/// about X, so that Y0 shows up and Z0 towards the viewer.
pub fn static_transforms(stamp_ns: u64) -> TfMessage {
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let mut tf = TfMessage::default();
    // One transform: within MAX_TRANSFORMS.
    let _ = tf.transforms.push(transform(
        stamp_ns,
        FRAME_WORLD,
        FRAME_BASE,
        [0.0; 3],
        [h, 0.0, 0.0, h],
    ));
    tf
}

/// `/tf`: `base` -> `carriage` (at P, axes of {0}) and, with a pose, `base`
/// -> `tip` (at D, x along the rod axis u).
pub fn moving_transforms(s: &StateMsg, g: &SceneGeometry) -> TfMessage {
    let f = Frame::new(s, g);
    let mut tf = TfMessage::default();
    let p = add(g.p_home_m, [s.q_m[2], s.q_m[1], s.q_m[0]]);
    if finite(p) {
        let _ = tf.transforms.push(transform(
            s.now_ns,
            FRAME_BASE,
            FRAME_CARRIAGE,
            p,
            [0.0, 0.0, 0.0, 1.0],
        ));
    }
    if f.has_pose {
        let q = rotation_between([1.0, 0.0, 0.0], f.u, [0.0, 0.0, 1.0]);
        let _ = tf
            .transforms
            .push(transform(s.now_ns, FRAME_BASE, FRAME_TIP, s.tip_m, q));
    }
    tf
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]
    use super::*;

    #[test]
    fn every_scene_carries_every_marker_once_in_order() {
        let g = SceneGeometry {
            p_home_m: [0.1, 0.2, 0.3],
            support_m: [0.5, 0.0, 0.0],
            length_m: 0.4,
            offset_m: 0.01,
            force_scale_m_per_n: 0.01,
            rod_diameter_m: 0.008,
            support_radius_m: 0.012,
            axis_length_m: 0.1,
        };
        let expected: Vec<(String, i32)> = ids::ALL
            .iter()
            .flat_map(|(ns, n)| (0..*n).map(move |id| ((*ns).to_owned(), id)))
            .collect();
        assert!(expected.len() <= sar_msgs::viz::MAX_MARKERS);
        let mut out = MarkerArray::default();
        for s in [
            StateMsg::default(),
            StateMsg {
                flags: flags::POSE | flags::ESTIMATE,
                tip_force_n: [1.0, 2.0, 3.0],
                tip_m: [0.9, 0.0, 0.0],
                ..StateMsg::default()
            },
        ] {
            scene(&s, &g, &mut out);
            let got: Vec<(String, i32)> = out
                .markers
                .as_slice()
                .iter()
                .map(|m| (m.ns.as_str().to_owned(), m.id))
                .collect();
            assert_eq!(got, expected);
        }
        let arrow = &out.markers.as_slice()[13];
        assert_eq!(arrow.action, marker_action::ADD);
        let p = arrow.points_m.as_slice();
        let length = norm(add(p[1], scale(p[0], -1.0)));
        assert!((length - 14f64.sqrt() * 0.01).abs() < 1e-12, "{length}");
    }
}
