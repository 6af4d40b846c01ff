//! `cull_epipolar` (MG-SLAM) and `cull_epipolar_adaptive` (YSAG-VINS).

use super::*;

params! {
    struct EpipolarConfig {
        /// distance in pixels above which a point is dynamic (MG-SLAM's 0.40; sub-pixel LK tracks put static points well below it)
        threshold: f64 [0.0, 1000.0] = 0.4,
        /// RANSAC inlier threshold on the epipolar distances, pixels (chosen for sub-pixel LK tracks; OpenCV's default is 3)
        ransac_threshold: f64 [0.01, 100.0] = 1.0,
        /// RANSAC confidence
        confidence: f64 [0.5, 0.999_999] = 0.99,
        /// a track labelled dynamic stays dynamic while it is tracked (MG-SLAM's dynamic features tracked)
        sticky: bool = false,
        /// fit F only on the tracks not already labelled dynamic in the previous frame
        fit_static: bool = false,
        /// frames between the two views tested: 1 compares consecutive frames (MG-SLAM); k > 1 each track's pixel k frames ago with now, where it has been tracked that long (the rest: consecutive frames)
        baseline: u64 [1, 60] = 1,
        /// when the `baseline` test replaces the consecutive one: on every frame, or only where the consecutive pair has too little parallax for F (ORB-SLAM2's model selection: R_H > 0.40)
        long_baseline: LongBaseline = LongBaseline::Always,
        /// test the `baseline` pair against the model ORB-SLAM2's model selection picks for it: its homography's transfer error where R_H > 0.40 (a rotation: F is ill-posed), its epipolar distance otherwise
        select_model: bool = false,
    }
}

param_enum! {
    /// When the longer-baseline epipolar test runs.
    enum LongBaseline { Always = "always", LowParallax = "low_parallax" }
}

rule_op!(CULL_EPIPOLAR, "cull_epipolar", &[TRACKS.spec], EpipolarConfig, |c: EpipolarConfig| {
    EpipolarOp(rules::EpipolarCull::new(rules::EpipolarOptions {
        threshold: c.threshold as f32,
        ransac: ransac(c.ransac_threshold, c.confidence),
        sticky: c.sticky,
        fit_static: c.fit_static,
        baseline: c.baseline as usize,
        long_baseline: match c.long_baseline {
            LongBaseline::Always => rules::LongBaseline::Always,
            LongBaseline::LowParallax => rules::LongBaseline::LowParallax,
        },
        select_model: c.select_model,
    }))
}, tunable: &["threshold"]);

struct EpipolarOp(rules::EpipolarCull);

impl Operator for EpipolarOp {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, t) = TRACKS.require(inputs)?;
        let (prev, cur) = endpoints(t);
        let ids: Vec<u64> = t.tracks.iter().map(|t| t.id).collect();
        let frame = self.0.label(&ids, &prev, &cur, ctx.rng.next_u64());
        let threshold = f64::from(self.0.options().threshold);
        let mut extra = vec![("threshold", threshold), ("long_baseline", frame.long as f64)];
        if let Some(r) = frame.homography_ratio {
            extra.push(("homography_ratio", r));
        }
        if let Some(r) = frame.long_homography_ratio {
            extra.push(("long_homography_ratio", r));
            extra.push(("long_homography", f64::from(u8::from(frame.long_homography))));
        }
        Ok(labelled(msg, t, &frame.decisions, &extra))
    }

    fn set_params(&mut self, _ctx: &mut Context, params: &Params) -> Result<(), OpError> {
        self.0.set_threshold(EpipolarConfig::from_params(params)?.threshold as f32);
        Ok(())
    }
}

params! {
    struct AdaptiveConfig {
        /// RANSAC inlier threshold on the epipolar distances of the points outside the boxes, pixels
        ransac_threshold: f64 [0.01, 100.0] = 1.0,
        /// RANSAC confidence
        confidence: f64 [0.5, 0.999_999] = 0.99,
    }
}

const ADAPTIVE_DETECTIONS: In<Detections> =
    In::wired("detections", "boxes of potentially dynamic objects (a frame without: no box)");

rule_op!(
    CULL_EPIPOLAR_ADAPTIVE,
    "cull_epipolar_adaptive",
    &[TRACKS.spec, ADAPTIVE_DETECTIONS.spec],
    AdaptiveConfig,
    AdaptiveOp
);

struct AdaptiveOp(AdaptiveConfig);

impl Operator for AdaptiveOp {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, t) = TRACKS.require(inputs)?;
        let (prev, cur) = endpoints(t);
        let seed = ctx.rng.next_u64();
        let in_box = rules::in_any_box(&cur, &boxes(ADAPTIVE_DETECTIONS.get(inputs)?));
        let outside: Vec<bool> = in_box.iter().map(|b| !b).collect();
        let ransac = ransac(self.0.ransac_threshold, self.0.confidence);
        Ok(match rules::epipolar_distances(&prev, &cur, &outside, &ransac, seed) {
            Some((_, d)) => {
                let (decisions, threshold) = rules::epipolar_adaptive(&d, &in_box);
                labelled(msg, t, &decisions, &[("threshold", f64::from(threshold))])
            }
            // No F from the points outside the boxes: no threshold either.
            None => labelled(msg, t, &all_static(prev.len(), 0.0), &[]),
        })
    }
}
