//! `euroc`: a EuRoC MAV (ASL) folder: cam0, a rectified cam1, depth0, the IMU and the ground
//! truth (the reader is `dynaflow_datasets::euroc`).

use std::path::PathBuf;

use dynaflow_datasets::euroc::{EurocFrame, EurocSequence};

use dynaflow_engine::msg::{CameraInfo, DepthImage, Header, Image, ImuBatch, Pose, StereoRig};
use dynaflow_engine::op::{Instance, OpError, OpSpec, Out, Outputs, Params};
use dynaflow_engine::params;

use super::sequence::{OnError, SequenceSource, ground_truth_pose};

params! {
    struct Config {
        /// the `mav0` folder, or the folder holding it
        path: PathBuf,
        /// read at most this many frames (0 = all)
        frames: u64 [0, i64::MAX] = 0,
        /// an unreadable frame: fail the run, or skip the frame (counted, logged)
        on_error: OnError = OnError::Fail,
    }
}

const RGB: Out<Image> = Out::new(
    "rgb",
    "cam0's image (grey in EuRoC; named `rgb` as every source's main image, so graphs run with `--input`)",
);
const RIGHT: Out<Image> = Out::new("right", "cam1's image, when cam1 is a rectified partner of cam0");
const DEPTH: Out<DepthImage> =
    Out::new("depth", "depth0's depth in metres, registered to cam0 (when the folder has depth0)");
const CAMERA_INFO: Out<CameraInfo> = Out::new("camera_info", "cam0's intrinsics and radial-tangential distortion");
const STEREO: Out<StereoRig> =
    Out::new("stereo", "the rig, when cam1 is a rectified partner of cam0: its baseline, metres");
const IMU: Out<ImuBatch> = Out::new(
    "imu",
    "the IMU samples stamped after the previous frame up to this one (the first frame: all up to it), with the IMU's calibration (cam0's pose in the IMU frame)",
);
const GT_POSE: Out<Pose> = Out::ground_truth(
    "gt_pose",
    "ground-truth world_from_cam of cam0, interpolated between the two ground-truth samples around the frame",
);

pub(crate) const EUROC: OpSpec =
    OpSpec::source("euroc", "decode", dynaflow_engine::op::doc_line(include_str!("docs/euroc.md")), build)
        .outputs(&[RGB.spec, RIGHT.spec, DEPTH.spec, CAMERA_INFO.spec, STEREO.spec, IMU.spec, GT_POSE.spec])
        .params(Config::PARAMS)
        .cpu_heavy();

fn build(params: &Params) -> Result<Instance, OpError> {
    let c = Config::from_params(params)?;
    let sequence = EurocSequence::open(&c.path, c.frames as usize).map_err(OpError::library)?;
    if let Err(e) = sequence.baseline() {
        tracing::warn!("{e}");
    }
    let imu = sequence.imu();
    if imu.duplicates_dropped > 0 || imu.irregular_intervals > 0 {
        tracing::warn!(
            "{}: {} repeated IMU lines dropped, {} intervals over 1.5 sample periods integrated through (longest {:.1} ms)",
            sequence.dir().join("imu0/data.csv").display(),
            imu.duplicates_dropped,
            imu.irregular_intervals,
            imu.longest_interval * 1e3
        );
    }
    Ok(Instance::Source(Box::new(SequenceSource::new(sequence, emit, &c.path, c.on_error))))
}

fn emit(sequence: &EurocSequence, f: EurocFrame, header: &Header) -> Outputs {
    let mut out = Outputs::new().send(&RGB, header.clone(), f.left).send(&CAMERA_INFO, header.clone(), f.camera).send(
        &IMU,
        Header { frame_id: "imu".into(), ..header.clone() },
        ImuBatch { samples: f.imu, calibration: *sequence.calibration() },
    );
    if let (Some(right), Some(baseline)) = (f.right, sequence.stereo_baseline()) {
        out = out.send(&RIGHT, header.clone(), right).send(&STEREO, header.clone(), StereoRig { baseline });
    }
    if let Some(depth) = f.depth {
        out = out.send(&DEPTH, header.clone(), depth);
    }
    if let Some(p) = f.gt_pose {
        ground_truth_pose(&mut out, &GT_POSE, header, Pose { world_from_cam: p });
    }
    out
}
