//! The 3D scene's messages, standard ROS 2 types that rviz2, Foxglove and
//! Lichtblick render: `visualization_msgs/msg/MarkerArray` (of
//! `visualization_msgs/Marker`) and `tf2_msgs/msg/TFMessage` (of
//! `geometry_msgs/TransformStamped`), as ROS 2 Jazzy defines them, with their
//! `ros2msg` schemas (each nested type after a line of 80 `=` and
//! `MSG: pkg/Type`).
//!
//! Fixed-size and `Copy` (every sequence bounded at construction:
//! [`Bounded`], [`MAX_MARKERS`], [`MAX_POINTS`], [`MAX_TRANSFORMS`]); the
//! encoder writes into a caller's buffer. The fields the scene does not use
//! (per-point colors, textures, meshes) are written empty, and the decoder
//! refuses them non-empty rather than drop them.

use crate::cdr::{CdrError, CdrReader, CdrWriter, FixedStr};
use crate::msgs::{FrameId, RosMessage};

/// Markers in one [`MarkerArray`] at most.
pub const MAX_MARKERS: usize = 24;
/// Points of one [`Marker`] at most.
pub const MAX_POINTS: usize = 40;
/// Transforms in one [`TfMessage`] at most.
pub const MAX_TRANSFORMS: usize = 4;
/// A marker's namespace, at most 32 bytes.
pub type MarkerNs = FixedStr<32>;
/// A text marker's text, at most 96 bytes.
pub type MarkerText = FixedStr<96>;

/// A sequence of at most N values held inline.
#[derive(Clone, Copy)]
pub struct Bounded<T: Copy + Default, const N: usize> {
    len: usize,
    items: [T; N],
}

impl<T: Copy + Default, const N: usize> Default for Bounded<T, N> {
    fn default() -> Self {
        Self {
            len: 0,
            items: [T::default(); N],
        }
    }
}

impl<T: Copy + Default + core::fmt::Debug, const N: usize> core::fmt::Debug for Bounded<T, N> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_list().entries(self.as_slice()).finish()
    }
}

/// Equal when the values in use are (what lies beyond them is not).
impl<T: Copy + Default + PartialEq, const N: usize> PartialEq for Bounded<T, N> {
    fn eq(&self, other: &Self) -> bool {
        self.as_slice() == other.as_slice()
    }
}

/// A [`Bounded`] sequence is full.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("a bounded sequence holds at most {capacity} values")]
pub struct Full {
    /// Its capacity.
    pub capacity: usize,
}

impl<T: Copy + Default, const N: usize> Bounded<T, N> {
    /// Appends `v`, or says it is full.
    pub fn push(&mut self, v: T) -> Result<(), Full> {
        let slot = self.items.get_mut(self.len).ok_or(Full { capacity: N })?;
        *slot = v;
        self.len += 1;
        Ok(())
    }
    /// The values.
    pub fn as_slice(&self) -> &[T] {
        self.items.get(..self.len).unwrap_or(&[])
    }
    /// Empties it.
    pub fn clear(&mut self) {
        self.len = 0;
    }
    /// Its length.
    pub fn len(&self) -> usize {
        self.len
    }
    /// Whether it is empty.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

/// `visualization_msgs/Marker`'s `type` (its constants).
pub mod marker_type {
    /// An arrow (pose: tail, x along the arrow; scale: length, shaft and
    /// head diameters), or from `points[0]` to `points[1]`.
    pub const ARROW: i32 = 0;
    /// A box.
    pub const CUBE: i32 = 1;
    /// A sphere (scale: diameters).
    pub const SPHERE: i32 = 2;
    /// A cylinder along its z (scale: diameters, height).
    pub const CYLINDER: i32 = 3;
    /// A line through `points` (scale.x: width).
    pub const LINE_STRIP: i32 = 4;
    /// Text facing the viewer (scale.z: height of a capital).
    pub const TEXT_VIEW_FACING: i32 = 9;
}

/// `visualization_msgs/Marker`'s `action`.
pub mod marker_action {
    /// Add or modify.
    pub const ADD: i32 = 0;
    /// Delete the marker of this ns and id.
    pub const DELETE: i32 = 2;
}

/// `geometry_msgs/Pose`: position, m, and orientation (x, y, z, w).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Position, m.
    pub position_m: [f64; 3],
    /// Orientation, a unit quaternion x, y, z, w.
    pub orientation: [f64; 4],
}

impl Default for Pose {
    fn default() -> Self {
        Self {
            position_m: [0.0; 3],
            orientation: [0.0, 0.0, 0.0, 1.0],
        }
    }
}

/// One `visualization_msgs/Marker` (the fields the scene uses; the rest
/// written empty).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Marker {
    /// `header.stamp`, ns.
    pub stamp_ns: u64,
    /// `header.frame_id`.
    pub frame_id: FrameId,
    /// `ns`: with `id`, the marker's name.
    pub ns: MarkerNs,
    /// `id`.
    pub id: i32,
    /// `type` ([`marker_type`]).
    pub kind: i32,
    /// `action` ([`marker_action`]).
    pub action: i32,
    /// `pose`.
    pub pose: Pose,
    /// `scale`, m.
    pub scale_m: [f64; 3],
    /// `color`, r, g, b, a in 0..=1.
    pub color: [f32; 4],
    /// `frame_locked`.
    pub frame_locked: bool,
    /// `points`, m.
    pub points_m: Bounded<[f64; 3], MAX_POINTS>,
    /// `text`.
    pub text: MarkerText,
}

/// `visualization_msgs/msg/MarkerArray`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MarkerArray {
    /// `markers`.
    pub markers: Bounded<Marker, MAX_MARKERS>,
}

/// One `geometry_msgs/TransformStamped`: `frame_id` -> `child_frame_id`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TransformStamped {
    /// `header.stamp`, ns.
    pub stamp_ns: u64,
    /// `header.frame_id`: the parent frame.
    pub frame_id: FrameId,
    /// `child_frame_id`.
    pub child_frame_id: FrameId,
    /// `transform.translation`, m.
    pub translation_m: [f64; 3],
    /// `transform.rotation`, x, y, z, w.
    pub rotation: [f64; 4],
}

/// `tf2_msgs/msg/TFMessage`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TfMessage {
    /// `transforms`.
    pub transforms: Bounded<TransformStamped, MAX_TRANSFORMS>,
}

macro_rules! sep {
    () => {
        "================================================================================\n"
    };
}

macro_rules! header_time {
    () => {
        concat!(
            sep!(),
            "MSG: std_msgs/Header\n",
            "# Standard metadata for higher-level stamped data types.\n",
            "# This is generally used to communicate timestamped data\n",
            "# in a particular coordinate frame.\n",
            "\n",
            "# Two-integer timestamp that is expressed as seconds and nanoseconds.\n",
            "builtin_interfaces/Time stamp\n",
            "\n",
            "# Transform frame with which this data is associated.\n",
            "string frame_id\n",
            sep!(),
            "MSG: builtin_interfaces/Time\n",
            "# This message communicates ROS Time defined here:\n",
            "# https://design.ros2.org/articles/clock_and_time.html\n",
            "\n",
            "# The seconds component, valid over all int32 values.\n",
            "int32 sec\n",
            "\n",
            "# The nanoseconds component, valid in the range [0, 1e9), to be added to the seconds component.\n",
            "# e.g.\n",
            "# The time -1.7 seconds is represented as {sec: -2, nanosec: 3e8}\n",
            "# The time 1.7 seconds is represented as {sec: 1, nanosec: 7e8}\n",
            "uint32 nanosec\n",
        )
    };
}

macro_rules! vector3_quaternion {
    () => {
        concat!(
            sep!(),
            "MSG: geometry_msgs/Vector3\n",
            "# This represents a vector in free space.\n",
            "\n",
            "# This is semantically different than a point.\n",
            "# A vector is always anchored at the origin.\n",
            "# When a transform is applied to a vector, only the rotation is applied.\n",
            "\n",
            "float64 x\n",
            "float64 y\n",
            "float64 z\n",
        )
    };
}

macro_rules! quaternion {
    () => {
        concat!(
            sep!(),
            "MSG: geometry_msgs/Quaternion\n",
            "# This represents an orientation in free space in quaternion form.\n",
            "\n",
            "float64 x 0\n",
            "float64 y 0\n",
            "float64 z 0\n",
            "float64 w 1\n",
        )
    };
}

/// `visualization_msgs/Marker.msg` (ROS 2 Jazzy).
macro_rules! marker_msg {
    () => {
        concat!(
            "# See:\n",
            "#  - http://www.ros.org/wiki/rviz/DisplayTypes/Marker\n",
            "#  - http://www.ros.org/wiki/rviz/Tutorials/Markers%3A%20Basic%20Shapes\n",
            "#\n",
            "# for more information on using this message with rviz.\n",
            "\n",
            "int32 ARROW=0\n",
            "int32 CUBE=1\n",
            "int32 SPHERE=2\n",
            "int32 CYLINDER=3\n",
            "int32 LINE_STRIP=4\n",
            "int32 LINE_LIST=5\n",
            "int32 CUBE_LIST=6\n",
            "int32 SPHERE_LIST=7\n",
            "int32 POINTS=8\n",
            "int32 TEXT_VIEW_FACING=9\n",
            "int32 MESH_RESOURCE=10\n",
            "int32 TRIANGLE_LIST=11\n",
            "int32 ARROW_STRIP=12 # Currently unimplemented\n",
            "\n",
            "int32 ADD=0\n",
            "int32 MODIFY=0\n",
            "int32 DELETE=2\n",
            "int32 DELETEALL=3\n",
            "\n",
            "# Header for timestamp and frame id.\n",
            "std_msgs/Header header\n",
            "# Namespace in which to place the object.\n",
            "# Used in conjunction with id to create a unique name for the object.\n",
            "string ns\n",
            "# Object ID used in conjunction with the namespace for manipulating and deleting the object later.\n",
            "int32 id\n",
            "# Type of object.\n",
            "int32 type\n",
            "# Action to take; one of:\n",
            "#  - 0 add/modify an object\n",
            "#  - 1 (deprecated)\n",
            "#  - 2 deletes an object (with the given ns and id)\n",
            "#  - 3 deletes all objects (or those with the given ns if any)\n",
            "int32 action\n",
            "# Pose of the object with respect the frame_id specified in the header.\n",
            "geometry_msgs/Pose pose\n",
            "# Scale of the object; 1,1,1 means default (usually 1 meter square).\n",
            "geometry_msgs/Vector3 scale\n",
            "# Color of the object; in the range: [0.0-1.0]\n",
            "std_msgs/ColorRGBA color\n",
            "# How long the object should last before being automatically deleted.\n",
            "# 0 indicates forever.\n",
            "builtin_interfaces/Duration lifetime\n",
            "# If this marker should be frame-locked, i.e. retransformed into its frame every timestep.\n",
            "bool frame_locked\n",
            "\n",
            "# Only used if the type specified has some use for them (eg. POINTS, LINE_STRIP, ARROW_STRIP, etc.)\n",
            "geometry_msgs/Point[] points\n",
            "# Only used if the type specified has some use for them (eg. POINTS, LINE_STRIP, etc.)\n",
            "# The number of colors provided must either be 0 or equal to the number of points provided.\n",
            "# NOTE: alpha is not yet used\n",
            "std_msgs/ColorRGBA[] colors\n",
            "\n",
            "# Texture resource is a special URI that can either reference a texture file in\n",
            "# a format acceptable to (resource retriever)[https://index.ros.org/p/resource_retriever/]\n",
            "# or an embedded texture via a string matching the format:\n",
            "#   \"embedded://texture_name\"\n",
            "string texture_resource\n",
            "# An image to be loaded into the rendering engine as the texture for this marker.\n",
            "# This will be used iff texture_resource is set to embedded.\n",
            "sensor_msgs/CompressedImage texture\n",
            "# Location of each vertex within the texture; in the range: [0.0-1.0]\n",
            "UVCoordinate[] uv_coordinates\n",
            "\n",
            "# Only used for text markers\n",
            "string text\n",
            "\n",
            "# Only used for MESH_RESOURCE markers.\n",
            "# Similar to texture_resource, mesh_resource uses resource retriever to load a mesh.\n",
            "# Optionally, a mesh file can be sent in-message via the mesh_file field. If doing so,\n",
            "# use the following format for mesh_resource:\n",
            "#   \"embedded://mesh_name\"\n",
            "string mesh_resource\n",
            "MeshFile mesh_file\n",
            "bool mesh_use_embedded_materials\n",
        )
    };
}

/// The `ros2msg` schema of `visualization_msgs/msg/MarkerArray`.
pub const MARKER_ARRAY_SCHEMA: &str = concat!(
    "visualization_msgs/Marker[] markers\n",
    sep!(),
    "MSG: visualization_msgs/Marker\n",
    marker_msg!(),
    header_time!(),
    sep!(),
    "MSG: geometry_msgs/Pose\n",
    "# A representation of pose in free space, composed of position and orientation.\n",
    "\n",
    "Point position\n",
    "Quaternion orientation\n",
    sep!(),
    "MSG: geometry_msgs/Point\n",
    "# This contains the position of a point in free space\n",
    "float64 x\n",
    "float64 y\n",
    "float64 z\n",
    quaternion!(),
    vector3_quaternion!(),
    sep!(),
    "MSG: std_msgs/ColorRGBA\n",
    "float32 r\n",
    "float32 g\n",
    "float32 b\n",
    "float32 a\n",
    sep!(),
    "MSG: builtin_interfaces/Duration\n",
    "# Duration defines a period between two time points.\n",
    "# Messages of this datatype are of ROS Time following this design:\n",
    "# https://design.ros2.org/articles/clock_and_time.html\n",
    "\n",
    "# The seconds component, valid over all int32 values.\n",
    "int32 sec\n",
    "\n",
    "# The nanoseconds component, valid in the range [0, 1e9), to be added to the seconds component.\n",
    "# e.g.\n",
    "# The duration -1.7 seconds is represented as {sec: -2, nanosec: 3e8}\n",
    "# The duration 1.7 seconds is represented as {sec: 1, nanosec: 7e8}\n",
    "uint32 nanosec\n",
    sep!(),
    "MSG: sensor_msgs/CompressedImage\n",
    "# This message contains a compressed image.\n",
    "\n",
    "std_msgs/Header header # Header timestamp should be acquisition time of image\n",
    "\n",
    "string format                # Specifies the format of the data\n",
    "\n",
    "uint8[] data                 # Compressed image buffer\n",
    sep!(),
    "MSG: visualization_msgs/UVCoordinate\n",
    "# Location of the pixel as a ratio of the width of a 2D texture.\n",
    "# Values should be in range: [0.0-1.0].\n",
    "float32 u\n",
    "float32 v\n",
    sep!(),
    "MSG: visualization_msgs/MeshFile\n",
    "# Used to send raw mesh files.\n",
    "\n",
    "# The filename is used for both debug purposes and to provide a file extension\n",
    "# for whatever parser is used.\n",
    "string filename\n",
    "\n",
    "# This stores the raw text of the mesh file.\n",
    "uint8[] data\n",
);

/// The `ros2msg` schema of `tf2_msgs/msg/TFMessage`.
pub const TF_MESSAGE_SCHEMA: &str = concat!(
    "geometry_msgs/TransformStamped[] transforms\n",
    sep!(),
    "MSG: geometry_msgs/TransformStamped\n",
    "# This expresses a transform from coordinate frame header.frame_id\n",
    "# to the coordinate frame child_frame_id at the time of header.stamp\n",
    "#\n",
    "# This message is mostly used by the\n",
    "# <a href=\"https://index.ros.org/p/tf2/\">tf2</a> package.\n",
    "# See its documentation for more information.\n",
    "#\n",
    "# The child_frame_id is necessary in addition to the frame_id\n",
    "# in the Header to communicate the full reference for the transform\n",
    "# in a self contained message.\n",
    "\n",
    "std_msgs/Header header\n",
    "string child_frame_id # the frame id of the child frame\n",
    "Transform transform\n",
    header_time!(),
    sep!(),
    "MSG: geometry_msgs/Transform\n",
    "# This represents the transform between two coordinate frames in free space.\n",
    "\n",
    "Vector3 translation\n",
    "Quaternion rotation\n",
    vector3_quaternion!(),
    quaternion!(),
);

fn quaternion_out(w: &mut CdrWriter<'_>, q: &[f64; 4]) {
    w.f64_array(q);
}

fn empty_compressed_image(w: &mut CdrWriter<'_>) -> Result<(), CdrError> {
    w.time(0)?;
    w.string("");
    w.string("");
    w.seq_len(0);
    Ok(())
}

impl Marker {
    fn encode_into(&self, w: &mut CdrWriter<'_>) -> Result<(), CdrError> {
        w.time(self.stamp_ns)?;
        w.string(self.frame_id.as_str());
        w.string(self.ns.as_str());
        w.i32(self.id);
        w.i32(self.kind);
        w.i32(self.action);
        w.f64_array(&self.pose.position_m);
        quaternion_out(w, &self.pose.orientation);
        w.f64_array(&self.scale_m);
        for c in self.color {
            w.f32(c);
        }
        // lifetime: 0, forever (each scene replaces the markers by ns and id).
        w.i32(0);
        w.u32(0);
        w.bool(self.frame_locked);
        w.seq_len(self.points_m.len());
        for p in self.points_m.as_slice() {
            w.f64_array(p);
        }
        w.seq_len(0); // colors
        w.string(""); // texture_resource
        empty_compressed_image(w)?;
        w.seq_len(0); // uv_coordinates
        w.string(self.text.as_str());
        w.string(""); // mesh_resource
        w.string(""); // mesh_file.filename
        w.seq_len(0); // mesh_file.data
        w.bool(false); // mesh_use_embedded_materials
        Ok(())
    }

    fn decode_from(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        let mut m = Marker {
            stamp_ns: r.time()?,
            frame_id: r.fixed_str()?,
            ns: r.fixed_str()?,
            id: r.i32()?,
            kind: r.i32()?,
            action: r.i32()?,
            pose: Pose {
                position_m: r.f64_array()?,
                orientation: r.f64_array()?,
            },
            scale_m: r.f64_array()?,
            color: [r.f32()?, r.f32()?, r.f32()?, r.f32()?],
            ..Marker::default()
        };
        let (sec, nanosec) = (r.i32()?, r.u32()?);
        if sec != 0 || nanosec != 0 {
            return Err(CdrError::BadValue {
                field: "lifetime",
                value: i64::from(sec),
            });
        }
        m.frame_locked = r.bool()?;
        for _ in 0..r.seq_len(MAX_POINTS, 24)? {
            let p = r.f64_array()?;
            // Within MAX_POINTS (seq_len checked).
            let _ = m.points_m.push(p);
        }
        Self::decode_unused(r)?;
        m.text = r.fixed_str()?;
        r.fixed_str::<0>()?; // mesh_resource
        r.fixed_str::<0>()?; // mesh_file.filename
        r.seq_len(0, 1)?; // mesh_file.data
        r.bool()?; // mesh_use_embedded_materials
        Ok(m)
    }

    /// colors, texture_resource, texture, uv_coordinates: empty, as written.
    fn decode_unused(r: &mut CdrReader<'_>) -> Result<(), CdrError> {
        r.seq_len(0, 16)?;
        r.fixed_str::<0>()?;
        r.time()?;
        r.fixed_str::<0>()?;
        r.fixed_str::<0>()?;
        r.seq_len(0, 1)?;
        r.seq_len(0, 8)?;
        Ok(())
    }
}

impl RosMessage for MarkerArray {
    const TYPE_NAME: &'static str = "visualization_msgs/msg/MarkerArray";
    const SCHEMA: &'static str = MARKER_ARRAY_SCHEMA;
    fn encode_fields(&self, w: &mut CdrWriter<'_>) -> Result<(), CdrError> {
        w.seq_len(self.markers.len());
        for m in self.markers.as_slice() {
            m.encode_into(w)?;
        }
        Ok(())
    }
    fn decode_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        let mut out = MarkerArray::default();
        for _ in 0..r.seq_len(MAX_MARKERS, 64)? {
            let m = Marker::decode_from(r)?;
            let _ = out.markers.push(m);
        }
        Ok(out)
    }
}

impl RosMessage for TfMessage {
    const TYPE_NAME: &'static str = "tf2_msgs/msg/TFMessage";
    const SCHEMA: &'static str = TF_MESSAGE_SCHEMA;
    fn encode_fields(&self, w: &mut CdrWriter<'_>) -> Result<(), CdrError> {
        w.seq_len(self.transforms.len());
        for t in self.transforms.as_slice() {
            w.time(t.stamp_ns)?;
            w.string(t.frame_id.as_str());
            w.string(t.child_frame_id.as_str());
            w.f64_array(&t.translation_m);
            quaternion_out(w, &t.rotation);
        }
        Ok(())
    }
    fn decode_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        let mut out = TfMessage::default();
        for _ in 0..r.seq_len(MAX_TRANSFORMS, 64)? {
            let t = TransformStamped {
                stamp_ns: r.time()?,
                frame_id: r.fixed_str()?,
                child_frame_id: r.fixed_str()?,
                translation_m: r.f64_array()?,
                rotation: r.f64_array()?,
            };
            let _ = out.transforms.push(t);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]
    use super::*;

    #[test]
    fn a_marker_array_and_a_tf_message_decode_to_what_was_encoded() {
        let mut a = MarkerArray::default();
        let mut m = Marker {
            stamp_ns: 1_500_000_000,
            frame_id: FrameId::truncating("base"),
            ns: MarkerNs::truncating("rod"),
            id: 3,
            kind: marker_type::LINE_STRIP,
            scale_m: [0.01, 0.0, 0.0],
            color: [0.5, 0.25, 1.0, 0.75],
            text: MarkerText::truncating("hello"),
            ..Marker::default()
        };
        m.points_m.push([1.0, 2.0, 3.0]).unwrap();
        m.points_m.push([4.0, 5.0, 6.0]).unwrap();
        a.markers.push(m).unwrap();
        a.markers.push(Marker::default()).unwrap();
        let mut buf = Vec::new();
        a.encode(&mut buf).unwrap();
        assert_eq!(MarkerArray::decode(&buf).unwrap(), a);
        let mut tf = TfMessage::default();
        tf.transforms
            .push(TransformStamped {
                stamp_ns: 7,
                frame_id: FrameId::truncating("world"),
                child_frame_id: FrameId::truncating("base"),
                translation_m: [0.0; 3],
                rotation: [0.5, 0.0, 0.0, 0.5],
            })
            .unwrap();
        tf.encode(&mut buf).unwrap();
        assert_eq!(TfMessage::decode(&buf).unwrap(), tf);
    }

    #[test]
    fn a_bounded_sequence_refuses_beyond_its_capacity() {
        let mut p: Bounded<u8, 2> = Bounded::default();
        p.push(1).unwrap();
        p.push(2).unwrap();
        assert_eq!(p.push(3), Err(Full { capacity: 2 }));
        assert_eq!(p.as_slice(), &[1, 2]);
    }
}
