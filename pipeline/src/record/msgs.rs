//! The ROS 2 messages we record, as plain Rust structs with their CDR encoding.
//!
//! Field names and order mirror the ROS 2 `.msg` definitions in [`super::schema`]; a test
//! decodes every one of them with `mcap-ros2-support` and with `rosbags` (tests/record_peers.rs).

use super::cdr::{check_len, CdrReader, CdrWriter};
use crate::PipelineError;

/// A type that has a CDR encoding.
pub trait Cdr: Sized {
    fn encode(&self, w: &mut CdrWriter);
    fn decode(r: &mut CdrReader<'_>) -> Result<Self, PipelineError>;
}

/// A top-level ROS 2 message: a topic carries one of these.
pub trait RosMessage: Cdr {
    /// `pkg/msg/Type`, as ROS 2 names it in bags and on the wire.
    const TYPE_NAME: &'static str;

    /// The whole payload, encapsulation header included.
    fn to_cdr(&self) -> Vec<u8> {
        let mut w = CdrWriter::new();
        self.encode(&mut w);
        w.into_bytes()
    }

    /// Decodes a payload. Trailing bytes are allowed (some writers pad to 4 or 8 bytes).
    fn from_cdr(payload: &[u8]) -> Result<Self, PipelineError> {
        let mut r = CdrReader::new(payload, Self::TYPE_NAME)?;
        Self::decode(&mut r)
    }
}

pub(crate) fn seq<T: Cdr>(w: &mut CdrWriter, items: &[T]) {
    w.len(items.len());
    for i in items {
        i.encode(w);
    }
}

/// `min_bytes`: the smallest encoding of one `T`, which bounds the count a payload can hold.
pub(crate) fn read_seq<T: Cdr>(r: &mut CdrReader<'_>, what: &str, min_bytes: usize) -> Result<Vec<T>, PipelineError> {
    let n = r.seq_len(what, min_bytes)?;
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        out.push(T::decode(r)?);
    }
    Ok(out)
}

/// `builtin_interfaces/Time` (and `Duration`, which has the same layout).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    /// Splits nanoseconds since the epoch; `None` past 2038-01-19 (ROS 2 keeps `sec` in an i32).
    pub fn from_ns(ns: u64) -> Option<Self> {
        let sec = i32::try_from(ns / 1_000_000_000).ok()?;
        Some(Self { sec, nanosec: (ns % 1_000_000_000) as u32 })
    }

    /// Nanoseconds since the epoch; `None` for negative times.
    pub fn to_ns(self) -> Option<u64> {
        let sec = u64::try_from(self.sec).ok()?;
        Some(sec * 1_000_000_000 + u64::from(self.nanosec))
    }
}

impl Cdr for Time {
    fn encode(&self, w: &mut CdrWriter) {
        w.i32(self.sec);
        w.u32(self.nanosec);
    }
    fn decode(r: &mut CdrReader<'_>) -> Result<Self, PipelineError> {
        Ok(Self { sec: r.i32("sec")?, nanosec: r.u32("nanosec")? })
    }
}

/// `std_msgs/Header`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

impl Cdr for Header {
    fn encode(&self, w: &mut CdrWriter) {
        self.stamp.encode(w);
        w.string(&self.frame_id);
    }
    fn decode(r: &mut CdrReader<'_>) -> Result<Self, PipelineError> {
        Ok(Self { stamp: Time::decode(r)?, frame_id: r.string("frame_id")? })
    }
}

/// `geometry_msgs/Vector3` and `geometry_msgs/Point` (same layout).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

impl Vector3 {
    pub const fn new(x: f64, y: f64, z: f64) -> Self {
        Self { x, y, z }
    }
}

impl Cdr for Vector3 {
    fn encode(&self, w: &mut CdrWriter) {
        w.f64(self.x);
        w.f64(self.y);
        w.f64(self.z);
    }
    fn decode(r: &mut CdrReader<'_>) -> Result<Self, PipelineError> {
        Ok(Self { x: r.f64("x")?, y: r.f64("y")?, z: r.f64("z")? })
    }
}

/// `geometry_msgs/Quaternion`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Quaternion {
    pub const IDENTITY: Self = Self { x: 0.0, y: 0.0, z: 0.0, w: 1.0 };
}

impl Cdr for Quaternion {
    fn encode(&self, w: &mut CdrWriter) {
        w.f64(self.x);
        w.f64(self.y);
        w.f64(self.z);
        w.f64(self.w);
    }
    fn decode(r: &mut CdrReader<'_>) -> Result<Self, PipelineError> {
        Ok(Self { x: r.f64("x")?, y: r.f64("y")?, z: r.f64("z")?, w: r.f64("w")? })
    }
}

/// `geometry_msgs/Pose` (also the layout of `geometry_msgs/Transform`: translation, rotation).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Pose {
    pub position: Vector3,
    pub orientation: Quaternion,
}

impl Cdr for Pose {
    fn encode(&self, w: &mut CdrWriter) {
        self.position.encode(w);
        self.orientation.encode(w);
    }
    fn decode(r: &mut CdrReader<'_>) -> Result<Self, PipelineError> {
        Ok(Self { position: Vector3::decode(r)?, orientation: Quaternion::decode(r)? })
    }
}

/// `geometry_msgs/Twist`: linear (m/s) and angular (rad/s) velocity, as `/cmd_vel` carries it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Twist {
    pub linear: Vector3,
    pub angular: Vector3,
}

impl Cdr for Twist {
    fn encode(&self, w: &mut CdrWriter) {
        self.linear.encode(w);
        self.angular.encode(w);
    }
    fn decode(r: &mut CdrReader<'_>) -> Result<Self, PipelineError> {
        Ok(Self { linear: Vector3::decode(r)?, angular: Vector3::decode(r)? })
    }
}

impl RosMessage for Twist {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/Twist";
}

/// `sensor_msgs/Imu`. A covariance whose first element is -1 means "not provided" (REP 145).
#[derive(Clone, Debug, PartialEq)]
pub struct Imu {
    pub header: Header,
    pub orientation: Quaternion,
    pub orientation_covariance: [f64; 9],
    pub angular_velocity: Vector3,
    pub angular_velocity_covariance: [f64; 9],
    pub linear_acceleration: Vector3,
    pub linear_acceleration_covariance: [f64; 9],
}

impl Cdr for Imu {
    fn encode(&self, w: &mut CdrWriter) {
        self.header.encode(w);
        self.orientation.encode(w);
        w.f64_array(&self.orientation_covariance);
        self.angular_velocity.encode(w);
        w.f64_array(&self.angular_velocity_covariance);
        self.linear_acceleration.encode(w);
        w.f64_array(&self.linear_acceleration_covariance);
    }
    fn decode(r: &mut CdrReader<'_>) -> Result<Self, PipelineError> {
        Ok(Self {
            header: Header::decode(r)?,
            orientation: Quaternion::decode(r)?,
            orientation_covariance: r.f64_array("orientation_covariance")?,
            angular_velocity: Vector3::decode(r)?,
            angular_velocity_covariance: r.f64_array("angular_velocity_covariance")?,
            linear_acceleration: Vector3::decode(r)?,
            linear_acceleration_covariance: r.f64_array("linear_acceleration_covariance")?,
        })
    }
}

impl RosMessage for Imu {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/Imu";
}

/// `nav_msgs/Odometry`: pose in `header.frame_id`, twist in `child_frame_id`.
#[derive(Clone, Debug, PartialEq)]
pub struct Odometry {
    pub header: Header,
    pub child_frame_id: String,
    pub pose: Pose,
    pub pose_covariance: [f64; 36],
    /// Linear then angular velocity.
    pub twist: (Vector3, Vector3),
    pub twist_covariance: [f64; 36],
}

impl Cdr for Odometry {
    fn encode(&self, w: &mut CdrWriter) {
        self.header.encode(w);
        w.string(&self.child_frame_id);
        self.pose.encode(w);
        w.f64_array(&self.pose_covariance);
        self.twist.0.encode(w);
        self.twist.1.encode(w);
        w.f64_array(&self.twist_covariance);
    }
    fn decode(r: &mut CdrReader<'_>) -> Result<Self, PipelineError> {
        Ok(Self {
            header: Header::decode(r)?,
            child_frame_id: r.string("child_frame_id")?,
            pose: Pose::decode(r)?,
            pose_covariance: r.f64_array("pose.covariance")?,
            twist: (Vector3::decode(r)?, Vector3::decode(r)?),
            twist_covariance: r.f64_array("twist.covariance")?,
        })
    }
}

impl RosMessage for Odometry {
    const TYPE_NAME: &'static str = "nav_msgs/msg/Odometry";
}

/// `geometry_msgs/TransformStamped`: where `child_frame_id` sits in `header.frame_id`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TransformStamped {
    pub header: Header,
    pub child_frame_id: String,
    pub translation: Vector3,
    pub rotation: Quaternion,
}

impl Cdr for TransformStamped {
    fn encode(&self, w: &mut CdrWriter) {
        self.header.encode(w);
        w.string(&self.child_frame_id);
        self.translation.encode(w);
        self.rotation.encode(w);
    }
    fn decode(r: &mut CdrReader<'_>) -> Result<Self, PipelineError> {
        Ok(Self {
            header: Header::decode(r)?,
            child_frame_id: r.string("child_frame_id")?,
            translation: Vector3::decode(r)?,
            rotation: Quaternion::decode(r)?,
        })
    }
}

/// `tf2_msgs/TFMessage`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TfMessage {
    pub transforms: Vec<TransformStamped>,
}

impl Cdr for TfMessage {
    fn encode(&self, w: &mut CdrWriter) {
        seq(w, &self.transforms);
    }
    fn decode(r: &mut CdrReader<'_>) -> Result<Self, PipelineError> {
        // header (8 + 4) + child (4) + 7 f64
        Ok(Self { transforms: read_seq(r, "transforms", 72)? })
    }
}

impl RosMessage for TfMessage {
    const TYPE_NAME: &'static str = "tf2_msgs/msg/TFMessage";
}

/// `sensor_msgs/PointField`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PointField {
    pub name: String,
    pub offset: u32,
    pub datatype: u8,
    pub count: u32,
}

impl PointField {
    pub const UINT8: u8 = 2;
    pub const UINT32: u8 = 6;
    pub const FLOAT32: u8 = 7;
}

impl Cdr for PointField {
    fn encode(&self, w: &mut CdrWriter) {
        w.string(&self.name);
        w.u32(self.offset);
        w.u8(self.datatype);
        w.u32(self.count);
    }
    fn decode(r: &mut CdrReader<'_>) -> Result<Self, PipelineError> {
        Ok(Self {
            name: r.string("name")?,
            offset: r.u32("offset")?,
            datatype: r.u8("datatype")?,
            count: r.u32("count")?,
        })
    }
}

/// `sensor_msgs/PointCloud2`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointCloud2 {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub fields: Vec<PointField>,
    pub is_bigendian: bool,
    pub point_step: u32,
    pub row_step: u32,
    pub data: Vec<u8>,
    pub is_dense: bool,
}

impl Cdr for PointCloud2 {
    fn encode(&self, w: &mut CdrWriter) {
        w.reserve(self.data.len() + 64 + 24 * self.fields.len());
        self.header.encode(w);
        w.u32(self.height);
        w.u32(self.width);
        seq(w, &self.fields);
        w.bool(self.is_bigendian);
        w.u32(self.point_step);
        w.u32(self.row_step);
        w.bytes(&self.data);
        w.bool(self.is_dense);
    }
    fn decode(r: &mut CdrReader<'_>) -> Result<Self, PipelineError> {
        Ok(Self {
            header: Header::decode(r)?,
            height: r.u32("height")?,
            width: r.u32("width")?,
            fields: read_seq(r, "fields", 13)?,
            is_bigendian: r.bool("is_bigendian")?,
            point_step: r.u32("point_step")?,
            row_step: r.u32("row_step")?,
            data: r.bytes("data")?.to_vec(),
            is_dense: r.bool("is_dense")?,
        })
    }
}

impl RosMessage for PointCloud2 {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/PointCloud2";
}

/// `sensor_msgs/CompressedImage`: `format` is `png` or `jpeg` (image_transport's convention).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CompressedImage {
    pub header: Header,
    pub format: String,
    pub data: Vec<u8>,
}

impl Cdr for CompressedImage {
    fn encode(&self, w: &mut CdrWriter) {
        w.reserve(self.data.len() + 32);
        self.header.encode(w);
        w.string(&self.format);
        w.bytes(&self.data);
    }
    fn decode(r: &mut CdrReader<'_>) -> Result<Self, PipelineError> {
        Ok(Self { header: Header::decode(r)?, format: r.string("format")?, data: r.bytes("data")?.to_vec() })
    }
}

impl RosMessage for CompressedImage {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/CompressedImage";
}

/// `can_msgs/Frame` (ros2_socketcan's type): one CAN frame as the bus carried it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CanFrameMsg {
    pub header: Header,
    /// 11-bit or 29-bit identifier (`is_extended` says which).
    pub id: u32,
    pub is_rtr: bool,
    pub is_extended: bool,
    pub is_error: bool,
    pub dlc: u8,
    pub data: [u8; 8],
}

impl Cdr for CanFrameMsg {
    fn encode(&self, w: &mut CdrWriter) {
        self.header.encode(w);
        w.u32(self.id);
        w.bool(self.is_rtr);
        w.bool(self.is_extended);
        w.bool(self.is_error);
        w.u8(self.dlc);
        for b in self.data {
            w.u8(b);
        }
    }
    fn decode(r: &mut CdrReader<'_>) -> Result<Self, PipelineError> {
        let (header, id) = (Header::decode(r)?, r.u32("id")?);
        let (is_rtr, is_extended, is_error, dlc) =
            (r.bool("is_rtr")?, r.bool("is_extended")?, r.bool("is_error")?, r.u8("dlc")?);
        let mut data = [0u8; 8];
        for b in &mut data {
            *b = r.u8("data")?;
        }
        Ok(Self { header, id, is_rtr, is_extended, is_error, dlc, data })
    }
}

impl RosMessage for CanFrameMsg {
    const TYPE_NAME: &'static str = "can_msgs/msg/Frame";
}

/// `std_msgs/ColorRGBA`, components in 0..1.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ColorRgba {
    pub r: f32,
    pub g: f32,
    pub b: f32,
    pub a: f32,
}

impl Cdr for ColorRgba {
    fn encode(&self, w: &mut CdrWriter) {
        w.f32(self.r);
        w.f32(self.g);
        w.f32(self.b);
        w.f32(self.a);
    }
    fn decode(r: &mut CdrReader<'_>) -> Result<Self, PipelineError> {
        Ok(Self { r: r.f32("r")?, g: r.f32("g")?, b: r.f32("b")?, a: r.f32("a")? })
    }
}

/// `visualization_msgs/Marker`, limited to what a shape marker needs: the texture, UV and mesh
/// fields are always written empty; on read they are decoded (so the payload is checked) and
/// dropped.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Marker {
    pub header: Header,
    pub ns: String,
    pub id: i32,
    pub kind: i32,
    pub action: i32,
    pub pose: Pose,
    pub scale: Vector3,
    pub color: ColorRgba,
    /// `builtin_interfaces/Duration`; zero means "forever".
    pub lifetime: Time,
    pub frame_locked: bool,
    pub points: Vec<Vector3>,
    pub colors: Vec<ColorRgba>,
    pub text: String,
}

impl Marker {
    pub const CUBE: i32 = 1;
    pub const TEXT_VIEW_FACING: i32 = 9;
    pub const ADD: i32 = 0;
    pub const DELETE_ALL: i32 = 3;
}

impl Cdr for Marker {
    fn encode(&self, w: &mut CdrWriter) {
        self.header.encode(w);
        w.string(&self.ns);
        w.i32(self.id);
        w.i32(self.kind);
        w.i32(self.action);
        self.pose.encode(w);
        self.scale.encode(w);
        self.color.encode(w);
        self.lifetime.encode(w);
        w.bool(self.frame_locked);
        seq(w, &self.points);
        seq(w, &self.colors);
        w.string(""); // texture_resource
        CompressedImage::default().encode(w); // texture
        w.len(0); // uv_coordinates
        w.string(&self.text);
        w.string(""); // mesh_resource
        w.string(""); // mesh_file.filename
        w.len(0); // mesh_file.data
        w.bool(false); // mesh_use_embedded_materials
    }
    fn decode(r: &mut CdrReader<'_>) -> Result<Self, PipelineError> {
        let header = Header::decode(r)?;
        let ns = r.string("ns")?;
        let id = r.i32("id")?;
        let kind = r.i32("type")?;
        let action = r.i32("action")?;
        let pose = Pose::decode(r)?;
        let scale = Vector3::decode(r)?;
        let color = ColorRgba::decode(r)?;
        let lifetime = Time::decode(r)?;
        let frame_locked = r.bool("frame_locked")?;
        let points = read_seq(r, "points", 24)?;
        let colors = read_seq(r, "colors", 16)?;
        let _texture_resource = r.string("texture_resource")?;
        let _texture = CompressedImage::decode(r)?;
        let uv = r.seq_len("uv_coordinates", 8)?;
        for _ in 0..uv {
            r.f32("u")?;
            r.f32("v")?;
        }
        let text = r.string("text")?;
        let _mesh_resource = r.string("mesh_resource")?;
        let _mesh_filename = r.string("mesh_file.filename")?;
        let _mesh_data = r.bytes("mesh_file.data")?;
        let _embedded = r.bool("mesh_use_embedded_materials")?;
        Ok(Self { header, ns, id, kind, action, pose, scale, color, lifetime, frame_locked, points, colors, text })
    }
}

/// `visualization_msgs/MarkerArray`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MarkerArray {
    pub markers: Vec<Marker>,
}

impl Cdr for MarkerArray {
    fn encode(&self, w: &mut CdrWriter) {
        seq(w, &self.markers);
    }
    fn decode(r: &mut CdrReader<'_>) -> Result<Self, PipelineError> {
        Ok(Self { markers: read_seq(r, "markers", 100)? })
    }
}

impl RosMessage for MarkerArray {
    const TYPE_NAME: &'static str = "visualization_msgs/msg/MarkerArray";
}

/// Lengths CDR can carry; checked before encoding anything that came from outside.
pub(crate) fn check_cloud(c: &PointCloud2) -> Result<(), PipelineError> {
    check_len(PointCloud2::TYPE_NAME, "data", c.data.len())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn header(ns: u64, frame: &str) -> Header {
        Header { stamp: Time::from_ns(ns).unwrap(), frame_id: frame.into() }
    }

    fn round_trip<T: RosMessage + PartialEq + std::fmt::Debug>(m: &T) {
        let bytes = m.to_cdr();
        assert_eq!(&T::from_cdr(&bytes).unwrap(), m, "{}", T::TYPE_NAME);
        // every strict prefix fails to decode, with an error and no panic
        for cut in 0..bytes.len() {
            assert!(T::from_cdr(&bytes[..cut]).is_err(), "{} cut at {cut}", T::TYPE_NAME);
        }
    }

    #[test]
    fn time_splits_and_refuses_2038() {
        let t = Time::from_ns(1_700_000_000_123_456_789).unwrap();
        assert_eq!(t, Time { sec: 1_700_000_000, nanosec: 123_456_789 });
        assert_eq!(t.to_ns(), Some(1_700_000_000_123_456_789));
        assert!(Time::from_ns(u64::MAX).is_none());
        assert!(Time { sec: -1, nanosec: 0 }.to_ns().is_none());
    }

    #[test]
    fn every_message_round_trips_and_every_prefix_is_refused() {
        round_trip(&Imu {
            header: header(5, "imu_link"),
            orientation: Quaternion { x: 0.1, y: 0.2, z: 0.3, w: 0.9 },
            orientation_covariance: [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            angular_velocity: Vector3::new(0.01, -0.02, 0.03),
            angular_velocity_covariance: [1e-4; 9],
            linear_acceleration: Vector3::new(0.1, 0.2, 9.81),
            linear_acceleration_covariance: [2e-3; 9],
        });
        round_trip(&Odometry {
            header: header(6, "odom"),
            child_frame_id: "base_link".into(),
            pose: Pose { position: Vector3::new(1.0, 2.0, 3.0), orientation: Quaternion::IDENTITY },
            pose_covariance: [0.5; 36],
            twist: (Vector3::new(0.3, 0.0, 0.0), Vector3::new(0.0, 0.0, 0.1)),
            twist_covariance: [0.25; 36],
        });
        round_trip(&TfMessage {
            transforms: vec![TransformStamped {
                header: header(7, "map"),
                child_frame_id: "odom".into(),
                translation: Vector3::new(1.0, 0.0, 0.0),
                rotation: Quaternion::IDENTITY,
            }],
        });
        round_trip(&PointCloud2 {
            header: header(8, "avia"),
            height: 1,
            width: 1,
            fields: vec![PointField { name: "x".into(), offset: 0, datatype: PointField::FLOAT32, count: 1 }],
            is_bigendian: false,
            point_step: 4,
            row_step: 4,
            data: vec![0, 0, 128, 63],
            is_dense: true,
        });
        round_trip(&Twist { linear: Vector3::new(0.3, -0.1, 0.0), angular: Vector3::new(0.0, 0.0, 0.5) });
        round_trip(&CompressedImage { header: header(9, "fpv"), format: "png".into(), data: vec![1, 2, 3] });
        round_trip(&MarkerArray {
            markers: vec![Marker {
                header: header(10, "map"),
                ns: "people".into(),
                id: 3,
                kind: Marker::CUBE,
                action: Marker::ADD,
                pose: Pose::default(),
                scale: Vector3::new(0.5, 0.5, 1.8),
                color: ColorRgba { r: 1.0, g: 0.0, b: 0.0, a: 0.5 },
                lifetime: Time { sec: 0, nanosec: 200_000_000 },
                frame_locked: false,
                points: vec![Vector3::new(1.0, 2.0, 3.0)],
                colors: vec![],
                text: "person 0.93".into(),
            }],
        });
    }
}
