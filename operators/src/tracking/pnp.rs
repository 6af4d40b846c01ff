//! `pnp_track`.

use std::io::Write;
use std::sync::Arc;

use dynaflow_engine::msg::{Body, Header, Message, PortType, Pose, Scalars};
use dynaflow_engine::op::{
    Context, Default, Inputs, Instance, OpError, OpKind, OpSpec, Operator, Outputs, ParamSpec, ParamType, Params,
    PortSpec,
};
use dynaflow_slam::eval::{Align, evaluate};
use dynaflow_slam::{Feature, Tracker, TrackerConfig};
use dynaflow_vision::geometry::Camera;
use nalgebra::Isometry3;
use rand_core::Rng;

use super::convert;

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Config {
    min_inliers: u64,
    search_radius: f64,
    baseline: f64,
    close_depth: f64,
    max_depth: f64,
    ransac_threshold: f64,
    reset_after: u64,
}

const fn float(name: &'static str, min: f64, max: f64, default: f64, doc: &'static str) -> ParamSpec {
    ParamSpec { name, ty: ParamType::Float { min, max }, default: Default::Float(default), doc }
}

pub const PNP_TRACK: OpSpec = OpSpec {
    name: "pnp_track",
    family: "pnp_ba",
    doc: "ORB-SLAM-style RGB-D tracking against the local map: map points projected with a constant-velocity prediction are matched to the keypoints in a search radius (Hamming distance, ratio test), refined by motion-only BA (LM on SE(3), pixels plus depth as ORB-SLAM2's virtual right coordinate, Huber, four re-classification rounds); when too few survive, descriptor matching against the local map and P3P RANSAC relocalise. Dynamic keypoints (on `mask` pixels, or near a track `labels` marks dynamic) never reach the solver. Lost frames follow the motion model; after `reset_after` of them a new map starts at the dead-reckoned pose. Key frames (ORB-SLAM2's rules) go to `local_map`, whose refined map comes back on `map`. Writes `<out>/<graph>[-<variant>].<node>.trajectory.txt` (TUM format) and, with `gt_pose`, puts the ATE (SE(3)-aligned) in the summary.",
    kind: OpKind::Transform,
    inputs: &[
        PortSpec::input("keypoints", PortType::Keypoints, "this frame's ORB keypoints with descriptors"),
        PortSpec::input("depth", PortType::Depth, "depth in metres"),
        PortSpec::input("camera_info", PortType::CameraInfo, "intrinsics"),
        PortSpec::optional("map", PortType::Map, "local mapping's refined local map (`delay: 1`, `join: latest`)"),
        PortSpec::optional("mask", PortType::Mask, "pixels of a non-zero class are dynamic"),
        PortSpec::optional("labels", PortType::PointLabels, "culling's labels of `tracks`"),
        PortSpec::optional(
            "tracks",
            PortType::Tracks,
            "the tracks `labels` index (keypoints within 2 px of a dynamic one are left out)",
        ),
        PortSpec::optional("gt_pose", PortType::Pose, "ground truth, for the ATE in the summary"),
    ],
    outputs: &[
        PortSpec::output("pose", PortType::Pose, "world_from_cam (the first key frame is the world)"),
        PortSpec::output(
            "keyframe",
            PortType::Map,
            "a new key frame with its observations and new points (to `local_map`)",
        ),
        PortSpec::output(
            "stats",
            PortType::Scalars,
            "`state` (0 not initialised, 1 new map, 2 tracked, 3 relocalised, 4 lost), `matches`, `inliers`, `map_points`, `map_id`, `keyframe`",
        ),
    ],
    params: &[
        ParamSpec {
            name: "min_inliers",
            ty: ParamType::Int { min: 6, max: 100_000 },
            default: Default::Int(30),
            doc: "fewer inliers than this after motion-only BA: the frame is not tracked (ORB-SLAM: 30)",
        },
        float(
            "search_radius",
            1.0,
            200.0,
            15.0,
            "projection search radius, pixels (ORB-SLAM2's motion-model search: 15; widened 3x once)",
        ),
        float(
            "baseline",
            0.0,
            10.0,
            0.08,
            "virtual baseline, metres: bf = fx x baseline weighs the depth residual (ORB-SLAM2 TUM configs: bf 40 at fx 525); 0 uses pixels only",
        ),
        float(
            "close_depth",
            0.1,
            1000.0,
            3.2,
            "points closer than this are `close` in the key-frame rule (ORB-SLAM2 ThDepth 40 x baseline)",
        ),
        float(
            "max_depth",
            0.1,
            1000.0,
            6.0,
            "depths beyond this (metres) are not used (Kinect noise grows with the square)",
        ),
        float("ransac_threshold", 0.1, 100.0, 3.0, "P3P RANSAC reprojection threshold, pixels"),
        ParamSpec {
            name: "reset_after",
            ty: ParamType::Int { min: 0, max: 100_000 },
            default: Default::Int(5),
            doc: "lost frames in a row before a new map starts",
        },
    ],
    cpu_heavy: true,
    build: |p: &Params| {
        Ok(Instance::Transform(Box::new(PnpTrack {
            config: p.parse()?,
            tracker: None,
            trajectory: Vec::new(),
            ground_truth: Vec::new(),
            counts: [0; 5],
            last_map: None,
        })))
    },
};

struct PnpTrack {
    config: Config,
    tracker: Option<Tracker>,
    trajectory: Vec<(f64, Isometry3<f64>)>,
    ground_truth: Vec<(f64, Isometry3<f64>)>,
    /// Frames per state code.
    counts: [u64; 5],
    /// The map batch last applied (a `latest` join may repeat it).
    last_map: Option<Arc<Message>>,
}

/// Per keypoint: left out as dynamic?
fn dynamic_keypoints(inputs: &Inputs, points: &[[f32; 2]]) -> Vec<bool> {
    let mut dynamic = vec![false; points.len()];
    if let Some(Body::Mask(m)) = inputs.get("mask").map(|m| &m.body) {
        for (d, p) in dynamic.iter_mut().zip(points) {
            let (x, y) = (p[0].round() as i64, p[1].round() as i64);
            if x >= 0 && y >= 0 && (x as u32) < m.width && (y as u32) < m.height {
                *d |= m.classes.get(y as usize * m.width as usize + x as usize).is_some_and(|&c| c != 0);
            }
        }
    }
    if let (Some(Body::PointLabels(l)), Some(Body::Tracks(t))) =
        (inputs.get("labels").map(|m| &m.body), inputs.get("tracks").map(|m| &m.body))
    {
        for lab in l.labels.iter().filter(|l| l.dynamic) {
            let Some(tr) = t.tracks.get(lab.index as usize) else { continue };
            for (d, p) in dynamic.iter_mut().zip(points) {
                if (p[0] - tr.cur[0]).powi(2) + (p[1] - tr.cur[1]).powi(2) <= 4.0 {
                    *d = true;
                }
            }
        }
    }
    dynamic
}

impl Operator for PnpTrack {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let msg = inputs.require("keypoints")?;
        let Body::Keypoints(kp) = &msg.body else { return Err(OpError::Input("`keypoints` is not keypoints".into())) };
        let Body::Depth(depth) = &inputs.require("depth")?.body else {
            return Err(OpError::Input("`depth` is not a depth image".into()));
        };
        let Body::CameraInfo(k) = &inputs.require("camera_info")?.body else {
            return Err(OpError::Input("`camera_info` is not camera info".into()));
        };
        let descriptors = match &kp.descriptors {
            Some(d) if d.bytes_per == 32 && d.data.len() == 32 * kp.points.len() => &d.data,
            Some(d) if kp.points.is_empty() || d.data.is_empty() => &d.data,
            _ => {
                return Err(OpError::Input(
                    "`keypoints` need 32-byte ORB descriptors (connect `orb_extract.keypoints`)".into(),
                ));
            }
        };
        if self.tracker.is_none() {
            let mut tc = TrackerConfig::rgbd(k.fx);
            tc.bf = k.fx * self.config.baseline;
            tc.th_depth = self.config.close_depth;
            tc.max_depth = self.config.max_depth;
            tc.search_radius = self.config.search_radius;
            tc.min_inliers = self.config.min_inliers as usize;
            tc.ransac_threshold = self.config.ransac_threshold;
            tc.reset_after = self.config.reset_after as u32;
            let cam = Camera { fx: k.fx, fy: k.fy, cx: k.cx, cy: k.cy };
            self.tracker = Some(Tracker::new(tc, cam, k.width as usize, k.height as usize, ctx.rng.next_u64()));
        }
        let Some(tracker) = self.tracker.as_mut() else { return Ok(Outputs::new()) };
        if let Some(m) = inputs.get("map")
            && self.last_map.as_ref().is_none_or(|last| !Arc::ptr_eq(last, m))
        {
            if let Body::Map(update) = &m.body {
                tracker.apply_map_update(&convert::from_msg(update));
            }
            self.last_map = Some(m.clone());
        }
        let uv: Vec<[f32; 2]> = kp.points.iter().map(|p| [p.x, p.y]).collect();
        let dynamic = dynamic_keypoints(inputs, &uv);
        let features: Vec<Feature> = kp
            .points
            .iter()
            .zip(descriptors.chunks_exact(32))
            .zip(&dynamic)
            .map(|((p, d), &dynamic)| {
                let z = f64::from(depth.at_nearest(p.x, p.y));
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
        let stamp = msg.header.stamp;
        let r = tracker.track(stamp, &features);
        self.counts[r.state.code() as usize] += 1;
        if let Some(Body::Pose(gt)) = inputs.get("gt_pose").map(|m| &m.body) {
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
        let mut out = Outputs::new().with("stats", header.clone(), Body::Scalars(Scalars { values: stats }));
        if let Some(pose) = r.pose {
            self.trajectory.push((stamp, pose));
            out = out.with("pose", header.clone(), Body::Pose(Pose { world_from_cam: pose }));
        }
        if let Some(kf) = &r.keyframe {
            out = out.with("keyframe", header, Body::Map(convert::to_msg(kf)));
        }
        Ok(out)
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), OpError> {
        // The trajectory file first: whatever happens next, the estimate is on disk.
        let written = self.write_trajectory(ctx);
        let [not_initialised, new_map, tracked, relocalised, lost] = self.counts;
        let mut report = serde_json::json!({
            "frames": { "not_initialised": not_initialised, "new_map": new_map, "tracked": tracked,
                        "relocalised": relocalised, "lost": lost },
            "maps": self.tracker.as_ref().map_or(0, Tracker::map_id),
        });
        if !self.ground_truth.is_empty() && !self.trajectory.is_empty() {
            // evo's default tolerance (10 ms); SE(3) alignment as the RGB-D papers report it.
            match evaluate(&self.ground_truth, &self.trajectory, 0.01, Align::Se3, 1) {
                Ok(e) => {
                    report["ate"] = serde_json::json!({
                        "rmse": e.ate.rmse, "mean": e.ate.mean, "median": e.ate.median, "std": e.ate.std,
                        "max": e.ate.max, "align": "se3", "pairs": e.matched,
                    });
                    report["rpe"] = serde_json::json!({
                        "delta_frames": e.rpe_delta, "translation_rmse": e.rpe_translation.rmse,
                        "rotation_rmse_deg": e.rpe_rotation_deg.rmse,
                    });
                }
                Err(e) => report["ate_error"] = serde_json::json!(e.to_string()),
            }
        }
        ctx.report = Some(report);
        written
    }
}

impl PnpTrack {
    /// `<out>/<stem>.<node>.trajectory.txt`, and with `gt_pose` the ground truth of the same
    /// frames beside it (`.groundtruth.txt`), both TUM format (`dynaflow eval`, `dynaflow bench`).
    fn write_trajectory(&self, ctx: &Context) -> Result<(), OpError> {
        let Some(dir) = &ctx.out_dir else { return Ok(()) };
        for (what, poses) in [("trajectory", &self.trajectory), ("groundtruth", &self.ground_truth)] {
            if poses.is_empty() {
                continue;
            }
            let path = dir.join(format!("{}.{}.{what}.txt", ctx.stem, ctx.node));
            let io = |source| OpError::Io { path: path.clone(), source };
            let mut f = std::io::BufWriter::new(std::fs::File::create(&path).map_err(io)?);
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
