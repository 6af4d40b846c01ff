//! TUM RGB-D sequence folders as published: index files (`rgb.txt`, `depth.txt`: `timestamp
//! filename`; `groundtruth.txt`: `timestamp tx ty tz qx qy qz qw`, '#' comments), association
//! by nearest timestamp (as TUM's associate.py), ground truth by nearest pose (as evo), pose
//! interpolation, and the frames ([`TumSequence`]). Every error names the file and line.

use std::path::{Path, PathBuf};

use dynaflow_msg::{CameraInfo, DepthImage, Image, SegmentationMask};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

use crate::intrinsics::{Intrinsics, preset_for_folder, read_calibration};
use crate::png::{load_depth, load_rgb, same_size};

use crate::Error;

fn bad(path: &Path, line: usize, message: impl Into<String>) -> Error {
    Error::line(path, line, message.into())
}

/// Data lines of a TUM text file: `(line number, fields)`, comments and blank lines skipped.
fn lines(path: &Path) -> Result<Vec<(usize, Vec<String>)>, Error> {
    let text = std::fs::read(path).map_err(|e| bad(path, 0, e.to_string()))?;
    let text = String::from_utf8(text).map_err(|_| bad(path, 0, "not a text file (invalid UTF-8)"))?;
    // A UTF-8 byte-order mark (some editors write one) is not part of the first line.
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    Ok(text
        .lines()
        .enumerate()
        .filter_map(|(i, l)| {
            let l = l.trim();
            (!l.is_empty() && !l.starts_with('#')).then(|| (i + 1, l.split_whitespace().map(str::to_owned).collect()))
        })
        .collect())
}

fn stamp(path: &Path, line: usize, field: &str) -> Result<f64, Error> {
    number(path, line, field, "timestamp")
}

/// `field` as a finite number; the error names what it should have been (`what`).
fn number(path: &Path, line: usize, field: &str, what: &str) -> Result<f64, Error> {
    field
        .parse::<f64>()
        .ok()
        .filter(|t| t.is_finite())
        .ok_or_else(|| bad(path, line, format!("`{field}` is not a finite number (the {what})")))
}

/// A timestamp for messages: six decimals, or scientific notation where that would print
/// hundreds of digits.
fn show(t: f64) -> String {
    if t.abs() < 1e12 { format!("{t:.6}") } else { format!("{t:e}") }
}

fn check_order(path: &Path, prev: Option<(usize, f64)>, line: usize, t: f64) -> Result<(), Error> {
    match prev {
        Some((pl, pt)) if t == pt => {
            Err(bad(path, line, format!("duplicate timestamp {} (also on line {pl})", show(t))))
        }
        Some((pl, pt)) if t < pt => Err(bad(
            path,
            line,
            format!("timestamp {} is earlier than {} on line {pl}; timestamps must increase", show(t), show(pt)),
        )),
        _ => Ok(()),
    }
}

/// `timestamp filename` lines, in order; timestamps must strictly increase.
pub fn read_index(path: &Path) -> Result<Vec<(f64, String)>, Error> {
    let mut out: Vec<(f64, String)> = Vec::new();
    let mut prev = None;
    for (line, fields) in lines(path)? {
        let [t, file] = fields.as_slice() else {
            return Err(bad(path, line, format!("expected `timestamp filename`, found {} fields", fields.len())));
        };
        let t = stamp(path, line, t)?;
        check_order(path, prev, line, t)?;
        prev = Some((line, t));
        out.push((t, file.clone()));
    }
    if out.is_empty() {
        return Err(bad(path, 0, "no entries"));
    }
    Ok(out)
}

/// A TUM trajectory file: `(stamp, world_from_cam)` in order.
pub fn read_trajectory(path: &Path) -> Result<Vec<(f64, Isometry3<f64>)>, Error> {
    let mut out = Vec::new();
    let mut prev: Option<(usize, f64)> = None;
    let mut duplicates = 0usize;
    for (line, fields) in lines(path)? {
        if fields.len() != 8 {
            return Err(bad(
                path,
                line,
                format!("expected `timestamp tx ty tz qx qy qz qw`, found {} fields", fields.len()),
            ));
        }
        const NAMES: [&str; 8] = ["timestamp", "tx", "ty", "tz", "qx", "qy", "qz", "qw"];
        let v: Vec<f64> =
            fields.iter().zip(NAMES).map(|(f, what)| number(path, line, f, what)).collect::<Result<_, _>>()?;
        // Official TUM ground truth holds equal stamps (100 Hz motion capture written with four
        // decimals): kept, as evo keeps them; only a stamp going back is an error.
        if prev.is_some_and(|(_, t)| t == v[0]) {
            duplicates += 1;
        } else {
            check_order(path, prev, line, v[0])?;
        }
        prev = Some((line, v[0]));
        if v.iter().any(|x| !x.is_finite()) {
            return Err(bad(path, line, "a value is not a finite number"));
        }
        let q = Quaternion::new(v[7], v[4], v[5], v[6]);
        if (q.norm() - 1.0).abs() > 1e-2 {
            return Err(bad(path, line, format!("quaternion norm {:.4} is not 1", q.norm())));
        }
        out.push((
            v[0],
            Isometry3::from_parts(Translation3::new(v[1], v[2], v[3]), UnitQuaternion::from_quaternion(q)),
        ));
    }
    if duplicates > 0 {
        tracing::warn!(
            "{}: {duplicates} poses repeat the previous pose's timestamp; all are kept and associated as evo associates them (nearest stamp; of equal ones, the last)",
            path.display()
        );
    }
    Ok(out)
}

/// An associated RGB-D pair.
#[derive(Clone, Debug, PartialEq)]
pub struct Associated {
    /// Colour timestamp (the frame's stamp).
    pub rgb_stamp: f64,
    /// Colour file, relative to the sequence folder.
    pub rgb: String,
    /// Depth timestamp.
    pub depth_stamp: f64,
    /// Depth file.
    pub depth: String,
}

/// Associate by nearest timestamp within `max_difference`, each entry used at most once,
/// closest pairs first (the algorithm of TUM's `associate.py`), sorted by colour time.
pub fn associate(rgb: &[(f64, String)], depth: &[(f64, String)], max_difference: f64) -> Vec<Associated> {
    let rgb_t: Vec<f64> = rgb.iter().map(|r| r.0).collect();
    let depth_t: Vec<f64> = depth.iter().map(|d| d.0).collect();
    associate_stamps(&rgb_t, &depth_t, max_difference)
        .into_iter()
        .map(|(i, j)| Associated {
            rgb_stamp: rgb[i].0,
            rgb: rgb[i].1.clone(),
            depth_stamp: depth[j].0,
            depth: depth[j].1.clone(),
        })
        .collect()
}

/// [`associate`] on bare stamps (each list in increasing order): the `(colour, depth)` index
/// pairs, by colour stamp. Every source that pairs two streams by time (TUM folders, bags)
/// pairs them with this one rule.
pub fn associate_stamps(rgb: &[f64], depth: &[f64], max_difference: f64) -> Vec<(usize, usize)> {
    let mut candidates: Vec<(f64, usize, usize)> = Vec::new();
    let mut lo = 0;
    for (i, t) in rgb.iter().enumerate() {
        while lo < depth.len() && depth[lo] < t - max_difference {
            lo += 1;
        }
        let mut j = lo;
        while j < depth.len() && depth[j] < t + max_difference {
            candidates.push(((t - depth[j]).abs(), i, j));
            j += 1;
        }
    }
    candidates.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let (mut used_rgb, mut used_depth) = (vec![false; rgb.len()], vec![false; depth.len()]);
    let mut out = Vec::new();
    for (_, i, j) in candidates {
        if used_rgb[i] || used_depth[j] {
            continue;
        }
        used_rgb[i] = true;
        used_depth[j] = true;
        out.push((i, j));
    }
    out.sort_by(|a, b| rgb[a.0].total_cmp(&rgb[b.0]));
    out
}

/// The pose whose stamp is nearest `t`, if within `max_diff` seconds: the association evo
/// (`sync.matching_time_indices`, `--t_max_diff`, default 0.01 s) makes between an estimate
/// and its ground truth, step for step: the insertion point after equal stamps (numpy's
/// `searchsorted(side="right")`), then the later neighbour only if strictly nearer, so on
/// equal distances the earlier pose wins and of equal stamps the last. `traj` is sorted.
pub fn nearest_pose(traj: &[(f64, Isometry3<f64>)], t: f64, max_diff: f64) -> Option<Isometry3<f64>> {
    let (first, last) = (traj.first()?, traj.last()?);
    if t < first.0 - max_diff || t > last.0 + max_diff {
        return None;
    }
    let j = traj.partition_point(|(s, _)| *s <= t).min(traj.len() - 1);
    let upper = traj.get(j)?;
    let lower = j.checked_sub(1).and_then(|k| traj.get(k));
    let (diff_ub, diff_lb) = (upper.0 - t, lower.map_or(f64::INFINITY, |l| t - l.0));
    if diff_ub <= max_diff && diff_ub < diff_lb {
        Some(upper.1)
    } else if diff_lb <= max_diff && diff_lb <= diff_ub {
        lower.map(|l| l.1)
    } else {
        None
    }
}

/// The pose at `t`: linear in translation, slerp in rotation, between the two bracketing
/// poses. `None` when `t` is outside the trajectory by more than `slack` seconds.
pub fn interpolate_pose(traj: &[(f64, Isometry3<f64>)], t: f64, slack: f64) -> Option<Isometry3<f64>> {
    let (first, last) = (traj.first()?, traj.last()?);
    if t < first.0 - slack || t > last.0 + slack {
        return None;
    }
    let i = traj.partition_point(|(s, _)| *s <= t);
    match (i.checked_sub(1).and_then(|k| traj.get(k)), traj.get(i)) {
        (Some(a), Some(b)) => {
            let s = ((t - a.0) / (b.0 - a.0)).clamp(0.0, 1.0);
            let tr: Vector3<f64> = a.1.translation.vector.lerp(&b.1.translation.vector, s);
            let rot = a.1.rotation.try_slerp(&b.1.rotation, s, 1e-9).unwrap_or(a.1.rotation);
            Some(Isometry3::from_parts(Translation3::from(tr), rot))
        }
        (Some(a), None) => Some(a.1),
        (None, Some(b)) => Some(b.1),
        (None, None) => None,
    }
}

/// The ground-truth pose of a frame is the `groundtruth.txt` pose nearest its time within
/// this many seconds: evo's default `--t_max_diff` (and the TUM tools'), so the ATE a run
/// prints is the one `evo_ape tum groundtruth.txt trajectory.txt -a` computes.
pub const GT_MAX_DIFF_S: f64 = 0.01;

/// One frame of a [`TumSequence`].
#[derive(Clone, Debug)]
pub struct TumFrame {
    /// The colour image's time, seconds.
    pub stamp: f64,
    /// Colour image (RGB8, or Gray8 if the file is grey).
    pub rgb: Image,
    /// Depth in metres.
    pub depth: DepthImage,
    /// The intrinsics at the image's size.
    pub camera: CameraInfo,
    /// The class/instance mask from `mask/` and `instance/` (written by `dynaflow synth`).
    pub gt_mask: Option<SegmentationMask>,
    /// The `groundtruth.txt` pose nearest the frame within [`GT_MAX_DIFF_S`].
    pub gt_pose: Option<Isometry3<f64>>,
}

/// An opened TUM RGB-D sequence folder.
#[derive(Debug)]
pub struct TumSequence {
    dir: PathBuf,
    /// Whether the folder has `mask/` (written by `dynaflow synth`): then every frame has one.
    masks: bool,
    /// The first frame's size and colour file.
    size: std::sync::Mutex<Option<((u32, u32), String)>>,
    frames: Vec<Associated>,
    gt: Option<Vec<(f64, Isometry3<f64>)>>,
    intrinsics: Intrinsics,
    depth_factor: f64,
    /// Frames with no ground-truth pose within [`GT_MAX_DIFF_S`] (motion capture drops out
    /// now and then; evo leaves such frames out of the ATE too).
    pub frames_without_pose: usize,
}

/// The intrinsics of a TUM folder: its name (`rgbd_dataset_freiburgN_*`), else its
/// `calibration.txt`.
pub fn folder_intrinsics(dir: &Path) -> Result<Intrinsics, Error> {
    if let Some(preset) = preset_for_folder(dir) {
        return Ok(preset);
    }
    if let Some(calibrated) = read_calibration(dir) {
        return calibrated;
    }
    Err(Error::UnknownCamera { dir: dir.to_path_buf() })
}

impl TumSequence {
    /// Open `dir`: colour and depth associated within `max_difference` seconds (as TUM's
    /// associate.py), at most `frames` frames (0: all), with `intrinsics` (`None`: from the
    /// folder, [`folder_intrinsics`]); depth PNG values are `depth_factor` per metre.
    pub fn open(
        dir: &Path,
        intrinsics: Option<Intrinsics>,
        max_difference: f64,
        depth_factor: f64,
        frames: usize,
    ) -> Result<Self, Error> {
        if !dir.is_dir() {
            return Err(Error::file(dir, "not a folder"));
        }
        let intrinsics = match intrinsics {
            Some(k) => k,
            None => folder_intrinsics(dir)?,
        };
        for file in ["rgb.txt", "depth.txt"] {
            if !dir.join(file).is_file() {
                return Err(Error::file(
                    &dir.join(file),
                    "missing (a TUM RGB-D folder has rgb.txt, depth.txt and rgb/, depth/)",
                ));
            }
        }
        let rgb = read_index(&dir.join("rgb.txt"))?;
        let depth = read_index(&dir.join("depth.txt"))?;
        let mut associated = associate(&rgb, &depth, max_difference);
        if associated.is_empty() {
            return Err(Error::file(
                dir,
                format!(
                    "no colour frame has a depth frame within {max_difference} s (rgb.txt {:.3}..{:.3}, depth.txt {:.3}..{:.3})",
                    rgb.first().map_or(0.0, |r| r.0),
                    rgb.last().map_or(0.0, |r| r.0),
                    depth.first().map_or(0.0, |r| r.0),
                    depth.last().map_or(0.0, |r| r.0)
                ),
            ));
        }
        if frames > 0 {
            associated.truncate(frames);
        }
        let gt_path = dir.join("groundtruth.txt");
        let gt = if gt_path.is_file() { Some(read_trajectory(&gt_path)?) } else { None };
        let mut frames_without_pose = 0;
        if let Some(gt) = &gt {
            frames_without_pose =
                associated.iter().filter(|f| nearest_pose(gt, f.rgb_stamp, GT_MAX_DIFF_S).is_none()).count();
            if frames_without_pose == associated.len() {
                return Err(Error::file(
                    &gt_path,
                    format!(
                        "no pose within {GT_MAX_DIFF_S} s of any frame (ground truth {:.6}..{:.6}, frames {:.6}..{:.6})",
                        gt.first().map_or(0.0, |g| g.0),
                        gt.last().map_or(0.0, |g| g.0),
                        associated.first().map_or(0.0, |f| f.rgb_stamp),
                        associated.last().map_or(0.0, |f| f.rgb_stamp),
                    ),
                ));
            }
        }
        Ok(Self {
            masks: dir.join("mask").is_dir(),
            size: std::sync::Mutex::new(None),
            dir: dir.to_path_buf(),
            frames: associated,
            gt,
            intrinsics,
            depth_factor,
            frames_without_pose,
        })
    }

    /// The folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// Whether the sequence has no frame (never, once opened).
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// Frame `index`, `None` past the end. Errors name the file (relative to the folder).
    pub fn frame(&self, index: usize) -> Result<Option<TumFrame>, Error> {
        let Some(f) = self.frames.get(index) else { return Ok(None) };
        let rgb = load_rgb(&self.dir.join(&f.rgb))?;
        let depth = load_depth(&self.dir.join(&f.depth), self.depth_factor)?;
        let rgb_size = (rgb.width, rgb.height);
        // Every frame of a sequence has the first frame's size (the intrinsics are the first's).
        {
            let mut first = self.size.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            let ((w, h), name) = first.get_or_insert_with(|| (rgb_size, f.rgb.clone()));
            if (*w, *h) != rgb_size {
                return Err(Error::Data(format!(
                    "{}: {}x{} but the sequence's first frame ({name}) is {w}x{h}",
                    f.rgb, rgb.width, rgb.height
                )));
            }
        }
        same_size(&f.depth, (depth.width, depth.height), &f.rgb, rgb_size)?;
        let camera = self.intrinsics.camera_info(rgb.width, rgb.height);
        let mut gt_mask = None;
        let mask_path = self.dir.join("mask").join(Path::new(&f.rgb).file_name().unwrap_or_default());
        if self.masks && !mask_path.is_file() {
            return Err(Error::file(&mask_path, "missing (the folder has `mask/`, so every frame needs its mask)"));
        }
        if self.masks {
            let classes = load_rgb(&mask_path)?;
            let inst_path = self.dir.join("instance").join(Path::new(&f.rgb).file_name().unwrap_or_default());
            let instances = if inst_path.is_file() {
                Some(load_rgb(&inst_path)?.data.into_iter().map(u16::from).collect())
            } else {
                None
            };
            if classes.format != dynaflow_msg::PixelFormat::Gray8 {
                return Err(Error::file(&mask_path, "expected an 8-bit grey class mask"));
            }
            same_size(mask_path.display(), (classes.width, classes.height), &f.rgb, rgb_size)?;
            let mask = SegmentationMask {
                width: classes.width,
                height: classes.height,
                classes: classes.data.into_iter().map(u16::from).collect(),
                instances,
                class_names: vec!["static".into(), "person".into()],
            };
            gt_mask = Some(mask);
        }
        let gt_pose = self.gt.as_ref().and_then(|gt| nearest_pose(gt, f.rgb_stamp, GT_MAX_DIFF_S));
        Ok(Some(TumFrame { stamp: f.rgb_stamp, rgb, depth, camera, gt_mask, gt_pose }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_say_what_is_wrong_where() {
        // Defect 10.
        let dir = std::env::temp_dir().join(format!("dynaflow-index-msg-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = |name: &str, text: &str| {
            let p = dir.join(name);
            std::fs::write(&p, text).unwrap();
            p
        };
        // A byte-order mark is accepted.
        let p = file("bom.txt", "\u{feff}1.0 rgb/1.png\n2.0 rgb/2.png\n");
        assert_eq!(read_index(&p).unwrap().len(), 2);
        // A NaN in a pose field names the field, not a timestamp.
        let p = file("nan.txt", "1.0 0 0 0 nan 0 0 1\n");
        let e = read_trajectory(&p).unwrap_err().to_string();
        assert!(e.ends_with("nan.txt:1: `nan` is not a finite number (the qx)"), "{e}");
        // A whole-file problem has no line number.
        let e = read_trajectory(&dir.join("absent.txt")).unwrap_err().to_string();
        assert!(e.contains("absent.txt: ") && !e.contains(":0:"), "{e}");
        // A huge timestamp is printed in scientific notation, not as 300 digits.
        let p = file("huge.txt", "1e300 rgb/1.png\n1.0 rgb/2.png\n");
        let e = read_index(&p).unwrap_err().to_string();
        assert!(e.contains("earlier than 1e300") && e.len() < 200, "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn nearest_pose_is_evos_association() {
        let at = |x: f64| Isometry3::from_parts(Translation3::new(x, 0.0, 0.0), nalgebra::UnitQuaternion::identity());
        let traj: Vec<(f64, Isometry3<f64>)> = [1.0, 1.01, 1.02, 1.05].iter().map(|&t| (t, at(t))).collect();
        let x = |t: f64, d: f64| nearest_pose(&traj, t, d).map(|p| p.translation.vector.x);
        assert_eq!(x(1.004, 0.01), Some(1.0));
        assert_eq!(x(1.006, 0.01), Some(1.01));
        // A tie takes the earlier pose (numpy's argmin).
        assert_eq!(x(1.035, 0.02), Some(1.02));
        // Nothing within max_diff: no pose (evo leaves the estimate unmatched).
        assert_eq!(x(1.035, 0.01), None);
        assert_eq!(x(0.98, 0.01), None);
        assert_eq!(x(1.059, 0.01), Some(1.05));
        assert_eq!(nearest_pose(&[], 1.0, 1.0), None);
        // Equal stamps: an exact match takes the last of them, as evo's association does.
        let dup: Vec<(f64, Isometry3<f64>)> = vec![(1.0, at(1.0)), (1.0, at(2.0)), (1.01, at(3.0))];
        assert_eq!(nearest_pose(&dup, 1.0, 0.01).map(|p| p.translation.vector.x), Some(2.0));
        assert_eq!(nearest_pose(&dup, 1.004, 0.01).map(|p| p.translation.vector.x), Some(2.0));
    }

    fn list(ts: &[f64]) -> Vec<(f64, String)> {
        ts.iter().map(|t| (*t, format!("{t}.png"))).collect()
    }

    #[test]
    fn association_is_greedy_closest_first_and_one_to_one() {
        let rgb = list(&[1.00, 1.03, 1.07, 2.0]);
        let depth = list(&[1.01, 1.02, 1.08]);
        let a = associate(&rgb, &depth, 0.02);
        let pairs: Vec<(f64, f64)> = a.iter().map(|x| (x.rgb_stamp, x.depth_stamp)).collect();
        assert_eq!(pairs, vec![(1.00, 1.01), (1.03, 1.02), (1.07, 1.08)]);
    }

    #[test]
    fn interpolation_is_linear_and_bounded() {
        let traj = vec![(0.0, Isometry3::translation(0.0, 0.0, 0.0)), (1.0, Isometry3::translation(2.0, 0.0, 0.0))];
        let p = interpolate_pose(&traj, 0.25, 0.0).unwrap();
        assert!((p.translation.x - 0.5).abs() < 1e-12);
        assert!(interpolate_pose(&traj, 1.5, 0.1).is_none());
    }
}
