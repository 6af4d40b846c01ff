//! `rosbag`: a ROS 1 or ROS 2 bag as it is (the reader is `dynaflow_ros::sequence`).

use std::path::PathBuf;

use dynaflow_ros::sequence::{BagFrame, BagOptions, BagSequence, ImuOptions, Topics};

use dynaflow_engine::msg::{CameraInfo, DepthImage, Header, Image, ImuBatch, Pose};
use dynaflow_engine::op::{Instance, OpError, OpSpec, Out, Outputs, ParamType, Params};
use dynaflow_engine::params;

use super::CameraParam;
use super::sequence::{OnError, SequenceSource, ground_truth_pose};

/// A text parameter kept as written and checked by `$check` (which says what is wrong).
macro_rules! checked_text {
    ($(#[$doc:meta])* $name:ident, $what:literal, $check:expr) => {
        $(#[$doc])*
        #[derive(Clone, Debug, Default, PartialEq)]
        pub struct $name(pub String);

        impl dynaflow_engine::op::Param for $name {
            const TYPE: ParamType = ParamType::Text { what: $what, check: |s| $check(s).map(|_| ()) };
            fn from_json(value: &serde_json::Value, _: &Params) -> Result<Self, String> {
                let text = value.as_str().ok_or_else(|| format!("expected {}, found {value}", $what))?;
                $check(text)?;
                Ok(Self(text.to_string()))
            }
            fn to_json(&self) -> serde_json::Value {
                self.0.clone().into()
            }
        }
    };
}

checked_text!(
    /// The `topics` parameter: `role=topic` pairs.
    TopicsParam,
    "`role=topic` pairs: `rgb=/camera/color/image_raw,depth=...,camera_info=...,gt=...,imu=...` (`gt=tf:PARENT:CHILD`, `depth=none`, `gt=none`, `imu=none`)",
    Topics::parse
);
checked_text!(
    /// `imu_noise`: Kalibr's four noise figures (empty: the IMU is not read).
    ImuNoiseParam,
    "`GYRO_NOISE,ACCEL_NOISE,GYRO_WALK,ACCEL_WALK` (Kalibr's imu.yaml: rad/s/√Hz, m/s²/√Hz, rad/s²/√Hz, m/s³/√Hz), or empty",
    ImuOptions::parse_noise
);
checked_text!(
    /// `imu_extrinsic`: the camera's pose in the IMU frame (empty: from tf).
    ExtrinsicParam,
    "`TX,TY,TZ,QX,QY,QZ,QW`: the camera's pose in the IMU frame (Kalibr's T_imu_cam), or empty for the tf tree's",
    ImuOptions::parse_extrinsic
);

params! {
    struct Config {
        /// the bag: a `.bag` file, a rosbag2 folder, or a `.mcap` / `.db3` file
        path: PathBuf,
        /// the topic of each role where the bag has several candidates (or to override one): `rgb=...,depth=...,camera_info=...,gt=...`
        topics: TopicsParam = TopicsParam::default(),
        /// largest colour/depth header-stamp difference to pair, seconds
        max_difference: f64 [0.0, 1.0] = 0.02,
        /// 16-bit depth value per metre (REP 118: millimetres)
        depth_factor: f64 [1e-6, 1e9] = 1000.0,
        /// `auto` (the bag's CameraInfo), `fr1`/`fr2`/`fr3`, `fx,fy,cx,cy[,k1,k2,p1,p2,k3]` or `kb:fx,fy,cx,cy,k1,k2,k3,k4`
        intrinsics: CameraParam = CameraParam::Auto,
        /// an unreadable frame: fail the run, or skip the frame (counted, logged)
        on_error: OnError = OnError::Fail,
        /// read at most this many frames (0 = all)
        frames: u64 [0, i64::MAX] = 0,
        /// the IMU's noise (a bag does not hold it): `GYRO_NOISE,ACCEL_NOISE,GYRO_WALK,ACCEL_WALK`; empty: the IMU is not read unless `topics` names it (then an error)
        imu_noise: ImuNoiseParam = ImuNoiseParam::default(),
        /// the camera's pose in the IMU frame `TX,TY,TZ,QX,QY,QZ,QW`; empty: the tf tree's (IMU frame <- the images' frame)
        imu_extrinsic: ExtrinsicParam = ExtrinsicParam::default(),
    }
}

const RGB: Out<Image> =
    Out::new("rgb", "colour image (RGB8, or Gray8 for a grey camera), stamped with its header stamp");
const DEPTH: Out<DepthImage> =
    Out::new("depth", "depth in metres, the image paired with the colour one (absent in a monocular run)");
const CAMERA_INFO: Out<CameraInfo> = Out::new("camera_info", "intrinsics with distortion, from the CameraInfo topic");
const IMU: Out<ImuBatch> = Out::new(
    "imu",
    "the IMU samples since the previous frame (header stamps), with the calibration (`imu_noise`, the mounting from tf or `imu_extrinsic`, the stream's median rate); only when the run reads an IMU topic",
);
const GT_POSE: Out<Pose> = Out::ground_truth(
    "gt_pose",
    "ground-truth world_from_cam: the pose topic's nearest pose within 10 ms, or the tf lookup at the frame's stamp (absent where none is)",
);

pub(crate) const ROSBAG: OpSpec =
    OpSpec::source("rosbag", "decode", dynaflow_engine::op::doc_line(include_str!("docs/rosbag.md")), build)
        .outputs(&[RGB.spec, DEPTH.spec, CAMERA_INFO.spec, IMU.spec, GT_POSE.spec])
        .params(Config::PARAMS)
        .cpu_heavy();

fn build(params: &Params) -> Result<Instance, OpError> {
    let c = Config::from_params(params)?;
    let topics = Topics::parse(&c.topics.0).map_err(|e| OpError::Config { key: "topics".into(), message: e })?;
    let bag = dynaflow_ros::Bag::open(&c.path).map_err(OpError::library)?;
    let options = BagOptions {
        topics,
        max_difference: c.max_difference,
        depth_factor: c.depth_factor,
        frames: c.frames as usize,
        intrinsics: match c.intrinsics {
            CameraParam::Given(k) => Some(k),
            CameraParam::Auto => None,
        },
        imu: ImuOptions {
            noise: ImuOptions::parse_noise(&c.imu_noise.0)
                .map_err(|e| OpError::Config { key: "imu_noise".into(), message: e })?,
            body_from_cam: ImuOptions::parse_extrinsic(&c.imu_extrinsic.0)
                .map_err(|e| OpError::Config { key: "imu_extrinsic".into(), message: e })?,
        },
    };
    let sequence = BagSequence::open(bag, &options).map_err(OpError::library)?;
    let chosen: Vec<String> = sequence.topics().iter().map(|(role, t)| format!("{role}={t}")).collect();
    tracing::info!("{}: {} frames from {}", c.path.display(), sequence.len(), chosen.join(", "));
    if sequence.frames_without_pose() > 0 {
        tracing::warn!(
            "{}: {} of {} frames have no ground-truth pose; they are left out of the ATE",
            c.path.display(),
            sequence.frames_without_pose(),
            sequence.len()
        );
    }
    Ok(Instance::Source(Box::new(
        SequenceSource::new(sequence, emit, &c.path, c.on_error).with_bag_report(BagSequence::report),
    )))
}

fn emit(_: &BagSequence, f: BagFrame, header: &Header) -> Outputs {
    let mut out = Outputs::new().send(&RGB, header.clone(), f.rgb).send(&CAMERA_INFO, header.clone(), f.camera);
    if let Some(depth) = f.depth {
        DEPTH.push(&mut out, header.clone(), depth);
    }
    if let Some(batch) = f.imu {
        IMU.push(&mut out, header.clone(), batch);
    }
    if let Some(pose) = f.gt_pose {
        ground_truth_pose(&mut out, &GT_POSE, header, Pose { world_from_cam: pose });
    }
    out
}
