//! The 3D scene of the live view and of the recordings: a pure function of
//! one published state ([`StateMsg`]) and the robot's geometry
//! ([`SceneGeometry`]) to a ROS 2 `visualization_msgs/MarkerArray` in the
//! frame `base` ({0}, MODEL.md 2), and the frames as `tf2_msgs/TFMessage`
//! ([`static_frames`] for `/tf_static`, [`moving_frames`] for `/tf`).
//!
//! Markers (namespace = the part, [`ids`]; every array holds every marker,
//! each either added or, with nothing to show, deleted, so a viewer never
//! keeps a stale part):
//! - the base frame: X0, Y0, Z0 as red, green, blue arrows and their labels;
//! - the carriage P = P_home + (q3, q2, q1) (a cube) and its bracket to A;
//! - the U-joint A (a sphere), and its arm to the rod axis when d != 0;
//! - the rod: a cylinder of the configured length L from A's foot on the rod
//!   axis (A + d w) along u (from the published q4, q5) to the tip, through
//!   B; the tip D as a sphere coloured by the guard's state;
//! - the support B as a ring around the rod axis;
//! - F_tip as an arrow from the tip D, `force_scale_m_per_n` metres per
//!   newton, coloured by the guard's state (ok green, warn amber, stop red,
//!   fault magenta), and its label;
//! - the total warn and stop limits as translucent spheres at the tip, radius
//!   = the limit at the same scale (the arrow reaching a sphere is the force
//!   reaching that limit).
//!
//! The rod, the tip and the limits need the pose ([`flags::POSE`]); the arrow
//! needs an estimate ([`flags::ESTIMATE`]).

use crate::geometry::SceneGeometry;
use sar_msgs::scene::{IDENTITY, Marker, MarkerArray, TfMessage, TransformStamped, action, kind};
use sar_msgs::wire::{StateMsg, flags, guard_code};

/// The frame id of the base frame {0} (as in the recordings).
pub const FRAME_BASE: &str = "base";
/// The frame id of the display frame, Z up (ROS's and Foxglove's convention).
pub const FRAME_WORLD: &str = "world";
/// The carriage P (translated from `base`).
pub const FRAME_CARRIAGE: &str = "carriage";
/// The rod: origin at A's foot on the rod axis, x along u (towards the tip).
pub const FRAME_ROD: &str = "rod";
/// The tip D: the rod frame moved L along its x.
pub const FRAME_TIP: &str = "tip";

/// The markers' namespaces (one per part; ids count within).
pub mod ids {
    /// The base frame's axes (ids 0-2) and labels (3-5).
    pub const BASE_FRAME: &str = "base_frame";
    /// The carriage P (id 0) and its bracket to A (1).
    pub const CARRIAGE: &str = "carriage";
    /// The U-joint A (id 0) and its arm to the rod axis (1).
    pub const UJOINT: &str = "ujoint";
    /// The rod (id 0) and the tip (1).
    pub const ROD: &str = "rod";
    /// The support B's ring (id 0).
    pub const SUPPORT: &str = "support";
    /// The tip force's arrow (id 0) and label (1).
    pub const TIP_FORCE: &str = "tip_force";
    /// The warn (id 0) and stop (1) limits.
    pub const FORCE_LIMITS: &str = "force_limits";
    /// Every namespace, in the array's order.
    pub const ALL: [&str; 7] = [
        BASE_FRAME,
        CARRIAGE,
        UJOINT,
        ROD,
        SUPPORT,
        TIP_FORCE,
        FORCE_LIMITS,
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
pub fn rotate(q: [f64; 4], v: V3) -> V3 {
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

/// Points of the support ring (closed: the first again at the end).
const RING_POINTS: usize = 32;
/// The grey of the machine's parts.
const STEEL: Rgba = [0.6, 0.6, 0.65, 1.0];

/// u and w of MODEL.md 3 from q4, q5.
fn rod_frame(q45_rad: [f64; 2]) -> (V3, V3) {
    let (u, w) = sar_kinematics::rod_frame(q45_rad[0], q45_rad[1]);
    ([u.x, u.y, u.z], [w.x, w.y, w.z])
}

/// What one state shows: the pose and the estimate, when valid.
struct Seen {
    stamp_ns: u64,
    has_pose: bool,
    has_force: bool,
    u: V3,
    w: V3,
    guard: Rgba,
}

impl Seen {
    fn of(s: &StateMsg) -> Self {
        let has_pose = s.flags & flags::POSE != 0
            && finite(s.ujoint_m)
            && finite(s.tip_m)
            && s.q45_rad.iter().all(|x| x.is_finite());
        let has_force = has_pose && s.flags & flags::ESTIMATE != 0 && finite(s.tip_force_n);
        let (u, w) = rod_frame(s.q45_rad);
        Self {
            stamp_ns: s.now_ns,
            has_pose,
            has_force,
            u,
            w,
            guard: guard_color(s.guard_state),
        }
    }

    /// A marker of `ns`/`id` in `base`, added (shape, pose, scale, colour
    /// given by the caller) or deleted.
    fn marker(&self, ns: &str, id: i32, kind: i32, shown: bool) -> Marker {
        Marker {
            stamp_ns: self.stamp_ns,
            frame_id: FRAME_BASE.to_owned(),
            ns: ns.to_owned(),
            id,
            kind,
            action: if shown { action::ADD } else { action::DELETE },
            orientation: IDENTITY,
            ..Marker::default()
        }
    }
}

/// An arrow marker from `from` to `to`, `diameter_m` thick.
fn arrow(mut m: Marker, from: V3, to: V3, diameter_m: f64, color: Rgba) -> Marker {
    let head_m =
        (0.25 * norm([to[0] - from[0], to[1] - from[1], to[2] - from[2]])).min(4.0 * diameter_m);
    m.points_m = vec![from, to];
    m.scale_m = [diameter_m, 2.5 * diameter_m, head_m];
    m.color = color;
    m
}

/// A text marker at `at`, `height_m` high.
fn label(mut m: Marker, at: V3, height_m: f64, color: Rgba, text: String) -> Marker {
    m.position_m = at;
    m.scale_m = [0.0, 0.0, height_m];
    m.color = color;
    m.text = text;
    m
}

/// A shape of `size_m` at `at` (a sphere, a cube).
fn solid(mut m: Marker, at: V3, size_m: V3, color: Rgba) -> Marker {
    m.position_m = at;
    m.scale_m = size_m;
    m.color = color;
    m
}

/// A polyline through `points`, `width_m` wide.
fn line(mut m: Marker, points: Vec<V3>, width_m: f64, color: Rgba) -> Marker {
    m.points_m = points;
    m.scale_m = [width_m, 0.0, 0.0];
    m.color = color;
    m
}

/// The base frame's axes and their labels.
fn base_frame(v: &Seen, g: &SceneGeometry, out: &mut Vec<Marker>) {
    let axes: [(V3, &str, Rgba); 3] = [
        ([1.0, 0.0, 0.0], "X0", [0.9, 0.1, 0.1, 1.0]),
        ([0.0, 1.0, 0.0], "Y0", [0.1, 0.8, 0.1, 1.0]),
        ([0.0, 0.0, 1.0], "Z0", [0.1, 0.3, 0.9, 1.0]),
    ];
    for (id, (dir, _, color)) in (0..).zip(axes) {
        let m = v.marker(ids::BASE_FRAME, id, kind::ARROW, true);
        out.push(arrow(
            m,
            [0.0; 3],
            scale(dir, g.axis_length_m),
            0.004,
            color,
        ));
    }
    for (id, (dir, name, color)) in (3..).zip(axes) {
        let m = v.marker(ids::BASE_FRAME, id, kind::TEXT_VIEW_FACING, true);
        let at = scale(dir, 1.15 * g.axis_length_m);
        out.push(label(m, at, 0.02, color, name.to_owned()));
    }
}

/// The carriage P and its bracket to A.
fn carriage(v: &Seen, s: &StateMsg, g: &SceneGeometry, out: &mut Vec<Marker>) {
    let p = carriage_m(s, g);
    let shown = finite(p);
    let cube = v.marker(ids::CARRIAGE, 0, kind::CUBE, shown);
    out.push(if shown {
        solid(cube, p, [0.04; 3], STEEL)
    } else {
        cube
    });
    let bracket = v.marker(ids::CARRIAGE, 1, kind::LINE_STRIP, shown && v.has_pose);
    out.push(if shown && v.has_pose {
        line(bracket, vec![p, s.ujoint_m], 0.006, STEEL)
    } else {
        bracket
    });
}

/// P = P_home + (q3, q2, q1), m.
fn carriage_m(s: &StateMsg, g: &SceneGeometry) -> V3 {
    add(g.p_home_m, [s.q_m[2], s.q_m[1], s.q_m[0]])
}

/// A's foot on the rod axis, A + d w, m.
fn foot_m(v: &Seen, s: &StateMsg, g: &SceneGeometry) -> V3 {
    add(s.ujoint_m, scale(v.w, g.offset_m))
}

/// The U-joint A and its arm to the rod axis (d != 0).
fn ujoint(v: &Seen, s: &StateMsg, g: &SceneGeometry, out: &mut Vec<Marker>) {
    let joint = [0.3, 0.3, 0.35, 1.0];
    let sphere = v.marker(ids::UJOINT, 0, kind::SPHERE, v.has_pose);
    out.push(if v.has_pose {
        solid(sphere, s.ujoint_m, [0.02; 3], joint)
    } else {
        sphere
    });
    let has_arm = v.has_pose && g.offset_m != 0.0;
    let arm = v.marker(ids::UJOINT, 1, kind::LINE_STRIP, has_arm);
    out.push(if has_arm {
        line(arm, vec![s.ujoint_m, foot_m(v, s, g)], 0.004, joint)
    } else {
        arm
    });
}

/// The rod from A's foot along u, L long, and the tip.
fn rod(v: &Seen, s: &StateMsg, g: &SceneGeometry, out: &mut Vec<Marker>) {
    let centre = add(foot_m(v, s, g), scale(v.u, 0.5 * g.length_m));
    let mut cylinder = v.marker(ids::ROD, 0, kind::CYLINDER, v.has_pose);
    if v.has_pose {
        cylinder = solid(
            cylinder,
            centre,
            [g.rod_diameter_m, g.rod_diameter_m, g.length_m],
            [0.85, 0.85, 0.9, 1.0],
        );
        cylinder.orientation = rotation_between([0.0, 0.0, 1.0], v.u, [1.0, 0.0, 0.0]);
    }
    out.push(cylinder);
    let tip = v.marker(ids::ROD, 1, kind::SPHERE, v.has_pose);
    out.push(if v.has_pose {
        solid(tip, s.tip_m, [1.6 * g.rod_diameter_m; 3], v.guard)
    } else {
        tip
    });
}

/// The support's ring around the rod axis (around X0 without a pose).
fn support(v: &Seen, g: &SceneGeometry, out: &mut Vec<Marker>) {
    let axis = if v.has_pose { v.u } else { [1.0, 0.0, 0.0] };
    let e1 = perpendicular(axis);
    let e2 = cross(axis, e1);
    let points = (0..=RING_POINTS)
        .map(|k| {
            let t = std::f64::consts::TAU * k as f64 / RING_POINTS as f64;
            let r = add(scale(e1, t.cos()), scale(e2, t.sin()));
            add(g.support_m, scale(r, g.support_radius_m))
        })
        .collect();
    let ring = v.marker(ids::SUPPORT, 0, kind::LINE_STRIP, true);
    out.push(line(ring, points, 0.004, [0.95, 0.8, 0.2, 1.0]));
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

/// F_tip as an arrow from the tip, and its label.
fn tip_force(v: &Seen, s: &StateMsg, g: &SceneGeometry, out: &mut Vec<Marker>) {
    let magnitude_n = norm(s.tip_force_n);
    let length_m = magnitude_n * g.force_scale_m_per_n;
    let has_arrow = v.has_force && length_m > 1e-6;
    let m = v.marker(ids::TIP_FORCE, 0, kind::ARROW, has_arrow);
    out.push(if has_arrow {
        let to = add(s.tip_m, scale(s.tip_force_n, g.force_scale_m_per_n));
        arrow(m, s.tip_m, to, 0.005, v.guard)
    } else {
        m
    });
    let m = v.marker(ids::TIP_FORCE, 1, kind::TEXT_VIEW_FACING, v.has_force);
    out.push(if v.has_force {
        let observable = if s.flags & flags::OBSERVABLE != 0 {
            ""
        } else {
            " (not observable)"
        };
        let text = format!(
            "|F| {magnitude_n:.2} N, {}{observable}",
            sar_msgs::wire::guard_state_name(s.guard_state)
        );
        label(m, add(s.tip_m, [0.0, 0.03, 0.0]), 0.02, v.guard, text)
    } else {
        m
    });
}

/// The total warn and stop limits as spheres at the tip.
fn limits(v: &Seen, s: &StateMsg, g: &SceneGeometry, out: &mut Vec<Marker>) {
    let spheres: [(f64, Rgba); 2] = [
        (s.limits_n[0], [1.0, 0.65, 0.0, 0.08]),
        (s.limits_n[1], [0.9, 0.1, 0.1, 0.12]),
    ];
    for (id, (limit_n, color)) in (0..).zip(spheres) {
        let diameter_m = 2.0 * limit_n * g.force_scale_m_per_n;
        let shown = v.has_pose && diameter_m.is_finite() && diameter_m > 0.0;
        let m = v.marker(ids::FORCE_LIMITS, id, kind::SPHERE, shown);
        out.push(if shown {
            solid(m, s.tip_m, [diameter_m; 3], color)
        } else {
            m
        });
    }
}

/// The scene of one published state: every marker, in [`ids::ALL`]'s order.
pub fn scene(s: &StateMsg, g: &SceneGeometry) -> MarkerArray {
    let v = Seen::of(s);
    let mut markers = Vec::with_capacity(MARKERS);
    base_frame(&v, g, &mut markers);
    carriage(&v, s, g, &mut markers);
    ujoint(&v, s, g, &mut markers);
    rod(&v, s, g, &mut markers);
    support(&v, g, &mut markers);
    tip_force(&v, s, g, &mut markers);
    limits(&v, s, g, &mut markers);
    MarkerArray { markers }
}

/// How many markers every scene holds.
pub const MARKERS: usize = 6 + 2 + 2 + 2 + 1 + 2 + 2;

/// The transform `world` (Z up) -> `base` ({0}, Y up): a quarter turn about
/// X, so that Y0 shows up and Z0 towards the viewer. `/tf_static`, stamped
/// `stamp_ns`.
pub fn static_frames(stamp_ns: u64) -> TfMessage {
    let h = std::f64::consts::FRAC_1_SQRT_2;
    TfMessage {
        transforms: vec![TransformStamped {
            stamp_ns,
            parent: FRAME_WORLD.to_owned(),
            child: FRAME_BASE.to_owned(),
            translation_m: [0.0; 3],
            rotation: [h, 0.0, 0.0, h],
        }],
    }
}

/// The moving frames of one state (`/tf`): `base` -> `carriage` (P), and
/// with a pose `base` -> `rod` (A's foot, x along u) -> `tip` (L along x).
pub fn moving_frames(s: &StateMsg, g: &SceneGeometry) -> TfMessage {
    let v = Seen::of(s);
    let frame =
        |parent: &str, child: &str, translation_m: V3, rotation: [f64; 4]| TransformStamped {
            stamp_ns: s.now_ns,
            parent: parent.to_owned(),
            child: child.to_owned(),
            translation_m,
            rotation,
        };
    let mut transforms = Vec::with_capacity(3);
    let p = carriage_m(s, g);
    if finite(p) {
        transforms.push(frame(FRAME_BASE, FRAME_CARRIAGE, p, IDENTITY));
    }
    if v.has_pose {
        let turn = rotation_between([1.0, 0.0, 0.0], v.u, [0.0, 0.0, 1.0]);
        transforms.push(frame(FRAME_BASE, FRAME_ROD, foot_m(&v, s, g), turn));
        transforms.push(frame(
            FRAME_ROD,
            FRAME_TIP,
            [g.length_m, 0.0, 0.0],
            IDENTITY,
        ));
    }
    TfMessage { transforms }
}
