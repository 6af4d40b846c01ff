use super::{PortType, Stored, decode};
use crate::mcap::proto::{RawLayout, raw_image};

fn mono8(width: u32, height: u32, step: u32, data: &[u8]) -> Stored {
    let payload = br#"{"seq":0,"stamp":0.0,"frame_id":"c","data":{}}"#;
    let layout = RawLayout { width, height, encoding: "mono8", step };
    Stored::Proto { raw: true, data: raw_image(0.0, "c", layout, |b| b.extend_from_slice(data), payload) }
}

#[test]
fn raw_images_with_odd_sizes_are_errors_or_empty_never_panics() {
    // A zero-width image (step 0) decodes to an empty mask.
    let (_, body) = decode(PortType::Mask, &mono8(0, 3, 0, &[])).unwrap();
    assert!(matches!(body, dynaflow_engine::msg::Body::Mask(m) if m.classes.is_empty()));
    // A step shorter than a row is an error naming the sizes.
    let err = decode(PortType::Mask, &mono8(4, 2, 1, &[1; 2])).unwrap_err();
    assert!(err.contains("mono8 4x2: step 1"), "{err}");
    let (_, body) = decode(PortType::Mask, &mono8(4, 2, 4, &[1; 8])).unwrap();
    assert!(matches!(body, dynaflow_engine::msg::Body::Mask(m) if m.classes == vec![1; 8]));
}

#[test]
fn an_imu_batch_replays_from_its_payload_with_the_recorded_digest() {
    use dynaflow_engine::msg::{Body, Header, ImuBatch, ImuCalibration, ImuSample, Message};
    use nalgebra::{Isometry3, Vector3};
    let samples = (0..7)
        .map(|k| {
            let t = f64::from(k);
            ImuSample {
                stamp: 1_700_000_000.0 + 0.005 * t,
                gyro: Vector3::new(0.1 * t, -0.2, 1.0 / 3.0),
                accel: Vector3::new(0.01, 9.81 - t * 1e-3, std::f64::consts::PI),
            }
        })
        .collect();
    let calibration = ImuCalibration {
        body_from_cam: Isometry3::new(
            Vector3::new(-0.02, -0.065, 0.01),
            Vector3::new(0.0, 0.0, std::f64::consts::FRAC_PI_2),
        ),
        ..ImuCalibration::adis16448()
    };
    let msg = Message::new(
        Header { seq: 4, stamp: 1_700_000_000.03, frame_id: "imu".into() },
        Body::Imu(ImuBatch { samples, calibration }),
    );
    let stored = serde_json::json!({ "dynaflow": serde_json::to_value(crate::payload::payload(&msg)).unwrap() });
    let body = super::decode_json(PortType::Imu, &stored).unwrap();
    let back = Message::new(msg.header.clone(), body);
    assert_eq!(back, msg);
    assert!(super::same_as_recorded(&back, &stored["dynaflow"]));
}

#[test]
fn a_camera_replays_with_its_lens() {
    use dynaflow_engine::msg::{Body, CameraInfo, Header, LensModel, Message};
    let header = Header { seq: 0, stamp: 1.0, frame_id: "camera".into() };
    let fisheye = CameraInfo {
        width: 512,
        height: 512,
        fx: 190.97,
        fy: 190.97,
        cx: 254.93,
        cy: 256.9,
        distortion: [0.0035, 0.0007, -0.0021, 0.0002, 0.0],
        model: LensModel::KannalaBrandt,
    };
    let kinect = CameraInfo {
        distortion: [0.2624, -0.9531, -0.0054, 0.0026, 1.1633],
        model: LensModel::BrownConrady,
        ..fisheye.clone()
    };
    for info in [fisheye, kinect] {
        let msg = Message::new(header.clone(), Body::CameraInfo(info));
        let stored = serde_json::json!({ "dynaflow": serde_json::to_value(crate::payload::payload(&msg)).unwrap() });
        let back = Message::new(header.clone(), super::decode_json(PortType::CameraInfo, &stored).unwrap());
        assert_eq!(back, msg);
        assert!(super::same_as_recorded(&back, &stored["dynaflow"]));
    }
}
