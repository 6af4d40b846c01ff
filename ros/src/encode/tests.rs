//! Every encoder read back by this crate's reader with [`crate::known`]'s definitions.

use super::*;
use crate::decode::{Encoding, Message, Value, decode};
use crate::known::bundle;
use crate::msgdef::{Dialect, Registry};
use crate::sensor::{self, Picture};
use nalgebra::{Translation3, UnitQuaternion};

fn read(ty: &str, data: &[u8]) -> Message {
    let registry = Registry::parse(ty, &bundle(ty).unwrap(), Dialect::Ros2).unwrap();
    decode(&registry, Encoding::Cdr, data).unwrap_or_else(|e| panic!("{ty}: {e}"))
}

fn iso() -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::new(1.5, -2.25, 0.125), UnitQuaternion::from_euler_angles(0.1, -0.2, 0.3))
}

fn f(v: Option<&Value>) -> f64 {
    match v {
        Some(Value::Float(x)) => *x,
        other => panic!("not a float: {other:?}"),
    }
}

#[test]
fn stamps_split_into_seconds_and_nanoseconds() {
    assert_eq!(time(1_305_031_102.175_304), (1_305_031_102, 175_304_000));
    assert_eq!(time(0.033_333), (0, 33_333_000));
    assert_eq!(time(2.999_999_999_7), (3, 0));
    assert_eq!(time(1e-10), (0, 0));
    assert_eq!(time(-1.0), (0, 0));
    for text in ["1700000000.633333", "0.000000001", "12.5"] {
        let (s, n) = time(text.parse().unwrap());
        assert_eq!(crate::sensor::seconds(i64::from(s) * 1_000_000_000 + i64::from(n)), text.parse::<f64>().unwrap());
    }
    assert_eq!(time(f64::NAN), (0, 0));
}

#[test]
fn images_camera_info_poses_and_imu_read_back() {
    let img = Image { width: 3, height: 2, format: PixelFormat::Rgb8, data: (0..18).collect() };
    let Picture::Colour(back) =
        sensor::image(&read("sensor_msgs/Image", &image(12.5, "camera", &img)), 1000.0).unwrap()
    else {
        panic!("not colour")
    };
    assert_eq!(back, img);
    let grey = Image { width: 3, height: 1, format: PixelFormat::Gray8, data: vec![7, 8, 9] };
    let Picture::Colour(back) = sensor::image(&read("sensor_msgs/Image", &image(0.0, "c", &grey)), 1000.0).unwrap()
    else {
        panic!("not grey")
    };
    assert_eq!(back, grey);
    let depth = DepthImage { width: 2, height: 2, data: vec![0.0, 1.25, 3.5, f32::NAN] };
    let m = read("sensor_msgs/Image", &depth_image(1.0, "camera", &depth));
    let Picture::Depth(back) = sensor::image(&m, 1000.0).unwrap() else { panic!("not depth") };
    assert_eq!(back.data[..3], depth.data[..3]);
    assert_eq!(back.data[3], 0.0, "NaN is read as no measurement");
    let h = sensor::header(&m).unwrap();
    assert_eq!((h.stamp_ns, h.frame_id.as_str()), (1_000_000_000, "camera"));

    let info = CameraInfo {
        width: 640,
        height: 480,
        fx: 517.3,
        fy: 516.5,
        cx: 318.6,
        cy: 255.3,
        distortion: [0.26, -0.95, -0.005, 0.002, 1.16],
        model: LensModel::BrownConrady,
    };
    assert_eq!(sensor::camera_info(&read("sensor_msgs/CameraInfo", &camera_info(2.0, "camera", &info))).unwrap(), info);
    // A fisheye is written `equidistant` with its four coefficients, and read back as one.
    let fisheye = CameraInfo {
        distortion: [0.0035, 0.0007, -0.0021, 0.0002, 0.0],
        model: LensModel::KannalaBrandt,
        ..info.clone()
    };
    let m = read("sensor_msgs/CameraInfo", &camera_info(2.0, "camera", &fisheye));
    assert_eq!(m.get("distortion_model"), Some(&Value::String("equidistant".into())));
    assert_eq!(sensor::camera_info(&m).unwrap(), fisheye);

    let (h, _, p) =
        sensor::stamped_pose(&read("geometry_msgs/PoseStamped", &pose_stamped(3.25, "map", &iso()))).unwrap();
    assert_eq!((h.stamp_ns, h.frame_id.as_str()), (3_250_000_000, "map"));
    assert!((p.inverse() * iso()).translation.vector.norm() < 1e-15);

    let edges = [
        Transform { stamp: 4.0, parent: "map", child: "camera", parent_from_child: iso() },
        Transform { stamp: 4.0, parent: "camera", child: "imu", parent_from_child: Isometry3::identity() },
    ];
    let back = sensor::transforms(&read("tf2_msgs/TFMessage", &tf(&edges))).unwrap();
    assert_eq!(back.len(), 2);
    assert_eq!((back[0].0.frame_id.as_str(), back[0].1.as_str()), ("map", "camera"));
    assert!((back[0].2.inverse() * iso()).translation.vector.norm() < 1e-15);
    assert_eq!(back[1].1, "imu");

    let s = sensor::imu(&read("sensor_msgs/Imu", &imu(5.0, "imu", [0.1, -0.2, 0.3], [0.0, 9.81, -0.5]))).unwrap();
    assert_eq!(s.gyro, nalgebra::Vector3::new(0.1, -0.2, 0.3));
    assert_eq!(s.accel, nalgebra::Vector3::new(0.0, 9.81, -0.5));
}

#[test]
fn compressed_images_path_cloud_markers_and_text_read_back() {
    let m = read("sensor_msgs/CompressedImage", &compressed_image(1.0, "camera", "jpeg", &[0xff, 0xd8, 1, 2]));
    assert_eq!(m.get("format"), Some(&Value::String("jpeg".into())));
    assert_eq!(m.get("data"), Some(&Value::Bytes(vec![0xff, 0xd8, 1, 2])));

    let poses = [(1.0, Isometry3::identity()), (1.5, iso())];
    let m = read("nav_msgs/Path", &path(1.5, "map", &poses));
    let Some(Value::Array(list)) = m.get("poses") else { panic!("no poses") };
    assert_eq!(list.len(), 2);
    let Value::Message(second) = &list[1] else { panic!() };
    let (h, _, p) = sensor::stamped_pose(second).unwrap();
    assert_eq!(h.stamp_ns, 1_500_000_000);
    assert!((p.inverse() * iso()).rotation.angle() < 1e-15);

    let pts = [[1.0f32, 2.0, 3.0], [-1.0, 0.5, 8.0]];
    let rgb = [[255u8, 0, 16], [1, 2, 3]];
    let m = read("sensor_msgs/PointCloud2", &point_cloud(2.0, "map", &pts, Some(&rgb)));
    let Some(Value::Bytes(data)) = m.get("data") else { panic!("no data") };
    assert_eq!(data.len(), 32);
    let word = |i: usize| [data[i], data[i + 1], data[i + 2], data[i + 3]];
    assert_eq!(f32::from_le_bytes(word(16 + 8)), 8.0);
    assert_eq!(u32::from_le_bytes(word(12)), 0x00ff_0010);
    let Some(Value::Array(fields)) = m.get("fields") else { panic!("no fields") };
    assert_eq!(fields.len(), 4);

    let m = read(
        "visualization_msgs/ImageMarker",
        &image_marker(3.0, "camera", "labels", MarkerKind::Points, 4.0, &[[10.5, 20.25]], &[[1.0, 0.0, 0.0, 1.0]]),
    );
    assert_eq!(m.get("type"), Some(&Value::Int(4)));
    let Some(Value::Array(points)) = m.get("points") else { panic!("no points") };
    let Value::Message(p) = &points[0] else { panic!() };
    assert_eq!((f(p.get("x")), f(p.get("y"))), (10.5, 20.25));

    let m = read("std_msgs/String", &string("{\"a\":1}"));
    assert_eq!(m.get("data"), Some(&Value::String("{\"a\":1}".into())));
}
