#![allow(clippy::unwrap_used)]

use std::fs;

use crate::synth::{
    EurocWriteOptions, Generator, Motion, STAMP_BASE, SynthConfig, rig_calibration, scaled_fr3, write_euroc,
};

use super::*;

fn generator() -> Generator {
    Generator::new(SynthConfig {
        motion: Motion::Handheld,
        seed: 3,
        intrinsics: scaled_fr3(64, 48),
        ..SynthConfig::default()
    })
}

/// A small sequence written by `synth --format euroc` into a fresh folder.
fn written(name: &str, frames: u64, baseline: Option<f64>, depth: bool) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("dynaflow-euroc-{name}-{}", std::process::id()));
    let _ = fs::remove_dir_all(&dir);
    let opts = EurocWriteOptions { frames, baseline, depth, calibration: rig_calibration() };
    write_euroc(&generator(), &dir, &opts).unwrap();
    dir
}

#[test]
fn a_written_sequence_reads_back_exactly() {
    let dir = written("roundtrip", 12, Some(0.12), true);
    let g = generator();
    let cal = rig_calibration();
    let mut seq = EurocSequence::open(&dir, 0).unwrap();
    assert_eq!(seq.len(), 12);
    assert_eq!(seq.baseline().unwrap(), Some(0.12));
    assert!(seq.has_depth());
    let c = seq.calibration();
    assert_eq!(
        (c.rate_hz, c.gyro_noise_density, c.accel_random_walk),
        (200.0, cal.gyro_noise_density, cal.accel_random_walk)
    );
    assert!((c.body_from_cam.to_homogeneous() - cal.body_from_cam.to_homogeneous()).abs().max() < 1e-14);
    let k = &g.config().intrinsics;
    assert_eq!((seq.camera().fx, seq.camera().cx, seq.camera().width), (k.fx, k.cx, 64));
    // Every IMU sample, in exactly one frame's batch, as generated (17 significant digits).
    let truth: Vec<_> =
        g.imu(&cal, g.time(12), true).into_iter().filter(|s| s.stamp <= STAMP_BASE + g.time(11) + 1e-6).collect();
    let mut read = Vec::new();
    for i in 0..12 {
        let f = seq.frame(i).unwrap().unwrap();
        assert_eq!(f.stamp_ns, 1_700_000_000_000_000_000 + (g.time(i as u64) * 1e9).round() as i64);
        // Ground truth: the camera's pose, through the body and T_BS.
        let gt = f.gt_pose.unwrap();
        let want = g.pose(i as u64);
        assert!((gt.to_homogeneous() - want.to_homogeneous()).abs().max() < 1e-9, "frame {i}");
        let gf = g.frame(i as u64, false);
        assert_eq!(f.left.data, gf.rgb, "frame {i}: cam0");
        assert_eq!(f.right.unwrap().data, g.right(&gf, 0.12).unwrap(), "frame {i}: cam1");
        let depth = f.depth.unwrap();
        let worst = depth.data.iter().zip(&gf.depth).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(worst <= 0.5 / 5000.0 + 1e-6, "frame {i}: depth off by {worst} m");
        assert!(f.imu.iter().all(|s| s.stamp <= f.stamp + 1e-6));
        read.extend(f.imu);
    }
    assert_eq!(read.len(), truth.len());
    for (a, b) in read.iter().zip(&truth) {
        assert!((a.stamp - b.stamp).abs() < 1e-6);
        assert_eq!((a.gyro, a.accel), (b.gyro, b.accel));
    }
    assert!(seq.frame(12).unwrap().is_none());
    let _ = fs::remove_dir_all(&dir);
}

/// Replace `from` by `to` in `mav0/<file>` (the change must happen).
fn edit(dir: &Path, file: &str, from: &str, to: &str) {
    let path = dir.join("mav0").join(file);
    let text = fs::read_to_string(&path).unwrap();
    assert!(text.contains(from), "{file} has no `{from}`");
    fs::write(&path, text.replacen(from, to, 1)).unwrap();
}

/// Replace the `data: [...]` of `T_BS` in `mav0/<file>` by `values`.
fn set_t_bs(dir: &Path, file: &str, values: &str) {
    let path = dir.join("mav0").join(file);
    let text = fs::read_to_string(&path).unwrap();
    let start = text.find("data: [").unwrap() + "data: [".len();
    let end = start + text[start..].find(']').unwrap();
    fs::write(&path, format!("{}{values}{}", &text[..start], &text[end..])).unwrap();
}

#[track_caller]
fn open_error(dir: &Path) -> String {
    EurocSequence::open(dir, 0).unwrap_err().to_string()
}

#[test]
fn bad_files_are_refused_naming_file_and_line() {
    let dir = written("bad", 30, None, false);
    let fresh = || {
        let _ = fs::remove_dir_all(&dir);
        write_euroc(
            &generator(),
            &dir,
            &EurocWriteOptions { frames: 30, baseline: None, depth: false, calibration: rig_calibration() },
        )
        .unwrap();
    };
    // An extrinsic that is no rotation: a scaled 3x3 block.
    fresh();
    set_t_bs(&dir, "cam0/sensor.yaml", "2.0, 0, 0, 0, 0, 2.0, 0, 0, 0, 0, 2.0, 0, 0, 0, 0, 1");
    let e = open_error(&dir);
    assert!(e.contains("cam0/sensor.yaml:9:") && e.contains("not a rotation"), "{e}");
    // The IMU's stated rate far from its samples'.
    fresh();
    edit(&dir, "imu0/sensor.yaml", "rate_hz: 200", "rate_hz: 100");
    let e = open_error(&dir);
    assert!(e.contains("imu0/data.csv") && e.contains("states 100 Hz"), "{e}");
    fresh();
    let path = dir.join("mav0/imu0/data.csv");
    let text = fs::read_to_string(&path).unwrap();
    let mut lines: Vec<&str> = text.lines().collect();
    lines.swap(5, 6);
    fs::write(&path, lines.join("\n")).unwrap();
    let e = open_error(&dir);
    assert!(e.contains("imu0/data.csv:7:") && e.contains("out of order"), "{e}");
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    lines[4] = lines[4].replacen(",", ",NaN,", 1).splitn(8, ',').take(7).collect::<Vec<_>>().join(",");
    fs::write(&path, lines.join("\n")).unwrap();
    let e = open_error(&dir);
    assert!(e.contains("imu0/data.csv:5:") && e.contains("finite"), "{e}");
    // A line with a field missing.
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    lines[3] = lines[3].rsplit_once(',').unwrap().0.to_owned();
    fs::write(&path, lines.join("\n")).unwrap();
    let e = open_error(&dir);
    assert!(e.contains("imu0/data.csv:4:") && e.contains("6 fields, expected 7"), "{e}");
    // A gap longer than the stated limit.
    let lines: Vec<&str> = text.lines().enumerate().filter(|(i, _)| !(10..30).contains(i)).map(|(_, l)| l).collect();
    fs::write(&path, lines.join("\n")).unwrap();
    let e = open_error(&dir);
    assert!(e.contains("imu0/data.csv:") && e.contains("gap"), "{e}");
    // Image stamps that go back; a missing image (named when its frame is read).
    fresh();
    let path = dir.join("mav0/cam0/data.csv");
    let text = fs::read_to_string(&path).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    fs::write(&path, [lines[0], lines[2], lines[1], lines[3]].join("\n")).unwrap();
    let e = open_error(&dir);
    assert!(e.contains("cam0/data.csv:3:") && e.contains("not after"), "{e}");
    fresh();
    let mut names: Vec<PathBuf> =
        fs::read_dir(dir.join("mav0/cam0/data")).unwrap().map(|e| e.unwrap().path()).collect();
    names.sort();
    fs::remove_file(&names[1]).unwrap();
    let mut seq = EurocSequence::open(&dir, 0).unwrap();
    assert!(seq.frame(0).is_ok());
    let e = seq.frame(1).unwrap_err().to_string();
    assert!(e.contains(&*names[1].to_string_lossy()), "{e}");
    // Not a EuRoC folder at all.
    let e = open_error(&dir.join("mav0/cam0"));
    assert!(e.contains("not a EuRoC MAV folder"), "{e}");
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn an_unrectified_pair_is_refused_for_stereo_with_what_differs() {
    let dir = written("unrectified", 2, Some(0.11), false);
    // cam1 turned by about 1.1° about y (EuRoC's raw pairs differ by about that).
    let cam0 = EurocSequence::open(&dir, 0).unwrap().cam0.body_from_sensor;
    let turned = cam0
        * Isometry3::from_parts(
            Translation3::new(0.11, 0.0, 0.0),
            UnitQuaternion::from_scaled_axis(Vector3::y() * 0.02),
        );
    let m = turned.to_homogeneous();
    let values: Vec<String> =
        (0..4).flat_map(|r| (0..4).map(move |c| (r, c))).map(|(r, c)| format!("{:e}", m[(r, c)])).collect();
    set_t_bs(&dir, "cam1/sensor.yaml", &values.join(", "));
    let seq = EurocSequence::open(&dir, 0).unwrap();
    let e = seq.baseline().unwrap_err().to_string();
    assert!(e.contains("cam1/sensor.yaml") && e.contains("no rectified partner") && e.contains("1.146°"), "{e}");
    let _ = fs::remove_dir_all(&dir);
}

#[test]
fn an_equidistant_camera_is_read_as_kannala_brandt() {
    let dir = written("equidistant", 2, None, false);
    // TUM-VI's cam0 calibration as Kalibr writes it.
    edit(&dir, "cam0/sensor.yaml", "distortion_model: radial-tangential", "distortion_model: equidistant");
    edit(
        &dir,
        "cam0/sensor.yaml",
        "distortion_coefficients: [0.0, 0.0, 0.0, 0.0]",
        "distortion_coefficients: [0.003482389, 0.000715034, -0.002053236, 0.000202936]",
    );
    let seq = EurocSequence::open(&dir, 0).unwrap();
    assert_eq!(seq.camera().model, dynaflow_msg::LensModel::KannalaBrandt);
    assert_eq!(seq.camera().distortion, [0.003482389, 0.000715034, -0.002053236, 0.000202936, 0.0]);
    // Five coefficients are no Kannala-Brandt lens.
    edit(&dir, "cam0/sensor.yaml", "0.000202936]", "0.000202936, 0.1]");
    let e = open_error(&dir);
    assert!(e.contains("cam0/sensor.yaml:") && e.contains("more than 4 equidistant"), "{e}");
    let _ = fs::remove_dir_all(&dir);
}
