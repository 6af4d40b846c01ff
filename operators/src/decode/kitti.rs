//! `kitti_odometry`: a KITTI odometry sequence folder (`calib.txt`, `times.txt`,
//! `image_0/`+`image_1/` grey or `image_2/`+`image_3/` colour, optional poses).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use dynaflow_engine::msg::{Body, CameraInfo, Header, PortType, Pose, Scalars};
use dynaflow_engine::op::{
    Context, Default, Instance, OpError, OpKind, OpSpec, Outputs, ParamSpec, ParamType, Params, PortSpec, Source,
};
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

use super::png::{load_rgb, same_size};

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Config {
    path: String,
    camera: String,
    poses: String,
    frames: u64,
}

pub(crate) const KITTI_ODOMETRY: OpSpec = OpSpec {
    name: "kitti_odometry",
    family: "decode",
    doc: "Reads a KITTI odometry sequence folder: `calib.txt` (projection matrices P0..P3), `times.txt`, the grey (`image_0`/`image_1`) or colour (`image_2`/`image_3`) rectified stereo pair, and the ground-truth poses (`poses/NN.txt` two folders up, or `poses`). Poses are of the left camera of the chosen pair.",
    kind: OpKind::Source,
    inputs: &[],
    outputs: &[
        PortSpec::output("left", PortType::Image, "left rectified image"),
        PortSpec::output("right", PortType::Image, "right rectified image"),
        PortSpec::output("camera_info", PortType::CameraInfo, "left camera intrinsics (rectified, no distortion)"),
        PortSpec::output("stereo", PortType::Scalars, "`baseline_m`: stereo baseline in metres"),
        PortSpec::ground_truth(
            "gt_pose",
            PortType::Pose,
            "ground-truth world_from_cam of the left camera, when poses are available",
        ),
    ],
    params: &[
        ParamSpec {
            name: "path",
            ty: ParamType::Path,
            default: Default::Required,
            doc: "sequence folder (e.g. `dataset/sequences/00`)",
        },
        ParamSpec {
            name: "camera",
            ty: ParamType::Enum { values: &["gray", "color"] },
            default: Default::Str("gray"),
            doc: "`gray`: image_0/image_1, `color`: image_2/image_3",
        },
        ParamSpec {
            name: "poses",
            ty: ParamType::Str,
            default: Default::Str("auto"),
            doc: "pose file; `auto`: `../../poses/<sequence>.txt` if present; `none`",
        },
        ParamSpec {
            name: "frames",
            ty: ParamType::Int { min: 0, max: i64::MAX },
            default: Default::Int(0),
            doc: "read at most this many frames (0 = all)",
        },
    ],
    cpu_heavy: true,
    ground_truth_outputs: None,
    build,
};

fn input(path: &Path, line: usize, message: impl std::fmt::Display) -> OpError {
    OpError::Input(format!("{}:{line}: {message}", path.display()))
}

fn numbers(path: &Path, line: usize, text: &str) -> Result<Vec<f64>, OpError> {
    text.split_whitespace()
        .map(|s| {
            s.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| input(path, line, format!("`{s}` is not a number")))
        })
        .collect()
}

/// The line of `calib.txt` that defines `key` (1-based; 0 when absent).
fn calib_line(path: &Path, key: &str) -> usize {
    std::fs::read_to_string(path)
        .ok()
        .and_then(|t| t.lines().position(|l| l.split_once(':').is_some_and(|(k, _)| k.trim() == key)))
        .map_or(0, |i| i + 1)
}

/// `P0`..`P3` from `calib.txt`.
fn read_calib(path: &Path) -> Result<[[f64; 12]; 4], OpError> {
    let text = std::fs::read_to_string(path).map_err(|source| OpError::Io { path: path.to_path_buf(), source })?;
    let mut p = [[f64::NAN; 12]; 4];
    for (i, line) in text.lines().enumerate() {
        let Some((key, rest)) = line.split_once(':') else { continue };
        let Some(k) = ["P0", "P1", "P2", "P3"].iter().position(|n| *n == key.trim()) else { continue };
        let v = numbers(path, i + 1, rest)?;
        let slot = p.get_mut(k).ok_or_else(|| input(path, i + 1, "bad key"))?;
        *slot = v
            .try_into()
            .map_err(|v: Vec<f64>| input(path, i + 1, format!("{key} has {} numbers, expected 12", v.len())))?;
    }
    Ok(p)
}

fn read_poses(path: &Path) -> Result<Vec<Isometry3<f64>>, OpError> {
    let text = std::fs::read_to_string(path).map_err(|source| OpError::Io { path: path.to_path_buf(), source })?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let v = numbers(path, i + 1, line)?;
        let [r00, r01, r02, tx, r10, r11, r12, ty, r20, r21, r22, tz] = v[..] else {
            return Err(input(path, i + 1, format!("expected 12 numbers (a 3×4 matrix), found {}", v.len())));
        };
        let r = Matrix3::new(r00, r01, r02, r10, r11, r12, r20, r21, r22);
        // A pose's 3x3 part must be a rotation (orthonormal, determinant +1), to the
        // precision the benchmark writes (about 6 significant digits).
        let off = (r.transpose() * r - Matrix3::identity()).abs().max();
        if off > 1e-3 || (r.determinant() - 1.0).abs() > 1e-3 {
            return Err(input(
                path,
                i + 1,
                format!("the 3x3 part is not a rotation (|R^T R - I| {off:.2e}, det {:.6})", r.determinant()),
            ));
        }
        let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_eps(
            &r,
            f64::EPSILON,
            100,
            Rotation3::identity(),
        ));
        out.push(Isometry3::from_parts(Translation3::new(tx, ty, tz), rot));
    }
    Ok(out)
}

fn build(params: &Params) -> Result<Instance, OpError> {
    let c: Config = params.parse()?;
    let dir = params.resolve_path(&c.path);
    let calib_path = dir.join("calib.txt");
    let times_path = dir.join("times.txt");
    for f in [&calib_path, &times_path] {
        if !f.is_file() {
            return Err(OpError::Input(format!(
                "{}: missing (a KITTI odometry sequence has calib.txt, times.txt and image_0/)",
                f.display()
            )));
        }
    }
    let calib = read_calib(&calib_path)?;
    let (li, ri) = if c.camera == "color" { (2, 3) } else { (0, 1) };
    let (pl, pr) = (calib[li], calib[ri]);
    if pl.iter().chain(&pr).any(|v| v.is_nan()) {
        return Err(OpError::Input(format!("{}: needs P{li} and P{ri}", calib_path.display())));
    }
    let fx = pl[0];
    // Focal lengths and principal points must be positive, as the TUM reader requires.
    for (name, p) in [(format!("P{li}"), &pl), (format!("P{ri}"), &pr)] {
        for (what, v) in [("fx", p[0]), ("fy", p[5]), ("cx", p[2]), ("cy", p[6])] {
            if v.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                let line = calib_line(&calib_path, &name);
                return Err(input(&calib_path, line, format!("{name}: {what} = {v} must be positive")));
            }
        }
    }
    // P = K [I | t] with K's fx on the diagonal: t_x = P[3] / fx relative to camera 0.
    let baseline = (pl[3] - pr[3]) / fx;
    let left_offset = Vector3::new(pl[3] / fx, pl[7] / fx, pl[11]);
    let times_text =
        std::fs::read_to_string(&times_path).map_err(|source| OpError::Io { path: times_path.clone(), source })?;
    let mut times = Vec::new();
    for (i, line) in times_text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let t: f64 = line
            .trim()
            .parse()
            .ok()
            .filter(|t: &f64| t.is_finite())
            .ok_or_else(|| input(&times_path, i + 1, format!("`{}` is not a time", line.trim())))?;
        if times.last().is_some_and(|p| t <= *p) {
            return Err(input(&times_path, i + 1, "times must increase"));
        }
        times.push(t);
    }
    if times.is_empty() {
        return Err(OpError::Input(format!("{}: no frame (the file has no time)", times_path.display())));
    }
    if c.frames > 0 {
        times.truncate(c.frames as usize);
    }
    let pose_path: Option<PathBuf> = match c.poses.as_str() {
        "none" => None,
        "auto" => {
            let seq = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            dir.parent()
                .and_then(Path::parent)
                .map(|root| root.join("poses").join(format!("{seq}.txt")))
                .filter(|p| p.is_file())
        }
        explicit => Some(params.resolve_path(explicit)),
    };
    let poses = match &pose_path {
        Some(p) => {
            let poses = read_poses(p)?;
            if poses.len() < times.len() {
                return Err(OpError::Input(format!(
                    "{}: {} poses for {} frames in times.txt",
                    p.display(),
                    poses.len(),
                    times.len()
                )));
            }
            // Poses are of camera 0; move them to the chosen left camera.
            Some(
                poses
                    .into_iter()
                    .map(|w0| w0 * Isometry3::translation(-left_offset.x, -left_offset.y, -left_offset.z))
                    .collect(),
            )
        }
        None => None,
    };
    let info = CameraInfo { width: 0, height: 0, fx, fy: pl[5], cx: pl[2], cy: pl[6], distortion: [0.0; 5] };
    Ok(Instance::Source(Box::new(Kitti {
        dir,
        dirs: (format!("image_{li}"), format!("image_{ri}")),
        times,
        poses,
        info,
        baseline,
        frame_id: "camera".into(),
    })))
}

struct Kitti {
    dir: PathBuf,
    dirs: (String, String),
    times: Vec<f64>,
    poses: Option<Vec<Isometry3<f64>>>,
    info: CameraInfo,
    baseline: f64,
    frame_id: Arc<str>,
}

impl Source for Kitti {
    fn next(&mut self, _ctx: &mut Context, seq: u64) -> Result<Option<Outputs>, OpError> {
        let Some(&stamp) = self.times.get(seq as usize) else { return Ok(None) };
        let name = format!("{seq:06}.png");
        let (left_path, right_path) =
            (self.dir.join(&self.dirs.0).join(&name), self.dir.join(&self.dirs.1).join(&name));
        let left = load_rgb(&left_path).map_err(OpError::Input)?;
        let right = load_rgb(&right_path).map_err(OpError::Input)?;
        same_size(right_path.display(), (right.width, right.height), left_path.display(), (left.width, left.height))
            .map_err(OpError::Input)?;
        let header = Header { seq, stamp, frame_id: self.frame_id.clone() };
        let info = CameraInfo { width: left.width, height: left.height, ..self.info.clone() };
        let mut out = Outputs::new()
            .with("left", header.clone(), Body::Image(left))
            .with("right", header.clone(), Body::Image(right))
            .with("camera_info", header.clone(), Body::CameraInfo(info))
            .with("stereo", header.clone(), Body::Scalars(Scalars::one("baseline_m", self.baseline)));
        if let Some(p) = self.poses.as_ref().and_then(|p| p.get(seq as usize)) {
            out.push("gt_pose", Header { frame_id: "world".into(), ..header }, Body::Pose(Pose { world_from_cam: *p }));
        }
        Ok(Some(out))
    }

    fn len_hint(&self) -> Option<u64> {
        Some(self.times.len() as u64)
    }
}
