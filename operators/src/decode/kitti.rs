//! `kitti_odometry`: a KITTI odometry sequence folder (`calib.txt`, `times.txt`,
//! `image_0/`+`image_1/` grey or `image_2/`+`image_3/` colour, optional poses).

use std::path::PathBuf;

use dynaflow_datasets::kitti::{KittiFrame, KittiSequence, Pair as KittiPair, Poses};

use dynaflow_engine::msg::{CameraInfo, Header, Image, Pose, StereoRig};
use dynaflow_engine::op::{Instance, OpError, OpSpec, Out, Outputs, Params};
use dynaflow_engine::{param_enum, params};

use super::sequence::{OnError, SequenceSource, ground_truth_pose};

param_enum! {
    /// Which stereo pair.
    enum Pair { Gray = "gray", Color = "color" }
}

params! {
    struct Config {
        /// sequence folder (e.g. `dataset/sequences/00`)
        path: PathBuf,
        /// `gray`: image_0/image_1, `color`: image_2/image_3
        camera: Pair = Pair::Gray,
        /// pose file; `auto`: `../../poses/<sequence>.txt` if present; `none`
        poses: String = "auto".into(),
        /// read at most this many frames (0 = all)
        frames: u64 [0, i64::MAX] = 0,
        /// an unreadable frame: fail the run, or skip the frame (counted, logged)
        on_error: OnError = OnError::Fail,
    }
}

const LEFT: Out<Image> = Out::new(
    "rgb",
    "left rectified image (grey or colour; named `rgb` as every source's main image, so a graph runs on KITTI with `--input`)",
);
const RIGHT: Out<Image> = Out::new("right", "right rectified image");
const CAMERA_INFO: Out<CameraInfo> = Out::new("camera_info", "left camera intrinsics (rectified, no distortion)");
const STEREO: Out<StereoRig> = Out::new("stereo", "the rig: baseline from `calib.txt`'s P1 (or P3 with P2), metres");
const GT_POSE: Out<Pose> =
    Out::ground_truth("gt_pose", "ground-truth world_from_cam of the left camera, when poses are available");

pub(crate) const KITTI_ODOMETRY: OpSpec = OpSpec::source(
    "kitti_odometry",
    "decode",
    dynaflow_engine::op::doc_line(include_str!("docs/kitti_odometry.md")),
    build,
)
.outputs(&[LEFT.spec, RIGHT.spec, CAMERA_INFO.spec, STEREO.spec, GT_POSE.spec])
.params(Config::PARAMS)
.cpu_heavy();

fn build(params: &Params) -> Result<Instance, OpError> {
    let c = Config::from_params(params)?;
    let pair = match c.camera {
        Pair::Color => KittiPair::Color,
        Pair::Gray => KittiPair::Gray,
    };
    let file = params.resolve_path(&c.poses);
    let poses = match c.poses.as_str() {
        "none" => Poses::None,
        "auto" => Poses::Auto,
        _ => Poses::File(&file),
    };
    let sequence = KittiSequence::open(&c.path, pair, poses, c.frames as usize).map_err(OpError::library)?;
    Ok(Instance::Source(Box::new(SequenceSource::new(sequence, emit, &c.path, c.on_error))))
}

fn emit(sequence: &KittiSequence, f: KittiFrame, header: &Header) -> Outputs {
    let mut out = Outputs::new()
        .send(&LEFT, header.clone(), f.left)
        .send(&RIGHT, header.clone(), f.right)
        .send(&CAMERA_INFO, header.clone(), f.camera)
        .send(&STEREO, header.clone(), StereoRig { baseline: sequence.baseline });
    if let Some(p) = f.gt_pose {
        ground_truth_pose(&mut out, &GT_POSE, header, Pose { world_from_cam: p });
    }
    out
}
