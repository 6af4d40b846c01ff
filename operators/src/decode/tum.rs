//! `tum_rgbd`: reads a TUM RGB-D sequence folder as it is.

use std::path::PathBuf;

use dynaflow_datasets::tum::{GT_MAX_DIFF_S, TumFrame, TumSequence};

use dynaflow_engine::msg::{CameraInfo, DepthImage, Header, Image, Pose, SegmentationMask};
use dynaflow_engine::op::{Instance, OpError, OpSpec, Out, Outputs, Params};
use dynaflow_engine::params;

use super::CameraParam;
use super::sequence::{OnError, SequenceSource, ground_truth_pose};

params! {
    struct Config {
        /// sequence folder
        path: PathBuf,
        /// `auto` (from the folder name `rgbd_dataset_freiburgN_*`, else `calibration.txt`), `fr1`, `fr2`, `fr3`, `fx,fy,cx,cy`, `fx,fy,cx,cy,k1,k2,p1,p2,k3` or `kb:fx,fy,cx,cy,k1,k2,k3,k4`
        intrinsics: CameraParam = CameraParam::Auto,
        /// largest colour/depth time difference to associate, seconds
        max_difference: f64 [0.0, 1.0] = 0.02,
        /// depth PNG value per metre
        depth_factor: f64 [1e-6, 1e9] = 5000.0,
        /// unreadable frame or missing ground truth: fail the run, or skip the frame (counted, logged)
        on_error: OnError = OnError::Fail,
        /// read at most this many frames (0 = all)
        frames: u64 [0, i64::MAX] = 0,
    }
}

const RGB: Out<Image> = Out::new("rgb", "colour image (RGB8, or Gray8 if the file is grey)");
const DEPTH: Out<DepthImage> = Out::new("depth", "depth in metres (value / depth_factor)");
const CAMERA_INFO: Out<CameraInfo> = Out::new("camera_info", "intrinsics with distortion");
const GT_POSE: Out<Pose> = Out::ground_truth(
    "gt_pose",
    "ground-truth world_from_cam: the groundtruth.txt pose nearest the frame time within 10 ms, as evo associates (absent where none is)",
);
const GT_MASK: Out<SegmentationMask> = Out::ground_truth(
    "gt_mask",
    "ground-truth class/instance mask from `mask/` and `instance/` (written by `dynaflow synth`; absent for real TUM data)",
);

pub(crate) const TUM_RGBD: OpSpec =
    OpSpec::source("tum_rgbd", "decode", dynaflow_engine::op::doc_line(include_str!("docs/tum_rgbd.md")), build)
        .outputs(&[RGB.spec, DEPTH.spec, CAMERA_INFO.spec, GT_POSE.spec, GT_MASK.spec])
        .params(Config::PARAMS)
        .cpu_heavy();

fn build(params: &Params) -> Result<Instance, OpError> {
    let c = Config::from_params(params)?;
    let given = match c.intrinsics {
        CameraParam::Given(k) => Some(k),
        CameraParam::Auto => None,
    };
    let sequence = TumSequence::open(&c.path, given, c.max_difference, c.depth_factor, c.frames as usize).map_err(
        |e| match e {
            // The camera could not be told: the parameter to set.
            dynaflow_datasets::Error::UnknownCamera { .. } => {
                OpError::Config { key: "intrinsics".into(), message: e.to_string() }
            }
            e => OpError::library(e),
        },
    )?;
    if sequence.frames_without_pose > 0 {
        tracing::warn!(
            "{}: {} of {} frames have no pose within {GT_MAX_DIFF_S} s; they have no `gt_pose` and are left out of the ATE, as evo leaves them",
            sequence.dir().join("groundtruth.txt").display(),
            sequence.frames_without_pose,
            sequence.len()
        );
    }
    Ok(Instance::Source(Box::new(SequenceSource::new(sequence, emit, &c.path, c.on_error))))
}

fn emit(_: &TumSequence, f: TumFrame, header: &Header) -> Outputs {
    let mut out = Outputs::new().send(&RGB, header.clone(), f.rgb).send(&DEPTH, header.clone(), f.depth).send(
        &CAMERA_INFO,
        header.clone(),
        f.camera,
    );
    if let Some(mask) = f.gt_mask {
        GT_MASK.push(&mut out, header.clone(), mask);
    }
    if let Some(pose) = f.gt_pose {
        ground_truth_pose(&mut out, &GT_POSE, header, Pose { world_from_cam: pose });
    }
    out
}
