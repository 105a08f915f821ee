//! ROS 2 message definitions (`ros2msg` schema encoding) for the types we record.
//!
//! An MCAP schema holds the top-level `.msg` text followed by every type it uses, each after a
//! line of 80 `=` and a `MSG: pkg/Type` line, so a reader can decode without a ROS install.
//! Field order and types follow ROS 2 Humble (and later), which is what Foxglove, rosbags and
//! `ros2 bag` expect; comments are left out.

/// (type without `/msg/`, its fields, the types it uses directly).
const TYPES: &[(&str, &str, &[&str])] = &[
    ("builtin_interfaces/Time", "int32 sec\nuint32 nanosec\n", &[]),
    ("builtin_interfaces/Duration", "int32 sec\nuint32 nanosec\n", &[]),
    ("std_msgs/Header", "builtin_interfaces/Time stamp\nstring frame_id\n", &["builtin_interfaces/Time"]),
    ("std_msgs/ColorRGBA", "float32 r\nfloat32 g\nfloat32 b\nfloat32 a\n", &[]),
    ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n", &[]),
    ("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z\n", &[]),
    ("geometry_msgs/Quaternion", "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n", &[]),
    (
        "geometry_msgs/Pose",
        "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
        &["geometry_msgs/Point", "geometry_msgs/Quaternion"],
    ),
    ("geometry_msgs/PoseWithCovariance", "geometry_msgs/Pose pose\nfloat64[36] covariance\n", &["geometry_msgs/Pose"]),
    (
        "geometry_msgs/Twist",
        "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n",
        &["geometry_msgs/Vector3"],
    ),
    (
        "geometry_msgs/TwistWithCovariance",
        "geometry_msgs/Twist twist\nfloat64[36] covariance\n",
        &["geometry_msgs/Twist"],
    ),
    (
        "geometry_msgs/Transform",
        "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n",
        &["geometry_msgs/Vector3", "geometry_msgs/Quaternion"],
    ),
    (
        "geometry_msgs/TransformStamped",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n",
        &["std_msgs/Header", "geometry_msgs/Transform"],
    ),
    (
        "sensor_msgs/PointField",
        "uint8 INT8=1\nuint8 UINT8=2\nuint8 INT16=3\nuint8 UINT16=4\nuint8 INT32=5\nuint8 UINT32=6\n\
         uint8 FLOAT32=7\nuint8 FLOAT64=8\nstring name\nuint32 offset\nuint8 datatype\nuint32 count\n",
        &[],
    ),
    (
        "sensor_msgs/PointCloud2",
        "std_msgs/Header header\nuint32 height\nuint32 width\nsensor_msgs/PointField[] fields\nbool is_bigendian\n\
         uint32 point_step\nuint32 row_step\nuint8[] data\nbool is_dense\n",
        &["std_msgs/Header", "sensor_msgs/PointField"],
    ),
    (
        "sensor_msgs/Imu",
        "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\nfloat64[9] orientation_covariance\n\
         geometry_msgs/Vector3 angular_velocity\nfloat64[9] angular_velocity_covariance\n\
         geometry_msgs/Vector3 linear_acceleration\nfloat64[9] linear_acceleration_covariance\n",
        &["std_msgs/Header", "geometry_msgs/Quaternion", "geometry_msgs/Vector3"],
    ),
    ("sensor_msgs/CompressedImage", "std_msgs/Header header\nstring format\nuint8[] data\n", &["std_msgs/Header"]),
    (
        "nav_msgs/Odometry",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n\
         geometry_msgs/TwistWithCovariance twist\n",
        &["std_msgs/Header", "geometry_msgs/PoseWithCovariance", "geometry_msgs/TwistWithCovariance"],
    ),
    (
        "can_msgs/Frame",
        "std_msgs/Header header\nuint32 id\nbool is_rtr\nbool is_extended\nbool is_error\nuint8 dlc\nuint8[8] data\n",
        &["std_msgs/Header"],
    ),
    ("tf2_msgs/TFMessage", "geometry_msgs/TransformStamped[] transforms\n", &["geometry_msgs/TransformStamped"]),
    ("visualization_msgs/UVCoordinate", "float32 u\nfloat32 v\n", &[]),
    ("visualization_msgs/MeshFile", "string filename\nuint8[] data\n", &[]),
    (
        "visualization_msgs/Marker",
        "int32 ARROW=0\nint32 CUBE=1\nint32 SPHERE=2\nint32 CYLINDER=3\nint32 LINE_STRIP=4\nint32 LINE_LIST=5\n\
         int32 CUBE_LIST=6\nint32 SPHERE_LIST=7\nint32 POINTS=8\nint32 TEXT_VIEW_FACING=9\nint32 MESH_RESOURCE=10\n\
         int32 TRIANGLE_LIST=11\nint32 ADD=0\nint32 MODIFY=0\nint32 DELETE=2\nint32 DELETEALL=3\n\
         std_msgs/Header header\nstring ns\nint32 id\nint32 type\nint32 action\ngeometry_msgs/Pose pose\n\
         geometry_msgs/Vector3 scale\nstd_msgs/ColorRGBA color\nbuiltin_interfaces/Duration lifetime\n\
         bool frame_locked\ngeometry_msgs/Point[] points\nstd_msgs/ColorRGBA[] colors\nstring texture_resource\n\
         sensor_msgs/CompressedImage texture\nvisualization_msgs/UVCoordinate[] uv_coordinates\nstring text\n\
         string mesh_resource\nvisualization_msgs/MeshFile mesh_file\nbool mesh_use_embedded_materials\n",
        &[
            "std_msgs/Header",
            "geometry_msgs/Pose",
            "geometry_msgs/Vector3",
            "std_msgs/ColorRGBA",
            "builtin_interfaces/Duration",
            "geometry_msgs/Point",
            "sensor_msgs/CompressedImage",
            "visualization_msgs/UVCoordinate",
            "visualization_msgs/MeshFile",
        ],
    ),
    ("visualization_msgs/MarkerArray", "visualization_msgs/Marker[] markers\n", &["visualization_msgs/Marker"]),
    ("vision_msgs/ObjectHypothesis", "string class_id\nfloat64 score\n", &[]),
    (
        "vision_msgs/ObjectHypothesisWithPose",
        "vision_msgs/ObjectHypothesis hypothesis\ngeometry_msgs/PoseWithCovariance pose\n",
        &["vision_msgs/ObjectHypothesis", "geometry_msgs/PoseWithCovariance"],
    ),
    (
        "vision_msgs/BoundingBox3D",
        "geometry_msgs/Pose center\ngeometry_msgs/Vector3 size\n",
        &["geometry_msgs/Pose", "geometry_msgs/Vector3"],
    ),
    (
        "vision_msgs/Detection3D",
        "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\nvision_msgs/BoundingBox3D bbox\n\
         string id\n",
        &["std_msgs/Header", "vision_msgs/ObjectHypothesisWithPose", "vision_msgs/BoundingBox3D"],
    ),
    (
        "vision_msgs/Detection3DArray",
        "std_msgs/Header header\nvision_msgs/Detection3D[] detections\n",
        &["std_msgs/Header", "vision_msgs/Detection3D"],
    ),
];

const SEPARATOR: &str = "================================================================================\n";

fn lookup(name: &str) -> Option<&'static (&'static str, &'static str, &'static [&'static str])> {
    TYPES.iter().find(|(n, _, _)| *n == name)
}

/// A type's own fields (`pkg/msg/Type` or `pkg/Type`), constants included, one per line; `None`
/// for a type this module does not know.
pub fn own_fields(type_name: &str) -> Option<&'static str> {
    lookup(&type_name.replacen("/msg/", "/", 1)).map(|(_, fields, _)| *fields)
}

/// The full `ros2msg` schema text for `type_name` (`pkg/msg/Type` or `pkg/Type`): its own fields,
/// then every type it uses, depth first, each once. `None` for a type this module does not know.
pub fn definition(type_name: &str) -> Option<String> {
    let short = type_name.replacen("/msg/", "/", 1);
    let (_, fields, _) = lookup(&short)?;
    let mut out = String::from(*fields);
    let mut seen: Vec<&str> = Vec::new();
    let mut stack: Vec<&str> = lookup(&short).map(|(_, _, d)| d.iter().rev().copied().collect()).unwrap_or_default();
    while let Some(dep) = stack.pop() {
        if seen.contains(&dep) {
            continue;
        }
        seen.push(dep);
        let (_, dep_fields, dep_deps) = lookup(dep)?;
        out.push_str(SEPARATOR);
        out.push_str("MSG: ");
        out.push_str(dep);
        out.push('\n');
        out.push_str(dep_fields);
        stack.extend(dep_deps.iter().rev().copied());
    }
    Some(out)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn every_dependency_is_known_and_listed_once() {
        for (name, _, _) in TYPES {
            let text = definition(name).unwrap();
            let msgs: Vec<&str> = text.lines().filter_map(|l| l.strip_prefix("MSG: ")).collect();
            let mut unique = msgs.clone();
            unique.sort_unstable();
            unique.dedup();
            assert_eq!(unique.len(), msgs.len(), "{name}");
        }
        let odom = definition("nav_msgs/msg/Odometry").unwrap();
        assert!(odom.starts_with("std_msgs/Header header\n"));
        assert!(odom.contains("MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"));
        assert!(odom.contains("MSG: geometry_msgs/Twist\n"));
        assert!(definition("sensor_msgs/msg/Nope").is_none());
    }
}
