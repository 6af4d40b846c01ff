//! `cull_flow`: flow consistency against the dominant homography.

use super::*;

param_enum! {
    /// The camera-induced motion a flow-consistency rule compares with.
    enum MotionModel { Homography = "homography", Fundamental = "fundamental" }
}

params! {
    struct FlowConfig {
        /// the camera-induced motion, a homography by PROSAC (PSPNet-SLAM; exact for rotation or a distant scene) or F (allows parallax)
        motion_model: MotionModel = MotionModel::Homography,
        /// residual in pixels above which a track is dynamic
        flow_threshold: f64 [0.0, 1000.0] = 1.0,
        /// RANSAC (or PROSAC) inlier threshold of the motion model, pixels
        ransac_threshold: f64 [0.01, 100.0] = 1.0,
        /// RANSAC confidence (`fundamental`)
        confidence: f64 [0.5, 0.999_999] = 0.99,
    }
}

rule_op!(CULL_FLOW, "cull_flow", &[TRACKS.spec], FlowConfig, FlowOp, tunable: &["flow_threshold"]);

struct FlowOp(FlowConfig);

impl Operator for FlowOp {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, t) = TRACKS.require(inputs)?;
        let (prev, cur) = endpoints(t);
        let seed = ctx.rng.next_u64();
        let residuals = match self.0.motion_model {
            MotionModel::Fundamental => {
                let ransac = ransac(self.0.ransac_threshold, self.0.confidence);
                rules::epipolar_distances(&prev, &cur, &vec![true; prev.len()], &ransac, seed).map(|(_, d)| d)
            }
            MotionModel::Homography => {
                let quality: Vec<f64> = t.tracks.iter().map(|t| 1.0 / (1.0 + f64::from(t.error.max(0.0)))).collect();
                rules::homography_residuals(&prev, &cur, &quality, self.0.ransac_threshold, seed).map(|(_, r)| r)
            }
        };
        let threshold = self.0.flow_threshold as f32;
        let decisions = match residuals {
            Some(r) => rules::flow_consistency(&r, threshold),
            None => all_static(prev.len(), 0.0),
        };
        Ok(labelled(msg, t, &decisions, &[("threshold", f64::from(threshold))]))
    }

    fn set_params(&mut self, _ctx: &mut Context, params: &Params) -> Result<(), OpError> {
        // Nothing carries over between frames but the parameters themselves.
        self.0.flow_threshold = FlowConfig::from_params(params)?.flow_threshold;
        Ok(())
    }
}
