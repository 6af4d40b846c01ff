//! `pnp_track`.

use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;

use dynaflow_engine::msg::{
    CameraInfo, DepthImage, Header, Keypoints, Message, PointLabels, Pose, Scalars, SegmentationMask, SparseMap, Tracks,
};
use dynaflow_engine::op::{
    Context, In, InputRole, Inputs, Instance, OpError, OpKind, OpSpec, Operator, Out, Outputs, Params,
};
use dynaflow_engine::{param_enum, params};
use dynaflow_slam::eval::{Align, evaluate};
use dynaflow_slam::{Feature, Tracker, TrackerConfig};
use dynaflow_vision::camera::Pinhole;
use nalgebra::Isometry3;
use rand_core::Rng;

use super::convert;

param_enum! {
    /// What gives keypoints their depth (ORB-SLAM2's three sensor modes).
    enum Sensor { Rgbd = "rgbd", Stereo = "stereo", Mono = "mono" }
}

params! {
    struct Config {
        /// `rgbd`: `depth` from a depth camera; `stereo`: `depth` from `stereo_match` and the rig on `stereo` (its baseline replaces `baseline`, close depth 40 baselines, ORB-SLAM2's ThDepth; every matched depth used, no `max_depth`); `mono`: no depth (`depth` ignored), the map starts from two views and scale is arbitrary (ATE Sim(3)-aligned)
        sensor: Sensor = Sensor::Rgbd,
        /// fewer inliers than this after motion-only BA: the frame is not tracked (ORB-SLAM: 30)
        min_inliers: u64 [6, 100_000] = 30,
        /// projection search radius, pixels (ORB-SLAM2's motion-model search: 15; widened 3x once)
        search_radius: f64 [1.0, 200.0] = 15.0,
        /// virtual baseline, metres: bf = fx x baseline weighs the depth residual (ORB-SLAM2 TUM configs: bf 40 at fx 525); 0 uses pixels only
        baseline: f64 [0.0, 10.0] = 0.08,
        /// points closer than this are `close` in the key-frame rule (ORB-SLAM2 ThDepth 40 x baseline)
        close_depth: f64 [0.1, 1000.0] = 3.2,
        /// depths beyond this (metres) are not used (Kinect noise grows with the square)
        max_depth: f64 [0.1, 1000.0] = 6.0,
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
    }
}

const KEYPOINTS: In<Keypoints> = In::required("keypoints", "this frame's ORB keypoints with descriptors");
const DEPTH: In<DepthImage> = In::optional("depth", "depth in metres (`sensor: rgbd` or `stereo`; ignored by `mono`)");
const STEREO: In<Scalars> =
    In::optional("stereo", "the stereo rig (`sensor: stereo`): `baseline_m`, as `kitti_odometry` and `synth` send it");
const CAMERA_INFO: In<CameraInfo> = In::required("camera_info", "intrinsics");
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
const GT_POSE: In<Pose> =
    In::optional("gt_pose", "ground truth, for the ATE in the summary").with_role(InputRole::Evaluation);
const POSE: Out<Pose> =
    Out::new("pose", "world_from_cam (the first key frame is the world); none on a frame the tracker lost");
const KEYFRAME: Out<SparseMap> =
    Out::new("keyframe", "a new key frame with its observations and new points (to `local_map`)");
const STATS: Out<Scalars> = Out::new(
    "stats",
    "`state` (0 not initialised, 1 new map, 2 tracked, 3 relocalised, 4 lost), `matches`, `inliers`, `map_points`, `map_id`, `keyframe`",
);

pub const PNP_TRACK: OpSpec = OpSpec {
    name: "pnp_track",
    family: "pnp_ba",
    doc: dynaflow_engine::op::doc_line(include_str!("docs/pnp_track.md")),
    kind: OpKind::Transform,
    inputs: &[
        KEYPOINTS.spec,
        DEPTH.spec,
        STEREO.spec,
        CAMERA_INFO.spec,
        MAP.spec,
        LOOP.spec,
        MASK.spec,
        LABELS.spec,
        TRACKS.spec,
        GT_POSE.spec,
    ],
    outputs: &[POSE.spec, KEYFRAME.spec, STATS.spec],
    params: Config::PARAMS,
    cpu_heavy: true,
    ground_truth_outputs: None,
    build: |p: &Params| {
        let config = Config::from_params(p)?;
        let (vocabulary, _, _) = super::load_vocabulary(&config.vocabulary)?;
        if !config.mapping && config.load_map.as_os_str().is_empty() {
            return Err(OpError::Config {
                key: "mapping".into(),
                message: "`mapping: false` (localisation mode) needs a map to localise in: set `load_map` (or `dynaflow run --load-map FILE`)".into(),
            });
        }
        // Where the map will be written, checked now (as the recorders check their files):
        // a run must not end with its map lost for a wrong path.
        if !config.save_map.as_os_str().is_empty() {
            let path = &config.save_map;
            let parent = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(std::path::Path::new("."));
            let problem = if path.is_dir() {
                Some("is a directory; give a file name".to_owned())
            } else if !parent.is_dir() {
                Some(format!("its folder {} does not exist", parent.display()))
            } else {
                None
            };
            if let Some(problem) = problem {
                return Err(OpError::Config {
                    key: "save_map".into(),
                    message: format!("{}: {problem}", path.display()),
                });
            }
        }
        // Read the map now, so that a bad file stops the run before it starts; the tracker
        // gives it its camera (`Tracker::use_map`) on the first frame.
        let loaded = if config.load_map.as_os_str().is_empty() {
            None
        } else {
            let cam = Pinhole { fx: 1.0, fy: 1.0, cx: 0.0, cy: 0.0 };
            Some(
                dynaflow_slam::map_file::load(&config.load_map, cam, 0.0, 0.0, 1.2, vocabulary.clone())
                    .map_err(|e| OpError::Input(e.to_string()))?,
            )
        };
        Ok(Instance::Transform(Box::new(PnpTrack {
            config,
            vocabulary,
            loaded,
            tracker: None,
            trajectory: Vec::new(),
            ground_truth: Vec::new(),
            counts: [0; 5],
            last_map: None,
            last_loop: None,
            best_usable: 0,
            frames: 0,
            first_pose_frame: None,
        })))
    },
};

struct PnpTrack {
    config: Config,
    /// For relocalisation in the whole map.
    vocabulary: Arc<dynaflow_slam::bow::Vocabulary>,
    /// A map to start in (`load_map`), until the first frame gives the camera.
    loaded: Option<dynaflow_slam::keyframe_map::KeyFrameMap>,
    tracker: Option<Tracker>,
    trajectory: Vec<(f64, Isometry3<f64>)>,
    ground_truth: Vec<(f64, Isometry3<f64>)>,
    /// Frames per state code.
    counts: [u64; 5],
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

/// Nearest-neighbour label transfer: each point whose nearest labelled track lies within
/// `radius` px (or exactly on it, for radius 0) is marked dynamic when that track is. Tracks
/// are bucketed in a grid of `radius`-sized cells, so only nine cells are searched.
fn transfer_labels(labelled: &[([f32; 2], bool)], points: &[[f32; 2]], radius: f32, dynamic: &mut [bool]) {
    if labelled.is_empty() || !labelled.iter().any(|l| l.1) {
        return;
    }
    let cell = radius.max(1.0);
    let key = |p: [f32; 2]| ((p[0] / cell).floor() as i64, (p[1] / cell).floor() as i64);
    let mut grid: std::collections::HashMap<(i64, i64), Vec<usize>> = std::collections::HashMap::new();
    for (i, (p, _)) in labelled.iter().enumerate() {
        if p[0].is_finite() && p[1].is_finite() {
            grid.entry(key(*p)).or_default().push(i);
        }
    }
    let r2 = radius * radius;
    for (d, p) in dynamic.iter_mut().zip(points) {
        let (cx, cy) = key(*p);
        let mut best: Option<(f32, usize)> = None;
        for gy in cy - 1..=cy + 1 {
            for gx in cx - 1..=cx + 1 {
                for &i in grid.get(&(gx, gy)).map_or(&[][..], Vec::as_slice) {
                    let q = labelled[i].0;
                    let d2 = (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2);
                    // Ties keep the first found (a fixed cell order): deterministic.
                    if d2 <= r2 && best.is_none_or(|(b, _)| d2 < b) {
                        best = Some((d2, i));
                    }
                }
            }
        }
        if let Some((_, i)) = best {
            *d |= labelled[i].1;
        }
    }
}

/// Per keypoint: left out as dynamic?
fn dynamic_keypoints(inputs: &Inputs, points: &[[f32; 2]], label_radius: f32) -> Result<Vec<bool>, OpError> {
    let mut dynamic = vec![false; points.len()];
    if let Some(m) = MASK.get(inputs)? {
        for (d, p) in dynamic.iter_mut().zip(points) {
            // (The mask's size was checked against the depth image's.)
            let (x, y) = (p[0].round() as i64, p[1].round() as i64);
            if x >= 0 && y >= 0 && (x as u32) < m.width && (y as u32) < m.height {
                *d |= m.classes.get(y as usize * m.width as usize + x as usize).is_some_and(|&c| c != 0);
            }
        }
    }
    if let (Some(l), Some(t)) = (LABELS.get(inputs)?, TRACKS.get(inputs)?) {
        let labelled: Vec<([f32; 2], bool)> = l
            .labels
            .iter()
            .filter_map(|lab| t.tracks.get(lab.index as usize).map(|tr| (tr.cur, lab.dynamic)))
            .collect();
        transfer_labels(&labelled, points, label_radius, &mut dynamic);
    }
    Ok(dynamic)
}

impl Operator for PnpTrack {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, kp) = KEYPOINTS.require(inputs)?;
        let (_, k) = CAMERA_INFO.require(inputs)?;
        let sensor = self.config.sensor;
        let depth = match sensor {
            Sensor::Mono => None,
            Sensor::Rgbd | Sensor::Stereo => Some(
                DEPTH
                    .get(inputs)?
                    .ok_or_else(|| {
                        OpError::Input(format!(
                            "`sensor: {}` needs `depth` (a depth camera's, or `stereo_match`'s); wire it, or set `sensor: mono`",
                            sensor.as_str()
                        ))
                    })?,
            ),
        };
        let rig_baseline = match sensor {
            Sensor::Stereo => {
                let rig = STEREO.get(inputs)?.ok_or_else(|| {
                    OpError::Input(
                        "`sensor: stereo` needs the rig on `stereo` (`baseline_m`, from the source's `stereo` port)"
                            .into(),
                    )
                })?;
                Some(crate::frontend::stereo_baseline(rig)?)
            }
            _ => None,
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
        if self.tracker.is_none() {
            let mut tc = match (sensor, rig_baseline) {
                (Sensor::Mono, _) => TrackerConfig::monocular(k.fx),
                (_, Some(b)) => TrackerConfig::stereo(k.fx, b),
                _ => TrackerConfig {
                    bf: k.fx * self.config.baseline,
                    th_depth: self.config.close_depth,
                    max_depth: self.config.max_depth,
                    ..TrackerConfig::rgbd(k.fx)
                },
            };
            tc.search_radius = self.config.search_radius;
            tc.min_inliers = self.config.min_inliers as usize;
            tc.ransac_threshold = self.config.ransac_threshold;
            tc.reset_after = self.config.reset_after as u32;
            let cam = Pinhole { fx: k.fx, fy: k.fy, cx: k.cx, cy: k.cy };
            let mut tracker = Tracker::new(tc, cam, k.width as usize, k.height as usize, ctx.rng.next_u64())
                .with_vocabulary(self.vocabulary.clone());
            if let Some(map) = self.loaded.take() {
                // A map of another camera's images cannot be found in these: refused, naming
                // the file, rather than tracked against keypoints outside the image.
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
            self.tracker = Some(tracker);
        }
        let Some(tracker) = self.tracker.as_mut() else { return Ok(Outputs::new()) };
        if let Some(update) = super::fresh(MAP.find(inputs)?, &mut self.last_map) {
            tracker.apply_map_update(&convert::from_msg(update));
        }
        if let Some(correction) = super::fresh(LOOP.find(inputs)?, &mut self.last_loop) {
            tracker.apply_correction(&convert::from_msg(correction));
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
        let r = tracker.track(stamp, &features);
        self.counts[r.state.code() as usize] += 1;
        if r.pose.is_some() && self.first_pose_frame.is_none() {
            self.first_pose_frame = Some(self.frames);
        }
        self.frames += 1;
        if let Some(gt) = GT_POSE.get(inputs)? {
            self.ground_truth.push((stamp, gt.world_from_cam));
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
        let mut out = Outputs::new().send(&STATS, header.clone(), Scalars { values: stats });
        // A lost frame's pose is the motion model's guess, not an estimate: it is left out of
        // the pose stream and the trajectory, as ORB-SLAM2's SaveTrajectoryTUM and the TUM tools
        // leave lost frames out (their count is in the report beside the ATE).
        if let Some(pose) = r.pose.filter(|_| r.state != dynaflow_slam::TrackState::Lost) {
            self.trajectory.push((stamp, pose));
            out = out.send(&POSE, header.clone(), Pose { world_from_cam: pose });
        }
        if let Some(kf) = &r.keyframe {
            out = out.send(&KEYFRAME, header, convert::to_msg(kf));
        }
        Ok(out)
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), OpError> {
        // The trajectory file first: whatever happens next, the estimate is on disk.
        let written = self.write_trajectory(ctx);
        let saved = self.save_map();
        let [not_initialised, new_map, tracked, relocalised, lost] = self.counts;
        let mut report = serde_json::json!({
            "frames": { "not_initialised": not_initialised, "new_map": new_map, "tracked": tracked,
                        "relocalised": relocalised, "lost": lost },
            "maps": self.tracker.as_ref().map_or(0, Tracker::map_id),
            "map_relocalisations": self.tracker.as_ref().map_or(0, Tracker::map_relocalisations),
            "sensor": self.config.sensor.as_str(),
            "first_pose_frame": self.first_pose_frame,
        });
        if self.first_pose_frame.is_none() && self.config.sensor == Sensor::Mono {
            let last = self.tracker.as_ref().and_then(Tracker::init_failure).unwrap_or("no frame");
            let why = format!(
                "the monocular tracker never initialised in {not_initialised} frames (it needs two views with enough parallax); the last attempt: {last}"
            );
            tracing::warn!("`{}`: {why}", ctx.node);
            report["initialised"] = serde_json::json!(false);
            report["not_initialised_because"] = serde_json::json!(why);
        } else if self.first_pose_frame.is_none() && !self.config.load_map.as_os_str().is_empty() {
            let why = format!(
                "the camera was never relocalised in the loaded map {}: {lost} frames lost of {}",
                self.config.load_map.display(),
                self.frames
            );
            tracing::warn!("`{}`: {why}", ctx.node);
            report["initialised"] = serde_json::json!(false);
            report["not_initialised_because"] = serde_json::json!(why);
        } else if self.first_pose_frame.is_none() {
            // No map ever started: no pose, no ATE. Said here, in the summary and by `run`.
            let why = format!(
                "the tracker never initialised in {not_initialised} frames: at most {} keypoints of a frame had a depth up to max_depth {} m and no mask or dynamic label; a map needs {}",
                self.best_usable,
                self.config.max_depth,
                TrackerConfig::rgbd(1.0).min_init_points
            );
            tracing::warn!("`{}`: {why}", ctx.node);
            report["initialised"] = serde_json::json!(false);
            report["not_initialised_because"] = serde_json::json!(why);
        }
        // The online estimate (each frame's pose as it was sent) and the final one (rebuilt
        // from the key frames at the end, as ORB-SLAM2 saves it: local BA's refinements and
        // loop corrections included).
        let final_trajectory = self.final_trajectory();
        for (poses, ate, rpe, error) in [
            (&self.trajectory, "ate", "rpe", "ate_error"),
            (&final_trajectory, "ate_final", "rpe_final", "ate_final_error"),
        ] {
            if self.ground_truth.is_empty() || poses.is_empty() {
                continue;
            }
            // evo's default tolerance (10 ms); SE(3) alignment as the RGB-D papers report it,
            // Sim(3) for a single camera (its scale is arbitrary; evo `-as`).
            let (align, name) =
                if self.config.sensor == Sensor::Mono { (Align::Sim3, "sim3") } else { (Align::Se3, "se3") };
            match evaluate(&self.ground_truth, poses, 0.01, align, 1) {
                Ok(e) => {
                    report[ate] = serde_json::json!({
                        "rmse": e.ate.rmse, "mean": e.ate.mean, "median": e.ate.median, "std": e.ate.std,
                        "max": e.ate.max, "align": name, "pairs": e.matched, "scale": e.scale,
                    });
                    report[rpe] = serde_json::json!({
                        "delta_frames": e.rpe_delta, "translation_rmse": e.rpe_translation.rmse,
                        "rotation_rmse_deg": e.rpe_rotation_deg.rmse,
                    });
                }
                Err(e) => report[error] = serde_json::json!(e.to_string()),
            }
        }
        match &saved {
            Ok(Some((k, p))) => {
                report["map_saved"] = serde_json::json!({ "file": self.config.save_map.display().to_string(), "keyframes": k, "points": p });
            }
            Ok(None) => {}
            Err(e) => report["map_saved_error"] = serde_json::json!(e.to_string()),
        }
        if !self.config.load_map.as_os_str().is_empty() {
            report["map_loaded"] = serde_json::json!(self.config.load_map.display().to_string());
        }
        ctx.report = Some(report);
        written.and(saved.map(|_| ()))
    }
}

impl PnpTrack {
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

    fn final_trajectory(&self) -> Vec<(f64, Isometry3<f64>)> {
        self.tracker.as_ref().map(Tracker::keyframe_trajectory).unwrap_or_default()
    }

    /// `<out>/<stem>.<node>.trajectory.txt` (the online estimate), `.final_trajectory.txt`
    /// (rebuilt from the final key frames, ORB-SLAM2's `SaveTrajectoryTUM`), and with `gt_pose`
    /// the ground truth of the same frames beside them (`.groundtruth.txt`), all TUM format
    /// (`dynaflow eval`, `dynaflow bench`).
    fn write_trajectory(&self, ctx: &Context) -> Result<(), OpError> {
        let final_trajectory = self.final_trajectory();
        for (what, poses) in [
            ("trajectory", &self.trajectory),
            ("final_trajectory", &final_trajectory),
            ("groundtruth", &self.ground_truth),
        ] {
            // The estimate's file is written even empty (a tracker that never initialised),
            // so a script finds it; the ground truth only when there is some.
            if poses.is_empty() && what == "groundtruth" {
                continue;
            }
            let Some(path) = ctx.output_file(&format!("{what}.txt")) else { return Ok(()) };
            let io = |source| OpError::Io { path: path.clone(), source };
            let mut f = std::io::BufWriter::new(dynaflow_engine::files::create_new(&path).map_err(io)?);
            writeln!(f, "# timestamp tx ty tz qx qy qz qw (world_from_cam, dynaflow pnp_track {what})").map_err(io)?;
            for (t, p) in poses.iter() {
                let (v, q) = (p.translation.vector, p.rotation.coords);
                writeln!(f, "{t:.6} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9}", v.x, v.y, v.z, q.x, q.y, q.z, q.w)
                    .map_err(io)?;
            }
            f.flush().map_err(io)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::transfer_labels;

    #[test]
    fn keypoints_take_the_label_of_the_nearest_track_within_the_radius() {
        // A dynamic track at (10, 10), a static one at (30, 10).
        let labelled = [([10.0, 10.0], true), ([30.0, 10.0], false)];
        let points = [[10.0, 10.0], [17.0, 10.0], [22.0, 10.0], [10.0, 25.0], [100.0, 100.0]];
        let mut dynamic = vec![false; points.len()];
        transfer_labels(&labelled, &points, 10.0, &mut dynamic);
        // On the track; nearer the dynamic one; nearer the static one; 15 px away; far away.
        assert_eq!(dynamic, [true, true, false, false, false]);
        // Radius 0: only a keypoint exactly on a dynamic track.
        let mut dynamic = vec![false; points.len()];
        transfer_labels(&labelled, &points, 0.0, &mut dynamic);
        assert_eq!(dynamic, [true, false, false, false, false]);
        // A mask's verdict is never undone by a static track.
        let mut dynamic = vec![true; points.len()];
        transfer_labels(&labelled, &points, 10.0, &mut dynamic);
        assert!(dynamic.iter().all(|&d| d));
    }
}
