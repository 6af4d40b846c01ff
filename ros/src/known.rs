//! The ROS 2 types a SLAM run reads, for bags that do not store their definitions (rosbag2's
//! SQLite storage before Iron), and those it records ([`crate::encode`]). Written from the
//! field lists of `common_interfaces` (sensor_msgs, geometry_msgs, nav_msgs, std_msgs,
//! visualization_msgs), `builtin_interfaces` and `tf2_msgs`, in the
//! `ros2msg` form a bag stores: a definition here must match the wire layout exactly, so each is
//! also checked against bags `rosbags` writes (the integration tests).

/// `(type, fields)`, ROS 2 dialect.
const DEFINITIONS: &[(&str, &str)] = &[
    ("builtin_interfaces/Time", "int32 sec\nuint32 nanosec\n"),
    ("std_msgs/Header", "builtin_interfaces/Time stamp\nstring frame_id\n"),
    (
        "sensor_msgs/Image",
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\nuint32 step\nuint8[] data\n",
    ),
    ("sensor_msgs/CompressedImage", "std_msgs/Header header\nstring format\nuint8[] data\n"),
    (
        "sensor_msgs/RegionOfInterest",
        "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n",
    ),
    (
        "sensor_msgs/CameraInfo",
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] d\nfloat64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\nuint32 binning_y\nsensor_msgs/RegionOfInterest roi\n",
    ),
    (
        "sensor_msgs/Imu",
        "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\nfloat64[9] orientation_covariance\ngeometry_msgs/Vector3 angular_velocity\nfloat64[9] angular_velocity_covariance\ngeometry_msgs/Vector3 linear_acceleration\nfloat64[9] linear_acceleration_covariance\n",
    ),
    ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n"),
    ("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z\n"),
    ("geometry_msgs/Quaternion", "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n"),
    ("geometry_msgs/Pose", "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n"),
    ("geometry_msgs/PoseStamped", "std_msgs/Header header\ngeometry_msgs/Pose pose\n"),
    ("geometry_msgs/PoseWithCovariance", "geometry_msgs/Pose pose\nfloat64[36] covariance\n"),
    ("geometry_msgs/Twist", "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n"),
    ("geometry_msgs/TwistWithCovariance", "geometry_msgs/Twist twist\nfloat64[36] covariance\n"),
    ("geometry_msgs/Transform", "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n"),
    (
        "geometry_msgs/TransformStamped",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n",
    ),
    ("tf2_msgs/TFMessage", "geometry_msgs/TransformStamped[] transforms\n"),
    ("nav_msgs/Path", "std_msgs/Header header\ngeometry_msgs/PoseStamped[] poses\n"),
    ("sensor_msgs/PointField", "string name\nuint32 offset\nuint8 datatype\nuint32 count\n"),
    (
        "sensor_msgs/PointCloud2",
        "std_msgs/Header header\nuint32 height\nuint32 width\nsensor_msgs/PointField[] fields\nbool is_bigendian\nuint32 point_step\nuint32 row_step\nuint8[] data\nbool is_dense\n",
    ),
    ("std_msgs/ColorRGBA", "float32 r\nfloat32 g\nfloat32 b\nfloat32 a\n"),
    ("builtin_interfaces/Duration", "int32 sec\nuint32 nanosec\n"),
    (
        "visualization_msgs/ImageMarker",
        "std_msgs/Header header\nstring ns\nint32 id\nint32 type\nint32 action\ngeometry_msgs/Point position\nfloat32 scale\nstd_msgs/ColorRGBA outline_color\nuint8 filled\nstd_msgs/ColorRGBA fill_color\nbuiltin_interfaces/Duration lifetime\ngeometry_msgs/Point[] points\nstd_msgs/ColorRGBA[] outline_colors\n",
    ),
    ("std_msgs/String", "string data\n"),
    (
        "nav_msgs/Odometry",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n",
    ),
];

fn fields(ty: &str) -> Option<&'static str> {
    DEFINITIONS.iter().find(|(n, _)| *n == ty).map(|(_, f)| *f)
}

/// `ty`'s definition with a `MSG:` section for every type it uses, as a bag would store it;
/// `None` for a type not listed here.
pub fn bundle(ty: &str) -> Option<String> {
    let mut out = fields(ty)?.to_string();
    let mut seen = vec![ty.to_string()];
    let mut queue = vec![ty.to_string()];
    while let Some(t) = queue.pop() {
        for line in fields(&t)?.lines() {
            let Some(used) = line.split_whitespace().next() else { continue };
            let used = used.split('[').next().unwrap_or(used);
            if used.contains('/') && !seen.iter().any(|s| s == used) {
                seen.push(used.to_string());
                queue.push(used.to_string());
                out.push_str(&format!(
                    "================================================================================\nMSG: {used}\n{}",
                    fields(used)?
                ));
            }
        }
    }
    Some(out)
}

/// Every type listed here.
pub fn types() -> impl Iterator<Item = &'static str> {
    DEFINITIONS.iter().map(|(n, _)| *n)
}

#[cfg(test)]
mod tests {
    use crate::msgdef::{Dialect, Registry};

    #[test]
    fn every_bundle_resolves() {
        for t in super::types() {
            let text = super::bundle(t).unwrap();
            Registry::parse(t, &text, Dialect::Ros2).unwrap_or_else(|e| panic!("{t}: {e}"));
        }
    }
}
