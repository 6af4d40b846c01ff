//! `cull_depth`: multi-view depth consistency.

use super::*;

params! {
    struct DepthConfig {
        /// predicted-vs-measured depth difference in metres above which a point is dynamic (4 sigma of Kinect depth noise at 4 m)
        depth_threshold: f64 [0.0, 100.0] = 0.1,
    }
}

const DEPTH: In<DepthImage> = In::wired("depth", "depth in metres (a frame without: nothing is judged)");
const CAMERA_INFO: In<CameraInfo> = In::wired("camera_info", "intrinsics");
const POSE: In<Pose> = In::wired(
    "pose",
    "world_from_cam, from the tracker (`delay: 1`) or ground truth (a frame without: nothing is judged)",
);

rule_op!(CULL_DEPTH, "cull_depth", &[TRACKS.spec, DEPTH.spec, CAMERA_INFO.spec, POSE.spec], DepthConfig, |c| DepthOp {
    config: c,
    last: None,
    anchors: rules::DepthAnchors::new()
}, tunable: &["depth_threshold"]);

struct DepthOp {
    config: DepthConfig,
    /// The previous frame's depth and pose, when this node saw both.
    last: Option<(DepthImage, Isometry3<f64>)>,
    anchors: rules::DepthAnchors,
}

impl Operator for DepthOp {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, t) = TRACKS.require(inputs)?;
        let depth = DEPTH.get(inputs)?;
        let pose = POSE.get(inputs)?.map(|p| p.world_from_cam);
        let camera = match CAMERA_INFO.get(inputs)? {
            Some(k) => {
                crate::frontend::pinhole_only(k, "the depth rule")?;
                Some(rules::Pinhole::new(k.fx, k.fy, k.cx, k.cy))
            }
            None => None,
        };
        let threshold = self.config.depth_threshold as f32;
        let decisions = match (depth, pose, camera) {
            (Some(cur_depth), Some(world_from_cur), Some(camera)) => {
                let tracks: Vec<rules::TrackedPoint> =
                    t.tracks.iter().map(|t| rules::TrackedPoint { id: t.id, prev: t.prev, cur: t.cur }).collect();
                let previous = self.last.as_ref().map(|(d, pose)| (|x, y| d.at_nearest(x, y), *pose));
                self.anchors.label(
                    &tracks,
                    camera,
                    previous,
                    (|x, y| cur_depth.at_nearest(x, y), world_from_cur),
                    threshold,
                )
            }
            // An input absent this frame: nothing can be judged.
            _ => all_static(t.tracks.len(), f32::NAN),
        };
        self.last = depth.cloned().zip(pose);
        Ok(labelled(msg, t, &decisions, &[("threshold", f64::from(threshold))]))
    }

    fn set_params(&mut self, _ctx: &mut Context, params: &Params) -> Result<(), OpError> {
        self.config.depth_threshold = DepthConfig::from_params(params)?.depth_threshold;
        Ok(())
    }
}
