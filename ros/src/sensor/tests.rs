use super::*;
use std::sync::Arc;

fn msg(ty: &str, fields: Vec<(&str, Value)>) -> Message {
    Message { ty: ty.into(), fields: fields.into_iter().map(|(n, v)| (Arc::<str>::from(n), v)).collect() }
}

fn header2(sec: i64, nsec: u64, frame: &str) -> Value {
    let stamp = msg("builtin_interfaces/Time", vec![("sec", Value::Int(sec)), ("nanosec", Value::UInt(nsec))]);
    Value::Message(msg(
        "std_msgs/Header",
        vec![("stamp", Value::Message(stamp)), ("frame_id", Value::String(frame.into()))],
    ))
}

fn raw_image(w: u64, h: u64, encoding: &str, step: u64, big: bool, data: Vec<u8>) -> Message {
    msg(
        "sensor_msgs/Image",
        vec![
            ("header", header2(1, 5, "cam")),
            ("height", Value::UInt(h)),
            ("width", Value::UInt(w)),
            ("encoding", Value::String(encoding.into())),
            ("is_bigendian", Value::UInt(big as u64)),
            ("step", Value::UInt(step)),
            ("data", Value::Bytes(data)),
        ],
    )
}

#[test]
fn bgr8_with_row_padding_comes_out_rgb() {
    // 2x2, step 8 (2 bytes of padding per row).
    let data = vec![1, 2, 3, 4, 5, 6, 99, 99, 7, 8, 9, 10, 11, 12, 99, 99];
    let Picture::Colour(img) = image(&raw_image(2, 2, "bgr8", 8, false, data), 1000.0).unwrap() else { panic!() };
    assert_eq!(img.data, [3, 2, 1, 6, 5, 4, 9, 8, 7, 12, 11, 10]);
    assert_eq!(img.format, PixelFormat::Rgb8);
}

#[test]
fn depth_encodings_and_byte_order() {
    let le = raw_image(2, 1, "16UC1", 4, false, vec![0xe8, 0x03, 0, 0]);
    let be = raw_image(2, 1, "16UC1", 4, true, vec![0x03, 0xe8, 0, 0]);
    for m in [le, be] {
        let Picture::Depth(d) = image(&m, 1000.0).unwrap() else { panic!() };
        assert_eq!(d.data, [1.0, 0.0]);
    }
    let mut f = 2.5f32.to_le_bytes().to_vec();
    f.extend(f32::NAN.to_le_bytes());
    let Picture::Depth(d) = image(&raw_image(2, 1, "32FC1", 8, false, f), 1000.0).unwrap() else { panic!() };
    assert_eq!(d.data, [2.5, 0.0]);
}

#[test]
fn short_data_bad_step_and_unknown_encodings_are_refused() {
    let e = image(&raw_image(2, 2, "rgb8", 6, false, vec![0; 11]), 1.0).unwrap_err();
    assert!(e.contains("needs 12"), "{e}");
    let e = image(&raw_image(2, 2, "rgb8", 5, false, vec![0; 12]), 1.0).unwrap_err();
    assert!(e.contains("`step` 5"), "{e}");
    let e = image(&raw_image(2, 2, "bayer_rggb8", 2, false, vec![0; 4]), 1.0).unwrap_err();
    assert!(e.contains("bayer_rggb8"), "{e}");
}

#[test]
fn compressed_depth_png_round_trip() {
    let depth = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(2, 1, vec![1500u16, 0]).unwrap();
    let mut png = Vec::new();
    image::DynamicImage::ImageLuma16(depth)
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    let mut data = vec![0u8; 12];
    data.extend(png);
    let m = msg(
        "sensor_msgs/CompressedImage",
        vec![
            ("header", header2(0, 0, "d")),
            ("format", Value::String("16UC1; compressedDepth".into())),
            ("data", Value::Bytes(data)),
        ],
    );
    let Picture::Depth(d) = compressed_image(&m, 1000.0).unwrap() else { panic!() };
    assert_eq!(d.data, [1.5, 0.0]);
}

#[test]
fn camera_info_ros1_and_ros2_names() {
    let k = |n: &str| {
        (n.to_string(), Value::Array([500.0, 0.0, 320.0, 0.0, 510.0, 240.0, 0.0, 0.0, 1.0].map(Value::Float).to_vec()))
    };
    for (kn, dn) in [("k", "d"), ("K", "D")] {
        let (kname, kval) = k(kn);
        let m = Message {
            ty: "sensor_msgs/CameraInfo".into(),
            fields: vec![
                ("width".into(), Value::UInt(640)),
                ("height".into(), Value::UInt(480)),
                ("distortion_model".into(), Value::String("plumb_bob".into())),
                (dn.into(), Value::Array([0.1, -0.2, 0.0, 0.0, 0.01].map(Value::Float).to_vec())),
                (kname.into(), kval),
            ],
        };
        let c = camera_info(&m).unwrap();
        assert_eq!((c.fx, c.fy, c.cx, c.cy, c.distortion), (500.0, 510.0, 320.0, 240.0, [0.1, -0.2, 0.0, 0.0, 0.01]));
    }
}

#[test]
fn stamps_and_transforms() {
    let q = msg(
        "geometry_msgs/Quaternion",
        vec![("x", Value::Float(0.0)), ("y", Value::Float(0.0)), ("z", Value::Float(0.0)), ("w", Value::Float(1.0))],
    );
    let t = msg(
        "geometry_msgs/Vector3",
        vec![("x", Value::Float(1.0)), ("y", Value::Float(2.0)), ("z", Value::Float(3.0))],
    );
    let tf = msg("geometry_msgs/Transform", vec![("translation", Value::Message(t)), ("rotation", Value::Message(q))]);
    let ts = msg(
        "geometry_msgs/TransformStamped",
        vec![
            ("header", header2(3, 250_000_000, "world")),
            ("child_frame_id", Value::String("cam".into())),
            ("transform", Value::Message(tf)),
        ],
    );
    let all =
        transforms(&msg("tf2_msgs/TFMessage", vec![("transforms", Value::Array(vec![Value::Message(ts)]))])).unwrap();
    assert_eq!(all[0].0.seconds(), 3.25);
    assert_eq!(all[0].1, "cam");
    assert_eq!(all[0].2.translation.vector, Vector3::new(1.0, 2.0, 3.0));
    // ROS 1 `time`.
    let h = msg(
        "std_msgs/Header",
        vec![("stamp", Value::Time { sec: 2, nsec: 7 }), ("frame_id", Value::String(String::new()))],
    );
    assert_eq!(header(&msg("x/Y", vec![("header", Value::Message(h))])).unwrap().stamp_ns, 2_000_000_007);
}
