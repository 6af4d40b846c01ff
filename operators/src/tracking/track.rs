//! `track_rgbd`, `track_stereo`, `track_mono`: one tracker (`dynaflow_slam::Tracker`) behind
//! three operators, one per sensor, each declaring as required exactly the inputs its sensor
//! needs, so a miswired graph is refused at validation instead of failing at frame 0.

use std::path::PathBuf;
use std::sync::Arc;

use dynaflow_engine::msg::{
    CameraInfo, DepthImage, Header, ImuBatch, ImuCalibration, Keypoints, Message, PointLabels, Pose, Scalars,
    SegmentationMask, SparseMap, StereoRig, Tracks,
};
use dynaflow_engine::op::{
    Context, In, InputRole, Inputs, Instance, OpError, OpSpec, Operator, Out, Outputs, ParamSpec, Params, concat_params,
};
use dynaflow_engine::params;
use dynaflow_slam::eval::Align;
use dynaflow_slam::{Feature, Sensor, Tracker, TrackerConfig};
use dynaflow_vision::camera::Pinhole;
use rand_core::Rng;

use super::evaluation::TrajectoryLog;

mod imu;
use crate::report::{FrameStates, MapSaved, NodeReport, TrackerReport};
use imu::check_imu_batch;

/// A tracker's sensor with what only it has: the depth camera's parameters.
enum Setup {
    /// `track_rgbd`.
    Rgbd(DepthCamera),
    /// `track_stereo`.
    Stereo,
    /// `track_mono`.
    Mono,
}

impl Setup {
    fn sensor(&self) -> Sensor {
        match self {
            Setup::Rgbd(_) => Sensor::Rgbd,
            Setup::Stereo => Sensor::Stereo,
            Setup::Mono => Sensor::Monocular,
        }
    }
}

/// The sensor's name in reports.
fn sensor_name(sensor: Sensor) -> &'static str {
    match sensor {
        Sensor::Rgbd => "rgbd",
        Sensor::Stereo => "stereo",
        Sensor::Monocular => "mono",
    }
}

params! {
    /// Every sensor's parameters.
    struct Common {
        /// fewer inliers than this after motion-only BA: the frame is not tracked (ORB-SLAM: 30)
        min_inliers: u64 [6, 100_000] = 30,
        /// projection search radius, pixels: the search of the whole local map (widened 3x once), or with `two_stage` of the previous frame's points at each keypoint's pyramid level (ORB-SLAM2's `TrackWithMotionModel`, doubled once); 0: ORB-SLAM2's for the sensor: 15, with `two_stage` a stereo camera's 7
        search_radius: f64 [0.0, 200.0] = 0.0,
        /// P3P RANSAC reprojection threshold, pixels
        ransac_threshold: f64 [0.1, 100.0] = 3.0,
        /// lost frames in a row before a new map starts
        reset_after: u64 [0, 100_000] = 5,
        /// vocabulary file (`dynaflow vocab train`) for relocalisation in the whole map when tracking is lost (ORB-SLAM2's key-frame database); empty: the embedded default (as `loop_close`'s; use the same file for both)
        vocabulary: PathBuf = PathBuf::new(),
        /// write the whole map here at the end of the run (key frames, keypoints, points, the vocabulary's id; `dynaflow run --save-map`)
        save_map: PathBuf = PathBuf::new(),
        /// start in this saved map (made with the same vocabulary): the first frames relocalise in it (`dynaflow run --load-map`)
        load_map: PathBuf = PathBuf::new(),
        /// false: ORB-SLAM2's localisation mode, with `load_map`: no key frames, the local map follows the camera through the loaded one, a lost camera relocalises again
        mapping: bool = true,
        /// a keypoint takes the culling label of the nearest labelled track within this many pixels (dynamic: left out); 10 = `lk_flow`'s `min_distance`, the spacing of the tracked corners, so a label speaks for its neighbourhood as a segment would; 0: only keypoints on a track
        label_radius: f64 [0.0, 100.0] = 10.0,
        /// ORB-SLAM2's two searches: the previous frame's points at each keypoint's level within `search_radius` (ORB-SLAM2's 15, stereo 7), then the local map within 2.5-4 px at the refined pose (`TrackWithMotionModel`, `TrackLocalMap`); what keeps a stereo camera on the street scene's `drive` (docs/benchmarks.md); off: one search of the local map (on the rooms the two searches drift more, not the default yet)
        two_stage: bool = false,
    }
}

params! {
    /// A depth camera's parameters (`track_rgbd`).
    struct DepthCamera {
        /// ORB-SLAM2's `Camera.bf`, pixels: fx x a virtual baseline, weighs the depth residual (its TUM RGB-D configurations: 40 at any fx); 0 uses pixels only
        bf: f64 [0.0, 10000.0] = 40.0,
        /// points closer than this (metres) are `close` in the key-frame rule; 0: ORB-SLAM2's ThDepth, 40 baselines (40 x bf / fx: 2.99 m at fx 535.4)
        close_depth: f64 [0.0, 1000.0] = 0.0,
        /// depths beyond this (metres) are not used (Kinect noise grows with the square)
        max_depth: f64 [0.1, 1000.0] = 6.0,
    }
}

const RGBD_PARAMS: [ParamSpec; Common::PARAMS.len() + DepthCamera::PARAMS.len()] =
    concat_params(Common::PARAMS, DepthCamera::PARAMS);

const KEYPOINTS: In<Keypoints> = In::required("keypoints", "this frame's ORB keypoints with descriptors");
const CAMERA_INFO: In<CameraInfo> = In::required("camera_info", "intrinsics");
const DEPTH_CAMERA: In<DepthImage> =
    In::required("depth", "the depth camera's image, metres, registered to the colour image");
const STEREO_DEPTH: In<DepthImage> =
    In::required("depth", "keypoint depth from the rectified pair (`stereo_match.depth`)");
const RIG: In<StereoRig> =
    In::required("stereo", "the stereo rig (the source's `stereo`): its baseline gives bf and the close depth");
const MAP: In<SparseMap> = In::optional("map", "local mapping's refined local map (`delay: 1`, `join: latest`)");
const LOOP: In<SparseMap> = In::optional(
    "loop",
    "`loop_close`'s corrected map (`delay: 1`, `join: latest`): key frames, points and the last pose move with it",
);
const MASK: In<SegmentationMask> = In::optional("mask", "pixels of a non-zero class are dynamic");
const LABELS: In<PointLabels> = In::optional("labels", "culling's labels of `tracks`");
const TRACKS: In<Tracks> = In::optional(
    "tracks",
    "the tracks `labels` index (a keypoint whose nearest labelled track within `label_radius` is dynamic is left out)",
);
const IMU: In<ImuBatch> = In::optional(
    "imu",
    "the IMU samples since the previous frame with the IMU's calibration (the source's `imu`): wired, the tracker is visual-inertial (ORB-SLAM3's: IMU initialisation, IMU prediction, inertial pose optimisation, IMU-only propagation through frames vision cannot track)",
);
const GT_POSE: In<Pose> =
    In::optional("gt_pose", "ground truth, for the ATE in the summary").with_role(InputRole::Evaluation);
const POSE: Out<Pose> =
    Out::new("pose", "world_from_cam (the first key frame is the world); none on a frame the tracker lost");
const KEYFRAME: Out<SparseMap> =
    Out::new("keyframe", "a new key frame with its observations and new points (to `local_map`)");
const STATS: Out<Scalars> = Out::new(
    "stats",
    "`state` (0 not initialised, 1 new map, 2 tracked, 3 relocalised, 4 lost, 5 propagated by the IMU), `matches`, `inliers`, `map_points`, `map_id`, `keyframe`; with an initialised IMU also `velocity_x/y/z` (m/s, world), `gyro_bias_x/y/z`, `accel_bias_x/y/z`, `gravity_x/y/z` (world) and `position_sigma` (m, the IMU-only propagation's)",
);

/// The inputs every sensor shares, after its own.
macro_rules! tracker_inputs {
    ($($own:expr),*) => {
        &[KEYPOINTS.spec, $($own,)* CAMERA_INFO.spec, IMU.spec, MAP.spec, LOOP.spec, MASK.spec, LABELS.spec, TRACKS.spec, GT_POSE.spec]
    };
}

const OUTPUTS: &[dynaflow_engine::op::PortSpec] = &[POSE.spec, KEYFRAME.spec, STATS.spec];

/// What `dynaflow run --save-map/--load-map/--localise` set on a tracker.
pub const MAP_STORE: dynaflow_engine::op::MapStore =
    dynaflow_engine::op::MapStore { save: "save_map", load: "load_map", mapping: "mapping" };

/// ORB-SLAM2's RGB-D tracking.
pub const TRACK_RGBD: OpSpec =
    OpSpec::transform("track_rgbd", "pnp_ba", dynaflow_engine::op::doc_line(include_str!("docs/track_rgbd.md")), |p| {
        build(p, Sensor::Rgbd)
    })
    .inputs(tracker_inputs!(DEPTH_CAMERA.spec))
    .outputs(OUTPUTS)
    .params(&RGBD_PARAMS)
    .cpu_heavy()
    .map_store(MAP_STORE);

/// ORB-SLAM2's stereo tracking.
pub const TRACK_STEREO: OpSpec = OpSpec::transform(
    "track_stereo",
    "pnp_ba",
    dynaflow_engine::op::doc_line(include_str!("docs/track_stereo.md")),
    |p| build(p, Sensor::Stereo),
)
.inputs(tracker_inputs!(STEREO_DEPTH.spec, RIG.spec))
.outputs(OUTPUTS)
.params(Common::PARAMS)
.cpu_heavy()
.map_store(MAP_STORE);

/// ORB-SLAM2's monocular tracking.
pub const TRACK_MONO: OpSpec =
    OpSpec::transform("track_mono", "pnp_ba", dynaflow_engine::op::doc_line(include_str!("docs/track_mono.md")), |p| {
        build(p, Sensor::Monocular)
    })
    .inputs(tracker_inputs!())
    .outputs(OUTPUTS)
    .params(Common::PARAMS)
    .cpu_heavy()
    .map_store(MAP_STORE);

/// What `pnp_track` graphs change to.
pub const PNP_TRACK_MIGRATION: &str = "`pnp_track` is one operator per sensor now: `op: track_rgbd` (what `sensor: rgbd`, the default, was), `op: track_stereo` (wire `depth: stereo.depth` and `stereo: camera.stereo`) or `op: track_mono`; drop the `sensor` param";

/// Where the map will be written, checked before the first frame (as the recorders check their
/// files): a run must not end with its map lost for a wrong path.
fn check_save_path(path: &std::path::Path) -> Result<(), OpError> {
    if path.as_os_str().is_empty() {
        return Ok(());
    }
    let parent = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(std::path::Path::new("."));
    let problem = if path.is_dir() {
        Some("is a directory; give a file name".to_owned())
    } else if !parent.is_dir() {
        Some(format!("its folder {} does not exist", parent.display()))
    } else {
        None
    };
    match problem {
        Some(problem) => {
            Err(OpError::Config { key: "save_map".into(), message: format!("{}: {problem}", path.display()) })
        }
        None => Ok(()),
    }
}

fn build(p: &Params, sensor: Sensor) -> Result<Instance, OpError> {
    let config = Common::from_params(p)?;
    let setup = match sensor {
        Sensor::Rgbd => Setup::Rgbd(DepthCamera::from_params(p)?),
        Sensor::Stereo => Setup::Stereo,
        Sensor::Monocular => Setup::Mono,
    };
    let (vocabulary, _, _) = super::load_vocabulary(&config.vocabulary)?;
    if !config.mapping && config.load_map.as_os_str().is_empty() {
        return Err(OpError::Config {
            key: "mapping".into(),
            message: "`mapping: false` (localisation mode) needs a map to localise in: set `load_map` (or `dynaflow run --load-map FILE`)".into(),
        });
    }
    check_save_path(&config.save_map)?;
    // Read the map now, so that a bad file stops the run before it starts; the tracker gives
    // it its camera (`Tracker::use_map`) on the first frame.
    let loaded = if config.load_map.as_os_str().is_empty() {
        None
    } else {
        let cam = Pinhole { fx: 1.0, fy: 1.0, cx: 0.0, cy: 0.0 };
        Some(
            dynaflow_slam::map_file::load(&config.load_map, cam, 0.0, 0.0, 1.2, vocabulary.clone())
                .map_err(OpError::library)?,
        )
    };
    Ok(Instance::Transform(Box::new(Track {
        setup,
        config,
        vocabulary,
        loaded,
        tracker: None,
        log: TrajectoryLog::default(),
        counts: [0; 6],
        first_stamp: None,
        last_imu_stamp: None,
        last_map: None,
        last_loop: None,
        best_usable: 0,
        frames: 0,
        first_pose_frame: None,
    })))
}

struct Track {
    setup: Setup,
    config: Common,
    /// For relocalisation in the whole map.
    vocabulary: Arc<dynaflow_slam::bow::Vocabulary>,
    /// A map to start in (`load_map`), until the first frame gives the camera.
    loaded: Option<dynaflow_slam::keyframe_map::KeyFrameMap>,
    tracker: Option<Tracker>,
    /// The poses sent and the ground truth, scored at the end.
    log: TrajectoryLog,
    /// Frames per state code.
    counts: [u64; 6],
    /// The first frame's time (the inertial initialisation's is reported after it).
    first_stamp: Option<f64>,
    /// The newest IMU sample's time so far.
    last_imu_stamp: Option<f64>,
    /// The map batch last applied (a `latest` join may repeat it).
    last_map: Option<Arc<Message>>,
    /// The loop correction last applied.
    last_loop: Option<Arc<Message>>,
    /// The most keypoints of one frame that a map could start from (static, with a depth up
    /// to `max_depth`): what the end-of-run message says when no map ever started.
    best_usable: usize,
    /// Frames seen, and the index of the first one with a pose (monocular: initialisation).
    frames: u64,
    first_pose_frame: Option<u64>,
}

/// Per keypoint: left out as dynamic? The culling crate's rules: a keypoint on a pixel of a
/// dynamic class (`mask`), or whose nearest labelled track within `label_radius` is dynamic.
fn dynamic_keypoints(inputs: &Inputs, points: &[[f32; 2]], label_radius: f32) -> Result<Vec<bool>, OpError> {
    let mut dynamic = match MASK.get(inputs)? {
        Some(m) => dynaflow_culling::mask_rule(points, |x, y| {
            // (The mask's size was checked against the camera's.)
            x < m.width as usize
                && y < m.height as usize
                && m.classes.get(y * m.width as usize + x).is_some_and(|&c| c != 0)
        })
        .iter()
        .map(|d| d.dynamic)
        .collect(),
        None => vec![false; points.len()],
    };
    if let (Some(l), Some(t)) = (LABELS.get(inputs)?, TRACKS.get(inputs)?) {
        let labelled: Vec<([f32; 2], bool)> = l
            .labels
            .iter()
            .filter_map(|lab| t.tracks.get(lab.index as usize).map(|tr| (tr.cur, lab.dynamic)))
            .collect();
        dynaflow_culling::nearest_track_labels(&labelled, points, label_radius, &mut dynamic);
    }
    Ok(dynamic)
}

impl Track {
    /// The tracker for this camera, made on the first frame (a loaded map gets its camera
    /// here; one made with another camera's images is refused, naming the file).
    fn start(
        &mut self,
        ctx: &mut Context,
        k: &CameraInfo,
        rig: Option<&StereoRig>,
        imu: Option<&ImuCalibration>,
    ) -> Result<Tracker, OpError> {
        let mut tc = match (&self.setup, rig) {
            (Setup::Mono, _) => TrackerConfig::monocular(k.fx),
            (Setup::Stereo, Some(rig)) => TrackerConfig::stereo(k.fx, crate::frontend::stereo_baseline(rig)?),
            (Setup::Stereo, None) => return Err(OpError::Input("`track_stereo` has no rig".into())),
            (Setup::Rgbd(d), _) => TrackerConfig {
                bf: d.bf,
                th_depth: if d.close_depth > 0.0 {
                    d.close_depth
                } else {
                    dynaflow_slam::tracker::CLOSE_BASELINES * d.bf / k.fx
                },
                max_depth: d.max_depth,
                ..TrackerConfig::rgbd(k.fx)
            },
        };
        tc.two_stage = self.config.two_stage;
        if self.config.search_radius > 0.0 {
            tc.search_radius = self.config.search_radius;
        } else if !tc.two_stage {
            // ORB-SLAM2's 7 px is its stereo motion-model search's, not a whole-map search's.
            tc.search_radius = TrackerConfig::rgbd(k.fx).search_radius;
        }
        tc.min_inliers = self.config.min_inliers as usize;
        tc.ransac_threshold = self.config.ransac_threshold;
        tc.reset_after = self.config.reset_after as u32;
        let cam = Pinhole::from(k);
        let mut tracker = Tracker::new(tc, cam, k.width as usize, k.height as usize, ctx.rng.next_u64())
            .with_vocabulary(self.vocabulary.clone());
        if let Some(calibration) = imu {
            tracker = tracker.with_imu(*calibration);
        }
        if let Some(map) = self.loaded.take() {
            let outside = map
                .kfs
                .values()
                .flat_map(|k| &k.keypoints)
                .find(|kp| kp.uv[0] > f64::from(k.width) + 1.0 || kp.uv[1] > f64::from(k.height) + 1.0);
            if let Some(kp) = outside {
                return Err(OpError::Input(format!(
                    "{}: the map holds a keypoint at ({:.0}, {:.0}), outside this run's {}x{} images: it was made with another camera",
                    self.config.load_map.display(),
                    kp.uv[0],
                    kp.uv[1],
                    k.width,
                    k.height
                )));
            }
            tracker.use_map(map, self.config.mapping);
        }
        Ok(tracker)
    }
}

impl Operator for Track {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, kp) = KEYPOINTS.require(inputs)?;
        let (_, k) = CAMERA_INFO.require(inputs)?;
        crate::frontend::pinhole_only(k, "tracking")?;
        let (depth, rig) = match self.setup {
            Setup::Mono => (None, None),
            Setup::Rgbd(_) => (Some(DEPTH_CAMERA.require(inputs)?.1), None),
            Setup::Stereo => (Some(STEREO_DEPTH.require(inputs)?.1), Some(RIG.require(inputs)?.1)),
        };
        if let Some(m) = MASK.get(inputs)?
            && (m.width, m.height) != (k.width, k.height)
        {
            return Err(OpError::Input(format!(
                "`mask` is {}x{} but the camera's images are {}x{}: a mask must cover the image the keypoints come from, pixel for pixel",
                m.width, m.height, k.width, k.height
            )));
        }
        let descriptors = crate::frontend::orb_descriptors(kp)?;
        let imu = IMU.get(inputs)?;
        if self.tracker.is_none() {
            self.tracker = Some(self.start(ctx, k, rig, imu.map(|b| &b.calibration))?);
        }
        let Some(tracker) = self.tracker.as_mut() else { return Ok(Outputs::new()) };
        // An inertial tracker needs every sample: a frame without its batch would integrate
        // through a gap, so it stops the run (and a batch after a first frame without one).
        match (imu, tracker.inertial()) {
            (Some(batch), true) => {
                check_imu_batch(&batch.samples, self.last_imu_stamp, msg.header.stamp)?;
                self.last_imu_stamp = batch.samples.last().map(|s| s.stamp).or(self.last_imu_stamp);
                tracker.add_imu(&batch.samples);
            }
            (None, false) => {}
            (Some(_), false) => {
                return Err(OpError::Input(
                    "`imu` gave its first batch after the first frame: the tracker started without an IMU (wire the source's `imu`, which sends one with every frame)".into(),
                ));
            }
            (None, true) => {
                return Err(OpError::Input(format!(
                    "no `imu` batch with the frame at {:.6} s: a visual-inertial tracker needs the samples of every frame (a dropped batch would be integrated as a gap)",
                    msg.header.stamp
                )));
            }
        }
        if let Some(update) = super::fresh(MAP.find(inputs)?, &mut self.last_map) {
            tracker.apply_map_update(update);
        }
        if let Some(correction) = super::fresh(LOOP.find(inputs)?, &mut self.last_loop) {
            tracker.apply_correction(correction);
        }
        let uv: Vec<[f32; 2]> = kp.points.iter().map(|p| [p.x, p.y]).collect();
        let dynamic = dynamic_keypoints(inputs, &uv, self.config.label_radius as f32)?;
        let features: Vec<Feature> = kp
            .points
            .iter()
            .zip(descriptors.chunks_exact(32))
            .zip(&dynamic)
            .map(|((p, d), &dynamic)| {
                let z = depth.map_or(0.0, |d| f64::from(d.at_nearest(p.x, p.y)));
                let mut descriptor = [0u8; 32];
                descriptor.copy_from_slice(d);
                Feature {
                    uv: [f64::from(p.x), f64::from(p.y)],
                    octave: p.octave,
                    angle: p.angle,
                    depth: (z > 0.0 && z.is_finite()).then_some(z),
                    descriptor,
                    dynamic,
                }
            })
            .collect();
        let max_depth = tracker.config().max_depth;
        let usable = features.iter().filter(|f| !f.dynamic && f.depth.is_some_and(|z| z <= max_depth)).count();
        self.best_usable = self.best_usable.max(usable);
        let stamp = msg.header.stamp;
        self.first_stamp.get_or_insert(stamp);
        let r = tracker.track(stamp, &features);
        self.counts[r.state.code() as usize] += 1;
        if r.world_from_cam.is_some() && self.first_pose_frame.is_none() {
            self.first_pose_frame = Some(self.frames);
        }
        self.frames += 1;
        if let Some(gt) = GT_POSE.get(inputs)? {
            self.log.ground_truth(stamp, gt.world_from_cam);
        }
        let header = Header { frame_id: Arc::from("world"), ..msg.header.clone() };
        let stats = vec![
            ("state".into(), r.state.code()),
            ("matches".into(), r.matches as f64),
            ("inliers".into(), r.inliers as f64),
            ("map_points".into(), r.map_points as f64),
            ("map_id".into(), f64::from(r.map_id)),
            ("keyframe".into(), if r.keyframe.is_some() { 1.0 } else { 0.0 }),
        ];
        let mut stats = stats;
        if let Some(e) = tracker.inertial_estimate() {
            for (name, v) in [
                ("velocity", e.velocity),
                ("gyro_bias", e.bias.gyro),
                ("accel_bias", e.bias.accel),
                ("gravity", e.gravity_w),
            ] {
                for (axis, x) in ["x", "y", "z"].iter().zip(v.iter()) {
                    stats.push((format!("{name}_{axis}").into(), *x));
                }
            }
            stats.push(("position_sigma".into(), e.position_sigma));
        }
        let mut out = Outputs::new().send(&STATS, header.clone(), Scalars { values: stats });
        // A lost frame's pose is the motion model's guess, not an estimate: it is left out of
        // the pose stream and the trajectory, as ORB-SLAM2's SaveTrajectoryTUM and the TUM tools
        // leave lost frames out (their count is in the report beside the ATE).
        if let Some(world_from_cam) = r.world_from_cam.filter(|_| r.state != dynaflow_slam::TrackState::Lost) {
            self.log.pose(stamp, world_from_cam);
            out = out.send(&POSE, header.clone(), Pose { world_from_cam });
        }
        if let Some(kf) = &r.keyframe {
            out = out.send(&KEYFRAME, header, kf.clone());
        }
        Ok(out)
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), OpError> {
        // The online estimate (each frame's pose as it was sent) and the final one (rebuilt
        // from the key frames at the end, as ORB-SLAM2 saves it: local BA's refinements and
        // loop corrections included). The trajectory files first: whatever happens next, the
        // estimate is on disk.
        let final_trajectory = self.tracker.as_ref().map(Tracker::keyframe_trajectory).unwrap_or_default();
        let written = self.log.write(ctx, &final_trajectory);
        let saved = self.save_map();
        let [not_initialised, new_map, tracked, relocalised, lost, inertial] = self.counts;
        let sensor = self.setup.sensor();
        let mut report = TrackerReport {
            frames: FrameStates { not_initialised, new_map, tracked, relocalised, lost, inertial },
            maps: self.tracker.as_ref().map_or(0, Tracker::maps),
            memory_bytes: self.tracker.as_ref().map(Tracker::memory).unwrap_or_default(),
            map_relocalisations: self.tracker.as_ref().map_or(0, Tracker::map_relocalisations),
            sensor: sensor_name(sensor).to_owned(),
            first_pose_frame: self.first_pose_frame,
            inertial: self.tracker.as_ref().filter(|t| t.inertial()).map(|t| self.inertial_report(t)),
            ..TrackerReport::default()
        };
        if let Some(why) = self.never_initialised_because() {
            tracing::warn!("`{}`: {why}", ctx.node);
            report.initialised = Some(false);
            report.not_initialised_because = Some(why);
        }
        // A single camera's map has no scale, unless an IMU made it metric.
        let metric = self.tracker.as_ref().is_some_and(|t| t.inertial_init().is_some());
        let align = if sensor == Sensor::Monocular && !metric { Align::Sim3 } else { Align::Se3 };
        self.log.score(&final_trajectory, align, &mut report);
        match &saved {
            Ok(Some((keyframes, points))) => {
                report.map_saved = Some(MapSaved {
                    file: self.config.save_map.display().to_string(),
                    keyframes: *keyframes,
                    points: *points,
                });
            }
            Ok(None) => {}
            Err(e) => report.map_saved_error = Some(e.to_string()),
        }
        if !self.config.load_map.as_os_str().is_empty() {
            report.map_loaded = Some(self.config.load_map.display().to_string());
        }
        ctx.report = Some(NodeReport::from(report).to_json());
        written.and(saved.map(|_| ()))
    }
}

impl Track {
    /// Why no frame ever had a pose (`None` when one did).
    fn never_initialised_because(&self) -> Option<String> {
        if self.first_pose_frame.is_some() {
            return None;
        }
        let [not_initialised, _, _, _, lost, _] = self.counts;
        Some(if matches!(self.setup, Setup::Mono) {
            let last = self.tracker.as_ref().and_then(Tracker::init_failure).unwrap_or("no frame");
            format!(
                "the monocular tracker never initialised in {not_initialised} frames (it needs two views with enough parallax); the last attempt: {last}"
            )
        } else if !self.config.load_map.as_os_str().is_empty() {
            format!(
                "the camera was never relocalised in the loaded map {}: {lost} frames lost of {}",
                self.config.load_map.display(),
                self.frames
            )
        } else {
            // No map ever started: no pose, no ATE. Said here, in the summary and by `run`.
            let max_depth = self.tracker.as_ref().map_or(0.0, |t| t.config().max_depth);
            format!(
                "the tracker never initialised in {not_initialised} frames: at most {} keypoints of a frame had a depth up to max_depth {max_depth} m and no mask or dynamic label; a map needs {}",
                self.best_usable,
                TrackerConfig::rgbd(1.0).min_init_points
            )
        })
    }

    /// Write the whole map to `save_map` (if set): its key frames and points.
    fn save_map(&self) -> Result<Option<(usize, usize)>, OpError> {
        if self.config.save_map.as_os_str().is_empty() {
            return Ok(None);
        }
        let Some(map) = self.tracker.as_ref().and_then(Tracker::places).filter(|m| !m.kfs.is_empty()) else {
            return Err(OpError::Failed(format!(
                "no map to save to {}: the tracker never started one",
                self.config.save_map.display()
            )));
        };
        let path = &self.config.save_map;
        dynaflow_engine::files::write_atomic(path, &dynaflow_slam::map_file::encode(map))
            .map_err(|source| OpError::Io { path: path.clone(), source })?;
        Ok(Some((map.kfs.len(), map.points.len())))
    }
}
