//! Writing a generated sequence in the EuRoC MAV (ASL) layout, read back by
//! [`crate::euroc::EurocSequence`] (and by any EuRoC tool): `ROOT/mav0/` with `cam0/` (the
//! camera), `cam1/` (a rectified right camera, with a baseline), `depth0/` (dynaflow's
//! RGB-D-inertial extension: 16-bit PNG, 5000 per metre, registered to cam0), `imu0/` (the
//! rig's noisy IMU, [`rig_calibration`](super::rig_calibration)) and
//! `state_groundtruth_estimate0/` (the IMU body's pose, velocity and true biases at the IMU
//! rate). Stamps are nanoseconds from [`STAMP_BASE`](super::STAMP_BASE), computed from the
//! frame and sample indices (no rounding through seconds).

use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};

use dynaflow_msg::ImuCalibration;
use image::ExtendedColorType;
use nalgebra::Isometry3;

use super::tum::{DEPTH_FACTOR, depth_png, png};
use super::{Generator, STAMP_BASE};
use crate::Error;

/// What to write.
#[derive(Clone, Debug)]
pub struct EurocWriteOptions {
    /// Number of frames.
    pub frames: u64,
    /// Stereo baseline in metres for `cam1/`; `None`: no `cam1/`.
    pub baseline: Option<f64>,
    /// Write `depth0/`.
    pub depth: bool,
    /// The IMU and its mounting.
    pub calibration: ImuCalibration,
}

/// Nanoseconds of `STAMP_BASE + seconds`.
fn ns(seconds: f64) -> i64 {
    STAMP_BASE as i64 * 1_000_000_000 + (seconds * 1e9).round() as i64
}

fn t_bs(pose: &Isometry3<f64>) -> String {
    let m = pose.to_homogeneous();
    let rows: Vec<String> =
        (0..4).map(|r| (0..4).map(|c| format!("{:e}", m[(r, c)])).collect::<Vec<_>>().join(", ")).collect();
    format!("T_BS:\n  cols: 4\n  rows: 4\n  data: [{}]\n", rows.join(",\n         "))
}

fn write(path: &Path, text: &str) -> Result<(), Error> {
    fs::write(path, text).map_err(|e| Error::file(path, e))
}

/// Write `opts.frames` frames of `generator` under `root/mav0/`; returns `root` (what
/// `--input` takes). A kidnap is refused: its rewind is a jump no IMU measures.
pub fn write_euroc(generator: &Generator, root: &Path, opts: &EurocWriteOptions) -> Result<PathBuf, Error> {
    let c = generator.config();
    if c.kidnap.is_some() {
        return Err(Error::file(
            root,
            "a kidnap rewinds the camera, a jump no IMU measures: the EuRoC layout is written without one",
        ));
    }
    if let Some(b) = opts.baseline
        && !(b > 0.0 && b.is_finite())
    {
        return Err(Error::file(root, format!("a stereo baseline must be positive, not {b}")));
    }
    let cal = &opts.calibration;
    let k = &c.intrinsics;
    let mav0 = root.join("mav0");
    let mut cams = vec![("cam0", cal.body_from_cam)];
    if let Some(b) = opts.baseline {
        cams.push(("cam1", cal.body_from_cam * nalgebra::Translation3::new(b, 0.0, 0.0)));
    }
    // Kalibr's names: a fisheye is `equidistant` with four coefficients.
    let distortion = if k.model == dynaflow_msg::LensModel::KannalaBrandt {
        let [k1, k2, k3, k4, _] = k.distortion;
        format!("distortion_model: equidistant\ndistortion_coefficients: [{k1:e}, {k2:e}, {k3:e}, {k4:e}]")
    } else {
        "distortion_model: radial-tangential\ndistortion_coefficients: [0.0, 0.0, 0.0, 0.0]".to_owned()
    };
    let camera_yaml = |name: &str, body_from_cam: &Isometry3<f64>| {
        format!(
            "# General sensor definitions.\nsensor_type: camera\ncomment: dynaflow synth {name} (seed {})\n\n# Sensor extrinsics wrt. the body-frame.\n{}\n# Camera specific definitions.\nrate_hz: {}\nresolution: [{}, {}]\ncamera_model: pinhole\nintrinsics: [{:e}, {:e}, {:e}, {:e}] #fu, fv, cu, cv\n{distortion}\n",
            c.seed,
            t_bs(body_from_cam),
            c.rate_hz,
            k.width,
            k.height,
            k.fx,
            k.fy,
            k.cx,
            k.cy
        )
    };
    let mut folders: Vec<(&str, String)> = cams.iter().map(|(n, p)| (*n, camera_yaml(n, p))).collect();
    if opts.depth {
        folders.push((
            "depth0",
            format!(
                "sensor_type: depth\ncomment: dynaflow synth depth registered to cam0 (16-bit PNG)\n{}rate_hz: {}\ndepth_factor: {DEPTH_FACTOR} # PNG units per metre\n",
                t_bs(&cal.body_from_cam),
                c.rate_hz
            ),
        ));
    }
    for (name, yaml) in &folders {
        let dir = mav0.join(name).join("data");
        fs::create_dir_all(&dir).map_err(|e| Error::file(&dir, e))?;
        write(&mav0.join(name).join("sensor.yaml"), yaml)?;
    }
    let mut csv: Vec<String> = folders.iter().map(|_| "#timestamp [ns],filename\n".to_owned()).collect();
    for i in 0..opts.frames {
        let f = generator.frame(i, false);
        let stamp = ns(generator.time(i));
        let name = format!("{stamp}.png");
        png(&mav0.join("cam0/data").join(&name), &f.rgb, k.width, k.height, ExtendedColorType::Rgb8)?;
        if let Some(b) = opts.baseline {
            let right = generator.right(&f, b).unwrap_or_default();
            png(&mav0.join("cam1/data").join(&name), &right, k.width, k.height, ExtendedColorType::Rgb8)?;
        }
        if opts.depth {
            depth_png(&mav0.join("depth0/data").join(&name), &f.depth, k.width, k.height)?;
        }
        for text in &mut csv {
            let _ = writeln!(text, "{stamp},{name}");
        }
    }
    for ((name, _), text) in folders.iter().zip(&csv) {
        write(&mav0.join(name).join("data.csv"), text)?;
    }

    // The IMU and the ground truth over the frames' span and two samples past the last frame
    // (so the ground truth brackets every frame).
    let dt = 1.0 / cal.rate_hz;
    let until = generator.time(opts.frames.saturating_sub(1)) + 2.0 * dt;
    let samples = generator.imu_with_biases(cal, until, true);
    let (mut imu, mut gt) = (
        "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n".to_owned(),
        "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], b_w_RS_S_y [rad s^-1], b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], b_a_RS_S_z [m s^-2]\n".to_owned(),
    );
    for (j, (s, [bg, ba])) in samples.iter().enumerate() {
        let t = j as f64 * dt;
        let stamp = ns(t);
        let (w, a) = (s.gyro, s.accel);
        let _ = writeln!(imu, "{stamp},{:e},{:e},{:e},{:e},{:e},{:e}", w.x, w.y, w.z, a.x, a.y, a.z);
        let pose = generator.body_pose(t, cal);
        let v = generator.body_velocity(t, cal);
        let (p, q) = (pose.translation.vector, pose.rotation);
        let _ = writeln!(
            gt,
            "{stamp},{:e},{:e},{:e},{:e},{:e},{:e},{:e},{:e},{:e},{:e},{:e},{:e},{:e},{:e},{:e},{:e}",
            p.x, p.y, p.z, q.w, q.i, q.j, q.k, v.x, v.y, v.z, bg.x, bg.y, bg.z, ba.x, ba.y, ba.z
        );
    }
    let imu_yaml = format!(
        "#Default imu sensor yaml file\nsensor_type: imu\ncomment: dynaflow synth IMU with {} noise\n\n# Sensor extrinsics wrt. the body-frame.\n{}rate_hz: {}\n\n# inertial sensor noise model parameters (static)\ngyroscope_noise_density: {:e}     # [ rad / s / sqrt(Hz) ]   ( gyro \"white noise\" )\ngyroscope_random_walk: {:e}       # [ rad / s^2 / sqrt(Hz) ] ( gyro bias diffusion )\naccelerometer_noise_density: {:e}  # [ m / s^2 / sqrt(Hz) ]  ( accel \"white noise\" )\naccelerometer_random_walk: {:e}    # [ m / s^3 / sqrt(Hz) ].  ( accel bias diffusion )\n",
        if *cal == (ImuCalibration { body_from_cam: cal.body_from_cam, ..ImuCalibration::adis16448() }) {
            "EuRoC's ADIS16448"
        } else {
            "the given"
        },
        t_bs(&Isometry3::identity()),
        cal.rate_hz,
        cal.gyro_noise_density,
        cal.gyro_random_walk,
        cal.accel_noise_density,
        cal.accel_random_walk
    );
    let gt_yaml = format!(
        "sensor_type: visual-inertial\ncomment: dynaflow synth ground truth of the IMU body (exact)\n{}",
        t_bs(&Isometry3::identity())
    );
    for (dir, yaml, data) in [("imu0", imu_yaml, imu), ("state_groundtruth_estimate0", gt_yaml, gt)] {
        let d = mav0.join(dir);
        fs::create_dir_all(&d).map_err(|e| Error::file(&d, e))?;
        write(&d.join("sensor.yaml"), &yaml)?;
        write(&d.join("data.csv"), &data)?;
    }
    Ok(root.to_path_buf())
}
