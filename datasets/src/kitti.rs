//! KITTI odometry sequence folders: `calib.txt` (projection matrices P0..P3), `times.txt`, the
//! grey (`image_0`/`image_1`) or colour (`image_2`/`image_3`) rectified stereo pair, and the
//! ground-truth poses (`poses/NN.txt` two folders up, or a file given). Poses are of the left
//! camera of the chosen pair. Every error names the file and line.

use std::path::{Path, PathBuf};

use dynaflow_msg::{CameraInfo, Image};
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::Error;
use crate::intrinsics::Intrinsics;
use crate::png::{load_rgb, same_size};

/// Which stereo pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pair {
    /// `image_0`/`image_1`.
    Gray,
    /// `image_2`/`image_3`.
    Color,
}

/// Where the ground-truth poses come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Poses<'a> {
    /// `../../poses/<sequence>.txt` if present.
    Auto,
    /// None.
    None,
    /// This file.
    File(&'a Path),
}

fn input(path: &Path, line: usize, message: impl std::fmt::Display) -> Error {
    Error::line(path, line, message)
}

fn numbers(path: &Path, line: usize, text: &str) -> Result<Vec<f64>, Error> {
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
fn read_calib(path: &Path) -> Result<[[f64; 12]; 4], Error> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, e))?;
    let mut p = [[f64::NAN; 12]; 4];
    let mut defined = [0usize; 4];
    for (i, line) in text.lines().enumerate() {
        let Some((key, rest)) = line.split_once(':') else { continue };
        let Some(k) = ["P0", "P1", "P2", "P3"].iter().position(|n| *n == key.trim()) else { continue };
        if defined[k] > 0 {
            return Err(input(path, i + 1, format!("{} is defined twice (first on line {})", key.trim(), defined[k])));
        }
        defined[k] = i + 1;
        let v = numbers(path, i + 1, rest)?;
        let slot = p.get_mut(k).ok_or_else(|| input(path, i + 1, "bad key"))?;
        *slot = v
            .try_into()
            .map_err(|v: Vec<f64>| input(path, i + 1, format!("{key} has {} numbers, expected 12", v.len())))?;
    }
    Ok(p)
}

fn read_poses(path: &Path) -> Result<Vec<Isometry3<f64>>, Error> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, e))?;
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

/// One stereo frame.
#[derive(Clone, Debug)]
pub struct KittiFrame {
    /// `times.txt`'s time, seconds.
    pub stamp: f64,
    /// Left rectified image.
    pub left: Image,
    /// Right rectified image.
    pub right: Image,
    /// Left camera intrinsics (rectified, no distortion) at the image's size.
    pub camera: CameraInfo,
    /// Ground-truth `world_from_cam` of the left camera, when poses are available.
    pub gt_pose: Option<Isometry3<f64>>,
}

/// An opened KITTI odometry sequence.
#[derive(Debug)]
pub struct KittiSequence {
    dir: PathBuf,
    dirs: (String, String),
    times: Vec<f64>,
    poses: Option<Vec<Isometry3<f64>>>,
    intrinsics: Intrinsics,
    /// Stereo baseline, metres.
    pub baseline: f64,
    /// The first left image's size: every frame must have it (the intrinsics are for it).
    size: (u32, u32),
}

impl KittiSequence {
    /// Open the sequence folder `dir` (at most `frames` frames; 0: all).
    pub fn open(dir: &Path, pair: Pair, poses: Poses<'_>, frames: usize) -> Result<Self, Error> {
        let calib_path = dir.join("calib.txt");
        let times_path = dir.join("times.txt");
        for f in [&calib_path, &times_path] {
            if !f.is_file() {
                return Err(Error::file(
                    f,
                    "missing (a KITTI odometry sequence has calib.txt, times.txt and image_0/)",
                ));
            }
        }
        let calib = read_calib(&calib_path)?;
        let (li, ri) = match pair {
            Pair::Color => (2, 3),
            Pair::Gray => (0, 1),
        };
        let (pl, pr) = (calib[li], calib[ri]);
        if pl.iter().chain(&pr).any(|v| v.is_nan()) {
            return Err(Error::file(&calib_path, format!("needs P{li} and P{ri}")));
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
        // A rectified pair shares one camera matrix: the right camera's fx, fy, cx, cy are
        // the left's (KITTI's calib.txt writes them identically).
        let right_name = format!("P{ri}");
        let right_error = |message: String| input(&calib_path, calib_line(&calib_path, &right_name), message);
        for (what, l, r) in [("fx", pl[0], pr[0]), ("fy", pl[5], pr[5]), ("cx", pl[2], pr[2]), ("cy", pl[6], pr[6])] {
            if (l - r).abs() > 1e-6 * l.abs().max(1.0) {
                return Err(right_error(format!(
                    "{right_name}: {what} = {r} differs from P{li}'s {l}: a rectified pair shares one camera matrix"
                )));
            }
        }
        // P = K [I | t] with K's fx on the diagonal: t_x = P[3] / fx relative to camera 0.
        let baseline = (pl[3] - pr[3]) / fx;
        if baseline.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return Err(right_error(format!(
                "{right_name} gives a baseline of {baseline} m from P{li}: the right camera must be to the right of the left one (P{ri}[3] < P{li}[3])"
            )));
        }
        let left_offset = Vector3::new(pl[3] / fx, pl[7] / fx, pl[11]);
        let times_text = std::fs::read_to_string(&times_path).map_err(|e| Error::file(&times_path, e))?;
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
            return Err(Error::file(&times_path, "no frame (the file has no time)"));
        }
        // One time per image: a times.txt shorter or longer than the image folder would run a
        // part of the sequence without a word.
        let (li_dir, ri_dir) = (dir.join(format!("image_{li}")), dir.join(format!("image_{ri}")));
        for d in [&li_dir, &ri_dir] {
            if let Some(missing) = (0..times.len()).map(|i| d.join(format!("{i:06}.png"))).find(|p| !p.is_file()) {
                return Err(Error::file(
                    &missing,
                    format!("missing: {} has {} times, one per image", times_path.display(), times.len()),
                ));
            }
            let images = std::fs::read_dir(d)
                .map_err(|e| Error::file(d, e))?
                .filter_map(Result::ok)
                .filter(|e| e.path().extension().is_some_and(|x| x == "png"))
                .count();
            if images != times.len() {
                return Err(Error::file(
                    &times_path,
                    format!("{} times for {images} images in {}: one time per image", times.len(), d.display()),
                ));
            }
        }
        let first = li_dir.join("000000.png");
        let size = image::image_dimensions(&first).map_err(|e| Error::file(&first, e))?;
        if frames > 0 {
            times.truncate(frames);
        }
        let pose_path: Option<PathBuf> = match poses {
            Poses::None => None,
            Poses::Auto => {
                let seq = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
                dir.parent()
                    .and_then(Path::parent)
                    .map(|root| root.join("poses").join(format!("{seq}.txt")))
                    .filter(|p| p.is_file())
            }
            Poses::File(p) => Some(p.to_path_buf()),
        };
        let poses = match &pose_path {
            Some(p) => {
                let poses = read_poses(p)?;
                if poses.len() != times.len() {
                    return Err(Error::file(
                        p,
                        format!("{} poses for {} frames in times.txt", poses.len(), times.len()),
                    ));
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
        Ok(Self {
            dir: dir.to_path_buf(),
            dirs: (format!("image_{li}"), format!("image_{ri}")),
            times,
            poses,
            intrinsics: Intrinsics::pinhole(fx, pl[5], pl[2], pl[6]),
            baseline,
            size,
        })
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.times.len()
    }

    /// Whether the sequence has no frame (never, once opened).
    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }

    /// Frame `index`, `None` past the end.
    pub fn frame(&self, index: usize) -> Result<Option<KittiFrame>, Error> {
        let Some(&stamp) = self.times.get(index) else { return Ok(None) };
        let name = format!("{index:06}.png");
        let (left_path, right_path) =
            (self.dir.join(&self.dirs.0).join(&name), self.dir.join(&self.dirs.1).join(&name));
        let left = load_rgb(&left_path)?;
        let right = load_rgb(&right_path)?;
        same_size(right_path.display(), (right.width, right.height), left_path.display(), (left.width, left.height))?;
        same_size(left_path.display(), (left.width, left.height), "the sequence's first image", self.size)?;
        let camera = self.intrinsics.camera_info(left.width, left.height);
        let gt_pose = self.poses.as_ref().and_then(|p| p.get(index)).copied();
        Ok(Some(KittiFrame { stamp, left, right, camera, gt_pose }))
    }
}
