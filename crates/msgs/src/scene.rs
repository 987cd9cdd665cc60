//! The 3D scene's ROS 2 messages: `visualization_msgs/msg/MarkerArray` and
//! `tf2_msgs/msg/TFMessage` (ROS 2 Jazzy's definitions), encoded and decoded
//! by the project's CDR, with the schema texts ROS 2's recorder writes
//! (every nested type in a `MSG: pkg/Type` section, fields spelled with their
//! package). rviz2, Foxglove and Lichtblick render them; they are written
//! into every recording (`sar-record`) and served by the live view
//! (`sarctl view`), drawn by `sar-scene`.
//!
//! Only what the scene uses is a field of [`Marker`]; the rest of the ROS 2
//! message (per-point colours, texture, UV coordinates, mesh) is written
//! empty and skipped when read. Sequences and texts are bounded when read
//! ([`MAX_MARKERS`], [`MAX_POINTS`], [`MAX_TEXT_BYTES`]).

use crate::cdr::{CdrError, CdrReader, CdrWriter};

/// The most markers a [`MarkerArray`] read may hold.
pub const MAX_MARKERS: usize = 256;
/// The most points a [`Marker`] read may hold.
pub const MAX_POINTS: usize = 1024;
/// The longest text (name, frame id, label) a read accepts, bytes.
pub const MAX_TEXT_BYTES: usize = 1024;
/// The most transforms a [`TfMessage`] read may hold.
pub const MAX_TRANSFORMS: usize = 64;

macro_rules! sep {
    () => {
        "================================================================================\n"
    };
}

macro_rules! common_sections {
    () => {
        concat!(
            sep!(),
            "MSG: std_msgs/Header\n",
            "builtin_interfaces/Time stamp\n",
            "string frame_id\n",
            sep!(),
            "MSG: builtin_interfaces/Time\n",
            "int32 sec\n",
            "uint32 nanosec\n",
            sep!(),
            "MSG: geometry_msgs/Vector3\n",
            "float64 x\n",
            "float64 y\n",
            "float64 z\n",
            sep!(),
            "MSG: geometry_msgs/Quaternion\n",
            "float64 x 0\n",
            "float64 y 0\n",
            "float64 z 0\n",
            "float64 w 1\n",
        )
    };
}

/// A marker's shape (`visualization_msgs/Marker` `type`).
pub mod kind {
    /// An arrow: from `points[0]` to `points[1]`; scale x shaft diameter,
    /// y head diameter, z head length.
    pub const ARROW: i32 = 0;
    /// A box of size `scale`.
    pub const CUBE: i32 = 1;
    /// An ellipsoid of diameters `scale`.
    pub const SPHERE: i32 = 2;
    /// A cylinder along its z axis, diameters x, y and height z.
    pub const CYLINDER: i32 = 3;
    /// A polyline through `points`, width scale x.
    pub const LINE_STRIP: i32 = 4;
    /// Text facing the viewer, height scale z.
    pub const TEXT_VIEW_FACING: i32 = 9;
}

/// A marker's action (`visualization_msgs/Marker` `action`).
pub mod action {
    /// Adds or replaces the marker of the same namespace and id.
    pub const ADD: i32 = 0;
    /// Deletes the marker of the same namespace and id.
    pub const DELETE: i32 = 2;
}

/// One `visualization_msgs/Marker` (the fields the scene uses).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Marker {
    /// `header.stamp`, ns.
    pub stamp_ns: u64,
    /// `header.frame_id`.
    pub frame_id: String,
    /// The namespace (with `id`, the marker's name).
    pub ns: String,
    /// Its id within the namespace.
    pub id: i32,
    /// [`kind`].
    pub kind: i32,
    /// [`action`].
    pub action: i32,
    /// `pose.position`, m.
    pub position_m: [f64; 3],
    /// `pose.orientation`, a unit quaternion x, y, z, w.
    pub orientation: [f64; 4],
    /// `scale` (its meaning depends on `kind`), m.
    pub scale_m: [f64; 3],
    /// `color`, r, g, b, a in 0..1.
    pub color: [f32; 4],
    /// `points`, m.
    pub points_m: Vec<[f64; 3]>,
    /// `text` (TEXT_VIEW_FACING).
    pub text: String,
}

/// The identity rotation (x, y, z, w).
pub const IDENTITY: [f64; 4] = [0.0, 0.0, 0.0, 1.0];

/// `visualization_msgs/msg/MarkerArray`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MarkerArray {
    /// The markers.
    pub markers: Vec<Marker>,
}

/// One `geometry_msgs/TransformStamped`: the pose of `child` in `parent`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TransformStamped {
    /// `header.stamp`, ns.
    pub stamp_ns: u64,
    /// `header.frame_id`: the parent frame.
    pub parent: String,
    /// `child_frame_id`.
    pub child: String,
    /// `transform.translation`: the child's origin in the parent, m.
    pub translation_m: [f64; 3],
    /// `transform.rotation`: x, y, z, w.
    pub rotation: [f64; 4],
}

/// `tf2_msgs/msg/TFMessage`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TfMessage {
    /// The transforms.
    pub transforms: Vec<TransformStamped>,
}

fn header(w: &mut CdrWriter<'_>, stamp_ns: u64, frame_id: &str) -> Result<(), CdrError> {
    w.time(stamp_ns)?;
    w.string(frame_id);
    Ok(())
}

fn text(r: &mut CdrReader<'_>) -> Result<String, CdrError> {
    let s = r.str()?;
    if s.len() > MAX_TEXT_BYTES {
        return Err(CdrError::SequenceTooLong {
            offset: 0,
            count: s.len(),
            max: MAX_TEXT_BYTES,
        });
    }
    Ok(s.to_owned())
}

fn vec3(r: &mut CdrReader<'_>) -> Result<[f64; 3], CdrError> {
    Ok([r.f64()?, r.f64()?, r.f64()?])
}

fn quaternion(r: &mut CdrReader<'_>) -> Result<[f64; 4], CdrError> {
    Ok([r.f64()?, r.f64()?, r.f64()?, r.f64()?])
}

fn rgba(r: &mut CdrReader<'_>) -> Result<[f32; 4], CdrError> {
    Ok([r.f32()?, r.f32()?, r.f32()?, r.f32()?])
}

impl Marker {
    /// Writes the marker (a sequence element).
    fn encode_fields(&self, w: &mut CdrWriter<'_>) -> Result<(), CdrError> {
        header(w, self.stamp_ns, &self.frame_id)?;
        w.string(&self.ns);
        w.i32(self.id);
        w.i32(self.kind);
        w.i32(self.action);
        w.f64_array(&self.position_m);
        w.f64_array(&self.orientation);
        w.f64_array(&self.scale_m);
        for c in self.color {
            w.f32(c);
        }
        // lifetime 0: until replaced; frame_locked false.
        w.i32(0);
        w.u32(0);
        w.bool(false);
        w.seq_len(self.points_m.len());
        for p in &self.points_m {
            w.f64_array(p);
        }
        // colors, texture_resource, texture (header, format, data),
        // uv_coordinates: empty.
        w.seq_len(0);
        w.string("");
        header(w, 0, "")?;
        w.string("");
        w.seq_len(0);
        w.seq_len(0);
        w.string(&self.text);
        // mesh_resource, mesh_file (filename, data), embedded materials.
        w.string("");
        w.string("");
        w.seq_len(0);
        w.bool(false);
        Ok(())
    }

    /// Reads one marker (the fields it does not keep are checked and
    /// skipped).
    fn decode_fields(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        let stamp_ns = r.time()?;
        let frame_id = text(r)?;
        let ns = text(r)?;
        let (id, kind, action) = (r.i32()?, r.i32()?, r.i32()?);
        let position_m = vec3(r)?;
        let orientation = quaternion(r)?;
        let scale_m = vec3(r)?;
        let color = rgba(r)?;
        let (_lifetime_s, _lifetime_ns, _locked) = (r.i32()?, r.u32()?, r.bool()?);
        let n = r.seq_len(MAX_POINTS, 24)?;
        let points_m = (0..n).map(|_| vec3(r)).collect::<Result<Vec<_>, _>>()?;
        let colors = r.seq_len(MAX_POINTS, 16)?;
        for _ in 0..colors {
            rgba(r)?;
        }
        let _texture_resource = r.str()?;
        let (_stamp, _frame, _format) = (r.time()?, r.str()?, r.str()?);
        r.byte_seq(usize::MAX)?;
        let uv = r.seq_len(MAX_POINTS, 8)?;
        for _ in 0..uv {
            let (_u, _v) = (r.f32()?, r.f32()?);
        }
        let text = text(r)?;
        let (_mesh_resource, _filename) = (r.str()?, r.str()?);
        r.byte_seq(usize::MAX)?;
        let _embedded = r.bool()?;
        Ok(Self {
            stamp_ns,
            frame_id,
            ns,
            id,
            kind,
            action,
            position_m,
            orientation,
            scale_m,
            color,
            points_m,
            text,
        })
    }
}

impl MarkerArray {
    /// The ROS 2 type.
    pub const TYPE_NAME: &'static str = "visualization_msgs/msg/MarkerArray";
    /// The `ros2msg` schema (ROS 2 Jazzy).
    pub const SCHEMA: &'static str = concat!(
        "visualization_msgs/Marker[] markers\n",
        sep!(),
        "MSG: visualization_msgs/Marker\n",
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
        "int32 ARROW_STRIP=12\n",
        "int32 ADD=0\n",
        "int32 MODIFY=0\n",
        "int32 DELETE=2\n",
        "int32 DELETEALL=3\n",
        "std_msgs/Header header\n",
        "string ns\n",
        "int32 id\n",
        "int32 type\n",
        "int32 action\n",
        "geometry_msgs/Pose pose\n",
        "geometry_msgs/Vector3 scale\n",
        "std_msgs/ColorRGBA color\n",
        "builtin_interfaces/Duration lifetime\n",
        "bool frame_locked\n",
        "geometry_msgs/Point[] points\n",
        "std_msgs/ColorRGBA[] colors\n",
        "string texture_resource\n",
        "sensor_msgs/CompressedImage texture\n",
        "visualization_msgs/UVCoordinate[] uv_coordinates\n",
        "string text\n",
        "string mesh_resource\n",
        "visualization_msgs/MeshFile mesh_file\n",
        "bool mesh_use_embedded_materials\n",
        common_sections!(),
        sep!(),
        "MSG: geometry_msgs/Pose\n",
        "geometry_msgs/Point position\n",
        "geometry_msgs/Quaternion orientation\n",
        sep!(),
        "MSG: geometry_msgs/Point\n",
        "float64 x\n",
        "float64 y\n",
        "float64 z\n",
        sep!(),
        "MSG: std_msgs/ColorRGBA\n",
        "float32 r\n",
        "float32 g\n",
        "float32 b\n",
        "float32 a\n",
        sep!(),
        "MSG: builtin_interfaces/Duration\n",
        "int32 sec\n",
        "uint32 nanosec\n",
        sep!(),
        "MSG: sensor_msgs/CompressedImage\n",
        "std_msgs/Header header\n",
        "string format\n",
        "uint8[] data\n",
        sep!(),
        "MSG: visualization_msgs/UVCoordinate\n",
        "float32 u\n",
        "float32 v\n",
        sep!(),
        "MSG: visualization_msgs/MeshFile\n",
        "string filename\n",
        "uint8[] data\n",
    );

    /// Encodes into `buf` (cleared first).
    pub fn encode(&self, buf: &mut Vec<u8>) -> Result<(), CdrError> {
        let mut w = CdrWriter::new(buf);
        w.seq_len(self.markers.len());
        for m in &self.markers {
            m.encode_fields(&mut w)?;
        }
        Ok(())
    }

    /// Decodes one message.
    pub fn decode(bytes: &[u8]) -> Result<Self, CdrError> {
        let mut r = CdrReader::new(bytes)?;
        let n = r.seq_len(MAX_MARKERS, 100)?;
        let markers = (0..n)
            .map(|_| Marker::decode_fields(&mut r))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self { markers })
    }
}

impl TfMessage {
    /// The ROS 2 type.
    pub const TYPE_NAME: &'static str = "tf2_msgs/msg/TFMessage";
    /// The `ros2msg` schema (ROS 2 Jazzy).
    pub const SCHEMA: &'static str = concat!(
        "geometry_msgs/TransformStamped[] transforms\n",
        sep!(),
        "MSG: geometry_msgs/TransformStamped\n",
        "std_msgs/Header header\n",
        "string child_frame_id\n",
        "geometry_msgs/Transform transform\n",
        sep!(),
        "MSG: geometry_msgs/Transform\n",
        "geometry_msgs/Vector3 translation\n",
        "geometry_msgs/Quaternion rotation\n",
        common_sections!(),
    );

    /// Encodes into `buf` (cleared first).
    pub fn encode(&self, buf: &mut Vec<u8>) -> Result<(), CdrError> {
        let mut w = CdrWriter::new(buf);
        w.seq_len(self.transforms.len());
        for t in &self.transforms {
            header(&mut w, t.stamp_ns, &t.parent)?;
            w.string(&t.child);
            w.f64_array(&t.translation_m);
            w.f64_array(&t.rotation);
        }
        Ok(())
    }

    /// Decodes one message.
    pub fn decode(bytes: &[u8]) -> Result<Self, CdrError> {
        let mut r = CdrReader::new(bytes)?;
        let n = r.seq_len(MAX_TRANSFORMS, 72)?;
        let mut transforms = Vec::with_capacity(n);
        for _ in 0..n {
            let stamp_ns = r.time()?;
            let parent = text(&mut r)?;
            let child = text(&mut r)?;
            let translation_m = vec3(&mut r)?;
            let rotation = quaternion(&mut r)?;
            transforms.push(TransformStamped {
                stamp_ns,
                parent,
                child,
                translation_m,
                rotation,
            });
        }
        Ok(Self { transforms })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn marker() -> Marker {
        Marker {
            stamp_ns: 1_500_000_123,
            frame_id: "base".into(),
            ns: "rod".into(),
            id: 3,
            kind: kind::ARROW,
            action: action::ADD,
            position_m: [0.1, -0.2, 0.3],
            orientation: [0.0, 0.5f64.sqrt(), 0.0, 0.5f64.sqrt()],
            scale_m: [0.005, 0.0125, 0.02],
            color: [0.1, 0.75, 0.2, 1.0],
            points_m: vec![[0.45, 0.2, 0.0], [0.5, 0.2, 0.01]],
            text: "|F| 3.00 N".into(),
        }
    }

    #[test]
    fn a_marker_array_and_a_tf_message_come_back_as_written() {
        let array = MarkerArray {
            markers: vec![
                marker(),
                Marker {
                    action: action::DELETE,
                    points_m: Vec::new(),
                    text: String::new(),
                    ..marker()
                },
            ],
        };
        let mut buf = Vec::new();
        array.encode(&mut buf).unwrap();
        assert_eq!(MarkerArray::decode(&buf).unwrap(), array);
        let tf = TfMessage {
            transforms: vec![TransformStamped {
                stamp_ns: 7,
                parent: "world".into(),
                child: "base".into(),
                translation_m: [1.0, 2.0, 3.0],
                rotation: [0.5f64.sqrt(), 0.0, 0.0, 0.5f64.sqrt()],
            }],
        };
        tf.encode(&mut buf).unwrap();
        assert_eq!(TfMessage::decode(&buf).unwrap(), tf);
        // Cut short anywhere: an error, never a panic.
        array.encode(&mut buf).unwrap();
        for len in 0..buf.len() {
            assert!(
                MarkerArray::decode(buf.get(..len).unwrap()).is_err(),
                "{len}"
            );
        }
    }
}
