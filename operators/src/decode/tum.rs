//! `tum_rgbd`: reads a TUM RGB-D sequence folder as it is.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use dynaflow_engine::msg::{Body, CameraInfo, Header, PortType, Pose};
use dynaflow_engine::op::{
    Context, Default, Instance, OpError, OpKind, OpSpec, Outputs, ParamSpec, ParamType, Params, PortSpec, Source,
};
use nalgebra::Isometry3;

use super::index::{Associated, associate, nearest_pose, read_index, read_trajectory};
use super::intrinsics::{Intrinsics, preset_for_folder, read_calibration};
use super::png::{load_depth, load_rgb, same_size};

/// Ground truth may end this long before/after a frame and still be used (TUM's mocap runs at
/// 100 Hz; its ends can miss the first or last frame by a few ms).
/// The ground-truth pose of a frame is the `groundtruth.txt` pose nearest its time within
/// this many seconds: evo's default `--t_max_diff` (and the TUM tools'), so the ATE a run
/// prints is the one `evo_ape tum groundtruth.txt trajectory.txt -a` computes.
const GT_MAX_DIFF_S: f64 = 0.01;

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Config {
    path: String,
    intrinsics: String,
    max_difference: f64,
    depth_factor: f64,
    on_error: String,
    frames: u64,
}

pub(crate) const TUM_RGBD: OpSpec = OpSpec {
    name: "tum_rgbd",
    family: "decode",
    doc: "Reads a TUM RGB-D sequence folder as published: `rgb.txt`, `depth.txt` and optional `groundtruth.txt` ('#' comments), associating colour and depth by nearest timestamp within `max_difference` (as TUM's associate.py). Ground truth is interpolated at each colour timestamp. Bad input names the file and line; with `on_error: skip` unreadable frames are skipped, counted and logged.",
    kind: OpKind::Source,
    inputs: &[],
    outputs: &[
        PortSpec::output("rgb", PortType::Image, "colour image (RGB8, or Gray8 if the file is grey)"),
        PortSpec::output("depth", PortType::Depth, "depth in metres (value / depth_factor)"),
        PortSpec::output("camera_info", PortType::CameraInfo, "intrinsics with distortion"),
        PortSpec::ground_truth(
            "gt_pose",
            PortType::Pose,
            "ground-truth world_from_cam: the groundtruth.txt pose nearest the frame time within 10 ms, as evo associates (absent where none is)",
        ),
        PortSpec::ground_truth(
            "gt_mask",
            PortType::Mask,
            "ground-truth class/instance mask from `mask/` and `instance/` (written by `dynaflow synth`; absent for real TUM data)",
        ),
    ],
    params: &[
        ParamSpec { name: "path", ty: ParamType::Path, default: Default::Required, doc: "sequence folder" },
        ParamSpec {
            name: "intrinsics",
            ty: ParamType::Str,
            default: Default::Str("auto"),
            doc: "`auto` (from the folder name `rgbd_dataset_freiburgN_*`, else `calibration.txt`), `fr1`, `fr2`, `fr3`, `fx,fy,cx,cy` or `fx,fy,cx,cy,k1,k2,p1,p2,k3`",
        },
        ParamSpec {
            name: "max_difference",
            ty: ParamType::Float { min: 0.0, max: 1.0 },
            default: Default::Float(0.02),
            doc: "largest colour/depth time difference to associate, seconds",
        },
        ParamSpec {
            name: "depth_factor",
            ty: ParamType::Float { min: 1e-6, max: 1e9 },
            default: Default::Float(5000.0),
            doc: "depth PNG value per metre",
        },
        ParamSpec {
            name: "on_error",
            ty: ParamType::Enum { values: &["fail", "skip"] },
            default: Default::Str("fail"),
            doc: "unreadable frame or missing ground truth: fail the run, or skip the frame (counted, logged)",
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

fn resolve_intrinsics(dir: &Path, spec: &str) -> Result<Intrinsics, OpError> {
    let config = |message: String| OpError::Config { key: "intrinsics".into(), message };
    if spec != "auto" {
        return Intrinsics::parse(spec).map_err(config);
    }
    if let Some(preset) = preset_for_folder(dir) {
        return Ok(preset);
    }
    if let Some(calibrated) = read_calibration(dir) {
        return calibrated;
    }
    Err(config(format!(
        "{}: cannot tell the camera: the folder is not named `rgbd_dataset_freiburgN_*` and has no calibration.txt; set `intrinsics: fr1|fr2|fr3|fx,fy,cx,cy` (or `--intrinsics`)",
        dir.display()
    )))
}

fn build(params: &Params) -> Result<Instance, OpError> {
    let c: Config = params.parse()?;
    let dir = params.resolve_path(&c.path);
    if !dir.is_dir() {
        return Err(OpError::Input(format!("{}: not a folder", dir.display())));
    }
    let intrinsics = resolve_intrinsics(&dir, &c.intrinsics)?;
    let input = |e: super::index::IndexError| OpError::Input(e.to_string());
    for file in ["rgb.txt", "depth.txt"] {
        if !dir.join(file).is_file() {
            return Err(OpError::Input(format!(
                "{}: missing (a TUM RGB-D folder has rgb.txt, depth.txt and rgb/, depth/)",
                dir.join(file).display()
            )));
        }
    }
    let rgb = read_index(&dir.join("rgb.txt")).map_err(input)?;
    let depth = read_index(&dir.join("depth.txt")).map_err(input)?;
    let mut frames = associate(&rgb, &depth, c.max_difference);
    if frames.is_empty() {
        return Err(OpError::Input(format!(
            "{}: no colour frame has a depth frame within {} s (rgb.txt {:.3}..{:.3}, depth.txt {:.3}..{:.3})",
            dir.display(),
            c.max_difference,
            rgb.first().map_or(0.0, |r| r.0),
            rgb.last().map_or(0.0, |r| r.0),
            depth.first().map_or(0.0, |r| r.0),
            depth.last().map_or(0.0, |r| r.0)
        )));
    }
    if c.frames > 0 {
        frames.truncate(c.frames as usize);
    }
    let gt_path = dir.join("groundtruth.txt");
    let gt = if gt_path.is_file() { Some(read_trajectory(&gt_path).map_err(input)?) } else { None };
    let skip = c.on_error == "skip";
    if let Some(gt) = &gt {
        // Motion capture drops out now and then: such frames have no ground truth (evo leaves
        // them out of the ATE too), said once here; none at all is an error.
        let without = frames.iter().filter(|f| nearest_pose(gt, f.rgb_stamp, GT_MAX_DIFF_S).is_none()).count();
        if without == frames.len() {
            return Err(OpError::Input(format!(
                "{}: no pose within {GT_MAX_DIFF_S} s of any frame (ground truth {:.6}..{:.6}, frames {:.6}..{:.6})",
                gt_path.display(),
                gt.first().map_or(0.0, |g| g.0),
                gt.last().map_or(0.0, |g| g.0),
                frames.first().map_or(0.0, |f| f.rgb_stamp),
                frames.last().map_or(0.0, |f| f.rgb_stamp),
            )));
        }
        if without > 0 {
            tracing::warn!(
                "{}: {without} of {} frames have no pose within {GT_MAX_DIFF_S} s; they have no `gt_pose` and are left out of the ATE, as evo leaves them",
                gt_path.display(),
                frames.len()
            );
        }
    }
    Ok(Instance::Source(Box::new(TumSource {
        masks: dir.join("mask").is_dir(),
        size: std::cell::RefCell::new(None),
        dir,
        frames,
        gt,
        intrinsics,
        factor: c.depth_factor,
        skip,
        skipped: Vec::new(),
        frame_id: "camera".into(),
    })))
}

struct TumSource {
    dir: PathBuf,
    /// Whether the folder has `mask/` (written by `dynaflow synth`): then every frame has one.
    masks: bool,
    /// The first frame's size and colour file.
    size: std::cell::RefCell<Option<((u32, u32), String)>>,
    frames: Vec<Associated>,
    gt: Option<Vec<(f64, Isometry3<f64>)>>,
    intrinsics: Intrinsics,
    factor: f64,
    skip: bool,
    skipped: Vec<String>,
    frame_id: Arc<str>,
}

impl TumSource {
    fn load(&self, seq: u64, f: &Associated) -> Result<Outputs, String> {
        let rgb = load_rgb(&self.dir.join(&f.rgb))?;
        let depth = load_depth(&self.dir.join(&f.depth), self.factor)?;
        let rgb_size = (rgb.width, rgb.height);
        // Every frame of a sequence has the first frame's size (the intrinsics are the first's).
        {
            let mut first = self.size.borrow_mut();
            let ((w, h), name) = first.get_or_insert_with(|| (rgb_size, f.rgb.clone()));
            if (*w, *h) != rgb_size {
                return Err(format!(
                    "{}: {}x{} but the sequence's first frame ({name}) is {w}x{h}",
                    f.rgb, rgb.width, rgb.height
                ));
            }
        }
        same_size(&f.depth, (depth.width, depth.height), &f.rgb, rgb_size)?;
        let header = Header { seq, stamp: f.rgb_stamp, frame_id: self.frame_id.clone() };
        let k = &self.intrinsics;
        let info = CameraInfo {
            width: rgb.width,
            height: rgb.height,
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
            distortion: k.distortion,
        };
        let mut out = Outputs::new()
            .with("rgb", header.clone(), Body::Image(rgb))
            .with("depth", header.clone(), Body::Depth(depth))
            .with("camera_info", header.clone(), Body::CameraInfo(info));
        let mask_path = self.dir.join("mask").join(Path::new(&f.rgb).file_name().unwrap_or_default());
        if self.masks && !mask_path.is_file() {
            return Err(format!(
                "{}: missing (the folder has `mask/`, so every frame needs its mask)",
                mask_path.display()
            ));
        }
        if self.masks {
            let classes = load_rgb(&mask_path)?;
            let inst_path = self.dir.join("instance").join(Path::new(&f.rgb).file_name().unwrap_or_default());
            let instances = if inst_path.is_file() {
                Some(load_rgb(&inst_path)?.data.into_iter().map(u16::from).collect())
            } else {
                None
            };
            if classes.format != dynaflow_engine::msg::PixelFormat::Gray8 {
                return Err(format!("{}: expected an 8-bit grey class mask", mask_path.display()));
            }
            same_size(mask_path.display(), (classes.width, classes.height), &f.rgb, rgb_size)?;
            let mask = dynaflow_engine::msg::SegmentationMask {
                width: classes.width,
                height: classes.height,
                classes: classes.data.into_iter().map(u16::from).collect(),
                instances,
                class_names: vec!["static".into(), "person".into()],
            };
            out.push("gt_mask", header.clone(), Body::Mask(mask));
        }
        if let Some(pose) = self.gt.as_ref().and_then(|gt| nearest_pose(gt, f.rgb_stamp, GT_MAX_DIFF_S)) {
            out.push(
                "gt_pose",
                Header { frame_id: "world".into(), ..header },
                Body::Pose(Pose { world_from_cam: pose }),
            );
        }
        Ok(out)
    }
}

impl Source for TumSource {
    fn next(&mut self, _ctx: &mut Context, seq: u64) -> Result<Option<Outputs>, OpError> {
        let Some(f) = self.frames.get(seq as usize) else { return Ok(None) };
        match self.load(seq, f) {
            Ok(out) => Ok(Some(out)),
            Err(e) if self.skip => {
                tracing::warn!("skipping frame {seq}: {e}");
                self.skipped.push(e);
                Ok(Some(Outputs::new()))
            }
            Err(e) => Err(OpError::Input(format!("{}: {e}", self.dir.display()))),
        }
    }

    fn stop(&mut self, _ctx: &mut Context) -> Result<(), OpError> {
        if !self.skipped.is_empty() {
            tracing::warn!("{}: skipped {} of {} frames", self.dir.display(), self.skipped.len(), self.frames.len());
        }
        Ok(())
    }

    fn len_hint(&self) -> Option<u64> {
        Some(self.frames.len() as u64)
    }
}
