//! # xsurf-msgs
//!
//! The ROS 2 message types xsurf exchanges, as serde structs laid out exactly like their `.msg`
//! definitions, so that one struct serves DDS (through `ros2-client`, feature `dds`) and rosbag2
//! MCAP files byte for byte. Each type knows its ROS 2 name and its full `.msg` definition in the
//! rosbag2/MCAP `ros2msg` layout ([`RosMessage::definition`]), so bags are written without a ROS
//! install.
//!
//! ```
//! use xsurf_msgs::{cdr, std_msgs::Header, builtin_interfaces::Time, RosMessage};
//! let h = Header { stamp: Time { sec: 1, nanosec: 2 }, frame_id: "table".into() };
//! let bytes = cdr::encode(&h).unwrap();
//! assert_eq!(&bytes[..4], &[0, 1, 0, 0]);
//! assert_eq!(cdr::decode::<Header>(&bytes).unwrap(), h);
//! assert_eq!(Header::TYPE_NAME, "std_msgs/msg/Header");
//! ```
#![deny(missing_docs)]

mod definitions;
pub mod pointcloud;

use serde::{de::DeserializeOwned, Deserialize, Serialize};

/// A ROS 2 message type: its name and `.msg` definition.
pub trait RosMessage: Serialize + DeserializeOwned {
    /// The ROS 2 type name, `pkg/msg/Type`.
    const TYPE_NAME: &'static str;
    /// The definition with its dependency closure, as rosbag2 stores it in MCAP schemas.
    fn definition() -> String {
        definition_of(Self::TYPE_NAME).unwrap_or_default()
    }
}

/// The `ros2msg` schema text of a type: its own `.msg` text, then every type it depends on
/// (depth first, each once) after a line of 80 `=` and `MSG: pkg/Type`. `None` for a type we
/// do not know.
pub fn definition_of(type_name: &str) -> Option<String> {
    let find = |n: &str| definitions::DEFINITIONS.iter().find(|d| d.0 == n);
    let top = find(type_name)?;
    let mut out = top.1.to_string();
    let mut seen: Vec<&str> = vec![top.0];
    let mut stack: Vec<&str> = top.2.iter().rev().copied().collect();
    while let Some(dep) = stack.pop() {
        if seen.contains(&dep) {
            continue;
        }
        seen.push(dep);
        let d = find(dep)?;
        let short = dep.replacen("/msg/", "/", 1);
        out.push_str(&"=".repeat(80));
        out.push_str(&format!("\nMSG: {short}\n"));
        out.push_str(d.1);
        stack.extend(d.2.iter().rev().copied());
    }
    Some(out)
}

/// Every type name this crate defines.
pub fn known_types() -> impl Iterator<Item = &'static str> {
    definitions::DEFINITIONS.iter().map(|d| d.0)
}

/// CDR (de)serialisation with the 4-byte encapsulation header, as DDS and rosbag2 carry it.
pub mod cdr {
    use serde::{de::DeserializeOwned, Serialize};

    /// Why bytes could not be turned into a message (or back).
    #[derive(Debug, thiserror::Error)]
    pub enum CdrError {
        /// Fewer than 4 bytes: no encapsulation header.
        #[error("CDR payload of {0} bytes has no 4-byte encapsulation header")]
        TooShort(usize),
        /// Encapsulation kind other than CDR_LE / CDR_BE.
        #[error("unsupported CDR encapsulation {0:02x}{1:02x} (expected 0001 CDR_LE or 0000 CDR_BE)")]
        Encapsulation(u8, u8),
        /// The body does not decode as the type.
        #[error("CDR body does not decode: {0}")]
        Decode(String),
        /// The value does not encode.
        #[error("CDR encoding failed: {0}")]
        Encode(String),
    }

    /// Little-endian CDR with the header `00 01 00 00`.
    pub fn encode<T: Serialize>(value: &T) -> Result<Vec<u8>, CdrError> {
        let mut out = vec![0u8, 1, 0, 0];
        cdr_encoding::to_writer::<T, byteorder_le::Le, _>(&mut out, value)
            .map_err(|e| CdrError::Encode(e.to_string()))?;
        Ok(out)
    }

    /// Decodes a payload with its encapsulation header (little- or big-endian CDR).
    pub fn decode<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, CdrError> {
        if bytes.len() < 4 {
            return Err(CdrError::TooShort(bytes.len()));
        }
        let body = &bytes[4..];
        let r = match (bytes[0], bytes[1]) {
            (0, 1) => cdr_encoding::from_bytes::<T, byteorder_le::Le>(body),
            (0, 0) => cdr_encoding::from_bytes::<T, byteorder_le::Be>(body),
            (a, b) => return Err(CdrError::Encapsulation(a, b)),
        };
        r.map(|(v, _)| v).map_err(|e| CdrError::Decode(e.to_string()))
    }

    mod byteorder_le {
        pub type Le = byteorder::LittleEndian;
        pub type Be = byteorder::BigEndian;
    }
}

macro_rules! ros_type {
    ($t:ty, $name:literal) => {
        impl RosMessage for $t {
            const TYPE_NAME: &'static str = $name;
        }
        #[cfg(feature = "dds")]
        impl ros2_client::Message for $t {}
    };
}

/// `builtin_interfaces`.
pub mod builtin_interfaces {
    use super::*;
    /// `builtin_interfaces/msg/Time`.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, PartialOrd, Ord)]
    pub struct Time {
        /// Seconds.
        pub sec: i32,
        /// Nanoseconds, 0..1e9.
        pub nanosec: u32,
    }
    impl Time {
        /// From nanoseconds since the epoch.
        pub fn from_nanos(ns: i64) -> Time {
            Time { sec: ns.div_euclid(1_000_000_000) as i32, nanosec: ns.rem_euclid(1_000_000_000) as u32 }
        }
        /// Nanoseconds since the epoch.
        pub fn nanos(&self) -> i64 {
            i64::from(self.sec) * 1_000_000_000 + i64::from(self.nanosec)
        }
    }
    /// `builtin_interfaces/msg/Duration`.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
    pub struct Duration {
        /// Seconds.
        pub sec: i32,
        /// Nanoseconds, 0..1e9.
        pub nanosec: u32,
    }
    ros_type!(Time, "builtin_interfaces/msg/Time");
    ros_type!(Duration, "builtin_interfaces/msg/Duration");
}

/// `std_msgs`.
pub mod std_msgs {
    use super::builtin_interfaces::Time;
    use super::*;
    /// `std_msgs/msg/Header`.
    #[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
    pub struct Header {
        /// Stamp.
        pub stamp: Time,
        /// Frame id.
        pub frame_id: String,
    }
    /// `std_msgs/msg/ColorRGBA`.
    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
    pub struct ColorRGBA {
        /// Red 0..1.
        pub r: f32,
        /// Green 0..1.
        pub g: f32,
        /// Blue 0..1.
        pub b: f32,
        /// Alpha 0..1.
        pub a: f32,
    }
    /// `std_msgs/msg/String`.
    #[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
    pub struct StringMsg {
        /// Text.
        pub data: String,
    }
    /// `std_msgs/msg/Float64`.
    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
    pub struct Float64 {
        /// Value.
        pub data: f64,
    }
    ros_type!(Header, "std_msgs/msg/Header");
    ros_type!(ColorRGBA, "std_msgs/msg/ColorRGBA");
    ros_type!(StringMsg, "std_msgs/msg/String");
    ros_type!(Float64, "std_msgs/msg/Float64");
}

/// `rosgraph_msgs`.
pub mod rosgraph_msgs {
    use super::builtin_interfaces::Time;
    use super::*;
    /// `rosgraph_msgs/msg/Clock`: what ROS 2 publishes on `/clock`.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
    pub struct Clock {
        /// Simulated time.
        pub clock: Time,
    }
    ros_type!(Clock, "rosgraph_msgs/msg/Clock");
}

/// `geometry_msgs`.
pub mod geometry_msgs {
    use super::std_msgs::Header;
    use super::*;
    /// `geometry_msgs/msg/Vector3`.
    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
    pub struct Vector3 {
        /// X.
        pub x: f64,
        /// Y.
        pub y: f64,
        /// Z.
        pub z: f64,
    }
    /// `geometry_msgs/msg/Point`.
    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
    pub struct Point {
        /// X.
        pub x: f64,
        /// Y.
        pub y: f64,
        /// Z.
        pub z: f64,
    }
    /// `geometry_msgs/msg/Quaternion`.
    #[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
    pub struct Quaternion {
        /// X.
        pub x: f64,
        /// Y.
        pub y: f64,
        /// Z.
        pub z: f64,
        /// W.
        pub w: f64,
    }
    impl Default for Quaternion {
        fn default() -> Self {
            Self { x: 0.0, y: 0.0, z: 0.0, w: 1.0 }
        }
    }
    /// `geometry_msgs/msg/Pose`.
    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
    pub struct Pose {
        /// Position.
        pub position: Point,
        /// Orientation.
        pub orientation: Quaternion,
    }
    /// `geometry_msgs/msg/Transform`.
    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
    pub struct Transform {
        /// Translation.
        pub translation: Vector3,
        /// Rotation.
        pub rotation: Quaternion,
    }
    /// `geometry_msgs/msg/TransformStamped`: `header.frame_id -> child_frame_id`.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct TransformStamped {
        /// Stamp and parent frame.
        pub header: Header,
        /// Child frame.
        pub child_frame_id: String,
        /// Pose of the child in the parent.
        pub transform: Transform,
    }
    ros_type!(Vector3, "geometry_msgs/msg/Vector3");
    ros_type!(Point, "geometry_msgs/msg/Point");
    ros_type!(Quaternion, "geometry_msgs/msg/Quaternion");
    ros_type!(Pose, "geometry_msgs/msg/Pose");
    ros_type!(Transform, "geometry_msgs/msg/Transform");
    ros_type!(TransformStamped, "geometry_msgs/msg/TransformStamped");
}

/// `tf2_msgs`.
pub mod tf2_msgs {
    use super::geometry_msgs::TransformStamped;
    use super::*;
    /// `tf2_msgs/msg/TFMessage`.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct TFMessage {
        /// Transforms.
        pub transforms: Vec<TransformStamped>,
    }
    ros_type!(TFMessage, "tf2_msgs/msg/TFMessage");
}

/// `sensor_msgs`.
pub mod sensor_msgs {
    use super::std_msgs::Header;
    use super::*;
    /// `sensor_msgs/msg/Image`.
    #[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
    pub struct Image {
        /// Stamp (exposure time) and optical frame.
        pub header: Header,
        /// Rows.
        pub height: u32,
        /// Columns.
        pub width: u32,
        /// Encoding (`mono8`, `rgb8`, ...).
        pub encoding: String,
        /// 1 if 16-bit samples are big-endian.
        pub is_bigendian: u8,
        /// Bytes per row.
        pub step: u32,
        /// Pixels.
        #[serde(with = "serde_bytes")]
        pub data: Vec<u8>,
    }
    /// `sensor_msgs/msg/CompressedImage`.
    #[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
    pub struct CompressedImage {
        /// Stamp and frame.
        pub header: Header,
        /// `png`, `jpeg`, ...
        pub format: String,
        /// Compressed bytes.
        #[serde(with = "serde_bytes")]
        pub data: Vec<u8>,
    }
    /// `sensor_msgs/msg/RegionOfInterest`.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
    pub struct RegionOfInterest {
        /// First column.
        pub x_offset: u32,
        /// First row.
        pub y_offset: u32,
        /// Rows.
        pub height: u32,
        /// Columns.
        pub width: u32,
        /// Rectify the region.
        pub do_rectify: bool,
    }
    /// `sensor_msgs/msg/CameraInfo`.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct CameraInfo {
        /// Stamp (same as the image) and optical frame.
        pub header: Header,
        /// Rows.
        pub height: u32,
        /// Columns.
        pub width: u32,
        /// `plumb_bob` or `rational_polynomial`.
        pub distortion_model: String,
        /// Distortion coefficients.
        pub d: Vec<f64>,
        /// Camera matrix, row-major.
        pub k: [f64; 9],
        /// Rectification rotation, row-major.
        pub r: [f64; 9],
        /// Projection matrix, row-major.
        pub p: [f64; 12],
        /// Horizontal binning.
        pub binning_x: u32,
        /// Vertical binning.
        pub binning_y: u32,
        /// Region of interest.
        pub roi: RegionOfInterest,
    }
    /// `sensor_msgs/msg/PointField`.
    #[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
    pub struct PointField {
        /// Field name.
        pub name: String,
        /// Byte offset in a point.
        pub offset: u32,
        /// Datatype (7 = FLOAT32).
        pub datatype: u8,
        /// Elements.
        pub count: u32,
    }
    impl PointField {
        /// `FLOAT32` datatype.
        pub const FLOAT32: u8 = 7;
        /// `FLOAT64` datatype.
        pub const FLOAT64: u8 = 8;
        /// `UINT32` datatype.
        pub const UINT32: u8 = 6;
    }
    /// `sensor_msgs/msg/PointCloud2`.
    #[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
    pub struct PointCloud2 {
        /// Stamp and frame.
        pub header: Header,
        /// Rows (1 for unorganized clouds).
        pub height: u32,
        /// Columns.
        pub width: u32,
        /// Fields of a point.
        pub fields: Vec<PointField>,
        /// Byte order of the data.
        pub is_bigendian: bool,
        /// Bytes per point.
        pub point_step: u32,
        /// Bytes per row.
        pub row_step: u32,
        /// Points.
        #[serde(with = "serde_bytes")]
        pub data: Vec<u8>,
        /// True if no point is invalid (NaN).
        pub is_dense: bool,
    }
    /// `sensor_msgs/msg/JointState`.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct JointState {
        /// Stamp.
        pub header: Header,
        /// Joint names.
        pub name: Vec<String>,
        /// Positions (m or rad).
        pub position: Vec<f64>,
        /// Velocities.
        pub velocity: Vec<f64>,
        /// Efforts.
        pub effort: Vec<f64>,
    }
    ros_type!(Image, "sensor_msgs/msg/Image");
    ros_type!(CompressedImage, "sensor_msgs/msg/CompressedImage");
    ros_type!(RegionOfInterest, "sensor_msgs/msg/RegionOfInterest");
    ros_type!(CameraInfo, "sensor_msgs/msg/CameraInfo");
    ros_type!(PointField, "sensor_msgs/msg/PointField");
    ros_type!(PointCloud2, "sensor_msgs/msg/PointCloud2");
    ros_type!(JointState, "sensor_msgs/msg/JointState");
}

/// `shape_msgs`.
pub mod shape_msgs {
    use super::geometry_msgs::Point;
    use super::*;
    /// `shape_msgs/msg/MeshTriangle`.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
    pub struct MeshTriangle {
        /// Vertex indices.
        pub vertex_indices: [u32; 3],
    }
    /// `shape_msgs/msg/Mesh`.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct Mesh {
        /// Triangles.
        pub triangles: Vec<MeshTriangle>,
        /// Vertices.
        pub vertices: Vec<Point>,
    }
    ros_type!(MeshTriangle, "shape_msgs/msg/MeshTriangle");
    ros_type!(Mesh, "shape_msgs/msg/Mesh");
}

/// `visualization_msgs` (the Humble/Jazzy layout, with texture and mesh_file fields).
pub mod visualization_msgs {
    use super::builtin_interfaces::Duration;
    use super::geometry_msgs::{Point, Pose, Vector3};
    use super::sensor_msgs::CompressedImage;
    use super::std_msgs::{ColorRGBA, Header};
    use super::*;
    /// `visualization_msgs/msg/UVCoordinate`.
    #[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
    pub struct UVCoordinate {
        /// U.
        pub u: f32,
        /// V.
        pub v: f32,
    }
    /// `visualization_msgs/msg/MeshFile`.
    #[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
    pub struct MeshFile {
        /// File name.
        pub filename: String,
        /// File contents.
        #[serde(with = "serde_bytes")]
        pub data: Vec<u8>,
    }
    /// `visualization_msgs/msg/Marker`.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct Marker {
        /// Stamp and frame.
        pub header: Header,
        /// Namespace.
        pub ns: String,
        /// Id within the namespace.
        pub id: i32,
        /// Marker type (`TRIANGLE_LIST` = 11, ...).
        #[serde(rename = "type")]
        pub type_: i32,
        /// `ADD` = 0, `DELETE` = 2, `DELETEALL` = 3.
        pub action: i32,
        /// Pose of the marker frame.
        pub pose: Pose,
        /// Scale.
        pub scale: Vector3,
        /// Colour (used when `colors` is empty).
        pub color: ColorRGBA,
        /// Lifetime (0: forever).
        pub lifetime: Duration,
        /// Re-transform every frame.
        pub frame_locked: bool,
        /// Points (3 per triangle for `TRIANGLE_LIST`).
        pub points: Vec<Point>,
        /// Per-point colours.
        pub colors: Vec<ColorRGBA>,
        /// Texture resource URI.
        pub texture_resource: String,
        /// Embedded texture.
        pub texture: CompressedImage,
        /// Texture coordinates per point.
        pub uv_coordinates: Vec<UVCoordinate>,
        /// Text.
        pub text: String,
        /// Mesh resource URI.
        pub mesh_resource: String,
        /// Embedded mesh file.
        pub mesh_file: MeshFile,
        /// Use the mesh's own materials.
        pub mesh_use_embedded_materials: bool,
    }
    impl Marker {
        /// `type`: a list of triangles, three points each.
        pub const TRIANGLE_LIST: i32 = 11;
        /// `type`: a list of points.
        pub const POINTS: i32 = 8;
        /// `action`: add or modify.
        pub const ADD: i32 = 0;
        /// `action`: delete this marker.
        pub const DELETE: i32 = 2;
        /// `action`: delete every marker (of the display the topic feeds).
        pub const DELETEALL: i32 = 3;
    }
    /// `visualization_msgs/msg/MarkerArray`.
    #[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
    pub struct MarkerArray {
        /// Markers.
        pub markers: Vec<Marker>,
    }
    ros_type!(UVCoordinate, "visualization_msgs/msg/UVCoordinate");
    ros_type!(MeshFile, "visualization_msgs/msg/MeshFile");
    ros_type!(Marker, "visualization_msgs/msg/Marker");
    ros_type!(MarkerArray, "visualization_msgs/msg/MarkerArray");
}

/// `xsurf_msgs`: the messages of our own (ROS package in `msgs/ros/xsurf_msgs`).
pub mod xsurf_msgs {
    use super::std_msgs::Header;
    use super::*;
    /// `xsurf_msgs/msg/LaserLine`: the laser line found in one camera image; with several
    /// lasers, each laser's line, one block of samples per laser in the order of `lasers`.
    #[derive(Debug, Clone, PartialEq, Default, Serialize)]
    pub struct LaserLine {
        /// Stamp and frame of the source image.
        pub header: Header,
        /// Source image width.
        pub image_width: u32,
        /// Source image height.
        pub image_height: u32,
        /// `ORIENTATION_VERTICAL` (one sample per row) or `ORIENTATION_HORIZONTAL`.
        pub orientation: u8,
        /// Sub-pixel column of the line centre, NaN where none.
        pub u: Vec<f32>,
        /// Sub-pixel row of the line centre, NaN where none.
        pub v: Vec<f32>,
        /// Peak height above the local background, grey levels; 0 where none.
        pub strength: Vec<f32>,
        /// Full width at half maximum, pixels; 0 where none.
        pub width: Vec<f32>,
        /// Colour beside the line, 3 bytes a sample; empty for grey images.
        #[serde(with = "serde_bytes")]
        pub rgb: Vec<u8>,
        /// The lasers whose lines these are, one block of samples each (samples
        /// `k * n .. (k + 1) * n` are laser `lasers[k]`'s, `n` one per row or column); empty:
        /// one laser, the single `laser_plane` (and every message written before this field).
        pub lasers: Vec<String>,
        /// Lines per laser: 2 where the detector keeps a second surface's line (a row where
        /// the line crosses two surfaces, as where an object hides part of the table): the
        /// blocks of samples are layer-major, every laser's first line in the order of
        /// `lasers`, then every laser's second line (NaN where a row has one surface). 0 or
        /// 1: one line per laser (0: every message written before this field).
        pub layers: u8,
    }

    /// The fields of a `LaserLine` before `lasers` (what older bags and peers send).
    #[derive(Deserialize)]
    struct LaserLineFields {
        header: Header,
        image_width: u32,
        image_height: u32,
        orientation: u8,
        u: Vec<f32>,
        v: Vec<f32>,
        strength: Vec<f32>,
        width: Vec<f32>,
        #[serde(with = "serde_bytes")]
        rgb: Vec<u8>,
    }

    /// Every field, `lasers` and `layers` defaulted: a `LaserLine` from a self-describing
    /// format (JSON).
    #[derive(Deserialize)]
    struct LaserLineAll {
        #[serde(flatten)]
        f: LaserLineFields,
        #[serde(default)]
        lasers: Vec<String>,
        #[serde(default)]
        layers: u8,
    }

    impl LaserLineFields {
        fn with(self, lasers: Vec<String>, layers: u8) -> LaserLine {
            let f = self;
            LaserLine {
                header: f.header,
                image_width: f.image_width,
                image_height: f.image_height,
                orientation: f.orientation,
                u: f.u,
                v: f.v,
                strength: f.strength,
                width: f.width,
                rgb: f.rgb,
                lasers,
                layers,
            }
        }
    }

    /// A `LaserLine` whose payload ends before `lasers` or `layers` (a message written before
    /// the field existed) reads as one laser, one line; CDR lays a nested struct out inline,
    /// so the older fields are read as one.
    impl<'de> Deserialize<'de> for LaserLine {
        fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
            struct V;
            impl<'de> serde::de::Visitor<'de> for V {
                type Value = LaserLine;
                fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                    f.write_str("xsurf_msgs/msg/LaserLine")
                }
                fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<LaserLine, A::Error> {
                    let f: LaserLineFields =
                        seq.next_element()?.ok_or_else(|| serde::de::Error::invalid_length(0, &self))?;
                    // The payload's end before `lasers` or `layers`: an older message, one
                    // laser, one line.
                    let lasers = seq.next_element::<Vec<String>>().ok().flatten().unwrap_or_default();
                    let layers = seq.next_element::<u8>().ok().flatten().unwrap_or_default();
                    Ok(f.with(lasers, layers))
                }
                fn visit_map<A: serde::de::MapAccess<'de>>(self, map: A) -> Result<LaserLine, A::Error> {
                    let a = LaserLineAll::deserialize(serde::de::value::MapAccessDeserializer::new(map))?;
                    Ok(a.f.with(a.lasers, a.layers))
                }
            }
            d.deserialize_struct("LaserLine", &["fields", "lasers", "layers"], V)
        }
    }
    impl LaserLine {
        /// Lines per laser (`layers`, at least 1).
        pub fn layer_count(&self) -> usize {
            usize::from(self.layers.max(1))
        }
        /// One sample per image row.
        pub const ORIENTATION_VERTICAL: u8 = 0;
        /// One sample per image column.
        pub const ORIENTATION_HORIZONTAL: u8 = 1;
    }
    /// `xsurf_msgs/msg/ScanEvent`.
    #[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
    pub struct ScanEvent {
        /// Stamp of the event.
        pub header: Header,
        /// Scan number.
        pub scan_id: u32,
        /// `START`, `END` or `ABORT`.
        pub event: u8,
    }
    impl ScanEvent {
        /// A scan begins.
        pub const START: u8 = 0;
        /// A scan ended normally.
        pub const END: u8 = 1;
        /// A scan was abandoned.
        pub const ABORT: u8 = 2;
    }
    ros_type!(LaserLine, "xsurf_msgs/msg/LaserLine");
    ros_type!(ScanEvent, "xsurf_msgs/msg/ScanEvent");
}

/// `rcl_interfaces/msg/Log` (what `/rosout` carries).
pub mod rcl_interfaces {
    use super::builtin_interfaces::Time;
    use super::*;
    /// `rcl_interfaces/msg/Log`.
    #[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
    pub struct Log {
        /// Time of the log call.
        pub stamp: Time,
        /// Severity (10 debug, 20 info, 30 warn, 40 error, 50 fatal).
        pub level: u8,
        /// Logger name.
        pub name: String,
        /// Message.
        pub msg: String,
        /// Source file.
        pub file: String,
        /// Function.
        pub function: String,
        /// Line.
        pub line: u32,
    }
    ros_type!(Log, "rcl_interfaces/msg/Log");
}
