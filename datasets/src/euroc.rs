//! EuRoC MAV (ASL) sequence folders (Burri et al., "The EuRoC micro aerial vehicle datasets",
//! IJRR 2016): `mav0/` with one folder per sensor, each with a `sensor.yaml` (its extrinsic
//! `T_BS` in the body frame and its model) and a `data.csv` (nanosecond stamps first):
//!
//! - `cam0/` (required): `data.csv` is `#timestamp [ns],filename`, images under `data/`;
//!   `sensor.yaml` gives `resolution`, `camera_model: pinhole`, `intrinsics: [fu, fv, cu, cv]`,
//!   `distortion_model: radial-tangential` with `[k1, k2, p1, p2]`, or Kalibr's `equidistant`
//!   (a Kannala-Brandt fisheye) with `[k1, k2, k3, k4]`.
//! - `cam1/` (optional): the second camera of a stereo pair. Only a rectified pair is
//!   streamed as stereo (same intrinsics, no distortion, the same orientation, offset along
//!   cam0's `x`); EuRoC's own raw pairs are not rectified and are refused by
//!   [`EurocSequence::baseline`] with what differs.
//! - `depth0/` (optional, dynaflow's RGB-D-inertial extension): 16-bit PNG depth registered
//!   to `cam0` (the same stamps and `T_BS`), `depth_factor` PNG units per metre.
//! - `imu0/` (required): `w_RS_S` (rad/s) and `a_RS_S` (m/s²) per line; `sensor.yaml` gives
//!   `rate_hz` and the noise densities and random walks. The stream is checked by
//!   [`crate::imu::check`]'s rules against `rate_hz` and cut into one batch per frame.
//! - `state_groundtruth_estimate0/` (optional): `p_RS_R`, `q_RS` (w, x, y, z), `v_RS_R` and
//!   the biases; frames get `world_from_cam0` interpolated between the two samples around
//!   their stamp when those are at most [`GT_MAX_INTERVAL_S`] apart.
//!
//! Every `T_BS` must be a rigid transform (an orthonormal rotation with determinant +1, last
//! row `0 0 0 1`): anything else is refused at `sensor.yaml:line`.

use std::path::{Path, PathBuf};

use dynaflow_base::yaml::{self, Yaml, YamlKind};
use dynaflow_msg::{CameraInfo, DepthImage, Image, ImuCalibration, ImuSample, LensModel, STANDARD_GRAVITY};
use nalgebra::{Isometry3, Matrix3, Quaternion, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::Error;
use crate::imu::ImuStream;
use crate::png::{load_depth, load_rgb, same_size};

/// Ground truth is interpolated between two samples at most this far apart (chosen: four
/// periods of EuRoC's 200 Hz ground truth; a frame in a longer hole of the ground truth gets
/// none).
pub const GT_MAX_INTERVAL_S: f64 = 0.02;

/// How far from a rigid transform a `T_BS` may be (EuRoC writes 12 significant digits;
/// chosen: `|RᵀR - I|` and `|det R - 1|` within 1e-6).
pub const RIGID_TOLERANCE: f64 = 1e-6;

/// A `sensor.yaml`: its text (for line numbers) and tree.
struct SensorYaml {
    path: PathBuf,
    text: String,
    doc: Yaml,
}

impl SensorYaml {
    fn read(path: &Path) -> Result<Self, Error> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, e))?;
        let doc = yaml::parse(&text).map_err(|e| {
            let (line, col) = yaml::line_col(&text, e.span.offset);
            Error::line(path, line, format!("column {col}: {}", e.message))
        })?;
        Ok(Self { path: path.to_path_buf(), text, doc })
    }

    fn line(&self, node: &Yaml) -> usize {
        yaml::line_col(&self.text, node.span.offset).0
    }

    fn get(&self, key: &str) -> Result<&Yaml, Error> {
        self.doc.get(key).ok_or_else(|| Error::file(&self.path, format!("no `{key}`")))
    }

    fn number_of(&self, node: &Yaml, what: &str) -> Result<f64, Error> {
        node.as_str()
            .and_then(|s| s.trim().parse::<f64>().ok())
            .filter(|v| v.is_finite())
            .ok_or_else(|| Error::line(&self.path, self.line(node), format!("`{what}` is not a number")))
    }

    fn number(&self, key: &str) -> Result<f64, Error> {
        self.number_of(self.get(key)?, key)
    }

    fn numbers(&self, node: &Yaml, what: &str) -> Result<Vec<f64>, Error> {
        let YamlKind::Seq(items) = &node.kind else {
            return Err(Error::line(&self.path, self.line(node), format!("`{what}` is not a list")));
        };
        items.iter().map(|n| self.number_of(n, what)).collect()
    }

    fn string(&self, key: &str) -> Option<&str> {
        self.doc.get(key).and_then(Yaml::as_str)
    }

    /// `T_BS` (`data`: 16 numbers, row-major), checked to be rigid.
    fn t_bs(&self) -> Result<Isometry3<f64>, Error> {
        let node = self.get("T_BS")?;
        let data = node.get("data").unwrap_or(node);
        let v = self.numbers(data, "T_BS data")?;
        let at = self.line(data);
        let [r00, r01, r02, tx, r10, r11, r12, ty, r20, r21, r22, tz, a, b, c, d] = v[..] else {
            return Err(Error::line(
                &self.path,
                at,
                format!("T_BS has {} numbers, expected 16 (a 4x4 matrix)", v.len()),
            ));
        };
        rigid(Matrix3::new(r00, r01, r02, r10, r11, r12, r20, r21, r22), Vector3::new(tx, ty, tz), [a, b, c, d])
            .map_err(|m| Error::line(&self.path, at, format!("T_BS {m}")))
    }
}

/// A rigid transform from a 3x3 block, a translation and a last row, or what is wrong.
fn rigid(r: Matrix3<f64>, t: Vector3<f64>, last: [f64; 4]) -> Result<Isometry3<f64>, String> {
    if last != [0.0, 0.0, 0.0, 1.0] {
        return Err(format!("has last row {last:?}, expected [0, 0, 0, 1]"));
    }
    let off = (r.transpose() * r - Matrix3::identity()).abs().max();
    let det = r.determinant();
    if off > RIGID_TOLERANCE || (det - 1.0).abs() > RIGID_TOLERANCE {
        return Err(format!(
            "is no rigid transform: its 3x3 block is not a rotation (|RᵀR - I| {off:.2e}, det {det:.6})"
        ));
    }
    let rot = Rotation3::from_matrix_eps(&r, f64::EPSILON, 100, Rotation3::identity());
    Ok(Isometry3::from_parts(Translation3::from(t), UnitQuaternion::from_rotation_matrix(&rot)))
}

/// One line of a `data.csv`: stamp (ns), the rest of the fields, its 1-based line.
struct CsvRow {
    ns: i64,
    fields: Vec<String>,
    line: usize,
}

fn read_csv(path: &Path, fields: usize) -> Result<Vec<CsvRow>, Error> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, e))?;
    let mut rows = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let parts: Vec<&str> = line.split(',').map(str::trim).collect();
        if parts.len() != fields + 1 {
            return Err(Error::line(path, i + 1, format!("{} fields, expected {}", parts.len(), fields + 1)));
        }
        let ns = parts[0]
            .parse::<i64>()
            .map_err(|_| Error::line(path, i + 1, format!("`{}` is not a nanosecond stamp", parts[0])))?;
        rows.push(CsvRow { ns, fields: parts[1..].iter().map(|s| (*s).to_owned()).collect(), line: i + 1 });
    }
    Ok(rows)
}

fn floats(path: &Path, row: &CsvRow) -> Result<Vec<f64>, Error> {
    row.fields
        .iter()
        .map(|s| s.parse::<f64>().map_err(|_| Error::line(path, row.line, format!("`{s}` is not a number"))))
        .collect()
}

/// Seconds from a nanosecond stamp.
pub fn seconds(ns: i64) -> f64 {
    ns as f64 * 1e-9
}

/// One image stream (`cam0`, `cam1`, `depth0`).
#[derive(Debug)]
struct Stream {
    dir: PathBuf,
    body_from_sensor: Isometry3<f64>,
    /// (stamp ns, file under `data/`), strictly increasing.
    images: Vec<(i64, String)>,
}

fn read_stream(dir: &Path) -> Result<(Stream, SensorYaml), Error> {
    let sensor = SensorYaml::read(&dir.join("sensor.yaml"))?;
    let body_from_sensor = sensor.t_bs()?;
    let csv = dir.join("data.csv");
    let mut images: Vec<(i64, String)> = Vec::new();
    for row in read_csv(&csv, 1)? {
        if let Some(&(prev, _)) = images.last()
            && row.ns <= prev
        {
            return Err(Error::line(
                &csv,
                row.line,
                format!("stamp {} ns is not after the previous one ({prev} ns)", row.ns),
            ));
        }
        images.push((row.ns, row.fields[0].clone()));
    }
    if images.is_empty() {
        return Err(Error::file(&csv, "no images listed"));
    }
    Ok((Stream { dir: dir.to_path_buf(), body_from_sensor, images }, sensor))
}

/// A camera's `sensor.yaml` model: pinhole with radial-tangential (or no) distortion, or
/// Kalibr's `equidistant` (Kannala-Brandt, four coefficients: TUM-VI, EuRoC's fisheye rigs).
fn camera_info(sensor: &SensorYaml) -> Result<CameraInfo, Error> {
    let model = sensor.string("camera_model").unwrap_or("pinhole");
    if model != "pinhole" {
        return Err(Error::file(
            &sensor.path,
            format!(
                "camera_model `{model}`: only `pinhole` (with `radial-tangential` or `equidistant` distortion) is read"
            ),
        ));
    }
    let resolution = sensor.numbers(sensor.get("resolution")?, "resolution")?;
    let k = sensor.numbers(sensor.get("intrinsics")?, "intrinsics")?;
    let [w, h] = resolution[..] else {
        return Err(Error::file(&sensor.path, "`resolution` must be [width, height]"));
    };
    let [fx, fy, cx, cy] = k[..] else {
        return Err(Error::file(&sensor.path, "`intrinsics` must be [fu, fv, cu, cv]"));
    };
    if !(w >= 1.0 && h >= 1.0 && w.fract() == 0.0 && h.fract() == 0.0 && fx > 0.0 && fy > 0.0) {
        return Err(Error::file(&sensor.path, "`resolution` must be positive integers and the focal lengths positive"));
    }
    let mut distortion = [0.0; 5];
    let d_model = sensor.string("distortion_model").unwrap_or("radial-tangential");
    let lens = match d_model {
        "equidistant" => LensModel::KannalaBrandt,
        _ => LensModel::BrownConrady,
    };
    if let Some(node) = sensor.doc.get("distortion_coefficients") {
        let d = sensor.numbers(node, "distortion_coefficients")?;
        if !matches!(d_model, "radial-tangential" | "equidistant") && d.iter().any(|&v| v != 0.0) {
            return Err(Error::line(
                &sensor.path,
                sensor.line(node),
                format!("distortion_model `{d_model}`: `radial-tangential` and `equidistant` are read"),
            ));
        }
        let most = if lens == LensModel::KannalaBrandt { 4 } else { 5 };
        if d.len() > most {
            return Err(Error::line(
                &sensor.path,
                sensor.line(node),
                format!("more than {most} {d_model} coefficients"),
            ));
        }
        distortion[..d.len()].copy_from_slice(&d);
    }
    Ok(CameraInfo { width: w as u32, height: h as u32, fx, fy, cx, cy, distortion, model: lens })
}

/// One ground-truth sample: the IMU body's pose and velocity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GroundTruth {
    /// Time, seconds.
    pub stamp: f64,
    /// `world_from_body` (the ground-truth sensor's pose mapped to the IMU body).
    pub world_from_body: Isometry3<f64>,
    /// The body's velocity in the world, m/s.
    pub velocity: Vector3<f64>,
}

/// One frame of a EuRoC sequence.
#[derive(Clone, Debug)]
pub struct EurocFrame {
    /// cam0's time, seconds.
    pub stamp: f64,
    /// cam0's time, nanoseconds, as written.
    pub stamp_ns: i64,
    /// cam0's image (grey in EuRoC; colour when the files are).
    pub left: Image,
    /// cam1's image at the same stamp, for a rectified pair.
    pub right: Option<Image>,
    /// depth0's depth in metres at the same stamp, when the folder has one.
    pub depth: Option<DepthImage>,
    /// cam0's intrinsics.
    pub camera: CameraInfo,
    /// The IMU samples stamped after the previous frame up to this one (the first frame: every
    /// sample up to it).
    pub imu: Vec<ImuSample>,
    /// Ground-truth `world_from_cam0`, when the ground truth covers the stamp.
    pub gt_pose: Option<Isometry3<f64>>,
}

/// An opened EuRoC MAV sequence.
#[derive(Debug)]
pub struct EurocSequence {
    mav0: PathBuf,
    cam0: Stream,
    camera: CameraInfo,
    cam1: Option<(Stream, CameraInfo)>,
    /// cam1's baseline when it is a rectified partner of cam0 (checked once, at open).
    rectified_baseline: Option<f64>,
    depth0: Option<(Stream, f64)>,
    calibration: ImuCalibration,
    imu: ImuStream,
    batches: Vec<Vec<ImuSample>>,
    gt: Vec<GroundTruth>,
    frames: usize,
}

impl EurocSequence {
    /// Open `dir`: a `mav0` folder or the folder holding one; at most `frames` frames (0: all).
    pub fn open(dir: &Path, frames: usize) -> Result<Self, Error> {
        let mav0 = if dir.join("mav0").is_dir() { dir.join("mav0") } else { dir.to_path_buf() };
        if !mav0.join("cam0").is_dir() || !mav0.join("imu0").is_dir() {
            return Err(Error::file(dir, "not a EuRoC MAV folder: expected `mav0/cam0/` and `mav0/imu0/`"));
        }
        let (cam0, sensor0) = read_stream(&mav0.join("cam0"))?;
        let camera = camera_info(&sensor0)?;

        // The IMU: its sensor.yaml, its samples, checked and cut into batches per frame.
        let imu_dir = mav0.join("imu0");
        let sensor = SensorYaml::read(&imu_dir.join("sensor.yaml"))?;
        let body_from_imu = sensor.t_bs()?;
        let calibration = ImuCalibration {
            gyro_noise_density: sensor.number("gyroscope_noise_density")?,
            accel_noise_density: sensor.number("accelerometer_noise_density")?,
            gyro_random_walk: sensor.number("gyroscope_random_walk")?,
            accel_random_walk: sensor.number("accelerometer_random_walk")?,
            rate_hz: sensor.number("rate_hz")?,
            body_from_cam: body_from_imu.inverse() * cam0.body_from_sensor,
            gravity: STANDARD_GRAVITY,
        };
        let csv = imu_dir.join("data.csv");
        let samples = read_csv(&csv, 6)?
            .iter()
            .map(|row| {
                let v = floats(&csv, row)?;
                let s = ImuSample {
                    stamp: seconds(row.ns),
                    gyro: Vector3::new(v[0], v[1], v[2]),
                    accel: Vector3::new(v[3], v[4], v[5]),
                };
                Ok((row.line, s))
            })
            .collect::<Result<Vec<_>, Error>>()?;
        let imu = crate::imu::check(&samples, calibration.rate_hz, &csv)?;
        let stamps: Vec<f64> = cam0.images.iter().map(|&(ns, _)| seconds(ns)).collect();
        let batches = imu.batches(&stamps);

        let cam1 = if mav0.join("cam1").is_dir() {
            let (stream, sensor) = read_stream(&mav0.join("cam1"))?;
            let info = camera_info(&sensor)?;
            Some((stream, info))
        } else {
            None
        };
        let depth0 = if mav0.join("depth0").is_dir() {
            let (stream, sensor) = read_stream(&mav0.join("depth0"))?;
            let factor = sensor.number("depth_factor")?;
            if factor.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                return Err(Error::file(&sensor.path, format!("depth_factor {factor} is not positive")));
            }
            let off = (stream.body_from_sensor.inverse() * cam0.body_from_sensor).to_homogeneous()
                - nalgebra::Matrix4::identity();
            if off.abs().max() > RIGID_TOLERANCE {
                return Err(Error::file(&sensor.path, "depth0 must be registered to cam0 (the same T_BS)"));
            }
            Some((stream, factor))
        } else {
            None
        };
        let gt = read_ground_truth(&mav0)?;
        let frames = if frames == 0 { cam0.images.len() } else { frames.min(cam0.images.len()) };
        let mut sequence =
            Self { mav0, cam0, camera, cam1, rectified_baseline: None, depth0, calibration, imu, batches, gt, frames };
        sequence.rectified_baseline = sequence.baseline().ok().flatten();
        Ok(sequence)
    }

    /// Frames to read.
    pub fn len(&self) -> usize {
        self.frames
    }

    /// Whether there is no frame.
    pub fn is_empty(&self) -> bool {
        self.frames == 0
    }

    /// The `mav0` folder.
    pub fn dir(&self) -> &Path {
        &self.mav0
    }

    /// cam0's intrinsics.
    pub fn camera(&self) -> &CameraInfo {
        &self.camera
    }

    /// The IMU's calibration: `imu0/sensor.yaml`'s noise model and rate, cam0's pose in the
    /// IMU frame, standard gravity.
    pub fn calibration(&self) -> &ImuCalibration {
        &self.calibration
    }

    /// The checked IMU stream (its counts of dropped repeats and irregular intervals).
    pub fn imu(&self) -> &ImuStream {
        &self.imu
    }

    /// Whether the folder has `depth0/`.
    pub fn has_depth(&self) -> bool {
        self.depth0.is_some()
    }

    /// The stereo baseline in metres when `cam1` forms a rectified pair with `cam0` (frames
    /// carry its image then); `None` otherwise.
    pub fn stereo_baseline(&self) -> Option<f64> {
        self.rectified_baseline
    }

    /// The stereo baseline in metres when `cam1` forms a rectified pair with `cam0`; `Ok(None)`
    /// without `cam1`; an error saying what differs for a pair that is not rectified.
    pub fn baseline(&self) -> Result<Option<f64>, Error> {
        let Some((cam1, info)) = &self.cam1 else { return Ok(None) };
        let rel = self.cam0.body_from_sensor.inverse() * cam1.body_from_sensor;
        let yaml = cam1.dir.join("sensor.yaml");
        let angle = rel.rotation.angle();
        let t = rel.translation.vector;
        let same_k =
            [info.fx - self.camera.fx, info.fy - self.camera.fy, info.cx - self.camera.cx, info.cy - self.camera.cy]
                .iter()
                .all(|d| d.abs() <= 1e-6)
                && (info.width, info.height) == (self.camera.width, self.camera.height);
        let undistorted = self.camera.distortion.iter().chain(&info.distortion).all(|&d| d == 0.0);
        if !(same_k && undistorted && angle <= 1e-6 && t.x > 0.0 && t.y.abs() <= 1e-6 * t.x && t.z.abs() <= 1e-6 * t.x)
        {
            return Err(Error::file(
                &yaml,
                format!(
                    "cam1 is no rectified partner of cam0 (relative rotation {:.3}°, offset [{:.4}, {:.4}, {:.4}] m, same intrinsics: {same_k}, no distortion: {undistorted}); stereo needs a rectified pair, so run cam0 alone (monocular) or rectify the images first",
                    angle.to_degrees(),
                    t.x,
                    t.y,
                    t.z
                ),
            ));
        }
        Ok(Some(t.x))
    }

    /// Ground truth `world_from_cam0` at `stamp` (seconds), interpolated between the two
    /// samples around it when they are at most [`GT_MAX_INTERVAL_S`] apart.
    pub fn gt_pose(&self, stamp: f64) -> Option<Isometry3<f64>> {
        let i = self.gt.partition_point(|g| g.stamp < stamp);
        let after = self.gt.get(i)?;
        if after.stamp == stamp {
            return Some(after.world_from_body * self.calibration.body_from_cam);
        }
        let before = self.gt.get(i.checked_sub(1)?)?;
        if after.stamp - before.stamp > GT_MAX_INTERVAL_S {
            return None;
        }
        let a = (stamp - before.stamp) / (after.stamp - before.stamp);
        let (p, q) = (&before.world_from_body, &after.world_from_body);
        let t = p.translation.vector.lerp(&q.translation.vector, a);
        let r = p.rotation.slerp(&q.rotation, a);
        Some(Isometry3::from_parts(Translation3::from(t), r) * self.calibration.body_from_cam)
    }

    /// Every ground-truth sample.
    pub fn ground_truth(&self) -> &[GroundTruth] {
        &self.gt
    }

    /// Frame `index`; `None` past the end.
    pub fn frame(&mut self, index: usize) -> Result<Option<EurocFrame>, Error> {
        if index >= self.frames {
            return Ok(None);
        }
        let (ns, ref name) = self.cam0.images[index];
        let left_path = self.cam0.dir.join("data").join(name);
        let left = load_rgb(&left_path)?;
        same_size(
            left_path.display(),
            (left.width, left.height),
            "cam0/sensor.yaml's resolution",
            (self.camera.width, self.camera.height),
        )?;
        let find = |stream: &Stream| -> Result<PathBuf, Error> {
            let i = stream.images.binary_search_by_key(&ns, |(t, _)| *t).map_err(|_| {
                Error::file(&stream.dir.join("data.csv"), format!("no image at cam0's stamp {ns} ns ({left_path:?})"))
            })?;
            Ok(stream.dir.join("data").join(&stream.images[i].1))
        };
        let right = match &self.cam1 {
            Some((stream, _)) if self.rectified_baseline.is_some() => {
                let path = find(stream)?;
                let img = load_rgb(&path)?;
                same_size(path.display(), (img.width, img.height), left_path.display(), (left.width, left.height))?;
                Some(img)
            }
            _ => None,
        };
        let depth = match &self.depth0 {
            Some((stream, factor)) => {
                let path = find(stream)?;
                let d = load_depth(&path, *factor)?;
                same_size(path.display(), (d.width, d.height), left_path.display(), (left.width, left.height))?;
                Some(d)
            }
            None => None,
        };
        let stamp = seconds(ns);
        Ok(Some(EurocFrame {
            stamp,
            stamp_ns: ns,
            left,
            right,
            depth,
            camera: self.camera.clone(),
            imu: self.batches[index].clone(),
            gt_pose: self.gt_pose(stamp),
        }))
    }
}

/// `state_groundtruth_estimate0/data.csv` as `world_from_body` (through its `sensor.yaml`'s
/// `T_BS`), when the folder has one.
fn read_ground_truth(mav0: &Path) -> Result<Vec<GroundTruth>, Error> {
    let dir = mav0.join("state_groundtruth_estimate0");
    if !dir.is_dir() {
        return Ok(Vec::new());
    }
    let yaml = dir.join("sensor.yaml");
    let body_from_sensor = if yaml.is_file() { SensorYaml::read(&yaml)?.t_bs()? } else { Isometry3::identity() };
    let sensor_from_body = body_from_sensor.inverse();
    let mut out = read_ground_truth_csv(&dir.join("data.csv"))?;
    for g in &mut out {
        g.world_from_body *= sensor_from_body;
    }
    Ok(out)
}

/// A EuRoC ground-truth file (`state_groundtruth_estimate0/data.csv`: nanosecond stamp,
/// `p_RS_R`, `q_RS` as w, x, y, z, `v_RS_R`, the biases) as written: the pose of the sensor it
/// states (EuRoC's body), as evo's `euroc` format reads it. Errors name the file and line.
pub fn read_ground_truth_csv(csv: &Path) -> Result<Vec<GroundTruth>, Error> {
    let mut out: Vec<GroundTruth> = Vec::new();
    for row in read_csv(csv, 16)? {
        let v = floats(csv, &row)?;
        let q = Quaternion::new(v[3], v[4], v[5], v[6]);
        if !v.iter().all(|x| x.is_finite()) || (q.norm() - 1.0).abs() > 1e-3 {
            return Err(Error::line(csv, row.line, format!("not finite, or a quaternion of norm {:.6}", q.norm())));
        }
        let stamp = seconds(row.ns);
        if out.last().is_some_and(|g| stamp <= g.stamp) {
            return Err(Error::line(csv, row.line, "stamp not after the previous line's"));
        }
        out.push(GroundTruth {
            stamp,
            world_from_body: Isometry3::from_parts(
                Translation3::new(v[0], v[1], v[2]),
                UnitQuaternion::from_quaternion(q),
            ),
            velocity: Vector3::new(v[7], v[8], v[9]),
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests;
