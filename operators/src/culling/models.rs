//! `fundamental_ransac` and `homography_prosac`: the two-view models as operators.

use super::*;

// --- fundamental_ransac ----------------------------------------------------------------

params! {
    struct FConfig {
        /// RANSAC inlier threshold on the epipolar distances, pixels (chosen for sub-pixel LK tracks; OpenCV's default is 3)
        ransac_threshold: f64 [0.01, 100.0] = 1.0,
        /// RANSAC confidence
        confidence: f64 [0.5, 0.999_999] = 0.99,
        /// samples at most (fewer when the inlier ratio allows)
        max_iterations: u64 [1, 1_000_000] = 1000,
        /// refit on the inliers of each new best model (LO-RANSAC)
        local_optimisation: bool = true,
    }
}

const F_MODEL: Out<Scalars> = Out::new("model", "`f00`..`f22` (x2^T F x1 = 0), `inliers`, `tracks`, `iterations`");
const F_LABELS: Out<PointLabels> =
    Out::new("labels", "per track: outlier = dynamic, reason `epipolar`, score = distance");

const FUNDAMENTAL_RANSAC_DOC: &str = "The fundamental matrix of the previous-to-current tracks by LO-RANSAC over the 7-point solver (8-point refits), deterministic from the node's seed. `labels` marks RANSAC outliers dynamic with each track's epipolar distance (pixels, MG-SLAM's Eq. 4) as score.";

/// The `fundamental_ransac` operator (its doc: `dynaflow ops fundamental_ransac`).
pub const FUNDAMENTAL_RANSAC: OpSpec =
    OpSpec::transform("fundamental_ransac", "epipolar", FUNDAMENTAL_RANSAC_DOC, |p: &Params| {
        let c = FConfig::from_params(p)?;
        Ok(Instance::Transform(Box::new(FundamentalOp(RansacConfig {
            threshold: c.ransac_threshold,
            confidence: c.confidence,
            max_iterations: c.max_iterations as usize,
            local_optimisation: c.local_optimisation,
        }))))
    })
    .inputs(&[TRACKS.spec])
    .outputs(&[F_MODEL.spec, F_LABELS.spec])
    .params(FConfig::PARAMS)
    .cpu_heavy();

struct FundamentalOp(RansacConfig);

impl Operator for FundamentalOp {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, t) = TRACKS.require(inputs)?;
        let (prev, cur) = endpoints(t);
        let seed = ctx.rng.next_u64();
        let mut out = Outputs::new();
        let Some((fit, dist)) = rules::epipolar_distances(&prev, &cur, &vec![true; prev.len()], &self.0, seed) else {
            // Too few tracks for a model: nothing is labelled.
            return Ok(out);
        };
        let mut values: Vec<(Arc<str>, f64)> =
            fit.f.transpose().iter().enumerate().map(|(i, v)| (format!("f{}{}", i / 3, i % 3).into(), *v)).collect();
        values.push(("inliers".into(), fit.inlier_count() as f64));
        values.push(("tracks".into(), prev.len() as f64));
        values.push(("iterations".into(), fit.iterations as f64));
        F_MODEL.push(&mut out, msg.header.clone(), Scalars { values });
        let decisions: Vec<Decision> = fit
            .inliers
            .iter()
            .zip(&dist)
            .map(|(&inlier, &d)| Decision {
                dynamic: !inlier,
                reason: if inlier { LabelReason::Static } else { LabelReason::Epipolar },
                score: d,
            })
            .collect();
        F_LABELS.push(&mut out, msg.header.clone(), labels(t, &decisions));
        Ok(out)
    }
}

// --- homography_prosac ----------------------------------------------------------------

params! {
    struct HConfig {
        /// inlier threshold on the transfer error, pixels
        threshold: f64 [0.01, 1000.0] = 1.0,
    }
}

const H_MODEL: Out<Scalars> = Out::new("model", "`h00`..`h22` (p2 ~ H p1), `inliers`, `tracks`, `iterations`");
const H_LABELS: Out<PointLabels> =
    Out::new("labels", "per track: outlier = dynamic, reason `flow`, score = transfer error (px)");

const HOMOGRAPHY_PROSAC_DOC: &str = "The homography of the previous-to-current tracks by PROSAC (samples from the best-ranked tracks first; rank = 1 / (1 + error), the tracker's residual or Hamming distance), for camera-motion compensation as in PSPNet-SLAM. `labels` marks tracks whose transfer error exceeds `threshold` pixels.";

/// The `homography_prosac` operator (its doc: `dynaflow ops homography_prosac`).
pub const HOMOGRAPHY_PROSAC: OpSpec =
    OpSpec::transform("homography_prosac", "epipolar", HOMOGRAPHY_PROSAC_DOC, |p: &Params| {
        Ok(Instance::Transform(Box::new(HomographyOp(HConfig::from_params(p)?))))
    })
    .inputs(&[TRACKS.spec])
    .outputs(&[H_MODEL.spec, H_LABELS.spec])
    .params(HConfig::PARAMS)
    .cpu_heavy();

struct HomographyOp(HConfig);

impl Operator for HomographyOp {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, t) = TRACKS.require(inputs)?;
        let (prev, cur) = endpoints(t);
        let quality: Vec<f64> = t.tracks.iter().map(|t| 1.0 / (1.0 + f64::from(t.error.max(0.0)))).collect();
        let seed = ctx.rng.next_u64();
        let mut out = Outputs::new();
        let Some((fit, residuals)) = rules::homography_residuals(&prev, &cur, &quality, self.0.threshold, seed) else {
            return Ok(out);
        };
        let mut values: Vec<(Arc<str>, f64)> =
            fit.h.transpose().iter().enumerate().map(|(i, v)| (format!("h{}{}", i / 3, i % 3).into(), *v)).collect();
        values.push(("inliers".into(), fit.inliers.iter().filter(|&&i| i).count() as f64));
        values.push(("tracks".into(), prev.len() as f64));
        values.push(("iterations".into(), fit.iterations as f64));
        H_MODEL.push(&mut out, msg.header.clone(), Scalars { values });
        let decisions = rules::flow_consistency(&residuals, self.0.threshold as f32);
        H_LABELS.push(&mut out, msg.header.clone(), labels(t, &decisions));
        Ok(out)
    }
}
