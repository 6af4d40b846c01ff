//! The `synth` source operator: streams generated frames straight into a graph.

use std::path::Path;

use dynaflow_engine::msg::{
    CameraInfo, DepthImage, Header, Image, ImuBatch, ImuSample, PixelFormat, Pose, SegmentationMask, StereoRig,
};
use dynaflow_engine::op::Seeded;
use dynaflow_engine::op::{Instance, OpError, OpSpec, Out, Outputs, Param, ParamType, Params};
use dynaflow_engine::params;

use dynaflow_datasets::synth::{
    Frame, Generator, Motion, PeopleMode, SynthConfig, fisheye, rig_calibration, scaled_fr3, scaled_kitti,
};

use crate::decode::{OnError, SequenceSource, ground_truth_pose};
use dynaflow_datasets::Sequence;

/// The camera motion as a parameter (the generator's names).
#[derive(Clone, Copy, Debug)]
struct MotionParam(Motion);

impl Param for MotionParam {
    const TYPE: ParamType = ParamType::Enum { values: Motion::NAMES };
    fn from_json(value: &serde_json::Value, _: &Params) -> Result<Self, String> {
        value.as_str().and_then(Motion::from_name).map(MotionParam).ok_or_else(|| format!("unknown motion {value}"))
    }
    fn to_json(&self) -> serde_json::Value {
        Motion::NAMES.iter().find(|n| Motion::from_name(n) == Some(self.0)).copied().unwrap_or("?").into()
    }
}

params! {
    struct Config {
        /// camera motion, like the TUM fr3 sequences (`static`, `xyz`, `rpy`, `halfsphere`), round the room (`loop`), in the hand (`handheld`), or a car round a city block in the street scene (`drive`: KITTI's camera, 3 m/s, 583 m a round; with `people: 0`, `rate_hz: 10`, 1241x376 for KITTI's layout)
        motion: MotionParam = MotionParam(Motion::Xyz),
        /// number of people
        people: u64 [0, 16] = 2,
        /// people sit and move little (TUM `sitting`)
        sitting: bool = false,
        /// number of frames
        frames: u64 [1, 1_000_000] = 300,
        /// image width (intrinsics scale with it)
        width: u32 [16, 4096] = 640,
        /// image height
        height: u32 [16, 4096] = 480,
        /// a Kannala-Brandt fisheye (TUM-VI's lens, 123 degrees across at 640x480) instead of the fr3 pinhole; `undistort` turns it into a pinhole for the operators that need one
        fisheye: bool = false,
        /// frame rate
        rate_hz: f64 [0.1, 1000.0] = 30.0,
        /// scene and noise seed; unset, it derives from the graph seed (`--seed`) and the node id
        seed: Seeded [0, i64::MAX],
        /// Kinect depth noise, holes and quantisation
        depth_noise: bool = true,
        /// image noise σ in grey levels
        image_noise: f64 [0.0, 50.0] = 2.0,
        /// 3×3 image blur
        blur: bool = true,
        /// kidnap the camera at this frame: 30 frames black with no depth, then the motion resumes 10 s earlier (a place already seen: relocalisation); 0: never
        kidnap: u64 [0, 1_000_000] = 0,
        /// a rectified right camera this many metres to the right (`right`, `stereo`); 0: none (a zero baseline has no disparity)
        stereo_baseline: f64 [0.0, 10.0] = 0.0,
        /// cover the camera at this frame: `blackout_frames` frames black with no depth while the motion goes on (a visual blackout the IMU carries a tracker through; long, the camera comes back where its map never saw: a new map, merged when an old place returns); 0: never
        blackout: u64 [0, 1_000_000] = 0,
        /// how many frames a `blackout` lasts
        blackout_frames: u64 [1, 1_000_000] = 30,
        /// the rig's IMU on `imu`: 200 Hz with EuRoC's ADIS16448 noise and bias walks, the camera mounted as EuRoC's cam0 (what `dynaflow synth --format euroc` writes)
        imu: bool = false,
    }
}

const RGB: Out<Image> = Out::new("rgb", "RGB8 camera image");
const DEPTH: Out<DepthImage> = Out::new("depth", "depth in metres (0 = no measurement)");
const CAMERA_INFO: Out<CameraInfo> = Out::new(
    "camera_info",
    "intrinsics: TUM fr3's pinhole scaled to the resolution, or with `fisheye` the Kannala-Brandt lens",
);
const GT_POSE: Out<Pose> = Out::ground_truth("gt_pose", "ground-truth world_from_cam");
const RIGHT: Out<Image> =
    Out::new("right", "RGB8 image of the rectified right camera (with `stereo_baseline` > 0; its own sensor noise)");
const STEREO: Out<StereoRig> = Out::new("stereo", "the rig (with `stereo_baseline` > 0)");
const IMU: Out<ImuBatch> = Out::new(
    "imu",
    "with `imu`: the IMU samples after the previous frame up to this one (the first frame: from the start), with the rig's calibration",
);
const GT_MASK: Out<SegmentationMask> =
    Out::ground_truth("gt_mask", "ground-truth class (0 static, 1 person) and instance masks");

pub(crate) const SYNTH: OpSpec =
    OpSpec::source("synth", "synth", dynaflow_engine::op::doc_line(include_str!("docs/synth.md")), build)
        .outputs(&[
            RGB.spec,
            DEPTH.spec,
            CAMERA_INFO.spec,
            GT_POSE.spec,
            GT_MASK.spec,
            RIGHT.spec,
            STEREO.spec,
            IMU.spec,
        ])
        .params(Config::PARAMS)
        .cpu_heavy();

fn build(params: &Params) -> Result<Instance, OpError> {
    let c = Config::from_params(params)?;
    let config = SynthConfig {
        motion: c.motion.0,
        people: c.people as usize,
        mode: if c.sitting { PeopleMode::Sitting } else { PeopleMode::Walking },
        // Replaced in `start` by the node's seed when the graph sets none.
        seed: c.seed.or(0),
        rate_hz: c.rate_hz,
        intrinsics: if c.fisheye {
            fisheye(c.width, c.height)
        } else if c.motion.0 == Motion::Drive {
            scaled_kitti(c.width, c.height)
        } else {
            scaled_fr3(c.width, c.height)
        },
        depth_noise: c.depth_noise,
        image_noise: c.image_noise as f32,
        blur: c.blur,
        kidnap: (c.kidnap > 0).then_some(c.kidnap),
        blackout: (c.blackout > 0).then_some(c.blackout),
        blackout_frames: c.blackout_frames,
    };
    if c.motion.0 == Motion::Drive && c.people > 0 {
        return Err(OpError::Config {
            key: "people".into(),
            message: "with `motion: drive`: the street has no people yet; set `people: 0`".into(),
        });
    }
    if c.imu && c.kidnap > 0 {
        return Err(OpError::Config {
            key: "imu".into(),
            message: "with `kidnap`: a kidnap rewinds the camera, a jump no IMU measures (use `blackout` for a covered camera)"
                .into(),
        });
    }
    let mut frames = Synth {
        generator: Generator::new(config),
        seeded: c.seed.0.is_some(),
        frames: c.frames,
        stereo_baseline: (c.stereo_baseline > 0.0).then_some(c.stereo_baseline),
        imu: c.imu.then(Vec::new),
    };
    frames.draw_imu();
    Ok(Instance::Source(Box::new(SequenceSource::new(frames, emit, Path::new("synth"), OnError::Fail))))
}

struct Synth {
    generator: Generator,
    /// Whether the graph gave `seed`; otherwise the node's seed is used.
    seeded: bool,
    frames: u64,
    /// The right camera's baseline, metres.
    stereo_baseline: Option<f64>,
    /// With `imu`: each frame's batch of the rig's samples.
    imu: Option<Vec<Vec<ImuSample>>>,
}

impl Synth {
    /// The IMU's samples over the frames, cut into one batch per frame (drawn again when the
    /// seed changes: the noise is the scene seed's).
    fn draw_imu(&mut self) {
        if self.imu.is_none() {
            return;
        }
        let g = &self.generator;
        let last = g.time(self.frames.saturating_sub(1));
        let samples = g.imu(&rig_calibration(), last, true);
        let stamps: Vec<f64> = (0..self.frames).map(|k| dynaflow_datasets::synth::STAMP_BASE + g.time(k)).collect();
        self.imu = Some(dynaflow_datasets::imu::batches(&samples, &stamps));
    }
}

impl Sequence for Synth {
    type Frame = Frame;

    fn len(&self) -> usize {
        self.frames as usize
    }

    fn read(&mut self, i: usize) -> Result<Option<Frame>, dynaflow_datasets::Error> {
        Ok((i < self.len()).then(|| self.generator.frame(i as u64, false)))
    }

    fn stamp(f: &Frame) -> f64 {
        f.stamp
    }

    fn seed(&mut self, seed: u64) {
        if !self.seeded {
            let mut config = self.generator.config().clone();
            config.seed = seed;
            self.generator = Generator::new(config);
            self.draw_imu();
        }
    }
}

fn emit(synth: &Synth, f: Frame, header: &Header) -> Outputs {
    let k = &synth.generator.config().intrinsics;
    let mut out = Outputs::new();
    if let Some(b) = synth.stereo_baseline
        && let Some(right) = synth.generator.right(&f, b)
    {
        let image = Image { width: k.width, height: k.height, format: PixelFormat::Rgb8, data: right };
        out = out.send(&RIGHT, header.clone(), image).send(&STEREO, header.clone(), StereoRig { baseline: b });
    }
    let mask = SegmentationMask {
        width: k.width,
        height: k.height,
        classes: f.class,
        instances: Some(f.instance),
        class_names: vec!["static".into(), "person".into()],
    };
    let rgb = Image { width: k.width, height: k.height, format: PixelFormat::Rgb8, data: f.rgb };
    let mut out = out
        .send(&RGB, header.clone(), rgb)
        .send(&DEPTH, header.clone(), DepthImage { width: k.width, height: k.height, data: f.depth })
        .send(&CAMERA_INFO, header.clone(), k.clone());
    if let Some(batches) = &synth.imu {
        let samples = batches.get(f.index as usize).cloned().unwrap_or_default();
        out = out.send(
            &IMU,
            Header { frame_id: "imu".into(), ..header.clone() },
            ImuBatch { samples, calibration: rig_calibration() },
        );
    }
    ground_truth_pose(&mut out, &GT_POSE, header, Pose { world_from_cam: f.world_from_cam });
    out.send(&GT_MASK, header.clone(), mask)
}
