//! The 3D scene of the live view and of the recordings: a pure
//! function of one published state ([`StateMsg`]) and the robot's geometry
//! ([`SceneGeometry`], from the configuration's calibration and profile) to a
//! `foxglove.SceneUpdate`, everything in the frame `base` ({0}, MODEL.md 2).
//!
//! Entities (ids in [`ids`]; each update replaces them all, an entity with
//! nothing to show is sent empty):
//! - the base frame: X0, Y0, Z0 as red, green, blue arrows at the origin;
//! - the carriage P = P_home + (q3, q2, q1) (a cube) and its bracket to A;
//! - the U-joint A (a sphere);
//! - the rod: a cylinder of the configured length L from A's foot on the rod
//!   axis (A + d w) along u (from the published q4, q5) to the tip, through B;
//! - the support B as a ring around the rod axis;
//! - F_tip as an arrow from the tip D, `force_scale_m_per_n` metres per
//!   newton, coloured by the guard's state (ok green, warn amber, stop red,
//!   fault magenta);
//! - the limits as translucent spheres at the tip: radius = the total warn and
//!   stop limits at the same scale (the arrow reaching a sphere is the force
//!   reaching that limit).
//!
//! The rod, the tip and the limits need the pose ([`flags::POSE`]); the arrow
//! needs an estimate ([`flags::ESTIMATE`]).
//!
//! [`frame_transforms`] gives the transform `world` -> `base` that shows Y0
//! up in Foxglove (whose 3D view has Z up). [`encode`] and [`schema`] give
//! the bytes and the schema for an MCAP channel (protobuf, the SDK's
//! built-in descriptor).

use crate::geometry::SceneGeometry;
use foxglove::Encode;
use foxglove::messages::{
    ArrowPrimitive, Color, CubePrimitive, CylinderPrimitive, FrameTransform, FrameTransforms,
    KeyValuePair, LinePrimitive, Point3, Pose, Quaternion, SceneEntity, SceneUpdate,
    SpherePrimitive, TextPrimitive, Timestamp, Vector3, line_primitive,
};
use sar_msgs::wire::{StateMsg, flags, guard_code};

/// The frame id of the base frame {0} (as in the recordings).
pub const FRAME_BASE: &str = "base";
/// The frame id of the display frame, Z up (Foxglove's convention).
pub const FRAME_WORLD: &str = "world";

/// The entity ids.
pub mod ids {
    /// The base frame's axes.
    pub const BASE_FRAME: &str = "base_frame";
    /// The carriage P and its bracket to A.
    pub const CARRIAGE: &str = "carriage";
    /// The U-joint A.
    pub const UJOINT: &str = "ujoint";
    /// The rod.
    pub const ROD: &str = "rod";
    /// The support B.
    pub const SUPPORT: &str = "support";
    /// The tip force.
    pub const TIP_FORCE: &str = "tip_force";
    /// The force limits.
    pub const FORCE_LIMITS: &str = "force_limits";
    /// Every id, in the order of the update's entities.
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

/// The rotation taking `from` (unit) onto `to` (unit), as a quaternion; a
/// half turn about `across` (unit, perpendicular to `from`) when they are
/// opposite.
fn rotation_between(from: V3, to: V3, across: V3) -> Quaternion {
    let w = 1.0 + dot(from, to);
    if w < 1e-9 {
        return Quaternion {
            x: across[0],
            y: across[1],
            z: across[2],
            w: 0.0,
        };
    }
    let c = cross(from, to);
    let n = (w * w + dot(c, c)).sqrt();
    Quaternion {
        x: c[0] / n,
        y: c[1] / n,
        z: c[2] / n,
        w: w / n,
    }
}

/// Rotates `v` by the unit quaternion `q`.
pub fn rotate(q: &Quaternion, v: V3) -> V3 {
    let u = [q.x, q.y, q.z];
    let t = scale(cross(u, v), 2.0);
    add(add(v, scale(t, q.w)), cross(u, t))
}

fn vec3(a: V3) -> Vector3 {
    Vector3 {
        x: a[0],
        y: a[1],
        z: a[2],
    }
}
fn point(a: V3) -> Point3 {
    Point3 {
        x: a[0],
        y: a[1],
        z: a[2],
    }
}
fn pose(at: V3, orientation: Quaternion) -> Option<Pose> {
    Some(Pose {
        position: Some(vec3(at)),
        orientation: Some(orientation),
    })
}
fn identity() -> Quaternion {
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 1.0,
    }
}
fn color(r: f64, g: f64, b: f64, a: f64) -> Option<Color> {
    Some(Color { r, g, b, a })
}

/// The colour of a guard state (alpha 1).
pub fn guard_color(code: u32) -> (f64, f64, f64) {
    match code {
        guard_code::OK => (0.1, 0.75, 0.2),
        guard_code::WARN => (1.0, 0.65, 0.0),
        guard_code::STOP => (0.9, 0.1, 0.1),
        _ => (0.8, 0.0, 0.8),
    }
}

/// The foxglove timestamp of a monotonic stamp, ns.
pub fn timestamp(ns: u64) -> Timestamp {
    let sec = u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX);
    // Below 1e9: fits.
    let nsec = u32::try_from(ns % 1_000_000_000).unwrap_or(0);
    Timestamp::new(sec, nsec)
}

/// An arrow from `from` along `dir` (any length > 0), `length` long.
fn arrow(from: V3, dir: V3, length: f64, diameter: f64, c: Option<Color>) -> ArrowPrimitive {
    let n = norm(dir);
    let d = scale(dir, 1.0 / n);
    let head = (0.25 * length).min(4.0 * diameter);
    ArrowPrimitive {
        pose: pose(from, rotation_between([1.0, 0.0, 0.0], d, [0.0, 0.0, 1.0])),
        shaft_length: length - head,
        shaft_diameter: diameter,
        head_length: head,
        head_diameter: 2.5 * diameter,
        color: c,
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

/// Points of the support ring.
const RING_POINTS: usize = 32;

/// u and w of MODEL.md 3 from q4, q5.
fn rod_frame(q45_rad: [f64; 2]) -> (V3, V3) {
    let (u, w) = sar_kinematics::rod_frame(q45_rad[0], q45_rad[1]);
    ([u.x, u.y, u.z], [w.x, w.y, w.z])
}

fn entity(id: &str, stamp: &Timestamp) -> SceneEntity {
    SceneEntity {
        timestamp: Some(*stamp),
        frame_id: FRAME_BASE.to_owned(),
        id: id.to_owned(),
        ..SceneEntity::default()
    }
}

/// The scene of one published state.
pub fn scene(s: &StateMsg, g: &SceneGeometry) -> SceneUpdate {
    let stamp = timestamp(s.now_ns);
    let has_pose = s.flags & flags::POSE != 0
        && finite(s.ujoint_m)
        && finite(s.tip_m)
        && s.q45_rad.iter().all(|x| x.is_finite());
    let has_force = has_pose && s.flags & flags::ESTIMATE != 0 && finite(s.tip_force_n);
    let (u, w) = rod_frame(s.q45_rad);
    let (gr, gg, gb) = guard_color(s.guard_state);

    // The base frame.
    let mut base = entity(ids::BASE_FRAME, &stamp);
    let axes = [
        ([1.0, 0.0, 0.0], "X0", color(0.9, 0.1, 0.1, 1.0)),
        ([0.0, 1.0, 0.0], "Y0", color(0.1, 0.8, 0.1, 1.0)),
        ([0.0, 0.0, 1.0], "Z0", color(0.1, 0.3, 0.9, 1.0)),
    ];
    for (dir, name, c) in axes {
        base.arrows
            .push(arrow([0.0; 3], dir, g.axis_length_m, 0.004, c));
        base.texts.push(TextPrimitive {
            pose: pose(scale(dir, 1.15 * g.axis_length_m), identity()),
            billboard: true,
            font_size: 12.0,
            scale_invariant: true,
            color: c,
            text: name.to_owned(),
        });
    }

    // The carriage P and its bracket to A.
    let mut carriage = entity(ids::CARRIAGE, &stamp);
    let p = add(g.p_home_m, [s.q_m[2], s.q_m[1], s.q_m[0]]);
    if finite(p) {
        carriage.cubes.push(CubePrimitive {
            pose: pose(p, identity()),
            size: Some(vec3([0.04, 0.04, 0.04])),
            color: color(0.6, 0.6, 0.65, 1.0),
        });
        if has_pose {
            carriage.lines.push(LinePrimitive {
                r#type: line_primitive::Type::LineStrip as i32,
                pose: pose([0.0; 3], identity()),
                thickness: 0.006,
                scale_invariant: false,
                points: vec![point(p), point(s.ujoint_m)],
                color: color(0.6, 0.6, 0.65, 1.0),
                ..LinePrimitive::default()
            });
        }
    }

    // The U-joint A, the rod, the tip.
    let mut ujoint = entity(ids::UJOINT, &stamp);
    let mut rod = entity(ids::ROD, &stamp);
    if has_pose {
        ujoint.spheres.push(SpherePrimitive {
            pose: pose(s.ujoint_m, identity()),
            size: Some(vec3([0.02, 0.02, 0.02])),
            color: color(0.3, 0.3, 0.35, 1.0),
        });
        let foot = add(s.ujoint_m, scale(w, g.offset_m));
        if g.offset_m != 0.0 {
            ujoint.lines.push(LinePrimitive {
                r#type: line_primitive::Type::LineStrip as i32,
                pose: pose([0.0; 3], identity()),
                thickness: 0.004,
                points: vec![point(s.ujoint_m), point(foot)],
                color: color(0.3, 0.3, 0.35, 1.0),
                ..LinePrimitive::default()
            });
        }
        let centre = add(foot, scale(u, 0.5 * g.length_m));
        rod.cylinders.push(CylinderPrimitive {
            pose: pose(
                centre,
                rotation_between([0.0, 0.0, 1.0], u, [1.0, 0.0, 0.0]),
            ),
            size: Some(vec3([g.rod_diameter_m, g.rod_diameter_m, g.length_m])),
            bottom_scale: 1.0,
            top_scale: 1.0,
            color: color(0.85, 0.85, 0.9, 1.0),
        });
        rod.spheres.push(SpherePrimitive {
            pose: pose(s.tip_m, identity()),
            size: Some(vec3([1.6 * g.rod_diameter_m; 3])),
            color: color(gr, gg, gb, 1.0),
        });
        rod.metadata.push(KeyValuePair {
            key: "cycle".to_owned(),
            value: s.cycle.to_string(),
        });
    }

    // The support ring around the rod axis (or around X0 without a pose).
    let mut support = entity(ids::SUPPORT, &stamp);
    let axis = if has_pose { u } else { [1.0, 0.0, 0.0] };
    let e1 = perpendicular(axis);
    let e2 = cross(axis, e1);
    let points = (0..RING_POINTS)
        .map(|k| {
            let t = std::f64::consts::TAU * k as f64 / RING_POINTS as f64;
            let r = add(scale(e1, t.cos()), scale(e2, t.sin()));
            point(add(g.support_m, scale(r, g.support_radius_m)))
        })
        .collect();
    support.lines.push(LinePrimitive {
        r#type: line_primitive::Type::LineLoop as i32,
        pose: pose([0.0; 3], identity()),
        thickness: 0.004,
        points,
        color: color(0.95, 0.8, 0.2, 1.0),
        ..LinePrimitive::default()
    });

    // F_tip from the tip.
    let mut force = entity(ids::TIP_FORCE, &stamp);
    let magnitude = norm(s.tip_force_n);
    if has_force {
        let length = magnitude * g.force_scale_m_per_n;
        if length > 1e-6 {
            force.arrows.push(arrow(
                s.tip_m,
                s.tip_force_n,
                length,
                0.005,
                color(gr, gg, gb, 1.0),
            ));
        }
        let observable = if s.flags & flags::OBSERVABLE != 0 {
            ""
        } else {
            " (not observable)"
        };
        force.texts.push(TextPrimitive {
            pose: pose(add(s.tip_m, [0.0, 0.03, 0.0]), identity()),
            billboard: true,
            font_size: 14.0,
            scale_invariant: true,
            color: color(gr, gg, gb, 1.0),
            text: format!(
                "|F| {magnitude:.2} N, {}{observable}",
                sar_msgs::wire::guard_state_name(s.guard_state)
            ),
        });
    }

    // The total limits as spheres at the tip.
    let mut limits = entity(ids::FORCE_LIMITS, &stamp);
    if has_pose {
        let spheres = [
            (s.limits_n[0], color(1.0, 0.65, 0.0, 0.08)),
            (s.limits_n[1], color(0.9, 0.1, 0.1, 0.12)),
        ];
        for (limit_n, c) in spheres {
            let d = 2.0 * limit_n * g.force_scale_m_per_n;
            if d.is_finite() && d > 0.0 {
                limits.spheres.push(SpherePrimitive {
                    pose: pose(s.tip_m, identity()),
                    size: Some(vec3([d, d, d])),
                    color: c,
                });
            }
        }
    }

    SceneUpdate {
        deletions: Vec::new(),
        entities: vec![base, carriage, ujoint, rod, support, force, limits],
    }
}

/// The transform `world` (Z up) -> `base` ({0}, Y up): a quarter turn about
/// X, so that Y0 shows up and Z0 towards the viewer.
pub fn frame_transforms(now_ns: u64) -> FrameTransforms {
    let h = std::f64::consts::FRAC_1_SQRT_2;
    FrameTransforms {
        transforms: vec![FrameTransform {
            timestamp: Some(timestamp(now_ns)),
            parent_frame_id: FRAME_WORLD.to_owned(),
            child_frame_id: FRAME_BASE.to_owned(),
            translation: Some(vec3([0.0; 3])),
            rotation: Some(Quaternion {
                x: h,
                y: 0.0,
                z: 0.0,
                w: h,
            }),
        }],
    }
}

/// A schema for an MCAP channel: name, encoding, data.
#[derive(Debug, Clone, PartialEq)]
pub struct McapSchema {
    /// The schema's name (`foxglove.SceneUpdate`).
    pub name: String,
    /// Its encoding (`protobuf`).
    pub encoding: String,
    /// The binary `FileDescriptorSet`.
    pub data: Vec<u8>,
    /// The channel's message encoding (`protobuf`).
    pub message_encoding: String,
}

/// The MCAP schema of the scene topic.
pub fn schema() -> McapSchema {
    let (name, encoding, data) = match SceneUpdate::get_schema() {
        Some(s) => (s.name, s.encoding, s.data.into_owned()),
        None => (String::new(), String::new(), Vec::new()),
    };
    McapSchema {
        name,
        encoding,
        data,
        message_encoding: SceneUpdate::get_message_encoding(),
    }
}

/// Encodes a scene for an MCAP message (protobuf) into `buf` (cleared
/// first).
pub fn encode(update: &SceneUpdate, buf: &mut Vec<u8>) -> Result<(), EncodeError> {
    buf.clear();
    Encode::encode(update, buf)
}

/// Why a scene could not be encoded (into a `Vec`: never in practice).
pub type EncodeError = <SceneUpdate as Encode>::Error;

/// The MCAP schema of the scene's frame transform topic.
pub fn tf_schema() -> McapSchema {
    let (name, encoding, data) = match FrameTransforms::get_schema() {
        Some(s) => (s.name, s.encoding, s.data.into_owned()),
        None => (String::new(), String::new(), Vec::new()),
    };
    McapSchema {
        name,
        encoding,
        data,
        message_encoding: FrameTransforms::get_message_encoding(),
    }
}

/// Encodes the frame transforms for an MCAP message (protobuf) into `buf`
/// (cleared first).
pub fn encode_tf(
    tf: &FrameTransforms,
    buf: &mut Vec<u8>,
) -> Result<(), <FrameTransforms as Encode>::Error> {
    buf.clear();
    Encode::encode(tf, buf)
}
